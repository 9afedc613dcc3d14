//! One run: what to run and what came out. The typed specification that input is
//! validated into once (`spec`, from a scene file and its `overrides` by `scene_file`),
//! the disks placed and the method and dt resolved (`prepare`, choosing through `auto`), the limits checked before a run
//! (`limits`, `scene_limits`), the backend kind and how workers split (`backend_kind`),
//! and the result of one run (`summary`), which the JSON output and the study's records
//! both follow. Nothing here runs a backend or touches a study.

pub mod auto;
pub mod backend_kind;
pub mod limits;
pub mod overrides;
pub mod prepare;
pub mod scene_file;
pub mod scene_limits;
pub mod spec;
pub mod summary;
