//! The backends a run can ask for, by kind: their names (on the command line, in
//! manifests, in the JSON summary and the records) and how a run's workers split into
//! threads and MPI ranks. Declared here once; every layer derives its strings and its
//! thread and rank counts from it.

use clap::ValueEnum;

/// Which backend runs the steps. The order is the order of tables and figures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, ValueEnum)]
pub enum BackendKind {
    // One thread: the reference every other backend reproduces bit for bit.
    Serial,
    // A rayon pool of threads in one process.
    Rayon,
    // MPI ranks, one thread each.
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

    /// How `workers` split into (threads per process, processes).
    pub fn split(self, workers: usize) -> (usize, usize) {
        match self {
            BackendKind::Serial => (1, 1),
            BackendKind::Rayon => (workers, 1),
            BackendKind::Mpi => (1, workers),
        }
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

#[cfg(test)]
mod tests {
    use super::BackendKind;

    #[test]
    fn names_round_trip_and_workers_split_by_kind() {
        for kind in BackendKind::ALL {
            assert_eq!(BackendKind::from_name(kind.name()), Some(kind));
            let (threads, ranks) = kind.split(4);
            assert_eq!(
                threads * ranks,
                if kind == BackendKind::Serial { 1 } else { 4 }
            );
        }
        assert_eq!(BackendKind::from_name("cuda"), None);
        assert_eq!(BackendKind::rank_of("mpi"), 2);
    }
}
