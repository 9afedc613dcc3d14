//! Study records: one row per repetition, kept in Parquet through polars (the schema is
//! documented in docs/records.md, which a test keeps in step with [`to_frame`]; bump
//! [`SCHEMA_VERSION`] when a column is added or changes meaning).

use std::fs::File;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use polars::prelude::{
    Column, DataFrame, ParquetCompression, ParquetReader, ParquetWriter, PolarsResult, SerReader,
};

use crate::environment::Environment;
use crate::manifest::Scaling;
use crate::output::write_atomically;
use crate::summary::RunSummary;

pub const SCHEMA_VERSION: u32 = 6;
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

/// Columns added after version 1, each with the version that added it and what older
/// files implicitly meant: reading an older file adds them with that value.
const ADDED_COLUMNS: &[(u32, &str, Fill)] = &[
    // Version 1 studies could be weak only through their manifest; records assumed strong.
    (2, "scaling", Fill::Str("strong")),
    // Version 1 ran only the time-stepped method, timed, without accuracy observables.
    (2, "method", Fill::Str("step")),
    (2, "observe", Fill::Str("timing")),
    (2, "events_per_s", Fill::F64(f64::NAN)),
    (2, "collision_rate", Fill::F64(f64::NAN)),
    (2, "temperature", Fill::F64(f64::NAN)),
    (2, "pressure", Fill::F64(f64::NAN)),
    (2, "compressibility_z", Fill::F64(f64::NAN)),
    (2, "missed_collisions", Fill::NullU64),
    (2, "missed_collision_fraction", Fill::F64(f64::NAN)),
    (2, "mean_overlap", Fill::F64(f64::NAN)),
    (2, "energy_relative_error", Fill::F64(f64::NAN)),
    (2, "collapse_guard_fired", Fill::NullU64),
    // Version 2 did not record the stepping loop's CPU time (some of its files do) or
    // how far the rms disk moves per step.
    (3, "cpu_s", Fill::F64(f64::NAN)),
    (3, "rms_step_over_radius", Fill::F64(f64::NAN)),
    // Version 3 had no `method = "auto"` / tolerance-chosen dt.
    (4, "choice", Fill::Str("")),
    (4, "temperature_curve", Fill::Str("")),
    // Version 4 had no collapse detector (a collapsing run stalled until its timeout, so
    // no successful row had a collapse) and did not record the event method's TC time.
    (5, "collapse_time", Fill::F64(f64::NAN)),
    (5, "tc", Fill::F64(f64::NAN)),
    // Version 5 did not measure how far disks went into the walls; it judged
    // oversubscription by the machine's CPUs, not those the study could use, and did not
    // record them.
    (6, "max_wall_penetration", Fill::F64(f64::NAN)),
    (6, "usable_cpus", Fill::NullU64),
    (6, "cpu_affinity", Fill::Str("")),
];

/// What became of one run.
pub const STATUS_OK: &str = "ok";
pub const STATUS_FAILED: &str = "failed";
pub const STATUS_TIMED_OUT: &str = "timed_out";

/// One repetition of one configuration. Failed runs keep their row, with NaN
/// measurements, zero counts, an empty `state_hash` and the reason in `error`.
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    pub study: String,
    /// xxh3 of the manifest text: `--resume` only continues the same manifest.
    pub manifest_hash: String,
    /// Commit, dirty flag, profile and features: `--resume` only continues the same build.
    pub build_id: String,
    /// [`crate::manifest::Configuration::key`].
    pub config_key: String,
    pub scene: String,
    /// `strong` (n fixed) or `weak` (n grows with the workers): how the study scaled.
    pub scaling: String,
    pub repetition: u32,
    pub status: String,
    pub error: String,
    pub backend: String,
    pub threads: u64,
    pub ranks: u64,
    pub workers: u64,
    pub n: u64,
    pub steps: u64,
    pub dt: f64,
    pub packing: f64,
    pub seed: Option<u64>,
    pub boundary: String,
    pub broadphase: String,
    pub wall_s: f64,
    /// CPU seconds of the stepping loop, summed over threads and ranks (NaN: unknown).
    pub cpu_s: f64,
    pub setup_s: f64,
    pub fps: f64,
    pub particle_steps_per_s: f64,
    pub integration_s: f64,
    pub broad_phase_s: f64,
    pub collision_s: f64,
    pub communication_s: f64,
    pub kinetic_energy_initial: f64,
    pub kinetic_energy_final: f64,
    pub momentum_initial_x: f64,
    pub momentum_initial_y: f64,
    pub momentum_final_x: f64,
    pub momentum_final_y: f64,
    pub pair_collisions: u64,
    pub wall_collisions: u64,
    pub max_overlap: f64,
    /// Largest penetration into a wall, as a fraction of the radius (see the JSON summary).
    pub max_wall_penetration: f64,
    pub state_hash: String,
    /// `step` or `event`; `timing` or `accuracy` (see the JSON summary).
    pub method: String,
    pub observe: String,
    /// Accuracy observables of the JSON summary; NaN (floats) or null (counts) where
    /// the summary has null.
    pub events_per_s: f64,
    pub collision_rate: f64,
    pub temperature: f64,
    pub pressure: f64,
    pub compressibility_z: f64,
    pub missed_collisions: Option<u64>,
    pub missed_collision_fraction: f64,
    pub mean_overlap: f64,
    pub energy_relative_error: f64,
    pub collapse_guard_fired: Option<u64>,
    /// Event method: simulated time of the detected inelastic collapse (the run stopped
    /// there, `steps` counting the interval it fell in); NaN when none, and for step.
    pub collapse_time: f64,
    /// Event method: the TC model time used (0: guard off); NaN for the step method.
    pub tc: f64,
    /// v_rms·dt/r_min at the start (see the JSON summary); NaN where not known.
    pub rms_step_over_radius: f64,
    /// What `method = "auto"` / `dt = "auto"` chose and why (the JSON summary's
    /// `choice`); empty when nothing was automatic.
    pub choice: String,
    /// The JSON summary's `temperature_curve` as JSON text ([[t, T], ...]); empty where
    /// it is null (elastic scenes, parallel backends).
    pub temperature_curve: String,
    pub oversubscribed: bool,
    pub hostname: String,
    pub cpu_model: String,
    pub logical_cores: u64,
    pub physical_cores: u64,
    /// The CPUs the study could run on (affinity mask and quota); `oversubscribed` means
    /// more workers than these. Null in files of schema version 5 and older.
    pub usable_cpus: Option<u64>,
    /// Those CPUs as the kernel lists them (e.g. `0-3`); "" in older files.
    pub cpu_affinity: String,
    pub memory_bytes: u64,
    pub os: String,
    pub rustc: String,
    pub profile: String,
    pub features: String,
    pub git_commit: String,
    pub git_dirty: bool,
    pub mpi_library: String,
    pub load_average_start: f64,
    /// 1-minute load average when this row was written.
    pub load_average: f64,
    /// 1-minute load average when the study finished; NaN while it runs (or if killed).
    pub load_average_end: f64,
    /// UTC, RFC 3339: when the study started and when this run finished.
    pub study_started_utc: String,
    pub finished_utc: String,
}

/// The parts of a record that do not come from the run itself.
#[derive(Clone, Debug)]
pub struct RecordContext<'a> {
    pub study: &'a str,
    pub manifest_hash: &'a str,
    pub build_id: &'a str,
    pub config_key: &'a str,
    pub scene: &'a str,
    /// `strong` or `weak`.
    pub scaling: &'a str,
    pub backend: &'a str,
    pub workers: u64,
    pub repetition: u32,
    pub environment: &'a Environment,
    pub study_started_utc: &'a str,
}

impl Record {
    /// The row of a run that finished and printed `summary`.
    pub fn measured(context: &RecordContext<'_>, summary: &RunSummary) -> Record {
        let mut record = Record::blank(context, STATUS_OK, String::new());
        record.threads = summary.threads as u64;
        record.ranks = summary.ranks as u64;
        record.workers = summary.workers as u64;
        record.n = summary.n as u64;
        record.steps = summary.steps;
        record.dt = summary.dt;
        record.packing = summary.packing;
        record.seed = summary.seed;
        record.boundary = summary.boundary.clone();
        record.broadphase = summary.broadphase.clone();
        record.wall_s = summary.wall_s;
        record.cpu_s = summary.cpu_s.unwrap_or(f64::NAN);
        record.setup_s = summary.setup_s;
        record.fps = summary.fps;
        record.particle_steps_per_s = summary.particle_steps_per_s;
        record.integration_s = summary.integration_s;
        record.broad_phase_s = summary.broad_phase_s;
        record.collision_s = summary.collision_s;
        record.communication_s = summary.communication_s;
        record.kinetic_energy_initial = summary.kinetic_energy_initial;
        record.kinetic_energy_final = summary.kinetic_energy_final;
        [record.momentum_initial_x, record.momentum_initial_y] = summary.momentum_initial;
        [record.momentum_final_x, record.momentum_final_y] = summary.momentum_final;
        record.pair_collisions = summary.pair_collisions;
        record.wall_collisions = summary.wall_collisions;
        record.max_overlap = summary.max_overlap;
        record.max_wall_penetration = summary.max_wall_penetration;
        record.state_hash = summary.state_hash.clone();
        record.method = summary.method.clone();
        record.observe = summary.observe.clone();
        let nan = |value: Option<f64>| value.unwrap_or(f64::NAN);
        record.events_per_s = nan(summary.events_per_s);
        record.collision_rate = nan(summary.collision_rate);
        record.temperature = nan(summary.temperature);
        record.pressure = nan(summary.pressure);
        record.compressibility_z = nan(summary.compressibility_z);
        record.missed_collisions = summary.missed_collisions;
        record.missed_collision_fraction = nan(summary.missed_collision_fraction);
        record.mean_overlap = nan(summary.mean_overlap);
        record.energy_relative_error = nan(summary.energy_relative_error);
        record.collapse_guard_fired = summary.collapse_guard_fired;
        record.collapse_time = nan(summary.collapse_time);
        record.tc = nan(summary.tc);
        record.rms_step_over_radius = nan(summary.rms_step_over_radius);
        record.choice = summary.choice.clone().unwrap_or_default();
        record.temperature_curve = summary
            .temperature_curve
            .as_ref()
            .and_then(|curve| serde_json::to_string(curve).ok())
            .unwrap_or_default();
        record.oversubscribed = summary.oversubscribed;
        record
    }

    /// The row of a run that failed or timed out.
    pub fn failed(context: &RecordContext<'_>, status: &str, error: String) -> Record {
        Record::blank(context, status, error)
    }

    fn blank(context: &RecordContext<'_>, status: &str, error: String) -> Record {
        let env = context.environment;
        let workers = context.workers;
        let (threads, ranks) = match context.backend {
            "rayon" => (workers, 1),
            "mpi" => (1, workers),
            _ => (1, 1),
        };
        Record {
            study: context.study.to_owned(),
            manifest_hash: context.manifest_hash.to_owned(),
            build_id: context.build_id.to_owned(),
            config_key: context.config_key.to_owned(),
            scene: context.scene.to_owned(),
            scaling: context.scaling.to_owned(),
            repetition: context.repetition,
            status: status.to_owned(),
            error,
            backend: context.backend.to_owned(),
            threads,
            ranks,
            workers,
            n: 0,
            steps: 0,
            dt: f64::NAN,
            packing: f64::NAN,
            seed: None,
            boundary: String::new(),
            broadphase: String::new(),
            wall_s: f64::NAN,
            cpu_s: f64::NAN,
            setup_s: f64::NAN,
            fps: f64::NAN,
            particle_steps_per_s: f64::NAN,
            integration_s: f64::NAN,
            broad_phase_s: f64::NAN,
            collision_s: f64::NAN,
            communication_s: f64::NAN,
            kinetic_energy_initial: f64::NAN,
            kinetic_energy_final: f64::NAN,
            momentum_initial_x: f64::NAN,
            momentum_initial_y: f64::NAN,
            momentum_final_x: f64::NAN,
            momentum_final_y: f64::NAN,
            pair_collisions: 0,
            wall_collisions: 0,
            max_overlap: f64::NAN,
            max_wall_penetration: f64::NAN,
            state_hash: String::new(),
            method: String::new(),
            observe: String::new(),
            events_per_s: f64::NAN,
            collision_rate: f64::NAN,
            temperature: f64::NAN,
            pressure: f64::NAN,
            compressibility_z: f64::NAN,
            missed_collisions: None,
            missed_collision_fraction: f64::NAN,
            mean_overlap: f64::NAN,
            energy_relative_error: f64::NAN,
            collapse_guard_fired: None,
            collapse_time: f64::NAN,
            tc: f64::NAN,
            rms_step_over_radius: f64::NAN,
            choice: String::new(),
            temperature_curve: String::new(),
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
            load_average: crate::environment::load_average(),
            load_average_end: f64::NAN,
            study_started_utc: context.study_started_utc.to_owned(),
            finished_utc: utc_now(),
        }
    }
}

impl Record {
    /// The physical setup a run computed (scene, n, steps, dt, seed, packing, broad
    /// phase, and the method when it is not the default step method), whatever the
    /// backend: runs with the same setup must end in the same state.
    pub fn setup_key(&self) -> String {
        self.key_with_n(&format!("n={}", self.n))
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
        if self.scaling() == Scaling::Weak {
            self.key_with_n(&format!("weak n/worker={}", self.n / self.workers.max(1)))
        } else {
            self.setup_key()
        }
    }

    fn key_with_n(&self, n: &str) -> String {
        let method = match self.method.as_str() {
            "" | "step" => String::new(),
            other => format!(" method={other}"),
        };
        format!(
            "{} {n} steps={} dt={} seed={} packing={:.4} broadphase={}{method}",
            self.scene,
            self.steps,
            self.dt,
            self.seed
                .map_or_else(|| "none".to_owned(), |s| s.to_string()),
            self.packing,
            self.broadphase
        )
    }
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

/// Applies the same code to every column: the one list of the schema.
macro_rules! for_each_column {
    ($apply:ident) => {
        $apply!(
            str: study, manifest_hash, build_id, config_key, scene, scaling, status, error, backend,
                 boundary, broadphase, state_hash, hostname, cpu_model, os, rustc, profile,
                 features, git_commit, mpi_library, study_started_utc, finished_utc, method,
                 observe, choice, temperature_curve, cpu_affinity;
            u64: threads, ranks, workers, n, steps, pair_collisions, wall_collisions,
                 logical_cores, physical_cores, memory_bytes;
            u32: repetition;
            f64: dt, packing, wall_s, cpu_s, setup_s, fps, particle_steps_per_s, integration_s,
                 broad_phase_s, collision_s, communication_s, kinetic_energy_initial,
                 kinetic_energy_final, momentum_initial_x, momentum_initial_y,
                 momentum_final_x, momentum_final_y, max_overlap, max_wall_penetration,
                 load_average_start,
                 load_average, load_average_end, events_per_s, collision_rate, temperature,
                 pressure, compressibility_z, missed_collision_fraction, mean_overlap,
                 energy_relative_error, rms_step_over_radius, collapse_time, tc;
            bool: oversubscribed, git_dirty;
            opt_u64: seed, missed_collisions, collapse_guard_fired, usable_cpus
        )
    };
}

/// The records as a table, with `schema_version` first.
pub fn to_frame(records: &[Record]) -> PolarsResult<DataFrame> {
    macro_rules! build {
        (str: $($s:ident),*; u64: $($u:ident),*; u32: $($r:ident),*; f64: $($f:ident),*;
         bool: $($b:ident),*; opt_u64: $($o:ident),*) => {{
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
        (str: $($s:ident),*; u64: $($u:ident),*; u32: $($r:ident),*; f64: $($f:ident),*;
         bool: $($b:ident),*; opt_u64: $($o:ident),*) => {{
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

/// Writes the records to `path` atomically (Parquet, zstd).
pub fn write(path: &Path, records: &[Record]) -> anyhow::Result<()> {
    let mut frame = to_frame(records)?;
    // Encoded in memory first (result tables are small), so that a failing disk's own
    // error reaches the message rather than the encoder's "transport error".
    let mut bytes = Vec::new();
    ParquetWriter::new(&mut bytes)
        .with_compression(ParquetCompression::Zstd(None))
        .finish(&mut frame)
        .context("cannot encode the records as Parquet")?;
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
    let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let bytes = file
        .metadata()
        .with_context(|| format!("cannot read {}", path.display()))?
        .len();
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
    from_frame(&frame).with_context(|| format!("{}", path.display()))
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
        scaling: "strong",
        backend: "serial",
        workers: 1,
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
}
