//! The collectives the distributed backend needs, behind a small trait: MPI
//! implements it (feature `mpi`), and so do threads in one process, which lets the
//! domain decomposition be tested on machines without MPI.

use std::sync::{Arc, Barrier, Mutex};

/// A group of ranks that exchange `f64` buffers. Every rank must call the same
/// collectives in the same order.
pub trait Communicator {
    fn rank(&self) -> usize;
    fn size(&self) -> usize;
    /// Sends `outgoing[r]` to rank `r` (one buffer per rank, maybe empty) and returns
    /// what every rank sent to this one, indexed by sender.
    fn exchange(&self, outgoing: &[Vec<f64>]) -> Vec<Vec<f64>>;
    /// Every rank's `data`, indexed by rank, on every rank.
    fn all_gather(&self, data: &[f64]) -> Vec<Vec<f64>>;
    /// Returns once every rank has called it.
    fn barrier(&self);
}

/// Ranks as threads of one process, meeting at a barrier: for tests and for machines
/// without MPI. Create all ranks with [`ThreadComm::group`], one per thread.
#[derive(Debug)]
pub struct ThreadComm {
    rank: usize,
    size: usize,
    shared: Arc<Shared>,
}

#[derive(Debug)]
struct Shared {
    barrier: Barrier,
    /// `mailbox[to][from]`: the buffer in flight from `from` to `to`.
    mailbox: Mutex<Vec<Vec<Vec<f64>>>>,
}

impl ThreadComm {
    /// The `size` ranks of a new group.
    pub fn group(size: usize) -> Vec<ThreadComm> {
        let shared = Arc::new(Shared {
            barrier: Barrier::new(size),
            mailbox: Mutex::new(vec![vec![Vec::new(); size]; size]),
        });
        (0..size)
            .map(|rank| ThreadComm {
                rank,
                size,
                shared: Arc::clone(&shared),
            })
            .collect()
    }

    fn mailbox(&self) -> std::sync::MutexGuard<'_, Vec<Vec<Vec<f64>>>> {
        // A rank that panicked poisons the lock; the test that made it panic fails anyway.
        self.shared
            .mailbox
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

impl Communicator for ThreadComm {
    fn rank(&self) -> usize {
        self.rank
    }

    fn size(&self) -> usize {
        self.size
    }

    fn exchange(&self, outgoing: &[Vec<f64>]) -> Vec<Vec<f64>> {
        {
            let mut mailbox = self.mailbox();
            for (to, buffer) in outgoing.iter().enumerate() {
                mailbox[to][self.rank] = buffer.clone();
            }
        }
        self.shared.barrier.wait();
        let incoming = std::mem::take(&mut self.mailbox()[self.rank]);
        self.mailbox()[self.rank] = vec![Vec::new(); incoming.len()];
        // Nobody writes the next round's buffers before everyone has taken this round's.
        self.shared.barrier.wait();
        incoming
    }

    fn all_gather(&self, data: &[f64]) -> Vec<Vec<f64>> {
        self.exchange(&vec![data.to_vec(); self.size])
    }

    fn barrier(&self) {
        self.shared.barrier.wait();
    }
}
