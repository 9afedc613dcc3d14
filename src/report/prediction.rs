//! A scaling prediction from a study's records, stated as a model with its assumptions:
//! the time of a step at P ranks is
//!
//! T(N, P) = c(N/P)·(N/P)·ι·s·(1 + σ·√(2 ln P)) + m(N/P, P)·α + b(N/P, P)·β + k·⌈log₂ P⌉·r
//!
//! with c the measured compute cost per disk-step (serial and 1-rank runs; a power law
//! in the disks per process, held at its measured ends outside them), σ the per-step
//! jitter (the expected slowest of P ranks is μ(1 + σ√(2 ln P))), inferred from the time
//! the MPI runs waited beyond what the network explains, with the repetitions' spread
//! as the band's low end, ι the measured load imbalance, s the ranks
//! per usable CPU where the runs shared CPUs (1 in a prediction), m and b the messages
//! and bytes the busiest rank sent per step (power laws in N/P and P fitted to the MPI
//! records; m without the all-reduces' rounds), k the collectives per step, and α, β,
//! r the network's latency, inverse bandwidth and all-reduce round (a site's measured
//! or assumed `[network]`). Pure: records and a network band in, a [`Prediction`] out;
//! leaves the figure to `figures::prediction` and the words to [`markdown`].

use std::collections::BTreeMap;

use crate::cluster::network::{Band, Link};
use crate::stats::median;
use crate::study::records::{Record, STATUS_OK};

/// The largest rank count predicted.
pub const MAX_RANKS: u64 = 10_000;
/// Rank counts up to this are the held-out check's fitting set; the rest are predicted.
pub const FIT_UP_TO: u64 = 2;
/// Standard errors each side of a fitted exponent that the band spans.
const BAND_SE: f64 = 2.0;

/// y = exp(log_coefficient)·(N/P)^exponent_n·P^exponent_p, fitted by least squares on
/// logarithms. An exponent whose variable did not vary (or varied only with the other)
/// is not identifiable: it is 0 and says so.
#[derive(Clone, Debug, PartialEq)]
pub struct PowerLaw {
    pub log_coefficient: f64,
    pub exponent_n: f64,
    pub exponent_p: f64,
    pub se_n: f64,
    pub se_p: f64,
    pub fitted_n: bool,
    pub fitted_p: bool,
    pub points: usize,
}

impl PowerLaw {
    /// The law at (N/P, P), each exponent moved by `shift` standard errors.
    fn at(&self, n_per_rank: f64, ranks: f64, shift: f64) -> f64 {
        (self.log_coefficient
            + (self.exponent_n + shift * self.se_n) * n_per_rank.ln()
            + (self.exponent_p + shift * self.se_p) * ranks.ln())
        .exp()
    }

    /// In words: `a·(N/P)^b·P^c`, each exponent with its standard error or "not fitted".
    pub fn describe(&self, unit: &str) -> String {
        let exponent = |fitted: bool, value: f64, se: f64, var: &str| match fitted {
            true => format!("{var}^({value:.2} ± {se:.2})"),
            false => format!("{var}^0 (not identifiable: {var} did not vary apart)"),
        };
        format!(
            "{} {unit} · {} · {}",
            significant(self.log_coefficient.exp()),
            exponent(self.fitted_n, self.exponent_n, self.se_n, "(N/P)"),
            exponent(self.fitted_p, self.exponent_p, self.se_p, "P"),
        )
    }
}

/// Least squares of ln y on ln(N/P) and ln P over `points` (N/P, P, y); points with
/// y ≤ 0 are left out. `None` without a point.
pub fn fit_power_law(points: &[(f64, f64, f64)]) -> Option<PowerLaw> {
    let rows: Vec<[f64; 3]> = points
        .iter()
        .filter(|&&(n, p, y)| y > 0.0 && n > 0.0 && p > 0.0)
        .map(|&(n, p, y)| [n.ln(), p.ln(), y.ln()])
        .collect();
    if rows.is_empty() {
        return None;
    }
    let varies = |i: usize| {
        let first = rows[0][i];
        rows.iter().any(|row| (row[i] - first).abs() > 1e-9)
    };
    let fitted_p = varies(1);
    // ln(N/P) that moves only with ln P (a strong-scaling study of one N) says nothing
    // of its own exponent.
    let fitted_n = varies(0) && !(fitted_p && collinear(&rows));
    let columns: Vec<usize> = [(fitted_n, 0), (fitted_p, 1)]
        .iter()
        .filter(|(used, _)| *used)
        .map(|&(_, i)| i)
        .collect();
    let design: Vec<Vec<f64>> = rows
        .iter()
        .map(|row| {
            std::iter::once(1.0)
                .chain(columns.iter().map(|&i| row[i]))
                .collect()
        })
        .collect();
    let ys: Vec<f64> = rows.iter().map(|row| row[2]).collect();
    let (beta, se) = least_squares(&design, &ys)?;
    let pick = |i: usize| {
        columns
            .iter()
            .position(|&c| c == i)
            .map_or((0.0, 0.0), |k| (beta[k + 1], se[k + 1]))
    };
    let ((exponent_n, se_n), (exponent_p, se_p)) = (pick(0), pick(1));
    Some(PowerLaw {
        log_coefficient: beta[0],
        exponent_n,
        exponent_p,
        se_n,
        se_p,
        fitted_n,
        fitted_p,
        points: rows.len(),
    })
}

/// Whether the first two columns of `rows` lie on one line.
fn collinear(rows: &[[f64; 3]]) -> bool {
    let n = rows.len() as f64;
    let mean = |i: usize| rows.iter().map(|r| r[i]).sum::<f64>() / n;
    let (m0, m1) = (mean(0), mean(1));
    let (mut s00, mut s11, mut s01) = (0.0, 0.0, 0.0);
    for r in rows {
        s00 += (r[0] - m0).powi(2);
        s11 += (r[1] - m1).powi(2);
        s01 += (r[0] - m0) * (r[1] - m1);
    }
    s01 * s01 >= (1.0 - 1e-9) * s00 * s11
}

/// Ordinary least squares: coefficients and their standard errors (0 when there are no
/// more points than coefficients). `None` when the normal equations are singular.
fn least_squares(design: &[Vec<f64>], ys: &[f64]) -> Option<(Vec<f64>, Vec<f64>)> {
    let k = design[0].len();
    // [XᵀX | I] reduced to [I | (XᵀX)⁻¹] by Gauss–Jordan with partial pivoting.
    let mut m = vec![vec![0.0; 2 * k]; k];
    for (i, row) in m.iter_mut().enumerate() {
        for j in 0..k {
            row[j] = design.iter().map(|x| x[i] * x[j]).sum();
        }
        row[k + i] = 1.0;
    }
    for col in 0..k {
        let pivot = (col..k).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))?;
        if m[pivot][col].abs() < 1e-12 {
            return None;
        }
        m.swap(col, pivot);
        let lead = m[col][col];
        m[col].iter_mut().for_each(|v| *v /= lead);
        for row in 0..k {
            if row != col {
                let factor = m[row][col];
                let pivot_row = m[col].clone();
                m[row]
                    .iter_mut()
                    .zip(&pivot_row)
                    .for_each(|(v, p)| *v -= factor * p);
            }
        }
    }
    let xty: Vec<f64> = (0..k)
        .map(|j| design.iter().zip(ys).map(|(x, y)| x[j] * y).sum())
        .collect();
    let beta: Vec<f64> = (0..k)
        .map(|i| (0..k).map(|j| m[i][k + j] * xty[j]).sum())
        .collect();
    let dof = ys.len().saturating_sub(k);
    let variance = match dof {
        0 => 0.0,
        _ => {
            design
                .iter()
                .zip(ys)
                .map(|(x, y)| (y - x.iter().zip(&beta).map(|(a, b)| a * b).sum::<f64>()).powi(2))
                .sum::<f64>()
                / dof as f64
        }
    };
    let se = (0..k).map(|i| (variance * m[i][k + i]).sqrt()).collect();
    Some((beta, se))
}

/// One configuration's successful runs of the step method, summarised.
#[derive(Clone, Debug)]
struct Config {
    n: f64,
    ranks: f64,
    /// Median seconds per step (the slowest rank's, for MPI).
    step_s: f64,
    /// Repetitions' coefficient of variation of the time per step (0 for one).
    spread: f64,
    messages: f64,
    bytes: f64,
    /// Median seconds per step in communication, waiting included (the slowest rank's).
    communication_s: f64,
    collectives: f64,
    imbalance: f64,
    /// Ranks per CPU the study could use, at least 1.
    share: f64,
}

/// The study's configurations that the model reads: serial runs (as 1 rank) and MPI runs
/// of one thread per rank (the model's ranks step on one thread; ranks on several are
/// left out rather than pooled with them).
fn configs(records: &[Record]) -> Vec<Config> {
    let mut groups: BTreeMap<(String, u64, u64), Vec<&Record>> = BTreeMap::new();
    for r in records.iter().filter(|r| {
        r.status == STATUS_OK
            && r.method == "step"
            && (r.backend == "serial" || r.backend == "mpi")
            && r.threads == 1
            && r.steps > 0
            && r.n > 0
    }) {
        groups
            .entry((r.backend.clone(), r.n, r.ranks))
            .or_default()
            .push(r);
    }
    groups
        .into_iter()
        .map(|((_, n, ranks), rows)| {
            let mut steps: Vec<f64> = rows.iter().map(|r| r.wall_s / r.steps as f64).collect();
            let mean = steps.iter().sum::<f64>() / steps.len() as f64;
            let spread = match steps.len() {
                1 => 0.0,
                k => {
                    (steps.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (k - 1) as f64).sqrt()
                        / mean
                }
            };
            let mid = |get: fn(&Record) -> f64| {
                let mut values: Vec<f64> = rows
                    .iter()
                    .map(|r| get(r))
                    .filter(|v| v.is_finite())
                    .collect();
                match values.is_empty() {
                    true => f64::NAN,
                    false => median(&mut values),
                }
            };
            let usable = rows[0].usable_cpus.unwrap_or(ranks).max(1);
            Config {
                n: n as f64,
                ranks: ranks as f64,
                step_s: median(&mut steps),
                spread,
                messages: mid(|r| r.messages_per_step_max),
                bytes: mid(|r| r.bytes_per_step_max),
                communication_s: mid(|r| r.communication_s / r.steps as f64),
                collectives: mid(|r| r.collectives_per_step),
                imbalance: mid(|r| r.load_imbalance),
                share: (ranks as f64 / usable as f64).max(1.0),
            }
        })
        .collect()
}

/// ⌈log₂ P⌉, the rounds of a recursive-doubling all-reduce.
fn rounds(ranks: f64) -> f64 {
    ranks.log2().ceil().max(0.0)
}

/// The fitted model.
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    /// Seconds per disk-step against disks per process (P fixed at 1).
    pub compute: PowerLaw,
    /// The measured disks per process the compute cost was fitted over.
    pub compute_range: (f64, f64),
    /// The least and most measured compute cost over the fitted one.
    pub compute_spread: (f64, f64),
    /// Per-step jitter σ: the band's low end (the repetitions' mean coefficient of
    /// variation of a run's time per step) and its middle and high end (inferred from the
    /// MPI runs' waiting).
    pub jitter: (f64, f64),
    /// Point-to-point messages the busiest rank sent per step (all-reduce rounds taken off).
    pub messages: PowerLaw,
    /// Bytes the busiest rank sent per step.
    pub bytes: PowerLaw,
    pub collectives: f64,
    /// Load imbalance: least, median and most measured.
    pub imbalance: (f64, f64, f64),
    /// The most ranks measured.
    pub largest_ranks: f64,
}

/// One end of the band, or its middle.
#[derive(Clone, Copy, Debug)]
struct Corner {
    compute: f64,
    imbalance: f64,
    jitter: f64,
    link: Link,
    shift_messages: f64,
    shift_bytes: f64,
}

impl Model {
    /// Fits the model to `configs`; `None` without a serial or 1-rank run, or without an
    /// MPI run of 2 ranks or more.
    fn fit(configs: &[Config], link: Link) -> Option<Model> {
        let single: Vec<&Config> = configs.iter().filter(|c| c.ranks == 1.0).collect();
        let costs: Vec<(f64, f64, f64)> =
            single.iter().map(|c| (c.n, 1.0, c.step_s / c.n)).collect();
        let compute = fit_power_law(&costs)?;
        let ratios: Vec<f64> = single
            .iter()
            .map(|c| c.step_s / c.n / compute.at(c.n, 1.0, 0.0))
            .collect();
        let many: Vec<&Config> = configs.iter().filter(|c| c.ranks >= 2.0).collect();
        let collectives = mean(many.iter().map(|c| c.collectives).filter(|v| v.is_finite()))?;
        let messages = fit_power_law(
            &many
                .iter()
                .map(|c| {
                    let peers = c.messages - collectives * rounds(c.ranks);
                    (c.n / c.ranks, c.ranks, peers)
                })
                .collect::<Vec<_>>(),
        )?;
        let bytes = fit_power_law(
            &many
                .iter()
                .map(|c| (c.n / c.ranks, c.ranks, c.bytes))
                .collect::<Vec<_>>(),
        )?;
        let mut imbalance: Vec<f64> = many
            .iter()
            .map(|c| c.imbalance)
            .filter(|v| v.is_finite())
            .collect();
        let imbalance = match imbalance.is_empty() {
            true => (1.0, 1.0, 1.0),
            false => {
                let mid = median(&mut imbalance);
                (imbalance[0], mid, imbalance[imbalance.len() - 1])
            }
        };
        let mut model = Model {
            compute,
            compute_range: min_max(single.iter().map(|c| c.n)),
            compute_spread: min_max(ratios.into_iter()),
            jitter: (0.0, 0.0),
            messages,
            bytes,
            collectives,
            imbalance,
            largest_ranks: many.iter().map(|c| c.ranks).fold(1.0, f64::max),
        };
        let repetitions = mean(single.iter().map(|c| c.spread)).unwrap_or(0.0);
        // A rank that waits beyond the network's time waits for the slowest rank: that
        // wait is μσ√(2 ln P), μ the compute of a step.
        let mut waits: Vec<f64> = many
            .iter()
            .map(|c| {
                let compute = model.compute_s(c.n / c.ranks, 1.0) * c.share;
                let network = model.network_s(c.n / c.ranks, c.ranks, &model.middle(link));
                (c.communication_s - network).max(0.0) / (compute * (2.0 * c.ranks.ln()).sqrt())
            })
            .filter(|sigma| sigma.is_finite())
            .collect();
        let inferred = match waits.is_empty() {
            true => repetitions,
            false => median(&mut waits).max(repetitions),
        };
        model.jitter = (repetitions, inferred);
        Some(model)
    }

    /// Seconds of compute of a step of `per_rank` disks on one process, at `factor`
    /// times the fitted cost per disk-step.
    fn compute_s(&self, per_rank: f64, factor: f64) -> f64 {
        let held = per_rank.clamp(self.compute_range.0, self.compute_range.1);
        self.compute.at(held, 1.0, 0.0) * factor * per_rank
    }

    /// Seconds of a step's messages and all-reduce rounds at `corner`.
    fn network_s(&self, per_rank: f64, ranks: f64, corner: &Corner) -> f64 {
        let link = corner.link;
        self.messages.at(per_rank, ranks, corner.shift_messages) * link.alpha_s
            + self.bytes.at(per_rank, ranks, corner.shift_bytes) * link.beta_s_per_byte
            + self.collectives * rounds(ranks) * link.round_s
    }

    /// Seconds of a step of N disks on P ranks, `share` ranks per CPU, at `corner`.
    fn step_s(&self, n: f64, ranks: f64, share: f64, corner: &Corner) -> f64 {
        let per_rank = n / ranks;
        let compute = self.compute_s(per_rank, corner.compute);
        if ranks <= 1.0 {
            return compute;
        }
        let jitter = 1.0 + corner.jitter * (2.0 * ranks.ln()).sqrt();
        compute * corner.imbalance * share * jitter + self.network_s(per_rank, ranks, corner)
    }

    /// The middle of the band on `link`.
    fn middle(&self, link: Link) -> Corner {
        Corner {
            compute: 1.0,
            imbalance: self.imbalance.1,
            jitter: self.jitter.1,
            link,
            shift_messages: 0.0,
            shift_bytes: 0.0,
        }
    }

    /// Every end of the band: fast and slow compute, least and most imbalance and
    /// jitter, the network's two ends, the exponents ± 2 standard errors.
    fn corners(&self, band: &Band) -> Vec<Corner> {
        let mut corners = Vec::new();
        for compute in [self.compute_spread.0, self.compute_spread.1] {
            for (imbalance, jitter) in [
                (self.imbalance.0, self.jitter.0),
                (self.imbalance.2, self.jitter.1),
            ] {
                for link in [band.fast, band.slow] {
                    for shift_messages in [-BAND_SE, BAND_SE] {
                        for shift_bytes in [-BAND_SE, BAND_SE] {
                            corners.push(Corner {
                                compute,
                                imbalance,
                                jitter,
                                link,
                                shift_messages,
                                shift_bytes,
                            });
                        }
                    }
                }
            }
        }
        corners
    }

    /// Weak (N₀ per rank) or strong (N in all) efficiency at P ranks, at `corner`.
    fn efficiency(&self, scaling: Scaling, size: f64, ranks: f64, corner: &Corner) -> f64 {
        match scaling {
            Scaling::Weak => {
                self.step_s(size, 1.0, 1.0, corner) / self.step_s(size * ranks, ranks, 1.0, corner)
            }
            Scaling::Strong => {
                self.step_s(size, 1.0, 1.0, corner)
                    / (ranks * self.step_s(size, ranks, 1.0, corner))
            }
        }
    }
}

/// Which scaling a curve predicts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scaling {
    /// N₀ disks per rank.
    Weak,
    /// N disks in all.
    Strong,
}

/// A predicted efficiency with its band.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Predicted {
    pub ranks: u64,
    pub low: f64,
    pub mid: f64,
    pub high: f64,
}

/// A measured configuration beside the model's time for it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Checked {
    pub n: u64,
    pub ranks: u64,
    pub measured_s: f64,
    pub modelled_s: f64,
}

impl Checked {
    /// modelled / measured − 1.
    pub fn error(&self) -> f64 {
        self.modelled_s / self.measured_s - 1.0
    }
}

/// What the model says, and from what.
#[derive(Clone, Debug, PartialEq)]
pub struct Prediction {
    /// Fitted on every configuration.
    pub model: Model,
    pub network: Band,
    /// Disks per rank of the weak curve, and disks of the strong curve.
    pub weak_size: f64,
    pub strong_size: f64,
    pub weak: Vec<Predicted>,
    /// Only where every rank holds a disk.
    pub strong: Vec<Predicted>,
    /// Fitted on P ≤ [`FIT_UP_TO`], then each larger measured configuration predicted;
    /// empty when the study has none.
    pub held_out: Vec<Checked>,
    /// The refitted model against every MPI configuration (the ranks sharing CPUs as they
    /// did).
    pub fitted: Vec<Checked>,
    /// Efficiencies of the measured MPI configurations that have a 1-process run to
    /// compare with, beside the refitted model's for them as they ran.
    pub measured: Vec<Efficiency>,
}

/// A measured configuration's efficiency and the model's for it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Efficiency {
    pub scaling: Scaling,
    pub ranks: u64,
    pub measured: f64,
    pub modelled: f64,
}

/// The measured efficiencies: weak against the 1-process run of N/P disks, strong
/// against that of N disks, each beside `model`'s on `link`.
fn efficiencies(configs: &[Config], model: &Model, corner: &Corner) -> Vec<Efficiency> {
    let single = |n: f64| configs.iter().find(|c| c.ranks == 1.0 && c.n == n);
    let mut out = Vec::new();
    for c in configs.iter().filter(|c| c.ranks >= 2.0) {
        let modelled = model.step_s(c.n, c.ranks, c.share, corner);
        for (scaling, n, times) in [
            (Scaling::Weak, c.n / c.ranks, 1.0),
            (Scaling::Strong, c.n, c.ranks),
        ] {
            if let Some(one) = single(n) {
                out.push(Efficiency {
                    scaling,
                    ranks: c.ranks as u64,
                    measured: one.step_s / (times * c.step_s),
                    modelled: model.step_s(n, 1.0, 1.0, corner) / (times * modelled),
                });
            }
        }
    }
    out
}

impl Prediction {
    /// The most ranks predicted over the most measured.
    pub fn extrapolation(&self) -> f64 {
        MAX_RANKS as f64 / self.model.largest_ranks
    }

    /// The largest held-out error, in magnitude.
    pub fn held_out_error(&self) -> Option<f64> {
        self.held_out
            .iter()
            .map(|c| c.error().abs())
            .max_by(f64::total_cmp)
    }
}

/// The rank counts predicted: powers of 2 to 8192, then 10⁴.
pub fn predicted_ranks() -> Vec<u64> {
    (0..14).map(|k| 1u64 << k).chain([MAX_RANKS]).collect()
}

/// The prediction of `records` on `network`, or why there is none.
pub fn predict(records: &[Record], network: &Band) -> Result<Prediction, String> {
    let configs = configs(records);
    let link = mean_link(network);
    let model = Model::fit(&configs, link).ok_or_else(|| {
        "a prediction needs runs of the step method on 1 process (serial, or MPI with 1 \
         rank) and MPI runs of 2 ranks or more, with their message counts (records of \
         schema version 9 or later); add them to the study (docs/clusters.md, Predicting \
         scaling)"
            .to_owned()
    })?;
    let mpi: Vec<&Config> = configs.iter().filter(|c| c.ranks >= 2.0).collect();
    let weak_size = mpi.iter().map(|c| c.n / c.ranks).fold(0.0, f64::max);
    let strong_size = mpi.iter().map(|c| c.n).fold(0.0, f64::max);
    let corners = model.corners(network);
    let middle = model.middle(link);
    let curve = |scaling: Scaling, size: f64| {
        predicted_ranks()
            .into_iter()
            .filter(|&p| scaling == Scaling::Weak || p as f64 <= size)
            .map(|ranks| {
                let p = ranks as f64;
                let (low, high) = min_max(
                    corners
                        .iter()
                        .map(|c| model.efficiency(scaling, size, p, c)),
                );
                Predicted {
                    ranks,
                    low,
                    mid: model.efficiency(scaling, size, p, &middle),
                    high,
                }
            })
            .collect()
    };
    let check = |model: &Model, corner: &Corner, config: &Config| Checked {
        n: config.n as u64,
        ranks: config.ranks as u64,
        measured_s: config.step_s,
        modelled_s: model.step_s(config.n, config.ranks, config.share, corner),
    };
    let training: Vec<Config> = configs
        .iter()
        .filter(|c| c.ranks <= FIT_UP_TO as f64)
        .cloned()
        .collect();
    let held_out = match Model::fit(&training, link) {
        Some(early) => configs
            .iter()
            .filter(|c| c.ranks > FIT_UP_TO as f64)
            .map(|c| check(&early, &early.middle(link), c))
            .collect(),
        None => Vec::new(),
    };
    Ok(Prediction {
        weak: curve(Scaling::Weak, weak_size),
        strong: curve(Scaling::Strong, strong_size),
        fitted: mpi.iter().map(|c| check(&model, &middle, c)).collect(),
        measured: efficiencies(&configs, &model, &middle),
        held_out,
        model,
        network: network.clone(),
        weak_size,
        strong_size,
    })
}

/// The band's middle: the geometric mean of its ends.
fn mean_link(band: &Band) -> Link {
    let geo = |a: f64, b: f64| (a * b).sqrt();
    Link {
        alpha_s: geo(band.fast.alpha_s, band.slow.alpha_s),
        beta_s_per_byte: geo(band.fast.beta_s_per_byte, band.slow.beta_s_per_byte),
        round_s: geo(band.fast.round_s, band.slow.round_s),
    }
}

fn mean(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (sum, count) = values.fold((0.0, 0usize), |(s, k), v| (s + v, k + 1));
    (count > 0).then(|| sum / count as f64)
}

fn min_max(values: impl Iterator<Item = f64>) -> (f64, f64) {
    values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    })
}

/// Three significant digits in scientific notation where needed.
fn significant(value: f64) -> String {
    if (0.01..10_000.0).contains(&value.abs()) {
        format!("{value:.3}")
    } else {
        format!("{value:.2e}")
    }
}

/// A percentage with one decimal.
fn percent(value: f64) -> String {
    format!("{:.1}%", 100.0 * value)
}

/// The assumptions, one sentence each: the figure's caption and the section's list.
pub fn assumptions(prediction: &Prediction) -> Vec<String> {
    let model = &prediction.model;
    vec![
        format!("network: {}", prediction.network.label),
        "one rank per core at scale (the measured runs shared CPUs where they had more ranks than CPUs; their check counts that)".to_owned(),
        format!(
            "compute cost measured on this machine over {}–{} disks per process, held at its ends outside them",
            model.compute_range.0, model.compute_range.1
        ),
        format!(
            "per-step jitter σ {} (from the MPI runs' waiting; low end {}, the repetitions' spread), the slowest of P ranks μ(1 + σ√(2 ln P)): this machine's noise, not a cluster's",
            percent(model.jitter.1),
            percent(model.jitter.0)
        ),
        format!(
            "load imbalance as measured ({:.3}–{:.3}), not growing with P",
            model.imbalance.0, model.imbalance.2
        ),
        "no network contention, no topology: every message costs α + bytes·β".to_owned(),
    ]
}

/// The prediction as markdown: what was fitted, the curves at a few rank counts, the
/// held-out check, the extrapolation factor and the assumptions. `figure` is the file
/// name of its figure, if drawn.
pub fn markdown(prediction: &Prediction, figure: Option<&str>) -> String {
    let model = &prediction.model;
    let mut out = String::from("## Predicted scaling (a model, not a measurement)\n\n");
    if let Some(figure) = figure {
        out += &format!("![measured and modelled efficiency]({figure})\n\n");
    }
    out += &fitted_table(model);
    out += &format!(
        "Weak scaling at {} disks per rank, strong scaling of {} disks; efficiency as \
         low–high (middle):\n\n",
        prediction.weak_size, prediction.strong_size
    );
    out += &efficiency_table(prediction);
    out += &format!(
        "\nExtrapolation factor: {} predicted ranks / {} measured = {:.0}×. A model fitted \
         on a few ranks of one machine says what its terms imply, not what a cluster will \
         do at that scale.\n\n",
        MAX_RANKS,
        model.largest_ranks,
        prediction.extrapolation()
    );
    match prediction.held_out_error() {
        Some(worst) => {
            out += &format!(
                "Held-out check: fitted on P ≤ {FIT_UP_TO} only, then each larger measured \
                 configuration predicted (largest error {}):\n\n",
                percent(worst)
            );
            out += &checks_table(&prediction.held_out);
        }
        None => {
            out += &format!(
                "Held-out check: none (no measured configuration above {FIT_UP_TO} ranks, \
                 or too few at or below it to fit).\n\n"
            )
        }
    }
    out += "Assumptions:\n\n";
    for assumption in assumptions(prediction) {
        out += &format!("- {assumption}\n");
    }
    out
}

/// What was fitted to the records, part by part of a step.
fn fitted_table(model: &Model) -> String {
    let mut out = String::from("| part of a step | fitted to the records |\n| --- | --- |\n");
    out += &format!(
        "| compute per disk-step | {} |\n",
        model.compute.describe("s")
    );
    out += &format!(
        "| messages per step, busiest rank (less all-reduce rounds) | {} |\n",
        model.messages.describe("")
    );
    out += &format!(
        "| bytes per step, busiest rank | {} |\n",
        model.bytes.describe("B")
    );
    out += &format!(
        "| collectives per step | {:.2}, each ⌈log₂ P⌉ rounds |\n",
        model.collectives
    );
    out += &format!(
        "| load imbalance | {:.3} (measured {:.3}–{:.3}) |\n\n",
        model.imbalance.1, model.imbalance.0, model.imbalance.2
    );
    out
}

/// The weak and strong efficiency at a few rank counts, each as low–high (middle).
fn efficiency_table(prediction: &Prediction) -> String {
    let mut out =
        String::from("| ranks P | weak efficiency | strong efficiency |\n| ---: | ---: | ---: |\n");
    let cell = |curve: &[Predicted], ranks: u64| {
        curve
            .iter()
            .find(|p| p.ranks == ranks)
            .map_or("—".to_owned(), |p| {
                format!(
                    "{}–{} ({})",
                    percent(p.low),
                    percent(p.high),
                    percent(p.mid)
                )
            })
    };
    for ranks in [8, 64, 1024, 8192, MAX_RANKS] {
        out += &format!(
            "| {ranks} | {} | {} |\n",
            cell(&prediction.weak, ranks),
            cell(&prediction.strong, ranks)
        );
    }
    out
}

/// The held-out check: each configuration measured and predicted, with the error.
fn checks_table(checks: &[Checked]) -> String {
    let mut out = String::from(
        "| n | ranks | measured ms/step | predicted ms/step | error |\n| ---: | ---: | ---: | ---: | ---: |\n",
    );
    for c in checks {
        out += &format!(
            "| {} | {} | {:.4} | {:.4} | {:+.1}% |\n",
            c.n,
            c.ranks,
            1e3 * c.measured_s,
            1e3 * c.modelled_s,
            100.0 * c.error()
        );
    }
    out + "\n"
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cluster::network::assumed_band;
    use crate::study::environment::Environment;
    use crate::study::records;

    #[test]
    fn a_power_law_is_fitted_with_its_exponents_and_unvaried_ones_are_not() {
        let points: Vec<(f64, f64, f64)> =
            [(1000.0, 2.0), (4000.0, 2.0), (1000.0, 8.0), (4000.0, 4.0)]
                .iter()
                .map(|&(n, p)| (n, p, 3.0 * f64::powf(n, 0.5) * f64::powf(p, 0.25)))
                .collect();
        let law = fit_power_law(&points).unwrap();
        assert!((law.exponent_n - 0.5).abs() < 1e-9 && (law.exponent_p - 0.25).abs() < 1e-9);
        assert!((law.log_coefficient.exp() - 3.0).abs() < 1e-9);
        assert!(law.fitted_n && law.fitted_p);
        // One rank count: the P exponent cannot be told, and is 0.
        let two = fit_power_law(&points[..2]).unwrap();
        assert!(!two.fitted_p && two.exponent_p == 0.0);
        // One N, strong scaling: N/P moves only with P, so only P's exponent is fitted.
        let strong: Vec<(f64, f64, f64)> = [2.0, 4.0, 8.0]
            .iter()
            .map(|&p| (8000.0 / p, p, 5.0 * f64::powf(p, 0.5)))
            .collect();
        let law = fit_power_law(&strong).unwrap();
        assert!(!law.fitted_n && (law.exponent_p - 0.5).abs() < 1e-9);
    }

    /// Rows of a study whose runs follow the model exactly: c = 40 ns per disk-step,
    /// 4 peer messages and 2 collectives per step, bytes ∝ √(N/P·P), α = 2 µs,
    /// β = 0.1 ns/B, ranks alone on their CPUs.
    fn exact_study(link: Link) -> Vec<Record> {
        let environment = Environment::capture();
        let mut rows = Vec::new();
        for n_per_rank in [2000u64, 8000] {
            for ranks in [1u64, 2, 4, 8] {
                let n = n_per_rank * ranks;
                let (p, per) = (ranks as f64, n_per_rank as f64);
                let messages = 4.0 + 2.0 * rounds(p);
                let bytes = 100.0 * (per * p).sqrt();
                let step = 40e-9 * per
                    + match ranks {
                        1 => 0.0,
                        _ => {
                            4.0 * link.alpha_s
                                + bytes * link.beta_s_per_byte
                                + 2.0 * rounds(p) * link.round_s
                        }
                    };
                let context = records::serial_context(&environment);
                let mut r = Record::failed(&context, STATUS_OK, String::new());
                r.method = "step".to_owned();
                r.backend = if ranks == 1 { "serial" } else { "mpi" }.to_owned();
                r.n = n;
                r.ranks = ranks;
                r.steps = 100;
                r.wall_s = step * 100.0;
                r.usable_cpus = Some(64);
                if ranks > 1 {
                    r.messages_per_step_max = messages;
                    r.bytes_per_step_max = bytes;
                    r.collectives_per_step = 2.0;
                    r.load_imbalance = 1.0;
                }
                rows.push(r);
            }
        }
        rows
    }

    #[test]
    fn runs_that_follow_the_model_are_predicted_before_they_are_used() {
        let link = Link {
            alpha_s: 2e-6,
            beta_s_per_byte: 1e-10,
            round_s: 2e-6,
        };
        let band = Band {
            fast: link,
            slow: link,
            label: "test".into(),
        };
        let prediction = predict(&exact_study(link), &band).unwrap();
        let model = &prediction.model;
        assert!((model.bytes.exponent_n - 0.5).abs() < 1e-6);
        assert!((model.bytes.exponent_p - 0.5).abs() < 1e-6);
        assert!(model.messages.exponent_p.abs() < 1e-6);
        // Fitted on P ≤ 2 (the P exponents unknown, taken as 0), P = 4 and 8 are
        // predicted with only the bytes' growth in P missing.
        assert_eq!(prediction.held_out.len(), 4);
        assert!(prediction.held_out_error().unwrap() < 0.05);
        for checked in &prediction.fitted {
            assert!(checked.error().abs() < 1e-6, "{checked:?}");
        }
        assert_eq!(prediction.extrapolation(), 1250.0);
        let weak_at_max = prediction.weak.last().unwrap();
        assert_eq!(weak_at_max.ranks, MAX_RANKS);
        assert!(weak_at_max.low <= weak_at_max.mid && weak_at_max.mid <= weak_at_max.high);
        // The efficiency falls as ranks grow: the all-reduce's rounds and the bytes grow.
        assert!(
            prediction
                .weak
                .windows(2)
                .all(|w| w[1].mid <= w[0].mid + 1e-12)
        );
        // Strong scaling stops where a rank would hold no disk.
        assert!(
            prediction
                .strong
                .iter()
                .all(|p| p.ranks as f64 <= prediction.strong_size)
        );
    }

    #[test]
    fn a_slower_network_lowers_the_band_and_the_words_say_what_was_assumed() {
        let link = Link {
            alpha_s: 2e-6,
            beta_s_per_byte: 1e-10,
            round_s: 2e-6,
        };
        let prediction = predict(&exact_study(link), &assumed_band()).unwrap();
        let at = prediction.weak.last().unwrap();
        assert!(at.low < at.high);
        let text = markdown(&prediction, Some("prediction.png"));
        assert!(text.contains("![measured and modelled efficiency](prediction.png)"));
        assert!(text.contains("assumed network (none measured)"));
        assert!(text.contains("Extrapolation factor: 10000 predicted ranks / 8 measured = 1250×"));
        assert!(text.contains("Held-out check: fitted on P ≤ 2 only"));
    }

    #[test]
    fn a_study_without_mpi_runs_has_no_prediction_and_says_what_it_needs() {
        let link = assumed_band().fast;
        let serial: Vec<Record> = exact_study(link)
            .into_iter()
            .filter(|r| r.ranks == 1)
            .collect();
        let err = predict(&serial, &assumed_band()).unwrap_err();
        assert!(err.contains("MPI runs of 2 ranks or more"), "{err}");
    }
}
