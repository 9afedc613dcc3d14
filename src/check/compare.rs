//! The comparisons of `collide check`, one [`Row`] per configuration and measure: this
//! build against the baseline (each run's time in units of its round's calibration), B
//! against A in an A/B check (runs paired by round), and instruction counts. Each row's
//! verdict is `stats::verdict` of its interval and noise threshold; the intervals are
//! `stats`'s bootstrap, seeded by the configuration's key. Reading the baseline is
//! `baseline`'s, counting instructions `instructions`'s, writing the rows `summary`'s.

use std::collections::BTreeMap;

use anyhow::bail;

use crate::check::baseline::{Baseline, BaselineInfo};
use crate::check::instructions::InstructionCount;
use crate::stats::{self, Interval, Verdict, median};
use crate::study::records::{Record, STATUS_OK};
use crate::study::runner::Calibration;

/// Confidence of the bootstrap interval.
pub const CONFIDENCE: f64 = 0.95;
/// An instruction count counts as changed beyond this fraction, on every backend: about
/// 10 times the largest difference measured between two builds of one commit in 20 A/A
/// checks (1.7 × 10⁻⁴ serial, 1.0 × 10⁻³ rayon, whose idle threads spin, 10⁻⁵ for MPI
/// rank 0's own code; docs/ci-check.md).
const INSTRUCTION_NOISE: f64 = 0.01;
/// The unit of the instruction-count row.
pub const INSTRUCTIONS: &str = "instructions";
/// The `ab_side` of the runs of the build checked against, and of this build's.
pub const SIDE_A: &str = "A";
pub const SIDE_B: &str = "B";

/// One compared configuration (or the instruction count).
#[derive(Clone, Debug)]
pub struct Row {
    pub what: String,
    /// What `old` and `new` count: CPU or wall seconds, or instructions.
    pub unit: &'static str,
    /// Medians of the baseline and of this run, before normalisation.
    pub old: f64,
    pub new: f64,
    /// new / old after normalisation: the verdict's evidence.
    pub ratio: Interval,
    pub verdict: Verdict,
    /// The normalised wall-time ratio, shown beside a verdict on CPU time.
    pub wall: Option<Interval>,
    pub note: String,
    /// The configuration's key, or the backend's name for an instruction count.
    pub key: String,
}

impl Row {
    /// Whether this row's verdict against the baseline decides the check's outcome:
    /// instruction counts always, timings where `timings_decide`
    /// (`baseline::timings_decide`).
    pub fn decides(&self, timings_decide: bool) -> bool {
        self.unit == INSTRUCTIONS || timings_decide
    }
}

/// The bootstrap's seed for configuration `key`: a check is reproducible from its records.
fn seed_of(key: &str) -> u64 {
    xxhash_rust::xxh3::xxh3_64(key.as_bytes())
}

/// The successful runs of one configuration in one check. Each run is normalised by the
/// calibration timed just before its round of repetitions (`calibrations[repetition]`),
/// so that a busy spell of the machine slows both sides of the quotient.
struct Runs<'a> {
    first: &'a Record,
    wall: Vec<f64>,
    wall_normalised: Vec<f64>,
    /// `None` when a run or a calibration has no CPU time.
    cpu: Option<Vec<f64>>,
    cpu_normalised: Option<Vec<f64>>,
}

impl<'a> Runs<'a> {
    fn new(first: &'a Record) -> Runs<'a> {
        Runs {
            first,
            wall: Vec::new(),
            wall_normalised: Vec::new(),
            cpu: Some(Vec::new()),
            cpu_normalised: Some(Vec::new()),
        }
    }

    /// Adds `row`, normalised by the calibration of its round.
    fn push(&mut self, row: &Record, calibration: &Calibration) {
        self.wall.push(row.wall_s);
        self.wall_normalised
            .push(row.wall_s / calibration.calibration_s);
        match calibration
            .calibration_cpu_s
            .filter(|_| row.cpu_s.is_finite())
        {
            Some(calibration_cpu_s) => {
                if let (Some(cpu), Some(normalised)) = (&mut self.cpu, &mut self.cpu_normalised) {
                    cpu.push(row.cpu_s);
                    normalised.push(row.cpu_s / calibration_cpu_s);
                }
            }
            None => (self.cpu, self.cpu_normalised) = (None, None),
        }
    }
}

/// The runs of each configuration, in first-seen order.
fn runs_by_configuration<'a>(
    rows: &'a [Record],
    calibrations: &[Calibration],
) -> anyhow::Result<Vec<Runs<'a>>> {
    let mut order: Vec<Runs<'a>> = Vec::new();
    for row in rows.iter().filter(|r| r.status == STATUS_OK) {
        let Some(calibration) = calibrations.get(row.repetition as usize) else {
            bail!(
                "no calibration for repetition {} of {}; record the baseline again \
                 with `collide check --update-baseline`",
                row.repetition,
                row.config_key
            );
        };
        let index = match order
            .iter()
            .position(|r| r.first.config_key == row.config_key)
        {
            Some(index) => index,
            None => {
                order.push(Runs::new(row));
                order.len() - 1
            }
        };
        order[index].push(row, calibration);
    }
    Ok(order)
}

/// One row per configuration of this run (`new_info`'s runs `new_rows`) and one per
/// instruction count, each compared with the baseline `old`: on CPU time where both
/// checks measured it, on wall time otherwise.
pub fn compare_baseline(
    old: &Baseline,
    new_info: &BaselineInfo,
    new_rows: &[Record],
    noise: f64,
) -> anyhow::Result<Vec<Row>> {
    let old_runs: BTreeMap<&str, Runs<'_>> =
        runs_by_configuration(&old.records, &old.info.calibrations)?
            .into_iter()
            .map(|runs| (runs.first.config_key.as_str(), runs))
            .collect();
    let mut rows = Vec::new();
    for new in runs_by_configuration(new_rows, &new_info.calibrations)? {
        let key = &new.first.config_key;
        let Some(old) = old_runs.get(key.as_str()) else {
            bail!(
                "the baseline has no runs of {key}; record one on purpose with \
                 `collide check --update-baseline`"
            );
        };
        rows.push(configuration_row(old, &new, noise));
    }
    rows.extend(compare_instructions(
        &old.info.instructions,
        &new_info.instructions,
    ));
    Ok(rows)
}

/// The row of one configuration against the baseline: judged on the ratio of normalised
/// CPU times (the wall-time ratio beside it) where both sides have CPU times, on the
/// ratio of normalised wall times otherwise.
fn configuration_row(old: &Runs<'_>, new: &Runs<'_>, noise: f64) -> Row {
    let key = &new.first.config_key;
    let seed = seed_of(key);
    let ratio = |new: &[f64], old: &[f64]| stats::ratio_of_medians(new, old, CONFIDENCE, seed);
    let wall = ratio(&new.wall_normalised, &old.wall_normalised);
    let (unit, old_median, new_median, judged, shown_wall) =
        match (&new.cpu, &new.cpu_normalised, &old.cpu, &old.cpu_normalised) {
            (Some(new_cpu), Some(new_normalised), Some(old_cpu), Some(old_normalised)) => (
                "CPU s",
                median(&mut old_cpu.clone()),
                median(&mut new_cpu.clone()),
                ratio(new_normalised, old_normalised),
                Some(wall),
            ),
            _ => (
                "wall s",
                median(&mut old.wall.clone()),
                median(&mut new.wall.clone()),
                wall,
                None,
            ),
        };
    let row = new.first;
    Row {
        what: format!(
            "{} {} ×{} (n = {})",
            row.scene, row.backend, row.workers, row.n
        ),
        unit,
        old: old_median,
        new: new_median,
        ratio: judged,
        verdict: stats::verdict(&judged, noise),
        wall: shown_wall,
        note: match old.first.state_hash == row.state_hash {
            true => String::new(),
            false => "state_hash changed: the runs compute other states".to_owned(),
        },
        key: key.clone(),
    }
}

/// The A/B rows, one per configuration in first-seen order: the paired ratio B/A of the
/// stepping loop's wall seconds ([`ab_measure`]), each run of B paired with the run of A
/// of the same configuration and round; the paired ratio of CPU seconds in the note.
pub fn compare_ab(rows: &[Record], noise: f64) -> anyhow::Result<Vec<Row>> {
    let mut keys: Vec<&str> = Vec::new();
    for row in rows {
        if !keys.contains(&row.config_key.as_str()) {
            keys.push(&row.config_key);
        }
    }
    keys.into_iter()
        .map(|key| ab_row(key, &pairs_of(rows, key), noise))
        .collect()
}

/// The A/B row of configuration `key` from its `pairs` of runs (A, B).
fn ab_row(key: &str, pairs: &[(&Record, &Record)], noise: f64) -> anyhow::Result<Row> {
    let Some(&(first_a, first_b)) = pairs.first() else {
        bail!("no round has a successful run of both builds of {key}");
    };
    let seed = seed_of(key);
    let paired = |measure: fn(&Record) -> f64| {
        let (a, b): (Vec<f64>, Vec<f64>) =
            pairs.iter().map(|(a, b)| (measure(a), measure(b))).unzip();
        let ratio = stats::paired_ratio(&a, &b, CONFIDENCE, seed);
        (median(&mut a.clone()), median(&mut b.clone()), ratio)
    };
    let (old, new, ratio) = paired(ab_measure);
    let mut note = String::new();
    if pairs
        .iter()
        .all(|(a, b)| a.cpu_s.is_finite() && b.cpu_s.is_finite())
    {
        let (_, _, cpu) = paired(|row| row.cpu_s);
        note = format!(
            "CPU ratio {:.3} ({:.3}–{:.3})",
            cpu.point, cpu.lower, cpu.upper
        );
    }
    if first_a.state_hash != first_b.state_hash {
        note.push_str("; state_hash changed: the builds compute other states");
    }
    Ok(Row {
        what: format!(
            "{} {} ×{} (n = {}, {} pairs)",
            first_b.scene,
            first_b.backend,
            first_b.workers,
            first_b.n,
            pairs.len()
        ),
        unit: AB_UNIT,
        old,
        new,
        ratio,
        verdict: stats::verdict(&ratio, noise),
        wall: None,
        note,
        key: key.to_owned(),
    })
}

/// What the A/B verdict is judged on: the wall seconds of the stepping loop (the slowest
/// rank's for MPI), which also grow when a parallel backend waits (a load imbalance, a
/// serialised stage) without working more; docs/ci-check.md says what decided the choice.
fn ab_measure(row: &Record) -> f64 {
    row.wall_s
}
const AB_UNIT: &str = "wall s";

/// The successful runs of configuration `key` by A and by B, paired by round.
fn pairs_of<'a>(rows: &'a [Record], key: &str) -> Vec<(&'a Record, &'a Record)> {
    let ok = |side: &'static str| {
        rows.iter().filter(move |row| {
            row.config_key == key && row.ab_side == side && row.status == STATUS_OK
        })
    };
    ok(SIDE_A)
        .filter_map(|a| {
            ok(SIDE_B)
                .find(|b| b.repetition == a.repetition)
                .map(|b| (a, b))
        })
        .collect()
}

/// Instruction rows: each backend's count now against the count of the same command
/// in `old` (backends counted on one side only are left out).
pub fn compare_instructions(old: &[InstructionCount], new: &[InstructionCount]) -> Vec<Row> {
    new.iter()
        .filter_map(|new| {
            let old = old.iter().find(|old| old.command == new.command)?;
            let ratio = new.instructions as f64 / old.instructions as f64;
            let exact = Interval {
                lower: ratio,
                point: ratio,
                upper: ratio,
            };
            Some(Row {
                what: format!("{} instructions (callgrind)", new.backend),
                unit: INSTRUCTIONS,
                old: old.instructions as f64,
                new: new.instructions as f64,
                ratio: exact,
                verdict: stats::verdict(&exact, INSTRUCTION_NOISE),
                wall: None,
                note: format!("noise threshold {:.0}%", 100.0 * INSTRUCTION_NOISE),
                key: new.backend.clone(),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::environment::Environment;
    use crate::study::records;

    /// Runs of one configuration: A's wall times, and B's, one per round.
    fn runs(key: &str, a: &[f64], b: &[f64]) -> Vec<Record> {
        let environment = Environment::capture();
        let context = records::serial_context(&environment);
        let run = |side: &str, repetition: usize, wall_s: f64| {
            let mut row = Record::failed(&context, STATUS_OK, String::new());
            (row.config_key, row.ab_side) = (key.to_owned(), side.to_owned());
            (row.repetition, row.wall_s, row.cpu_s) = (repetition as u32, wall_s, wall_s);
            row
        };
        let mut rows = Vec::new();
        for (round, (&a, &b)) in a.iter().zip(b).enumerate() {
            rows.extend([run(SIDE_A, round, a), run(SIDE_B, round, b)]);
        }
        rows
    }

    #[test]
    fn each_configuration_is_judged_by_its_own_pairs() {
        let a = [1.00, 1.30, 0.90, 1.10, 1.25, 0.95, 1.05, 1.15];
        let same: Vec<f64> = a.iter().map(|t| t * 1.01).collect();
        let slower: Vec<f64> = a.iter().map(|t| t * 1.20).collect();
        let mut rows = runs("fast", &a, &same);
        rows.extend(runs("slow", &a, &slower));
        // A failed B run leaves its round unpaired.
        rows.last_mut().unwrap().status = "failed".to_owned();
        let compared = compare_ab(&rows, 0.10).unwrap();
        assert_eq!(compared.len(), 2);
        assert_eq!(
            (compared[0].key.as_str(), compared[0].verdict),
            ("fast", Verdict::Unchanged)
        );
        assert_eq!(
            (compared[1].key.as_str(), compared[1].verdict),
            ("slow", Verdict::Regressed)
        );
        assert!(compared[1].what.contains("7 pairs"), "{}", compared[1].what);
        assert!((compared[1].ratio.point - 1.2).abs() < 1e-9);
        // The paired CPU-time ratio rides along in the note.
        assert!(
            compared[1].note.contains("CPU ratio 1.200"),
            "{}",
            compared[1].note
        );
    }

    #[test]
    fn instruction_counts_are_compared_per_backend_and_command() {
        let count = |backend: &str, instructions| InstructionCount {
            backend: backend.to_owned(),
            command: vec!["simulate".to_owned(), backend.to_owned()],
            instructions,
        };
        let old = [count("serial", 1000), count("rayon", 1000)];
        let new = [count("serial", 1005), count("rayon", 1020), count("mpi", 9)];
        let rows = compare_instructions(&old, &new);
        let verdicts: Vec<(&str, Verdict)> =
            rows.iter().map(|r| (r.key.as_str(), r.verdict)).collect();
        assert_eq!(
            verdicts,
            [
                ("serial", Verdict::Unchanged),
                ("rayon", Verdict::Regressed)
            ]
        );
    }
}
