//! All integration tests, built into one test binary.

mod cli;
mod physics;
