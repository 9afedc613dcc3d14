//! Scaling analysis of a study's records: medians and spreads per configuration,
//! speedup, parallel efficiency, the Karp–Flatt serial fraction and an Amdahl fit.
//! Pure: records in, numbers out.

use std::collections::BTreeMap;

use crate::records::{Record, STATUS_OK};
use crate::results::median;

/// One backend at one worker count.
#[derive(Clone, Debug, PartialEq)]
pub struct Point {
    pub workers: u64,
    pub reps: usize,
    pub median_s: f64,
    pub min_s: f64,
    pub max_s: f64,
    /// Median steps per second.
    pub fps: f64,
    pub oversubscribed: bool,
    /// T(baseline) / T(p), with [`Setup::baseline`].
    pub speedup: f64,
    /// speedup / p.
    pub efficiency: f64,
    /// Karp–Flatt e(p) = (1/S − 1/p)/(1 − 1/p); undefined (NaN) at p = 1.
    pub karp_flatt: f64,
}

/// Amdahl's law T(p) = T₁·(f + (1 − f)/p), fitted by least squares as T = a + b/p.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AmdahlFit {
    /// Serial fraction f = a/(a + b).
    pub serial_fraction: f64,
    /// Coefficient of determination of the fit on the median times.
    pub r_squared: f64,
}

/// What a backend's speedups are measured against.
#[derive(Clone, Debug, PartialEq)]
pub enum Baseline {
    /// The serial backend's median time for the same setup.
    Serial(f64),
    /// The same backend's median time at one worker (no serial run in the study).
    OneWorker(f64),
    /// Neither was measured: speedups are not defined.
    Missing,
}

#[derive(Clone, Debug, PartialEq)]
pub struct BackendScaling {
    pub backend: String,
    pub baseline: Baseline,
    /// By worker count.
    pub points: Vec<Point>,
    /// With at least two worker counts.
    pub amdahl: Option<AmdahlFit>,
}

/// One physical setup (same scene, n, steps, dt, packing, seed, broad phase) under every
/// backend that ran it.
#[derive(Clone, Debug, PartialEq)]
pub struct Setup {
    pub scene: String,
    pub n: u64,
    pub steps: u64,
    pub dt: f64,
    pub packing: f64,
    pub broadphase: String,
    /// Serial first, then rayon, then MPI.
    pub backends: Vec<BackendScaling>,
    /// Distinct final-state hashes among the successful runs (1 means all agree).
    pub distinct_hashes: usize,
}

/// The successful records grouped into setups, each analysed per backend.
pub fn analyse(records: &[Record]) -> Vec<Setup> {
    // In order of first appearance, which is the manifest's order.
    let mut order: Vec<String> = Vec::new();
    let mut setups: BTreeMap<String, Vec<&Record>> = BTreeMap::new();
    for record in records.iter().filter(|r| r.status == STATUS_OK) {
        let key = record.setup_key();
        if !setups.contains_key(&key) {
            order.push(key.clone());
        }
        setups.entry(key).or_default().push(record);
    }
    order
        .iter()
        .map(|key| analyse_setup(&setups[key]))
        .collect()
}

fn backend_rank(backend: &str) -> usize {
    match backend {
        "serial" => 0,
        "rayon" => 1,
        "mpi" => 2,
        _ => 3,
    }
}

fn analyse_setup(rows: &[&Record]) -> Setup {
    let mut by_backend: BTreeMap<(usize, String), BTreeMap<u64, Vec<&Record>>> = BTreeMap::new();
    for row in rows {
        by_backend
            .entry((backend_rank(&row.backend), row.backend.clone()))
            .or_default()
            .entry(row.workers)
            .or_default()
            .push(row);
    }
    let serial_median = by_backend
        .iter()
        .find(|((_, name), _)| name == "serial")
        .and_then(|(_, points)| points.get(&1))
        .map(|runs| median(&mut runs.iter().map(|r| r.wall_s).collect::<Vec<_>>()));
    let backends = by_backend
        .into_iter()
        .map(|((_, backend), points)| {
            let medians: BTreeMap<u64, f64> = points
                .iter()
                .map(|(&p, runs)| {
                    (
                        p,
                        median(&mut runs.iter().map(|r| r.wall_s).collect::<Vec<_>>()),
                    )
                })
                .collect();
            let baseline = match (serial_median, medians.get(&1)) {
                (Some(t), _) => Baseline::Serial(t),
                (None, Some(&t)) => Baseline::OneWorker(t),
                (None, None) => Baseline::Missing,
            };
            let t_base = match baseline {
                Baseline::Serial(t) | Baseline::OneWorker(t) => t,
                Baseline::Missing => f64::NAN,
            };
            let points: Vec<Point> = points
                .iter()
                .map(|(&workers, runs)| {
                    let mut times: Vec<f64> = runs.iter().map(|r| r.wall_s).collect();
                    let median_s = median(&mut times);
                    let speedup = t_base / median_s;
                    let p = workers as f64;
                    Point {
                        workers,
                        reps: runs.len(),
                        median_s,
                        min_s: times[0],
                        max_s: times[times.len() - 1],
                        fps: median(&mut runs.iter().map(|r| r.fps).collect::<Vec<_>>()),
                        oversubscribed: runs.iter().any(|r| r.oversubscribed),
                        speedup,
                        efficiency: speedup / p,
                        karp_flatt: if workers > 1 {
                            (1.0 / speedup - 1.0 / p) / (1.0 - 1.0 / p)
                        } else {
                            f64::NAN
                        },
                    }
                })
                .collect();
            let amdahl = amdahl_fit(&points);
            BackendScaling {
                backend,
                baseline,
                points,
                amdahl,
            }
        })
        .collect();
    let first = rows[0];
    let mut hashes: Vec<&str> = rows.iter().map(|r| r.state_hash.as_str()).collect();
    hashes.sort_unstable();
    hashes.dedup();
    Setup {
        scene: first.scene.clone(),
        n: first.n,
        steps: first.steps,
        dt: first.dt,
        packing: first.packing,
        broadphase: first.broadphase.clone(),
        backends,
        distinct_hashes: hashes.len(),
    }
}

/// Least squares of the medians on T = a + b·(1/p); f = a/(a + b). None with fewer than
/// two worker counts or a degenerate fit.
pub fn amdahl_fit(points: &[Point]) -> Option<AmdahlFit> {
    if points.len() < 2 {
        return None;
    }
    let xs: Vec<f64> = points.iter().map(|p| 1.0 / p.workers as f64).collect();
    let ys: Vec<f64> = points.iter().map(|p| p.median_s).collect();
    let n = xs.len() as f64;
    let (mean_x, mean_y) = (xs.iter().sum::<f64>() / n, ys.iter().sum::<f64>() / n);
    let sxx: f64 = xs.iter().map(|x| (x - mean_x).powi(2)).sum();
    let sxy: f64 = xs
        .iter()
        .zip(&ys)
        .map(|(x, y)| (x - mean_x) * (y - mean_y))
        .sum();
    if sxx == 0.0 {
        return None;
    }
    let b = sxy / sxx;
    let a = mean_y - b * mean_x;
    let syy: f64 = ys.iter().map(|y| (y - mean_y).powi(2)).sum();
    let residual: f64 = xs
        .iter()
        .zip(&ys)
        .map(|(x, y)| (y - (a + b * x)).powi(2))
        .sum();
    let r_squared = if syy > 0.0 { 1.0 - residual / syy } else { 1.0 };
    let serial_fraction = a / (a + b);
    serial_fraction.is_finite().then_some(AmdahlFit {
        serial_fraction,
        r_squared,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(workers: u64, median_s: f64) -> Point {
        Point {
            workers,
            reps: 1,
            median_s,
            min_s: median_s,
            max_s: median_s,
            fps: 1.0 / median_s,
            oversubscribed: false,
            speedup: f64::NAN,
            efficiency: f64::NAN,
            karp_flatt: f64::NAN,
        }
    }

    #[test]
    fn amdahl_fit_recovers_the_serial_fraction_of_exact_amdahl_times() {
        // T(p) = 10·(0.2 + 0.8/p).
        let points: Vec<Point> = [1, 2, 4, 8]
            .iter()
            .map(|&p| point(p, 10.0 * (0.2 + 0.8 / p as f64)))
            .collect();
        let fit = amdahl_fit(&points).unwrap();
        assert!((fit.serial_fraction - 0.2).abs() < 1e-12, "{fit:?}");
        assert!((fit.r_squared - 1.0).abs() < 1e-12);
        assert!(amdahl_fit(&points[..1]).is_none());
    }
}
