//! Statistics of the timing check: a seeded bootstrap confidence interval of the ratio
//! of two medians, each normalised by its own calibration times, and the verdict as a
//! pure function of that interval and a noise threshold (criterion.rs'
//! `compare_to_threshold`). No I/O and no clock: the same numbers give the same answer.

use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::results::median;

/// Timings of one configuration in one run, with the calibration times of the same run.
/// Both slices are non-empty and hold positive, finite seconds.
#[derive(Clone, Copy, Debug)]
pub struct Sample<'a> {
    pub times: &'a [f64],
    pub calibration: &'a [f64],
}

impl Sample<'_> {
    /// Median time in units of the median calibration time.
    pub fn normalised_median(&self) -> f64 {
        median(&mut self.times.to_vec()) / median(&mut self.calibration.to_vec())
    }
}

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

/// Resamples drawn by [`ratio_of_medians`].
pub const RESAMPLES: usize = 10_000;

/// The ratio of normalised medians new/old with its central `confidence` interval
/// (e.g. 0.95), from [`RESAMPLES`] bootstrap resamples of all four slices, drawn with
/// the RNG seeded by `seed`: the calibration's own noise widens the interval.
pub fn ratio_of_medians(new: Sample<'_>, old: Sample<'_>, confidence: f64, seed: u64) -> Interval {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut scratch = Vec::new();
    let mut resampled_median = |values: &[f64], rng: &mut Xoshiro256PlusPlus| {
        scratch.clear();
        scratch.extend((0..values.len()).map(|_| values[rng.random_range(0..values.len())]));
        median(&mut scratch)
    };
    let mut ratios: Vec<f64> = (0..RESAMPLES)
        .map(|_| {
            let new_time = resampled_median(new.times, &mut rng);
            let new_calibration = resampled_median(new.calibration, &mut rng);
            let old_time = resampled_median(old.times, &mut rng);
            let old_calibration = resampled_median(old.calibration, &mut rng);
            (new_time / new_calibration) / (old_time / old_calibration)
        })
        .collect();
    ratios.sort_by(f64::total_cmp);
    let tail = (1.0 - confidence) / 2.0;
    let at = |quantile: f64| {
        let index = (quantile * (RESAMPLES - 1) as f64).round() as usize;
        ratios[index.min(RESAMPLES - 1)]
    };
    Interval {
        lower: at(tail),
        point: new.normalised_median() / old.normalised_median(),
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

    const CALIBRATION: [f64; 5] = [0.200, 0.202, 0.198, 0.201, 0.199];

    #[test]
    fn equal_samples_give_an_interval_around_one() {
        let times = [1.00, 1.02, 0.99, 1.01, 0.98, 1.03, 1.00];
        let sample = Sample {
            times: &times,
            calibration: &CALIBRATION,
        };
        let ratio = ratio_of_medians(sample, sample, 0.95, 7);
        assert_eq!(ratio.point, 1.0);
        assert!(ratio.lower < 1.0 && ratio.upper > 1.0, "{ratio:?}");
        assert!(ratio.lower > 0.95 && ratio.upper < 1.05, "{ratio:?}");
        assert_eq!(verdict(&ratio, 0.03), Verdict::Unchanged);
        // Seeded: the same numbers give the same interval.
        assert_eq!(ratio, ratio_of_medians(sample, sample, 0.95, 7));
    }

    #[test]
    fn a_slower_machine_cancels_out_and_a_slower_code_does_not() {
        let old_times = [1.00, 1.02, 0.99, 1.01, 0.98];
        let old = Sample {
            times: &old_times,
            calibration: &CALIBRATION,
        };
        // Everything 30% slower, calibration included: the machine, not the code.
        let slow_times = old_times.map(|t| 1.3 * t);
        let slow_calibration = CALIBRATION.map(|t| 1.3 * t);
        let machine = ratio_of_medians(
            Sample {
                times: &slow_times,
                calibration: &slow_calibration,
            },
            old,
            0.95,
            1,
        );
        assert!((machine.point - 1.0).abs() < 1e-12, "{machine:?}");
        assert_eq!(verdict(&machine, 0.03), Verdict::Unchanged);
        // Only the measured runs 20% slower: the code.
        let code = ratio_of_medians(
            Sample {
                times: &old_times.map(|t| 1.2 * t),
                calibration: &CALIBRATION,
            },
            old,
            0.95,
            1,
        );
        assert!((code.point - 1.2).abs() < 1e-12, "{code:?}");
        assert_eq!(verdict(&code, 0.03), Verdict::Regressed);
    }
}
