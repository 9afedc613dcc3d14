//! Pictures of the disks, from the core's snapshot only: the pure rasterizer (snapshot
//! and view settings to pixels) and the offscreen drawing of every step of a run. A leaf
//! beside `sim`: the backends draw through it, the live view and `collide render` show
//! what it draws.

pub mod offscreen;
pub mod raster;
