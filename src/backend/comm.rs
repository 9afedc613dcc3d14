//! The collectives the distributed backend needs, behind a small trait: MPI
//! implements it (feature `mpi`), and so do threads in one process, which lets the
//! domain decomposition be tested on machines without MPI. [`Counting`] counts what a
//! rank sends through any of them, by one definition (the trait's docs).

use std::cell::Cell;
use std::sync::{Arc, Barrier, Mutex};

/// A group of ranks that exchange `f64` buffers. Every rank must call the same
/// collectives in the same order.
///
/// **What a rank sends**, as [`Counting`] counts it ([`Traffic`]): the messages and
/// bytes that MPI's linear algorithms send for the calls `MpiComm` (`backend::mpi`)
/// makes, whatever the implementation (threads move the same buffers through memory):
/// - [`exchange`](Communicator::exchange) is an all-to-all of the counts, then an
///   all-to-allv of the data: one message of [`COUNT_BYTES`] to every other rank, and
///   one message to every other rank whose buffer is non-empty, of 8 bytes a value;
/// - [`all_gather`](Communicator::all_gather) is an all-gather of the counts, then an
///   all-gatherv: the same as an exchange that sends `data` to every other rank;
/// - [`barrier`](Communicator::barrier) moves no data and sends nothing.
///
/// Nothing is sent to the rank itself, so one rank sends nothing at all. Each call is
/// one collective, whatever MPI calls it makes.
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

/// Bytes of one count in the counts round of an exchange or all-gather: an MPI count,
/// a C `int`.
pub const COUNT_BYTES: u64 = 4;

/// Bytes of one value of a buffer.
const VALUE_BYTES: u64 = size_of::<f64>() as u64;

/// What one rank sent, as the [`Communicator`] docs define it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Traffic {
    pub messages: u64,
    pub bytes: u64,
    pub exchanges: u64,
    pub all_gathers: u64,
    pub barriers: u64,
}

impl Traffic {
    /// The collectives called, of every kind.
    pub fn collectives(&self) -> u64 {
        self.exchanges + self.all_gathers + self.barriers
    }

    /// What was sent after `earlier`, a reading of the same counter.
    pub fn since(&self, earlier: &Traffic) -> Traffic {
        Traffic {
            messages: self.messages - earlier.messages,
            bytes: self.bytes - earlier.bytes,
            exchanges: self.exchanges - earlier.exchanges,
            all_gathers: self.all_gathers - earlier.all_gathers,
            barriers: self.barriers - earlier.barriers,
        }
    }

    /// Counts the messages of one collective that moves data: the counts round to every
    /// other rank, then a message for each non-empty buffer of `lengths` (values sent
    /// to each other rank).
    fn count_buffers(&mut self, n_others: usize, lengths: impl Iterator<Item = usize>) {
        self.messages += n_others as u64;
        self.bytes += n_others as u64 * COUNT_BYTES;
        for len in lengths.filter(|&len| len > 0) {
            self.messages += 1;
            self.bytes += len as u64 * VALUE_BYTES;
        }
    }
}

/// The [`Traffic`] of every rank of a run, reduced over the ranks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RankTraffic {
    /// Messages of the rank that sent most, and the mean over ranks.
    pub messages_max: u64,
    pub messages_mean: f64,
    /// Bytes of the rank that sent most, and the mean over ranks.
    pub bytes_max: u64,
    pub bytes_mean: f64,
    /// Collectives of each rank: every rank calls the same ones.
    pub collectives: u64,
}

impl RankTraffic {
    /// `ranks[r]`: what rank r sent. Sums are exact (integers), so the means do not
    /// depend on the order of the ranks.
    pub fn over(ranks: &[Traffic]) -> RankTraffic {
        debug_assert!(
            ranks
                .windows(2)
                .all(|w| w[0].collectives() == w[1].collectives()),
            "every rank calls the same collectives"
        );
        let n_ranks = ranks.len().max(1) as f64;
        let max = |field: fn(&Traffic) -> u64| ranks.iter().map(field).max().unwrap_or(0);
        let mean =
            |field: fn(&Traffic) -> u64| ranks.iter().map(field).sum::<u64>() as f64 / n_ranks;
        RankTraffic {
            messages_max: max(|t| t.messages),
            messages_mean: mean(|t| t.messages),
            bytes_max: max(|t| t.bytes),
            bytes_mean: mean(|t| t.bytes),
            collectives: max(Traffic::collectives),
        }
    }
}

/// A [`Communicator`] that counts what this rank sends through `inner` ([`Traffic`]).
#[derive(Debug)]
pub struct Counting<'a, C> {
    inner: &'a C,
    traffic: Cell<Traffic>,
}

impl<'a, C: Communicator> Counting<'a, C> {
    pub fn new(inner: &'a C) -> Counting<'a, C> {
        Counting {
            inner,
            traffic: Cell::new(Traffic::default()),
        }
    }

    /// What this rank sent so far.
    pub fn traffic(&self) -> Traffic {
        self.traffic.get()
    }

    fn count(&self, tally: impl FnOnce(&mut Traffic)) {
        let mut traffic = self.traffic.get();
        tally(&mut traffic);
        self.traffic.set(traffic);
    }
}

impl<C: Communicator> Communicator for Counting<'_, C> {
    fn rank(&self) -> usize {
        self.inner.rank()
    }

    fn size(&self) -> usize {
        self.inner.size()
    }

    fn exchange(&self, outgoing: &[Vec<f64>]) -> Vec<Vec<f64>> {
        let me = self.rank();
        self.count(|traffic| {
            traffic.exchanges += 1;
            let to_others = (outgoing.iter().enumerate())
                .filter(|&(to, _)| to != me)
                .map(|(_, buffer)| buffer.len());
            traffic.count_buffers(self.size() - 1, to_others);
        });
        self.inner.exchange(outgoing)
    }

    fn all_gather(&self, data: &[f64]) -> Vec<Vec<f64>> {
        let n_others = self.size() - 1;
        self.count(|traffic| {
            traffic.all_gathers += 1;
            traffic.count_buffers(n_others, std::iter::repeat_n(data.len(), n_others));
        });
        self.inner.all_gather(data)
    }

    fn barrier(&self) {
        self.count(|traffic| traffic.barriers += 1);
        self.inner.barrier();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs `body` on every rank of a [`ThreadComm`] group of `size`, counting; returns
    /// each rank's traffic.
    fn counted(size: usize, body: impl Fn(&Counting<'_, ThreadComm>) + Sync) -> Vec<Traffic> {
        std::thread::scope(|scope| {
            let handles: Vec<_> = ThreadComm::group(size)
                .into_iter()
                .map(|comm| {
                    let body = &body;
                    scope.spawn(move || {
                        let counting = Counting::new(&comm);
                        body(&counting);
                        counting.traffic()
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        })
    }

    #[test]
    fn an_exchange_counts_the_counts_round_and_each_non_empty_buffer_to_another_rank() {
        // Rank r sends r + 1 values to rank r + 1 and one value to itself.
        let traffic = counted(3, |comm| {
            let me = comm.rank();
            let mut outgoing = vec![Vec::new(); 3];
            outgoing[me] = vec![0.0];
            if me + 1 < 3 {
                outgoing[me + 1] = vec![1.0; me + 1];
            }
            let incoming = comm.exchange(&outgoing);
            assert_eq!(incoming[me], vec![0.0]);
        });
        let counts = 2 * COUNT_BYTES;
        assert_eq!(traffic[0].messages, 2 + 1);
        assert_eq!(traffic[0].bytes, counts + 8);
        assert_eq!(traffic[1].messages, 2 + 1);
        assert_eq!(traffic[1].bytes, counts + 16);
        assert_eq!(traffic[2].messages, 2);
        assert_eq!(traffic[2].bytes, counts);
        assert!(
            traffic
                .iter()
                .all(|t| t.exchanges == 1 && t.collectives() == 1)
        );
    }

    #[test]
    fn an_all_gather_sends_the_data_to_every_other_rank_and_a_barrier_nothing() {
        let traffic = counted(4, |comm| {
            comm.all_gather(&vec![1.0; comm.rank()]);
            comm.barrier();
        });
        for (rank, t) in traffic.iter().enumerate() {
            let data_messages = if rank == 0 { 0 } else { 3 };
            assert_eq!(t.messages, 3 + data_messages, "rank {rank}");
            assert_eq!(
                t.bytes,
                3 * COUNT_BYTES + 3 * 8 * rank as u64,
                "rank {rank}"
            );
            assert_eq!((t.all_gathers, t.barriers, t.collectives()), (1, 1, 2));
        }
    }

    #[test]
    fn one_rank_sends_nothing() {
        let traffic = counted(1, |comm| {
            comm.exchange(&[vec![1.0; 5]]);
            comm.all_gather(&[1.0; 5]);
        });
        assert_eq!((traffic[0].messages, traffic[0].bytes), (0, 0));
        assert_eq!(traffic[0].collectives(), 2);
    }
}
