//! The edges to the operating system that every layer shares: what commands print
//! (`console`, never panicking on a closed pipe), files read with a size cap (`input`),
//! files written atomically and output paths checked (`output`), child processes under
//! a timeout (`process`), what this machine offers: CPUs, memory, CPU-time clocks
//! (`machine`), and large allocations on huge pages (`huge_pages`).

pub mod console;
pub mod huge_pages;
pub mod input;
pub mod machine;
pub mod output;
pub mod process;
