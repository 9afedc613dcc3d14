//! Statistics of a correlated time series (a run's observables block by block): the
//! MSER-5 equilibration cut, Flyvbjerg–Petersen blocking with the Wolff/Lee optimal
//! block, Geyer's initial monotone sequence estimate of the statistical inefficiency,
//! the ratio-of-means linearisation, and the standard error over independent replicas
//! with Student's t. Pure: the same numbers give the same answer. What they are and why
//! these were chosen: `docs/accuracy.md`.

/// Points averaged into one MSER batch (White's MSER-5: raw MSER under-discards on noise).
pub const MSER_BATCH: usize = 5;

/// Fewest points MSER-5 cuts (four batches); fewer are not equilibrated.
pub const MSER_MIN_POINTS: usize = 4 * MSER_BATCH;

/// Where the production part of a series starts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cut {
    /// Discard the first `start` points; the rest is production.
    At(usize),
    /// The MSER minimum lies in the second half (or the series is too short to tell):
    /// the run has not settled, and no number should be printed from it.
    NotEquilibrated,
}

/// The MSER-5 cut (White 1997; Spratt 1998): the points are averaged in batches of
/// [`MSER_BATCH`], and the cut is the batch d that minimises the squared standard error
/// of the remaining mean, Σ_{j≥d}(y_j − ȳ_d)²/(m − d)², the last few batches left out of
/// the search (their few points make the statistic erratic). A minimum in the second
/// half, or fewer than [`MSER_MIN_POINTS`] points, is [`Cut::NotEquilibrated`].
pub fn mser5(series: &[f64]) -> Cut {
    if series.len() < MSER_MIN_POINTS {
        return Cut::NotEquilibrated;
    }
    let m = series.len() / MSER_BATCH;
    let batches: Vec<f64> = series
        .chunks_exact(MSER_BATCH)
        .map(|batch| batch.iter().sum::<f64>() / MSER_BATCH as f64)
        .collect();
    // Centred on the overall mean so that the suffix sums of squares do not cancel.
    let centre = batches.iter().sum::<f64>() / m as f64;
    let ignored = (m / 4).clamp(1, 5);
    let (mut sum, mut squares) = (0.0, 0.0);
    let mut statistic = vec![0.0; m];
    for d in (0..m).rev() {
        let y = batches[d] - centre;
        sum += y;
        squares += y * y;
        let kept = (m - d) as f64;
        statistic[d] = (squares - sum * sum / kept).max(0.0) / (kept * kept);
    }
    // The first minimum (a constant series cuts nothing).
    let best = (0..m - ignored).fold(0, |best, d| {
        if statistic[d] < statistic[best] {
            d
        } else {
            best
        }
    });
    if 2 * best > m {
        Cut::NotEquilibrated
    } else {
        Cut::At(best * MSER_BATCH)
    }
}

/// The mean of a series, its standard error and how many points it is worth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    pub mean: f64,
    /// Standard error of the mean from blocking (at the optimal block, or the largest
    /// of the levels with at least [`MIN_BLOCKS`] blocks where there is no plateau).
    pub se: f64,
    /// Geyer's statistical inefficiency g = 1 + 2Σρ_k (≥ 1).
    pub g: f64,
    /// Points in the series.
    pub n: usize,
    /// Whether the blocking curve reached a plateau at a block that still leaves
    /// [`MIN_BLOCKS`] blocks.
    pub plateau: bool,
}

impl Estimate {
    /// Independent points the series is worth, n/g.
    pub fn n_eff(&self) -> f64 {
        self.n as f64 / self.g
    }
}

/// Fewest blocks a blocking level must hold for its standard error to count.
pub const MIN_BLOCKS: usize = 4;

/// The mean of `series` (at least two points) with its blocked standard error and
/// Geyer's statistical inefficiency.
pub fn estimate(series: &[f64]) -> Estimate {
    let blocked = blocking(series);
    Estimate {
        mean: mean(series),
        se: blocked.se,
        g: statistical_inefficiency(series),
        n: series.len(),
        plateau: blocked.plateau,
    }
}

/// The outcome of Flyvbjerg–Petersen blocking.
#[derive(Clone, Debug, PartialEq)]
pub struct Blocking {
    /// Standard error of the mean at each level k (blocks of 2^k points).
    pub levels: Vec<f64>,
    /// The Wolff/Lee optimal level, where found.
    pub optimal: Option<usize>,
    pub se: f64,
    pub plateau: bool,
}

/// Flyvbjerg–Petersen blocking (J. Chem. Phys. 91, 461 (1989)): at each level the
/// neighbouring pairs are averaged, and the naive standard error grows until the
/// blocks are longer than the correlation time. The optimal level is the smallest k
/// with 2^{3k} > 2n·(SE_k/SE_0)⁴ (Wolff 2004, Lee et al. 2011, as pyblock's
/// `find_optimal_block`), among levels with at least [`MIN_BLOCKS`] blocks; it is a
/// plateau when the next level (if it has enough blocks) does not rise above it by
/// more than twice its error SE_k/√(2(n_k − 1)).
pub fn blocking(series: &[f64]) -> Blocking {
    let n = series.len();
    let mut blocks = series.to_vec();
    let mut levels = Vec::new();
    let mut errors = Vec::new();
    while blocks.len() >= MIN_BLOCKS {
        let count = blocks.len();
        let centre = mean(&blocks);
        let variance =
            blocks.iter().map(|x| (x - centre).powi(2)).sum::<f64>() / (count - 1) as f64;
        let se = (variance / count as f64).sqrt();
        levels.push(se);
        errors.push(se / (2.0 * (count - 1) as f64).sqrt());
        blocks = blocks
            .chunks_exact(2)
            .map(|p| 0.5 * (p[0] + p[1]))
            .collect();
    }
    let Some(&first) = levels.first() else {
        return Blocking {
            levels,
            optimal: None,
            se: f64::NAN,
            plateau: false,
        };
    };
    if first == 0.0 {
        // A constant series: no error at all.
        return Blocking {
            levels,
            optimal: Some(0),
            se: 0.0,
            plateau: true,
        };
    }
    let optimal = (0..levels.len())
        .find(|&k| 2f64.powi(3 * k as i32) > 2.0 * n as f64 * (levels[k] / first).powi(4));
    let plateau = optimal.is_some_and(|k| {
        levels
            .get(k + 1)
            .is_none_or(|&next| next <= levels[k] + 2.0 * errors[k])
    });
    let se = match optimal {
        Some(k) => levels[k],
        None => levels.iter().copied().fold(0.0, f64::max),
    };
    Blocking {
        levels,
        optimal,
        se,
        plateau,
    }
}

/// Geyer's initial monotone sequence estimate (Stat. Sci. 7, 473 (1992)) of the
/// statistical inefficiency g = 1 + 2Σ_k ρ_k: the sums Γ_m = γ_{2m} + γ_{2m+1} of the
/// autocovariances are summed while positive, each capped by the one before. At least 1;
/// 1 for a constant series.
pub fn statistical_inefficiency(series: &[f64]) -> f64 {
    let n = series.len();
    let centre = mean(series);
    let deviations: Vec<f64> = series.iter().map(|x| x - centre).collect();
    let autocovariance = |lag: usize| {
        deviations[..n - lag]
            .iter()
            .zip(&deviations[lag..])
            .map(|(a, b)| a * b)
            .sum::<f64>()
            / n as f64
    };
    let variance = autocovariance(0);
    if variance <= 0.0 {
        return 1.0;
    }
    let mut sum = -variance;
    let mut previous = f64::INFINITY;
    let mut pair = 0;
    while 2 * pair + 1 < n {
        let gamma = autocovariance(2 * pair) + autocovariance(2 * pair + 1);
        if gamma <= 0.0 {
            break;
        }
        previous = gamma.min(previous);
        sum += 2.0 * previous;
        pair += 1;
    }
    (sum / variance).max(1.0)
}

/// The ratio of means r = Σ num / Σ den over blocks (a pressure from the virial and
/// the kinetic-energy integral, a rate from counts and durations), with its error bar:
/// the estimate of the linearised series u_k = (num_k − r·den_k)/mean(den) (the delta
/// method), shifted to r. `num` and `den` have equal lengths, at least two, and the
/// denominators a positive sum.
pub fn ratio_estimate(num: &[f64], den: &[f64]) -> Estimate {
    assert_eq!(num.len(), den.len(), "numerators and denominators pair up");
    let ratio = num.iter().sum::<f64>() / den.iter().sum::<f64>();
    let scale = mean(den);
    let linear: Vec<f64> = num
        .iter()
        .zip(den)
        .map(|(x, d)| (x - ratio * d) / scale)
        .collect();
    Estimate {
        mean: ratio,
        ..estimate(&linear)
    }
}

/// The mean over independent replicas (runs of other seeds) with the standard error of
/// their spread, s/√R, and the 95% half-width t_{R−1}·s/√R.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReplicaEstimate {
    pub mean: f64,
    pub se: f64,
    pub half_width_95: f64,
    pub replicas: usize,
}

/// The replica estimate of at least two replicas' means; `None` for fewer.
pub fn replica_estimate(means: &[f64]) -> Option<ReplicaEstimate> {
    let replicas = means.len();
    if replicas < 2 {
        return None;
    }
    let centre = mean(means);
    let variance = means.iter().map(|x| (x - centre).powi(2)).sum::<f64>() / (replicas - 1) as f64;
    let se = (variance / replicas as f64).sqrt();
    Some(ReplicaEstimate {
        mean: centre,
        se,
        half_width_95: student_t_975(replicas - 1) * se,
        replicas,
    })
}

/// The 97.5% quantile of Student's t with `df` ≥ 1 degrees of freedom (two-sided 95%).
pub fn student_t_975(df: usize) -> f64 {
    const TABLE: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    match df {
        0 => f64::INFINITY,
        1..=30 => TABLE[df - 1],
        // Beyond the table: the normal quantile with the first correction in 1/df.
        _ => 1.959964 * (1.0 + 0.25 * (1.0 + 1.959964_f64.powi(2)) / df as f64),
    }
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    use rand_xoshiro::Xoshiro256PlusPlus;

    use super::*;

    const PHI: f64 = 0.9;

    /// x_t = φx_{t−1} + √(1−φ²)ε_t (unit variance), started from its stationary law,
    /// plus the transient A·e^{−t/τ}.
    fn ar1(n: usize, amplitude: f64, tau: f64, seed: u64) -> Vec<f64> {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
        let mut x = normal();
        (0..n)
            .map(|t| {
                let value = x + amplitude * (-(t as f64) / tau).exp();
                x = PHI * x + (1.0 - PHI * PHI).sqrt() * normal();
                value
            })
            .collect()
    }

    /// The exact variance of the mean of n points of the unit-variance AR(1).
    fn true_variance_of_mean(n: usize) -> f64 {
        let sum: f64 = (1..n)
            .map(|k| (1.0 - k as f64 / n as f64) * PHI.powi(k as i32))
            .sum();
        (1.0 + 2.0 * sum) / n as f64
    }

    #[test]
    fn blocking_after_the_mser_cut_gives_the_true_error_and_removes_the_transient() {
        let (n, amplitude, tau) = (1 << 14, 5.0, 100.0);
        let seeds = 200;
        let (mut se_squared, mut covered, mut removed) = (0.0, 0, 0);
        for seed in 0..seeds {
            let series = ar1(n, amplitude, tau, seed);
            let Cut::At(start) = mser5(&series) else {
                panic!("seed {seed}: a settled series is not equilibrated");
            };
            let production = &series[start..];
            let kept = production.len();
            let estimate = estimate(production);
            let true_se = true_variance_of_mean(kept).sqrt();
            se_squared += estimate.se.powi(2) / true_se.powi(2);
            // The transient is the only bias: the mean is 0 without it.
            let bias: f64 = (start..n)
                .map(|t| amplitude * (-(t as f64) / tau).exp())
                .sum::<f64>()
                / kept as f64;
            removed += usize::from(bias < true_se);
            covered += usize::from(estimate.mean.abs() < 1.96 * estimate.se);
        }
        let ratio = (se_squared / seeds as f64).sqrt();
        assert!((0.85..=1.15).contains(&ratio), "rms SE / true SE = {ratio}");
        assert!(removed * 100 >= 95 * seeds as usize, "removed in {removed}");
        assert!(covered * 100 >= 88 * seeds as usize, "covered in {covered}");
    }

    #[test]
    fn geyer_finds_the_inefficiency_of_an_ar1_series_and_of_white_noise() {
        // g = (1 + φ)/(1 − φ) = 19.
        let g = statistical_inefficiency(&ar1(1 << 16, 0.0, 1.0, 3));
        assert!((15.0..23.0).contains(&g), "g = {g}");
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(4);
        let noise: Vec<f64> = (0..1 << 14)
            .map(|_| StandardNormal.sample(&mut rng))
            .collect();
        let g = statistical_inefficiency(&noise);
        assert!((0.9..1.1).contains(&g), "g = {g}");
        let blocked = estimate(&noise);
        assert!(blocked.plateau);
        let ratio = blocked.se * (noise.len() as f64).sqrt();
        assert!((0.9..1.1).contains(&ratio), "{ratio}");
    }

    #[test]
    fn a_series_worth_few_points_says_so() {
        // n/g ≈ 10 (g = 19): fewer than 50 independent points, whose error bar is itself
        // uncertain; the summary warns below 50.
        let series = ar1(200, 0.0, 1.0, 5);
        let estimate = estimate(&series);
        assert!(estimate.n_eff() < 50.0, "{estimate:?}");
    }

    #[test]
    fn exact_series_give_exact_answers() {
        let constant = [2.5; 64];
        assert_eq!(mser5(&constant), Cut::At(0));
        let e = estimate(&constant);
        assert_eq!((e.mean, e.se, e.g), (2.5, 0.0, 1.0));
        let alternating: Vec<f64> = (0..64)
            .map(|t| if t % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        assert_eq!(statistical_inefficiency(&alternating), 1.0);
        // A step down after a fifth of the series: cut exactly there.
        let step: Vec<f64> = (0..100).map(|t| if t < 20 { 10.0 } else { 1.0 }).collect();
        assert_eq!(mser5(&step), Cut::At(20));
    }

    #[test]
    fn a_series_still_moving_in_its_second_half_is_not_equilibrated() {
        // A transient as long as the run: the minimum lands late.
        let drifting: Vec<f64> = (0..128).map(|t| (-(t as f64) / 400.0).exp()).collect();
        assert_eq!(mser5(&drifting), Cut::NotEquilibrated);
        let step: Vec<f64> = (0..100).map(|t| if t < 70 { 10.0 } else { 1.0 }).collect();
        assert_eq!(mser5(&step), Cut::NotEquilibrated);
        assert_eq!(mser5(&[1.0; 19]), Cut::NotEquilibrated);
    }

    #[test]
    fn a_ratio_of_means_carries_the_error_of_its_numerator() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(6);
        let num: Vec<f64> = (0..4096)
            .map(|_| {
                let noise: f64 = StandardNormal.sample(&mut rng);
                3.0 + 0.5 * noise
            })
            .collect();
        let den = vec![2.0; 4096];
        let ratio = ratio_estimate(&num, &den);
        assert!((ratio.mean - 1.5).abs() < 4.0 * ratio.se, "{ratio:?}");
        // Var(num/2) = 0.25/4 per point.
        let expected = (0.0625_f64 / 4096.0).sqrt();
        assert!((ratio.se / expected - 1.0).abs() < 0.1, "{ratio:?}");
    }

    #[test]
    fn the_replica_error_uses_student_t() {
        assert_eq!(replica_estimate(&[1.0]), None);
        let r = replica_estimate(&[1.0, 2.0, 3.0]).unwrap();
        assert_eq!(r.mean, 2.0);
        assert!((r.se - (1.0_f64 / 3.0).sqrt()).abs() < 1e-12);
        assert!((r.half_width_95 - 4.303 * r.se).abs() < 1e-12);
        assert!((student_t_975(1000) - 1.962).abs() < 0.002);
    }
}
