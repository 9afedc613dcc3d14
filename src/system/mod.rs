//! The edges to the operating system that every layer shares: files written atomically
//! and output paths checked (`output`), child processes under a timeout (`process`), and
//! what this machine offers: CPUs, memory, CPU-time clocks (`machine`).

pub mod machine;
pub mod output;
pub mod process;
