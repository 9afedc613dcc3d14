//! The pure simulation core: state, physics, broad phase and stepping.
//!
//! No I/O, no printing, no threads: backends wrap it (a parallel one runs some of its
//! passes in pieces at once, `pieces`), and a step cannot fail.

pub mod calendar;
pub mod cells;
pub mod collapse;
pub mod collision;
pub mod counters;
pub mod engine;
pub mod event;
pub mod exact_sum;
pub mod grid;
pub mod neighbours;
pub mod observe;
pub mod particles;
pub mod pieces;
pub mod pilot;
pub mod place;
pub mod prefetch;
pub mod resolve;
pub mod scene;
pub mod schedule;
pub mod snapshot;
pub mod step;

pub use counters::StepCounters;
pub use particles::{Disk, DiskFigures, DiskSlices, Particles, PerDisk, PerDiskSlice};
pub use scene::{Boundary, Domain, Physics, Scene};
pub use step::{Broadphase, StepParams, Stepper};
