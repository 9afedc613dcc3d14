//! `method = "auto"` and `dt = "auto"` under a missed-collision tolerance: the cheapest
//! method and the largest dt whose pilot run misses at most `missed_tolerance` of its
//! collisions. Deterministic: decided from pilot runs of the pure core (`sim::pilot`,
//! fixed length, the scene's own seed) and a stated cost model, never from timings on
//! this machine, so every run and backend makes the same choice. Reads no files.

use std::borrow::Cow;

use crate::sim::Scene;
use crate::sim::event::EventParams;
use crate::sim::pilot::{StepPilot, event_pilot, step_pilot};
use crate::sim::scene::{Extent, PlacementError};
use crate::sim::step::auto_dt;
use crate::spec::{DEFAULT_DT_FRACTION, DtChoice, Method, MethodChoice, MethodSpec, SceneSource};

/// Default of `missed_tolerance`: issue 6's 10⁻³ (also the accuracy study's failure line).
pub const DEFAULT_MISSED_TOLERANCE: f64 = 1e-3;

/// The dt fractions tried, largest first: v_max·dt = f·r_min for f = 4, 2, 1, ½, … 1/128.
const LADDER_TOP: f64 = 4.0;
const LADDER_RUNGS: i32 = 10;

/// Pilot length: the time the fastest disk takes to cross this many smallest radii (64 /
/// f steps at fraction f; about two collisions per disk at packing 0.05).
pub const PILOT_RADII: f64 = 64.0;

/// A pilot never runs more steps than the ladder's last rung needs (64 · 128).
const MAX_PILOT_STEPS: u64 = 8192;

/// Pilots run on at most this many disks: a random gas given by its packing is rebuilt
/// with this many disks (same seed, packing and speeds); other scenes run whole.
pub const PILOT_DISKS: usize = 2000;

/// Cost model, step method: particle-steps per second of one serial step at N = 10⁵,
/// packing 0.05 (README, Speed: `serial/step`, 28.4 M/s).
pub const STEP_PARTICLE_STEPS_PER_S: f64 = 28.4e6;

/// Cost model, event method: pair + wall collisions per second at N = 10⁴, packing 0.05
/// (README, Accuracy: the event bench at load 2.6, 0.53 M/s).
pub const EVENT_EVENTS_PER_S: f64 = 0.53e6;

/// The resolved method and step, and why (`None` when nothing was automatic).
#[derive(Clone, Debug, PartialEq)]
pub struct Choice {
    pub method: Method,
    pub dt: f64,
    /// The f of v_max·dt = f·r_min when dt came from a rule; `None` for a given dt.
    pub dt_auto_fraction: Option<f64>,
    pub reason: Option<String>,
}

/// Resolves `method` and `dt` for `scene` (built from `source`); `event` is the event
/// method's resolved settings, used by its pilot.
pub fn choose(
    source: &SceneSource,
    scene: &Scene,
    spec: &MethodSpec,
    event: EventParams,
) -> Result<Choice, PlacementError> {
    let fraction_dt = |fraction: f64| Choice {
        method: Method::Step,
        dt: auto_dt(&scene.particles, &scene.domain, &scene.physics, fraction),
        dt_auto_fraction: Some(fraction),
        reason: None,
    };
    let plain = match (spec.method, spec.dt) {
        (MethodChoice::Fixed(method), DtChoice::Fixed(dt)) => Some(Choice {
            method,
            dt,
            dt_auto_fraction: None,
            reason: None,
        }),
        (MethodChoice::Fixed(method), DtChoice::Auto { fraction }) => Some(Choice {
            method,
            ..fraction_dt(fraction)
        }),
        (MethodChoice::Fixed(Method::Event), DtChoice::Tolerance) => Some(Choice {
            method: Method::Event,
            reason: Some(format!(
                "dt auto: the event method misses no collisions, so dt is the dt_fraction rule \
                 (v_max·dt = {DEFAULT_DT_FRACTION}·r_min)"
            )),
            ..fraction_dt(DEFAULT_DT_FRACTION)
        }),
        _ => None,
    };
    if let Some(choice) = plain {
        return Ok(choice);
    }
    let pilot_scene = pilot_scene(source, scene)?;
    let pilot_scene = pilot_scene.as_ref();
    let tolerance = spec.missed_tolerance;
    let pilot_time = auto_dt(
        &pilot_scene.particles,
        &pilot_scene.domain,
        &pilot_scene.physics,
        PILOT_RADII,
    );
    // The step method's dt, and its pilot at that dt.
    let (step, pilot, dt_note) = match spec.dt {
        DtChoice::Fixed(dt) => {
            let steps = ((pilot_time / dt).ceil() as u64).clamp(1, MAX_PILOT_STEPS);
            let pilot = step_pilot(pilot_scene, dt, steps, spec.broadphase);
            let choice = Choice {
                method: Method::Step,
                dt,
                dt_auto_fraction: None,
                reason: None,
            };
            (choice, pilot, String::new())
        }
        DtChoice::Auto { fraction } => {
            let choice = fraction_dt(fraction);
            let dt = auto_dt(
                &pilot_scene.particles,
                &pilot_scene.domain,
                &pilot_scene.physics,
                fraction,
            );
            let steps = ((PILOT_RADII / fraction).ceil() as u64).clamp(1, MAX_PILOT_STEPS);
            let pilot = step_pilot(pilot_scene, dt, steps, spec.broadphase);
            (choice, pilot, format!("dt_fraction = {fraction}; "))
        }
        DtChoice::Tolerance => {
            let (fraction, pilot) = largest_passing_fraction(pilot_scene, spec);
            let verdict = if pilot.missed_fraction() <= tolerance {
                "the largest of 4·2^-k (k < 10) within"
            } else {
                "the smallest tried, still above"
            };
            let note = format!("dt auto: v_max·dt = {fraction}·r_min, {verdict} the tolerance; ",);
            (fraction_dt(fraction), pilot, note)
        }
    };
    let pilot_note = format!(
        "pilot ({} disks, {} steps of {:.4e}): {} of {} met pairs missed = {:.2e} against \
         missed_tolerance {tolerance:e}",
        pilot_scene.particles.len(),
        pilot.steps,
        pilot.dt,
        pilot.missed_collisions,
        pilot.missed_collisions + pilot.pair_collisions,
        pilot.missed_fraction(),
    );
    let step_passes = pilot.missed_fraction() <= tolerance;
    if spec.method == MethodChoice::Fixed(Method::Step) {
        return Ok(Choice {
            reason: Some(format!("{dt_note}{pilot_note}")),
            ..step
        });
    }
    // method = "auto" from here.
    if scene.physics.gravity.is_some() {
        return Ok(Choice {
            reason: Some(format!(
                "method auto: step, the only method with gravity (the event method flies \
                 straight lines); {dt_note}{pilot_note}"
            )),
            ..step
        });
    }
    let n = scene.particles.len() as f64;
    let step_cost = n * spec.steps as f64 / STEP_PARTICLE_STEPS_PER_S;
    // Both methods run the same simulated time, steps × dt.
    let sim_time = spec.steps as f64 * step.dt;
    let events = event_pilot(pilot_scene, event, pilot_time) as f64;
    let events_per_disk_time = events / (pilot_scene.particles.len() as f64 * pilot_time);
    let event_cost = events_per_disk_time * n * sim_time / EVENT_EVENTS_PER_S;
    let costs = format!(
        "cost model (step {:.0} M particle-steps/s, event {:.2} M events/s): step {step_cost:.3e} s, \
         event {event_cost:.3e} s ({events} events in the event pilot to t = {pilot_time:.4e})",
        STEP_PARTICLE_STEPS_PER_S / 1e6,
        EVENT_EVENTS_PER_S / 1e6,
    );
    let choice = if step_passes && step_cost <= event_cost {
        Choice {
            reason: Some(format!(
                "method auto: step, within the tolerance and cheaper; {costs}; {dt_note}{pilot_note}"
            )),
            ..step
        }
    } else {
        let why = if step_passes {
            "cheaper"
        } else {
            "the step method misses more than the tolerance"
        };
        Choice {
            method: Method::Event,
            reason: Some(format!(
                "method auto: event, {why}; {costs}; {dt_note}{pilot_note}"
            )),
            ..step
        }
    };
    Ok(choice)
}

/// The largest fraction on the ladder whose pilot misses at most the tolerance, with its
/// pilot; the smallest tried if none does.
fn largest_passing_fraction(scene: &Scene, spec: &MethodSpec) -> (f64, StepPilot) {
    let mut last = None;
    for k in 0..LADDER_RUNGS {
        let fraction = LADDER_TOP * 2f64.powi(-k);
        let dt = auto_dt(&scene.particles, &scene.domain, &scene.physics, fraction);
        let steps = ((PILOT_RADII / fraction).ceil() as u64).clamp(1, MAX_PILOT_STEPS);
        let pilot = step_pilot(scene, dt, steps, spec.broadphase);
        if pilot.missed_fraction() <= spec.missed_tolerance {
            return (fraction, pilot);
        }
        last = Some((fraction, pilot));
    }
    last.expect("the ladder has rungs")
}

/// The scene the pilots run: a random gas given by its packing with more than
/// [`PILOT_DISKS`] disks is rebuilt with that many (same seed and settings).
fn pilot_scene<'a>(
    source: &SceneSource,
    scene: &'a Scene,
) -> Result<Cow<'a, Scene>, PlacementError> {
    match source {
        SceneSource::Gas(gas)
            if gas.n_particles > PILOT_DISKS && matches!(gas.extent, Extent::Packing(_)) =>
        {
            let mut small = *gas;
            small.n_particles = PILOT_DISKS;
            Ok(Cow::Owned(small.build()?))
        }
        _ => Ok(Cow::Borrowed(scene)),
    }
}
