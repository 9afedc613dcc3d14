//! collide: a deterministic 2D hard-disk collision simulator and the harness that
//! times it under serial, threaded and distributed backends.
//!
//! Arrows point one way (ARCHITECTURE.md draws the map):
//! `cli`/`app` → `check` → `report` → `study` → `run` → `sim`, and `app` → `backend` →
//! `run` → `sim`. `sim` is pure; `system` and `stats` are leaves anyone may use.

pub mod app;
pub mod backend;
pub mod check;
pub mod cli;
pub mod draw;
pub mod exit;
pub mod report;
pub mod run;
pub mod sim;
pub mod stats;
pub mod study;
pub mod system;
pub mod view;
