//! All integration tests, built into one test binary.

mod accuracy;
mod architecture;
mod auto;
mod backends;
mod check;
mod cli;
mod cluster;
mod equilibrium;
mod event_reference;
mod faults;
mod golden;
mod hazards;
mod limits;
#[cfg(feature = "mpi")]
mod mpi;
mod physics;
mod reliability;
mod report;
mod resting;
mod schema;
mod study;
mod util;
mod view;
