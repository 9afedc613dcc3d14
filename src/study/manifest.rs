//! Experiment manifests (TOML) → a validated [`Study`]: every configuration to run.
//!
//! A manifest names the study, lists scenes (scene files, or inline `scene`/`method`
//! tables in the scene-file format), sweeps over scene and method settings, and the
//! backends with their worker counts. Every error names the manifest, the line and the
//! field, and how to fix it.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use crate::cluster::placement::Layout;
use crate::run::backend_kind::{BackendKind, Placement};
use crate::run::limits::{Machine, WorkerSource, check_memory, check_workers};
use crate::run::overrides::{Overrides, SweepLists, SweptList};
use crate::run::scene_file;
use crate::run::spec::{Footprint, RunSpec, SceneSource};
use crate::study::names::check_name;
use crate::system::input::{MAX_TEXT_BYTES, read_text};

/// A validated study: what to run, how often, and in which order.
#[derive(Clone, Debug, PartialEq)]
pub struct Study {
    pub name: String,
    pub description: String,
    /// The manifest it came from.
    pub manifest: PathBuf,
    pub warmups: u32,
    /// Per run; a run that takes longer is killed and recorded as failed.
    pub timeout: Duration,
    pub scaling: Scaling,
    pub configurations: Vec<Configuration>,
}

impl Study {
    /// The rounds of repetitions: as many as the configuration measured most often has.
    pub fn rounds(&self) -> u32 {
        self.configurations
            .iter()
            .map(|configuration| configuration.repetitions)
            .max()
            .unwrap_or(0)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Scaling {
    /// The same n for every worker count.
    Strong,
    /// n = (the swept or scene n) × workers (threads, ranks, or ranks × threads per
    /// rank): the work per worker stays fixed.
    Weak,
}

impl Scaling {
    /// The name used in manifests and records.
    pub fn name(self) -> &'static str {
        match self {
            Scaling::Strong => "strong",
            Scaling::Weak => "weak",
        }
    }
}

/// Where a configuration's scene comes from.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum SceneInput {
    File(PathBuf),
    /// Scene-file text from an inline table; the runner writes it beside the results.
    Inline(String),
}

/// One thing to time: a scene, its overrides, a backend and its worker count.
#[derive(Clone, Debug, PartialEq)]
pub struct Configuration {
    /// The scene's name: `name`, or the scene file's stem.
    pub scene: String,
    pub input: SceneInput,
    pub overrides: Overrides,
    pub backend: BackendKind,
    /// Where its runs' ranks and threads go: the backend's own count on its axis (rayon
    /// threads, MPI ranks), with `[placement]`'s nodes and threads per MPI rank.
    pub layout: Layout,
    /// Run worker counts above the ceiling of [`crate::run::limits`] (`[backends]
    /// oversubscribe = true`); not part of the key.
    pub oversubscribe: bool,
    /// Measured runs (`repetitions`, by backend when a table); not part of the key, so
    /// raising it and resuming runs only the new ones.
    pub repetitions: u32,
    /// Memory and placement time of each of its runs, as checked against the machine.
    pub footprint: Footprint,
}

/// The entries of a configuration's key that place its runs (backend, workers, nodes,
/// threads per rank) rather than say what they compute: a record's setup is its key
/// without them.
pub const PLACEMENT_KEYS: [&str; 4] = ["backend=", "workers=", "nodes=", "threads="];

impl Configuration {
    /// A stable text key naming the configuration: the same in every run of the same
    /// manifest, so `--resume` can tell what is already measured.
    pub fn key(&self) -> String {
        let entries = self.overrides.entries();
        let mut always = Vec::new();
        let mut when_set = String::new();
        for (name, value) in entries {
            if Overrides::ALWAYS_KEYED.contains(&name) {
                always.push(format!("{name}={}", value.as_deref().unwrap_or("-")));
            } else if let Some(value) = value {
                when_set.push_str(&format!(";{name}={value}"));
            }
        }
        let [backend, workers, nodes, threads] = PLACEMENT_KEYS;
        let (count, threads_per_rank) = self.backend.counts_of(self.placement());
        // One node and one thread per rank are left out, so that keys written before
        // placements (and before threaded ranks) still resume.
        let nodes = match self.layout.nodes {
            1 => String::new(),
            spread => format!(";{nodes}{spread}"),
        };
        let threads = match threads_per_rank {
            1 => String::new(),
            per_rank => format!(";{threads}{per_rank}"),
        };
        format!(
            "scene={};{};{backend}{};{workers}{count}{nodes}{threads}{when_set}",
            self.scene,
            always.join(";"),
            self.backend.name(),
        )
    }

    /// Its runs' ranks, and the threads each steps on.
    pub fn placement(&self) -> Placement {
        Placement {
            ranks: self.layout.ranks,
            threads: self.layout.threads,
        }
    }

    /// The `collide simulate` arguments after the scene path.
    pub fn simulate_args(&self) -> Vec<String> {
        let mut args = vec!["--json".to_owned()];
        // `--name=value`, one argument: a flag that may also stand alone (`--draw`)
        // takes its value only that way.
        args.extend(
            self.overrides
                .entries()
                .into_iter()
                .filter_map(|(name, value)| Some(format!("--{name}={}", value?))),
        );
        args.extend(["--backend".to_owned(), self.backend.name().to_owned()]);
        let (count, threads_per_rank) = self.backend.counts_of(self.placement());
        if let Some(flag) = self.backend.workers_flag() {
            args.extend([flag.to_owned(), count.to_string()]);
        }
        if self.layout.nodes > 1 {
            args.extend(["--nodes".to_owned(), self.layout.nodes.to_string()]);
        }
        if threads_per_rank > 1 {
            args.extend(["--threads".to_owned(), threads_per_rank.to_string()]);
        }
        if self.oversubscribe {
            args.push("--oversubscribe".to_owned());
        }
        args
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ManifestError {
    #[error("{location}: {message}")]
    Invalid { location: String, message: String },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawManifest {
    name: Spanned<String>,
    #[serde(default)]
    description: String,
    /// A count for every backend, or a table of counts by backend name.
    repetitions: Option<Spanned<toml::Value>>,
    warmups: Option<Spanned<i64>>,
    timeout_s: Option<Spanned<f64>>,
    scaling: Option<Spanned<Scaling>>,
    scenes: Spanned<Vec<Spanned<RawScene>>>,
    #[serde(default)]
    sweep: SweepLists,
    backends: Spanned<RawBackends>,
    placement: Option<Spanned<RawPlacement>>,
}

/// Where MPI ranks go: each list a sweep, multiplying the `mpi` rank counts.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlacement {
    #[serde(default = "one")]
    nodes: Vec<i64>,
    /// Threads each MPI rank steps on (serial and rayon configurations are not
    /// multiplied by it).
    #[serde(default = "one")]
    threads: Vec<i64>,
}

fn one() -> Vec<i64> {
    vec![1]
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    name: Option<Spanned<String>>,
    file: Option<String>,
    scene: Option<toml::Table>,
    method: Option<toml::Table>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBackends {
    #[serde(default)]
    serial: bool,
    #[serde(default)]
    rayon: Vec<i64>,
    #[serde(default)]
    mpi: Vec<i64>,
    /// Allow worker counts above the ceiling of [`crate::run::limits`].
    #[serde(default)]
    oversubscribe: bool,
}

/// Reads and validates the manifest at `path` for this machine: the study, and the text
/// it came from.
pub fn load(path: &Path) -> anyhow::Result<(Study, String)> {
    let text = read_text(path, MAX_TEXT_BYTES)
        .map_err(|reason| anyhow::anyhow!("cannot read manifest {}: {reason}", path.display()))?;
    Ok((parse(path, &text, &Machine::this())?, text))
}

/// Validates manifest text for `machine` (every configuration's workers and memory must
/// fit it); scene files are found relative to `path`'s folder.
pub fn parse(path: &Path, text: &str, machine: &Machine) -> Result<Study, ManifestError> {
    let at = Locator { path, text };
    let raw: RawManifest = toml::from_str(text).map_err(|err| {
        at.invalid(
            err.span().map_or(0, |span| span.start),
            format!(
                "{}; see docs/guide.md, Experiment manifests, for the keys a manifest accepts",
                err.message().trim_end()
            ),
        )
    })?;
    let name = raw.name.get_ref().trim().to_owned();
    check_name(&name)
        .map_err(|reason| at.invalid(raw.name.span().start, format!("`name` {reason}")))?;
    let repetitions = repetitions_by_backend(&at, raw.repetitions.as_ref())?;
    let warmups = match &raw.warmups {
        None => 1,
        Some(warmups) => count_of("warmups", &toml::Value::from(*warmups.get_ref()), 0)
            .map_err(|message| at.invalid(warmups.span().start, message))?,
    };
    let timeout_s = raw.timeout_s.as_ref().map_or(600.0, |t| *t.get_ref());
    if !(timeout_s > 0.0 && timeout_s <= MAX_TIMEOUT_S) {
        let offset = raw.timeout_s.as_ref().map_or(0, |t| t.span().start);
        return Err(at.invalid(
            offset,
            format!(
                "`timeout_s` is {timeout_s}; give a positive number of seconds, at most \
                 {MAX_TIMEOUT_S} (a week)"
            ),
        ));
    }
    let scaling = raw
        .scaling
        .as_ref()
        .map_or(Scaling::Strong, |s| *s.get_ref());
    let configurations = configurations(&at, &raw, scaling, repetitions, machine)?;
    Ok(Study {
        name,
        description: raw.description,
        manifest: path.to_owned(),
        warmups,
        timeout: Duration::from_secs_f64(timeout_s),
        scaling,
        configurations,
    })
}

/// Measured runs per configuration, indexed by [`BackendKind`]: `repetitions = 30` for
/// every backend, or a table by backend name (`[repetitions]` with `mpi = 90`), where a
/// backend left out gets the default, 3.
fn repetitions_by_backend(
    at: &Locator,
    value: Option<&Spanned<toml::Value>>,
) -> Result<[u32; BackendKind::ALL.len()], ManifestError> {
    const DEFAULT: u32 = 3;
    let Some(value) = value else {
        return Ok([DEFAULT; BackendKind::ALL.len()]);
    };
    let invalid = |message: String| at.invalid(value.span().start, message);
    let count = |field: String, count: &toml::Value| count_of(&field, count, 1).map_err(invalid);
    match value.get_ref() {
        toml::Value::Table(table) => {
            let mut counts = [DEFAULT; BackendKind::ALL.len()];
            for (name, value) in table {
                let Some(kind) = BackendKind::from_name(name) else {
                    let names: Vec<&str> = BackendKind::ALL.map(BackendKind::name).to_vec();
                    return Err(invalid(format!(
                        "`repetitions.{name}` names no backend; the table takes {}",
                        names.join(", ")
                    )));
                };
                counts[kind as usize] = count(format!("repetitions.{name}"), value)?;
            }
            Ok(counts)
        }
        other => Ok([count("repetitions".to_owned(), other)?; BackendKind::ALL.len()]),
    }
}

/// `value` of `field` as a count: a whole number from `min` up (at most `u32::MAX`), or
/// what is wrong with it.
fn count_of(field: &str, value: &toml::Value, min: i64) -> Result<u32, String> {
    value
        .as_integer()
        .filter(|&count| count >= min)
        .and_then(|count| u32::try_from(count).ok())
        .ok_or_else(|| {
            format!(
                "`{field}` is {value}; give a whole number of at least {min} (at most {})",
                u32::MAX
            )
        })
}

/// Where a manifest's errors point: its path, and the line of an offset in its text.
struct Locator<'a> {
    path: &'a Path,
    text: &'a str,
}

impl Locator<'_> {
    /// The error `message` at the line of `offset`.
    fn invalid(&self, offset: usize, message: String) -> ManifestError {
        ManifestError::Invalid {
            location: format!(
                "{}:{}",
                self.path.display(),
                scene_file::line_of(self.text, offset)
            ),
            message,
        }
    }
}

/// The most configurations a study may have, and the most runs (configurations ×
/// repetitions): beyond them a manifest is refused before anything is expanded, since
/// at a tenth of a second a run such a study would last longer than a day.
pub const MAX_CONFIGURATIONS: usize = 10_000;
pub const MAX_RUNS: u64 = 1_000_000;

/// The longest `timeout_s` accepted: a week.
const MAX_TIMEOUT_S: f64 = 7.0 * 86_400.0;

/// Every configuration of the manifest: each scene × sweep point × (backend, workers),
/// in that order, each checked as `collide simulate` would check it, none twice.
fn configurations(
    at: &Locator,
    raw: &RawManifest,
    scaling: Scaling,
    repetitions: [u32; BackendKind::ALL.len()],
    machine: &Machine,
) -> Result<Vec<Configuration>, ManifestError> {
    let backends = backend_list(raw.backends.get_ref(), machine)
        .map_err(|message| at.invalid(raw.backends.span().start, message))?;
    let points =
        sweep_points(&raw.sweep).map_err(|(offset, message)| at.invalid(offset, message))?;
    if raw.scenes.get_ref().is_empty() {
        return Err(at.invalid(
            raw.scenes.span().start,
            "`scenes` is empty; add a [[scenes]] entry with `file = ...` or inline tables".into(),
        ));
    }
    let n_placements = raw.placement.as_ref().map_or(1, |p| {
        p.get_ref().nodes.len().max(1) * p.get_ref().threads.len().max(1)
    });
    let n_configurations =
        raw.scenes.get_ref().len() * points.len() * backends.len() * n_placements;
    check_study_size(at, raw, n_configurations, &repetitions)?;
    let folder = at.path.parent().unwrap_or(Path::new("."));
    let mut configurations = Vec::new();
    let mut seen = BTreeSet::new();
    let placed = placed(at, raw, &backends, machine)?;
    for entry in raw.scenes.get_ref() {
        let offset = entry.span().start;
        if let Some(name) = &entry.get_ref().name {
            check_name(name.get_ref()).map_err(|reason| {
                at.invalid(name.span().start, format!("`scenes.name` {reason}"))
            })?;
        }
        let (scene, input) =
            scene_input(entry.get_ref(), folder).map_err(|message| at.invalid(offset, message))?;
        for point in &points {
            for &(backend, layout) in &placed {
                let mut overrides = point.clone();
                if scaling == Scaling::Weak {
                    // Per worker: an MPI rank of 2 threads gets twice the disks of one of 1.
                    let n = weak_n(&input, &overrides, layout.ranks * layout.threads).map_err(
                        |message| at.invalid(offset, format!("scene `{scene}`: {message}")),
                    )?;
                    overrides.n = Some(n);
                }
                let footprint = checked(
                    at,
                    raw,
                    offset,
                    (&scene, &input),
                    &overrides,
                    (backend, layout.ranks),
                    machine,
                )?;
                let configuration = Configuration {
                    scene: scene.clone(),
                    input: input.clone(),
                    overrides,
                    backend,
                    layout,
                    oversubscribe: raw.backends.get_ref().oversubscribe,
                    repetitions: repetitions[backend as usize],
                    footprint,
                };
                if !seen.insert(configuration.key()) {
                    return Err(at.invalid(
                        offset,
                        format!(
                            "the configuration {} appears twice; remove the repeated scene, sweep value or worker count",
                            configuration.key()
                        ),
                    ));
                }
                configurations.push(configuration);
            }
        }
    }
    Ok(configurations)
}

/// Each (backend, workers) laid out with the node counts and threads per rank of
/// `[placement]`: MPI ranks on each node count that divides them evenly, each stepping
/// on each thread count (ranks × threads within the worker ceiling of `machine` unless
/// `oversubscribe`); every other backend on one node, its threads its workers.
fn placed(
    at: &Locator,
    raw: &RawManifest,
    backends: &[(BackendKind, usize)],
    machine: &Machine,
) -> Result<Vec<(BackendKind, Layout)>, ManifestError> {
    let on_one_node = |backend: BackendKind, workers, threads_per_rank| {
        let placement = backend.placement(workers);
        Layout {
            nodes: 1,
            ranks: placement.ranks,
            threads: placement.threads * threads_per_rank,
        }
    };
    let Some(placement) = &raw.placement else {
        return Ok(backends
            .iter()
            .map(|&(b, w)| (b, on_one_node(b, w, 1)))
            .collect());
    };
    let offset = placement.span().start;
    let (nodes, threads) = (&placement.get_ref().nodes, &placement.get_ref().threads);
    if [nodes, threads]
        .iter()
        .any(|list| list.is_empty() || list.iter().any(|&count| count < 1))
    {
        return Err(at.invalid(
            offset,
            "`placement.nodes` and `placement.threads` each list whole numbers of at least 1"
                .into(),
        ));
    }
    let mut placed = Vec::new();
    for &(backend, workers) in backends {
        if !backend.capabilities().mpi {
            placed.push((backend, on_one_node(backend, workers, 1)));
            continue;
        }
        for &count in nodes {
            let count = count as usize;
            if workers % count != 0 {
                return Err(at.invalid(
                    offset,
                    format!(
                        "`placement.nodes` = {count} does not divide the {workers} ranks of \
                         `backends.mpi` evenly; give node counts that divide every rank count"
                    ),
                ));
            }
            for &per_rank in threads {
                let per_rank = per_rank as usize;
                let source = WorkerSource {
                    field: &format!(
                        "`backends.mpi` = {workers} × `placement.threads` = {per_rank}"
                    ),
                    insist: "set `oversubscribe = true` in [backends]",
                };
                check_workers(
                    workers.saturating_mul(per_rank),
                    machine,
                    raw.backends.get_ref().oversubscribe,
                    source,
                )
                .map_err(|message| at.invalid(offset, message))?;
                let layout = on_one_node(backend, workers, per_rank);
                placed.push((
                    backend,
                    Layout {
                        nodes: count,
                        ..layout
                    },
                ));
            }
        }
    }
    Ok(placed)
}

/// Refuses, before anything is expanded, a study of more than [`MAX_CONFIGURATIONS`]
/// configurations or [`MAX_RUNS`] runs.
fn check_study_size(
    at: &Locator,
    raw: &RawManifest,
    n_configurations: usize,
    repetitions: &[u32],
) -> Result<(), ManifestError> {
    let most_repetitions = repetitions.iter().copied().max().unwrap_or(1);
    let n_runs = n_configurations as u64 * u64::from(most_repetitions);
    if n_configurations <= MAX_CONFIGURATIONS && n_runs <= MAX_RUNS {
        return Ok(());
    }
    Err(at.invalid(
        raw.scenes.span().start,
        format!(
            "the study has {n_configurations} configurations (scenes × sweep points × \
             backends × placements) of up to {most_repetitions} repetitions, up to {n_runs} runs; collide \
             runs at most {MAX_CONFIGURATIONS} configurations and {MAX_RUNS} runs in a study: \
             sweep fewer values, lower `repetitions`, or split the study"
        ),
    ))
}

/// A weak-scaling configuration's n: the scene's (or swept) n times the workers, or
/// why not.
fn weak_n(input: &SceneInput, overrides: &Overrides, workers: usize) -> Result<i64, String> {
    let base = per_worker_n(input, overrides)?;
    base.checked_mul(workers as i64).ok_or_else(|| {
        format!(
            "weak scaling makes n = {base} × {workers} disks, beyond any count collide can \
             hold; lower n"
        )
    })
}

/// The memory footprint of `scene` (its `input`) with `overrides` on `backend` in
/// `ranks` processes, once it is a valid scene (the same checks as `collide simulate`) that fits
/// the machine and that the backend can run; errors point at its scene entry (`offset`)
/// or at the swept key that asks for what the backend cannot do.
fn checked(
    at: &Locator,
    raw: &RawManifest,
    offset: usize,
    (scene, input): (&str, &SceneInput),
    overrides: &Overrides,
    (backend, ranks): (BackendKind, usize),
    machine: &Machine,
) -> Result<Footprint, ManifestError> {
    let in_scene = |message: String| {
        at.invalid(
            offset,
            format!("scene `{scene}` with {}: {message}", describe(overrides)),
        )
    };
    let spec = load_scene(input, overrides).map_err(in_scene)?;
    let capabilities = backend.capabilities();
    let copies = match capabilities.scene_in_every_process {
        true => spec.whole_scene_copies(ranks),
        false => 1,
    };
    let footprint = spec.footprint(copies);
    check_memory(&footprint, machine).map_err(in_scene)?;
    // What the backend cannot run, at the swept key that asks for it (else at `backends`).
    let refuse = |swept: Option<usize>, does: &str, fix: &str| {
        at.invalid(
            swept.unwrap_or(raw.backends.span().start),
            format!(
                "scene `{scene}` with {} {does}, but `backends` also lists {}; {fix}",
                describe(overrides),
                backend_label(backend)
            ),
        )
    };
    if spec.method.method.may_be_event() && !capabilities.event_method {
        return Err(refuse(
            raw.sweep.method.as_ref().map(|m| m.span().start),
            "runs the event method, which runs on the serial backend only",
            "run the event method in a study with only `serial = true` (or sweep `method` over [\"step\"] here)",
        ));
    }
    if spec.method.draw && !capabilities.draws {
        return Err(refuse(
            raw.sweep.draw.as_ref().map(|d| d.span().start),
            "draws every step, which needs all the disks in one process",
            "draw in a study of `serial` and `rayon` only (or sweep `draw` over [false] here)",
        ));
    }
    Ok(footprint)
}

/// (backend, workers) pairs, in manifest order, each within the worker ceiling of
/// `machine` unless `oversubscribe` is set.
fn backend_list(raw: &RawBackends, machine: &Machine) -> Result<Vec<(BackendKind, usize)>, String> {
    let mut list = Vec::new();
    if raw.serial {
        list.push((BackendKind::Serial, 1));
    }
    for (backend, counts) in [
        (BackendKind::Rayon, &raw.rayon),
        (BackendKind::Mpi, &raw.mpi),
    ] {
        let field = backend.name();
        for &count in counts {
            if count < 1 {
                return Err(format!(
                    "`backends.{field}` lists {count}; worker counts are whole numbers of at least 1"
                ));
            }
            let source = WorkerSource {
                field: &format!("`backends.{field}`"),
                insist: "set `oversubscribe = true` in [backends]",
            };
            check_workers(count as usize, machine, raw.oversubscribe, source)?;
            list.push((backend, count as usize));
        }
    }
    if list.is_empty() {
        return Err(
            "`backends` runs nothing; set `serial = true` or list thread counts (`rayon = [1, 2]`) or rank counts (`mpi = [1, 2]`)"
                .into(),
        );
    }
    Ok(list)
}

/// Refuses, before any point is made (a product of long lists would fill memory first),
/// a sweep of more than [`MAX_CONFIGURATIONS`] points: the product of the `free` lists'
/// lengths and the `paired` lists' common length.
fn check_point_count(paired: &[SweptList], free: &[SweptList]) -> Result<(), (usize, String)> {
    let n_points = free
        .iter()
        .map(|list| list.len)
        .chain(paired.first().map(|list| list.len))
        .try_fold(1usize, usize::checked_mul)
        .filter(|&n| n <= MAX_CONFIGURATIONS);
    match n_points {
        Some(_) => Ok(()),
        None => Err((
            free.first()
                .or(paired.first())
                .map_or(0, |list| list.offset),
            format!(
                "the sweep's lists multiply to more than {MAX_CONFIGURATIONS} points; sweep \
                 fewer values, pair lists with `sweep.zip`, or split the study"
            ),
        )),
    }
}

/// The sweep's points: the full product of its lists, except that the lists named in
/// `zip` pair up element by element (and must have the same length).
fn sweep_points(sweep: &SweepLists) -> Result<Vec<Overrides>, (usize, String)> {
    let lists = sweep.lists();
    for SweptList {
        key, offset, len, ..
    } in &lists
    {
        if *len == 0 {
            return Err((
                *offset,
                format!("`sweep.{key}` is empty; give at least one value or drop the key"),
            ));
        }
    }
    let no_zip = Vec::new();
    let zipped = sweep.zip.as_ref().map_or(&no_zip, |zip| zip.get_ref());
    let zip_offset = sweep.zip.as_ref().map_or(0, |zip| zip.span().start);
    for key in zipped {
        if !lists.iter().any(|list| list.key == key) {
            return Err((
                zip_offset,
                format!("`sweep.zip` names `{key}`, which is not a swept list here"),
            ));
        }
    }
    let (paired, free): (Vec<_>, Vec<_>) = lists
        .into_iter()
        .partition(|list| zipped.iter().any(|z| z == list.key));
    check_point_count(&paired, &free)?;
    let mut points = vec![Overrides::default()];
    if let Some(SweptList { len, .. }) = paired.first() {
        if let Some(SweptList { key, .. }) = paired.iter().find(|list| list.len != *len) {
            return Err((
                zip_offset,
                format!(
                    "`sweep.zip` pairs lists of different lengths (`{key}` has another length than `{}`); give them the same length",
                    paired[0].key
                ),
            ));
        }
        points = (0..*len)
            .map(|i| {
                let mut o = Overrides::default();
                for list in &paired {
                    (list.set)(&mut o, i);
                }
                o
            })
            .collect();
    }
    for list in &free {
        points = points
            .iter()
            .flat_map(|point| {
                (0..list.len).map(move |i| {
                    let mut o = point.clone();
                    (list.set)(&mut o, i);
                    o
                })
            })
            .collect();
    }
    Ok(points)
}

fn scene_input(raw: &RawScene, folder: &Path) -> Result<(String, SceneInput), String> {
    match (&raw.file, &raw.scene) {
        (Some(file), None) => {
            if raw.method.is_some() {
                return Err("a [[scenes]] entry with `file` takes its method from the file; drop `method` or inline the scene".into());
            }
            let path = folder.join(file);
            let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned());
            let given = raw.name.as_ref().map(|name| name.get_ref().clone());
            if given.is_none() {
                // The name reaches reports and terminals as the inline names do.
                let stem = stem.as_deref().unwrap_or_default();
                check_name(stem).map_err(|reason| {
                    format!(
                        "the scene's name, taken from its file name, {reason}; rename the file \
                         or give the entry a `name`"
                    )
                })?;
            }
            let name = given.or(stem).unwrap_or_else(|| file.clone());
            Ok((name, SceneInput::File(path)))
        }
        (None, Some(scene)) => {
            let name = raw.name.as_ref().map(|name| name.get_ref().clone()).ok_or(
                "an inline scene needs a `name` (it labels the results); add `name = \"...\"`",
            )?;
            let mut document = toml::Table::new();
            document.insert("scene".into(), toml::Value::Table(scene.clone()));
            if let Some(method) = &raw.method {
                document.insert("method".into(), toml::Value::Table(method.clone()));
            }
            let text = toml::to_string(&document).map_err(|e| e.to_string())?;
            Ok((name, SceneInput::Inline(text)))
        }
        (Some(_), Some(_)) => {
            Err("a [[scenes]] entry has both `file` and an inline `scene`; keep one".into())
        }
        (None, None) => Err(
            "a [[scenes]] entry needs `file = \"...\"` or an inline [scenes.scene] table".into(),
        ),
    }
}

/// Parses the configuration's scene as `collide simulate` would; the error's text if not.
fn load_scene(input: &SceneInput, overrides: &Overrides) -> Result<RunSpec, String> {
    match input {
        SceneInput::File(path) => scene_file::load(path, overrides),
        SceneInput::Inline(text) => scene_file::parse(Path::new("(inline scene)"), text, overrides),
    }
    .map_err(|e| e.to_string())
}

/// The `backends` entry that names a backend, e.g. `rayon = [...]`.
fn backend_label(backend: BackendKind) -> String {
    match backend.workers_flag() {
        None => format!("`{} = true`", backend.name()),
        Some(_) => format!("`{} = [...]`", backend.name()),
    }
}

/// The n a weak-scaling study multiplies by the worker count.
fn per_worker_n(input: &SceneInput, overrides: &Overrides) -> Result<i64, String> {
    if let Some(n) = overrides.n {
        return Ok(n);
    }
    match load_scene(input, overrides)?.scene {
        SceneSource::Gas(gas) => Ok(gas.n_particles as i64),
        SceneSource::Explicit(_) => Err(
            "weak scaling multiplies n by the workers, and explicit disks have no n; use a random gas or strong scaling".into(),
        ),
    }
}

fn describe(o: &Overrides) -> String {
    let parts: Vec<String> = o
        .entries()
        .into_iter()
        .filter_map(|(name, value)| Some(format!("{name} = {}", value?)))
        .collect();
    if parts.is_empty() {
        "its own settings".into()
    } else {
        parts.join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::spec::{Method, MethodChoice, Observe};

    const INLINE: &str = "[[scenes]]\nname = \"gas\"\n[scenes.scene]\nn = 100\npacking = 0.1\n\
                          [scenes.method]\ndt = 0.1\nsteps = 10\n";

    /// A machine with room for every test manifest here.
    const MACHINE: Machine = Machine {
        usable_cpus: 2,
        memory_bytes: 1 << 34,
    };

    fn study(head: &str) -> Study {
        parse(
            Path::new("m.toml"),
            &format!("name = \"m\"\n{head}\n{INLINE}"),
            &MACHINE,
        )
        .unwrap()
    }

    fn points(study: &Study) -> Vec<(Option<i64>, Option<f64>, String, usize)> {
        study
            .configurations
            .iter()
            .map(|c| {
                (
                    c.overrides.n,
                    c.overrides.packing,
                    c.backend.name().to_owned(),
                    c.backend.counts_of(c.placement()).0,
                )
            })
            .collect()
    }

    #[test]
    fn sweeps_multiply_unless_zipped_and_backends_multiply_them_all() {
        let product = study(
            "[sweep]\nn = [100, 200]\npacking = [0.1, 0.2]\n[backends]\nserial = true\nrayon = [2]\n",
        );
        assert_eq!(product.configurations.len(), 8);
        let zipped = study(
            "[sweep]\nn = [100, 200]\npacking = [0.1, 0.2]\nzip = [\"n\", \"packing\"]\n[backends]\nserial = true\n",
        );
        assert_eq!(
            points(&zipped),
            [
                (Some(100), Some(0.1), "serial".into(), 1),
                (Some(200), Some(0.2), "serial".into(), 1)
            ]
        );
    }

    #[test]
    fn repetitions_are_one_count_or_a_table_by_backend_and_counts_are_checked() {
        let counts = |study: Study| -> Vec<(String, u32)> {
            study
                .configurations
                .iter()
                .map(|c| (c.backend.name().to_owned(), c.repetitions))
                .collect()
        };
        let backends = "[backends]\nserial = true\nrayon = [1, 2]\nmpi = [2]\n";
        let owned = |list: &[(&str, u32)]| -> Vec<(String, u32)> {
            list.iter().map(|&(b, n)| (b.to_owned(), n)).collect()
        };
        let every = study(&format!("repetitions = 4\n{backends}"));
        assert_eq!(every.rounds(), 4);
        assert_eq!(
            counts(every),
            owned(&[("serial", 4), ("rayon", 4), ("rayon", 4), ("mpi", 4)])
        );
        let by_backend = study(&format!("{backends}[repetitions]\nmpi = 9\nserial = 5\n"));
        assert_eq!(by_backend.rounds(), 9);
        assert_eq!(
            counts(by_backend),
            owned(&[("serial", 5), ("rayon", 3), ("rayon", 3), ("mpi", 9)])
        );
        assert_eq!(study(backends).rounds(), 3);
        for (bad, says) in [
            (
                "repetitions = { gpu = 2 }",
                "`repetitions.gpu` names no backend; the table takes serial, rayon, mpi",
            ),
            (
                "repetitions = { mpi = 0 }",
                "`repetitions.mpi` is 0; give a whole number of at least 1 (at most 4294967295)",
            ),
            (
                "repetitions = 2.5",
                "`repetitions` is 2.5; give a whole number of at least 1 (at most 4294967295)",
            ),
            (
                "repetitions = { mpi = 5000000000 }",
                "`repetitions.mpi` is 5000000000; give a whole number of at least 1 (at most 4294967295)",
            ),
            (
                "warmups = -1",
                "`warmups` is -1; give a whole number of at least 0 (at most 4294967295)",
            ),
        ] {
            let text = format!("name = \"m\"\n{bad}\n{backends}{INLINE}");
            let err = parse(Path::new("m.toml"), &text, &MACHINE)
                .unwrap_err()
                .to_string();
            assert_eq!(err, format!("m.toml:2: {says}"));
        }
    }

    #[test]
    fn placements_spread_mpi_ranks_over_nodes_and_threads_per_rank() {
        let placed = study(
            "[backends]\nserial = true\nrayon = [2]\nmpi = [4]\n[placement]\nnodes = [1, 2]\n\
             threads = [1, 2]\n",
        );
        let got: Vec<(String, usize, usize, usize)> = placed
            .configurations
            .iter()
            .map(|c| {
                let layout = c.layout;
                (
                    c.backend.name().to_owned(),
                    layout.nodes,
                    layout.ranks,
                    layout.threads,
                )
            })
            .collect();
        // Serial and rayon are not multiplied by the threads per rank.
        assert_eq!(
            got,
            [
                ("serial".into(), 1, 1, 1),
                ("rayon".into(), 1, 1, 2),
                ("mpi".into(), 1, 4, 1),
                ("mpi".into(), 1, 4, 2),
                ("mpi".into(), 2, 4, 1),
                ("mpi".into(), 2, 4, 2)
            ]
        );
        let keys: Vec<String> = placed.configurations.iter().map(|c| c.key()).collect();
        // One node and one thread per rank keep the keys of studies written before.
        assert!(keys[2].ends_with("backend=mpi;workers=4"), "{keys:?}");
        assert!(
            keys[3].ends_with("backend=mpi;workers=4;threads=2"),
            "{keys:?}"
        );
        assert!(keys[4].ends_with("workers=4;nodes=2"), "{keys:?}");
        assert!(keys[5].ends_with("workers=4;nodes=2;threads=2"), "{keys:?}");
        let args = placed.configurations[5].simulate_args();
        assert!(args.windows(2).any(|w| w == ["--nodes", "2"]), "{args:?}");
        assert!(args.windows(2).any(|w| w == ["--ranks", "4"]), "{args:?}");
        assert!(args.windows(2).any(|w| w == ["--threads", "2"]), "{args:?}");
        let one_thread = placed.configurations[2].simulate_args();
        assert!(
            !one_thread.contains(&"--threads".to_owned()),
            "{one_thread:?}"
        );
        // A site's cores hold ranks × threads.
        let site = crate::cluster::site::Site {
            cores_per_node: 4,
            max_nodes: 2,
            ..crate::cluster::site::Site::local()
        };
        assert_eq!(placed.configurations[2].layout.check(&site, false), Ok(()));
        let err = placed.configurations[3]
            .layout
            .check(&site, false)
            .unwrap_err();
        assert!(err.contains("4 ranks × 2 threads need 8 cores"), "{err}");
        for (bad, says) in [
            ("nodes = [3]", "does not divide the 4 ranks"),
            ("nodes = [0]", "at least 1"),
            ("threads = [0]", "at least 1"),
            (
                "threads = [5]",
                "`backends.mpi` = 4 × `placement.threads` = 5 asks for 20 workers",
            ),
        ] {
            let text = format!("name = \"m\"\n[backends]\nmpi = [4]\n[placement]\n{bad}\n{INLINE}");
            let err = parse(Path::new("m.toml"), &text, &MACHINE)
                .unwrap_err()
                .to_string();
            assert!(err.starts_with("m.toml:4: ") && err.contains(says), "{err}");
        }
    }

    #[test]
    fn weak_scaling_multiplies_n_by_ranks_times_threads() {
        let weak =
            study("scaling = \"weak\"\n[backends]\nmpi = [2]\n[placement]\nthreads = [1, 2]\n");
        let n: Vec<Option<i64>> = weak.configurations.iter().map(|c| c.overrides.n).collect();
        assert_eq!(n, [Some(200), Some(400)]);
    }

    #[test]
    fn weak_scaling_multiplies_n_by_the_workers() {
        let weak = study("scaling = \"weak\"\n[backends]\nserial = true\nrayon = [2, 4]\n");
        let n: Vec<Option<i64>> = weak.configurations.iter().map(|c| c.overrides.n).collect();
        assert_eq!(n, [Some(100), Some(200), Some(400)]);
        let args = weak.configurations[2].simulate_args();
        assert!(args.contains(&"--n=400".to_owned()), "{args:?}");
        assert!(args.windows(2).any(|w| w == ["--threads", "4"]), "{args:?}");
    }

    #[test]
    fn method_and_observe_sweep_like_the_other_keys() {
        let swept = study(
            "[sweep]\nmethod = [\"step\", \"event\"]\nobserve = [\"timing\", \"accuracy\"]\n[backends]\nserial = true\n",
        );
        let pairs: Vec<(Option<MethodChoice>, Option<Observe>)> = swept
            .configurations
            .iter()
            .map(|c| (c.overrides.method, c.overrides.observe))
            .collect();
        assert_eq!(pairs.len(), 4);
        assert!(pairs.contains(&(
            Some(MethodChoice::Fixed(Method::Event)),
            Some(Observe::Accuracy)
        )));
        let event = swept
            .configurations
            .iter()
            .find(|c| c.overrides.method == Some(MethodChoice::Fixed(Method::Event)))
            .unwrap();
        let args = event.simulate_args();
        assert!(args.contains(&"--method=event".to_owned()), "{args:?}");
        assert!(event.key().contains(";method=event"), "{}", event.key());
        // Unswept, the key keeps its old form, so older results resume.
        let plain = study("[backends]\nserial = true\n");
        assert!(plain.configurations[0].key().ends_with("workers=1"));
    }

    #[test]
    fn tc_sweeps_into_distinct_configurations_and_is_validated() {
        let swept = study(
            "[sweep]\nmethod = [\"event\", \"event\"]\ntc = [1e-4, 0.0]\nzip = [\"method\", \"tc\"]\n[backends]\nserial = true\n",
        );
        let tcs: Vec<Option<f64>> = swept
            .configurations
            .iter()
            .map(|c| c.overrides.tc)
            .collect();
        assert_eq!(tcs, [Some(1e-4), Some(0.0)]);
        let keys: Vec<String> = swept
            .configurations
            .iter()
            .map(Configuration::key)
            .collect();
        assert!(keys[0].ends_with(";method=event;tc=0.0001"), "{keys:?}");
        assert!(keys[1].ends_with(";method=event;tc=0"), "{keys:?}");
        let args = swept.configurations[1].simulate_args();
        assert!(args.contains(&"--tc=0".to_owned()), "{args:?}");
        // Each configuration's spec carries its tc.
        let spec = load_scene(
            &swept.configurations[1].input,
            &swept.configurations[1].overrides,
        )
        .unwrap();
        assert_eq!(spec.method.tc, Some(0.0));
        // A negative tc names the scene, the sweep value and the fix.
        let bad =
            format!("name = \"m\"\n[sweep]\ntc = [-1.0]\n[backends]\nserial = true\n{INLINE}");
        let err = parse(Path::new("m.toml"), &bad, &MACHINE)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("tc = -1")
                && err.contains("method.tc")
                && err.contains("0 turns the guard off"),
            "{err}"
        );
        let empty = format!("name = \"m\"\n[sweep]\ntc = []\n[backends]\nserial = true\n{INLINE}");
        let err = parse(Path::new("m.toml"), &empty, &MACHINE)
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("m.toml:3: `sweep.tc` is empty"), "{err}");
    }

    #[test]
    fn the_figure_5_manifest_draws_serial_and_rayon_runs() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("experiments/seed-figure5.toml");
        let text = std::fs::read_to_string(&path).unwrap();
        let study = parse(&path, &text, &MACHINE).unwrap();
        let runs: Vec<(BackendKind, usize)> = study
            .configurations
            .iter()
            .map(|c| (c.backend, c.backend.counts_of(c.placement()).0))
            .collect();
        assert_eq!(
            runs,
            [
                (BackendKind::Serial, 1),
                (BackendKind::Rayon, 1),
                (BackendKind::Rayon, 2)
            ]
        );
        for configuration in &study.configurations {
            assert_eq!(configuration.overrides.draw, Some(true));
            assert_eq!(configuration.overrides.n, Some(2000));
        }
    }

    #[test]
    fn the_event_method_on_a_parallel_backend_is_a_manifest_error() {
        let text = format!(
            "name = \"m\"\n[sweep]\nmethod = [\"step\", \"event\"]\n[backends]\nserial = true\nrayon = [2]\n{INLINE}"
        );
        let err = parse(Path::new("m.toml"), &text, &MACHINE)
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("m.toml:3: "), "{err}");
        assert!(
            err.contains("serial backend only") && err.contains("rayon"),
            "{err}"
        );
        let bad = format!(
            "name = \"m\"\n[sweep]\nmethod = [\"exact\"]\n[backends]\nserial = true\n{INLINE}"
        );
        let err = parse(Path::new("m.toml"), &bad, &MACHINE)
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("m.toml:3: "), "{err}");
    }
}
