//! The serial backend: the reference implementation every parallel backend must match.

use std::time::Instant;

use crate::backend::{
    BackendError, CpuScope, Measured, RunOutcome, StageSeconds, Workers, step_loop, summarize,
    timed,
};
use crate::sim::Stepper;
use crate::sim::observe::observe;
use crate::spec::RunSpec;

/// Builds the scene, steps it on one thread, and measures the run stage by stage.
pub fn run(spec: &RunSpec) -> Result<RunOutcome, BackendError> {
    let setup_start = Instant::now();
    let prepared = spec.prepare()?;
    let mut particles = prepared.scene.particles.clone();
    let mut stepper = Stepper::for_scene(&prepared.scene, prepared.params);
    let setup_s = setup_start.elapsed().as_secs_f64();
    let initial = observe(&particles);

    let mut stages = StageSeconds::default();
    let seconds = step_loop(prepared.steps, spec.slowdown, CpuScope::Thread, || {
        timed(&mut stages.integration, || stepper.advance(&mut particles));
        timed(&mut stages.broad_phase, || {
            stepper.find_contacts(&mut particles)
        });
        timed(&mut stages.collisions, || {
            stepper.resolve_contacts(&mut particles)
        });
    });

    let measured = Measured {
        setup_s,
        wall_s: seconds.wall,
        cpu_s: seconds.cpu,
        stages,
        counters: stepper.counters(),
        initial,
    };
    let workers = Workers {
        backend: "serial",
        threads: 1,
        ranks: 1,
    };
    let summary = summarize(&prepared, workers, &measured, &particles);
    Ok(RunOutcome {
        summary,
        final_state: particles,
    })
}
