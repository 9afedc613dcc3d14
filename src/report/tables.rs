//! `collide results`: a study's records found and read, then its tables — the
//! configurations' (`configurations`), whether the backends agreed on `state_hash`, and
//! per setup the seed-style table of median times, speedup and efficiency per backend
//! (which `collide run` prints at its end too); or the configurations as CSV, JSON or
//! markdown.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

use crate::report::analysis::{self, Setup};
use crate::report::configurations::{Format, Table};
use crate::report::markdown::describe;
use crate::report::units::TimeUnit;
use crate::study::manifest::Scaling;
use crate::study::records::{self, Record, STATUS_OK};

/// Every record under `path`: a results file, or a study folder of them. In a folder, a
/// file that cannot be read, or holds no runs, is skipped with a warning that names it
/// and says why; a file named on its own must be readable. A folder whose subfolders
/// are studies is refused with their list ([`study_folders`]).
pub fn load(path: &Path) -> anyhow::Result<Vec<Record>> {
    if !path.is_dir() {
        let records = records::read(path)?;
        if records.is_empty() {
            bail!(
                "{} holds no runs: the study stopped before its first run ended",
                path.display()
            );
        }
        return Ok(records);
    }
    let files = records::files_in(path)?;
    if files.is_empty() {
        let studies = study_folders(path)?;
        if studies.is_empty() {
            bail!(
                "no .parquet results in {}; run a study first (`collide run experiments/NAME.toml`)",
                path.display()
            );
        }
        bail!(
            "{} holds no results files itself but {} study folder(s):\n{}name one of them",
            path.display(),
            studies.len(),
            list_folders(&studies)
        );
    }
    let mut all = Vec::new();
    let mut skipped = Vec::new();
    for file in files {
        match records::read(&file) {
            Ok(rows) if rows.is_empty() => skipped.push(format!(
                "{} holds no runs: its study stopped before its first run ended",
                file.display()
            )),
            Ok(rows) => all.extend(rows),
            Err(err) => skipped.push(format!("{err:#}")),
        }
    }
    for reason in &skipped {
        eprintln!("warning: skipped {reason}");
    }
    let (all, copies) = records::without_copies(all);
    if copies > 0 {
        eprintln!(
            "warning: {copies} row(s) in {} are copies of runs in another file there (a \
             backup, or rows a resumed study carried over); each run is counted once",
            path.display()
        );
    }
    if all.is_empty() {
        bail!(
            "no readable runs in {}: every results file there was skipped (see the warnings); \
             run the study again",
            path.display()
        );
    }
    Ok(all)
}

/// What `collide results` prints of one study: the configurations' [`Table`], whether
/// the backends agreed ([`hash_agreement`]), then [`scaling_table`].
pub fn summary(records: &[Record]) -> anyhow::Result<String> {
    let setups = analysis::analyse(records)?;
    Ok(format!(
        "{}{}{}",
        Table::of(records).text(),
        hash_agreement(records),
        scaling_table(&setups)
    ))
}

/// Per setup that scales, the seed's table: one line per worker count, and per backend
/// the median seconds, the speedup S(p) and the efficiency E(p) (as in the report).
pub fn scaling_table(setups: &[Setup]) -> String {
    let mut out = String::new();
    for setup in setups.iter().filter(|s| s.scales()) {
        let _ = writeln!(out, "\n{}", describe(setup));
        let workers = setup.worker_counts();
        // Each backend's times in the unit that fits its fastest.
        let units: Vec<TimeUnit> = (setup.backends.iter())
            .map(|b| TimeUnit::for_column(b.points.iter().map(|p| p.median_s)))
            .collect();
        // A curve's column is as wide as its label (`mpi, 2 threads/rank`), at least 12.
        let widths: Vec<usize> = (setup.backends.iter())
            .map(|b| b.label().chars().count().max(12))
            .collect();
        let _ = write!(out, "{:>7}", "workers");
        for (backend, width) in setup.backends.iter().zip(&widths) {
            let _ = write!(
                out,
                " {:>width$} {:>7} {:>6}",
                backend.label(),
                "S(p)",
                "E(p)"
            );
        }
        let _ = writeln!(out);
        for p in workers {
            let _ = write!(out, "{p:>7}");
            for ((backend, unit), width) in setup.backends.iter().zip(&units).zip(&widths) {
                match backend.points.iter().find(|point| point.workers == p) {
                    // Without a serial or 1-worker run there is no speedup to show.
                    Some(point) if point.speedup.is_finite() => {
                        let _ = write!(
                            out,
                            " {:>width$} {:>7.2} {:>5.0}%",
                            unit.format(point.median_s),
                            point.speedup,
                            100.0 * point.efficiency
                        );
                    }
                    Some(point) => {
                        let _ = write!(
                            out,
                            " {:>width$} {:>7} {:>6}",
                            unit.format(point.median_s),
                            "—",
                            "—"
                        );
                    }
                    None => {
                        let _ = write!(out, " {:>width$} {:>7} {:>6}", "", "", "");
                    }
                }
            }
            let _ = writeln!(out);
        }
    }
    if !out.is_empty() {
        let _ = writeln!(
            out,
            "\nMedian time of the stepping loop; speedup S(p) against the serial backend \
             (else the same backend at 1 worker); efficiency E(p) = S(p)/p."
        );
    }
    if setups
        .iter()
        .any(|s| s.scales() && s.scaling == Scaling::Weak)
    {
        let _ = writeln!(
            out,
            "Weak scaling: E(p) = T(1, N₀)/T(p, p·N₀) and S(p) = p·E(p), the scaled speedup."
        );
    }
    out
}

/// A subfolder holding results files: a study's folder, as `collide run` writes them.
#[derive(Clone, Debug, PartialEq)]
pub struct StudyFolder {
    pub path: PathBuf,
    pub n_files: usize,
}

/// How many folder levels below the one named [`study_folders`] looks for studies.
const STUDY_DEPTH: usize = 3;

/// The folders below `dir` (down to [`STUDY_DEPTH`] levels, not below a study folder)
/// that hold `.parquet` files, by path.
pub fn study_folders(dir: &Path) -> anyhow::Result<Vec<StudyFolder>> {
    let mut folders = Vec::new();
    let mut level = vec![dir.to_path_buf()];
    for depth in 0..STUDY_DEPTH {
        let mut next = Vec::new();
        for parent in &level {
            let entries = match std::fs::read_dir(parent) {
                Ok(entries) => entries,
                Err(_) if depth > 0 => continue,
                Err(err) => {
                    return Err(err).with_context(|| format!("cannot list {}", dir.display()));
                }
            };
            // Links are not followed: a link to a parent folder would loop.
            let subfolders = entries
                .flatten()
                .filter(|entry| entry.file_type().is_ok_and(|kind| kind.is_dir()));
            for path in subfolders.map(|entry| entry.path()) {
                match records::files_in(&path).map_or(0, |files| files.len()) {
                    0 => next.push(path),
                    n_files => folders.push(StudyFolder { path, n_files }),
                }
            }
        }
        level = next;
    }
    folders.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(folders)
}

/// One line per folder: `  PATH (N results files)`.
pub fn list_folders(folders: &[StudyFolder]) -> String {
    folders
        .iter()
        .map(|f| format!("  {} ({} results file(s))\n", f.path.display(), f.n_files))
        .collect()
}

/// The records split by study, in first-seen order (a folder may hold files copied
/// from several studies).
pub fn by_study(records: Vec<Record>) -> Vec<(String, Vec<Record>)> {
    let mut studies: Vec<(String, Vec<Record>)> = Vec::new();
    for record in records {
        match studies.iter_mut().find(|(name, _)| *name == record.study) {
            Some((_, rows)) => rows.push(record),
            None => studies.push((record.study.clone(), vec![record])),
        }
    }
    studies
}

/// What `collide results PATH` prints: the tables of each study under `path` (a results
/// file, a study folder, a folder of files copied from several studies, or a folder of
/// study folders), each headed by its name when there is more than one; as CSV or JSON,
/// one table of every study's configurations.
pub fn show(path: &Path, format: Format) -> anyhow::Result<String> {
    let folders = match path.is_dir() && records::files_in(path)?.is_empty() {
        true => study_folders(path)?,
        false => Vec::new(),
    };
    let mut studies = Vec::new();
    if folders.is_empty() {
        studies = by_study(load(path)?);
    }
    for folder in &folders {
        match load(&folder.path) {
            Ok(rows) => studies.extend(by_study(rows)),
            Err(err) => eprintln!("warning: skipped {}: {err:#}", folder.path.display()),
        }
    }
    if studies.is_empty() {
        bail!(
            "no readable runs in the study folders of {}",
            path.display()
        );
    }
    let every = || -> Vec<Record> { studies.iter().flat_map(|(_, rows)| rows.clone()).collect() };
    match format {
        Format::Csv => return Ok(Table::of(&every()).csv()),
        Format::Json => return Ok(Table::of(&every()).json()),
        Format::Text | Format::Markdown => {}
    }
    let mut out = String::new();
    if studies.len() > 1 {
        let names: Vec<&str> = studies.iter().map(|(name, _)| name.as_str()).collect();
        let _ = writeln!(
            out,
            "{} studies in {}: {}",
            studies.len(),
            path.display(),
            names.join(", ")
        );
    }
    for (name, rows) in &studies {
        match (format, studies.len() > 1) {
            (Format::Markdown, true) => {
                let _ = writeln!(out, "\n## Study `{name}`\n");
            }
            (_, true) => {
                let _ = writeln!(out, "\nstudy {name}:");
            }
            _ => {}
        }
        match format {
            Format::Markdown => out.push_str(&Table::of(rows).markdown()),
            _ => out.push_str(&summary(rows)?),
        }
    }
    Ok(out)
}

/// The one study `records` belong to; refuses records of several studies, naming them,
/// since one report or comparison covers one study.
pub fn one_study<'a>(records: &'a [Record], path: &Path) -> anyhow::Result<&'a str> {
    let mut names: Vec<&str> = records.iter().map(|r| r.study.as_str()).collect();
    names.sort_unstable();
    names.dedup();
    match names.as_slice() {
        [one] => Ok(one),
        _ => bail!(
            "{} holds the runs of {} studies ({}); a report covers one study: keep each \
             study's files in its own folder (as `collide run` writes them) and report that folder",
            path.display(),
            names.len(),
            names.join(", ")
        ),
    }
}

/// One line per physical setup (scene, n, steps, dt, seed, packing) measured by more than
/// one configuration: whether every successful run gave the same final state.
fn hash_agreement(records: &[Record]) -> String {
    let mut setups: BTreeMap<String, (String, BTreeMap<&str, Vec<String>>)> = BTreeMap::new();
    for record in records.iter().filter(|r| r.status == STATUS_OK) {
        let who = setups
            .entry(record.setup_key())
            .or_insert_with(|| (record.setup_label(), BTreeMap::new()))
            .1
            .entry(&record.state_hash)
            .or_default();
        // Each placement once, however many repetitions it ran.
        let placement = record.placement_label();
        if !who.contains(&placement) {
            who.push(placement);
        }
    }
    let mut out = String::new();
    for (setup, hashes) in setups.values() {
        if hashes.len() == 1 {
            let _ = writeln!(out, "state_hash: all runs agree for {setup}");
        } else {
            let _ = writeln!(out, "state_hash: runs DISAGREE for {setup}:");
            for (hash, who) in hashes {
                let _ = writeln!(out, "  {hash}: {}", who.join(", "));
            }
        }
    }
    out
}
