//! `collide results`: terminal tables of a study's records — median wall time and its
//! spread per configuration, whether the backends agreed on `state_hash`, and per setup
//! the seed-style table of median seconds, speedup and efficiency per backend (which
//! `collide run` prints at its end too).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::bail;

use crate::analysis::{self, Setup};
use crate::manifest::Scaling;
use crate::records::{self, Record, STATUS_OK};
use crate::report::describe;

/// Every record under `path` (a results file, or a study folder of them).
pub fn load(path: &Path) -> anyhow::Result<Vec<Record>> {
    let files: Vec<PathBuf> = if path.is_dir() {
        records::files_in(path)?
    } else {
        vec![path.to_owned()]
    };
    if files.is_empty() {
        bail!(
            "no .parquet results in {}; run a study first (`collide run experiments/NAME.toml`)",
            path.display()
        );
    }
    let mut all = Vec::new();
    for file in files {
        all.extend(records::read(&file)?);
    }
    Ok(all)
}

/// What `collide results` prints: [`table`], then [`scaling_table`].
pub fn summary(records: &[Record]) -> anyhow::Result<String> {
    let setups = analysis::analyse(records)?;
    Ok(format!("{}{}", table(records), scaling_table(&setups)))
}

/// Per setup that scales, the seed's table: one line per worker count, and per backend
/// the median seconds, the speedup S(p) and the efficiency E(p) (as in the report).
pub fn scaling_table(setups: &[Setup]) -> String {
    let mut out = String::new();
    for setup in setups.iter().filter(|s| s.scales()) {
        let _ = writeln!(out, "\n{}", describe(setup));
        let mut workers: Vec<u64> = setup
            .backends
            .iter()
            .flat_map(|b| b.points.iter().map(|p| p.workers))
            .collect();
        workers.sort_unstable();
        workers.dedup();
        let _ = write!(out, "{:>7}", "workers");
        for backend in &setup.backends {
            let _ = write!(
                out,
                " {:>12} {:>7} {:>6}",
                format!("{} s", backend.backend),
                "S(p)",
                "E(p)"
            );
        }
        let _ = writeln!(out);
        for p in workers {
            let _ = write!(out, "{p:>7}");
            for backend in &setup.backends {
                match backend.points.iter().find(|point| point.workers == p) {
                    // Without a serial or 1-worker run there is no speedup to show.
                    Some(point) if point.speedup.is_finite() => {
                        let _ = write!(
                            out,
                            " {:>12.4} {:>7.2} {:>5.0}%",
                            point.median_s,
                            point.speedup,
                            100.0 * point.efficiency
                        );
                    }
                    Some(point) => {
                        let _ = write!(out, " {:>12.4} {:>7} {:>6}", point.median_s, "—", "—");
                    }
                    None => {
                        let _ = write!(out, " {:>12} {:>7} {:>6}", "", "", "");
                    }
                }
            }
            let _ = writeln!(out);
        }
    }
    if !out.is_empty() {
        let _ = writeln!(
            out,
            "\nMedian seconds of the stepping loop; speedup S(p) against the serial backend \
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

/// Median of a non-empty slice.
pub fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let mid = values.len() / 2;
    if values.len() % 2 == 1 {
        values[mid]
    } else {
        0.5 * (values[mid - 1] + values[mid])
    }
}

/// The table, one line per configuration in first-seen order, then the hash check.
pub fn table(records: &[Record]) -> String {
    let mut order: Vec<&str> = Vec::new();
    let mut groups: BTreeMap<&str, Vec<&Record>> = BTreeMap::new();
    for record in records {
        let group = groups.entry(&record.config_key).or_default();
        if group.is_empty() {
            order.push(&record.config_key);
        }
        group.push(record);
    }
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<9} {:>7} {:>9} {:>7} {:>12} {:>21} {:>4} {:>6}  scene",
        "backend", "workers", "n", "steps", "median s", "min–max s", "reps", "failed"
    );
    for key in &order {
        let group = &groups[key];
        let ok: Vec<&&Record> = group.iter().filter(|r| r.status == STATUS_OK).collect();
        let mut times: Vec<f64> = ok.iter().map(|r| r.wall_s).collect();
        let first = group[0];
        let (median_s, spread) = if times.is_empty() {
            ("—".to_owned(), "—".to_owned())
        } else {
            let median_s = median(&mut times);
            (
                format!("{median_s:.4}"),
                format!("{:.4}–{:.4}", times[0], times[times.len() - 1]),
            )
        };
        let shown = ok.first().copied().copied().unwrap_or(first);
        let oversubscribed = if shown.oversubscribed {
            " (oversubscribed)"
        } else {
            ""
        };
        let _ = writeln!(
            out,
            "{:<9} {:>7} {:>9} {:>7} {:>12} {:>21} {:>4} {:>6}  {}{oversubscribed}",
            first.backend,
            first.workers,
            shown.n,
            shown.steps,
            median_s,
            spread,
            ok.len(),
            group.len() - ok.len(),
            first.scene
        );
    }
    let _ = write!(out, "{}", hash_agreement(records));
    out
}

/// One line per physical setup (scene, n, steps, dt, seed, packing) measured by more than
/// one configuration: whether every successful run gave the same final state.
fn hash_agreement(records: &[Record]) -> String {
    let mut setups: BTreeMap<String, BTreeMap<&str, Vec<String>>> = BTreeMap::new();
    for record in records.iter().filter(|r| r.status == STATUS_OK) {
        setups
            .entry(record.setup_key())
            .or_default()
            .entry(&record.state_hash)
            .or_default()
            .push(format!("{} {}", record.backend, record.workers));
    }
    let mut out = String::new();
    for (setup, hashes) in &setups {
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
