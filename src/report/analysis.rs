//! Scaling analysis of a study's records: medians with seeded bootstrap intervals and
//! spreads per configuration, speedup, parallel efficiency, and the Karp–Flatt serial
//! fraction and an Amdahl fit where they mean something (at least
//! [`MIN_WORKER_COUNTS`] worker counts, a serial fraction within [0, 1]). Pure: records
//! in, numbers out.

use std::collections::BTreeMap;

use polars::prelude::{
    Column, DataFrame, DataType, IntoLazy, PolarsResult, StringChunked, col, len,
};

use crate::run::backend_kind::BackendKind;
use crate::stats::median_interval;
use crate::study::manifest::Scaling;
use crate::study::records::{self, Record, STATUS_OK};

/// One backend at one worker count.
#[derive(Clone, Debug, PartialEq)]
pub struct Point {
    pub workers: u64,
    pub reps: usize,
    pub median_s: f64,
    /// The 95% bootstrap interval of the median ([`TIMING_CONFIDENCE`], seeded: the same
    /// records give the same interval).
    pub median_ci_s: [f64; 2],
    pub min_s: f64,
    pub max_s: f64,
    /// Median steps per second.
    pub fps: f64,
    /// Median frames per second with drawing of the runs that drew every step (NaN
    /// when none did).
    pub fps_with_drawing: f64,
    pub oversubscribed: bool,
    /// MPI: median messages and bytes per step of the rank that sent most (NaN for
    /// serial and rayon, and in files older than schema version 9).
    pub messages_per_step: f64,
    pub bytes_per_step: f64,
    /// Strong scaling: T(baseline) / T(p), with [`Setup::baseline`]. Weak scaling: the
    /// scaled speedup p·E(p).
    pub speedup: f64,
    /// Strong scaling: speedup / p. Weak scaling: T(1, N₀) / T(p, p·N₀).
    pub efficiency: f64,
    /// Karp–Flatt e(p) = (1/S − 1/p)/(1 − 1/p); NaN at p = 1, for weak scaling, where
    /// the backend has fewer than [`MIN_WORKER_COUNTS`] worker counts, and where it falls
    /// outside [0, 1] (then the model does not describe the times).
    pub karp_flatt: f64,
}

impl Point {
    /// A median under [`TOO_SHORT_S`] of stepping: timer resolution, start-up effects and
    /// the scheduler weigh on it (flagged, with a suggestion to run more steps).
    pub fn too_short(&self) -> bool {
        self.median_s < TOO_SHORT_S
    }
}

/// Runs whose median stepping time is under this many seconds are flagged.
pub const TOO_SHORT_S: f64 = 0.01;

/// Confidence of the median's bootstrap interval.
pub const TIMING_CONFIDENCE: f64 = 0.95;

/// Seed of the median's bootstrap interval.
pub const TIMING_SEED: u64 = 0x7469_6d65;

/// Fewest distinct worker counts from which a serial fraction is shown: two points fit
/// any two-parameter law exactly (R² = 1 says nothing).
pub const MIN_WORKER_COUNTS: usize = 3;

/// Amdahl's law T(p) = T₁·(f + (1 − f)/p), fitted by least squares as T = a + b/p.
#[derive(Clone, Debug, PartialEq)]
pub struct AmdahlFit {
    /// Serial fraction f = a/(a + b), within [0, 1].
    pub serial_fraction: f64,
    /// Coefficient of determination of the fit on the median times.
    pub r_squared: f64,
    /// (T − T_fit)/T_fit of each point, by worker count.
    pub residuals: Vec<(u64, f64)>,
}

/// Why a backend's serial fraction is not shown.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NoFit {
    /// Weak scaling: Amdahl's law and Karp–Flatt describe strong scaling.
    Weak,
    /// Fewer than [`MIN_WORKER_COUNTS`] worker counts.
    FewWorkerCounts(usize),
    /// The least-squares serial fraction fell outside [0, 1] (or was undefined): the
    /// times do not follow the law (oversubscription, communication that grows with p).
    OutsideUnitInterval(f64),
}

impl NoFit {
    /// Why not, as a sentence for the report.
    pub fn reason(&self) -> String {
        match self {
            NoFit::Weak => "weak scaling (Amdahl's law describes strong scaling)".to_owned(),
            NoFit::FewWorkerCounts(counts) => format!(
                "{counts} worker count(s), fewer than {MIN_WORKER_COUNTS}: two points fit any \
                 two-parameter law exactly"
            ),
            NoFit::OutsideUnitInterval(f) => format!(
                "the least-squares serial fraction is {f:.3}, outside [0, 1]: Amdahl's law does \
                 not describe these times"
            ),
        }
    }
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

/// One scaling curve: a backend's runs at one number of threads per MPI rank, on one
/// number of nodes.
#[derive(Clone, Debug, PartialEq)]
pub struct BackendScaling {
    pub backend: String,
    /// The threads each MPI rank stepped on ([`Record::threads_per_rank`]): 1 but for
    /// MPI ranks on several threads each.
    pub threads_per_rank: u64,
    /// The nodes its ranks spread over ([`Record::nodes`]): 1 but for MPI runs placed
    /// on several.
    pub nodes: u64,
    pub baseline: Baseline,
    /// By worker count.
    pub points: Vec<Point>,
    /// The Amdahl fit, or why it is not shown.
    pub amdahl: Result<AmdahlFit, NoFit>,
}

impl BackendScaling {
    /// The curve's name in tables and legends ([`records::curve_label`]).
    pub fn label(&self) -> String {
        records::curve_label(&self.backend, self.threads_per_rank, self.nodes)
    }
}

/// One physical setup (same scene, n, steps, dt, packing, seed, broad phase) under every
/// backend that ran it; for weak scaling, the setups whose n is N₀ × workers.
#[derive(Clone, Debug, PartialEq)]
pub struct Setup {
    pub scene: String,
    pub scaling: Scaling,
    /// Disks; for weak scaling N₀, the disks per worker.
    pub n: u64,
    pub steps: u64,
    pub dt: f64,
    pub packing: f64,
    pub broadphase: String,
    /// Whether its runs drew every step offscreen (`draw = true`).
    pub drawn: bool,
    /// The other values its configurations set (`method=event`, `tc=0`, ...), which tell
    /// it apart from setups of the same scene, n, steps, dt and packing.
    pub settings: Vec<String>,
    /// Serial first, then rayon, then MPI (by threads per rank).
    pub backends: Vec<BackendScaling>,
    /// The most distinct final-state hashes among the successful runs of one physical
    /// setup (1 means all backends agree).
    pub distinct_hashes: usize,
}

impl Setup {
    /// The worker counts measured by any backend, ascending, each once.
    pub fn worker_counts(&self) -> Vec<u64> {
        let mut workers: Vec<u64> = self
            .backends
            .iter()
            .flat_map(|b| b.points.iter().map(|p| p.workers))
            .collect();
        workers.sort_unstable();
        workers.dedup();
        workers
    }

    /// Whether there is any scaling to show: more than one backend-and-workers point.
    pub fn scales(&self) -> bool {
        self.backends.iter().map(|b| b.points.len()).sum::<usize>() > 1
    }
}

/// The settings a setup's description shows by their own fields.
const DESCRIBED: [&str; 5] = ["steps", "dt", "packing", "broadphase", "draw"];

/// The successful records grouped into setups (in the manifest's order), each analysed
/// per backend. The grouping, medians and spreads are polars aggregations.
pub fn analyse(records: &[Record]) -> anyhow::Result<Vec<Setup>> {
    let ok: Vec<Record> = records
        .iter()
        .filter(|r| r.status == STATUS_OK)
        .cloned()
        .collect();
    let series_keys: Vec<String> = ok.iter().map(Record::series_key).collect();
    let frame = keyed_frame(&ok, &series_keys)?;
    let points = per_configuration(&frame)?;
    let hashes = distinct_hashes_per_series(&frame)?;
    let first_of_series = |series: &str| {
        let row = series_keys.iter().position(|key| key == series);
        &ok[row.expect("every series comes from a record")]
    };
    let mut setups: Vec<Setup> = Vec::new();
    let mut series_order: Vec<String> = Vec::new();
    for (series, (backend, threads_per_rank, nodes), point) in points {
        let index = match series_order.iter().position(|s| *s == series) {
            Some(index) => index,
            None => {
                let first = first_of_series(&series);
                let scaling = first.scaling();
                series_order.push(series.clone());
                setups.push(Setup {
                    scene: first.scene.clone(),
                    scaling,
                    n: match scaling {
                        Scaling::Strong => first.n,
                        Scaling::Weak => first.n / first.workers.max(1),
                    },
                    steps: first.steps,
                    dt: first.dt,
                    packing: first.packing,
                    broadphase: first.broadphase.clone(),
                    drawn: first.drew(),
                    settings: first.settings(&DESCRIBED),
                    backends: Vec::new(),
                    distinct_hashes: hashes.get(&series).copied().unwrap_or(1),
                });
                setups.len() - 1
            }
        };
        let setup = &mut setups[index];
        let curve = |b: &&mut BackendScaling| {
            b.backend == backend && b.threads_per_rank == threads_per_rank && b.nodes == nodes
        };
        match setup.backends.iter_mut().find(curve) {
            Some(scaling) => scaling.points.push(point),
            None => setup.backends.push(BackendScaling {
                backend,
                threads_per_rank,
                nodes,
                baseline: Baseline::Missing,
                points: vec![point],
                amdahl: Err(NoFit::FewWorkerCounts(0)),
            }),
        }
    }
    for setup in &mut setups {
        derive_scaling(setup);
    }
    Ok(setups)
}

/// The records as a polars table, with each row's series (what one scaling curve
/// shares), physical setup (what must end in the same state), threads per rank and nodes
/// (which curve of its backend) as key columns.
fn keyed_frame(records: &[Record], series_keys: &[String]) -> PolarsResult<DataFrame> {
    let mut frame = records::to_frame(records)?;
    let setup: Vec<String> = records.iter().map(Record::setup_key).collect();
    let per_rank: Vec<u64> = records.iter().map(Record::threads_per_rank).collect();
    frame.with_column(Column::new("series".into(), series_keys))?;
    frame.with_column(Column::new("setup".into(), setup))?;
    frame.with_column(Column::new("threads_per_rank".into(), per_rank))?;
    let nodes: Vec<u64> = records.iter().map(Record::nodes).collect();
    frame.with_column(Column::new("nodes".into(), nodes))?;
    Ok(frame)
}

/// A scaling curve's backend, threads per rank and nodes.
type Curve = (String, u64, u64);

/// The rows of `frame` grouped by series, backend and placement, with the times' median,
/// list, min and max, the repetitions and the medians of the other figures.
fn configuration_table(frame: &DataFrame) -> PolarsResult<DataFrame> {
    frame
        .clone()
        .lazy()
        // By placement, not only the worker count: 2 ranks × 2 threads is not 4 × 1.
        .group_by_stable([
            col("series"),
            col("backend"),
            col("workers"),
            col("ranks"),
            col("threads"),
            col("threads_per_rank"),
            col("nodes"),
        ])
        .agg([
            col("wall_s").median().alias("median_s"),
            col("wall_s").alias("times"),
            col("wall_s").min().alias("min_s"),
            col("wall_s").max().alias("max_s"),
            len().cast(DataType::UInt64).alias("reps"),
            col("fps").median().alias("fps"),
            col("fps_with_drawing").median().alias("fps_with_drawing"),
            col("oversubscribed").any(true).alias("oversubscribed"),
            col("messages_per_step_max")
                .median()
                .alias("messages_per_step"),
            col("bytes_per_step_max").median().alias("bytes_per_step"),
        ])
        .collect()
}

/// Median, min and max time, repetitions and median FPS per (series, backend, placement),
/// in first-seen order: (series, curve, point without its derived ratios).
fn per_configuration(frame: &DataFrame) -> PolarsResult<Vec<(String, Curve, Point)>> {
    let table = configuration_table(frame)?;
    let series = table.column("series")?.str()?;
    let backend = table.column("backend")?.str()?;
    let workers = table.column("workers")?.u64()?;
    let per_rank = table.column("threads_per_rank")?.u64()?;
    let nodes = table.column("nodes")?.u64()?;
    let median_s = table.column("median_s")?.f64()?;
    let times = table.column("times")?.list()?;
    let min_s = table.column("min_s")?.f64()?;
    let max_s = table.column("max_s")?.f64()?;
    let reps = table.column("reps")?.u64()?;
    let fps = table.column("fps")?.f64()?;
    let fps_with_drawing = table.column("fps_with_drawing")?.f64()?;
    let oversubscribed = table.column("oversubscribed")?.bool()?;
    let messages_per_step = table.column("messages_per_step")?.f64()?;
    let bytes_per_step = table.column("bytes_per_step")?.f64()?;
    (0..table.height())
        .map(|i| {
            let times: Vec<f64> = match times.get_as_series(i) {
                Some(values) => values.f64()?.into_no_null_iter().collect(),
                None => Vec::new(),
            };
            let median_ci_s = match times.is_empty() {
                true => [f64::NAN; 2],
                false => {
                    let interval = median_interval(&times, TIMING_CONFIDENCE, TIMING_SEED);
                    [interval.lower, interval.upper]
                }
            };
            let point = Point {
                workers: workers.get(i).unwrap_or_default(),
                reps: reps.get(i).unwrap_or_default() as usize,
                median_s: median_s.get(i).unwrap_or(f64::NAN),
                median_ci_s,
                min_s: min_s.get(i).unwrap_or(f64::NAN),
                max_s: max_s.get(i).unwrap_or(f64::NAN),
                fps: fps.get(i).unwrap_or(f64::NAN),
                fps_with_drawing: fps_with_drawing.get(i).unwrap_or(f64::NAN),
                oversubscribed: oversubscribed.get(i).unwrap_or_default(),
                messages_per_step: messages_per_step.get(i).unwrap_or(f64::NAN),
                bytes_per_step: bytes_per_step.get(i).unwrap_or(f64::NAN),
                speedup: f64::NAN,
                efficiency: f64::NAN,
                karp_flatt: f64::NAN,
            };
            let text = |column: &StringChunked| column.get(i).unwrap_or_default().to_owned();
            let curve = (
                text(backend),
                per_rank.get(i).unwrap_or(1),
                nodes.get(i).unwrap_or(1),
            );
            Ok((text(series), curve, point))
        })
        .collect()
}

/// Per series, the most distinct `state_hash`es of any one physical setup in it.
fn distinct_hashes_per_series(frame: &DataFrame) -> PolarsResult<BTreeMap<String, usize>> {
    let table = frame
        .clone()
        .lazy()
        .group_by([col("series"), col("setup")])
        .agg([col("state_hash")
            .n_unique()
            .cast(DataType::UInt64)
            .alias("hashes")])
        .group_by([col("series")])
        .agg([col("hashes").max()])
        .collect()?;
    let series = table.column("series")?.str()?;
    let hashes = table.column("hashes")?.u64()?;
    Ok((0..table.height())
        .filter_map(|i| Some((series.get(i)?.to_owned(), hashes.get(i)? as usize)))
        .collect())
}

/// Orders a setup's backends and points, picks each backend's baseline and derives
/// speedup, efficiency, Karp–Flatt and the Amdahl fit from the medians.
fn derive_scaling(setup: &mut Setup) {
    setup.backends.sort_by_key(|b| {
        (
            BackendKind::rank_of(&b.backend),
            b.threads_per_rank,
            b.nodes,
        )
    });
    for backend in &mut setup.backends {
        backend.points.sort_by_key(|p| p.workers);
    }
    // A backend's time at one worker, whichever of its curves measured it: one rank of
    // one thread is the start of its curves of several threads per rank too.
    let one_worker = |name: &str| {
        (setup.backends.iter())
            .filter(|b| b.backend == name)
            .flat_map(|b| &b.points)
            .find(|p| p.workers == 1)
            .map(|p| p.median_s)
    };
    let serial = one_worker(BackendKind::Serial.name());
    let own: Vec<Option<f64>> = (setup.backends.iter())
        .map(|b| one_worker(&b.backend))
        .collect();
    let weak = setup.scaling == Scaling::Weak;
    for (backend, own) in setup.backends.iter_mut().zip(own) {
        backend.baseline = match (serial, own) {
            (Some(t), _) => Baseline::Serial(t),
            (None, Some(t)) => Baseline::OneWorker(t),
            (None, None) => Baseline::Missing,
        };
        let t_base = match backend.baseline {
            Baseline::Serial(t) | Baseline::OneWorker(t) => t,
            Baseline::Missing => f64::NAN,
        };
        for point in &mut backend.points {
            let p = point.workers as f64;
            if weak {
                // Each worker has N₀ disks: ideal time stays T(1, N₀).
                point.efficiency = t_base / point.median_s;
                point.speedup = p * point.efficiency;
            } else {
                point.speedup = t_base / point.median_s;
                point.efficiency = point.speedup / p;
                if point.workers > 1 {
                    point.karp_flatt = (1.0 / point.speedup - 1.0 / p) / (1.0 - 1.0 / p);
                }
            }
        }
        backend.amdahl = if weak {
            Err(NoFit::Weak)
        } else {
            amdahl_fit(&backend.points)
        };
        // Karp–Flatt is a serial fraction too: shown under the same conditions.
        let counts = distinct_worker_counts(&backend.points);
        for point in &mut backend.points {
            if counts < MIN_WORKER_COUNTS || !(0.0..=1.0).contains(&point.karp_flatt) {
                point.karp_flatt = f64::NAN;
            }
        }
    }
}

fn distinct_worker_counts(points: &[Point]) -> usize {
    let mut workers: Vec<u64> = points.iter().map(|p| p.workers).collect();
    workers.sort_unstable();
    workers.dedup();
    workers.len()
}

/// Least squares of the medians on T = a + b·(1/p); f = a/(a + b), with each point's
/// relative residual. Not shown ([`NoFit`]) with fewer than [`MIN_WORKER_COUNTS`]
/// distinct worker counts or a serial fraction outside [0, 1].
pub fn amdahl_fit(points: &[Point]) -> Result<AmdahlFit, NoFit> {
    let counts = distinct_worker_counts(points);
    if counts < MIN_WORKER_COUNTS {
        return Err(NoFit::FewWorkerCounts(counts));
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
        return Err(NoFit::FewWorkerCounts(1));
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
    if !(0.0..=1.0).contains(&serial_fraction) {
        return Err(NoFit::OutsideUnitInterval(serial_fraction));
    }
    let residuals = points
        .iter()
        .zip(xs.iter().zip(&ys))
        .map(|(point, (x, y))| (point.workers, y / (a + b * x) - 1.0))
        .collect();
    Ok(AmdahlFit {
        serial_fraction,
        r_squared,
        residuals,
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
            median_ci_s: [median_s; 2],
            min_s: median_s,
            max_s: median_s,
            fps: 1.0 / median_s,
            fps_with_drawing: f64::NAN,
            oversubscribed: false,
            messages_per_step: f64::NAN,
            bytes_per_step: f64::NAN,
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
        assert!(
            fit.residuals.iter().all(|(_, r)| r.abs() < 1e-12),
            "{fit:?}"
        );
        // Two worker counts fit any law exactly: no serial fraction from them.
        assert_eq!(amdahl_fit(&points[..2]), Err(NoFit::FewWorkerCounts(2)));
        assert_eq!(amdahl_fit(&points[..1]), Err(NoFit::FewWorkerCounts(1)));
    }

    #[test]
    fn a_serial_fraction_outside_zero_to_one_is_not_shown() {
        // Slower with more workers (oversubscribed): T grows with p, f > 1.
        let points: Vec<Point> = [1, 2, 4]
            .iter()
            .map(|&p| point(p, 1.0 + 0.1 * p as f64))
            .collect();
        match amdahl_fit(&points) {
            Err(NoFit::OutsideUnitInterval(f)) => assert!(f > 1.0, "{f}"),
            other => panic!("{other:?}"),
        }
        // Faster than ideal (superlinear): f < 0.
        let points: Vec<Point> = [1, 2, 4]
            .iter()
            .map(|&p| point(p, 1.0 / (p * p) as f64))
            .collect();
        assert!(matches!(
            amdahl_fit(&points),
            Err(NoFit::OutsideUnitInterval(f)) if f < 0.0
        ));
    }
}
