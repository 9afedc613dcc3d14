//! `collide check`, the CI timing check, orchestrated: runs a small manifest through the
//! study runner (fresh processes, warm-ups, repetitions interleaved with a calibration
//! workload), by this build and, with `--against REV`, by REV's build (`against`)
//! interleaved with it; then compares, writes the summary and appends the deciding
//! verdicts to the history, or records a new baseline with `--update-baseline`. The
//! baseline folder and the history are `baseline`'s, the comparisons `compare`'s (the
//! verdicts `stats`'s), the instruction counts under callgrind `instructions`', the
//! markdown `summary`'s.

pub mod against;
mod baseline;
pub mod calibrate;
mod compare;
mod instructions;
mod summary;

use std::path::{Path, PathBuf};

use anyhow::Context;

use crate::exit::RunsFailed;
use crate::stats::Verdict;
use crate::study::environment::Environment;
use crate::study::manifest::{self, Study};
use crate::study::records::{self, Record};
use crate::study::runner::{self, ENABLE_MPI, Program, RunOptions, Slowdown};
use crate::system::output::{check_output_folder, write_atomically};
use baseline::{Baseline, BaselineInfo};
use compare::{Row, SIDE_A, SIDE_B};

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
        check_output_folder(dir, "--history")?;
    }
    check_output_folder(&options.out, "--out")?;
    let (study, text) = manifest::load(&options.manifest)?;
    let environment = Environment::capture();
    let manifest_hash = runner::text_hash(&text);
    let old = match options.update_baseline {
        true => None,
        false => Some(baseline::load(
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
            old.as_ref().map(|old| &old.info),
            options,
            &this.exe,
            &environment,
        )?),
        None => None,
    };
    let against_program = against.as_ref().map(|(_, a)| a);
    let new = measure(
        &study,
        &text,
        options,
        &this,
        against_program,
        manifest_hash,
        environment,
    )?;
    match old {
        None => record_baseline(options, &new),
        Some(old) => judge(options, &study, &old, &new, against),
    }
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
) -> anyhow::Result<Baseline> {
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
        system: crate::cluster::site::LOCAL.to_owned(),
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
    let records = records::read(&outcome.results)?;
    let scene_dir = options.out.join(&study.name);
    let instructions = instructions::count(&study.configurations, &scene_dir, this)?;
    let info = BaselineInfo {
        format: baseline::BASELINE_FORMAT,
        recorded_utc: records::utc_now(),
        manifest: options.manifest.display().to_string(),
        manifest_hash,
        inject_slowdown: options.slowdown.fraction,
        inject_into: options.slowdown.into.map(|kind| kind.name().to_owned()),
        calibrations: outcome.calibrations,
        instructions,
        environment,
        boot_id: baseline::boot_id(),
    };
    Ok(Baseline { info, records })
}

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

/// `--update-baseline`: keeps what was measured as the baseline.
fn record_baseline(options: &CheckOptions, new: &Baseline) -> anyhow::Result<CheckOutcome> {
    baseline::write(&options.baseline, new)?;
    crate::outln!(
        "baseline recorded in {} ({} runs, {} calibrations); commit it",
        options.baseline.display(),
        new.records.len(),
        new.info.calibrations.len()
    );
    Ok(CheckOutcome::Passed)
}

/// Compares what was measured (`new`) with the baseline `old` and, in an A/B check, B's
/// runs with A's (`against`); writes the summary and appends the deciding verdicts to
/// the history.
fn judge(
    options: &CheckOptions,
    study: &Study,
    old: &Baseline,
    new: &Baseline,
    against: Option<(against::Rev, Program)>,
) -> anyhow::Result<CheckOutcome> {
    // This build's runs: all of them, or side B of an A/B check.
    let this_rows: Vec<Record> = new
        .records
        .iter()
        .filter(|row| row.ab_side != SIDE_A)
        .cloned()
        .collect();
    let mut compared = compare::compare_baseline(old, &new.info, &this_rows, options.noise)?;
    let notes = feature_notes(study, old, new);
    if old.info.environment.features != new.info.environment.features {
        compared.retain(|row| row.unit != compare::INSTRUCTIONS);
    }
    let ab = match against {
        Some((rev, a)) => Some(compare_against(options, study, new, rev, &a)?),
        None => None,
    };
    let timings_decide = baseline::timings_decide(&old.info.boot_id, &new.info.boot_id);
    let text = summary::markdown(
        options,
        &old.info,
        &new.info,
        &compared,
        ab.as_ref(),
        timings_decide,
        &notes,
    );
    write_summary(&options.out, &text)?;
    let deciding: Vec<&Row> = match &ab {
        Some(ab) => ab.rows.iter().collect(),
        None => compared
            .iter()
            .filter(|row| row.decides(timings_decide))
            .collect(),
    };
    if let Some(dir) = &options.history {
        let rev = ab.as_ref().map(|ab| &ab.rev);
        baseline::append_history(dir, options.quiet, &deciding, &new.info, &old.info, rev)?;
    }
    Ok(
        match deciding.iter().any(|row| row.verdict == Verdict::Regressed) {
            true => CheckOutcome::Regressed,
            false => CheckOutcome::Passed,
        },
    )
}

/// What a baseline recorded with other cargo features leaves out, for the summary: the
/// manifest's backends this build cannot run (MPI without the feature `mpi`), and the
/// instruction counts, which the MPI library's loading changes in every process.
fn feature_notes(study: &Study, old: &Baseline, new: &Baseline) -> Vec<String> {
    let mut unrunnable: Vec<&str> = Vec::new();
    for configuration in &study.configurations {
        let name = configuration.backend.name();
        if !configuration.backend.is_available() && !unrunnable.contains(&name) {
            unrunnable.push(name);
        }
    }
    let mut notes = Vec::new();
    if !unrunnable.is_empty() {
        notes.push(format!(
            "not checked: the manifest's {} runs, which this build cannot run; to check them, \
             {ENABLE_MPI}",
            unrunnable.join(", ")
        ));
    }
    let (old_features, new_features) = (
        &old.info.environment.features,
        &new.info.environment.features,
    );
    if old_features != new_features {
        notes.push(format!(
            "instruction counts not compared against the baseline: it was recorded by a build \
             with features [{old_features}], this one has [{new_features}], and loading the MPI \
             library changes every run's count"
        ));
    }
    notes
}

/// The A/B verdicts: B's runs in `new` paired with A's, and A's instruction counts
/// (counted now, by `a`, the build of `rev`) against B's.
fn compare_against(
    options: &CheckOptions,
    study: &Study,
    new: &Baseline,
    rev: against::Rev,
    a: &Program,
) -> anyhow::Result<AbCheck> {
    let scene_dir = options.out.join(&study.name);
    let a_instructions = instructions::count(&study.configurations, &scene_dir, a)?;
    let mut rows = compare::compare_ab(&new.records, options.noise)?;
    rows.extend(compare::compare_instructions(
        &a_instructions,
        &new.info.instructions,
    ));
    Ok(AbCheck { rev, rows })
}

/// Prints the summary and writes it to `summary.md` in `out`.
fn write_summary(out: &Path, text: &str) -> anyhow::Result<()> {
    crate::out!("{text}");
    let path = out.join("summary.md");
    write_atomically(&path, |file| file.write_all(text.as_bytes()))?;
    crate::outln!("summary written to {}", path.display());
    Ok(())
}
