//! `collide check`: the CI timing check. Runs a small manifest through the study runner
//! (fresh processes, warm-ups, repetitions interleaved with a calibration workload) and
//! compares it with a baseline folder kept in the repository (`records.parquet` and
//! `baseline.json`, the environment it was recorded on), written only by
//! `--update-baseline`. With `--against REV` it also runs the build of REV (`against`)
//! interleaved with this one in the same job, and the paired ratios of the two decide.
//! Verdicts come from `stats`; instruction counts of each backend under callgrind, where
//! valgrind is installed, are a second, nearly noise-free signal. Each check appends its
//! verdicts to a history (`study::history`).

pub mod against;
pub mod calibrate;

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, bail};
use serde::{Deserialize, Serialize};

use crate::exit::RunsFailed;
use crate::run::backend_kind::BackendKind;
use crate::stats::median;
use crate::stats::{self, Interval, Verdict};
use crate::study::environment::Environment;
use crate::study::history;
use crate::study::manifest::{self, Configuration, Study};
use crate::study::records::{self, Record, STATUS_OK};
use crate::study::runner::{self, Calibration, Program, RunOptions, Slowdown};
use crate::system::output::write_atomically;

/// How to run a check.
#[derive(Clone, Debug)]
pub struct CheckOptions {
    pub manifest: PathBuf,
    pub baseline: PathBuf,
    /// Record this run as the baseline instead of comparing.
    pub update_baseline: bool,
    /// Where this run's records and `summary.md` go.
    pub out: PathBuf,
    /// Relative change within which a ratio counts as noise.
    pub noise: f64,
    /// Extra work per step of this build's measured runs (none in real checks).
    pub slowdown: Slowdown,
    /// Also run the build of this revision interleaved with this one, and judge by the
    /// paired ratios (`Some("")`: the commit that recorded the baseline).
    pub against: Option<String>,
    /// Where each check appends its verdicts (`None`: nowhere).
    pub history: Option<PathBuf>,
    pub quiet: bool,
}

/// How a check ended, when it could run at all.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CheckOutcome {
    /// Nothing regressed (or a baseline was recorded).
    Passed,
    /// At least one configuration or the instruction count regressed.
    Regressed,
}

/// Version of `baseline.json`; a baseline of another version must be re-recorded.
const BASELINE_FORMAT: u32 = 2;
const BASELINE_INFO: &str = "baseline.json";
const BASELINE_RECORDS: &str = "records.parquet";
/// Confidence of the bootstrap interval.
const CONFIDENCE: f64 = 0.95;
/// An instruction count counts as changed beyond this fraction, on every backend: about
/// 10 times the largest difference measured between two builds of one commit in 20 A/A
/// checks (1.7 × 10⁻⁴ serial, 1.0 × 10⁻³ rayon, whose idle threads spin, 10⁻⁵ for MPI
/// rank 0's own code; docs/ci-check.md).
const INSTRUCTION_NOISE: f64 = 0.01;
/// The unit of the instruction-count row.
const INSTRUCTIONS: &str = "instructions";
/// The instruction workloads: the manifest's first configuration of each backend, this
/// small.
const INSTRUCTION_DISKS: i64 = 2000;
const INSTRUCTION_STEPS: i64 = 50;

/// `baseline.json`: what a baseline was recorded from and on.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BaselineInfo {
    pub format: u32,
    pub recorded_utc: String,
    pub manifest: String,
    pub manifest_hash: String,
    /// Non-zero only for baselines recorded to test the check itself.
    pub inject_slowdown: f64,
    /// The only backend slowed down by `inject_slowdown`; `None`: every backend.
    #[serde(default)]
    pub inject_into: Option<String>,
    /// Every calibration run, one per round of repetitions.
    pub calibrations: Vec<Calibration>,
    /// One count per backend of the manifest (empty without valgrind).
    pub instructions: Vec<InstructionCount>,
    pub environment: Environment,
    /// The kernel's boot id (`/proc/sys/kernel/random/boot_id`) when it was recorded:
    /// timing verdicts decide only on the machine, and boot, the baseline came from.
    #[serde(default)]
    pub boot_id: String,
}

/// The running kernel's boot id; empty where the system does not say.
fn boot_id() -> String {
    std::fs::read_to_string("/proc/sys/kernel/random/boot_id")
        .map(|id| id.trim().to_owned())
        .unwrap_or_default()
}

/// Whether timing verdicts decide the outcome: only against a baseline recorded on this
/// very machine since its last boot. Across machines (and VM instances, and reboots) the
/// calibration leaves the simulator's normalised time off by up to about 20% (docs/ci-check.md),
/// beyond any useful noise threshold; instruction counts do not move and always decide.
fn timings_decide(baseline_boot: &str, this_boot: &str) -> bool {
    !this_boot.is_empty() && baseline_boot == this_boot
}

/// Whether a compared row's verdict decides the check's outcome.
fn decides(row: &Row, timings_decide: bool) -> bool {
    row.unit == INSTRUCTIONS || timings_decide
}

/// Instructions executed by one small run of a backend under callgrind (rank 0's for MPI).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InstructionCount {
    /// The backend's name.
    pub backend: String,
    /// The `collide simulate` arguments after the program (without an injected slowdown).
    pub command: Vec<String>,
    pub instructions: u64,
}

/// One compared configuration (or the instruction count).
#[derive(Clone, Debug)]
struct Row {
    what: String,
    /// What `old` and `new` count: CPU or wall seconds, or instructions.
    unit: &'static str,
    /// Medians of the baseline and of this run, before normalisation.
    old: f64,
    new: f64,
    /// new / old after normalisation: the verdict's evidence.
    ratio: Interval,
    verdict: Verdict,
    /// The normalised wall-time ratio, shown beside a verdict on CPU time.
    wall: Option<Interval>,
    note: String,
    /// The configuration's key, or the backend's name for an instruction count.
    key: String,
}

impl Row {
    /// The row's line in the history.
    fn history_entry(&self, info: &BaselineInfo, against: &str) -> history::Entry {
        history::Entry {
            commit: info.environment.git_commit.clone(),
            dirty: info.environment.git_dirty,
            checked_utc: info.recorded_utc.clone(),
            against: against.to_owned(),
            what: self.what.clone(),
            key: self.key.clone(),
            measure: self.unit.to_owned(),
            old: self.old,
            new: self.new,
            ratio: self.ratio.point,
            lower: self.ratio.lower,
            upper: self.ratio.upper,
            verdict: self.verdict.name().to_owned(),
            inject_slowdown: info.inject_slowdown,
        }
    }
}

/// The build checked against in an A/B check, and its verdicts.
struct AbCheck {
    rev: against::Rev,
    /// One row per configuration (paired ratio B/A) and one per backend's instruction count.
    rows: Vec<Row>,
}

/// Runs the check: the manifest by this build (and REV's, with `--against`), then the
/// comparisons, the summary and the history. Records a new baseline instead with
/// `--update-baseline`.
pub fn run(options: &CheckOptions) -> anyhow::Result<CheckOutcome> {
    // Refused before anything is measured, not after.
    if let Some(dir) = &options.history {
        crate::system::output::check_output_folder(dir, "--history")?;
    }
    crate::system::output::check_output_folder(&options.out, "--out")?;
    let (study, text) = manifest::load(&options.manifest)?;
    let environment = Environment::capture();
    let manifest_hash = runner::manifest_hash(&text);
    let baseline = match options.update_baseline {
        true => None,
        false => Some(load_baseline(
            &options.baseline,
            &manifest_hash,
            &environment,
        )?),
    };
    let this = Program {
        side: "",
        exe: runner::this_exe()?,
        commit: None,
        slowdown: options.slowdown,
    };
    let against = match &options.against {
        Some(rev) => Some(prepare_against(
            rev,
            baseline.as_ref().map(|(info, _)| info),
            options,
            &this.exe,
            &environment,
        )?),
        None => None,
    };
    let (info, rows) = measure(
        &study,
        &text,
        options,
        &this,
        against.as_ref().map(|(_, a)| a),
        manifest_hash,
        environment,
    )?;
    let Some((old_info, old_rows)) = baseline else {
        write_baseline(&options.baseline, &info, &rows)?;
        crate::outln!(
            "baseline recorded in {} ({} runs, {} calibrations); commit it",
            options.baseline.display(),
            rows.len(),
            info.calibrations.len()
        );
        return Ok(CheckOutcome::Passed);
    };
    // This build's runs: all of them, or side B of an A/B check.
    let this_rows: Vec<Record> = rows
        .iter()
        .filter(|row| row.ab_side != SIDE_A)
        .cloned()
        .collect();
    let compared = compare(&old_info, &old_rows, &info, &this_rows, options.noise)?;
    let scene_dir = options.out.join(&study.name);
    let ab = match against {
        Some((rev, a)) => {
            let a_instructions = count_instructions(&study.configurations, &scene_dir, &a)?;
            let mut rows = compare_ab(&rows, options.noise)?;
            rows.extend(compare_instructions(&a_instructions, &info.instructions));
            Some(AbCheck { rev, rows })
        }
        None => None,
    };
    let timings_decide = timings_decide(&old_info.boot_id, &info.boot_id);
    let text = summary(
        options,
        &old_info,
        &info,
        &compared,
        ab.as_ref(),
        timings_decide,
    );
    crate::out!("{text}");
    let path = options.out.join("summary.md");
    write_atomically(&path, |out| out.write_all(text.as_bytes()))?;
    crate::outln!("summary written to {}", path.display());
    let deciding: Vec<&Row> = match &ab {
        Some(ab) => ab.rows.iter().collect(),
        None => compared
            .iter()
            .filter(|row| decides(row, timings_decide))
            .collect(),
    };
    if let Some(dir) = &options.history {
        append_history(dir, options.quiet, &deciding, &info, &old_info, ab.as_ref())?;
    }
    Ok(
        match deciding.iter().any(|row| row.verdict == Verdict::Regressed) {
            true => CheckOutcome::Regressed,
            false => CheckOutcome::Passed,
        },
    )
}

/// Runs the manifest by this build (`this`), and by REV's (`against`) interleaved with
/// it, then counts this build's instructions: what this check measured, as a
/// baseline's description and its records. Failed runs end the check.
fn measure(
    study: &Study,
    manifest_text: &str,
    options: &CheckOptions,
    this: &Program,
    against: Option<&Program>,
    manifest_hash: String,
    environment: Environment,
) -> anyhow::Result<(BaselineInfo, Vec<Record>)> {
    let programs = match against {
        Some(a) => vec![
            a.clone(),
            Program {
                side: SIDE_B,
                ..this.clone()
            },
        ],
        None => vec![this.clone()],
    };
    let run_options = RunOptions {
        out: options.out.clone(),
        resume: false,
        // A check's verdict needs every run of one sitting: it never resumes.
        continue_with: "a new `collide check` (a check starts over; it does not resume)".to_owned(),
        quiet: options.quiet,
        programs,
        calibrate: true,
        mpi_yields_when_idle: true,
    };
    let outcome = runner::run_study(study, manifest_text, &run_options)?;
    if outcome.failed > 0 {
        return Err(RunsFailed(format!(
            "{} run(s) of the check failed; their rows in {} say why (status, error)",
            outcome.failed,
            outcome.results.display()
        ))
        .into());
    }
    let rows = records::read(&outcome.results)?;
    let scene_dir = options.out.join(&study.name);
    let instructions = count_instructions(&study.configurations, &scene_dir, this)?;
    let info = BaselineInfo {
        format: BASELINE_FORMAT,
        recorded_utc: records::utc_now(),
        manifest: options.manifest.display().to_string(),
        manifest_hash,
        inject_slowdown: options.slowdown.fraction,
        inject_into: options.slowdown.into.map(|kind| kind.name().to_owned()),
        calibrations: outcome.calibrations,
        instructions,
        environment,
        boot_id: boot_id(),
    };
    Ok((info, rows))
}

/// Appends the verdicts that decided this check to the history in `dir`.
fn append_history(
    dir: &Path,
    quiet: bool,
    deciding: &[&Row],
    info: &BaselineInfo,
    old_info: &BaselineInfo,
    ab: Option<&AbCheck>,
) -> anyhow::Result<()> {
    let against = match ab {
        Some(ab) => format!("A/B against {}", against::short(&ab.rev.commit)),
        None => format!("baseline of {}", old_info.environment.git_commit),
    };
    let entries: Vec<history::Entry> = deciding
        .iter()
        .map(|row| row.history_entry(info, &against))
        .collect();
    let path = history::append(dir, &info.environment, &entries)?;
    if !quiet {
        crate::outln!(
            "history: {} row(s) appended in {}",
            entries.len(),
            path.display()
        );
    }
    Ok(())
}

/// The `ab_side` of the runs of the build checked against, and of this build's.
const SIDE_A: &str = "A";
const SIDE_B: &str = "B";

/// Finds (or builds) the binary of the revision to check against: the program of side A.
fn prepare_against(
    rev: &str,
    baseline: Option<&BaselineInfo>,
    options: &CheckOptions,
    exe: &Path,
    environment: &Environment,
) -> anyhow::Result<(against::Rev, Program)> {
    let repo = against::repository()?;
    let recorded = baseline.map(|info| {
        (
            info.environment.git_commit.as_str(),
            options.baseline.as_path(),
        )
    });
    let (rev, reason) = against::choose(rev, recorded)?;
    let rev = against::resolve(&repo, &rev, reason)?;
    let cargo_target = std::env::var_os("CARGO_TARGET_DIR").map(PathBuf::from);
    let this = against::this_build(exe, cargo_target.as_deref(), environment)?;
    let cache = std::path::absolute(options.out.join("against"))
        .context("cannot find the current folder")?;
    let binary = against::binary(&repo, &rev, &this, &cache, options.quiet)?;
    let program = Program {
        side: SIDE_A,
        exe: binary,
        commit: Some(against::short(&rev.commit).to_owned()),
        slowdown: Slowdown::default(),
    };
    Ok((rev, program))
}

/// The baseline in `dir`, if it can be compared with a run of this manifest and build.
fn load_baseline(
    dir: &Path,
    manifest_hash: &str,
    environment: &Environment,
) -> anyhow::Result<(BaselineInfo, Vec<Record>)> {
    let info_path = dir.join(BASELINE_INFO);
    let re_record = "record one on purpose with `collide check --update-baseline` and commit it";
    let text = std::fs::read_to_string(&info_path)
        .with_context(|| format!("no baseline at {}; {re_record}", info_path.display()))?;
    let info: BaselineInfo = serde_json::from_str(&text).with_context(|| {
        format!(
            "{} is not a baseline this collide reads; {re_record}",
            info_path.display()
        )
    })?;
    if info.format != BASELINE_FORMAT {
        bail!(
            "{} has baseline format {}, this collide reads {BASELINE_FORMAT}; {re_record}",
            info_path.display(),
            info.format
        );
    }
    if info.manifest_hash != manifest_hash {
        bail!(
            "the baseline in {} was recorded from another version of {}; {re_record}",
            dir.display(),
            info.manifest
        );
    }
    let (old, new) = (&info.environment, environment);
    if (old.profile.as_str(), old.features.as_str())
        != (new.profile.as_str(), new.features.as_str())
    {
        bail!(
            "the baseline in {} was recorded by a {} build with features [{}], this is a {} \
             build with [{}]; build with `--release --features mpi`, or {re_record}",
            dir.display(),
            old.profile,
            old.features,
            new.profile,
            new.features
        );
    }
    let records = records::read(&dir.join(BASELINE_RECORDS))
        .with_context(|| format!("the baseline's records cannot be read; {re_record}"))?;
    if let Err(field) = impossible_in(&info, &records) {
        bail!(
            "the baseline in {} has {field}, which no measurement gives: it was edited or \
             damaged; restore it from git, or {re_record}",
            dir.display()
        );
    }
    Ok((info, records))
}

/// The first value of a baseline that no run can have measured (a time or count of zero
/// or less, or not a number), named with its field; the check would divide by it.
fn impossible_in(info: &BaselineInfo, records: &[Record]) -> Result<(), String> {
    let positive = |value: f64| value.is_finite() && value > 0.0;
    for (round, calibration) in info.calibrations.iter().enumerate() {
        if !positive(calibration.calibration_s) {
            return Err(format!(
                "`calibrations[{round}].calibration_s` = {}",
                calibration.calibration_s
            ));
        }
        if let Some(cpu) = calibration.calibration_cpu_s.filter(|&cpu| !positive(cpu)) {
            return Err(format!("`calibrations[{round}].calibration_cpu_s` = {cpu}"));
        }
    }
    if let Some(count) = info
        .instructions
        .iter()
        .find(|count| count.instructions == 0)
    {
        return Err(format!(
            "`instructions` = 0 for the {} backend",
            count.backend
        ));
    }
    let measured = records.iter().filter(|row| row.status == STATUS_OK);
    if let Some(row) = measured.clone().find(|row| !positive(row.wall_s)) {
        return Err(format!(
            "`wall_s` = {} in a row of {}",
            row.wall_s, row.config_key
        ));
    }
    match measured
        .clone()
        .find(|row| row.cpu_s.is_finite() && row.cpu_s <= 0.0)
    {
        Some(row) => Err(format!(
            "`cpu_s` = {} in a row of {}",
            row.cpu_s, row.config_key
        )),
        None => Ok(()),
    }
}

fn write_baseline(dir: &Path, info: &BaselineInfo, rows: &[Record]) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the baseline folder {}", dir.display()))?;
    records::write(&dir.join(BASELINE_RECORDS), rows)?;
    let json = serde_json::to_string_pretty(info)?;
    write_atomically(&dir.join(BASELINE_INFO), |out| writeln!(out, "{json}"))
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
                order.push(Runs {
                    first: row,
                    wall: Vec::new(),
                    wall_normalised: Vec::new(),
                    cpu: Some(Vec::new()),
                    cpu_normalised: Some(Vec::new()),
                });
                order.len() - 1
            }
        };
        let runs = &mut order[index];
        runs.wall.push(row.wall_s);
        runs.wall_normalised
            .push(row.wall_s / calibration.calibration_s);
        match calibration
            .calibration_cpu_s
            .filter(|_| row.cpu_s.is_finite())
        {
            Some(calibration_cpu_s) => {
                if let (Some(cpu), Some(normalised)) = (&mut runs.cpu, &mut runs.cpu_normalised) {
                    cpu.push(row.cpu_s);
                    normalised.push(row.cpu_s / calibration_cpu_s);
                }
            }
            None => (runs.cpu, runs.cpu_normalised) = (None, None),
        }
    }
    Ok(order)
}

/// One row per configuration of this run (and one for the instruction count), each
/// compared with the baseline: on CPU time where both checks measured it, on wall time
/// otherwise.
fn compare(
    old_info: &BaselineInfo,
    old_rows: &[Record],
    new_info: &BaselineInfo,
    new_rows: &[Record],
    noise: f64,
) -> anyhow::Result<Vec<Row>> {
    let old: BTreeMap<String, Runs<'_>> = runs_by_configuration(old_rows, &old_info.calibrations)?
        .into_iter()
        .map(|runs| (runs.first.config_key.clone(), runs))
        .collect();
    let mut rows = Vec::new();
    for new in runs_by_configuration(new_rows, &new_info.calibrations)? {
        let key = &new.first.config_key;
        let Some(old) = old.get(key) else {
            bail!(
                "the baseline has no runs of {key}; record one on purpose with \
                 `collide check --update-baseline`"
            );
        };
        let seed = xxhash_rust::xxh3::xxh3_64(key.as_bytes());
        let ratio = |new: &[f64], old: &[f64]| stats::ratio_of_medians(new, old, CONFIDENCE, seed);
        let wall = ratio(&new.wall_normalised, &old.wall_normalised);
        let cpu = match (&new.cpu, &new.cpu_normalised, &old.cpu, &old.cpu_normalised) {
            (Some(new_cpu), Some(new_normalised), Some(old_cpu), Some(old_normalised)) => Some((
                median(&mut old_cpu.clone()),
                median(&mut new_cpu.clone()),
                ratio(new_normalised, old_normalised),
            )),
            _ => None,
        };
        let row = new.first;
        let what = format!(
            "{} {} ×{} (n = {})",
            row.scene, row.backend, row.workers, row.n
        );
        let note = match old.first.state_hash == row.state_hash {
            true => String::new(),
            false => "state_hash changed: the runs compute other states".to_owned(),
        };
        let key = key.clone();
        rows.push(match cpu {
            Some((old_cpu, new_cpu, cpu)) => Row {
                what,
                unit: "CPU s",
                old: old_cpu,
                new: new_cpu,
                ratio: cpu,
                verdict: stats::verdict(&cpu, noise),
                wall: Some(wall),
                note,
                key,
            },
            None => Row {
                what,
                unit: "wall s",
                old: median(&mut old.wall.clone()),
                new: median(&mut new.wall.clone()),
                ratio: wall,
                verdict: stats::verdict(&wall, noise),
                wall: None,
                note,
                key,
            },
        });
    }
    rows.extend(compare_instructions(
        &old_info.instructions,
        &new_info.instructions,
    ));
    Ok(rows)
}

/// The A/B rows, one per configuration in first-seen order: the paired ratio B/A of the
/// stepping loop's wall seconds ([`ab_measure`]), each run of B paired with the run of A
/// of the same configuration and round; the paired ratio of CPU seconds in the note.
fn compare_ab(rows: &[Record], noise: f64) -> anyhow::Result<Vec<Row>> {
    let mut keys: Vec<&str> = Vec::new();
    for row in rows {
        if !keys.contains(&row.config_key.as_str()) {
            keys.push(&row.config_key);
        }
    }
    let mut compared = Vec::new();
    for key in keys {
        let pairs = pairs_of(rows, key);
        let Some(&(first_a, first_b)) = pairs.first() else {
            bail!("no round has a successful run of both builds of {key}");
        };
        let seed = xxhash_rust::xxh3::xxh3_64(key.as_bytes());
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
        compared.push(Row {
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
        });
    }
    Ok(compared)
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
fn compare_instructions(old: &[InstructionCount], new: &[InstructionCount]) -> Vec<Row> {
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

/// The instructions of `program` in the first configuration of each backend, shrunk to
/// a small run, under callgrind (rank 0's, for MPI); empty (with a note) where valgrind
/// is not installed.
fn count_instructions(
    configurations: &[Configuration],
    scene_dir: &Path,
    program: &Program,
) -> anyhow::Result<Vec<InstructionCount>> {
    let valgrind = Command::new("valgrind").arg("--version").output();
    if !valgrind.is_ok_and(|out| out.status.success()) {
        eprintln!(
            "note: valgrind is not installed: no instruction counts (apt-get install valgrind)"
        );
        return Ok(Vec::new());
    }
    let mut counts = Vec::new();
    for kind in BackendKind::ALL {
        if kind == BackendKind::Mpi && !cfg!(feature = "mpi") {
            continue;
        }
        let Some(configuration) = configurations.iter().find(|c| c.backend == kind) else {
            continue;
        };
        let mut small = configuration.clone();
        small.overrides.n = Some(INSTRUCTION_DISKS);
        small.overrides.steps = Some(INSTRUCTION_STEPS);
        let scene = runner::materialize_scenes(scene_dir, &[&small])?.remove(0);
        let mut command = vec!["simulate".to_owned(), scene.display().to_string()];
        command.extend(small.simulate_args());
        let instructions = callgrind(program, &command, kind, small.workers, scene_dir)?;
        counts.push(InstructionCount {
            backend: kind.name().to_owned(),
            command,
            instructions,
        });
    }
    Ok(counts)
}

/// The instructions `program` executes for `command` (its `collide` arguments) under
/// callgrind: the whole process's for serial and rayon; for MPI, rank 0's (of `ranks`
/// started by `mpirun`, each under its own callgrind, files in `work_dir`) in collide's
/// own code only, because the MPI library polls for messages while a rank waits, a
/// count that varied by ±25% from run to run.
fn callgrind(
    program: &Program,
    command: &[String],
    kind: BackendKind,
    ranks: usize,
    work_dir: &Path,
) -> anyhow::Result<u64> {
    let slowdown = program.slowdown.simulate_args(kind);
    let (out, counted) = match kind {
        BackendKind::Mpi => {
            let files = work_dir.join("callgrind");
            let rank = "%q{OMPI_COMM_WORLD_RANK}";
            let out = Command::new("mpirun")
                .args(["-n", &ranks.to_string(), "valgrind", "--tool=callgrind"])
                .arg(format!(
                    "--callgrind-out-file={}.out.{rank}",
                    files.display()
                ))
                .arg(format!("--log-file={}.log.{rank}", files.display()))
                .arg(&program.exe)
                .args(command)
                .args(&slowdown)
                // OpenMPI refuses root without these; harmless otherwise.
                .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
                .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
                .output()
                .context("cannot run mpirun")?;
            let exe = std::fs::canonicalize(&program.exe)?;
            let counted = std::fs::read_to_string(files.with_extension("out.0"))
                .ok()
                .map(|text| instructions_in_object(&text, &exe.display().to_string()));
            let log = std::fs::read_to_string(files.with_extension("log.0")).unwrap_or_default();
            (out, counted.ok_or(log))
        }
        BackendKind::Serial | BackendKind::Rayon => {
            let out = Command::new("valgrind")
                .args(["--tool=callgrind", "--callgrind-out-file=/dev/null"])
                .arg(&program.exe)
                .args(command)
                .args(&slowdown)
                .output()
                .context("cannot run valgrind")?;
            let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
            let collected = stderr
                .lines()
                .find_map(|line| line.split_once("Collected :").map(|(_, n)| n.trim()))
                .and_then(|n| n.parse().ok());
            (out, collected.ok_or(stderr))
        }
    };
    match counted {
        Ok(instructions) if out.status.success() => Ok(instructions),
        counted => bail!(
            "callgrind of `{} {}` failed{}",
            program.exe.display(),
            command.join(" "),
            crate::system::process::tail(
                "its output",
                &format!(
                    "{}{}",
                    String::from_utf8_lossy(&out.stderr),
                    counted.err().unwrap_or_default()
                )
            )
        ),
    }
}

/// The instructions a callgrind output file (its text) counts in the object file
/// `object` itself (the self cost of its functions, not of what they call).
fn instructions_in_object(text: &str, object: &str) -> u64 {
    // Names are compressed: `ob=(3) /path` the first time, `ob=(3)` after.
    let mut names: BTreeMap<String, String> = BTreeMap::new();
    let mut name_of = |spec: &str| -> Option<String> {
        let (id, name) = spec.strip_prefix('(')?.split_once(')')?;
        let name = name.trim();
        match name.is_empty() {
            true => names.get(id).cloned(),
            false => {
                names.insert(id.to_owned(), name.to_owned());
                Some(name.to_owned())
            }
        }
    };
    let (mut counting, mut call_cost_next, mut total) = (false, false, 0);
    for line in text.lines() {
        if let Some(spec) = line.strip_prefix("ob=") {
            counting = name_of(spec).as_deref() == Some(object);
        } else if let Some(spec) = line.strip_prefix("cob=") {
            name_of(spec);
        } else if line.starts_with("calls=") {
            // The next cost line is what the call cost, inclusively: not self cost.
            call_cost_next = true;
        } else if line.starts_with(|c: char| c.is_ascii_digit() || "+-*".contains(c)) {
            let cost: u64 = match line.split_whitespace().nth(1) {
                Some(cost) => cost.parse().unwrap_or(0),
                None => 0,
            };
            if counting && !call_cost_next {
                total += cost;
            }
            call_cost_next = false;
        }
    }
    total
}

/// The markdown summary, printed to the terminal and written to `summary.md`.
fn summary(
    options: &CheckOptions,
    old_info: &BaselineInfo,
    new_info: &BaselineInfo,
    rows: &[Row],
    ab: Option<&AbCheck>,
    timings_decide: bool,
) -> String {
    // In an A/B check its rows decide, and the baseline's are shown only.
    let (deciding, shown): (Vec<&Row>, Vec<&Row>) = match ab {
        Some(ab) => (ab.rows.iter().collect(), rows.iter().collect()),
        None => rows.iter().partition(|row| decides(row, timings_decide)),
    };
    let count =
        |rows: &[&Row], verdict: Verdict| rows.iter().filter(|r| r.verdict == verdict).count();
    let regressed = count(&deciding, Verdict::Regressed);
    let improved = count(&deciding, Verdict::Improved);
    let advisory = count(&shown, Verdict::Regressed);
    let mut out = String::new();
    let _ = writeln!(
        out,
        "# collide check: {}\n",
        match (regressed, advisory) {
            (0, 0) => "no regression".to_owned(),
            (0, n) =>
                format!("no regression ({n} regression(s) against the baseline shown, not judged)"),
            (n, _) => format!("{n} REGRESSED"),
        }
    );
    let _ = writeln!(out, "- manifest: `{}`", options.manifest.display());
    let _ = writeln!(out, "- this build (B): {}", describe(new_info));
    if let Some(ab) = ab {
        let _ = writeln!(
            out,
            "- checked against (A): commit {}, {}",
            against::short(&ab.rev.commit),
            ab.rev.reason
        );
        let _ = writeln!(
            out,
            "- A/B: both builds ran every repetition, next to each other in alternating order \
             (A B, then B A), each run a fresh process; measure: the wall seconds of the \
             stepping loop (`wall_s`, the slowest rank's for MPI); ratio = the median of the \
             paired ratios B/A with its {:.0}% bootstrap interval ({} resamples of the pairs); \
             regressed when the whole interval lies above {:.3}, improved when it lies below \
             {:.3}; instruction counts of both builds (callgrind) compared beside. These \
             verdicts decide.\n",
            100.0 * CONFIDENCE,
            stats::RESAMPLES,
            1.0 + options.noise,
            1.0 / (1.0 + options.noise),
        );
        write_table(&mut out, &ab.rows, ("A median", "B median"));
        let _ = writeln!(out, "\n## Against the baseline (shown, not judged)\n");
    }
    let _ = writeln!(
        out,
        "- baseline `{}`: {}",
        options.baseline.display(),
        describe(old_info)
    );
    write_method(&mut out, options, old_info, ab.is_some(), timings_decide);
    write_table(&mut out, rows, ("baseline median", "median now"));
    if new_info.instructions.is_empty() {
        let _ = writeln!(
            out,
            "\nNo instruction counts: valgrind is not installed on this machine."
        );
    }
    let _ = writeln!(
        out,
        "\nverdict: {regressed} regressed, {improved} improved, {} unchanged{}",
        deciding.len() - regressed - improved,
        match advisory {
            0 => String::new(),
            n => format!(", and {n} regression(s) against the baseline shown, not judged"),
        }
    );
    out
}

/// Where and how a set of records was measured, for the summary's header.
fn describe(info: &BaselineInfo) -> String {
    let env = &info.environment;
    let calibration = |pick: fn(&Calibration) -> Option<f64>| {
        let mut values: Vec<f64> = info.calibrations.iter().filter_map(pick).collect();
        match values.is_empty() {
            true => "—".to_owned(),
            false => format!("{:.4} s", median(&mut values)),
        }
    };
    format!(
        "{} on {} ({}, {} logical cores), commit {}{}, recorded {}{}; calibration median \
         {} CPU, {} wall over {} rounds",
        env.profile,
        env.hostname,
        env.cpu_model,
        env.logical_cores,
        env.git_commit,
        if env.git_dirty { " (dirty)" } else { "" },
        info.recorded_utc,
        match info.inject_slowdown > 0.0 {
            true => format!(", with an injected slowdown of {}", info.inject_slowdown),
            false => String::new(),
        },
        calibration(|c| c.calibration_cpu_s),
        calibration(|c| Some(c.calibration_s)),
        info.calibrations.len()
    )
}

/// The summary's lines on what is measured, how it is compared and what decides.
fn write_method(
    out: &mut String,
    options: &CheckOptions,
    old_info: &BaselineInfo,
    ab: bool,
    timings_decide: bool,
) {
    let _ = writeln!(
        out,
        "- measure: the CPU seconds of each run's stepping loop (`cpu_s`, summed over threads \
         and ranks; time spent waiting for a CPU is not counted), divided by the CPU seconds of \
         the calibration workload (`collide calibrate`, fixed work that is not simulator code) \
         timed just before the run's round of repetitions; wall seconds (`wall_s`) divided by \
         the calibration's wall seconds where CPU time is unknown, and shown beside it"
    );
    let _ = writeln!(
        out,
        "- ratio = median normalised time now / in the baseline, with its {:.0}% bootstrap \
         interval ({} resamples); regressed when the whole interval lies above {:.3}, improved \
         when it lies below {:.3} (noise threshold {:.0}%)\n",
        100.0 * CONFIDENCE,
        stats::RESAMPLES,
        1.0 + options.noise,
        1.0 / (1.0 + options.noise),
        100.0 * options.noise
    );
    let _ = writeln!(
        out,
        "- {}\n",
        match (ab, timings_decide) {
            (true, _) =>
                "these verdicts are shown, not judged: the A/B verdicts above decide".to_owned(),
            (false, true) =>
                "timing verdicts decide: the baseline was recorded on this machine since \
                     its last boot"
                    .to_owned(),
            (false, false) => format!(
                "timing verdicts are shown, not judged: the baseline was recorded on another \
                 machine or boot ({}), where the normalised times of the same build differ by \
                 up to about 20%; the instruction count (callgrind, the same on any machine) \
                 decides. Record a baseline here (`--update-baseline`) to judge timings",
                old_info.environment.cpu_model
            ),
        }
    );
}

/// The summary's table: one row per configuration and measure.
fn write_table(out: &mut String, rows: &[Row], (old, new): (&str, &str)) {
    let _ = writeln!(
        out,
        "| configuration | measure | {old} | {new} | ratio | {:.0}% interval | verdict | wall ratio (interval) | note |",
        100.0 * CONFIDENCE
    );
    let _ = writeln!(
        out,
        "| --- | --- | ---: | ---: | ---: | --- | --- | --- | --- |"
    );
    for row in rows {
        let digits = if row.unit == INSTRUCTIONS { 0 } else { 4 };
        let _ = writeln!(
            out,
            "| {} | {} | {:.digits$} | {:.digits$} | {:.3} | {:.3}–{:.3} | {} | {} | {} |",
            row.what,
            row.unit,
            row.old,
            row.new,
            row.ratio.point,
            row.ratio.lower,
            row.ratio.upper,
            match row.verdict {
                Verdict::Regressed => "**regressed**",
                verdict => verdict.name(),
            },
            row.wall.map_or_else(String::new, |wall| format!(
                "{:.3} ({:.3}–{:.3})",
                wall.point, wall.lower, wall.upper
            )),
            row.note
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_baseline_with_zero_times_or_counts_is_refused_naming_the_field() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("results/baseline");
        let text = std::fs::read_to_string(dir.join(BASELINE_INFO)).unwrap();
        let info: BaselineInfo = serde_json::from_str(&text).unwrap();
        let rows = records::read(&dir.join(BASELINE_RECORDS)).unwrap();
        assert_eq!(impossible_in(&info, &rows), Ok(()));
        let mut zero_calibration = info.clone();
        zero_calibration.calibrations[0].calibration_s = 0.0;
        let named = impossible_in(&zero_calibration, &rows).unwrap_err();
        assert!(named.contains("calibration_s"), "{named}");
        if !info.instructions.is_empty() {
            let mut zero_count = info.clone();
            zero_count.instructions[0].instructions = 0;
            let named = impossible_in(&zero_count, &rows).unwrap_err();
            assert!(named.contains("`instructions` = 0"), "{named}");
        }
        let mut zero_time = rows.clone();
        let ok = zero_time
            .iter()
            .position(|row| row.status == STATUS_OK)
            .unwrap();
        zero_time[ok].wall_s = 0.0;
        let named = impossible_in(&info, &zero_time).unwrap_err();
        assert!(named.contains("wall_s"), "{named}");
    }

    #[test]
    fn timings_decide_only_on_the_boot_the_baseline_was_recorded_on() {
        assert!(timings_decide("boot-a", "boot-a"));
        assert!(!timings_decide("boot-a", "boot-b"));
        // Baselines from before boot ids were kept, and systems that do not tell.
        assert!(!timings_decide("", "boot-b"));
        assert!(!timings_decide("", ""));
    }

    #[test]
    fn instructions_in_an_object_are_its_own_not_those_of_what_it_calls() {
        let text = "events: Ir\nsummary: 1111\n\n\
                    ob=(1) /bin/collide\nfl=(1) a.rs\nfn=(1) step\n10 100\n+2 5\n\
                    cob=(2) /lib/libmpi.so\ncfn=(2) MPI_Wait\ncalls=1 0\n12 900\n\
                    ob=(2)\nfn=(2)\n0 900\n\
                    ob=(1)\nfn=(3) collide\n* 6\n";
        assert_eq!(instructions_in_object(text, "/bin/collide"), 111);
        assert_eq!(instructions_in_object(text, "/lib/libmpi.so"), 900);
        assert_eq!(instructions_in_object(text, "/bin/other"), 0);
    }

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
