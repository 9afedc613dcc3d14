//! Work cut into pieces that a backend may run at once: how the core's passes take a
//! parallel backend's threads without knowing them.

use std::ops::Range;

/// Items per piece, at least, of a pass that streams through arrays (moving the disks,
/// rounding their positions, gathering them): enough to outweigh handing a piece out.
pub const MIN_STREAMING_PIECE: usize = 4096;

/// Runs a task on each of a set of items, perhaps several at once on other threads.
pub trait Pieces {
    /// How many threads the items are spread over (1: one after another).
    fn workers(&self) -> usize;

    /// Calls `task` once with each of `items`; returns when every call has returned.
    fn for_each<T: Send>(&self, items: &mut [T], task: impl Fn(&mut T) + Sync);

    /// `task` of each item, in the items' order ([`Pieces::for_each`]).
    fn map<T: Send, U: Send>(
        &self,
        items: impl IntoIterator<Item = T>,
        task: impl Fn(T) -> U + Sync,
    ) -> Vec<U> {
        let mut slots: Vec<Slot<T, U>> = items.into_iter().map(Slot::Input).collect();
        self.for_each(&mut slots, |slot| {
            if let Slot::Input(item) = std::mem::replace(slot, Slot::Taken) {
                *slot = Slot::Output(task(item));
            }
        });
        slots
            .into_iter()
            .map(|slot| match slot {
                Slot::Output(output) => output,
                _ => unreachable!("every item was mapped"),
            })
            .collect()
    }

    /// The length of the pieces [`Pieces::cut`] makes of `n` items: four pieces per
    /// worker, or fewer where pieces would be shorter than `min`, as many for every
    /// worker while there are enough (each thread's share is the same number of pieces);
    /// a whole number of `align` items; all `n` on one worker.
    fn piece_len(&self, n: usize, min: usize, align: usize) -> usize {
        let workers = self.workers();
        let len = if workers == 1 {
            n
        } else {
            let most = (n / min.max(1)).max(1);
            let pieces = if most >= 4 * workers {
                4 * workers
            } else if most >= workers {
                most - most % workers
            } else {
                most
            };
            n.div_ceil(pieces)
        };
        len.next_multiple_of(align).max(align)
    }

    /// Ranges that cut `0..n` into pieces of [`Pieces::piece_len`] (the last shorter).
    fn cut(&self, n: usize, min: usize, align: usize) -> Vec<Range<usize>> {
        let len = self.piece_len(n, min, align);
        (0..n)
            .step_by(len)
            .map(|start| start..(start + len).min(n))
            .collect()
    }
}

/// `values` cut into one slice per range of `ranges` (consecutive from 0, as
/// [`Pieces::cut`] gives them, covering `values`).
pub fn split_at_ranges<'a, T>(
    mut values: &'a mut [T],
    ranges: &[Range<usize>],
) -> Vec<&'a mut [T]> {
    debug_assert_eq!(ranges.last().map_or(0, |last| last.end), values.len());
    ranges
        .iter()
        .map(|range| {
            let (piece, after) = std::mem::take(&mut values).split_at_mut(range.len());
            values = after;
            piece
        })
        .collect()
}

/// An item of [`Pieces::map`]: before, during and after its task.
enum Slot<T, U> {
    Input(T),
    Taken,
    Output(U),
}

/// Every piece on the calling thread, one after another: the serial stepper's, and each
/// MPI rank's.
#[derive(Clone, Copy, Debug, Default)]
pub struct InTurn;

impl Pieces for InTurn {
    fn workers(&self) -> usize {
        1
    }

    fn for_each<T: Send>(&self, items: &mut [T], task: impl Fn(&mut T) + Sync) {
        items.iter_mut().for_each(task);
    }

    fn map<T: Send, U: Send>(
        &self,
        items: impl IntoIterator<Item = T>,
        task: impl Fn(T) -> U + Sync,
    ) -> Vec<U> {
        items.into_iter().map(task).collect()
    }
}

/// As if spread over `.0` workers, the pieces run one after another, the last first:
/// for tests that a pass gives in pieces what it gives in one, whatever their order.
#[cfg(test)]
#[derive(Clone, Copy, Debug)]
pub struct Backwards(pub usize);

#[cfg(test)]
impl Pieces for Backwards {
    fn workers(&self) -> usize {
        self.0
    }

    fn for_each<T: Send>(&self, items: &mut [T], task: impl Fn(&mut T) + Sync) {
        items.iter_mut().rev().for_each(task);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Where the minimum piece leaves fewer than four pieces per worker, the count is still
    /// a multiple of the workers: each thread's share is as long (20,000 disks over two
    /// threads made five pieces, shares of two and three, before).
    #[test]
    fn every_worker_gets_as_many_pieces() {
        let two = Backwards(2);
        for n in [8_192, 12_000, 20_000, 33_000, 40_000, 1_000_000] {
            let pieces = two.cut(n, MIN_STREAMING_PIECE, 64);
            assert_eq!(pieces.len() % 2, 0, "{n} items: {} pieces", pieces.len());
            let (first, last) = (&pieces[0], &pieces[pieces.len() - 1]);
            assert!(
                first.len() >= MIN_STREAMING_PIECE && last.end == n,
                "{n}: {pieces:?}"
            );
        }
        assert_eq!(two.cut(20_000, MIN_STREAMING_PIECE, 64).len(), 4);
        assert_eq!(two.cut(1_000_000, MIN_STREAMING_PIECE, 64).len(), 8);
        // Too few items for a piece each: one piece.
        assert_eq!(two.cut(5_000, MIN_STREAMING_PIECE, 64).len(), 1);
    }
}
