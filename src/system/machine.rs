//! What this machine offers a run: its logical CPUs, the CPUs this process may use,
//! its memory and its limit, and the CPU-time clocks (Linux `/proc` and `/sys`, and
//! `clock_gettime`). Backends, the limits checked before a run and the study's
//! environment all ask here.

use std::num::NonZeroUsize;
use std::time::Instant;

/// Whose CPU time a backend's stepping loop counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CpuScope {
    /// The calling thread (serial; one rank, whose ranks' times are then summed).
    Thread,
    /// Every thread of this process (the rayon pool).
    Process,
}

/// Wall and CPU seconds of a stretch of work (a stepping loop, the calibration workload).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopSeconds {
    pub wall: f64,
    /// CPU seconds of the threads in `scope` (`None` where unknown).
    pub cpu: Option<f64>,
}

/// CPU seconds run so far by this thread or process (`clock_gettime`'s CPU-time clocks,
/// exact to the nanosecond; time spent waiting for a CPU is not counted). `None` where
/// the system does not provide them.
pub fn cpu_seconds(scope: CpuScope) -> Option<f64> {
    let clock = match scope {
        CpuScope::Thread => libc::CLOCK_THREAD_CPUTIME_ID,
        CpuScope::Process => libc::CLOCK_PROCESS_CPUTIME_ID,
    };
    let mut now = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `now` is a valid, writable timespec for the duration of the call.
    let status = unsafe { libc::clock_gettime(clock, &mut now) };
    (status == 0).then_some(now.tv_sec as f64 + now.tv_nsec as f64 * 1e-9)
}

/// Logical CPUs online on this machine, whatever this process is bound to (an MPI rank
/// bound to one core still counts them all); the affinity-aware count as a fallback.
pub fn machine_cores() -> usize {
    let online = std::fs::read_to_string("/sys/devices/system/cpu/online").ok();
    online
        .as_deref()
        .and_then(count_cpu_list)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, NonZeroUsize::get))
}

/// Names the variable through which an MPI launch passes its [`usable_cpus`] to the
/// ranks it starts (each may be bound to a single core).
pub const USABLE_CPUS_ENV: &str = "COLLIDE_USABLE_CPUS";

/// The CPUs this process may run on: its affinity mask and CPU quota (`taskset`, a
/// batch scheduler's cpuset, a container's limit), as the standard library counts them.
/// Worker defaults and the oversubscription verdict follow it. An MPI rank takes the
/// count of the process that launched the ranks, from [`USABLE_CPUS_ENV`], never more
/// than the machine's CPUs (a variable set by hand cannot hide oversubscription).
pub fn usable_cpus() -> usize {
    std::env::var(USABLE_CPUS_ENV)
        .ok()
        .and_then(|count| count.parse::<usize>().ok())
        .filter(|&count| count > 0)
        .map(|count| count.min(machine_cores()))
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, NonZeroUsize::get))
}

/// The CPUs this process may run on as the kernel lists them (`Cpus_allowed_list` of
/// /proc/self/status, e.g. `0-3,8`), if known.
pub fn allowed_cpu_list() -> Option<String> {
    std::fs::read_to_string("/proc/self/status")
        .ok()?
        .lines()
        .find_map(|line| line.strip_prefix("Cpus_allowed_list:"))
        .map(|list| list.trim().to_owned())
}

/// Counts the CPUs in a kernel CPU list such as `0-3,8,10-11`.
fn count_cpu_list(list: &str) -> Option<usize> {
    let mut count = 0;
    for range in list.trim().split(',') {
        count += match range.split_once('-') {
            Some((first, last)) => last.parse::<usize>().ok()? + 1 - first.parse::<usize>().ok()?,
            None => range.parse::<usize>().map(|_| 1).ok()?,
        };
    }
    Some(count)
}

/// The machine's memory (`MemTotal`), if known.
pub fn machine_memory_bytes() -> Option<u64> {
    memory_bytes(&std::fs::read_to_string("/proc/meminfo").unwrap_or_default())
}

/// The memory limit of this process's control group (cgroup v2 `memory.max`), if any.
pub fn memory_limit_bytes() -> Option<u64> {
    std::fs::read_to_string("/sys/fs/cgroup/memory.max")
        .unwrap_or_default()
        .trim()
        .parse()
        .ok()
}

fn memory_bytes(meminfo: &str) -> Option<u64> {
    let line = meminfo.lines().find(|line| line.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Runs `work` and adds its wall time to `seconds`.
#[inline]
pub fn timed<T>(seconds: &mut f64, work: impl FnOnce() -> T) -> T {
    let start = Instant::now();
    let result = work();
    *seconds += start.elapsed().as_secs_f64();
    result
}

#[cfg(test)]
mod tests {
    #[test]
    fn cpu_lists_count_ranges_and_singles() {
        assert_eq!(super::count_cpu_list("0-1\n"), Some(2));
        assert_eq!(super::count_cpu_list("0-3,8,10-11"), Some(7));
        assert_eq!(super::count_cpu_list("garbage"), None);
    }

    #[test]
    fn meminfo_is_read_as_the_kernel_writes_it() {
        assert_eq!(
            super::memory_bytes("MemTotal:       24576 kB\nMemFree: 1 kB\n"),
            Some(24576 * 1024)
        );
    }
}
