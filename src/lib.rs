//! collide: a deterministic 2D hard-disk collision simulator and the harness that
//! times it under serial, threaded and distributed backends.
//!
//! Arrows point one way: `app` → `backend` → `sim`. `sim` is pure.

pub mod accuracy;
pub mod accuracy_figures;
pub mod analysis;
pub mod app;
pub mod auto;
pub mod backend;
pub mod calibrate;
pub mod check;
pub mod cli;
pub mod environment;
pub mod exit;
pub mod figures;
pub mod limits;
pub mod manifest;
pub mod names;
pub mod output;
pub mod process;
pub mod records;
pub mod render;
pub mod report;
pub mod results;
pub mod runner;
pub mod scene_file;
pub mod scene_limits;
pub mod sim;
pub mod spec;
pub mod stats;
pub mod summary;
pub mod view;
