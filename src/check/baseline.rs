//! The baseline folder of `collide check` (`records.parquet` and `baseline.json`, what
//! it was recorded from and on): read and validated before anything is measured, written
//! only by `--update-baseline`; whether its timings may decide here (the same boot); and
//! the history each comparing check appends its deciding verdicts to. Comparing with the
//! baseline is `compare`'s.

use std::path::Path;

use anyhow::{Context, bail};
use serde::{Deserialize, Serialize};

use crate::check::against;
use crate::check::compare::Row;
use crate::check::instructions::InstructionCount;
use crate::study::environment::Environment;
use crate::study::history;
use crate::study::records::{self, Record, STATUS_OK};
use crate::study::runner::Calibration;
use crate::system::output::write_atomically;

/// Version of `baseline.json`; a baseline of another version must be re-recorded.
pub const BASELINE_FORMAT: u32 = 2;
const BASELINE_INFO: &str = "baseline.json";
const BASELINE_RECORDS: &str = "records.parquet";

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

/// A baseline: its description and its records. What one check measured has the same
/// shape, and `--update-baseline` keeps it as the baseline.
pub struct Baseline {
    pub info: BaselineInfo,
    pub records: Vec<Record>,
}

/// The running kernel's boot id; empty where the system does not say.
pub fn boot_id() -> String {
    std::fs::read_to_string("/proc/sys/kernel/random/boot_id")
        .map(|id| id.trim().to_owned())
        .unwrap_or_default()
}

/// Whether timing verdicts decide the outcome: only against a baseline recorded on this
/// very machine since its last boot. Across machines (and VM instances, and reboots) the
/// calibration leaves the simulator's normalised time off by up to about 20% (docs/ci-check.md),
/// beyond any useful noise threshold; instruction counts do not move and always decide.
pub fn timings_decide(baseline_boot: &str, this_boot: &str) -> bool {
    !this_boot.is_empty() && baseline_boot == this_boot
}

/// What the error of a baseline that cannot be used asks the user to do.
const RE_RECORD: &str =
    "record one on purpose with `collide check --update-baseline` and commit it";

/// The baseline in `dir`, if it can be compared with a run of this manifest and build.
pub fn load(
    dir: &Path,
    manifest_hash: &str,
    environment: &Environment,
) -> anyhow::Result<Baseline> {
    let info = read_info(dir)?;
    if info.manifest_hash != manifest_hash {
        bail!(
            "the baseline in {} was recorded from another version of {}; {RE_RECORD}",
            dir.display(),
            info.manifest
        );
    }
    // Features add backends only (MPI): the configurations both builds run compare, and
    // the summary names those this build cannot run.
    let (old, new) = (&info.environment, environment);
    if old.profile != new.profile {
        bail!(
            "the baseline in {} was recorded by a {} build, this is a {} build; build with \
             `--release`, or {RE_RECORD}",
            dir.display(),
            old.profile,
            new.profile,
        );
    }
    let records = records::read(&dir.join(BASELINE_RECORDS))
        .with_context(|| format!("the baseline's records cannot be read; {RE_RECORD}"))?;
    if let Err(field) = impossible_in(&info, &records) {
        bail!(
            "the baseline in {} has {field}, which no measurement gives: it was edited or \
             damaged; restore it from git, or {RE_RECORD}",
            dir.display()
        );
    }
    Ok(Baseline { info, records })
}

/// `baseline.json` in `dir`, if it is there and of this collide's format.
fn read_info(dir: &Path) -> anyhow::Result<BaselineInfo> {
    let info_path = dir.join(BASELINE_INFO);
    let text = std::fs::read_to_string(&info_path)
        .with_context(|| format!("no baseline at {}; {RE_RECORD}", info_path.display()))?;
    let info: BaselineInfo = serde_json::from_str(&text).with_context(|| {
        format!(
            "{} is not a baseline this collide reads; {RE_RECORD}",
            info_path.display()
        )
    })?;
    if info.format != BASELINE_FORMAT {
        bail!(
            "{} has baseline format {}, this collide reads {BASELINE_FORMAT}; {RE_RECORD}",
            info_path.display(),
            info.format
        );
    }
    Ok(info)
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

/// Records `baseline` in `dir`: its records, then its description.
pub fn write(dir: &Path, baseline: &Baseline) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the baseline folder {}", dir.display()))?;
    records::write(&dir.join(BASELINE_RECORDS), &baseline.records)?;
    let json = serde_json::to_string_pretty(&baseline.info)?;
    write_atomically(&dir.join(BASELINE_INFO), |out| writeln!(out, "{json}"))
}

/// Appends the verdicts that decided this check (`info`'s) to the history in `dir`;
/// they were compared with the build of `ab` in an A/B check, with `old_info`'s
/// baseline otherwise.
pub fn append_history(
    dir: &Path,
    quiet: bool,
    deciding: &[&Row],
    info: &BaselineInfo,
    old_info: &BaselineInfo,
    ab: Option<&against::Rev>,
) -> anyhow::Result<()> {
    let against = match ab {
        Some(rev) => format!("A/B against {}", against::short(&rev.commit)),
        None => format!("baseline of {}", old_info.environment.git_commit),
    };
    let entries: Vec<history::Entry> = deciding
        .iter()
        .map(|row| history_entry(row, info, &against))
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

/// A compared row's line in the history.
fn history_entry(row: &Row, info: &BaselineInfo, against: &str) -> history::Entry {
    history::Entry {
        commit: info.environment.git_commit.clone(),
        dirty: info.environment.git_dirty,
        checked_utc: info.recorded_utc.clone(),
        against: against.to_owned(),
        what: row.what.clone(),
        key: row.key.clone(),
        measure: row.unit.to_owned(),
        old: row.old,
        new: row.new,
        ratio: row.ratio.point,
        lower: row.ratio.lower,
        upper: row.ratio.upper,
        verdict: row.verdict.name().to_owned(),
        inject_slowdown: info.inject_slowdown,
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
}
