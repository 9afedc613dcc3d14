//! Pure statistics: the median (the tables, the accuracy analysis and the timing check
//! all summarise repetitions by it), seeded bootstrap confidence intervals of a median,
//! of the ratio of two medians and of the median of paired ratios, and the timing check's verdict as a pure function of that interval and a noise
//! threshold (criterion.rs' `compare_to_threshold`). No I/O and no clock: the same
//! numbers give the same answer. The statistics of a run's observables as a time series
//! (equilibration cut, blocked errors, replicas) are in [`series`], applied to a run's
//! block series in [`observables`], compared with [`reference`] values.

pub mod observables;
pub mod reference;
pub mod series;

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
    let mut ratios: Vec<f64> = (0..RESAMPLES)
        .map(|_| {
            resampled_median(new, &mut rng, &mut scratch)
                / resampled_median(old, &mut rng, &mut scratch)
        })
        .collect();
    let point = median(&mut new.to_vec()) / median(&mut old.to_vec());
    central_interval(&mut ratios, confidence, point)
}

/// The median of the paired ratios `b[i] / a[i]` (runs of two builds measured next to
/// each other, in the same round), with its central `confidence` interval from
/// [`RESAMPLES`] bootstrap resamples of the pairs, drawn with the RNG seeded by `seed`.
/// `a` and `b` are non-empty, of equal length, positive and finite. Pairing cancels what
/// both runs of a pair share (a busy spell of the machine, a drift over the rounds),
/// which the ratio of two medians keeps as spread.
pub fn paired_ratio(a: &[f64], b: &[f64], confidence: f64, seed: u64) -> Interval {
    assert_eq!(a.len(), b.len(), "paired samples of equal length");
    let ratios: Vec<f64> = a.iter().zip(b).map(|(a, b)| b / a).collect();
    median_interval(&ratios, confidence, seed)
}

/// The median of a non-empty sample (run times) with its central `confidence` interval
/// from [`RESAMPLES`] bootstrap resamples, drawn with the RNG seeded by `seed`. With few
/// values the interval is wide, and it is never narrower than the values allow: one
/// value is its own interval.
pub fn median_interval(values: &[f64], confidence: f64, seed: u64) -> Interval {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut scratch = Vec::with_capacity(values.len());
    let mut medians: Vec<f64> = (0..RESAMPLES)
        .map(|_| resampled_median(values, &mut rng, &mut scratch))
        .collect();
    central_interval(&mut medians, confidence, median(&mut values.to_vec()))
}

/// The median of one bootstrap resample of `values` (drawn into `scratch`).
fn resampled_median(values: &[f64], rng: &mut Xoshiro256PlusPlus, scratch: &mut Vec<f64>) -> f64 {
    scratch.clear();
    scratch.extend((0..values.len()).map(|_| values[rng.random_range(0..values.len())]));
    median(scratch)
}

/// The central `confidence` interval of bootstrap estimates around `point`.
fn central_interval(estimates: &mut [f64], confidence: f64, point: f64) -> Interval {
    estimates.sort_by(f64::total_cmp);
    let tail = (1.0 - confidence) / 2.0;
    let last = (estimates.len() - 1) as f64;
    let at = |quantile: f64| estimates[(quantile * last).round() as usize];
    Interval {
        lower: at(tail),
        point,
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

    /// Times of one build over 12 rounds: scattered by a few percent.
    const A: [f64; 12] = [
        1.00, 1.03, 0.98, 1.01, 0.99, 1.02, 1.00, 0.97, 1.04, 1.01, 0.99, 1.02,
    ];

    #[test]
    fn equal_pairs_give_a_paired_ratio_around_one() {
        let b = A.map(|t| t * 1.001);
        let ratio = paired_ratio(&A, &b, 0.95, 3);
        assert!((ratio.point - 1.001).abs() < 1e-12, "{ratio:?}");
        assert!(ratio.lower <= 1.001 && ratio.upper >= 1.001, "{ratio:?}");
        assert_eq!(verdict(&ratio, 0.03), Verdict::Unchanged);
        assert_eq!(ratio, paired_ratio(&A, &b, 0.95, 3));
        // Pairs that scatter around 1 by ±2%: an interval that holds 1.
        let jitter = [
            1.02, 0.98, 1.01, 0.99, 1.0, 1.02, 0.98, 1.01, 0.99, 1.0, 1.02, 0.98,
        ];
        let b: Vec<f64> = A.iter().zip(jitter).map(|(a, j)| a * j).collect();
        let ratio = paired_ratio(&A, &b, 0.95, 3);
        assert!(ratio.lower < 1.0 && ratio.upper > 1.0, "{ratio:?}");
    }

    #[test]
    fn a_paired_shift_beyond_the_spread_is_a_regression_or_an_improvement() {
        let jitter = [
            1.02, 0.98, 1.01, 0.99, 1.0, 1.02, 0.98, 1.01, 0.99, 1.0, 1.02, 0.98,
        ];
        let slower: Vec<f64> = A.iter().zip(jitter).map(|(a, j)| 1.06 * a * j).collect();
        let ratio = paired_ratio(&A, &slower, 0.95, 5);
        assert!(ratio.lower > 1.03 && ratio.upper < 1.09, "{ratio:?}");
        assert_eq!(verdict(&ratio, 0.03), Verdict::Regressed);
        let faster: Vec<f64> = A.iter().zip(jitter).map(|(a, j)| a * j / 1.06).collect();
        assert_eq!(
            verdict(&paired_ratio(&A, &faster, 0.95, 5), 0.03),
            Verdict::Improved
        );
    }

    #[test]
    fn a_median_interval_holds_the_median_and_narrows_with_more_runs() {
        let few = median_interval(&A[..3], 0.95, 2);
        assert_eq!(few.point, 1.00);
        assert!(few.lower <= 0.98 && few.upper >= 1.03, "{few:?}");
        let many = median_interval(&A, 0.95, 2);
        assert!(
            many.lower <= many.point && many.point <= many.upper,
            "{many:?}"
        );
        assert!(
            many.upper - many.lower < few.upper - few.lower,
            "{many:?} {few:?}"
        );
        assert_eq!(median_interval(&[0.5], 0.95, 2).lower, 0.5);
        assert_eq!(many, median_interval(&A, 0.95, 2));
    }

    #[test]
    fn pairing_cancels_a_drift_that_an_unpaired_ratio_keeps() {
        // The machine gets slower round by round (both builds alike, up to 1.6 times);
        // B is 5% slower than A in every round.
        let drift: Vec<f64> = (0..12).map(|round| 1.0 + 0.05 * round as f64).collect();
        let a: Vec<f64> = A.iter().zip(&drift).map(|(a, d)| a * d).collect();
        let b: Vec<f64> = a.iter().map(|a| 1.05 * a).collect();
        let paired = paired_ratio(&a, &b, 0.95, 9);
        assert!((paired.point - 1.05).abs() < 1e-12, "{paired:?}");
        assert_eq!(verdict(&paired, 0.03), Verdict::Regressed);
        let unpaired = ratio_of_medians(&b, &a, 0.95, 9);
        assert_eq!(verdict(&unpaired, 0.03), Verdict::Unchanged, "{unpaired:?}");
    }
}
