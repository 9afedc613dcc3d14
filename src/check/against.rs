//! The build an A/B check compares this one with (`collide check --against REV`): which
//! commit REV names, and its `collide` binary, built once per commit in a temporary git
//! worktree with the same profile and features as this build, into a copy of this
//! build's target folder so that only the collide crate compiles. The binary is kept in
//! a cache folder by commit; the worktree and the copied target folder are removed
//! afterwards, also when the build fails. Running the two binaries is the runner's.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, bail};

use crate::study::environment::Environment;
use crate::system::output::write_atomically;

/// A commit to compare with, and why it was chosen.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Rev {
    /// The full commit hash.
    pub commit: String,
    /// Where it came from, for the summary ("the commit that recorded results/baseline/").
    pub reason: String,
}

/// The revision to build: `rev` as given, or (when empty) the commit recorded in the
/// baseline's environment, `baseline_commit` (`None` without a baseline).
pub fn choose(
    rev: &str,
    baseline_commit: Option<(&str, &Path)>,
) -> anyhow::Result<(String, String)> {
    if !rev.is_empty() {
        return Ok((rev.to_owned(), format!("given as --against {rev}")));
    }
    match baseline_commit {
        Some((commit, _)) if commit.is_empty() || commit == crate::study::environment::UNKNOWN => {
            bail!(
                "--against without a revision compares with the commit that recorded the \
                 baseline, but the baseline does not name one; give one, e.g. \
                 `--against origin/main`"
            )
        }
        Some((commit, dir)) => Ok((
            commit.to_owned(),
            format!("the commit that recorded the baseline in {}", dir.display()),
        )),
        None => bail!(
            "--against without a revision compares with the commit that recorded the \
             baseline, and there is no baseline; give one, e.g. `--against origin/main`"
        ),
    }
}

/// The full hash of the commit `rev` names in the repository at `repo`.
pub fn resolve(repo: &Path, rev: &str, reason: String) -> anyhow::Result<Rev> {
    let out = Command::new("git")
        .current_dir(repo)
        .args(["rev-parse", "--verify", "--quiet", "--end-of-options"])
        .arg(format!("{rev}^{{commit}}"))
        .output()
        .context("cannot run git; install it to check against another build")?;
    let commit = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    if !out.status.success() || commit.is_empty() {
        bail!(
            "`{rev}` ({reason}) names no commit of the repository in {}; give a commit, \
             branch or tag it holds (e.g. `--against HEAD~1`), or fetch it first",
            repo.display()
        );
    }
    Ok(Rev { commit, reason })
}

/// The top folder of the git checkout the check runs in.
pub fn repository() -> anyhow::Result<PathBuf> {
    let out = Command::new("git")
        .args(["rev-parse", "--show-toplevel"])
        .output()
        .context("cannot run git; install it to check against another build")?;
    if !out.status.success() {
        bail!(
            "`collide check --against` runs in a git checkout of collide; this folder is not in one"
        );
    }
    Ok(PathBuf::from(String::from_utf8_lossy(&out.stdout).trim()))
}

/// How this binary was built: the profile's folder in the target folder, and the cargo
/// arguments that build the same way.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ThisBuild {
    /// `<target>/<profile dir>`, e.g. `target/release`.
    pub profile_dir: PathBuf,
    pub cargo_args: Vec<String>,
}

/// This build's profile folder, from the binary's own path (`<target>/release/collide`)
/// or, when the binary was moved, from `CARGO_TARGET_DIR`; the cargo arguments of the
/// same profile and features.
pub fn this_build(
    exe: &Path,
    cargo_target_dir: Option<&Path>,
    environment: &Environment,
) -> anyhow::Result<ThisBuild> {
    let dir_name = match environment.profile.as_str() {
        "release" => "release",
        _ => "debug",
    };
    let looks_built = |dir: &Path| dir.join(".fingerprint").is_dir() && dir.join("deps").is_dir();
    let from_exe = exe
        .parent()
        .filter(|dir| dir.file_name().is_some_and(|name| name == dir_name) && looks_built(dir));
    let from_env = cargo_target_dir
        .map(|target| target.join(dir_name))
        .filter(|dir| looks_built(dir));
    let Some(profile_dir) = from_exe.map(Path::to_path_buf).or(from_env) else {
        bail!(
            "cannot find the cargo target folder this collide was built in: {} is not in a \
             `{dir_name}` folder of one, and CARGO_TARGET_DIR {}; run it from its target \
             folder (`cargo run --release --features mpi -- check --against ...`) or set \
             CARGO_TARGET_DIR",
            exe.display(),
            match cargo_target_dir {
                Some(dir) => format!("({}) holds no {dir_name} build", dir.display()),
                None => "is not set".to_owned(),
            }
        );
    };
    let mut cargo_args = vec!["build".to_owned(), "--bin".to_owned(), "collide".to_owned()];
    if dir_name == "release" {
        cargo_args.push("--release".to_owned());
    }
    if !environment.features.is_empty() {
        cargo_args.extend(["--features".to_owned(), environment.features.clone()]);
    }
    Ok(ThisBuild {
        profile_dir,
        cargo_args,
    })
}

/// The `collide` of `rev`, from the cache in `cache` or built now (and cached).
pub fn binary(
    repo: &Path,
    rev: &Rev,
    this: &ThisBuild,
    cache: &Path,
    quiet: bool,
) -> anyhow::Result<PathBuf> {
    let cached = cache.join(&rev.commit).join("collide");
    if cached.is_file() {
        if runs_simulate(&cached, rev).is_ok() {
            if !quiet {
                crate::outln!(
                    "against {}: the build cached in {}",
                    short(&rev.commit),
                    cached.display()
                );
            }
            return Ok(cached);
        }
        // A damaged cache (a truncated copy, a wrong file) is rebuilt, not trusted.
        eprintln!(
            "warning: the build cached in {} does not run; building {} again",
            cached.display(),
            short(&rev.commit)
        );
        std::fs::remove_file(&cached)
            .with_context(|| format!("cannot remove the damaged build {}", cached.display()))?;
    }
    std::fs::create_dir_all(cache)
        .with_context(|| format!("cannot create the build cache {}", cache.display()))?;
    let scratch = Scratch {
        repo: repo.to_owned(),
        worktree: cache.join(format!("worktree-{}", short(&rev.commit))),
        target: cache.join(format!("target-{}", short(&rev.commit))),
    };
    scratch.clear();
    let built = scratch.build(rev, this, quiet)?;
    let bytes =
        std::fs::read(&built).with_context(|| format!("cannot read {}", built.display()))?;
    std::fs::create_dir_all(cached.parent().expect("a file in a folder"))?;
    write_atomically(&cached, |out| out.write_all(&bytes))?;
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&cached, std::fs::Permissions::from_mode(0o755))?;
    drop(scratch);
    runs_simulate(&cached, rev).map(|()| cached)
}

/// The first 12 characters of a commit hash.
pub fn short(commit: &str) -> &str {
    &commit[..commit.len().min(12)]
}

/// A worktree of the commit and a copy of the target folder, removed when dropped.
struct Scratch {
    repo: PathBuf,
    worktree: PathBuf,
    target: PathBuf,
}

impl Scratch {
    fn build(&self, rev: &Rev, this: &ThisBuild, quiet: bool) -> anyhow::Result<PathBuf> {
        let commit = short(&rev.commit);
        run_quietly(
            Command::new("git")
                .current_dir(&self.repo)
                .args(["worktree", "add", "--detach", "--quiet"])
                .arg(&self.worktree)
                .arg(&rev.commit),
            &format!("cannot check out {commit} into {}", self.worktree.display()),
        )?;
        let profile = this.profile_dir.file_name().expect("a profile folder");
        copy_dependencies(&this.profile_dir, &self.target.join(profile))?;
        if !quiet {
            crate::outln!(
                "against {commit}: building with `cargo {}` in {}",
                this.cargo_args.join(" "),
                self.worktree.display()
            );
        }
        let cargo = std::env::var_os("CARGO").unwrap_or_else(|| OsString::from("cargo"));
        let mut command = Command::new(cargo);
        command
            .current_dir(&self.worktree)
            .args(&this.cargo_args)
            .arg("--quiet")
            .env("CARGO_TARGET_DIR", &self.target);
        run_quietly(
            &mut command,
            &format!("cannot build collide at {commit} ({})", rev.reason),
        )?;
        Ok(self.target.join(profile).join("collide"))
    }

    /// Removes the worktree (its folder and git's registration of it: only this one, never
    /// the user's other worktrees) and the copied target folder, if there.
    fn clear(&self) {
        if self.worktree.exists() {
            let _ = Command::new("git")
                .current_dir(&self.repo)
                .args(["worktree", "remove", "--force"])
                .arg(&self.worktree)
                .output();
            let _ = std::fs::remove_dir_all(&self.worktree);
        }
        forget_worktree(&self.repo, &self.worktree);
        let _ = std::fs::remove_dir_all(&self.target);
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        self.clear();
    }
}

/// Removes git's registration of the worktree at `path` if its folder is gone (what
/// `git worktree prune` does, for this one worktree only): the registration whose
/// `gitdir` file names `path/.git`.
fn forget_worktree(repo: &Path, path: &Path) {
    let Ok(out) = Command::new("git")
        .current_dir(repo)
        .args(["rev-parse", "--path-format=absolute", "--git-common-dir"])
        .output()
    else {
        return;
    };
    let common = PathBuf::from(String::from_utf8_lossy(&out.stdout).trim());
    let Ok(registrations) = std::fs::read_dir(common.join("worktrees")) else {
        return;
    };
    // git records the worktree's real path: its folder's, links resolved.
    let folder = path
        .parent()
        .and_then(|parent| std::fs::canonicalize(parent).ok());
    let (Some(folder), Some(name)) = (folder, path.file_name()) else {
        return;
    };
    let ours = folder.join(name);
    for registration in registrations.flatten().map(|entry| entry.path()) {
        let gitdir = std::fs::read_to_string(registration.join("gitdir")).unwrap_or_default();
        if Path::new(gitdir.trim()) == ours.join(".git") && !ours.exists() {
            let _ = std::fs::remove_dir_all(&registration);
        }
    }
}

/// Copies what cargo needs to find the dependencies built (`build/`, `.fingerprint/` and
/// the libraries in `deps/`, not collide's own binaries and tests, which are rebuilt) from
/// the profile folder `from` into `to`, with `cp -a --reflink=auto`: copies, not hard
/// links, because cargo rewrites fingerprints in place, and modification times kept,
/// because cargo compares them.
fn copy_dependencies(from: &Path, to: &Path) -> anyhow::Result<()> {
    let deps = to.join("deps");
    std::fs::create_dir_all(&deps).with_context(|| format!("cannot create {}", deps.display()))?;
    let what = format!("cannot copy the target folder {}", from.display());
    let mut libraries: Vec<PathBuf> = std::fs::read_dir(from.join("deps"))
        .with_context(|| what.clone())?
        .filter_map(|entry| entry.ok())
        .filter(|entry| {
            let name = entry.file_name().to_string_lossy().into_owned();
            name.starts_with("lib") && !name.starts_with("libcollide-")
        })
        .map(|entry| entry.path())
        .collect();
    libraries.sort();
    for chunk in libraries.chunks(500) {
        run_quietly(
            Command::new("cp")
                .args(["-a", "--reflink=auto"])
                .args(chunk)
                .arg(&deps),
            &what,
        )?;
    }
    run_quietly(
        Command::new("cp")
            .args(["-a", "--reflink=auto"])
            .arg(from.join("build"))
            .arg(from.join(".fingerprint"))
            .arg(to),
        &what,
    )
}

/// Runs `command`; on failure, an error that starts with `what` and quotes its output.
fn run_quietly(command: &mut Command, what: &str) -> anyhow::Result<()> {
    let out = command
        .output()
        .with_context(|| format!("{what}: cannot start {:?}", command.get_program()))?;
    if !out.status.success() {
        bail!(
            "{what} ({}){}",
            out.status,
            crate::system::process::tail("its output", &String::from_utf8_lossy(&out.stderr))
        );
    }
    Ok(())
}

/// Checks that the binary of `rev` runs `collide simulate --json`, all the check asks of it.
fn runs_simulate(exe: &Path, rev: &Rev) -> anyhow::Result<()> {
    let out = Command::new(exe).args(["simulate", "--help"]).output();
    match out {
        Ok(out)
            if out.status.success() && String::from_utf8_lossy(&out.stdout).contains("--json") =>
        {
            Ok(())
        }
        _ => bail!(
            "the build of {} ({}) in {} cannot run `collide simulate --json`, which the A/B \
             check needs of it; check against a later commit",
            short(&rev.commit),
            rev.reason,
            exe.display()
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_revision_is_the_baseline_commit_and_is_said_to_be() {
        let dir = Path::new("results/baseline");
        let (rev, reason) = choose("", Some(("fc38c564d214", dir))).unwrap();
        assert_eq!(rev, "fc38c564d214");
        assert!(reason.contains("baseline") && reason.contains("results/baseline"));
        assert_eq!(choose("HEAD~3", None).unwrap().0, "HEAD~3");
        for missing in [None, Some(("unknown", dir)), Some(("", dir))] {
            let err = choose("", missing).unwrap_err().to_string();
            assert!(err.contains("--against origin/main"), "{err}");
        }
    }

    #[test]
    fn a_revision_that_names_no_commit_is_an_error_in_words() {
        let repo = repository().expect("the tests run in a git checkout");
        let err = resolve(&repo, "no-such-branch-x", "given".to_owned())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("`no-such-branch-x`") && err.contains("names no commit"),
            "{err}"
        );
        let head = resolve(&repo, "HEAD", "given".to_owned()).unwrap();
        assert_eq!(head.commit.len(), 40);
    }

    #[test]
    fn the_target_folder_comes_from_the_binary_or_cargo_target_dir() {
        let environment = Environment::capture();
        let root = std::env::temp_dir().join(format!("collide-target-{}", std::process::id()));
        let profile = match environment.profile.as_str() {
            "release" => "release",
            _ => "debug",
        };
        let dir = root.join(profile);
        for sub in ["deps", ".fingerprint"] {
            std::fs::create_dir_all(dir.join(sub)).unwrap();
        }
        let build = this_build(&dir.join("collide"), None, &environment).unwrap();
        assert_eq!(build.profile_dir, dir);
        assert!(build.cargo_args.starts_with(&["build".to_owned()]));
        assert_eq!(
            build.cargo_args.contains(&"--release".to_owned()),
            profile == "release"
        );
        let moved = Path::new("/usr/local/bin/collide");
        assert_eq!(
            this_build(moved, Some(&root), &environment)
                .unwrap()
                .profile_dir,
            dir
        );
        let err = this_build(moved, None, &environment)
            .unwrap_err()
            .to_string();
        assert!(err.contains("CARGO_TARGET_DIR is not set"), "{err}");
        std::fs::remove_dir_all(&root).unwrap();
    }
}
