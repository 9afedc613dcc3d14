//! Work cut into pieces that a backend may run at once: how the core's passes take a
//! parallel backend's threads without knowing them.

/// Runs a task on each of a set of items, perhaps several at once on other threads.
pub trait Pieces {
    /// How many threads the items are spread over (1: one after another).
    fn workers(&self) -> usize;

    /// Calls `task` once with each of `items`; returns when every call has returned.
    fn for_each<T: Send>(&self, items: &mut [T], task: impl Fn(&mut T) + Sync);
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
