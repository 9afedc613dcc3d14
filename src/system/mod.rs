//! The edges to the operating system that every layer shares: files written atomically
//! and output paths checked (`output`), child processes under a timeout (`process`),
//! what this machine offers: CPUs, memory, CPU-time clocks (`machine`), and large
//! allocations on huge pages (`huge_pages`).

pub mod huge_pages;
pub mod machine;
pub mod output;
pub mod process;
