//! Short pilot runs that measure what a method would do with a scene: the step method's
//! exact missed-collision count at a given dt, and the event method's number of
//! events. Pure and deterministic (a function of the scene only, never of timings), so
//! that `method = "auto"` and `dt = "auto"` choose the same on every run and backend.
//! What to do with the measurements (tolerance, cost model) is `crate::run::auto`'s business.

use super::event::{EventParams, EventSim};
use super::observe::MissedCollisions;
use super::scene::Scene;
use super::step::{Broadphase, StepParams, Stepper};

/// What a pilot of the step method saw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepPilot {
    pub dt: f64,
    pub steps: u64,
    pub pair_collisions: u64,
    pub missed_collisions: u64,
}

impl StepPilot {
    /// missed / (missed + resolved); 0 when the pilot met no pair at all.
    pub fn missed_fraction(&self) -> f64 {
        let met = self.missed_collisions + self.pair_collisions;
        if met == 0 {
            0.0
        } else {
            self.missed_collisions as f64 / met as f64
        }
    }
}

/// Runs the step method from the scene's initial state for `steps` steps of `dt`,
/// counting missed collisions exactly (`MissedCollisions`, the same observer as
/// `observe = "accuracy"`).
pub fn step_pilot(scene: &Scene, dt: f64, steps: u64, broadphase: Broadphase) -> StepPilot {
    let mut particles = scene.particles.clone();
    let mut stepper = Stepper::for_scene(scene, StepParams { dt, broadphase });
    let mut missed = MissedCollisions::default();
    for _ in 0..steps {
        missed.before_step(&particles, &scene.domain, dt);
        stepper.advance(&mut particles);
        stepper.find_contacts(&mut particles);
        stepper.resolve_contacts_noting(&mut particles, |key| missed.resolved(key));
        missed.after_step();
    }
    StepPilot {
        dt,
        steps,
        pair_collisions: stepper.counters().pair_collisions,
        missed_collisions: missed.missed,
    }
}

/// What an exact event-driven pilot saw: its pair and wall collisions (the events the
/// event method's cost is counted in), and when it collapsed, if it did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EventPilot {
    pub collisions: u64,
    pub collapse_time: Option<f64>,
}

/// The exact event-driven run from the scene's initial state to time `t_end` (or to its
/// collapse). The scene must have no gravity (the event method refuses it).
pub fn event_pilot(scene: &Scene, event: EventParams, t_end: f64) -> EventPilot {
    let mut particles = scene.particles.clone();
    let mut sim = EventSim::new(scene.domain, scene.physics, event, &particles);
    sim.advance_to(&mut particles, t_end);
    let counters = sim.counters();
    EventPilot {
        collisions: counters.pair_collisions + counters.wall_collisions,
        collapse_time: sim.collapse_time(),
    }
}
