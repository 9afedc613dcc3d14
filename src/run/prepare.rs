//! From a specification to a run ready to step: [`RunSpec::prepare`] places the disks and
//! resolves the method and time step, through `auto` when either is "auto". Kept apart
//! from `spec` so that the specification's types depend on nothing that chooses.

use crate::run::auto::choose;
use crate::run::spec::{DEFAULT_TC_FRACTION, InitialFigures, PreparedRun, RunSpec, SceneSource};
use crate::sim::event::EventParams;
use crate::sim::observe::potential_energy;
use crate::sim::scene::PlacementError;
use crate::sim::step::StepParams;

impl RunSpec {
    /// Builds the initial disks (placing a random gas) and resolves the method and time
    /// step (running the pilots of `crate::run::auto` when either is "auto").
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
                potential_energy: potential_energy(&scene.particles, scene.physics.gravity),
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
            discard: self.method.discard,
        })
    }
}
