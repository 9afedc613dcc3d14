//! collide: a deterministic 2D hard-disk collision simulator and the harness that
//! times it under serial, threaded and distributed backends.
//!
//! Arrows point one way (ARCHITECTURE.md draws the map): `app` (behind `cli`) →
//! `check` → `study` → `run` → `sim`; `app` → `report` → `study`; `app` and `view` →
//! `backend` → `run`, `draw` → `sim`. `sim` is pure and imports nothing outside itself;
//! `system`, `stats` and `exit` are leaves anyone may use (and `view` borrows
//! `report`'s font).

pub mod app;
pub mod backend;
pub mod check;
pub mod cli;
pub mod cluster;
pub mod draw;
pub mod exit;
pub mod report;
pub mod run;
pub mod sim;
pub mod stats;
pub mod study;
pub mod system;
pub mod view;

/// Large allocations on transparent huge pages ([`system::huge_pages`]): for every binary
/// and test that links this library.
#[global_allocator]
static ALLOCATOR: system::huge_pages::HugePageAllocator = system::huge_pages::HugePageAllocator;
