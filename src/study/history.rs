//! The check's history: every check appends the verdicts that decided it (one row per
//! configuration and per instruction count) to a folder, one Parquet file per check,
//! named by its time and commit and never overwritten; `collide report` on the folder
//! draws them over the commits. Reading and writing only: the verdicts are the check's
//! (`collide check`).

use std::fs::File;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use polars::prelude::{Column, DataFrame, ParquetReader, SerReader};

use crate::study::environment::Environment;
use crate::system::output::free_path;

/// Version of the history files, their first column.
const HISTORY_VERSION: u32 = 1;
const VERSION_COLUMN: &str = "history_version";

/// One verdict of one check.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// The commit checked, and whether its tracked files had changes.
    pub commit: String,
    pub dirty: bool,
    /// When the check ran (UTC, ISO 8601).
    pub checked_utc: String,
    /// What it was compared with: `A/B against <commit>` or `baseline of <commit>`.
    pub against: String,
    /// The configuration (or instruction count), as the summary names it.
    pub what: String,
    /// The configuration's key, or the backend's name for an instruction count.
    pub key: String,
    /// What `old` and `new` count: `wall s`, `CPU s` or `instructions`.
    pub measure: String,
    /// Medians (or counts) of the build compared with and of this one.
    pub old: f64,
    pub new: f64,
    /// The ratio new/old and its 95% interval (equal for an instruction count).
    pub ratio: f64,
    pub lower: f64,
    pub upper: f64,
    /// `regressed`, `improved` or `unchanged`.
    pub verdict: String,
    /// Non-zero only in checks of the check itself.
    pub inject_slowdown: f64,
}

/// Declares the history's columns once: the [`Entry`] field of each, by type.
macro_rules! for_each_field {
    ($apply:ident) => {
        $apply! {
            str: commit, checked_utc, against, what, key, measure, verdict;
            bool: dirty;
            f64: old, new, ratio, lower, upper, inject_slowdown
        }
    };
}

/// Appends `entries` as a new file `<dir>/<UTC time>-<commit>.parquet` (`-2`, `-3`, ...
/// when that name is taken), written atomically; returns its path.
pub fn append(dir: &Path, environment: &Environment, entries: &[Entry]) -> anyhow::Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| {
        format!(
            "cannot create the history folder {}; choose another with --history",
            dir.display()
        )
    })?;
    let stamp: String = crate::study::records::utc_now()
        .chars()
        .filter(char::is_ascii_alphanumeric)
        .collect();
    let base = format!("{stamp}-{}", environment.git_commit);
    let path = free_path(dir, &base, "parquet");
    crate::study::records::write_frame(&path, &mut to_frame(entries)?, "the history")?;
    Ok(path)
}

fn to_frame(entries: &[Entry]) -> anyhow::Result<DataFrame> {
    let mut columns = vec![Column::new(
        VERSION_COLUMN.into(),
        vec![HISTORY_VERSION; entries.len()],
    )];
    macro_rules! push_columns {
        ($($kind:ident: $($name:ident),*);*) => {
            $($(
                columns.push(Column::new(
                    stringify!($name).into(),
                    entries.iter().map(|e| e.$name.clone()).collect::<Vec<_>>(),
                ));
            )*)*
        };
    }
    for_each_field!(push_columns);
    Ok(DataFrame::new_infer_height(columns)?)
}

/// Whether `dir` is a history folder: it holds `.parquet` files and the first is a
/// history file.
pub fn is_history(dir: &Path) -> bool {
    let Ok(files) = crate::study::records::files_in(dir) else {
        return false;
    };
    files.first().is_some_and(|path| {
        File::open(path)
            .ok()
            .and_then(|file| ParquetReader::new(file).finish().ok())
            .is_some_and(|frame| frame.column(VERSION_COLUMN).is_ok())
    })
}

/// Every entry in the history folder `dir`, oldest check first.
pub fn read(dir: &Path) -> anyhow::Result<Vec<Entry>> {
    let mut entries = Vec::new();
    for path in crate::study::records::files_in(dir)? {
        let frame = File::open(&path)
            .map_err(anyhow::Error::from)
            .and_then(|file| Ok(ParquetReader::new(file).finish()?))
            .with_context(|| format!("cannot read the history file {}", path.display()))?;
        entries.extend(from_frame(&frame).with_context(|| format!("{}", path.display()))?);
    }
    entries.sort_by(|a, b| a.checked_utc.cmp(&b.checked_utc));
    Ok(entries)
}

fn from_frame(frame: &DataFrame) -> anyhow::Result<Vec<Entry>> {
    let version = frame
        .column(VERSION_COLUMN)
        .ok()
        .and_then(|c| c.u32().ok()?.get(0));
    if version.is_some_and(|v| v != HISTORY_VERSION) || frame.column(VERSION_COLUMN).is_err() {
        bail!("not a history file of this collide (history version {HISTORY_VERSION})");
    }
    let height = frame.height();
    let mut entries = vec![
        Entry {
            commit: String::new(),
            dirty: false,
            checked_utc: String::new(),
            against: String::new(),
            what: String::new(),
            key: String::new(),
            measure: String::new(),
            old: f64::NAN,
            new: f64::NAN,
            ratio: f64::NAN,
            lower: f64::NAN,
            upper: f64::NAN,
            verdict: String::new(),
            inject_slowdown: 0.0,
        };
        height
    ];
    let column = |name: &str| {
        frame
            .column(name)
            .with_context(|| format!("no `{name}` column in a history file"))
    };
    macro_rules! read_columns {
        ($($kind:ident: $($name:ident),*);*) => {
            $($(
                read_columns!(@$kind $name);
            )*)*
        };
        (@str $name:ident) => {
            let values = column(stringify!($name))?.str()?;
            for (entry, value) in entries.iter_mut().zip(values.iter()) {
                entry.$name = value.unwrap_or_default().to_owned();
            }
        };
        (@bool $name:ident) => {
            let values = column(stringify!($name))?.bool()?;
            for (entry, value) in entries.iter_mut().zip(values.iter()) {
                entry.$name = value.unwrap_or_default();
            }
        };
        (@f64 $name:ident) => {
            let values = column(stringify!($name))?.f64()?;
            for (entry, value) in entries.iter_mut().zip(values.iter()) {
                entry.$name = value.unwrap_or(f64::NAN);
            }
        };
    }
    for_each_field!(read_columns);
    Ok(entries)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(verdict: &str, ratio: f64) -> Entry {
        Entry {
            commit: "abc".to_owned(),
            dirty: false,
            checked_utc: "2026-11-23T19:00:00Z".to_owned(),
            against: "A/B against def".to_owned(),
            what: "gas serial ×1".to_owned(),
            key: "gas/serial/1".to_owned(),
            measure: "wall s".to_owned(),
            old: 0.06,
            new: 0.06 * ratio,
            ratio,
            lower: ratio - 0.01,
            upper: ratio + 0.01,
            verdict: verdict.to_owned(),
            inject_slowdown: 0.0,
        }
    }

    #[test]
    fn appending_never_overwrites_and_reads_back_every_entry() {
        let dir = std::env::temp_dir().join(format!("collide-history-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let environment = Environment::capture();
        let first = append(&dir, &environment, &[entry("unchanged", 1.0)]).unwrap();
        // Two checks in the same second: the second gets a name of its own.
        let second = append(
            &dir,
            &environment,
            &[entry("regressed", 1.2), entry("improved", 0.8)],
        )
        .unwrap();
        assert_ne!(first, second);
        assert!(is_history(&dir));
        let read = read(&dir).unwrap();
        assert_eq!(read.len(), 3);
        assert!(read.contains(&entry("regressed", 1.2)));
        assert!(read.contains(&entry("unchanged", 1.0)));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
