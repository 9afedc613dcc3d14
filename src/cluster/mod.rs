//! Studies on a cluster: the site (scheduler, launcher, nodes and cores) apart from the
//! experiment (a run's ranks and threads on nodes), the launcher lines and job scripts
//! rendered from both (pure, golden-tested), and the Slurm queue a study's runs are
//! submitted to and followed in.
//!
//! - [`network`]: a site's latency and bandwidth, fitted from a ping-pong or assumed.
//! - [`site`]: a site file (`systems/NAME.toml`) → a validated [`site::Site`]; `local`.
//! - [`placement`]: a run's [`placement::Layout`] and whether a site holds it.
//! - [`render`]: a layout on a site → the launcher's words and variables, a job script.
//! - [`slurm`]: submitting, following and cancelling jobs; their states.

pub mod network;
pub mod placement;
pub mod render;
pub mod site;
pub mod slurm;
