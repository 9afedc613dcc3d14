//! The backends a run can ask for, by kind: their names (on the command line, in
//! manifests, in the JSON summary and the records), what each can run and needs
//! ([`Capabilities`]), and where a run's workers go ([`Placement`]: ranks × threads).
//! Declared here once; every layer derives its strings, its checks and its thread and
//! rank counts from it.

use clap::ValueEnum;

/// Which backend runs the steps. The order is the order of tables and figures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, ValueEnum)]
pub enum BackendKind {
    // One thread: the reference every other backend reproduces bit for bit.
    Serial,
    // A rayon pool of threads in one process.
    Rayon,
    // MPI ranks, each stepping on one thread or on a team of them (`--threads`).
    Mpi,
}

impl BackendKind {
    /// Every kind, in table order.
    pub const ALL: [BackendKind; 3] = [BackendKind::Serial, BackendKind::Rayon, BackendKind::Mpi];

    /// The name users write and records keep.
    pub fn name(self) -> &'static str {
        match self {
            BackendKind::Serial => "serial",
            BackendKind::Rayon => "rayon",
            BackendKind::Mpi => "mpi",
        }
    }

    /// The kind of a recorded backend name; `None` for a name no collide wrote.
    pub fn from_name(name: &str) -> Option<BackendKind> {
        BackendKind::ALL
            .into_iter()
            .find(|kind| kind.name() == name)
    }

    /// Where `workers` go on this backend: each backend today puts them on one axis.
    pub fn placement(self, workers: usize) -> Placement {
        match self {
            BackendKind::Serial => Placement::SERIAL,
            BackendKind::Rayon => Placement {
                ranks: 1,
                threads: workers,
            },
            BackendKind::Mpi => Placement {
                ranks: workers,
                threads: 1,
            },
        }
    }

    /// The counts a run placed as `placement` is asked for with: the one its
    /// [`BackendKind::workers_flag`] sets (rayon's threads, MPI's ranks; 1 for serial),
    /// and the threads each rank steps on beyond it (`--threads` of MPI ranks; else 1).
    /// The inverse of [`BackendKind::placement`] on the backend's axis.
    pub fn counts_of(self, placement: Placement) -> (usize, usize) {
        match self {
            BackendKind::Serial => (1, 1),
            BackendKind::Rayon => (placement.threads, 1),
            BackendKind::Mpi => (placement.ranks, placement.threads),
        }
    }

    /// What this backend can run and what it needs.
    pub fn capabilities(self) -> Capabilities {
        match self {
            BackendKind::Serial => Capabilities {
                event_method: true,
                draws: true,
                scene_in_every_process: false,
                mpi: false,
            },
            BackendKind::Rayon => Capabilities {
                event_method: false,
                draws: true,
                scene_in_every_process: false,
                mpi: false,
            },
            BackendKind::Mpi => Capabilities {
                event_method: false,
                draws: false,
                scene_in_every_process: true,
                mpi: true,
            },
        }
    }

    /// Whether this build can run it: MPI needs the `mpi` cargo feature.
    pub fn is_available(self) -> bool {
        !self.capabilities().mpi || cfg!(feature = "mpi")
    }

    /// Whether its runs are parallel: more than one worker is possible.
    pub fn is_parallel(self) -> bool {
        self.workers_flag().is_some()
    }

    /// The `collide simulate` flag that sets the worker count (serial has none).
    pub fn workers_flag(self) -> Option<&'static str> {
        match self {
            BackendKind::Serial => None,
            BackendKind::Rayon => Some("--threads"),
            BackendKind::Mpi => Some("--ranks"),
        }
    }

    /// Position in [`BackendKind::ALL`]: tables sort and figures colour by it; names no
    /// collide wrote come last.
    pub fn rank_of(name: &str) -> usize {
        BackendKind::from_name(name).map_or(BackendKind::ALL.len(), |kind| kind as usize)
    }
}

/// What a backend can run and what it needs: the questions every layer asks of a kind,
/// answered once per kind in [`BackendKind::capabilities`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Capabilities {
    /// Runs the event method, which steps in one thread of one process.
    pub event_method: bool,
    /// Holds every disk in one process, so it can draw every step (`draw`).
    pub draws: bool,
    /// Its processes may each place and hold the whole scene (a scene that is not placed
    /// in parts: [`crate::run::spec::RunSpec::whole_scene_copies`]).
    pub scene_in_every_process: bool,
    /// Its processes are started by an MPI launcher: it needs the `mpi` cargo feature.
    pub mpi: bool,
}

/// The MPI launcher: it starts a backend's ranks (`-n RANKS`, the program and its
/// arguments follow) where [`Capabilities::mpi`], unless `--launcher` (or
/// `COLLIDE_MPI_LAUNCHER`) names another for `collide simulate`.
pub const MPI_LAUNCHER: &str = "mpirun";

/// Where a run's work goes: `ranks` processes, each stepping on `threads` threads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Placement {
    pub ranks: usize,
    pub threads: usize,
}

impl Placement {
    /// One process of one thread.
    pub const SERIAL: Placement = Placement {
        ranks: 1,
        threads: 1,
    };

    /// The workers a scaling curve counts: ranks × threads.
    pub fn workers(self) -> usize {
        self.ranks * self.threads
    }
}

impl std::fmt::Display for Placement {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} rank(s) × {} thread(s)", self.ranks, self.threads)
    }
}

#[cfg(test)]
mod tests {
    use super::BackendKind;

    #[test]
    fn names_round_trip_and_workers_are_placed_by_kind() {
        for kind in BackendKind::ALL {
            assert_eq!(BackendKind::from_name(kind.name()), Some(kind));
            let placement = kind.placement(4);
            assert_eq!(placement.workers(), if kind.is_parallel() { 4 } else { 1 });
            // Only MPI places ranks, and only it needs the feature.
            assert_eq!(placement.ranks > 1, kind.capabilities().mpi);
        }
        assert_eq!(BackendKind::from_name("cuda"), None);
        assert_eq!(BackendKind::rank_of("mpi"), 2);
    }
}
