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

use crate::cli::BackendName;
use crate::scene_file::{self, DtValue, Overrides};
use crate::sim::Broadphase;
use crate::spec::{MethodChoice, Observe, RunSpec, SceneSource};

/// A validated study: what to run, how often, and in which order.
#[derive(Clone, Debug, PartialEq)]
pub struct Study {
    pub name: String,
    pub description: String,
    /// The manifest it came from.
    pub manifest: PathBuf,
    pub repetitions: u32,
    pub warmups: u32,
    /// Per run; a run that takes longer is killed and recorded as failed.
    pub timeout: Duration,
    pub scaling: Scaling,
    pub configurations: Vec<Configuration>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Scaling {
    /// The same n for every worker count.
    Strong,
    /// n = (the swept or scene n) × workers: the work per worker stays fixed.
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
    pub backend: BackendName,
    /// Threads (rayon), ranks (MPI) or 1 (serial).
    pub workers: usize,
}

impl Configuration {
    /// A stable text key naming the configuration: the same in every run of the same
    /// manifest, so `--resume` can tell what is already measured.
    pub fn key(&self) -> String {
        let o = &self.overrides;
        let dt = match &o.dt {
            Some(DtValue::Seconds(dt)) => dt.to_string(),
            Some(DtValue::Word(word)) => word.clone(),
            None => "-".to_owned(),
        };
        let show = |value: Option<String>| value.unwrap_or_else(|| "-".to_owned());
        // Method, observe and tc join the key only when swept, so the keys of manifests
        // written before they could be swept (and their `--resume`) stay as they were.
        let mut swept = String::new();
        if let Some(method) = o.method {
            swept.push_str(&format!(";method={}", method.name()));
        }
        if let Some(observe) = o.observe {
            swept.push_str(&format!(";observe={}", observe.name()));
        }
        if let Some(tc) = o.tc {
            swept.push_str(&format!(";tc={tc}"));
        }
        format!(
            "scene={};n={};packing={};dt={dt};steps={};seed={};broadphase={};backend={};workers={}{swept}",
            self.scene,
            show(o.n.map(|n| n.to_string())),
            show(o.packing.map(|p| p.to_string())),
            show(o.steps.map(|s| s.to_string())),
            show(o.seed.map(|s| s.to_string())),
            show(o.broadphase.map(|b| b.name().to_owned())),
            self.backend_name(),
            self.workers
        )
    }

    pub fn backend_name(&self) -> &'static str {
        match self.backend {
            BackendName::Serial => "serial",
            BackendName::Rayon => "rayon",
            BackendName::Mpi => "mpi",
        }
    }

    /// The `collide simulate` arguments after the scene path.
    pub fn simulate_args(&self) -> Vec<String> {
        let o = &self.overrides;
        let mut args = vec!["--json".to_owned()];
        let mut push = |flag: &str, value: Option<String>| {
            if let Some(value) = value {
                args.push(flag.to_owned());
                args.push(value);
            }
        };
        push("--n", o.n.map(|n| n.to_string()));
        push("--steps", o.steps.map(|s| s.to_string()));
        push("--seed", o.seed.map(|s| s.to_string()));
        push(
            "--dt",
            o.dt.as_ref().map(|dt| match dt {
                DtValue::Seconds(dt) => dt.to_string(),
                DtValue::Word(word) => word.clone(),
            }),
        );
        push("--packing", o.packing.map(|p| p.to_string()));
        push("--broadphase", o.broadphase.map(|b| b.name().to_owned()));
        push("--method", o.method.map(|m| m.name().to_owned()));
        push("--observe", o.observe.map(|m| m.name().to_owned()));
        push("--tc", o.tc.map(|tc| tc.to_string()));
        push("--backend", Some(self.backend_name().to_owned()));
        match self.backend {
            BackendName::Serial => {}
            BackendName::Rayon => push("--threads", Some(self.workers.to_string())),
            BackendName::Mpi => push("--ranks", Some(self.workers.to_string())),
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
    repetitions: Option<Spanned<i64>>,
    warmups: Option<Spanned<i64>>,
    timeout_s: Option<Spanned<f64>>,
    scaling: Option<Spanned<Scaling>>,
    scenes: Spanned<Vec<Spanned<RawScene>>>,
    #[serde(default)]
    sweep: RawSweep,
    backends: Spanned<RawBackends>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    name: Option<String>,
    file: Option<String>,
    scene: Option<toml::Table>,
    method: Option<toml::Table>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSweep {
    n: Option<Spanned<Vec<i64>>>,
    packing: Option<Spanned<Vec<f64>>>,
    dt: Option<Spanned<Vec<DtValue>>>,
    steps: Option<Spanned<Vec<i64>>>,
    seed: Option<Spanned<Vec<u64>>>,
    broadphase: Option<Spanned<Vec<Broadphase>>>,
    method: Option<Spanned<Vec<MethodChoice>>>,
    observe: Option<Spanned<Vec<Observe>>>,
    tc: Option<Spanned<Vec<f64>>>,
    /// Keys whose lists pair up element by element instead of multiplying.
    zip: Option<Spanned<Vec<String>>>,
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
}

/// Reads and validates the manifest at `path`: the study, and the text it came from.
pub fn load(path: &Path) -> anyhow::Result<(Study, String)> {
    let text = std::fs::read_to_string(path).map_err(|err| {
        anyhow::anyhow!(
            "cannot read manifest {}: {err}; check the path",
            path.display()
        )
    })?;
    Ok((parse(path, &text)?, text))
}

/// Validates manifest text; scene files are found relative to `path`'s folder.
pub fn parse(path: &Path, text: &str) -> Result<Study, ManifestError> {
    let at = |offset: usize| format!("{}:{}", path.display(), line_of(text, offset));
    let invalid = |offset: usize, message: String| ManifestError::Invalid {
        location: at(offset),
        message,
    };
    let raw: RawManifest = toml::from_str(text).map_err(|err| {
        invalid(
            err.span().map_or(0, |span| span.start),
            format!(
                "{}; see the README section Experiment manifests for the keys a manifest accepts",
                err.message().trim_end()
            ),
        )
    })?;
    let name = raw.name.get_ref().trim().to_owned();
    let name_ok = !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    if !name_ok {
        return Err(invalid(
            raw.name.span().start,
            format!(
                "`name` \"{name}\" must be letters, digits, - and _ only (it names the results folder)"
            ),
        ));
    }
    let count = |value: &Option<Spanned<i64>>, field: &str, default: i64, min: i64| {
        let v = value.as_ref().map_or(default, |v| *v.get_ref());
        if v < min {
            let offset = value.as_ref().map_or(0, |v| v.span().start);
            return Err(invalid(
                offset,
                format!("`{field}` is {v}; give a whole number of at least {min}"),
            ));
        }
        Ok(v as u32)
    };
    let repetitions = count(&raw.repetitions, "repetitions", 3, 1)?;
    let warmups = count(&raw.warmups, "warmups", 1, 0)?;
    let timeout_s = raw.timeout_s.as_ref().map_or(600.0, |t| *t.get_ref());
    if !(timeout_s > 0.0 && timeout_s.is_finite()) {
        let offset = raw.timeout_s.as_ref().map_or(0, |t| t.span().start);
        return Err(invalid(
            offset,
            format!("`timeout_s` is {timeout_s}; give a positive number of seconds"),
        ));
    }
    let scaling = raw
        .scaling
        .as_ref()
        .map_or(Scaling::Strong, |s| *s.get_ref());

    let backends = backend_list(raw.backends.get_ref())
        .map_err(|message| invalid(raw.backends.span().start, message))?;
    let points = sweep_points(&raw.sweep).map_err(|(offset, message)| invalid(offset, message))?;
    if raw.scenes.get_ref().is_empty() {
        return Err(invalid(
            raw.scenes.span().start,
            "`scenes` is empty; add a [[scenes]] entry with `file = ...` or inline tables".into(),
        ));
    }
    let folder = path.parent().unwrap_or(Path::new("."));
    let mut configurations = Vec::new();
    let mut seen = BTreeSet::new();
    for entry in raw.scenes.get_ref() {
        let offset = entry.span().start;
        let (scene, input) =
            scene_input(entry.get_ref(), folder).map_err(|message| invalid(offset, message))?;
        for point in &points {
            for &(backend, workers) in &backends {
                let mut overrides = point.clone();
                if scaling == Scaling::Weak {
                    let base = per_worker_n(&input, &overrides).map_err(|message| {
                        invalid(offset, format!("scene `{scene}`: {message}"))
                    })?;
                    overrides.n = Some(base * workers as i64);
                }
                // Every configuration is a valid scene: the same checks as `collide simulate`.
                let spec = load_scene(&input, &overrides).map_err(|message| {
                    invalid(
                        offset,
                        format!("scene `{scene}` with {}: {message}", describe(&overrides)),
                    )
                })?;
                if spec.method.method.may_be_event() && backend != BackendName::Serial {
                    let at = raw
                        .sweep
                        .method
                        .as_ref()
                        .map_or(raw.backends.span().start, |m| m.span().start);
                    return Err(invalid(
                        at,
                        format!(
                            "scene `{scene}` with {} runs the event method, which runs on the serial backend only, but `backends` also lists {}; run the event method in a study with only `serial = true` (or sweep `method` over [\"step\"] here)",
                            describe(&overrides),
                            backend_label(backend)
                        ),
                    ));
                }
                let configuration = Configuration {
                    scene: scene.clone(),
                    input: input.clone(),
                    overrides,
                    backend,
                    workers,
                };
                if !seen.insert(configuration.key()) {
                    return Err(invalid(
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
    Ok(Study {
        name,
        description: raw.description,
        manifest: path.to_owned(),
        repetitions,
        warmups,
        timeout: Duration::from_secs_f64(timeout_s),
        scaling,
        configurations,
    })
}

/// (backend, workers) pairs, in manifest order.
fn backend_list(raw: &RawBackends) -> Result<Vec<(BackendName, usize)>, String> {
    let mut list = Vec::new();
    if raw.serial {
        list.push((BackendName::Serial, 1));
    }
    for (backend, field, counts) in [
        (BackendName::Rayon, "rayon", &raw.rayon),
        (BackendName::Mpi, "mpi", &raw.mpi),
    ] {
        for &count in counts {
            if count < 1 {
                return Err(format!(
                    "`backends.{field}` lists {count}; worker counts are whole numbers of at least 1"
                ));
            }
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

/// The sweep's points: the full product of its lists, except that the lists named in
/// `zip` pair up element by element (and must have the same length).
fn sweep_points(sweep: &RawSweep) -> Result<Vec<Overrides>, (usize, String)> {
    type Setter = Box<dyn Fn(&mut Overrides, usize)>;
    // (key, span start, length, how to apply element i)
    let mut lists: Vec<(&str, usize, usize, Setter)> = Vec::new();
    macro_rules! list {
        ($key:literal, $field:ident, $convert:expr) => {
            if let Some(values) = &sweep.$field {
                let owned = values.get_ref().clone();
                let convert = $convert;
                lists.push((
                    $key,
                    values.span().start,
                    owned.len(),
                    Box::new(move |o: &mut Overrides, i: usize| {
                        o.$field = Some(convert(owned[i].clone()))
                    }),
                ));
            }
        };
    }
    list!("n", n, |v: i64| v);
    list!("packing", packing, |v: f64| v);
    list!("dt", dt, |v: DtValue| v);
    list!("steps", steps, |v: i64| v);
    list!("seed", seed, |v: u64| v);
    list!("broadphase", broadphase, |v: Broadphase| v);
    list!("method", method, |v: MethodChoice| v);
    list!("observe", observe, |v: Observe| v);
    list!("tc", tc, |v: f64| v);
    for (key, offset, len, _) in &lists {
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
        if !lists.iter().any(|(k, ..)| k == key) {
            return Err((
                zip_offset,
                format!("`sweep.zip` names `{key}`, which is not a swept list here"),
            ));
        }
    }
    let (paired, free): (Vec<_>, Vec<_>) = lists
        .into_iter()
        .partition(|(key, ..)| zipped.iter().any(|z| z == key));
    let mut points = vec![Overrides::default()];
    if let Some((_, _, len, _)) = paired.first() {
        if let Some((key, ..)) = paired.iter().find(|(_, _, l, _)| l != len) {
            return Err((
                zip_offset,
                format!(
                    "`sweep.zip` pairs lists of different lengths (`{key}` has another length than `{}`); give them the same length",
                    paired[0].0
                ),
            ));
        }
        points = (0..*len)
            .map(|i| {
                let mut o = Overrides::default();
                for (_, _, _, set) in &paired {
                    set(&mut o, i);
                }
                o
            })
            .collect();
    }
    for (_, _, len, set) in &free {
        points = points
            .iter()
            .flat_map(|point| {
                (0..*len).map(move |i| {
                    let mut o = point.clone();
                    set(&mut o, i);
                    o
                })
            })
            .collect();
    }
    Ok(points)
}

fn scene_input(raw: &RawScene, folder: &Path) -> Result<(String, SceneInput), String> {
    if raw.name.as_ref().is_some_and(|name| name.trim().is_empty()) {
        return Err(
            "a scene's `name` is blank; give it letters, digits, - or _ (it names the \
                    scene in the results and its file under scenes/), or drop it to use the file's"
                .into(),
        );
    }
    match (&raw.file, &raw.scene) {
        (Some(file), None) => {
            if raw.method.is_some() {
                return Err("a [[scenes]] entry with `file` takes its method from the file; drop `method` or inline the scene".into());
            }
            let path = folder.join(file);
            let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned());
            let name = raw.name.clone().or(stem).unwrap_or_else(|| file.clone());
            Ok((name, SceneInput::File(path)))
        }
        (None, Some(scene)) => {
            let name = raw.name.clone().ok_or(
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
fn backend_label(backend: BackendName) -> &'static str {
    match backend {
        BackendName::Serial => "`serial = true`",
        BackendName::Rayon => "`rayon = [...]`",
        BackendName::Mpi => "`mpi = [...]`",
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
    let mut parts = Vec::new();
    if let Some(n) = o.n {
        parts.push(format!("n = {n}"));
    }
    if let Some(p) = o.packing {
        parts.push(format!("packing = {p}"));
    }
    if let Some(s) = o.steps {
        parts.push(format!("steps = {s}"));
    }
    if let Some(m) = o.method {
        parts.push(format!("method = {}", m.name()));
    }
    if let Some(o) = o.observe {
        parts.push(format!("observe = {}", o.name()));
    }
    if let Some(tc) = o.tc {
        parts.push(format!("tc = {tc}"));
    }
    if parts.is_empty() {
        "its own settings".into()
    } else {
        parts.join(", ")
    }
}

fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::Method;

    const INLINE: &str = "[[scenes]]\nname = \"gas\"\n[scenes.scene]\nn = 100\npacking = 0.1\n\
                          [scenes.method]\ndt = 0.1\nsteps = 10\n";

    fn study(head: &str) -> Study {
        parse(
            Path::new("m.toml"),
            &format!("name = \"m\"\n{head}\n{INLINE}"),
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
                    c.backend_name().to_owned(),
                    c.workers,
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
    fn weak_scaling_multiplies_n_by_the_workers() {
        let weak = study("scaling = \"weak\"\n[backends]\nserial = true\nrayon = [2, 4]\n");
        let n: Vec<Option<i64>> = weak.configurations.iter().map(|c| c.overrides.n).collect();
        assert_eq!(n, [Some(100), Some(200), Some(400)]);
        let args = weak.configurations[2].simulate_args();
        assert!(args.windows(2).any(|w| w == ["--n", "400"]), "{args:?}");
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
        assert!(
            args.windows(2).any(|w| w == ["--method", "event"]),
            "{args:?}"
        );
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
        assert!(args.windows(2).any(|w| w == ["--tc", "0"]), "{args:?}");
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
        let err = parse(Path::new("m.toml"), &bad).unwrap_err().to_string();
        assert!(
            err.contains("tc = -1")
                && err.contains("method.tc")
                && err.contains("0 turns the guard off"),
            "{err}"
        );
        let empty = format!("name = \"m\"\n[sweep]\ntc = []\n[backends]\nserial = true\n{INLINE}");
        let err = parse(Path::new("m.toml"), &empty).unwrap_err().to_string();
        assert!(err.starts_with("m.toml:3: `sweep.tc` is empty"), "{err}");
    }

    #[test]
    fn the_event_method_on_a_parallel_backend_is_a_manifest_error() {
        let text = format!(
            "name = \"m\"\n[sweep]\nmethod = [\"step\", \"event\"]\n[backends]\nserial = true\nrayon = [2]\n{INLINE}"
        );
        let err = parse(Path::new("m.toml"), &text).unwrap_err().to_string();
        assert!(err.starts_with("m.toml:3: "), "{err}");
        assert!(
            err.contains("serial backend only") && err.contains("rayon"),
            "{err}"
        );
        let bad = format!(
            "name = \"m\"\n[sweep]\nmethod = [\"exact\"]\n[backends]\nserial = true\n{INLINE}"
        );
        let err = parse(Path::new("m.toml"), &bad).unwrap_err().to_string();
        assert!(err.starts_with("m.toml:3: "), "{err}");
    }
}
