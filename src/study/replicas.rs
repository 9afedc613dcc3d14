//! The replica check: runs of one setup that differ only in their seed are independent
//! replicas of one measurement. Each observable's means over the seeds give a replica
//! mean with the standard error of their spread (Student's t,
//! [`crate::stats::series::replica_estimate`]), set beside the error the runs' own
//! blocked error bars give that mean; a disagreement by more than [`DISAGREEMENT`]× is
//! flagged. Pure: records in, numbers out. The records carry the result in every row of
//! the group ([`fill`], when they are written), the report shows and flags it
//! ([`checks`]).

use std::collections::BTreeMap;

use crate::stats::series::{ReplicaEstimate, replica_estimate};
use crate::study::records::{Record, STATUS_OK};

/// The replica and within-run standard errors disagree when one is more than this many
/// times the other.
pub const DISAGREEMENT: f64 = 2.0;

/// An observable the check compares over seeds: its name in words, its mean and
/// blocked standard error in a record (NaN where the run did not equilibrate), and the
/// record's columns of its replica mean and standard error.
pub struct Observable {
    pub name: &'static str,
    pub mean: fn(&Record) -> f64,
    pub se: fn(&Record) -> f64,
    pub replica_columns: fn(&mut Record) -> (&mut f64, &mut f64),
}

/// An [`Observable`] from its record columns: mean, SE, replica mean, replica SE.
macro_rules! observable {
    ($name:literal: $mean:ident, $se:ident, $replica_mean:ident, $replica_se:ident) => {
        Observable {
            name: $name,
            mean: |r| r.$mean,
            se: |r| r.$se,
            replica_columns: |r| (&mut r.$replica_mean, &mut r.$replica_se),
        }
    };
}

/// The observables checked, in the report's order.
pub const OBSERVABLES: [Observable; 2] = [
    observable!("Z": compressibility_z, compressibility_z_se,
        compressibility_z_replica_mean, compressibility_z_replica_se),
    observable!("collision rate": collision_rate, collision_rate_se,
        collision_rate_replica_mean, collision_rate_replica_se),
];

/// One observable over the seeds of one setup.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReplicaCheck {
    /// The mean over the seeds with the standard error of their spread.
    pub replica: ReplicaEstimate,
    /// The standard error of that mean from the runs' own error bars, √(Σ SE_r²)/R.
    pub within_se: f64,
}

impl ReplicaCheck {
    /// Replica SE over within-run SE (1: they agree; NaN when both are 0).
    pub fn ratio(&self) -> f64 {
        self.replica.se / self.within_se
    }

    /// Whether one standard error is more than [`DISAGREEMENT`] times the other (two
    /// zeros agree).
    pub fn disagrees(&self) -> bool {
        let ratio = self.ratio();
        !ratio.is_nan() && !(1.0 / DISAGREEMENT..=DISAGREEMENT).contains(&ratio)
    }
}

/// The replicas of one setup: every observable of [`OBSERVABLES`], in order.
#[derive(Clone, Debug, PartialEq)]
pub struct ReplicaGroup {
    /// The setup in words, without the seed.
    pub label: String,
    /// The seeds, ascending.
    pub seeds: Vec<u64>,
    pub checks: Vec<ReplicaCheck>,
}

/// The setups run with at least two seeds, in the order of their first record: the runs
/// that equilibrated (a blocked error bar), one per seed (runs of one seed on other
/// backends or in other repetitions compute the same numbers), keyed by
/// [`Record::replica_key`].
pub fn checks(records: &[Record]) -> Vec<(String, ReplicaGroup)> {
    let mut order: Vec<String> = Vec::new();
    let mut by_seed: BTreeMap<String, BTreeMap<u64, &Record>> = BTreeMap::new();
    let settled = records
        .iter()
        .filter(|r| r.status == STATUS_OK && r.compressibility_z_se.is_finite());
    for record in settled {
        let Some(seed) = record.seed else { continue };
        let key = record.replica_key();
        let seeds = by_seed.entry(key.clone()).or_insert_with(|| {
            order.push(key);
            BTreeMap::new()
        });
        seeds.entry(seed).or_insert(record);
    }
    order
        .into_iter()
        .filter_map(|key| {
            let runs: Vec<&Record> = by_seed[&key].values().copied().collect();
            let checks = OBSERVABLES
                .iter()
                .map(|observable| check(&runs, observable))
                .collect::<Option<Vec<_>>>()?;
            let group = ReplicaGroup {
                label: runs[0].label_without(&["seed"]),
                seeds: by_seed[&key].keys().copied().collect(),
                checks,
            };
            Some((key, group))
        })
        .collect()
}

/// One observable over `runs` (one per seed); `None` for fewer than two.
fn check(runs: &[&Record], observable: &Observable) -> Option<ReplicaCheck> {
    let means: Vec<f64> = runs.iter().map(|r| (observable.mean)(r)).collect();
    let replica = replica_estimate(&means)?;
    let squares: f64 = runs.iter().map(|r| (observable.se)(r).powi(2)).sum();
    Some(ReplicaCheck {
        replica,
        within_se: squares.sqrt() / runs.len() as f64,
    })
}

/// Sets the replica columns of every successful row whose setup was run with at least
/// two seeds among `records` (NaN and null in the others).
pub fn fill(records: &mut [Record]) {
    let groups: BTreeMap<String, ReplicaGroup> = checks(records).into_iter().collect();
    for record in records.iter_mut() {
        let group = (record.status == STATUS_OK)
            .then(|| groups.get(&record.replica_key()))
            .flatten();
        record.replicas = group.map(|g| g.seeds.len() as u64);
        for (index, observable) in OBSERVABLES.iter().enumerate() {
            let replica = group.map(|g| g.checks[index].replica);
            let (mean, se) = (observable.replica_columns)(record);
            *mean = replica.map_or(f64::NAN, |e| e.mean);
            *se = replica.map_or(f64::NAN, |e| e.se);
        }
    }
}
