//! The quantities a run derives from its scene and method, checked before it starts:
//! the box side, the kinetic energy, the step length in radii and the collision time
//! scale must each be finite and within the range where f64 arithmetic keeps the
//! simulation meaningful. Pure; `scene_file` turns a violation into a located message.

use crate::run::spec::{DtChoice, MethodSpec, SceneSource};
use crate::sim::scene::{Extent, MassRule, RadiusDistribution};

/// Most radii a box may span: positions then keep at least 1e-7 of a radius
/// (f64 resolves 2.2e-16 of the box).
pub const MAX_BOX_IN_RADII: f64 = 1e9;
/// Most radii a disk may move in one time step (at the rms speed, or fall under gravity).
pub const MAX_STEP_IN_RADII: f64 = 1e4;
/// Least fraction of the box side a moving disk must travel per step: less is lost to
/// rounding when added to its position.
pub const MIN_STEP_IN_BOX: f64 = 1e-13;

/// The input a violated limit is traced to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Field {
    Radius,
    Size,
    SpeedRms,
    Mass,
    Gravity,
    Dt,
    Particles,
}

/// A derived quantity out of its range: the field it is traced to, what is wrong, and
/// how to fix it.
#[derive(Clone, Debug, PartialEq)]
pub struct Violation {
    pub field: Field,
    pub problem: String,
    pub fix: &'static str,
}

/// What a scene implies before any disk is placed.
struct Derived {
    n: f64,
    box_side: f64,
    box_area: f64,
    min_radius: f64,
    speed_rms: f64,
    /// The smallest disk mass (a gas: its one mass, or the smallest disk's area).
    min_mass: f64,
    kinetic_energy: f64,
    gravity: f64,
    /// Whether the box was given (`size`, or listed disks) or follows from the packing.
    sized: bool,
    listed: bool,
}

fn derive(scene: &SceneSource) -> Derived {
    match scene {
        SceneSource::Gas(gas) => {
            let n = gas.n_particles as f64;
            let (box_side, box_area, sized) = match gas.extent {
                Extent::Packing(packing) => {
                    let area = n * gas.radius.mean_area() / packing;
                    (area.sqrt(), area, false)
                }
                Extent::Size { width, height } => (width.max(height), width * height, true),
            };
            let min_radius = match gas.radius {
                RadiusDistribution::Fixed(r) => r,
                RadiusDistribution::Uniform { min, .. } => min,
            };
            let mean_mass = match gas.mass {
                MassRule::Fixed(m) => m,
                MassRule::Area => gas.radius.mean_area(),
            };
            let min_mass = match gas.mass {
                MassRule::Fixed(m) => m,
                MassRule::Area => std::f64::consts::PI * min_radius * min_radius,
            };
            Derived {
                n,
                min_mass,
                box_side,
                box_area,
                min_radius,
                speed_rms: gas.speed_rms,
                kinetic_energy: 0.5 * n * mean_mass * gas.speed_rms * gas.speed_rms,
                gravity: gas.physics.gravity.map_or(0.0, |[gx, gy]| gx.hypot(gy)),
                sized,
                listed: false,
            }
        }
        SceneSource::Explicit(scene) => {
            let particles = &scene.particles;
            let (width, height) = (scene.domain.width, scene.domain.height);
            Derived {
                n: particles.len() as f64,
                box_side: width.max(height),
                box_area: width * height,
                min_radius: particles.min_radius(),
                speed_rms: particles.rms_speed(),
                min_mass: particles.mass.iter().fold(f64::INFINITY, |a, &m| a.min(m)),
                kinetic_energy: (0..particles.len())
                    .map(|i| {
                        let v2 = particles.vx[i].powi(2) + particles.vy[i].powi(2);
                        0.5 * particles.mass[i] * v2
                    })
                    .sum(),
                gravity: scene.physics.gravity.map_or(0.0, |[gx, gy]| gx.hypot(gy)),
                sized: true,
                listed: true,
            }
        }
    }
}

/// Whether `value` is a number (not NaN or infinite) no larger than `limit`.
fn within(value: f64, limit: f64) -> bool {
    value.is_finite() && value <= limit
}

/// The first derived quantity of `scene` run by `method` that is not finite or out of
/// its range, if any.
pub fn check(scene: &SceneSource, method: &MethodSpec) -> Option<Violation> {
    let d = derive(scene);
    d.box_violation()
        .or_else(|| d.mass_violation())
        .or_else(|| d.energy_violation())
        .or_else(|| d.collision_time_violation())
        .or_else(|| {
            // A chosen dt ("auto") follows from these quantities; a given one is checked.
            let DtChoice::Fixed(dt) = method.dt else {
                return None;
            };
            d.step_violation(dt)
        })
}

fn violation(field: Field, problem: String, fix: &'static str) -> Option<Violation> {
    Some(Violation {
        field,
        problem,
        fix,
    })
}

impl Derived {
    /// The box: finite, positive, and few enough radii across for positions to resolve a disk.
    fn box_violation(&self) -> Option<Violation> {
        let (box_field, box_fix) = match (self.listed, self.sized) {
            (true, _) => (
                Field::Particles,
                "give radii and a box of comparable scales",
            ),
            (false, true) => (Field::Size, "give a box and radii of comparable scales"),
            (false, false) => (
                Field::Radius,
                "give radii of ordinary size, e.g. radius = 1.0 (scale the box through packing)",
            ),
        };
        if !(self.box_area.is_finite() && self.box_area > 0.0 && self.box_side.is_finite()) {
            return violation(
                box_field,
                format!(
                    "makes a box of area {:e}, which is not a finite positive number",
                    self.box_area
                ),
                box_fix,
            );
        }
        let box_in_radii = self.box_side / self.min_radius;
        if !within(box_in_radii, MAX_BOX_IN_RADII) {
            return violation(
                box_field,
                format!(
                    "makes a box {box_in_radii:e} radii across, more than the {MAX_BOX_IN_RADII:e} \
                     within which positions resolve a disk"
                ),
                box_fix,
            );
        }
        None
    }

    /// The lightest disk: a normal f64.
    fn mass_violation(&self) -> Option<Violation> {
        if !self.min_mass.is_normal() {
            let field = if self.listed {
                Field::Particles
            } else {
                Field::Mass
            };
            return violation(
                field,
                format!(
                    "makes a disk of mass {:e}, below the {:e} where f64 keeps its precision",
                    self.min_mass,
                    f64::MIN_POSITIVE
                ),
                "give masses of ordinary size, e.g. mass = 1.0, or mass = \"area\"",
            );
        }
        None
    }

    /// The kinetic energy: finite.
    fn energy_violation(&self) -> Option<Violation> {
        if !self.kinetic_energy.is_finite() {
            let field = match (
                self.listed,
                (self.n * self.speed_rms * self.speed_rms).is_finite(),
            ) {
                (true, _) => Field::Particles,
                (false, true) => Field::Mass,
                (false, false) => Field::SpeedRms,
            };
            return violation(
                field,
                format!(
                    "makes a kinetic energy of {:e}, not a finite number",
                    self.kinetic_energy
                ),
                "give speeds and masses whose ½·n·m·v² is a finite number, e.g. speed_rms = 1.0",
            );
        }
        None
    }

    /// The collision time scale of a moving gas: finite and positive.
    fn collision_time_violation(&self) -> Option<Violation> {
        if self.speed_rms > 0.0 {
            // The time a disk takes to move one radius: the scale of the collision times.
            let collision_time = self.min_radius / self.speed_rms;
            if !(collision_time.is_finite() && collision_time > 0.0) {
                return violation(
                    Field::SpeedRms,
                    format!(
                        "makes the time to move one radius {collision_time:e}, not a finite \
                         positive number"
                    ),
                    "give a speed of the order of radii per unit time, e.g. speed_rms = 1.0",
                );
            }
        }
        None
    }

    /// How far a disk falls and moves in one given step `dt`: far enough to move at all,
    /// not so far that it skips over its neighbours.
    fn step_violation(&self, dt: f64) -> Option<Violation> {
        let fall = 0.5 * self.gravity * dt * dt / self.min_radius;
        if !within(fall, MAX_STEP_IN_RADII) {
            return violation(
                Field::Gravity,
                format!(
                    "makes a disk fall {fall:e} radii in one step of dt = {dt}, more than \
                     {MAX_STEP_IN_RADII:e}"
                ),
                "give a weaker field or a smaller dt",
            );
        }
        let step = self.speed_rms * dt;
        let step_in_radii = step / self.min_radius;
        if !within(step_in_radii, MAX_STEP_IN_RADII) {
            return violation(
                Field::Dt,
                format!(
                    "makes the rms disk move {step_in_radii:e} radii per step, more than \
                     {MAX_STEP_IN_RADII:e}"
                ),
                "give a smaller dt (dt = \"auto\" chooses one), or a lower speed_rms",
            );
        }
        if self.speed_rms > 0.0 && step < MIN_STEP_IN_BOX * self.box_side {
            return violation(
                Field::Dt,
                format!(
                    "makes the rms disk move {:e} of the box per step, less than the {MIN_STEP_IN_BOX:e} \
                     positions resolve: the disks would not move",
                    step / self.box_side
                ),
                "give a larger dt (dt = \"auto\" chooses one), or a higher speed_rms",
            );
        }
        None
    }
}
