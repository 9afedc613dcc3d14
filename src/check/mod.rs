//! `collide check`: the CI timing check. Runs a small manifest through the study runner
//! (fresh processes, warm-ups, repetitions interleaved with a calibration workload) and
//! compares it with a baseline folder kept in the repository (`records.parquet` and
//! `baseline.json`, the environment it was recorded on), written only by
//! `--update-baseline`. Verdicts come from `stats`; instruction counts of the serial path
//! under callgrind, where valgrind is installed, are a second, noise-free signal.

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
use crate::study::manifest::{self, Configuration};
use crate::study::records::{self, Record, STATUS_OK};
use crate::study::runner::{self, Calibration, RunOptions};
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
    /// Extra work per step of the measured runs, as a fraction (0 in real checks).
    pub inject_slowdown: f64,
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
const BASELINE_FORMAT: u32 = 1;
const BASELINE_INFO: &str = "baseline.json";
const BASELINE_RECORDS: &str = "records.parquet";
/// Confidence of the bootstrap interval.
const CONFIDENCE: f64 = 0.95;
/// An instruction count counts as changed beyond this fraction (callgrind is exact for
/// one binary and input; this absorbs start-up differences such as the environment).
const INSTRUCTION_NOISE: f64 = 0.01;
/// The unit of the instruction-count row.
const INSTRUCTIONS: &str = "instructions";
/// The instruction workload: the manifest's first serial configuration, this small.
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
    /// Every calibration run, one per round of repetitions.
    pub calibrations: Vec<Calibration>,
    pub instructions: Option<InstructionCount>,
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

/// Instructions executed by one serial run under callgrind.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InstructionCount {
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
}

pub fn run(options: &CheckOptions) -> anyhow::Result<CheckOutcome> {
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
    let simulate_args = match options.inject_slowdown > 0.0 {
        true => vec![
            "--inject-slowdown".to_owned(),
            options.inject_slowdown.to_string(),
        ],
        false => Vec::new(),
    };
    let run_options = RunOptions {
        out: options.out.clone(),
        resume: false,
        quiet: options.quiet,
        simulate_args: simulate_args.clone(),
        calibrate: true,
    };
    let outcome = runner::run_study(&study, &text, &run_options)?;
    if outcome.failed > 0 {
        return Err(RunsFailed(format!(
            "{} run(s) of the check failed; their rows in {} say why (status, error)",
            outcome.failed,
            outcome.results.display()
        ))
        .into());
    }
    let rows = records::read(&outcome.results)?;
    let serial = study
        .configurations
        .iter()
        .find(|c| c.backend == BackendKind::Serial);
    let instructions = match serial {
        Some(configuration) => count_instructions(
            configuration,
            &options.out.join(&study.name),
            &simulate_args,
        )?,
        None => None,
    };
    let info = BaselineInfo {
        format: BASELINE_FORMAT,
        recorded_utc: records::utc_now(),
        manifest: options.manifest.display().to_string(),
        manifest_hash,
        inject_slowdown: options.inject_slowdown,
        calibrations: outcome.calibrations,
        instructions,
        environment,
        boot_id: boot_id(),
    };
    match baseline {
        None => {
            write_baseline(&options.baseline, &info, &rows)?;
            println!(
                "baseline recorded in {} ({} runs, {} calibrations); commit it",
                options.baseline.display(),
                rows.len(),
                info.calibrations.len()
            );
            Ok(CheckOutcome::Passed)
        }
        Some((old_info, old_rows)) => {
            let compared = compare(&old_info, &old_rows, &info, &rows, options.noise)?;
            let timings_decide = timings_decide(&old_info.boot_id, &info.boot_id);
            let text = summary(options, &old_info, &info, &compared, timings_decide);
            print!("{text}");
            let path = options.out.join("summary.md");
            write_atomically(&path, |out| out.write_all(text.as_bytes()))?;
            println!("summary written to {}", path.display());
            Ok(
                match compared
                    .iter()
                    .any(|row| row.verdict == Verdict::Regressed && decides(row, timings_decide))
                {
                    true => CheckOutcome::Regressed,
                    false => CheckOutcome::Passed,
                },
            )
        }
    }
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
    Ok((info, records))
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
            },
        });
    }
    match (&old_info.instructions, &new_info.instructions) {
        (Some(old), Some(new)) if old.command == new.command => {
            let ratio = new.instructions as f64 / old.instructions as f64;
            let exact = Interval {
                lower: ratio,
                point: ratio,
                upper: ratio,
            };
            rows.push(Row {
                what: "serial instructions (callgrind)".to_owned(),
                unit: INSTRUCTIONS,
                old: old.instructions as f64,
                new: new.instructions as f64,
                ratio: exact,
                verdict: stats::verdict(&exact, INSTRUCTION_NOISE),
                wall: None,
                note: format!("noise threshold {:.0}%", 100.0 * INSTRUCTION_NOISE),
            });
        }
        _ => {}
    }
    Ok(rows)
}

/// Instructions of the first serial configuration, shrunk to a small run, under
/// callgrind; `None` (with a note) where valgrind is not installed.
fn count_instructions(
    configuration: &Configuration,
    scene_dir: &Path,
    simulate_args: &[String],
) -> anyhow::Result<Option<InstructionCount>> {
    let valgrind = Command::new("valgrind").arg("--version").output();
    if !valgrind.is_ok_and(|out| out.status.success()) {
        eprintln!(
            "note: valgrind is not installed: no instruction counts (apt-get install valgrind)"
        );
        return Ok(None);
    }
    let mut small = configuration.clone();
    small.overrides.n = Some(INSTRUCTION_DISKS);
    small.overrides.steps = Some(INSTRUCTION_STEPS);
    let scene = runner::materialize_scenes(scene_dir, &[&small])?.remove(0);
    let mut command = vec!["simulate".to_owned(), scene.display().to_string()];
    command.extend(small.simulate_args());
    let exe = std::env::current_exe().context("cannot find this program's path")?;
    let out = Command::new("valgrind")
        .args(["--tool=callgrind", "--callgrind-out-file=/dev/null"])
        .arg(&exe)
        .args(&command)
        .args(simulate_args)
        .output()
        .context("cannot run valgrind")?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    let collected = stderr
        .lines()
        .find_map(|line| line.split_once("Collected :").map(|(_, n)| n.trim()))
        .and_then(|n| n.parse().ok());
    match (out.status.success(), collected) {
        (true, Some(instructions)) => Ok(Some(InstructionCount {
            command,
            instructions,
        })),
        _ => bail!(
            "callgrind of `collide {}` failed{}",
            command.join(" "),
            crate::system::process::tail("its output", &stderr)
        ),
    }
}

/// The markdown summary, printed to the terminal and written to `summary.md`.
fn summary(
    options: &CheckOptions,
    old_info: &BaselineInfo,
    new_info: &BaselineInfo,
    rows: &[Row],
    timings_decide: bool,
) -> String {
    let regressed = rows
        .iter()
        .filter(|r| r.verdict == Verdict::Regressed && decides(r, timings_decide))
        .count();
    let advisory = rows
        .iter()
        .filter(|r| r.verdict == Verdict::Regressed && !decides(r, timings_decide))
        .count();
    let improved = rows
        .iter()
        .filter(|r| r.verdict == Verdict::Improved)
        .count();
    let mut out = String::new();
    let _ = writeln!(
        out,
        "# collide check: {}\n",
        match (regressed, advisory) {
            (0, 0) => "no regression".to_owned(),
            (0, n) => format!("no regression ({n} timing regression(s) reported, not judged)"),
            (n, _) => format!("{n} REGRESSED"),
        }
    );
    let _ = writeln!(out, "- manifest: `{}`", options.manifest.display());
    let _ = writeln!(
        out,
        "- baseline `{}`: {}",
        options.baseline.display(),
        describe(old_info)
    );
    let _ = writeln!(out, "- this run: {}", describe(new_info));
    write_method(&mut out, options, old_info, timings_decide);
    write_table(&mut out, rows);
    if new_info.instructions.is_none() {
        let _ = writeln!(
            out,
            "\nNo instruction counts: valgrind is not installed on this machine."
        );
    }
    let _ = writeln!(
        out,
        "\nverdict: {regressed} regressed, {improved} improved, {} unchanged{}",
        rows.len() - regressed - improved - advisory,
        match advisory {
            0 => String::new(),
            n => format!(", {n} timing regression(s) not judged (another machine)"),
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
        match timings_decide {
            true => "timing verdicts decide: the baseline was recorded on this machine since \
                     its last boot"
                .to_owned(),
            false => format!(
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
fn write_table(out: &mut String, rows: &[Row]) {
    let _ = writeln!(
        out,
        "| configuration | measure | baseline median | median now | ratio | {:.0}% interval | verdict | wall ratio (interval) | note |",
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
    fn timings_decide_only_on_the_boot_the_baseline_was_recorded_on() {
        assert!(timings_decide("boot-a", "boot-a"));
        assert!(!timings_decide("boot-a", "boot-b"));
        // Baselines from before boot ids were kept, and systems that do not tell.
        assert!(!timings_decide("", "boot-b"));
        assert!(!timings_decide("", ""));
    }
}
