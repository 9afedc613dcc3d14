//! All integration tests, built into one test binary.

mod backends;
mod cli;
mod physics;
