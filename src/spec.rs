//! Validated run specifications: what to simulate and how, independent of any file format.
//!
//! `scene_file` turns TOML into a [`RunSpec`]; [`RunSpec::prepare`] builds the initial
//! state and resolves `dt = "auto"`. Nothing here reads files or prints.

use serde::Deserialize;

pub use crate::auto::DEFAULT_MISSED_TOLERANCE;
use crate::auto::choose;
pub use crate::sim::engine::Method;
use crate::sim::event::EventParams;
use crate::sim::scene::{GasSpec, PlacementError};
use crate::sim::step::StepParams;
use crate::sim::{Broadphase, Particles, Scene};

/// Where the disks come from.
#[derive(Clone, Debug, PartialEq)]
pub enum SceneSource {
    /// A seeded random gas.
    Gas(GasSpec),
    /// Disks listed one by one, already checked to fit the box without overlapping.
    Explicit(Scene),
}

/// How the time step is chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DtChoice {
    Fixed(f64),
    /// The largest dt with v_max·dt ≤ `fraction`·r_min.
    Auto {
        fraction: f64,
    },
    /// The largest dt whose pilot misses at most `missed_tolerance` of its collisions
    /// (`dt = "auto"` without `dt_fraction`; see `crate::auto`).
    Tolerance,
}

/// The method as asked for: one of them, or the cheapest within the tolerance.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(try_from = "String")]
pub enum MethodChoice {
    Fixed(Method),
    /// `method = "auto"`: chosen by `crate::auto::choose`.
    Auto,
}

impl MethodChoice {
    pub fn name(self) -> &'static str {
        match self {
            MethodChoice::Fixed(method) => method.name(),
            MethodChoice::Auto => "auto",
        }
    }

    /// The event method (serial backend only) is or may be chosen.
    pub fn may_be_event(self) -> bool {
        self != MethodChoice::Fixed(Method::Step)
    }
}

impl std::str::FromStr for MethodChoice {
    type Err = String;

    fn from_str(text: &str) -> Result<MethodChoice, String> {
        match text {
            "step" => Ok(MethodChoice::Fixed(Method::Step)),
            "event" => Ok(MethodChoice::Fixed(Method::Event)),
            "auto" => Ok(MethodChoice::Auto),
            _ => Err(format!("expected step, event or auto, got \"{text}\"")),
        }
    }
}

impl TryFrom<String> for MethodChoice {
    type Error = String;

    fn try_from(text: String) -> Result<MethodChoice, String> {
        text.parse()
    }
}

/// Default of `dt_fraction`: the fastest disk moves at most a tenth of the smallest radius per step.
pub const DEFAULT_DT_FRACTION: f64 = 0.1;

/// Default TC model time of the event method, in units of r_min / v_rms (the time the
/// rms disk takes to cross its radius): far below a mean free time at any packing.
pub const DEFAULT_TC_FRACTION: f64 = 1e-4;

/// What a run measures besides time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Observe {
    /// Only what costs nothing in the timed loop.
    #[default]
    Timing,
    /// Also the exact missed-collision count of the step method (a swept pair test
    /// every step, excluded from `wall_s`).
    Accuracy,
}

impl Observe {
    pub fn name(self) -> &'static str {
        match self {
            Observe::Timing => "timing",
            Observe::Accuracy => "accuracy",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MethodSpec {
    pub dt: DtChoice,
    /// Number of steps, at least 1.
    pub steps: u64,
    pub broadphase: Broadphase,
    pub method: MethodChoice,
    /// Largest missed-collision fraction `method = "auto"` and `dt = "auto"` accept, in (0, 1).
    pub missed_tolerance: f64,
    /// TC model time of the event method (≥ 0); `None`: [`DEFAULT_TC_FRACTION`] of r_min / v_rms.
    pub tc: Option<f64>,
    pub observe: Observe,
}

impl MethodSpec {
    /// `steps` time steps of `dt` with the given broad phase: the default method, timing only.
    pub fn stepped(dt: f64, steps: u64, broadphase: Broadphase) -> MethodSpec {
        MethodSpec {
            dt: DtChoice::Fixed(dt),
            steps,
            broadphase,
            method: MethodChoice::Fixed(Method::Step),
            missed_tolerance: DEFAULT_MISSED_TOLERANCE,
            tc: None,
            observe: Observe::Timing,
        }
    }
}

/// A complete, valid description of one run.
#[derive(Clone, Debug, PartialEq)]
pub struct RunSpec {
    pub scene: SceneSource,
    pub method: MethodSpec,
    /// Extra work added to every step, to test `collide check` against a known
    /// slowdown; [`InjectedSlowdown::NONE`] in every real run.
    pub slowdown: InjectedSlowdown,
}

/// Busy work added after every step, as a fraction of that step's own wall time (0.25:
/// each step takes 25% longer). It changes timings only, never the disks.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct InjectedSlowdown {
    fraction: f64,
}

impl InjectedSlowdown {
    pub const NONE: InjectedSlowdown = InjectedSlowdown { fraction: 0.0 };

    /// A slowdown of `fraction` (finite, 0 or more), or `None`.
    pub fn new(fraction: f64) -> Option<InjectedSlowdown> {
        (fraction.is_finite() && fraction >= 0.0).then_some(InjectedSlowdown { fraction })
    }

    pub fn fraction(self) -> f64 {
        self.fraction
    }
}

/// A run ready to step: the initial state and the resolved method.
#[derive(Clone, Debug, PartialEq)]
pub struct PreparedRun {
    pub scene: Scene,
    /// Figures of the initial disks, kept apart so that a backend may take the disks
    /// out of `scene` instead of copying them.
    pub initial: InitialFigures,
    pub params: StepParams,
    pub steps: u64,
    /// `Some(fraction)` when dt was chosen automatically.
    pub dt_auto_fraction: Option<f64>,
    /// What `method = "auto"` or `dt = "auto"` chose and why; `None` when nothing was.
    pub choice: Option<String>,
    pub seed: Option<u64>,
    pub method: Method,
    /// The event method's settings (its TC time resolved); unused by the step method.
    pub event: EventParams,
    pub observe: Observe,
}

/// What a run's summary needs to know of its initial disks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InitialFigures {
    /// Area fraction covered by disks.
    pub packing: f64,
    pub rms_speed: f64,
    pub min_radius: f64,
}

impl PreparedRun {
    /// Moves the initial disks out of the scene (leaving it empty), so that a run steps
    /// them without keeping a copy: at 10⁸ disks a copy costs 5 GB.
    pub fn take_particles(&mut self) -> Particles {
        std::mem::take(&mut self.scene.particles)
    }
}

impl RunSpec {
    /// Builds the initial disks (placing a random gas) and resolves the method and time
    /// step (running the pilots of `crate::auto` when either is "auto").
    pub fn prepare(&self) -> Result<PreparedRun, PlacementError> {
        let (scene, seed) = match &self.scene {
            SceneSource::Gas(gas) => (gas.build()?, Some(gas.seed)),
            SceneSource::Explicit(scene) => (scene.clone(), None),
        };
        let tc = self.method.tc.unwrap_or_else(|| {
            let rms = scene.particles.rms_speed();
            let speed = if rms > 0.0 { rms } else { 1.0 };
            DEFAULT_TC_FRACTION * scene.particles.min_radius() / speed
        });
        let event = EventParams { tc };
        let choice = choose(&self.scene, &scene, &self.method, event)?;
        Ok(PreparedRun {
            initial: InitialFigures {
                packing: scene.packing(),
                rms_speed: scene.particles.rms_speed(),
                min_radius: scene.particles.min_radius(),
            },
            scene,
            params: StepParams {
                dt: choice.dt,
                broadphase: self.method.broadphase,
            },
            steps: self.method.steps,
            dt_auto_fraction: choice.dt_auto_fraction,
            choice: choice.reason,
            seed,
            method: choice.method,
            event,
            observe: self.method.observe,
        })
    }
}
