//! From a specification to a run ready to step: [`RunSpec::prepare`] places the disks and
//! resolves the method and time step, through `auto` when either is "auto". Kept apart
//! from `spec` so that the specification's types depend on nothing that chooses.

use crate::run::auto::{choose, needs_pilots};
use crate::run::spec::{DEFAULT_TC_FRACTION, InitialFigures, PreparedRun, RunSpec, SceneSource};
use crate::sim::Scene;
use crate::sim::event::EventParams;
use crate::sim::observe::SceneSums;
use crate::sim::scene::PlacementError;
use crate::sim::step::StepParams;

impl RunSpec {
    /// Builds the initial disks (placing a random gas) and resolves the method and time
    /// step (running the pilots of `crate::run::auto` when either is "auto").
    pub fn prepare(&self) -> Result<PreparedRun, PlacementError> {
        let scene = match &self.scene {
            SceneSource::Gas(gas) => gas.build()?,
            SceneSource::Explicit(scene) => scene.clone(),
        };
        let whole = SceneSums::of(&scene.particles, scene.physics.gravity);
        self.prepare_from(scene, &whole)
    }

    /// Whether ranks may each build only their part of the scene
    /// ([`RunSpec::prepare_from`]): a seeded gas (placed band by band), whose method
    /// and dt need no pilot on the whole scene.
    pub fn may_prepare_in_parts(&self) -> bool {
        matches!(self.scene, SceneSource::Gas(_)) && !needs_pilots(&self.method)
    }

    /// [`RunSpec::prepare`] from a built `scene` and the sums over the whole scene's
    /// disks: `scene` may hold only some of them (a rank's) when
    /// [`RunSpec::may_prepare_in_parts`].
    pub fn prepare_from(
        &self,
        scene: Scene,
        whole: &SceneSums,
    ) -> Result<PreparedRun, PlacementError> {
        let figures = whole.figures();
        let tc = self.method.tc.unwrap_or_else(|| {
            let rms = whole.rms_speed();
            let speed = if rms > 0.0 { rms } else { 1.0 };
            DEFAULT_TC_FRACTION * figures.min_radius / speed
        });
        let event = EventParams { tc };
        let choice = choose(&self.scene, &scene, &figures, &self.method, event)?;
        let seed = match &self.scene {
            SceneSource::Gas(gas) => Some(gas.seed),
            SceneSource::Explicit(_) => None,
        };
        Ok(PreparedRun {
            initial: InitialFigures {
                packing: figures.disk_area / scene.domain.area(),
                rms_speed: whole.rms_speed(),
                min_radius: figures.min_radius,
                potential_energy: whole.state.potential_energy(),
                observables: whole.state.observables(),
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
