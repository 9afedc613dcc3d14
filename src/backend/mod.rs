//! Backends: drivers that run a prepared scene with the pure core and time it.
//!
//! The serial backend is the reference every other backend is tested against.

pub mod serial;

use crate::sim::Particles;
use crate::summary::RunSummary;

/// What a run leaves behind: its summary and the final state (for `--dump`).
#[derive(Clone, Debug)]
pub struct RunOutcome {
    pub summary: RunSummary,
    pub final_state: Particles,
}
