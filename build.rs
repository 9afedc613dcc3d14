//! Records the compiler that builds collide (`COLLIDE_RUSTC_VERSION`), so study
//! records name the toolchain of the binary that ran, not whichever rustc is on the PATH.

use std::process::Command;

fn main() {
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-env-changed=RUSTC");
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".to_owned());
    let version = Command::new(rustc)
        .arg("--version")
        .output()
        .ok()
        .filter(|out| out.status.success())
        .map_or_else(
            || "unknown".to_owned(),
            |out| String::from_utf8_lossy(&out.stdout).trim().to_owned(),
        );
    println!("cargo::rustc-env=COLLIDE_RUSTC_VERSION={version}");
}
