//! Scene files (TOML) → validated [`RunSpec`]; every error names the file, line, field and fix.
//!
//! Command-line overrides (`--n`, `--steps`, ...) are applied before validation, so a bad
//! override is reported against its flag rather than against the file.

use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use crate::run::overrides::{NumberOrWord, Overrides};
use crate::run::scene_limits::{self, Field};
use crate::run::spec::{
    DEFAULT_DT_FRACTION, DEFAULT_MISSED_TOLERANCE, Discard, DtChoice, InjectedSlowdown, Method,
    MethodChoice, MethodSpec, Observe, RunSpec, SceneSource,
};
use crate::sim::grid::StripGrid;
use crate::sim::observe::SERIES_BLOCKS;
use crate::sim::scene::{
    Extent, GasSpec, MassRule, Placement, RadiusDistribution, check_periodic_box,
};
use crate::sim::{Boundary, Broadphase, Disk, Domain, Particles, Physics, Scene};
use crate::stats::observables::MIN_KEPT_BLOCKS;
use crate::system::input::{MAX_TEXT_BYTES, read_text};

#[derive(Debug, thiserror::Error)]
pub enum SceneFileError {
    /// The reason is kept as words, not as a source error: shown as a chain, the
    /// source would repeat it.
    #[error("cannot read scene file {path}: {reason}")]
    Read { path: PathBuf, reason: String },
    #[error(
        "{path}:{line}: {message}; see docs/guide.md, Scene files, for the keys and values a scene accepts"
    )]
    Syntax {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error("{location}: `{field}` {problem}; {fix}")]
    Invalid {
        location: String,
        field: String,
        problem: String,
        fix: String,
    },
}

/// Reads and validates a scene file, applying overrides.
pub fn load(path: &Path, overrides: &Overrides) -> Result<RunSpec, SceneFileError> {
    let text = read_text(path, MAX_TEXT_BYTES).map_err(|reason| SceneFileError::Read {
        path: path.to_owned(),
        reason,
    })?;
    parse(path, &text, overrides)
}

/// Validates scene-file text; `path` is only used in messages.
pub fn parse(path: &Path, text: &str, overrides: &Overrides) -> Result<RunSpec, SceneFileError> {
    let raw: RawFile = toml::from_str(text).map_err(|err| SceneFileError::Syntax {
        path: path.to_owned(),
        line: err.span().map_or(1, |span| line_of(text, span.start)),
        message: err.message().trim_end().to_owned(),
    })?;
    let validator = Validator { path, text };
    let method = validator.method(&raw.method, overrides)?;
    let scene = if raw.scene.particle.is_some() {
        validator.explicit_scene(&raw.scene, overrides)?
    } else {
        SceneSource::Gas(validator.gas(&raw.scene, overrides)?)
    };
    validator.method_fits_scene(&raw, &method, &scene)?;
    validator.derived_quantities(&raw, overrides, &method, &scene)?;
    Ok(RunSpec {
        scene,
        method,
        slowdown: InjectedSlowdown::NONE,
    })
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    scene: RawScene,
    #[serde(default)]
    method: RawMethod,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    n: Option<Spanned<i64>>,
    packing: Option<Spanned<f64>>,
    size: Option<Spanned<Vec<f64>>>,
    radius: Option<Spanned<RawRadius>>,
    mass: Option<Spanned<RawMass>>,
    speed_rms: Option<Spanned<f64>>,
    restitution: Option<Spanned<f64>>,
    wall_restitution: Option<Spanned<f64>>,
    boundary: Option<Spanned<Boundary>>,
    seed: Option<Spanned<u64>>,
    gravity: Option<Spanned<Vec<f64>>>,
    placement: Option<Spanned<Placement>>,
    particle: Option<Vec<Spanned<RawParticle>>>,
}

#[derive(Deserialize)]
#[serde(
    untagged,
    expecting = "expected a radius: a number such as 1.0, or a range such as { min = 0.5, max = 1.5 }"
)]
enum RawRadius {
    Fixed(f64),
    Range { min: f64, max: f64 },
}

#[derive(Deserialize)]
#[serde(
    untagged,
    expecting = "expected a mass: a number such as 1.0, or \"area\""
)]
enum RawMass {
    Fixed(f64),
    Rule(String),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawParticle {
    x: f64,
    y: f64,
    #[serde(default)]
    vx: f64,
    #[serde(default)]
    vy: f64,
    radius: Option<f64>,
    mass: Option<f64>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawMethod {
    dt: Option<Spanned<NumberOrWord>>,
    dt_fraction: Option<Spanned<f64>>,
    steps: Option<Spanned<i64>>,
    broadphase: Option<Spanned<Broadphase>>,
    method: Option<Spanned<MethodChoice>>,
    missed_tolerance: Option<Spanned<f64>>,
    tc: Option<Spanned<f64>>,
    observe: Option<Spanned<Observe>>,
    discard: Option<Spanned<NumberOrWord>>,
}

/// What an explicit scene's disks take where they give no radius or mass.
struct DiskDefaults {
    radius: f64,
    /// Where the default radius came from.
    radius_origin: Origin,
    /// `None`: mass ∝ area.
    mass: Option<f64>,
}

/// Where a value came from, for error messages.
#[derive(Clone, Copy)]
enum Origin {
    File(usize),
    Flag(&'static str),
    Default,
}

/// A value with its origin: from an override flag, else from the file, else absent.
struct Sourced<T> {
    value: T,
    origin: Origin,
}

struct Validator<'a> {
    path: &'a Path,
    text: &'a str,
}

impl Validator<'_> {
    fn origin(&self, span: Range<usize>) -> Origin {
        Origin::File(line_of(self.text, span.start))
    }

    /// The override if given, else the file's value.
    fn pick<T: Clone, U>(
        &self,
        flag: &'static str,
        from_flag: Option<T>,
        from_file: &Option<Spanned<U>>,
        convert: impl Fn(&U) -> T,
    ) -> Option<Sourced<T>> {
        match (from_flag, from_file) {
            (Some(value), _) => Some(Sourced {
                value,
                origin: Origin::Flag(flag),
            }),
            (None, Some(spanned)) => Some(Sourced {
                value: convert(spanned.get_ref()),
                origin: self.origin(spanned.span()),
            }),
            (None, None) => None,
        }
    }

    fn in_file<T: Clone>(&self, value: &Option<Spanned<T>>) -> Option<Sourced<T>> {
        value.as_ref().map(|spanned| Sourced {
            value: spanned.get_ref().clone(),
            origin: self.origin(spanned.span()),
        })
    }

    fn invalid(&self, origin: Origin, field: &str, problem: String, fix: &str) -> SceneFileError {
        let location = match origin {
            Origin::File(line) => format!("{}:{line}", self.path.display()),
            Origin::Flag(flag) => format!("{} (from {flag})", self.path.display()),
            Origin::Default => self.path.display().to_string(),
        };
        SceneFileError::Invalid {
            location,
            field: field.to_owned(),
            problem,
            fix: fix.to_owned(),
        }
    }

    fn method(&self, raw: &RawMethod, overrides: &Overrides) -> Result<MethodSpec, SceneFileError> {
        let method = self
            .pick("--method", overrides.method, &raw.method, |m| *m)
            .map_or(MethodChoice::Fixed(Method::Step), |sourced| sourced.value);
        let missed_tolerance = self.missed_tolerance(raw)?;
        let dt = self.dt(raw, overrides, method)?;
        let steps = self.count(
            self.pick("--steps", overrides.steps, &raw.steps, |s| *s),
            "method.steps",
            u64::MAX,
            "add `steps = 400` under [method] or pass --steps",
            "give at least 1 step",
        )?;
        let broadphase = self
            .pick("--broadphase", overrides.broadphase, &raw.broadphase, |b| {
                *b
            })
            .map_or(Broadphase::Grid, |sourced| sourced.value);
        let observe = self
            .pick("--observe", overrides.observe, &raw.observe, |o| *o)
            .map_or(Observe::Timing, |sourced| sourced.value);
        let tc = self.tc(raw, overrides)?;
        let discard = self.discard(raw, overrides, dt, steps)?;
        Ok(MethodSpec {
            dt,
            steps,
            broadphase,
            method,
            missed_tolerance,
            tc,
            observe,
            draw: overrides.draw.unwrap_or(false),
            discard,
        })
    }

    fn missed_tolerance(&self, raw: &RawMethod) -> Result<f64, SceneFileError> {
        match self.in_file(&raw.missed_tolerance) {
            Some(Sourced { value, origin }) if !(value > 0.0 && value < 1.0) => Err(self.invalid(
                origin,
                "method.missed_tolerance",
                format!("is {value}, outside (0, 1)"),
                "give the largest fraction of missed collisions method = \"auto\" and \
                     dt = \"auto\" may accept, e.g. missed_tolerance = 1e-3",
            )),
            sourced => Ok(sourced.map_or(DEFAULT_MISSED_TOLERANCE, |s| s.value)),
        }
    }

    /// The time step: given, or a rule that chooses it (see `DtChoice`).
    fn dt(
        &self,
        raw: &RawMethod,
        overrides: &Overrides,
        method: MethodChoice,
    ) -> Result<DtChoice, SceneFileError> {
        // dt = "auto" follows the dt_fraction rule where dt_fraction is given, else the
        // tolerance; an absent dt is the dt_fraction rule unless the method is auto.
        let tolerance_or = |fraction: Option<f64>| {
            fraction.map_or(DtChoice::Tolerance, |fraction| DtChoice::Auto { fraction })
        };
        let explicit_fraction = self.dt_fraction(raw)?;
        let Some(Sourced { value, origin }) =
            self.pick("--dt", overrides.dt.clone(), &raw.dt, Clone::clone)
        else {
            return Ok(if method == MethodChoice::Auto {
                tolerance_or(explicit_fraction)
            } else {
                DtChoice::Auto {
                    fraction: explicit_fraction.unwrap_or(DEFAULT_DT_FRACTION),
                }
            });
        };
        match value {
            NumberOrWord::Word(word) if word == "auto" => Ok(tolerance_or(explicit_fraction)),
            NumberOrWord::Number(dt) if dt > 0.0 && dt.is_finite() => Ok(DtChoice::Fixed(dt)),
            NumberOrWord::Number(dt) => Err(self.invalid(
                origin,
                "method.dt",
                format!("is {dt}, not a positive number"),
                "give a positive time step, e.g. dt = 0.01, or dt = \"auto\"",
            )),
            NumberOrWord::Word(word) => Err(self.invalid(
                origin,
                "method.dt",
                format!("is \"{word}\""),
                "give a positive number or \"auto\"",
            )),
        }
    }

    fn dt_fraction(&self, raw: &RawMethod) -> Result<Option<f64>, SceneFileError> {
        let Some(Sourced { value, origin }) = self.in_file(&raw.dt_fraction) else {
            return Ok(None);
        };
        if !(value > 0.0 && value <= 1.0) {
            return Err(self.invalid(
                origin,
                "method.dt_fraction",
                format!("is {value}, outside (0, 1]"),
                "give the largest step as a fraction of the smallest radius, e.g. dt_fraction = 0.1",
            ));
        }
        Ok(Some(value))
    }

    /// How much of the run to drop before averaging its observables: "auto" (MSER-5,
    /// also when absent), a simulated time, or a share of the run ("30%"). A discard
    /// must leave [`MIN_KEPT_BLOCKS`] of the run's blocks to average; a time is checked
    /// against the run's end where dt is given (with dt = "auto", the summary says so
    /// when too little is left).
    fn discard(
        &self,
        raw: &RawMethod,
        overrides: &Overrides,
        dt: DtChoice,
        steps: u64,
    ) -> Result<Discard, SceneFileError> {
        let Some(Sourced { value, origin }) = self.pick(
            "--discard",
            overrides.discard.clone(),
            &raw.discard,
            Clone::clone,
        ) else {
            return Ok(Discard::Automatic);
        };
        let refuse =
            |problem: String, fix: &str| self.invalid(origin, "method.discard", problem, fix);
        let discard = parse_discard(value).map_err(|problem| refuse(problem, DISCARD_FORMS))?;
        leaves_blocks(discard, dt, steps).map_err(|(problem, fix)| refuse(problem, &fix))
    }

    /// The TC model time of the event method, if given.
    fn tc(&self, raw: &RawMethod, overrides: &Overrides) -> Result<Option<f64>, SceneFileError> {
        match self.pick("--tc", overrides.tc, &raw.tc, |t| *t) {
            Some(Sourced { value, origin }) if !(value >= 0.0 && value.is_finite()) => {
                Err(self.invalid(
                    origin,
                    "method.tc",
                    format!("is {value}, not a time ≥ 0"),
                    "give the TC model time of the event method, e.g. tc = 1e-5 (0 turns the guard off)",
                ))
            }
            sourced => Ok(sourced.map(|s| s.value)),
        }
    }

    /// What a method cannot do with a scene: the event method flies straight lines, so
    /// it refuses a field rather than give a wrong answer.
    fn method_fits_scene(
        &self,
        raw: &RawFile,
        method: &MethodSpec,
        scene: &SceneSource,
    ) -> Result<(), SceneFileError> {
        let physics = match scene {
            SceneSource::Gas(gas) => gas.physics,
            SceneSource::Explicit(scene) => scene.physics,
        };
        if method.method == MethodChoice::Fixed(Method::Event) && physics.gravity.is_some() {
            let origin = self
                .in_file(&raw.scene.gravity)
                .map_or(Origin::Default, |s| s.origin);
            return Err(self.invalid(
                origin,
                "scene.gravity",
                "is not modelled by the event method (its disks fly straight lines, not parabolas)"
                    .to_owned(),
                "remove gravity, or use method = \"step\"",
            ));
        }
        Ok(())
    }

    /// The derived quantities of [`scene_limits::check`], each traced to the field to change.
    fn derived_quantities(
        &self,
        raw: &RawFile,
        overrides: &Overrides,
        method: &MethodSpec,
        scene: &SceneSource,
    ) -> Result<(), SceneFileError> {
        let Some(violation) = scene_limits::check(scene, method) else {
            return Ok(());
        };
        let scene_raw = &raw.scene;
        let (field, origin) = match violation.field {
            Field::Radius => ("scene.radius", self.origin_of(&scene_raw.radius)),
            Field::Size => ("scene.size", self.origin_of(&scene_raw.size)),
            Field::SpeedRms => ("scene.speed_rms", self.origin_of(&scene_raw.speed_rms)),
            Field::Mass => ("scene.mass", self.origin_of(&scene_raw.mass)),
            Field::Gravity => ("scene.gravity", self.origin_of(&scene_raw.gravity)),
            Field::Particles => ("scene.particle", Origin::Default),
            Field::Dt => match overrides.dt {
                Some(_) => ("method.dt", Origin::Flag("--dt")),
                None => ("method.dt", self.origin_of(&raw.method.dt)),
            },
        };
        Err(self.invalid(origin, field, violation.problem, violation.fix))
    }

    /// Where a field was written, if it was.
    fn origin_of<T>(&self, value: &Option<Spanned<T>>) -> Origin {
        value
            .as_ref()
            .map_or(Origin::Default, |spanned| self.origin(spanned.span()))
    }

    fn physics(&self, raw: &RawScene) -> Result<Physics, SceneFileError> {
        let default = Physics::default();
        let coefficient = |value: &Option<Spanned<f64>>, field: &str, absent: f64| match self
            .in_file(value)
        {
            None => Ok(absent),
            Some(Sourced { value, origin }) if !(0.0..=1.0).contains(&value) => Err(self.invalid(
                origin,
                field,
                format!("is {value}, outside [0, 1]"),
                "give a restitution between 0 (perfectly inelastic) and 1 (elastic)",
            )),
            Some(Sourced { value, .. }) => Ok(value),
        };
        let restitution = coefficient(&raw.restitution, "scene.restitution", default.restitution)?;
        let wall_restitution = coefficient(
            &raw.wall_restitution,
            "scene.wall_restitution",
            default.wall_restitution,
        )?;
        let gravity = match self.in_file(&raw.gravity) {
            None => default.gravity,
            Some(Sourced { value, origin }) => {
                let [gx, gy] =
                    self.pair(&value, origin, "scene.gravity", "gravity = [0.0, -9.81]")?;
                // Model no more than the scene needs: a zero field is no field.
                (gx != 0.0 || gy != 0.0).then_some([gx, gy])
            }
        };
        Ok(Physics {
            restitution,
            wall_restitution,
            gravity,
        })
    }

    fn pair(
        &self,
        value: &[f64],
        origin: Origin,
        field: &str,
        example: &str,
    ) -> Result<[f64; 2], SceneFileError> {
        match value {
            [a, b] if a.is_finite() && b.is_finite() => Ok([*a, *b]),
            _ => Err(self.invalid(
                origin,
                field,
                format!("is {value:?}, not two finite numbers"),
                &format!("write it as {example}"),
            )),
        }
    }

    fn size(&self, raw: &RawScene) -> Result<Option<(f64, f64)>, SceneFileError> {
        let Some(Sourced { value, origin }) = self.in_file(&raw.size) else {
            return Ok(None);
        };
        let [width, height] = self.pair(&value, origin, "scene.size", "size = [100.0, 100.0]")?;
        if width <= 0.0 || height <= 0.0 {
            return Err(self.invalid(
                origin,
                "scene.size",
                format!("is [{width}, {height}], not positive"),
                "give a positive width and height, e.g. size = [100.0, 100.0]",
            ));
        }
        Ok(Some((width, height)))
    }

    fn positive(
        &self,
        value: f64,
        origin: Origin,
        field: &str,
        fix: &str,
    ) -> Result<f64, SceneFileError> {
        if value > 0.0 && value.is_finite() {
            Ok(value)
        } else {
            Err(self.invalid(origin, field, format!("is {value}, not positive"), fix))
        }
    }

    /// A required whole number in `1..=max`.
    fn count(
        &self,
        sourced: Option<Sourced<i64>>,
        field: &str,
        max: u64,
        fix_missing: &str,
        fix_bad: &str,
    ) -> Result<u64, SceneFileError> {
        let Some(Sourced { value, origin }) = sourced else {
            return Err(self.invalid(Origin::Default, field, "is missing".to_owned(), fix_missing));
        };
        u64::try_from(value)
            .ok()
            .filter(|count| (1..=max).contains(count))
            .ok_or_else(|| {
                self.invalid(
                    origin,
                    field,
                    format!("is {value}, not a whole number from 1 to {max}"),
                    fix_bad,
                )
            })
    }

    fn radius(&self, raw: &RawScene) -> Result<(RadiusDistribution, Origin), SceneFileError> {
        let Some(spanned) = &raw.radius else {
            return Ok((RadiusDistribution::Fixed(1.0), Origin::Default));
        };
        let origin = self.origin(spanned.span());
        let fix = "give a radius > 0, e.g. radius = 1.0 or radius = { min = 0.5, max = 1.5 }";
        let distribution = match *spanned.get_ref() {
            RawRadius::Fixed(r) => {
                RadiusDistribution::Fixed(self.positive(r, origin, "scene.radius", fix)?)
            }
            RawRadius::Range { min, max } => {
                let min = self.positive(min, origin, "scene.radius.min", fix)?;
                let max = self.positive(max, origin, "scene.radius.max", fix)?;
                if min > max {
                    return Err(self.invalid(
                        origin,
                        "scene.radius",
                        format!("has min {min} above max {max}"),
                        "swap them",
                    ));
                }
                RadiusDistribution::Uniform { min, max }
            }
        };
        Ok((distribution, origin))
    }

    fn mass(&self, raw: &RawScene) -> Result<MassRule, SceneFileError> {
        let Some(spanned) = &raw.mass else {
            return Ok(MassRule::Fixed(1.0));
        };
        let origin = self.origin(spanned.span());
        match spanned.get_ref() {
            RawMass::Fixed(m) => Ok(MassRule::Fixed(self.positive(
                *m,
                origin,
                "scene.mass",
                "give a mass > 0, or mass = \"area\"",
            )?)),
            RawMass::Rule(rule) if rule == "area" => Ok(MassRule::Area),
            RawMass::Rule(rule) => Err(self.invalid(
                origin,
                "scene.mass",
                format!("is \"{rule}\""),
                "give a positive number, or \"area\" for mass = π r²",
            )),
        }
    }

    fn gas(&self, raw: &RawScene, overrides: &Overrides) -> Result<GasSpec, SceneFileError> {
        let n_particles = self.count(
            self.pick("--n", overrides.n, &raw.n, |n| *n),
            "scene.n",
            u64::from(u32::MAX),
            "give the number of disks, e.g. n = 1000, or list them as [[scene.particle]]",
            "give at least 1 disk, e.g. n = 1000",
        )? as usize;
        let placement = self
            .in_file(&raw.placement)
            .map_or(Placement::Random, |sourced| sourced.value);
        let packing = self.pick("--packing", overrides.packing, &raw.packing, |p| *p);
        let extent = match (packing, self.size(raw)?) {
            (Some(Sourced { origin, .. }), Some(_)) => {
                return Err(self.invalid(
                    origin,
                    "scene.packing",
                    "is given together with scene.size".to_owned(),
                    "give either packing (the box is then square) or size, not both",
                ));
            }
            (Some(Sourced { value, origin }), None) => {
                let limit = placement.max_packing();
                if !(value > 0.0 && value <= limit) {
                    return Err(self.invalid(
                        origin,
                        "scene.packing",
                        format!(
                            "is {value}, outside (0, {limit:.3}], the range {} placement reaches",
                            placement.name()
                        ),
                        "random addition jams past 0.51 and a square lattice holds at most π/4; \
                         lower the packing, or use placement = \"lattice\" for dense scenes",
                    ));
                }
                Extent::Packing(value)
            }
            (None, Some((width, height))) => Extent::Size { width, height },
            (None, None) => {
                return Err(self.invalid(
                    Origin::Default,
                    "scene.packing",
                    "is missing, and so is scene.size".to_owned(),
                    "give the area fraction, e.g. packing = 0.05, or the box, e.g. size = [100.0, 100.0]",
                ));
            }
        };
        let speed_rms = match self.in_file(&raw.speed_rms) {
            None => 1.0,
            Some(Sourced { value, origin }) if !(value >= 0.0 && value.is_finite()) => {
                return Err(self.invalid(
                    origin,
                    "scene.speed_rms",
                    format!("is {value}, not a speed ≥ 0"),
                    "give the rms speed of the initial velocities, e.g. speed_rms = 1.0",
                ));
            }
            Some(Sourced { value, .. }) => value,
        };
        let radius = self.radius(raw)?.0;
        self.box_holds(raw, n_particles, &radius, placement, extent)?;
        Ok(GasSpec {
            n_particles,
            extent,
            radius,
            mass: self.mass(raw)?,
            speed_rms,
            placement,
            boundary: self
                .in_file(&raw.boundary)
                .map_or(Boundary::Walls, |s| s.value),
            physics: self.physics(raw)?,
            seed: self
                .pick("--seed", overrides.seed, &raw.seed, |s| *s)
                .map_or(0, |s| s.value),
        })
    }

    /// Refuses, at the box's line, a box given by `size` that `n_particles` disks of
    /// `radius` would fill beyond what `placement` reaches (rather than the placement
    /// failing later).
    fn box_holds(
        &self,
        raw: &RawScene,
        n_particles: usize,
        radius: &RadiusDistribution,
        placement: Placement,
        extent: Extent,
    ) -> Result<(), SceneFileError> {
        let Extent::Size { width, height } = extent else {
            return Ok(());
        };
        let packing = n_particles as f64 * radius.mean_area() / (width * height);
        let limit = placement.max_packing();
        if packing > limit {
            return Err(self.invalid(
                self.origin_of(&raw.size),
                "scene.size",
                format!(
                    "is {width} × {height}, where {n_particles} disks cover an area \
                     fraction of {packing:.3}, above the {limit:.3} that {} placement reaches",
                    placement.name()
                ),
                &match packing <= std::f64::consts::FRAC_PI_4 {
                    true => "enlarge the box, lower n or the radius, or use placement = \
                             \"lattice\""
                        .to_owned(),
                    false => format!(
                        "enlarge the box at least {:.2}-fold in area, or lower n or the radius \
                         (no placement packs disks beyond π/4 ≈ 0.785)",
                        packing / std::f64::consts::FRAC_PI_4
                    ),
                },
            ));
        }
        Ok(())
    }

    fn explicit_scene(
        &self,
        raw: &RawScene,
        overrides: &Overrides,
    ) -> Result<SceneSource, SceneFileError> {
        self.refuse_random_keys(raw, overrides)?;
        let Some((width, height)) = self.size(raw)? else {
            return Err(self.invalid(
                Origin::Default,
                "scene.size",
                "is missing".to_owned(),
                "a scene with explicit disks needs its box, e.g. size = [100.0, 100.0]",
            ));
        };
        let domain = Domain {
            width,
            height,
            boundary: self
                .in_file(&raw.boundary)
                .map_or(Boundary::Walls, |s| s.value),
        };
        let (default_radius, radius_origin) = match self.radius(raw)? {
            (RadiusDistribution::Fixed(r), origin) => (r, origin),
            (RadiusDistribution::Uniform { .. }, origin) => {
                return Err(self.invalid(
                    origin,
                    "scene.radius",
                    "is a range, which only random scenes draw from".to_owned(),
                    "give one radius as the default, or a radius per [[scene.particle]]",
                ));
            }
        };
        let default_mass = match self.mass(raw)? {
            MassRule::Fixed(m) => Some(m),
            MassRule::Area => None,
        };
        let defaults = DiskDefaults {
            radius: default_radius,
            radius_origin,
            mass: default_mass,
        };
        let entries = raw.particle.as_deref().unwrap_or_default();
        let mut disks = Vec::with_capacity(entries.len());
        let mut origins = Vec::with_capacity(entries.len());
        for (index, entry) in entries.iter().enumerate() {
            let origin = self.origin(entry.span());
            disks.push(self.explicit_disk(entry.get_ref(), index, origin, &defaults, &domain)?);
            origins.push(origin);
        }
        if disks.is_empty() {
            return Err(self.invalid(
                Origin::Default,
                "scene.particle",
                "is empty".to_owned(),
                "list at least one [[scene.particle]]",
            ));
        }
        let particles = Particles::from_disks(&disks);
        self.refuse_overlaps(raw, &domain, &particles, &origins)?;
        Ok(SceneSource::Explicit(Scene {
            domain,
            physics: self.physics(raw)?,
            particles,
        }))
    }

    /// Refuses the keys and flags that only random scenes take.
    fn refuse_random_keys(
        &self,
        raw: &RawScene,
        overrides: &Overrides,
    ) -> Result<(), SceneFileError> {
        let file_origin = |span: Option<Range<usize>>| span.map(|span| self.origin(span));
        let random_only = [
            ("scene.n", file_origin(raw.n.as_ref().map(Spanned::span))),
            (
                "scene.packing",
                file_origin(raw.packing.as_ref().map(Spanned::span)),
            ),
            (
                "scene.speed_rms",
                file_origin(raw.speed_rms.as_ref().map(Spanned::span)),
            ),
            (
                "scene.seed",
                file_origin(raw.seed.as_ref().map(Spanned::span)),
            ),
            (
                "scene.placement",
                file_origin(raw.placement.as_ref().map(Spanned::span)),
            ),
            ("--n", overrides.n.map(|_| Origin::Flag("--n"))),
            (
                "--packing",
                overrides.packing.map(|_| Origin::Flag("--packing")),
            ),
            ("--seed", overrides.seed.map(|_| Origin::Flag("--seed"))),
        ];
        for (field, origin) in random_only {
            if let Some(origin) = origin {
                return Err(self.invalid(
                    origin,
                    field,
                    "applies to random scenes, but this scene lists its disks as [[scene.particle]]".to_owned(),
                    "remove it, or remove the [[scene.particle]] entries",
                ));
            }
        }
        Ok(())
    }

    /// Disk `index` of an explicit scene, with the scene's default radius and mass where
    /// it gives none, checked to be finite and inside `domain`.
    fn explicit_disk(
        &self,
        p: &RawParticle,
        index: usize,
        origin: Origin,
        defaults: &DiskDefaults,
        domain: &Domain,
    ) -> Result<Disk, SceneFileError> {
        let field = format!("scene.particle[{index}]");
        let radius = match p.radius {
            Some(r) => self.positive(r, origin, &format!("{field}.radius"), "give a radius > 0")?,
            None => self.positive(
                defaults.radius,
                defaults.radius_origin,
                "scene.radius",
                "give a radius > 0",
            )?,
        };
        let mass = match p.mass.or(defaults.mass) {
            Some(m) => self.positive(m, origin, &format!("{field}.mass"), "give a mass > 0")?,
            None => std::f64::consts::PI * radius * radius,
        };
        if ![p.x, p.y, p.vx, p.vy].iter().all(|v| v.is_finite()) {
            return Err(self.invalid(
                origin,
                &field,
                "has a position or velocity that is not a finite number".to_owned(),
                "give finite x, y, vx, vy",
            ));
        }
        let inside = match domain.boundary {
            Boundary::Walls => {
                p.x - radius >= 0.0
                    && p.x + radius <= domain.width
                    && p.y - radius >= 0.0
                    && p.y + radius <= domain.height
            }
            Boundary::Periodic => {
                (0.0..domain.width).contains(&p.x) && (0.0..domain.height).contains(&p.y)
            }
        };
        if !inside {
            return Err(self.invalid(
                origin,
                &field,
                format!(
                    "at ({}, {}) with radius {radius} does not lie inside the {}×{} box",
                    p.x, p.y, domain.width, domain.height
                ),
                "move it inside [0, w] × [0, h] (the whole disk, with walls) or enlarge scene.size",
            ));
        }
        Ok(Disk {
            x: p.x,
            y: p.y,
            vx: p.vx,
            vy: p.vy,
            radius,
            mass,
        })
    }

    /// Refuses a periodic box too narrow for the disks, and disks that overlap (naming
    /// the later of the first overlapping pair).
    fn refuse_overlaps(
        &self,
        raw: &RawScene,
        domain: &Domain,
        particles: &Particles,
        origins: &[Origin],
    ) -> Result<(), SceneFileError> {
        if check_periodic_box(domain, particles.max_radius()).is_err() {
            return Err(self.invalid(
                self.in_file(&raw.size)
                    .map_or(Origin::Default, |s| s.origin),
                "scene.size",
                format!(
                    "is {}×{}, narrower than 3 contact diameters ({}) of a periodic box",
                    domain.width,
                    domain.height,
                    6.0 * particles.max_radius()
                ),
                "enlarge the box, or use boundary = \"walls\"",
            ));
        }
        let grid = StripGrid::new(domain, particles);
        let mut contacts = Vec::new();
        grid.find_contacts(particles, domain, &mut contacts);
        if let Some(first) = contacts
            .iter()
            .min_by_key(|contact| contact.key(&particles.id))
        {
            // The disk given later in the file is the one to name.
            let (a, b) = (first.a.min(first.b) as usize, first.a.max(first.b) as usize);
            return Err(self.invalid(
                origins[b],
                &format!("scene.particle[{b}]"),
                format!("overlaps scene.particle[{a}]"),
                "move the disks apart: centres must be at least r_a + r_b apart",
            ));
        }
        Ok(())
    }
}

/// The ways to write a discard, for its errors.
const DISCARD_FORMS: &str = "give a simulated time to drop from the start (discard = 200.0), a \
                             share of the run (discard = \"30%\"), or discard = \"auto\" \
                             (MSER-5 finds it)";

/// A discard as written: "auto", a simulated time ≥ 0, or a share of the run under
/// 100% ("30%"); otherwise what is wrong with it.
fn parse_discard(value: NumberOrWord) -> Result<Discard, String> {
    match value {
        NumberOrWord::Word(word) if word == "auto" => Ok(Discard::Automatic),
        NumberOrWord::Number(time) if time >= 0.0 && time.is_finite() => Ok(Discard::Time(time)),
        NumberOrWord::Number(time) => Err(format!("is {time}, not a simulated time ≥ 0")),
        NumberOrWord::Word(word) => {
            let percent = word
                .strip_suffix('%')
                .and_then(|p| p.trim().parse::<f64>().ok());
            match percent {
                Some(percent) if (0.0..100.0).contains(&percent) => {
                    Ok(Discard::Fraction(percent / 100.0))
                }
                Some(percent) if percent >= 100.0 => Err(format!(
                    "is {percent}%, the whole run: nothing is left to average"
                )),
                _ => Err(format!(
                    "is \"{word}\", neither a share of the run nor \"auto\""
                )),
            }
        }
    }
}

/// `discard` when it leaves at least [`MIN_KEPT_BLOCKS`] of the run's blocks of `steps`
/// to average (a time is checked where dt is fixed: with dt = "auto" the summary says
/// when too little is left); otherwise what is wrong and how to fix it.
fn leaves_blocks(discard: Discard, dt: DtChoice, steps: u64) -> Result<Discard, (String, String)> {
    // The latest cut that leaves MIN_KEPT_BLOCKS blocks: the end of the block before
    // them, in steps (block j ends at step ⌈j·steps/blocks⌉).
    let blocks = u128::from(SERIES_BLOCKS.min(steps));
    let kept = MIN_KEPT_BLOCKS as u128;
    let last_cut = match blocks > kept {
        true => ((blocks - kept) * u128::from(steps)).div_ceil(blocks) as f64,
        false => 0.0,
    };
    let leaves_too_little = |what: String, most: String| {
        (
            format!(
                "is {what}, which leaves fewer than {MIN_KEPT_BLOCKS} of the run's {blocks} \
                 blocks ({steps} steps) to average"
            ),
            format!("discard at most {most}, or run longer"),
        )
    };
    let slack = 1.0 + 1e-9;
    match (discard, dt) {
        (Discard::Fraction(fraction), _) if fraction * steps as f64 > last_cut * slack => {
            Err(leaves_too_little(
                format!("{}%", 100.0 * fraction),
                format!("\"{}%\"", (100.0 * last_cut / steps as f64).floor()),
            ))
        }
        (Discard::Time(time), DtChoice::Fixed(dt)) if time >= steps as f64 * dt => Err((
            format!(
                "is t = {time}, past the end of the run at t = {} ({steps} steps of dt = {dt})",
                steps as f64 * dt
            ),
            format!("discard at most {}, or run longer", last_cut * dt),
        )),
        (Discard::Time(time), DtChoice::Fixed(dt)) if time > last_cut * dt * slack => Err(
            leaves_too_little(format!("t = {time}"), format!("{}", last_cut * dt)),
        ),
        _ => Ok(discard),
    }
}

/// 1-based line number of a byte offset (scene files and manifests alike).
pub fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())]
        .bytes()
        .filter(|&b| b == b'\n')
        .count()
        + 1
}
