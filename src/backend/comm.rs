//! The collectives the distributed backend needs, behind a small trait: MPI
//! implements it (feature `mpi`), and so do threads in one process, which lets the
//! domain decomposition be tested on machines without MPI. [`Counting`] counts what a
//! rank sends through any of them, by one definition (the trait's docs).

use std::cell::Cell;
use std::collections::VecDeque;
use std::sync::{Arc, Barrier, Condvar, Mutex};

/// A group of ranks that exchange `f64` buffers. Every rank must call the same
/// collectives in the same order; point-to-point calls pair up between the ranks they
/// name.
///
/// **What a rank sends**, as [`Counting`] counts it ([`Traffic`]): the messages and
/// bytes that MPI's algorithms send for the calls `MpiComm` (`backend::mpi`) makes,
/// whatever the implementation (threads move the same buffers through memory):
/// - [`exchange`](Communicator::exchange) is an all-to-all of the counts, then an
///   all-to-allv of the data: one message of [`COUNT_BYTES`] to every other rank, and
///   one message to every other rank whose buffer is non-empty, of 8 bytes a value;
/// - [`all_gather`](Communicator::all_gather) is an all-gather of the counts, then an
///   all-gatherv: the same as an exchange that sends `data` to every other rank;
/// - [`max_all`](Communicator::max_all) is an all-reduce by recursive doubling: one
///   message of the values to each of ⌈log₂ P⌉ other ranks;
/// - [`barrier`](Communicator::barrier) moves no data and sends nothing;
/// - [`send_receive`](Communicator::send_receive) is not a collective: one message to
///   each rank it sends to, even an empty one, of 8 bytes a value.
///
/// Nothing is sent to the rank itself, so one rank sends nothing at all. Each call of
/// the first four is one collective, whatever MPI calls it makes.
pub trait Communicator {
    fn rank(&self) -> usize;
    fn size(&self) -> usize;
    /// Sends `outgoing[r]` to rank `r` (one buffer per rank, maybe empty) and returns
    /// what every rank sent to this one, indexed by sender.
    fn exchange(&self, outgoing: &[Vec<f64>]) -> Vec<Vec<f64>>;
    /// Every rank's `data`, indexed by rank, on every rank.
    fn all_gather(&self, data: &[f64]) -> Vec<Vec<f64>>;
    /// The largest of each entry of `values` over the ranks, on every rank (every rank
    /// passes as many values).
    fn max_all(&self, values: &[f64]) -> Vec<f64>;
    /// Returns once every rank has called it.
    fn barrier(&self);
    /// Sends each buffer of `sends` to its rank and returns one buffer from each rank of
    /// `from`, in that order. Only the ranks named take part, and they must pair up: a
    /// rank sends to another exactly when that one receives from it in its own call.
    /// Ranks are named once each, never this rank.
    fn send_receive(&self, sends: &[(usize, &[f64])], from: &[usize]) -> Vec<Vec<f64>>;
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
    /// `posts[to][from]`: the point-to-point buffers in flight from `from` to `to`, in
    /// the order sent, and a signal for their receivers.
    posts: Mutex<Vec<Vec<VecDeque<Vec<f64>>>>>,
    posted: Condvar,
}

impl ThreadComm {
    /// Runs `rank` on each of the `size` ranks of a new group, each on a thread of its
    /// own, all at once; returns what each returned, in rank order. A panic on a rank is
    /// raised again here.
    pub fn run_group<R: Send>(size: usize, rank: impl Fn(ThreadComm) -> R + Sync) -> Vec<R> {
        let rank = &rank;
        std::thread::scope(|scope| {
            let handles: Vec<_> = (ThreadComm::group(size).into_iter())
                .map(|comm| scope.spawn(move || rank(comm)))
                .collect();
            (handles.into_iter())
                .map(|handle| {
                    handle
                        .join()
                        .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
                })
                .collect()
        })
    }

    /// The `size` ranks of a new group.
    pub fn group(size: usize) -> Vec<ThreadComm> {
        let shared = Arc::new(Shared {
            barrier: Barrier::new(size),
            mailbox: Mutex::new(vec![vec![Vec::new(); size]; size]),
            posts: Mutex::new(vec![vec![VecDeque::new(); size]; size]),
            posted: Condvar::new(),
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

    fn max_all(&self, values: &[f64]) -> Vec<f64> {
        let mut largest = values.to_vec();
        for other in self.all_gather(values) {
            for (value, theirs) in largest.iter_mut().zip(other) {
                *value = value.max(theirs);
            }
        }
        largest
    }

    fn barrier(&self) {
        self.shared.barrier.wait();
    }

    fn send_receive(&self, sends: &[(usize, &[f64])], from: &[usize]) -> Vec<Vec<f64>> {
        let lock = || (self.shared.posts.lock()).unwrap_or_else(|poisoned| poisoned.into_inner());
        {
            let mut posts = lock();
            for &(to, buffer) in sends {
                posts[to][self.rank].push_back(buffer.to_vec());
            }
        }
        self.shared.posted.notify_all();
        let mut posts = lock();
        let mut received = Vec::with_capacity(from.len());
        for &sender in from {
            loop {
                if let Some(buffer) = posts[self.rank][sender].pop_front() {
                    received.push(buffer);
                    break;
                }
                posts = (self.shared.posted.wait(posts))
                    .unwrap_or_else(|poisoned| poisoned.into_inner());
            }
        }
        received
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
    /// Collectives called, of every kind.
    pub collectives: u64,
}

impl Traffic {
    /// What was sent after `earlier`, a reading of the same counter.
    pub fn since(&self, earlier: &Traffic) -> Traffic {
        Traffic {
            messages: self.messages - earlier.messages,
            bytes: self.bytes - earlier.bytes,
            collectives: self.collectives - earlier.collectives,
        }
    }

    /// Counts a message of `len` values.
    fn count_message(&mut self, len: usize) {
        self.messages += 1;
        self.bytes += len as u64 * VALUE_BYTES;
    }

    /// Counts the messages of one collective that moves data: the counts round to every
    /// other rank, then a message for each non-empty buffer of `lengths` (values sent
    /// to each other rank).
    fn count_buffers(&mut self, n_others: usize, lengths: impl Iterator<Item = usize>) {
        self.collectives += 1;
        self.messages += n_others as u64;
        self.bytes += n_others as u64 * COUNT_BYTES;
        for len in lengths.filter(|&len| len > 0) {
            self.count_message(len);
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
                .all(|w| w[0].collectives == w[1].collectives),
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
            collectives: max(|t| t.collectives),
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
            traffic.count_buffers(n_others, std::iter::repeat_n(data.len(), n_others));
        });
        self.inner.all_gather(data)
    }

    fn max_all(&self, values: &[f64]) -> Vec<f64> {
        let partners = (self.size() as u64).next_power_of_two().trailing_zeros();
        self.count(|traffic| {
            traffic.collectives += 1;
            for _ in 0..partners {
                traffic.count_message(values.len());
            }
        });
        self.inner.max_all(values)
    }

    fn barrier(&self) {
        self.count(|traffic| traffic.collectives += 1);
        self.inner.barrier();
    }

    fn send_receive(&self, sends: &[(usize, &[f64])], from: &[usize]) -> Vec<Vec<f64>> {
        self.count(|traffic| {
            for (_, buffer) in sends {
                traffic.count_message(buffer.len());
            }
        });
        self.inner.send_receive(sends, from)
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
        assert!(traffic.iter().all(|t| t.collectives == 1));
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
            assert_eq!(t.collectives, 2);
        }
    }

    #[test]
    fn one_rank_sends_nothing() {
        let traffic = counted(1, |comm| {
            comm.exchange(&[vec![1.0; 5]]);
            comm.all_gather(&[1.0; 5]);
        });
        assert_eq!((traffic[0].messages, traffic[0].bytes), (0, 0));
        assert_eq!(traffic[0].collectives, 2);
    }

    /// Ranks in a ring each send to the next and receive from the one before, twice, so
    /// that a fast rank's second message waits in line behind its first.
    #[test]
    fn point_to_point_buffers_arrive_in_the_order_sent_and_count_one_message_each() {
        let traffic = counted(3, |comm| {
            let me = comm.rank();
            let (next, previous) = ((me + 1) % 3, (me + 2) % 3);
            for round in 0..2 {
                let mine = vec![(10 * me + round) as f64; me];
                let got = comm.send_receive(&[(next, &mine)], &[previous]);
                assert_eq!(got, vec![vec![(10 * previous + round) as f64; previous]]);
            }
        });
        for (rank, t) in traffic.iter().enumerate() {
            assert_eq!(
                (t.messages, t.bytes),
                (2, 2 * 8 * rank as u64),
                "rank {rank}"
            );
            assert_eq!(t.collectives, 0, "not a collective");
        }
    }

    #[test]
    fn max_all_gives_every_rank_the_largest_of_each_entry_in_log2_p_messages() {
        let traffic = counted(5, |comm| {
            let me = comm.rank() as f64;
            assert_eq!(comm.max_all(&[me, -me]), vec![4.0, 0.0]);
        });
        for t in &traffic {
            assert_eq!((t.messages, t.bytes, t.collectives), (3, 3 * 16, 1));
        }
    }
}
