//! The live view: a software rasterizer of snapshots (`raster`), its status line
//! (`status`), and `collide view`, which runs a scene on its own thread and shows it in
//! a window (`window`). The simulation core only fills snapshots; nothing here steps it
//! differently from `collide simulate`.

pub mod render;
pub mod shm;
pub mod status;
pub mod window;
