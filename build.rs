//! Records what built collide, so study records name the binary that ran, whatever
//! folder it runs in: the compiler (`COLLIDE_RUSTC_VERSION`), and the git commit of the
//! source and whether its tracked files had changes (`COLLIDE_GIT_COMMIT`, "unknown"
//! outside a git checkout, and `COLLIDE_GIT_DIRTY`, "true" or "false").

use std::path::{Path, PathBuf};
use std::process::Command;

fn main() {
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-env-changed=RUSTC");
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".to_owned());
    let version = output_line(Command::new(rustc).arg("--version"));
    println!(
        "cargo::rustc-env=COLLIDE_RUSTC_VERSION={}",
        version.as_deref().unwrap_or("unknown")
    );
    git_provenance();
}

/// The commit and dirty flag, and the files whose change must rerun this script: the
/// checkout's HEAD, the branch it points to, the index, and the files the binary is
/// built from (an edit makes the build dirty without touching the index). In a
/// worktree `.git` is a file naming the real git folder; git itself resolves that.
fn git_provenance() {
    let manifest_dir = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default());
    let git =
        |args: &[&str]| output_line(Command::new("git").current_dir(&manifest_dir).args(args));
    for source in ["src", "Cargo.toml", "Cargo.lock", "assets"] {
        println!("cargo::rerun-if-changed={source}");
    }
    let Some(commit) = git(&["rev-parse", "--short=12", "HEAD"]) else {
        println!("cargo::rustc-env=COLLIDE_GIT_COMMIT=unknown");
        println!("cargo::rustc-env=COLLIDE_GIT_DIRTY=false");
        return;
    };
    let git_path =
        |name: &str| git(&["rev-parse", "--git-path", name]).map(|path| manifest_dir.join(path));
    let mut watched: Vec<Option<PathBuf>> = vec![git_path("HEAD"), git_path("index")];
    if let Some(branch) = git(&["symbolic-ref", "-q", "HEAD"]) {
        watched.push(git_path(&branch));
        watched.push(git_path("packed-refs"));
    }
    for path in watched.into_iter().flatten() {
        if Path::new(&path).exists() {
            println!("cargo::rerun-if-changed={}", path.display());
        }
    }
    let dirty = Command::new("git")
        .current_dir(&manifest_dir)
        // Without optional locks `git status` leaves the index alone: rewriting it would
        // rerun this script, and rebuild collide, on every build.
        .args([
            "--no-optional-locks",
            "status",
            "--porcelain",
            "--untracked-files=no",
        ])
        .output()
        .is_ok_and(|out| out.status.success() && !out.stdout.is_empty());
    println!("cargo::rustc-env=COLLIDE_GIT_COMMIT={commit}");
    println!("cargo::rustc-env=COLLIDE_GIT_DIRTY={dirty}");
}

/// The first line a command prints, if it runs and succeeds.
fn output_line(command: &mut Command) -> Option<String> {
    command
        .output()
        .ok()
        .filter(|out| out.status.success())
        .map(|out| String::from_utf8_lossy(&out.stdout).trim().to_owned())
        .filter(|line| !line.is_empty())
}
