//! The calibration workload of `collide check`: fixed work that is none of the
//! simulator's code, timed in the same run as the measured configurations, so that their
//! times can be expressed in its units (a slower core slows both, a slower simulator
//! only the configurations).
//!
//! It works in the first-level cache on purpose. A first draft walked a 4 MiB array:
//! its CPU time fell by 12% when the machine's other jobs stopped competing for the
//! shared caches while the simulator's hardly moved, and that difference alone was
//! reported as a 12–18% regression in A/A checks.

use std::hint::black_box;
use std::time::Instant;

use crate::system::machine::{CpuScope, LoopSeconds, cpu_seconds};

/// Values the workload reads and writes: 32 KiB, within a core's first-level cache.
const LEN: usize = 1 << 12;
/// Passes over the values, each a pseudo-random walk through all of them.
const PASSES: usize = 5000;

/// Wall and CPU seconds taken by the fixed workload: loads from pseudo-random places
/// mixed with floating-point arithmetic, like a broad phase and its impulses.
pub fn workload_seconds() -> LoopSeconds {
    let cpu_start = cpu_seconds(CpuScope::Thread);
    let start = Instant::now();
    let mut values: Vec<f64> = (0..LEN).map(|i| i as f64).collect();
    // A full-period linear congruential walk modulo LEN (odd increment, multiplier 1 mod 4).
    let mut index = 1_usize;
    let mut sum = 0.0;
    for _ in 0..PASSES {
        for _ in 0..LEN {
            index = (index.wrapping_mul(1_103_515_245).wrapping_add(12_345)) & (LEN - 1);
            let value = values[index];
            sum += value.sqrt();
            values[index] = 0.5 * value + 1.0;
        }
    }
    black_box(sum);
    let wall = start.elapsed().as_secs_f64();
    let cpu = cpu_seconds(CpuScope::Thread)
        .zip(cpu_start)
        .map(|(end, start)| end - start);
    LoopSeconds { wall, cpu }
}
