//! What a run may ask of this machine, checked before anything runs: memory for its
//! disks ([`crate::run::spec::Footprint`]) and a ceiling on workers per usable CPU. The
//! checks are pure functions of a [`Machine`], so that tests can pose any machine.

use crate::run::spec::Footprint;

/// Above this many workers (threads or ranks) per CPU this process may use, a run is
/// refused unless the user insists (`--oversubscribe`, or `oversubscribe = true` in a
/// manifest's `[backends]`): beyond it a run measures the scheduler, not the simulation.
pub const MAX_WORKERS_PER_CPU: usize = 8;

/// Placement estimated to take longer than this many seconds is announced first.
pub const LONG_PLACEMENT_S: f64 = 10.0;

/// The resources runs are checked against.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Machine {
    /// CPUs this process may run on (its affinity mask and quota).
    pub usable_cpus: usize,
    /// Memory this process may use: the machine's, or its control group's limit if
    /// lower; 0 when unknown (nothing is then refused for memory).
    pub memory_bytes: u64,
}

impl Machine {
    /// This machine, as the kernel reports it.
    pub fn this() -> Machine {
        let total = crate::system::machine::machine_memory_bytes().unwrap_or(0);
        let memory_bytes = crate::system::machine::memory_limit_bytes()
            .filter(|&limit| total == 0 || limit < total)
            .unwrap_or(total);
        Machine {
            usable_cpus: crate::system::machine::usable_cpus(),
            memory_bytes,
        }
    }

    /// The most workers a run may use without insisting.
    pub fn max_workers(&self) -> usize {
        MAX_WORKERS_PER_CPU * self.usable_cpus.max(1)
    }
}

/// How a worker count was given, for the message that refuses it.
#[derive(Clone, Copy, Debug)]
pub struct WorkerSource<'a> {
    /// The flag or field, e.g. "--threads" or "`backends.rayon`".
    pub field: &'a str,
    /// How to insist, e.g. "add --oversubscribe".
    pub insist: &'a str,
}

/// `Ok` when `workers` is within [`MAX_WORKERS_PER_CPU`] per usable CPU (or the user
/// insists); otherwise what was wrong and the two ways out.
pub fn check_workers(
    workers: usize,
    machine: &Machine,
    insist: bool,
    source: WorkerSource<'_>,
) -> Result<(), String> {
    let ceiling = machine.max_workers();
    if insist || workers <= ceiling {
        return Ok(());
    }
    Err(format!(
        "{} asks for {workers} workers, more than {MAX_WORKERS_PER_CPU} per CPU this \
         process may use ({} here: at most {ceiling}), where a run measures the scheduler \
         rather than the simulation; lower the count, or {} to run it anyway",
        source.field, machine.usable_cpus, source.insist
    ))
}

/// `Ok` when the run's estimated peak memory fits the machine; otherwise the estimate,
/// the machine's memory and the largest n that fits.
pub fn check_memory(footprint: &Footprint, machine: &Machine) -> Result<(), String> {
    if machine.memory_bytes == 0 || footprint.bytes <= machine.memory_bytes {
        return Ok(());
    }
    let per_copy = machine.memory_bytes / footprint.copies;
    let fits = per_copy.saturating_sub(crate::run::spec::BASE_BYTES) / footprint.bytes_per_disk;
    // Two significant digits: an estimate is not exact to the disk.
    let scale = 10u64.pow(fits.max(1).ilog10().saturating_sub(1));
    let fits = fits / scale * scale;
    let copies = if footprint.copies > 1 {
        format!(" in each of its {} MPI ranks", footprint.copies)
    } else {
        String::new()
    };
    Err(format!(
        "n = {} disks need about {} of memory ({} B per disk{copies}), but this machine has {}; \
         lower n to at most about {fits}{}",
        footprint.n_particles,
        bytes_text(footprint.bytes),
        footprint.bytes_per_disk,
        bytes_text(machine.memory_bytes),
        if footprint.copies > 1 {
            " or use fewer ranks"
        } else {
            ""
        }
    ))
}

/// A note saying how long placement will take, when that is over [`LONG_PLACEMENT_S`].
pub fn placement_note(footprint: &Footprint) -> Option<String> {
    (footprint.placement_s > LONG_PLACEMENT_S).then(|| {
        format!(
            "note: placing {} disks will take about {} before the run starts",
            footprint.n_particles,
            duration_text(footprint.placement_s)
        )
    })
}

/// Bytes in the largest unit that keeps a number of at least 1 (decimal units).
fn bytes_text(bytes: u64) -> String {
    let bytes = bytes as f64;
    match bytes {
        b if b >= 1e12 => format!("{:.1} TB", b / 1e12),
        b if b >= 1e9 => format!("{:.1} GB", b / 1e9),
        b => format!("{:.0} MB", b / 1e6),
    }
}

fn duration_text(seconds: f64) -> String {
    match seconds {
        s if s >= 5400.0 => format!("{:.1} h", s / 3600.0),
        s if s >= 90.0 => format!("{:.0} min", s / 60.0),
        s => format!("{s:.0} s"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::spec::{BASE_BYTES, EVENT_BYTES_PER_DISK, STEP_BYTES_PER_DISK};

    const LAPTOP: Machine = Machine {
        usable_cpus: 2,
        memory_bytes: 24_000_000_000,
    };

    fn footprint(n_particles: u64, copies: u64, bytes_per_disk: u64) -> Footprint {
        Footprint {
            n_particles,
            steps: 100,
            copies,
            bytes_per_disk,
            bytes: (n_particles * bytes_per_disk + BASE_BYTES) * copies,
            placement_s: n_particles as f64 * 1e-6,
        }
    }

    #[test]
    fn worker_counts_above_the_ceiling_need_insisting() {
        let source = WorkerSource {
            field: "--threads",
            insist: "add --oversubscribe",
        };
        assert_eq!(check_workers(16, &LAPTOP, false, source), Ok(()));
        let err = check_workers(17, &LAPTOP, false, source).unwrap_err();
        assert!(
            err.starts_with("--threads asks for 17 workers")
                && err.contains("at most 16")
                && err.contains("add --oversubscribe"),
            "{err}"
        );
        assert_eq!(check_workers(10_000, &LAPTOP, true, source), Ok(()));
    }

    #[test]
    fn memory_that_cannot_fit_is_refused_with_the_estimate_and_the_machine() {
        assert_eq!(
            check_memory(&footprint(1_000_000, 1, STEP_BYTES_PER_DISK), &LAPTOP),
            Ok(())
        );
        let err =
            check_memory(&footprint(1_000_000_000, 1, EVENT_BYTES_PER_DISK), &LAPTOP).unwrap_err();
        assert!(
            err.contains("368.0 GB")
                && err.contains("24.0 GB")
                && err.contains("at most about 65000000"),
            "{err}"
        );
        // Every rank of an MPI run holds all disks: 16 ranks of 10⁷ disks do not fit.
        let err =
            check_memory(&footprint(10_000_000, 16, STEP_BYTES_PER_DISK), &LAPTOP).unwrap_err();
        assert!(
            err.contains("16 MPI ranks") && err.contains("fewer ranks"),
            "{err}"
        );
        let unknown = Machine {
            memory_bytes: 0,
            ..LAPTOP
        };
        assert_eq!(
            check_memory(&footprint(u64::MAX / 1024, 1, 368), &unknown),
            Ok(())
        );
    }

    #[test]
    fn long_placements_are_announced() {
        assert_eq!(placement_note(&footprint(1_000_000, 1, 256)), None);
        let note = placement_note(&footprint(600_000_000, 1, 256)).unwrap();
        assert!(
            note.contains("600000000 disks") && note.contains("10 min"),
            "{note}"
        );
    }
}
