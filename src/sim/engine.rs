//! Either method behind one call: advance the disks by one observation interval dt.
//! For callers that only want the states (pictures); the serial backend times the
//! step method stage by stage and drives the two methods itself.

use serde::Deserialize;

use super::event::{EventParams, EventSim};
use super::particles::Particles;
use super::scene::Scene;
use super::step::{StepParams, Stepper};

/// How the disks are moved.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Time steps of dt with overlap detection and resolution (the seed's method).
    #[default]
    Step,
    /// The exact event-driven reference (`sim::event`); `steps × dt` is the simulated time.
    Event,
}

impl Method {
    pub fn name(self) -> &'static str {
        match self {
            Method::Step => "step",
            Method::Event => "event",
        }
    }
}

/// A running simulation of either method.
#[derive(Clone, Debug)]
pub enum Engine {
    Step(Box<Stepper>),
    Event {
        sim: Box<EventSim>,
        dt: f64,
        /// Intervals of dt done so far: the time is `done · dt`, never a running sum.
        done: u64,
    },
}

impl Engine {
    pub fn new(scene: &Scene, method: Method, params: StepParams, event: EventParams) -> Engine {
        match method {
            Method::Step => Engine::Step(Box::new(Stepper::for_scene(scene, params))),
            Method::Event => Engine::Event {
                sim: Box::new(EventSim::new(
                    scene.domain,
                    scene.physics,
                    event,
                    &scene.particles,
                )),
                dt: params.dt,
                done: 0,
            },
        }
    }

    /// One step of dt, or every event of the next interval of dt.
    pub fn step(&mut self, particles: &mut Particles) {
        match self {
            Engine::Step(stepper) => stepper.step(particles),
            Engine::Event { sim, dt, done } => {
                *done += 1;
                sim.advance_to(particles, *done as f64 * *dt);
            }
        }
    }
}
