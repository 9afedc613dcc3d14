//! A run's observables from its block series (`sim::observe::Block`): the equilibration
//! cut (MSER-5 on the blocks' compressibility factor, or the user's manual discard; the
//! same cut for every observable), then each observable's mean over the production
//! blocks with its blocked standard error and statistical inefficiency; and the same
//! from t = 0.

use crate::sim::observe::Block;
use crate::stats::series::{Cut, Estimate, mser5, ratio_estimate};

/// Fewer independent points than this: the error bar is itself uncertain (flagged).
pub const MIN_EFFECTIVE_POINTS: f64 = 50.0;

/// How much of a run to drop before averaging its observables: found by MSER-5, or
/// said by the user (`discard` in a scene's `[method]`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Discard {
    /// MSER-5 finds the end of the transient.
    #[default]
    Automatic,
    /// The first `time` units of simulated time (≥ 0).
    Time(f64),
    /// This fraction of the simulated time the run reached, in [0, 1).
    Fraction(f64),
}

/// The names of the two rules in the JSON summary and the records.
pub const MSER5_CUT: &str = "mser5";
pub const MANUAL_CUT: &str = "manual";

impl Discard {
    /// The rule's name: [`MSER5_CUT`] or [`MANUAL_CUT`].
    pub fn rule(self) -> &'static str {
        match self {
            Discard::Automatic => MSER5_CUT,
            Discard::Time(_) | Discard::Fraction(_) => MANUAL_CUT,
        }
    }

    /// The blocks a manual discard drops: every block that starts before the discarded
    /// time (so the cut is rounded up to the next block's end); `None` for MSER-5.
    fn blocks_dropped(self, blocks: &[Block]) -> Option<usize> {
        let reached = blocks.last().map_or(0.0, |b| b.end);
        let time = match self {
            Discard::Automatic => return None,
            Discard::Time(time) => time,
            Discard::Fraction(fraction) => fraction * reached,
        };
        // A block's end equal to the discarded time up to rounding counts as reaching it.
        let time = time - 1e-9 * reached;
        let ends_before = blocks.iter().filter(|b| b.end < time).count();
        Some(match time > 0.0 {
            true => (ends_before + 1).min(blocks.len()),
            false => 0,
        })
    }
}

/// Fewest blocks a manual discard must leave to average.
pub const MIN_KEPT_BLOCKS: usize = 2;

/// What a run's series says: its observables from t = 0 and, where the cut found (or
/// was told) the end of the transient, after it. `settled` is `None` when MSER-5's
/// minimum fell in the second half or the run has fewer than `MSER_MIN_POINTS` blocks
/// ("not equilibrated: run longer"), or when a manual discard leaves fewer than
/// [`MIN_KEPT_BLOCKS`] blocks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observed {
    pub from_zero: Production,
    pub settled: Option<Production>,
    /// The rule that chose the cut.
    pub discard: Discard,
    /// Where MSER-5 puts the end of the transient, whichever rule cut: the simulated
    /// time, or `None` when it finds none in the run's first half (or the run has too
    /// few blocks). A manual discard shorter than this may keep part of the transient.
    pub mser5_cut_time: Option<f64>,
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

/// The observables of `n` disks from the run's blocks, from t = 0 and after the cut
/// `discard` gives (MSER-5's, or the manual one). `None` without at least two blocks or
/// for a state at rest (no kinetic energy to measure a pressure against).
pub fn analyse(blocks: &[Block], n: usize, discard: Discard) -> Option<Observed> {
    if blocks.len() < 2 || blocks.iter().any(|b| b.kinetic_integral <= 0.0) {
        return None;
    }
    let z: Vec<f64> = blocks
        .iter()
        .map(|b| 1.0 + b.virial / (2.0 * b.kinetic_integral))
        .collect();
    let mser5_start = match mser5(&z) {
        Cut::At(start) => Some(start),
        Cut::NotEquilibrated => None,
    };
    let start = match discard.blocks_dropped(blocks) {
        None => mser5_start,
        Some(dropped) => (blocks.len() - dropped >= MIN_KEPT_BLOCKS).then_some(dropped),
    };
    Some(Observed {
        from_zero: production(blocks, 0, n),
        settled: start.map(|start| production(blocks, start, n)),
        discard,
        mser5_cut_time: mser5_start.map(|start| cut_time(blocks, start)),
    })
}

/// The simulated time cut when averaging starts at block `start`: the end of the block
/// before it (0 for the first).
fn cut_time(blocks: &[Block], start: usize) -> f64 {
    start
        .checked_sub(1)
        .map_or(0.0, |last_cut| blocks[last_cut].end)
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
        cut_time: cut_time(blocks, start),
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
        let observed = analyse(&blocks(&z), 10, Discard::Automatic).unwrap();
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
        let short = analyse(&blocks(&[5.0; MSER_MIN_POINTS - 1]), 10, Discard::Automatic).unwrap();
        assert_eq!(short.settled, None);
        assert!((short.from_zero.compressibility_z.mean - 5.0).abs() < 1e-12);
        let melting: Vec<f64> = (0..128)
            .map(|k| 4.0 + 5.0 * (-k as f64 / 300.0).exp())
            .collect();
        let melting = analyse(&blocks(&melting), 10, Discard::Automatic).unwrap();
        assert_eq!((melting.settled, melting.mser5_cut_time), (None, None));
    }

    #[test]
    fn a_manual_discard_averages_from_the_block_end_at_or_after_it() {
        // Z = 9 over the first 10 units, then 4: MSER-5 would cut at 10.
        let mut z = vec![9.0; 10];
        z.extend([4.0; 30]);
        let blocks = blocks(&z);
        let window = |discard| analyse(&blocks, 10, discard).unwrap().settled.unwrap();
        // 25% of t = 40 is t = 10, a block's end: the window starts there.
        let quarter = window(Discard::Fraction(0.25));
        assert_eq!((quarter.cut_time, quarter.kept_blocks), (10.0, 30));
        assert_eq!(quarter.compressibility_z.mean, 4.0);
        // A time inside a block rounds up to that block's end.
        let time = window(Discard::Time(4.5));
        assert_eq!((time.cut_time, time.kept_blocks), (5.0, 35));
        assert!((time.compressibility_z.mean - (5.0 * 9.0 + 30.0 * 4.0) / 35.0).abs() < 1e-12);
        // Nothing discarded: the average from t = 0.
        let none = window(Discard::Time(0.0));
        assert_eq!((none.cut_time, none.kept_blocks), (0.0, 40));
        let observed = analyse(&blocks, 10, Discard::Fraction(0.0)).unwrap();
        assert_eq!(observed.settled, Some(observed.from_zero));
        assert_eq!(observed.discard.rule(), "manual");
        // MSER-5's own cut is kept beside the manual one, to compare them.
        assert_eq!(observed.mser5_cut_time, Some(10.0));
        assert_eq!(
            analyse(&blocks, 10, Discard::Automatic)
                .unwrap()
                .mser5_cut_time,
            Some(10.0)
        );
        // A discard that leaves fewer than two blocks (a run cut short) averages nothing.
        for discard in [
            Discard::Time(39.5),
            Discard::Time(100.0),
            Discard::Fraction(0.99),
        ] {
            assert_eq!(
                analyse(&blocks, 10, discard).unwrap().settled,
                None,
                "{discard:?}"
            );
        }
        assert_eq!(window(Discard::Time(38.0)).kept_blocks, 2);
    }
}
