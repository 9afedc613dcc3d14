//! Studies: manifests validated into configurations (`manifest`, with the safe `names`
//! that become paths), the runner that times each configuration as a fresh
//! `collide simulate` child process (`runner`), the Parquet records it keeps run by run
//! (`records`) with the replica check over the seeds of a setup (`replicas`), the
//! machine and build they were measured on (`environment`), and the CI check's verdicts
//! over commits (`history`). A study never calls a backend or the
//! simulation itself.

pub mod batch;
pub mod environment;
pub mod history;
pub mod manifest;
pub mod names;
pub mod records;
pub mod replicas;
pub mod runner;
