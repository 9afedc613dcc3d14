//! Validated run specifications: what to simulate and how, independent of any file format.
//!
//! `scene_file` turns TOML into a [`RunSpec`]; [`RunSpec::prepare`] builds the initial
//! state and resolves `dt = "auto"`. Nothing here reads files or prints.

use crate::sim::scene::{GasSpec, PlacementError};
use crate::sim::step::{StepParams, auto_dt};
use crate::sim::{Broadphase, Scene};

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
}

/// Default of `dt_fraction`: the fastest disk moves at most a tenth of the smallest radius per step.
pub const DEFAULT_DT_FRACTION: f64 = 0.1;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MethodSpec {
    pub dt: DtChoice,
    /// Number of steps, at least 1.
    pub steps: u64,
    pub broadphase: Broadphase,
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
    pub params: StepParams,
    pub steps: u64,
    /// `Some(fraction)` when dt was chosen automatically.
    pub dt_auto_fraction: Option<f64>,
    pub seed: Option<u64>,
}

impl RunSpec {
    /// Builds the initial disks (placing a random gas) and resolves the time step.
    pub fn prepare(&self) -> Result<PreparedRun, PlacementError> {
        let (scene, seed) = match &self.scene {
            SceneSource::Gas(gas) => (gas.build()?, Some(gas.seed)),
            SceneSource::Explicit(scene) => (scene.clone(), None),
        };
        let (dt, dt_auto_fraction) = match self.method.dt {
            DtChoice::Fixed(dt) => (dt, None),
            DtChoice::Auto { fraction } => (
                auto_dt(&scene.particles, &scene.domain, &scene.physics, fraction),
                Some(fraction),
            ),
        };
        Ok(PreparedRun {
            scene,
            params: StepParams {
                dt,
                broadphase: self.method.broadphase,
            },
            steps: self.method.steps,
            dt_auto_fraction,
            seed,
        })
    }
}
