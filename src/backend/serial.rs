//! The serial backend: the reference implementation every parallel backend must match,
//! and the only one that runs the event-driven method and the accuracy observers.

use std::ops::ControlFlow;
use std::time::Instant;

use crate::backend::{
    Accuracy, BackendError, Collapse, CpuScope, Measured, RunOutcome, StageSeconds, Workers,
    is_curve_sample, step_loop, summarize, timed,
};
use crate::draw::offscreen::{Offscreen, draw_step};
use crate::run::backend_kind::BackendKind;
use crate::run::spec::{Method, Observe, PreparedRun, RunSpec};
use crate::sim::Stepper;
use crate::sim::event::EventSim;
use crate::sim::observe::{MissedCollisions, SeriesRecorder, StateSums, block_end, temperature};
use crate::sim::{Particles, Physics, StepCounters};
use crate::system::machine::LoopSeconds;

/// Builds the scene, runs it on one thread with its method, and measures the run
/// stage by stage. Observing (the temperature curve, missed collisions) and drawing
/// (`draw = true`) are timed apart and left out of `wall_s`.
pub fn run(spec: &RunSpec) -> Result<RunOutcome, BackendError> {
    let setup_start = Instant::now();
    let mut prepared = spec.prepare()?;
    let mut particles = prepared.take_particles();
    let initial = prepared.initial.observables;
    let mut curve = Curve::new(&particles, initial.kinetic_energy, &prepared.scene.physics);
    let mut offscreen = Offscreen::when(spec.method.draw, &prepared.scene.domain, &particles);
    let mut stages = StageSeconds::default();
    let (setup_s, seconds, counters, mut accuracy) = match prepared.method {
        Method::Step => step_method(
            spec,
            &prepared,
            setup_start,
            &mut particles,
            &mut curve,
            &mut offscreen,
            &mut stages,
        ),
        Method::Event => event_method(
            spec,
            &prepared,
            setup_start,
            &mut particles,
            &mut curve,
            &mut offscreen,
            &mut stages,
        ),
    };
    // Observing and drawing are single-threaded work inside the loop: out of both clocks.
    let draw_s = offscreen.map(|offscreen| offscreen.seconds);
    let apart = curve.seconds + draw_s.unwrap_or(0.0);
    let wall_s = seconds.wall - apart;
    let cpu_s = seconds.cpu.map(|cpu| cpu - apart);
    accuracy.temperature_curve = curve.points;
    accuracy.series = Some(curve.series.blocks());
    let measured = Measured {
        setup_s,
        wall_s,
        cpu_s,
        stages,
        counters,
        initial,
        accuracy,
        draw_s,
        traffic: None,
        balance: None,
    };
    let workers = Workers {
        backend: BackendKind::Serial,
        threads: 1,
        ranks: 1,
    };
    let last = StateSums::all(&particles, prepared.scene.physics.gravity);
    let summary = summarize(&prepared, workers, &measured, &last);
    Ok(RunOutcome {
        summary,
        final_state: Some(particles),
    })
}

/// The step method from its lists to its last step; returns the set-up seconds, the
/// loop's seconds, the counters and the missed collisions.
fn step_method(
    spec: &RunSpec,
    prepared: &PreparedRun,
    setup_start: Instant,
    particles: &mut Particles,
    curve: &mut Curve,
    offscreen: &mut Option<Offscreen>,
    stages: &mut StageSeconds,
) -> (f64, LoopSeconds, StepCounters, Accuracy) {
    let scene = &prepared.scene;
    let mut stepper = Stepper::new(scene.domain, scene.physics, prepared.params, particles);
    stepper.build_lists(particles);
    let setup_s = setup_start.elapsed().as_secs_f64();
    let mut missed = (prepared.observe == Observe::Accuracy).then(MissedCollisions::default);
    let (domain, dt) = (prepared.scene.domain, prepared.params.dt);
    let seconds = step_loop(prepared.steps, spec.slowdown, CpuScope::Thread, |step| {
        if let Some(missed) = missed.as_mut() {
            timed(&mut curve.seconds, || {
                missed.before_step(particles, &domain, dt)
            });
        }
        timed(&mut stages.integration, || stepper.advance(particles));
        timed(&mut stages.broad_phase, || stepper.find_contacts(particles));
        match missed.as_mut() {
            None => timed(&mut stages.collisions, || {
                stepper.resolve_contacts(particles)
            }),
            Some(missed) => {
                timed(&mut stages.collisions, || {
                    stepper.resolve_contacts_noting(particles, |key| missed.resolved(key))
                });
                timed(&mut curve.seconds, || missed.after_step());
            }
        }
        curve.sample(prepared, step, particles);
        curve.close_block(prepared, step, &stepper.counters(), particles);
        draw_step(offscreen, particles);
        ControlFlow::Continue(())
    });
    let accuracy = Accuracy {
        missed_collisions: missed.map(|m| m.missed),
        ..Accuracy::default()
    };
    (setup_s, seconds, stepper.counters(), accuracy)
}

/// The event method from its first prediction to its last interval or a detected
/// collapse; returns the set-up seconds, the loop's seconds, the counters, the TC guard
/// and the collapse.
fn event_method(
    spec: &RunSpec,
    prepared: &PreparedRun,
    setup_start: Instant,
    particles: &mut Particles,
    curve: &mut Curve,
    offscreen: &mut Option<Offscreen>,
    stages: &mut StageSeconds,
) -> (f64, LoopSeconds, StepCounters, Accuracy) {
    let scene = &prepared.scene;
    let mut sim = EventSim::new(scene.domain, scene.physics, prepared.event, particles);
    let setup_s = setup_start.elapsed().as_secs_f64();
    let mut collapse = None;
    let seconds = step_loop(prepared.steps, spec.slowdown, CpuScope::Thread, |step| {
        // The time of interval k is k·dt, not a running sum.
        timed(&mut stages.collisions, || {
            sim.advance_to(particles, step as f64 * prepared.params.dt)
        });
        draw_step(offscreen, particles);
        match sim.collapse_time() {
            // The run ends where the method broke down; so does its curve.
            Some(time) => {
                curve.push(time, particles);
                curve.close_block_at(time, &sim.counters(), particles);
                collapse = Some(Collapse { time, steps: step });
                ControlFlow::Break(())
            }
            None => {
                curve.sample(prepared, step, particles);
                curve.close_block(prepared, step, &sim.counters(), particles);
                ControlFlow::Continue(())
            }
        }
    });
    let accuracy = Accuracy {
        collapse_guard: Some((sim.collapse_guard_fired(), prepared.event.tc)),
        collapse,
        ..Accuracy::default()
    };
    (setup_s, seconds, sim.counters(), accuracy)
}

/// The temperature curve [t, kinetic energy per disk], the observables' block series,
/// and the seconds spent observing.
struct Curve {
    /// `None` in an elastic scene, whose temperature stays where it started: a point
    /// reads every disk (at 10⁶ disks and 50 steps, 40 points took a fifth of the run).
    points: Option<Vec<[f64; 2]>>,
    series: SeriesRecorder,
    seconds: f64,
}

impl Curve {
    /// Starts the curve and the series at t = 0, with the state's `kinetic_energy`.
    fn new(particles: &Particles, kinetic_energy: f64, physics: &Physics) -> Curve {
        let temperature = kinetic_energy / particles.len().max(1) as f64;
        Curve {
            points: (!physics.is_elastic()).then(|| vec![[0.0, temperature]]),
            series: SeriesRecorder::new(kinetic_energy, physics),
            seconds: 0.0,
        }
    }

    /// Closes a block of the series after `step` if it ends one.
    fn close_block(
        &mut self,
        prepared: &PreparedRun,
        step: u64,
        counters: &StepCounters,
        particles: &Particles,
    ) {
        if let Some(time) = block_end(step, prepared.steps, prepared.params.dt) {
            self.close_block_at(time, counters, particles);
        }
    }

    /// Closes a block of the series at `time`.
    fn close_block_at(&mut self, time: f64, counters: &StepCounters, particles: &Particles) {
        timed(&mut self.seconds, || {
            self.series.close_block(time, counters, particles)
        });
    }

    /// Records a point after `step` if it is one of the sampled steps.
    fn sample(&mut self, prepared: &PreparedRun, step: u64, particles: &Particles) {
        if is_curve_sample(step, prepared.steps) {
            self.push(step as f64 * prepared.params.dt, particles);
        }
    }

    /// Records the point [time, T].
    fn push(&mut self, time: f64, particles: &Particles) {
        if let Some(points) = &mut self.points {
            timed(&mut self.seconds, || {
                points.push([time, temperature(particles)]);
            });
        }
    }
}
