//! The machine and build a study ran on, captured once per study (Linux `/proc`, a
//! command or two, and what `build.rs` recorded of the build; anything unavailable is
//! recorded as "unknown").

use std::process::Command;

use crate::system::machine::{machine_cores, machine_memory_bytes, usable_cpus};

/// Facts recorded beside every measurement of a study.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Environment {
    pub hostname: String,
    pub cpu_model: String,
    pub logical_cores: usize,
    pub physical_cores: usize,
    /// The CPUs this process may run on (affinity and quota, see
    /// [`crate::system::machine::usable_cpus`]); 0 where not recorded (older baselines).
    #[serde(default)]
    pub usable_cpus: usize,
    /// The affinity mask as the kernel lists it (`Cpus_allowed_list`, e.g. `0-3`).
    #[serde(default)]
    pub cpu_affinity: String,
    pub memory_bytes: u64,
    pub os: String,
    /// The compiler that built this collide.
    pub rustc: String,
    /// "release" or "debug".
    pub profile: String,
    /// Cargo features compiled in, comma-separated ("" for none).
    pub features: String,
    /// The commit this collide was built from ("unknown" outside a git checkout), and
    /// whether its tracked files had uncommitted changes then (see `build.rs`).
    pub git_commit: String,
    pub git_dirty: bool,
    /// The MPI library's first `mpirun --version` line; "none" without the mpi feature.
    pub mpi_library: String,
    /// 1-minute load average when the study started.
    pub load_average_start: f64,
}

/// A field the system does not tell (a CPU model, a commit outside a git checkout).
pub const UNKNOWN: &str = "unknown";

impl Environment {
    pub fn capture() -> Environment {
        let cpuinfo = read("/proc/cpuinfo");
        let cpu_model = cpuinfo
            .lines()
            .find_map(|line| line.strip_prefix("model name"))
            .and_then(|rest| rest.split_once(':'))
            .map_or_else(|| UNKNOWN.to_owned(), |(_, model)| model.trim().to_owned());
        let features: Vec<&str> = [("mpi", cfg!(feature = "mpi"))]
            .into_iter()
            .filter_map(|(name, on)| on.then_some(name))
            .collect();
        Environment {
            hostname: first_line(&read("/proc/sys/kernel/hostname")),
            cpu_model,
            logical_cores: machine_cores(),
            physical_cores: physical_cores(&cpuinfo).unwrap_or_else(machine_cores),
            usable_cpus: usable_cpus(),
            cpu_affinity: crate::system::machine::allowed_cpu_list()
                .unwrap_or_else(|| UNKNOWN.to_owned()),
            memory_bytes: machine_memory_bytes().unwrap_or(0),
            os: os_name(),
            rustc: env!("COLLIDE_RUSTC_VERSION").to_owned(),
            profile: if cfg!(debug_assertions) {
                "debug"
            } else {
                "release"
            }
            .to_owned(),
            features: features.join(","),
            git_commit: env!("COLLIDE_GIT_COMMIT").to_owned(),
            git_dirty: env!("COLLIDE_GIT_DIRTY") == "true",
            mpi_library: if cfg!(feature = "mpi") {
                command_line("mpirun", &["--version"])
            } else {
                "none".to_owned()
            },
            load_average_start: load_average(),
        }
    }
}

/// The 1-minute load average now (NaN where unknown).
pub fn load_average() -> f64 {
    read("/proc/loadavg")
        .split_whitespace()
        .next()
        .and_then(|value| value.parse().ok())
        .unwrap_or(f64::NAN)
}

fn read(path: &str) -> String {
    std::fs::read_to_string(path).unwrap_or_default()
}

fn first_line(text: &str) -> String {
    let line = text.lines().next().unwrap_or("").trim();
    if line.is_empty() { UNKNOWN } else { line }.to_owned()
}

/// The first line a command prints, or "unknown" if it cannot run or fails.
fn command_line(program: &str, args: &[&str]) -> String {
    Command::new(program)
        .args(args)
        .output()
        .ok()
        .filter(|out| out.status.success())
        .map_or_else(
            || UNKNOWN.to_owned(),
            |out| first_line(&String::from_utf8_lossy(&out.stdout)),
        )
}

/// Distinct (physical id, core id) pairs in `/proc/cpuinfo`.
fn physical_cores(cpuinfo: &str) -> Option<usize> {
    let mut cores = std::collections::BTreeSet::new();
    for block in cpuinfo.split("\n\n") {
        let field = |name: &str| {
            block
                .lines()
                .find(|line| line.starts_with(name))
                .and_then(|line| line.split_once(':'))
                .map(|(_, value)| value.trim().to_owned())
        };
        if let Some(core) = field("core id") {
            cores.insert((field("physical id").unwrap_or_default(), core));
        }
    }
    (!cores.is_empty()).then_some(cores.len())
}

fn os_name() -> String {
    let release = read("/etc/os-release");
    let pretty = release
        .lines()
        .find_map(|line| line.strip_prefix("PRETTY_NAME="))
        .map(|name| name.trim_matches('"').to_owned())
        .unwrap_or_else(|| UNKNOWN.to_owned());
    format!(
        "{pretty}, Linux {}",
        first_line(&read("/proc/sys/kernel/osrelease"))
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpuinfo_is_read_as_the_kernel_writes_it() {
        let cpuinfo = "processor\t: 0\nphysical id\t: 0\ncore id\t: 0\n\n\
                       processor\t: 1\nphysical id\t: 0\ncore id\t: 0\n\n\
                       processor\t: 2\nphysical id\t: 0\ncore id\t: 1\n";
        assert_eq!(physical_cores(cpuinfo), Some(2));
    }
}
