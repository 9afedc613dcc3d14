//! Pure statistics: the median (the tables, the accuracy analysis and the timing check
//! all summarise repetitions by it), a seeded bootstrap confidence interval of the ratio
//! of two medians, and the timing check's verdict as a pure function of that interval and a noise
//! threshold (criterion.rs' `compare_to_threshold`). No I/O and no clock: the same
//! numbers give the same answer.

use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

/// A confidence interval around a point estimate: `lower <= point <= upper` for
/// the ratios this module computes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    pub lower: f64,
    pub point: f64,
    pub upper: f64,
}

/// What became of a configuration's speed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    Regressed,
    Improved,
    Unchanged,
}

impl Verdict {
    pub fn name(self) -> &'static str {
        match self {
            Verdict::Regressed => "regressed",
            Verdict::Improved => "improved",
            Verdict::Unchanged => "unchanged",
        }
    }
}

/// The verdict on a ratio new/old of times: regressed only when the whole interval lies
/// above `1 + noise`, improved only when it lies wholly below `1 / (1 + noise)` (the
/// same change in the other direction), unchanged otherwise.
pub fn verdict(ratio: &Interval, noise: f64) -> Verdict {
    if ratio.lower > 1.0 + noise {
        Verdict::Regressed
    } else if ratio.upper < 1.0 / (1.0 + noise) {
        Verdict::Improved
    } else {
        Verdict::Unchanged
    }
}

/// Median of a non-empty slice.
pub fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let mid = values.len() / 2;
    if values.len() % 2 == 1 {
        values[mid]
    } else {
        0.5 * (values[mid - 1] + values[mid])
    }
}

/// Resamples drawn by [`ratio_of_medians`].
pub const RESAMPLES: usize = 10_000;

/// The ratio of medians new/old of two non-empty samples of positive, finite values,
/// with its central `confidence` interval (e.g. 0.95) from [`RESAMPLES`] bootstrap
/// resamples of both, drawn with the RNG seeded by `seed`.
pub fn ratio_of_medians(new: &[f64], old: &[f64], confidence: f64, seed: u64) -> Interval {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut scratch = Vec::new();
    let mut resampled_median = |values: &[f64], rng: &mut Xoshiro256PlusPlus| {
        scratch.clear();
        scratch.extend((0..values.len()).map(|_| values[rng.random_range(0..values.len())]));
        median(&mut scratch)
    };
    let mut ratios: Vec<f64> = (0..RESAMPLES)
        .map(|_| resampled_median(new, &mut rng) / resampled_median(old, &mut rng))
        .collect();
    ratios.sort_by(f64::total_cmp);
    let tail = (1.0 - confidence) / 2.0;
    let at = |quantile: f64| ratios[(quantile * (RESAMPLES - 1) as f64).round() as usize];
    Interval {
        lower: at(tail),
        point: median(&mut new.to_vec()) / median(&mut old.to_vec()),
        upper: at(1.0 - tail),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn interval(lower: f64, upper: f64) -> Interval {
        Interval {
            lower,
            point: 0.5 * (lower + upper),
            upper,
        }
    }

    #[test]
    fn the_verdict_needs_the_whole_interval_beyond_the_noise() {
        assert_eq!(verdict(&interval(1.04, 1.20), 0.03), Verdict::Regressed);
        assert_eq!(verdict(&interval(1.02, 1.20), 0.03), Verdict::Unchanged);
        assert_eq!(verdict(&interval(0.80, 0.96), 0.03), Verdict::Improved);
        assert_eq!(verdict(&interval(0.80, 0.975), 0.03), Verdict::Unchanged);
        assert_eq!(verdict(&interval(0.90, 1.10), 0.03), Verdict::Unchanged);
        // A ratio known exactly (an instruction count) is its own interval.
        assert_eq!(verdict(&interval(1.011, 1.011), 0.01), Verdict::Regressed);
    }

    #[test]
    fn equal_samples_give_an_interval_around_one() {
        let times = [1.00, 1.02, 0.99, 1.01, 0.98, 1.03, 1.00];
        let ratio = ratio_of_medians(&times, &times, 0.95, 7);
        assert_eq!(ratio.point, 1.0);
        assert!(ratio.lower < 1.0 && ratio.upper > 1.0, "{ratio:?}");
        assert!(ratio.lower > 0.97 && ratio.upper < 1.03, "{ratio:?}");
        assert_eq!(verdict(&ratio, 0.03), Verdict::Unchanged);
        // Seeded: the same numbers give the same interval.
        assert_eq!(ratio, ratio_of_medians(&times, &times, 0.95, 7));
    }

    #[test]
    fn a_shift_beyond_the_spread_is_a_regression_or_an_improvement() {
        let old = [1.00, 1.02, 0.99, 1.01, 0.98, 1.03, 1.00];
        let slower = old.map(|t| 1.2 * t);
        let ratio = ratio_of_medians(&slower, &old, 0.95, 1);
        assert!((ratio.point - 1.2).abs() < 1e-12, "{ratio:?}");
        assert_eq!(verdict(&ratio, 0.03), Verdict::Regressed);
        assert_eq!(
            verdict(&ratio_of_medians(&old, &slower, 0.95, 1), 0.03),
            Verdict::Improved
        );
        // The same medians with a wide spread: not enough evidence either way.
        let noisy_old = [0.6, 1.0, 1.4, 0.7, 1.3, 1.0, 0.8];
        let noisy_new = noisy_old.map(|t| 1.2 * t);
        assert_eq!(
            verdict(&ratio_of_medians(&noisy_new, &noisy_old, 0.95, 1), 0.03),
            Verdict::Unchanged
        );
    }
}
