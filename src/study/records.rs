//! Study records: one row per repetition, kept in Parquet through polars (the schema is
//! documented in docs/records.md, which a test keeps in step with [`to_frame`]; a column
//! added is marked with the version that adds it, and one that changes meaning is added
//! under a new name).

use std::fs::File;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use polars::prelude::{
    Column, DataFrame, ParquetCompression, ParquetReader, ParquetWriter, PolarsResult, SerReader,
};

use crate::run::backend_kind::{BackendKind, Placement};
use crate::run::summary::RunSummary;
use crate::study::environment::Environment;
use crate::study::manifest::{PLACEMENT_KEYS, Scaling};
use crate::system::output::write_atomically;

/// The version of the files this collide writes: the newest column's, so that adding a
/// column marked with the next version (`@VERSION` in `for_each_column!`) bumps it.
pub const SCHEMA_VERSION: u32 = newest_version(ADDED_COLUMNS);
/// The first version collide wrote; [`ADDED_COLUMNS`] upgrades every later one.
const OLDEST_READABLE_VERSION: u32 = 1;

/// A value a column takes in files written before the column existed.
#[derive(Clone, Copy, Debug)]
enum Fill {
    Str(&'static str),
    /// Not measured (NaN).
    F64(f64),
    /// Not measured (null).
    NullU64,
}

/// What became of one run.
pub const STATUS_OK: &str = "ok";
pub const STATUS_FAILED: &str = "failed";
pub const STATUS_TIMED_OUT: &str = "timed_out";

/// The parts of a record that do not come from the run itself.
#[derive(Clone, Debug)]
pub struct RecordContext<'a> {
    pub study: &'a str,
    pub manifest_hash: &'a str,
    pub build_id: &'a str,
    pub config_key: &'a str,
    pub scene: &'a str,
    /// xxh3 of the scene file's text (see [`scene_hash`]).
    pub scene_hash: &'a str,
    /// `strong` or `weak`.
    pub scaling: &'a str,
    pub backend: BackendKind,
    /// Its ranks and the threads each steps on.
    pub placement: Placement,
    pub repetition: u32,
    pub environment: &'a Environment,
    pub study_started_utc: &'a str,
}

impl Record {
    /// The row of a run that finished and printed `summary`.
    pub fn measured(context: &RecordContext<'_>, summary: &RunSummary) -> Record {
        let mut record = Record::blank(context, STATUS_OK, String::new());
        record.copy_run(summary);
        [record.momentum_initial_x, record.momentum_initial_y] = summary.momentum_initial;
        [record.momentum_final_x, record.momentum_final_y] = summary.momentum_final;
        record
    }

    /// The row of a run that failed or timed out.
    pub fn failed(context: &RecordContext<'_>, status: &str, error: String) -> Record {
        Record::blank(context, status, error)
    }

    /// A row with the context and the environment, and nothing measured: NaN, zero, ""
    /// or null in every column of the run.
    fn blank(context: &RecordContext<'_>, status: &str, error: String) -> Record {
        let env = context.environment;
        let placement = context.placement;
        let (threads, ranks) = (placement.threads as u64, placement.ranks as u64);
        let workers = placement.workers() as u64;
        Record {
            study: context.study.to_owned(),
            manifest_hash: context.manifest_hash.to_owned(),
            build_id: context.build_id.to_owned(),
            config_key: context.config_key.to_owned(),
            scene: context.scene.to_owned(),
            scene_hash: context.scene_hash.to_owned(),
            scaling: context.scaling.to_owned(),
            repetition: context.repetition,
            status: status.to_owned(),
            error,
            backend: context.backend.name().to_owned(),
            threads,
            ranks,
            workers,
            oversubscribed: threads * ranks > env.usable_cpus as u64,
            hostname: env.hostname.clone(),
            cpu_model: env.cpu_model.clone(),
            logical_cores: env.logical_cores as u64,
            physical_cores: env.physical_cores as u64,
            usable_cpus: Some(env.usable_cpus as u64),
            cpu_affinity: env.cpu_affinity.clone(),
            memory_bytes: env.memory_bytes,
            os: env.os.clone(),
            rustc: env.rustc.clone(),
            profile: env.profile.clone(),
            features: env.features.clone(),
            git_commit: env.git_commit.clone(),
            git_dirty: env.git_dirty,
            mpi_library: env.mpi_library.clone(),
            load_average_start: env.load_average_start,
            load_average: crate::study::environment::load_average(),
            study_started_utc: context.study_started_utc.to_owned(),
            finished_utc: utc_now(),
            ..Record::unmeasured()
        }
    }
}

/// A column's value from the JSON summary's field of the same name: a count widened to
/// u64, a missing number NaN, missing text "", a curve as JSON text.
trait ToCell<T> {
    fn to_cell(&self) -> T;
}

impl ToCell<u64> for usize {
    fn to_cell(&self) -> u64 {
        *self as u64
    }
}

impl<T: Clone> ToCell<T> for T {
    fn to_cell(&self) -> T {
        self.clone()
    }
}

impl ToCell<f64> for Option<f64> {
    fn to_cell(&self) -> f64 {
        self.unwrap_or(f64::NAN)
    }
}

impl ToCell<String> for Option<String> {
    fn to_cell(&self) -> String {
        self.clone().unwrap_or_default()
    }
}

impl ToCell<String> for Option<Vec<[f64; 2]>> {
    fn to_cell(&self) -> String {
        self.as_ref()
            .and_then(|curve| serde_json::to_string(curve).ok())
            .unwrap_or_default()
    }
}

/// What a column holds where nothing was measured.
trait Unmeasured {
    const UNMEASURED: Self;
}

impl Unmeasured for String {
    const UNMEASURED: String = String::new();
}

impl Unmeasured for u64 {
    const UNMEASURED: u64 = 0;
}

impl Unmeasured for u32 {
    const UNMEASURED: u32 = 0;
}

impl Unmeasured for f64 {
    const UNMEASURED: f64 = f64::NAN;
}

impl Unmeasured for bool {
    const UNMEASURED: bool = false;
}

impl Unmeasured for Option<u64> {
    const UNMEASURED: Option<u64> = None;
}

impl Record {
    /// The computation a run did, whatever placed it: its configuration key without the
    /// backend and worker count, the scene's contents and the resolved n (which weak
    /// scaling multiplies by the workers). Runs with the same setup must end in the same
    /// state. Derived from the configuration key, so every override (each declared once
    /// in [`crate::run::overrides`]) is part of it.
    pub fn setup_key(&self) -> String {
        self.computation_with(&format!("n={}", self.n))
    }

    /// The configuration key's entries but the placement and n, then `n` and the scene's
    /// contents.
    fn computation_with(&self, n: &str) -> String {
        let mut entries: Vec<&str> = self
            .config_key
            .split(';')
            .filter(|entry| !entry.starts_with("n="))
            .filter(|entry| !PLACEMENT_KEYS.iter().any(|key| entry.starts_with(key)))
            .collect();
        let scene = format!("scene_hash={}", self.scene_hash);
        entries.extend([n, &scene]);
        entries.join(";")
    }

    /// The setup without its seed: what the runs of other seeds of it share, the
    /// replicas of one measurement ([`crate::study::replicas`]).
    pub fn replica_key(&self) -> String {
        let setup = self.setup_key();
        let entries: Vec<&str> = setup
            .split(';')
            .filter(|entry| !entry.starts_with("seed="))
            .collect();
        entries.join(";")
    }

    /// The setup in words for tables: the scene, n, then every value the configuration
    /// set.
    pub fn setup_label(&self) -> String {
        self.label_without(&[])
    }

    /// The setup in words but the settings named in `shown`: the scene, n, then every
    /// other value the configuration set.
    pub fn label_without(&self, shown: &[&str]) -> String {
        let mut words = vec![self.scene.clone(), format!("n={}", self.n)];
        words.extend(self.settings(shown));
        words.join(" ")
    }

    /// The `NAME=VALUE` entries of the configuration's key that set a value, but the scene,
    /// n, the placement and the names in `shown` elsewhere.
    pub fn settings(&self, shown: &[&str]) -> Vec<String> {
        self.config_key
            .split(';')
            .filter(|entry| !entry.ends_with("=-"))
            .filter(|entry| !PLACEMENT_KEYS.iter().any(|key| entry.starts_with(key)))
            .filter(|entry| {
                let name = entry.split('=').next().unwrap_or_default();
                !["scene", "n"].contains(&name) && !shown.contains(&name)
            })
            .map(str::to_owned)
            .collect()
    }

    /// How the study scaled; anything but `weak` (older files have `strong`) is strong.
    pub fn scaling(&self) -> Scaling {
        if self.scaling == Scaling::Weak.name() {
            Scaling::Weak
        } else {
            Scaling::Strong
        }
    }

    /// The runs one scaling curve compares: the setup, except that in a weak-scaling
    /// study n grows with the workers, so the curve is keyed by n per worker.
    pub fn series_key(&self) -> String {
        match self.scaling() {
            Scaling::Weak => {
                self.computation_with(&format!("n/worker={}", self.n / self.workers.max(1)))
            }
            Scaling::Strong => self.setup_key(),
        }
    }

    /// The threads each MPI rank stepped on, which tell a backend's scaling curves apart
    /// (2 ranks × 2 threads is not 4 ranks × 1); 1 for serial and rayon, whose threads are
    /// their workers.
    pub fn threads_per_rank(&self) -> u64 {
        match BackendKind::from_name(&self.backend) {
            Some(kind) if kind.capabilities().mpi => self.threads,
            _ => 1,
        }
    }

    /// The nodes the run's ranks spread over, from its configuration key (`nodes=N`, left
    /// out for one node and in keys older than placements): another curve of its backend.
    pub fn nodes(&self) -> u64 {
        let [_, _, nodes, _] = PLACEMENT_KEYS;
        (self.config_key.split(';'))
            .find_map(|entry| entry.strip_prefix(nodes)?.parse().ok())
            .unwrap_or(1)
    }

    /// The run's backend and workers in words: `rayon × 4`, `mpi × 4`, or `mpi × 2 ranks
    /// × 2 threads` for MPI ranks on several threads each.
    pub fn placement_label(&self) -> String {
        match self.threads_per_rank() {
            1 => format!("{} × {}", self.backend, self.workers),
            per_rank => {
                let ranks = match self.ranks {
                    1 => "1 rank".to_owned(),
                    count => format!("{count} ranks"),
                };
                format!("{} × {ranks} × {per_rank} threads", self.backend)
            }
        }
    }

    /// Whether the run drew every step offscreen (`draw = true`).
    pub fn drew(&self) -> bool {
        self.draw_s.is_finite()
    }

    /// One run's identity: which repetition of which configuration of which study, on
    /// which host, in which sitting of the study, by which build and side. Rows with the
    /// same run id are copies of one run (a backup of a results file, rows a resumed study
    /// carried).
    pub fn run_id(&self) -> String {
        format!(
            "{}|{}|{}|{}|{}|{}|{}|{}",
            self.study,
            self.hostname,
            self.study_started_utc,
            self.build_id,
            self.config_key,
            self.scene_hash,
            self.ab_side,
            self.repetition
        )
    }

    /// The first value in row `index` that no run can measure (named with its field),
    /// if any: a successful run's negative or non-numeric time, no workers.
    fn impossible(&self, index: usize) -> Option<String> {
        let at = |field: &str, value: String| Some(format!("row {index}: `{field}` = {value}"));
        if self.workers == 0 || self.threads == 0 || self.ranks == 0 {
            return at("workers", self.workers.to_string());
        }
        if self.status != STATUS_OK {
            return None;
        }
        // (`cpu_s` less the drawing's CPU time may come out a little below zero.)
        match self.wall_s.is_finite() && self.wall_s >= 0.0 {
            true => None,
            false => at("wall_s", self.wall_s.to_string()),
        }
    }
}

/// The name of a backend's scaling curve at `threads_per_rank` ([`Record::threads_per_rank`])
/// on `nodes` ([`Record::nodes`]): the backend's name, then the threads of each rank and
/// the nodes where they are more than one (`mpi, 2 threads/rank, 2 nodes`).
pub fn curve_label(backend: &str, threads_per_rank: u64, nodes: u64) -> String {
    let mut label = backend.to_owned();
    if threads_per_rank > 1 {
        label += &format!(", {threads_per_rank} threads/rank");
    }
    if nodes > 1 {
        label += &format!(", {nodes} nodes");
    }
    label
}

/// `records` with every copy of a run after its first left out (by [`Record::run_id`]),
/// and how many were left out.
pub fn without_copies(records: Vec<Record>) -> (Vec<Record>, usize) {
    let mut seen = std::collections::BTreeSet::new();
    let total = records.len();
    let unique: Vec<Record> = records
        .into_iter()
        .filter(|record| seen.insert(record.run_id()))
        .collect();
    let copies = total - unique.len();
    (unique, copies)
}

/// The current UTC time, RFC 3339 to the second.
pub fn utc_now() -> String {
    let seconds = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rest) = (seconds / 86_400, seconds % 86_400);
    let (year, month, day) = civil_from_days(days as i64);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        rest / 3600,
        rest % 3600 / 60,
        rest % 60
    )
}

/// Days since 1970-01-01 → (year, month, day), Howard Hinnant's algorithm.
fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let month = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let year = yoe + era * 400 + i64::from(month <= 2);
    (year, month, day)
}

/// The one list of the schema: every column in Parquet order (after `schema_version`),
/// grouped by type. [`Record`] is declared from it, and so are writing, reading and the
/// blank row. A column marked `<- run` is the JSON summary's field of the same name
/// ([`RunSummary`], where its meaning and unit are documented), copied by
/// [`Record::measured`] through [`ToCell`]; docs/records.md documents every column. A
/// column added after version 1 is marked `@VERSION`, the version that added it (and
/// `= "TEXT"` where older files meant that text rather than "not measured"): the upgrade
/// of older files ([`ADDED_COLUMNS`]) and the version written ([`SCHEMA_VERSION`])
/// follow from the marks.
macro_rules! for_each_column {
    ($apply:ident) => {
        $apply! {
            str: study, manifest_hash, build_id, config_key, scene, scaling @2 = "strong", status, error, backend,
                 boundary <- run, broadphase <- run, state_hash <- run, hostname, cpu_model, os,
                 rustc, profile, features, git_commit, mpi_library, study_started_utc,
                 finished_utc, method <- run @2 = "step", observe <- run @2 = "timing", choice <- run @4,
                 temperature_curve <- run @4, cpu_affinity @6, ab_side @8, scene_hash @10, job_id @11,
                 node_list @11, rank_cpus <- run @13, equilibration_cut <- run @14;
            u64: threads <- run, ranks <- run, workers <- run, n <- run, steps <- run,
                 pair_collisions <- run, wall_collisions <- run, logical_cores, physical_cores,
                 memory_bytes;
            u32: repetition;
            f64: dt <- run, packing <- run, wall_s <- run, cpu_s <- run @3, setup_s <- run,
                 fps <- run, draw_s <- run @7, fps_with_drawing <- run @7, particle_steps_per_s <- run, integration_s <- run,
                 broad_phase_s <- run, collision_s <- run, communication_s <- run,
                 messages_per_step_max <- run @9, messages_per_step_mean <- run @9,
                 bytes_per_step_max <- run @9, bytes_per_step_mean <- run @9,
                 collectives_per_step <- run @9, load_imbalance <- run @13,
                 kinetic_energy_initial <- run, kinetic_energy_final <- run, momentum_initial_x,
                 momentum_initial_y, momentum_final_x, momentum_final_y, max_overlap <- run,
                 max_wall_penetration <- run @6, load_average_start, load_average,
                 load_average_end, events_per_s <- run @2, collision_rate <- run @2,
                 temperature <- run @2, pressure <- run @2, compressibility_z <- run @2,
                 missed_collision_fraction <- run @2, mean_overlap <- run @2,
                 energy_relative_error <- run @2, rms_step_over_radius <- run @3,
                 collapse_time <- run @5, tc <- run @5, queue_wait_s @11,
                 equilibration_cut_time <- run @12, compressibility_z_se <- run @12,
                 compressibility_z_g <- run @12, collision_rate_se <- run @12, temperature_se <- run @12,
                 compressibility_z_replica_mean @14, compressibility_z_replica_se @14,
                 collision_rate_replica_mean @14, collision_rate_replica_se @14;
            bool: oversubscribed <- run, git_dirty;
            opt_u64: seed <- run, missed_collisions <- run @2, collapse_guard_fired <- run @2,
                 usable_cpus @6, replicas @14
        }
    };
}

/// Declares [`Record`] from the column list, its blank row and its copy of a summary.
macro_rules! declare_record {
    ($($kind:ident: $($name:ident $(<- $from:ident)? $(@ $from_added:literal $(= $from_meant:literal)?)?),*);*) => {
        /// One repetition of one configuration: the result of the run (its JSON summary),
        /// the study's context and the environment. Failed runs keep their row, with NaN
        /// measurements, zero counts, an empty `state_hash` and the reason in `error`.
        /// Columns are documented in docs/records.md.
        #[derive(Clone, Debug, PartialEq)]
        pub struct Record {
            $($(pub $name: column_type!($kind),)*)*
        }

        impl Record {
            /// A row with nothing in it: every column's [`Unmeasured`] value.
            fn unmeasured() -> Record {
                Record {
                    $($($name: Unmeasured::UNMEASURED,)*)*
                }
            }

            /// Copies the columns that are the summary's fields.
            fn copy_run(&mut self, summary: &RunSummary) {
                $($($(
                    let _ = stringify!($from); // only the columns marked `<- run`
                    self.$name = summary.$name.to_cell();
                )?)*)*
            }
        }
    };
}

/// The Rust type of a column of each kind.
macro_rules! column_type {
    (str) => { String };
    (u64) => { u64 };
    (u32) => { u32 };
    (f64) => { f64 };
    (bool) => { bool };
    (opt_u64) => { Option<u64> };
}

for_each_column!(declare_record);

/// Declares [`ADDED_COLUMNS`] from the column list: each column marked `@VERSION` (and
/// `= "TEXT"` where older files meant a text of their own).
macro_rules! declare_added_columns {
    ($($kind:ident: $($name:ident $(<- $from:ident)? $(@ $added:literal $(= $meant:literal)?)?),*);*) => {
        /// Columns added after version 1, each with the version that added it and what
        /// older files implicitly meant: reading an older file adds them with that value.
        const ADDED_COLUMNS: &[(u32, &str, Fill)] = &[
            $($($(($added, stringify!($name), older_fill!($kind $(, $meant)?)),)?)*)*
        ];
    };
}

/// What files older than a column meant by its absence: the text it names, or the
/// column kind's "not measured". A count, a flag or a repetition column added later
/// must say what it meant.
macro_rules! older_fill {
    ($kind:ident, $meant:literal) => {
        Fill::Str($meant)
    };
    (str) => {
        Fill::Str("")
    };
    (f64) => {
        Fill::F64(f64::NAN)
    };
    (opt_u64) => {
        Fill::NullU64
    };
}

for_each_column!(declare_added_columns);

/// The newest version among `columns`: the version this collide writes.
const fn newest_version(columns: &[(u32, &str, Fill)]) -> u32 {
    let mut newest = OLDEST_READABLE_VERSION;
    let mut i = 0;
    while i < columns.len() {
        if columns[i].0 > newest {
            newest = columns[i].0;
        }
        i += 1;
    }
    newest
}

/// A column's value as JSON: text, a count, a number (null where not measured), true
/// or false.
trait ToValue {
    fn to_value(&self) -> serde_json::Value;
}

impl ToValue for String {
    fn to_value(&self) -> serde_json::Value {
        serde_json::Value::from(self.as_str())
    }
}

impl ToValue for u64 {
    fn to_value(&self) -> serde_json::Value {
        serde_json::Value::from(*self)
    }
}

impl ToValue for u32 {
    fn to_value(&self) -> serde_json::Value {
        serde_json::Value::from(*self)
    }
}

impl ToValue for f64 {
    fn to_value(&self) -> serde_json::Value {
        // NaN (not measured) has no JSON number: null.
        serde_json::Number::from_f64(*self).map_or(serde_json::Value::Null, Into::into)
    }
}

impl ToValue for bool {
    fn to_value(&self) -> serde_json::Value {
        serde_json::Value::from(*self)
    }
}

impl ToValue for Option<u64> {
    fn to_value(&self) -> serde_json::Value {
        self.map_or(serde_json::Value::Null, Into::into)
    }
}

impl Record {
    /// The value of the column `name` as JSON (null where not measured); `None` when no
    /// column has that name.
    pub fn value(&self, name: &str) -> Option<serde_json::Value> {
        macro_rules! look_up {
            ($($kind:ident: $($column:ident $(<- $from:ident)? $(@ $from_added:literal $(= $from_meant:literal)?)?),*);*) => {
                match name {
                    $($(stringify!($column) => Some(self.$column.to_value()),)*)*
                    _ => None,
                }
            };
        }
        for_each_column!(look_up)
    }
}

/// The records as a table, with `schema_version` first.
pub fn to_frame(records: &[Record]) -> PolarsResult<DataFrame> {
    macro_rules! build {
        (str: $($s:ident $(<- $s_:ident)? $(@ $s__added:literal $(= $s__meant:literal)?)?),*; u64: $($u:ident $(<- $u_:ident)? $(@ $u__added:literal $(= $u__meant:literal)?)?),*;
         u32: $($r:ident $(<- $r_:ident)? $(@ $r__added:literal $(= $r__meant:literal)?)?),*; f64: $($f:ident $(<- $f_:ident)? $(@ $f__added:literal $(= $f__meant:literal)?)?),*;
         bool: $($b:ident $(<- $b_:ident)? $(@ $b__added:literal $(= $b__meant:literal)?)?),*; opt_u64: $($o:ident $(<- $o_:ident)? $(@ $o__added:literal $(= $o__meant:literal)?)?),*) => {{
            let mut columns = vec![Column::new(
                "schema_version".into(),
                vec![SCHEMA_VERSION; records.len()],
            )];
            $(columns.push(Column::new(stringify!($s).into(), records.iter().map(|r| r.$s.as_str()).collect::<Vec<_>>()));)*
            $(columns.push(Column::new(stringify!($u).into(), records.iter().map(|r| r.$u).collect::<Vec<_>>()));)*
            $(columns.push(Column::new(stringify!($r).into(), records.iter().map(|r| r.$r).collect::<Vec<_>>()));)*
            $(columns.push(Column::new(stringify!($f).into(), records.iter().map(|r| r.$f).collect::<Vec<_>>()));)*
            $(columns.push(Column::new(stringify!($b).into(), records.iter().map(|r| r.$b).collect::<Vec<_>>()));)*
            $(columns.push(Column::new(stringify!($o).into(), records.iter().map(|r| r.$o).collect::<Vec<_>>()));)*
            DataFrame::new_infer_height(columns)
        }};
    }
    for_each_column!(build)
}

/// Rebuilds records from a table written by [`to_frame`]; names the first missing or
/// mistyped column otherwise.
pub fn from_frame(frame: &DataFrame) -> anyhow::Result<Vec<Record>> {
    let versions = frame
        .column("schema_version")
        .context("no `schema_version` column: not a collide results file")?
        .u32()
        .context("`schema_version` is not an unsigned integer: not a collide results file")?;
    // A table without rows has no version to read (polars' `get(0)` and `first()` panic).
    let version = versions.iter().next().flatten();
    let upgraded;
    let frame = match version {
        Some(version) if version > SCHEMA_VERSION => bail!(
            "results schema version {version} is newer than this collide's ({SCHEMA_VERSION}); \
             read them with the collide that wrote them, or a newer one"
        ),
        Some(version) if version < OLDEST_READABLE_VERSION => bail!(
            "results schema version {version} is older than any this collide reads \
             ({OLDEST_READABLE_VERSION} to {SCHEMA_VERSION}); re-run the study"
        ),
        Some(version) if version < SCHEMA_VERSION => {
            upgraded = upgrade(frame, version)?;
            &upgraded
        }
        _ => frame,
    };
    let column = |name: &str| {
        frame.column(name).with_context(|| {
            format!("no `{name}` column: not a collide results file, or a damaged one")
        })
    };
    let rows = frame.height();
    macro_rules! read {
        (str: $($s:ident $(<- $s_:ident)? $(@ $s__added:literal $(= $s__meant:literal)?)?),*; u64: $($u:ident $(<- $u_:ident)? $(@ $u__added:literal $(= $u__meant:literal)?)?),*;
         u32: $($r:ident $(<- $r_:ident)? $(@ $r__added:literal $(= $r__meant:literal)?)?),*; f64: $($f:ident $(<- $f_:ident)? $(@ $f__added:literal $(= $f__meant:literal)?)?),*;
         bool: $($b:ident $(<- $b_:ident)? $(@ $b__added:literal $(= $b__meant:literal)?)?),*; opt_u64: $($o:ident $(<- $o_:ident)? $(@ $o__added:literal $(= $o__meant:literal)?)?),*) => {{
            $(let $s = column(stringify!($s))?.str().with_context(|| mistyped(stringify!($s), "text"))?;)*
            $(let $u = column(stringify!($u))?.u64().with_context(|| mistyped(stringify!($u), "a count (u64)"))?;)*
            $(let $r = column(stringify!($r))?.u32().with_context(|| mistyped(stringify!($r), "a count (u32)"))?;)*
            $(let $f = column(stringify!($f))?.f64().with_context(|| mistyped(stringify!($f), "a number (f64)"))?;)*
            $(let $b = column(stringify!($b))?.bool().with_context(|| mistyped(stringify!($b), "true/false"))?;)*
            $(let $o = column(stringify!($o))?.u64().with_context(|| mistyped(stringify!($o), "a count (u64)"))?;)*
            (0..rows)
                .map(|i| Record {
                    $($s: $s.get(i).unwrap_or_default().to_owned(),)*
                    $($u: $u.get(i).unwrap_or_default(),)*
                    $($r: $r.get(i).unwrap_or_default(),)*
                    $($f: $f.get(i).unwrap_or(f64::NAN),)*
                    $($b: $b.get(i).unwrap_or_default(),)*
                    $($o: $o.get(i),)*
                })
                .collect()
        }};
    }
    Ok(for_each_column!(read))
}

/// The message for a column of the wrong type.
fn mistyped(name: &str, expected: &str) -> String {
    format!(
        "column `{name}` does not hold {expected}: not a collide results file, or a damaged one"
    )
}

/// A table of an older schema version with the columns added since then, each filled
/// with what the older files meant ([`ADDED_COLUMNS`]).
fn upgrade(frame: &DataFrame, version: u32) -> anyhow::Result<DataFrame> {
    let mut frame = frame.clone();
    for &(added_in, name, fill) in ADDED_COLUMNS {
        if added_in > version && frame.column(name).is_err() {
            let column = match fill {
                Fill::Str(value) => Column::new(name.into(), vec![value; frame.height()]),
                Fill::F64(value) => Column::new(name.into(), vec![value; frame.height()]),
                Fill::NullU64 => Column::new(name.into(), vec![None::<u64>; frame.height()]),
            };
            frame.with_column(column)?;
        }
    }
    Ok(frame)
}

/// Writes the records to `path` atomically (Parquet, zstd), their replica columns
/// filled from the rows written ([`crate::study::replicas::fill`]: a statistic over the
/// seeds of a setup, brought up to date as each run adds its row).
pub fn write(path: &Path, records: &[Record]) -> anyhow::Result<()> {
    let mut rows = records.to_vec();
    crate::study::replicas::fill(&mut rows);
    write_frame(path, &mut to_frame(&rows)?, "the records")
}

/// Writes `frame` (`what` it holds, for the message) to `path` atomically (Parquet, zstd).
pub fn write_frame(path: &Path, frame: &mut DataFrame, what: &str) -> anyhow::Result<()> {
    // Encoded in memory first (result tables are small), so that a failing disk's own
    // error reaches the message rather than the encoder's "transport error".
    let mut bytes = Vec::new();
    ParquetWriter::new(&mut bytes)
        .with_compression(ParquetCompression::Zstd(None))
        .finish(frame)
        .with_context(|| format!("cannot encode {what} as Parquet"))?;
    write_atomically(path, |out| out.write_all(&bytes))
}

/// The `.parquet` files in `dir`, sorted by name (oldest first: names start with the
/// UTC time they were started).
pub fn files_in(dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot list {}", dir.display()))?
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|path| path.extension().is_some_and(|ext| ext == "parquet"))
        .collect();
    files.sort();
    Ok(files)
}

/// Reads the records of one results file, saying which file and why if it cannot. A
/// file without rows (a study stopped before its first run ended) reads as no records.
pub fn read(path: &Path) -> anyhow::Result<Vec<Record>> {
    // Opening a FIFO would wait for a writer forever: look before opening.
    let meta =
        std::fs::metadata(path).with_context(|| format!("cannot read {}", path.display()))?;
    if !meta.is_file() {
        bail!(
            "{} is a {}, not a results file; move it out of the results folder",
            path.display(),
            crate::system::input::kind_of(&meta)
        );
    }
    let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let bytes = meta.len();
    if bytes == 0 {
        bail!(
            "{} is empty (0 bytes), not a results file; delete it (a study that was \
             stopped while writing may leave one)",
            path.display()
        );
    }
    let frame = ParquetReader::new(file).finish().with_context(|| {
        format!(
            "{} is not a readable Parquet file (truncated, damaged, or another format)",
            path.display()
        )
    })?;
    let records = from_frame(&frame).with_context(|| format!("{}", path.display()))?;
    if let Some(problem) = records
        .iter()
        .enumerate()
        .find_map(|(i, r)| r.impossible(i))
    {
        bail!(
            "{}: {problem}, which no run can measure: the file was edited or damaged; restore \
             it, or move it out of the results folder",
            path.display()
        );
    }
    Ok(records)
}

/// A serial run's context for unit tests: one worker, repetition 0, placeholder names.
#[cfg(test)]
pub(crate) fn serial_context(environment: &Environment) -> RecordContext<'_> {
    RecordContext {
        study: "s",
        manifest_hash: "m",
        build_id: "b",
        config_key: "k",
        scene: "gas",
        scene_hash: "0123456789abcdef",
        scaling: "strong",
        backend: BackendKind::Serial,
        placement: Placement::SERIAL,
        repetition: 0,
        environment,
        study_started_utc: "2026-11-22T18:00:00Z",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_dates_follow_the_civil_calendar() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(19_782), (2024, 2, 29));
        assert_eq!(civil_from_days(20_414), (2025, 11, 22));
    }

    #[test]
    fn the_column_marks_give_the_version_written_and_what_older_files_meant() {
        // The newest mark is the version written: version 14 added the replica columns.
        assert_eq!(SCHEMA_VERSION, 14);
        let added = |name: &str| {
            ADDED_COLUMNS
                .iter()
                .find(|column| column.1 == name)
                .map(|&(version, _, fill)| (version, format!("{fill:?}")))
        };
        // A text of its own where older files meant one, else the kind's "not measured".
        assert_eq!(added("scaling"), Some((2, "Str(\"strong\")".into())));
        assert_eq!(added("method"), Some((2, "Str(\"step\")".into())));
        assert_eq!(added("scene_hash"), Some((10, "Str(\"\")".into())));
        assert_eq!(
            added("equilibration_cut_time"),
            Some((12, "F64(NaN)".into()))
        );
        assert_eq!(added("replicas"), Some((14, "NullU64".into())));
        // Columns of version 1 are not added to older files: they were always there.
        assert_eq!(added("wall_s"), None);
        assert_eq!(ADDED_COLUMNS.len(), 47);
    }
}
