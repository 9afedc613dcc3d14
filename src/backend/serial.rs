//! The serial backend: the reference implementation every parallel backend must match.

use std::time::Instant;

use crate::backend::RunOutcome;
use crate::sim::Stepper;
use crate::sim::observe::{observe, state_hash};
use crate::sim::scene::PlacementError;
use crate::spec::RunSpec;
use crate::summary::RunSummary;

/// Builds the scene, steps it `steps` times on one thread, and measures the run.
pub fn run(spec: &RunSpec) -> Result<RunOutcome, PlacementError> {
    let setup_start = Instant::now();
    let prepared = spec.prepare()?;
    let mut particles = prepared.scene.particles.clone();
    let mut stepper = Stepper::for_scene(&prepared.scene, prepared.params);
    let setup_s = setup_start.elapsed().as_secs_f64();
    let initial = observe(&particles);

    let loop_start = Instant::now();
    for _ in 0..prepared.steps {
        stepper.step(&mut particles);
    }
    let wall_s = loop_start.elapsed().as_secs_f64();

    let last = observe(&particles);
    let counters = stepper.counters();
    let n = particles.len();
    let summary = RunSummary {
        n,
        steps: prepared.steps,
        dt: prepared.params.dt,
        dt_auto_fraction: prepared.dt_auto_fraction,
        backend: "serial".to_owned(),
        workers: 1,
        boundary: prepared.scene.domain.boundary.name().to_owned(),
        broadphase: prepared.params.broadphase.name().to_owned(),
        packing: prepared.scene.packing(),
        seed: prepared.seed,
        wall_s,
        setup_s,
        fps: prepared.steps as f64 / wall_s,
        particle_steps_per_s: (n as f64 * prepared.steps as f64) / wall_s,
        kinetic_energy_initial: initial.kinetic_energy,
        kinetic_energy_final: last.kinetic_energy,
        momentum_initial: initial.momentum,
        momentum_final: last.momentum,
        pair_collisions: counters.pair_collisions,
        wall_collisions: counters.wall_collisions,
        max_overlap: counters.max_overlap,
        state_hash: state_hash(&particles),
    };
    Ok(RunOutcome {
        summary,
        final_state: particles,
    })
}
