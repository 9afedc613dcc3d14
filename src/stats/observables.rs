//! A run's observables from its block series (`sim::observe::Block`): the equilibration
//! cut (MSER-5 on the blocks' compressibility factor, the same cut for every
//! observable), then each observable's mean over the production blocks with its
//! blocked standard error and statistical inefficiency; and the same from t = 0.

use crate::sim::observe::Block;
use crate::stats::series::{Cut, Estimate, mser5, ratio_estimate};

/// Fewer independent points than this: the error bar is itself uncertain (flagged).
pub const MIN_EFFECTIVE_POINTS: f64 = 50.0;

/// What a run's series says: its observables from t = 0 and, where MSER-5 found the
/// end of the transient, after it. `settled` is `None` when MSER-5's minimum fell in the
/// second half or the run has fewer than `MSER_MIN_POINTS` blocks: "not equilibrated:
/// run longer".
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observed {
    pub from_zero: Production,
    pub settled: Option<Production>,
}

/// The observables over the blocks after a cut.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Production {
    /// Simulated time cut from the start.
    pub cut_time: f64,
    /// Blocks kept.
    pub kept_blocks: usize,
    /// Z = 1 + Σ W / (2 Σ ∫KE dt) (with n·T̄·t = ∫KE dt: P·A/(n·T̄)).
    pub compressibility_z: Estimate,
    /// Pair collisions per disk per unit time, 2·Σ pairs / (n·Σ Δt).
    pub collision_rate: Estimate,
    /// Kinetic energy per disk, Σ ∫KE dt / (n·Σ Δt).
    pub temperature: Estimate,
}

/// The observables of `n` disks from the run's blocks, from t = 0 and after the MSER-5
/// cut. `None` without at least two blocks or for a state at rest (no kinetic energy to
/// measure a pressure against).
pub fn analyse(blocks: &[Block], n: usize) -> Option<Observed> {
    if blocks.len() < 2 || blocks.iter().any(|b| b.kinetic_integral <= 0.0) {
        return None;
    }
    let z: Vec<f64> = blocks
        .iter()
        .map(|b| 1.0 + b.virial / (2.0 * b.kinetic_integral))
        .collect();
    let settled = match mser5(&z) {
        Cut::At(start) => Some(production(blocks, start, n)),
        Cut::NotEquilibrated => None,
    };
    Some(Observed {
        from_zero: production(blocks, 0, n),
        settled,
    })
}

/// The observables over `blocks[start..]` (at least two blocks).
fn production(blocks: &[Block], start: usize, n: usize) -> Production {
    let kept = &blocks[start..];
    let n = n as f64;
    let durations: Vec<f64> = kept.iter().map(|b| b.duration).collect();
    let twice_kinetic: Vec<f64> = kept.iter().map(|b| 2.0 * b.kinetic_integral).collect();
    let virial: Vec<f64> = kept.iter().map(|b| b.virial).collect();
    let ratio_z = ratio_estimate(&virial, &twice_kinetic);
    let collisions: Vec<f64> = kept
        .iter()
        .map(|b| 2.0 * b.pair_collisions as f64 / n)
        .collect();
    let kinetic_per_disk: Vec<f64> = kept.iter().map(|b| b.kinetic_integral / n).collect();
    Production {
        cut_time: start
            .checked_sub(1)
            .map_or(0.0, |last_cut| blocks[last_cut].end),
        kept_blocks: kept.len(),
        compressibility_z: Estimate {
            mean: 1.0 + ratio_z.mean,
            ..ratio_z
        },
        collision_rate: ratio_estimate(&collisions, &durations),
        temperature: ratio_estimate(&kinetic_per_disk, &durations),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::series::MSER_MIN_POINTS;

    /// Blocks of unit duration with Z_k given and T = 1 for `n` = 10 disks.
    fn blocks(z: &[f64]) -> Vec<Block> {
        z.iter()
            .enumerate()
            .map(|(k, &z)| Block {
                end: (k + 1) as f64,
                duration: 1.0,
                pair_collisions: 30,
                wall_collisions: 0,
                virial: (z - 1.0) * 2.0 * 10.0,
                kinetic_integral: 10.0,
            })
            .collect()
    }

    #[test]
    fn a_melting_start_is_cut_and_the_rest_averaged() {
        let mut z = vec![9.0; 20];
        z.extend((0..108).map(|k| 4.0 + 0.01 * f64::from(k % 3) - 0.01));
        let observed = analyse(&blocks(&z), 10).unwrap();
        let p = observed.settled.unwrap();
        assert_eq!(p.kept_blocks, 108);
        assert_eq!(p.cut_time, 20.0);
        assert!((p.compressibility_z.mean - 4.0).abs() < 1e-3, "{p:?}");
        assert!(p.compressibility_z.se < 1e-2, "{p:?}");
        assert_eq!(p.collision_rate.mean, 6.0);
        assert_eq!(p.temperature.mean, 1.0);
        // From t = 0 the melting start is in the number.
        assert!(
            observed.from_zero.compressibility_z.mean > 4.7,
            "{observed:?}"
        );
    }

    #[test]
    fn a_run_too_short_or_still_melting_is_not_equilibrated() {
        let short = analyse(&blocks(&[5.0; MSER_MIN_POINTS - 1]), 10).unwrap();
        assert_eq!(short.settled, None);
        assert!((short.from_zero.compressibility_z.mean - 5.0).abs() < 1e-12);
        let melting: Vec<f64> = (0..128)
            .map(|k| 4.0 + 5.0 * (-k as f64 / 300.0).exp())
            .collect();
        assert_eq!(analyse(&blocks(&melting), 10).unwrap().settled, None);
    }
}
