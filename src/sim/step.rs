//! One time step of the seed's method, composed from integration, boundary, broad phase
//! and contact resolution. Cannot fail, does no I/O.
//!
//! Determinism rule: contacts are resolved one after another in the canonical order of
//! their id pairs (`Contact::key`). Two contacts that share no disk commute exactly, so
//! any schedule that keeps this order within each chain of contacts sharing disks gives
//! the same bits; that is what lets parallel backends reproduce this serial reference.

use serde::{Deserialize, Serialize};

use super::collision::ContactOutcome;
use super::grid::{Contact, StripGrid, find_contacts_all_pairs};
use super::particles::{DiskSlices, Particles};
use super::resolve::resolve_contacts;
use super::scene::{Boundary, Domain, Physics, Scene, wrap_periodic};

/// Grid builds between re-storings of the disks in grid order.
pub const REORDER_INTERVAL: u32 = 16;

/// Where the count of builds starts: the first build (a sort from scratch) re-stores the
/// disks too, since a new scene is stored in placement order, which is random in space.
pub const FIRST_BUILDS_SINCE_REORDER: u32 = REORDER_INTERVAL - 1;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Broadphase {
    /// Cell list, O(N) per step.
    #[default]
    Grid,
    /// Every pair, O(N²) per step: the seed report's algorithm, kept for comparison.
    AllPairs,
}

impl Broadphase {
    pub fn name(self) -> &'static str {
        match self {
            Broadphase::Grid => "grid",
            Broadphase::AllPairs => "allpairs",
        }
    }
}

/// Settings of the time-stepped method.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepParams {
    /// Time step, positive and finite.
    pub dt: f64,
    pub broadphase: Broadphase,
}

/// Running totals of what the steps did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepCounters {
    /// Pair impulses applied (overlapping and approaching pairs).
    pub pair_collisions: u64,
    /// Wall reflections applied (a disk touching a wall and moving outward).
    pub wall_collisions: u64,
    /// Largest overlap seen, as a fraction of the pair's contact distance.
    pub max_overlap: f64,
    /// Largest penetration of a disk into a wall seen after a move, as a fraction of
    /// its radius (0 with periodic boundaries).
    pub max_wall_penetration: f64,
    /// Σ overlap fraction over the pairs that received an impulse (for the mean overlap).
    pub overlap_sum: f64,
    /// Σ d·J over the impulses applied: the collision virial (for the pressure).
    pub virial: f64,
}

/// Advances a set of disks in time. Holds scratch memory only; the caller owns the disks.
#[derive(Clone, Debug)]
pub struct Stepper {
    domain: Domain,
    physics: Physics,
    params: StepParams,
    grid: StripGrid,
    /// Grid builds since the disks were last stored in sorted order.
    builds_since_reorder: u32,
    contacts: Vec<Contact>,
    counters: StepCounters,
}

impl Stepper {
    pub fn new(
        domain: Domain,
        physics: Physics,
        params: StepParams,
        particles: &Particles,
    ) -> Self {
        Stepper {
            domain,
            physics,
            params,
            grid: StripGrid::new(&domain, particles.max_radius(), particles.len()),
            builds_since_reorder: FIRST_BUILDS_SINCE_REORDER,
            contacts: Vec::new(),
            counters: StepCounters::default(),
        }
    }

    /// A stepper for the disks of `scene`.
    pub fn for_scene(scene: &Scene, params: StepParams) -> Self {
        Stepper::new(scene.domain, scene.physics, params, &scene.particles)
    }

    pub fn counters(&self) -> StepCounters {
        self.counters
    }

    /// One full step: move, apply the boundary, find overlaps, resolve them.
    pub fn step(&mut self, particles: &mut Particles) {
        self.advance(particles);
        self.find_contacts(particles);
        self.resolve_contacts(particles);
    }

    /// Moves every disk by one dt and applies the boundary ([`advance_disks`]).
    pub fn advance(&mut self, particles: &mut Particles) {
        let walls = advance_disks(
            &self.domain,
            &self.physics,
            self.params.dt,
            particles.disk_slices_mut(),
        );
        self.counters.merge(&walls);
    }

    /// Finds every overlapping pair and puts them in canonical order. May change the
    /// storage order of the disks (never their ids or values).
    pub fn find_contacts(&mut self, particles: &mut Particles) {
        self.contacts.clear();
        match self.params.broadphase {
            Broadphase::Grid => {
                self.grid.build(particles);
                self.builds_since_reorder += 1;
                if self.builds_since_reorder >= REORDER_INTERVAL {
                    // Storing disks in grid order keeps the next builds' reads sequential.
                    // Results do not change: pair order and sums go by id, not storage.
                    particles.reorder(&self.grid.sorted_indices());
                    self.grid.storage_now_sorted();
                    self.builds_since_reorder = 0;
                }
                self.grid
                    .find_contacts(particles, &self.domain, &mut self.contacts);
            }
            Broadphase::AllPairs => {
                find_contacts_all_pairs(particles, &self.domain, &mut self.contacts);
            }
        }
        // Canonical order: the result of resolution must not depend on how pairs were found.
        self.contacts.sort_unstable_by_key(|contact| contact.key);
    }

    /// Resolves the found pairs ([`resolve_contacts`]).
    pub fn resolve_contacts(&mut self, particles: &mut Particles) {
        self.resolve_contacts_noting(particles, |_| {});
    }

    /// [`Stepper::resolve_contacts`], calling `collided` with the key
    /// ([`Contact::key`]) of every pair that received an impulse of the first pass: the
    /// accuracy observer (`sim::observe::MissedCollisions`) compares them with the pairs
    /// that met.
    pub fn resolve_contacts_noting(
        &mut self,
        particles: &mut Particles,
        collided: impl FnMut(u64),
    ) {
        resolve_contacts(
            particles,
            &self.domain,
            &self.physics,
            self.params.dt,
            &self.contacts,
            &mut self.counters,
            collided,
        );
    }
}

impl StepCounters {
    /// Counts one resolved pair.
    #[inline(always)]
    pub fn record(&mut self, outcome: ContactOutcome) {
        self.pair_collisions += u64::from(outcome.collided);
        self.max_overlap = self.max_overlap.max(outcome.overlap_fraction);
        if outcome.collided {
            self.overlap_sum += outcome.overlap_fraction;
        }
        self.virial += outcome.virial;
    }

    /// Adds the counts of another worker's steps.
    pub fn merge(&mut self, other: &StepCounters) {
        self.pair_collisions += other.pair_collisions;
        self.wall_collisions += other.wall_collisions;
        self.max_overlap = self.max_overlap.max(other.max_overlap);
        self.max_wall_penetration = self.max_wall_penetration.max(other.max_wall_penetration);
        self.overlap_sum += other.overlap_sum;
        self.virial += other.virial;
    }
}

/// The per-disk half of a step for any chunk of disks: move them by one dt (the
/// seed's equations 8–9, x += v·dt, without a field; velocity Verlet, equations 6–7,
/// with a constant one), then reflect those that touch a wall while moving outward, or
/// wrap periodic ones. No disk's update reads another's, so chunks can go in any order
/// or in parallel. Returns what the walls saw: the reflections and the deepest
/// penetration (the other counters are zero).
pub fn advance_disks(
    domain: &Domain,
    physics: &Physics,
    dt: f64,
    disks: DiskSlices<'_>,
) -> StepCounters {
    let DiskSlices {
        x,
        y,
        vx,
        vy,
        radius,
    } = disks;
    match physics.gravity {
        None => {
            drift(x, vx, dt);
            drift(y, vy, dt);
        }
        Some([gx, gy]) => {
            accelerate(x, vx, gx, dt);
            accelerate(y, vy, gy, dt);
        }
    }
    match domain.boundary {
        Boundary::Periodic => {
            for x in x.iter_mut() {
                *x = wrap_periodic(*x, domain.width);
            }
            for y in y.iter_mut() {
                *y = wrap_periodic(*y, domain.height);
            }
            StepCounters::default()
        }
        Boundary::Walls => {
            let e = physics.wall_restitution;
            let mut walls = reflect_at_walls(x, vx, radius, domain.width, e);
            walls.merge(&reflect_at_walls(y, vy, radius, domain.height, e));
            walls
        }
    }
}

fn drift(positions: &mut [f64], velocities: &[f64], dt: f64) {
    for (p, v) in positions.iter_mut().zip(velocities) {
        *p += v * dt;
    }
}

fn accelerate(positions: &mut [f64], velocities: &mut [f64], acceleration: f64, dt: f64) {
    let half_a_dt2 = 0.5 * acceleration * dt * dt;
    let a_dt = acceleration * dt;
    for (p, v) in positions.iter_mut().zip(velocities) {
        *p += *v * dt + half_a_dt2;
        *v += a_dt;
    }
}

/// Reflects, along one axis, the disks that touch the wall at 0 or at `length` and move
/// towards it. Returns how many it reflected and the deepest penetration.
fn reflect_at_walls(
    positions: &[f64],
    velocities: &mut [f64],
    radii: &[f64],
    length: f64,
    wall_restitution: f64,
) -> StepCounters {
    let mut hits = 0;
    let mut deepest = 0.0_f64;
    for ((&p, v), &r) in positions.iter().zip(velocities).zip(radii) {
        let outward = (p - r < 0.0 && *v < 0.0) || (p + r > length && *v > 0.0);
        if outward {
            *v *= -wall_restitution;
            hits += 1;
        }
        deepest = deepest.max((r - p).max(p + r - length) / r);
    }
    StepCounters {
        wall_collisions: hits,
        max_wall_penetration: deepest,
        ..StepCounters::default()
    }
}

/// The largest dt for which the fastest disk moves at most `fraction` of the smallest
/// radius per step. With a field, the fastest speed includes what a fall across the
/// whole box can add. A scene at rest gets the dt of unit speed.
pub fn auto_dt(particles: &Particles, domain: &Domain, physics: &Physics, fraction: f64) -> f64 {
    let mut max_speed = particles.max_speed();
    if let Some([gx, gy]) = physics.gravity {
        let g = gx.hypot(gy);
        max_speed += (2.0 * g * domain.width.max(domain.height)).sqrt();
    }
    let max_speed = if max_speed > 0.0 { max_speed } else { 1.0 };
    fraction * particles.min_radius() / max_speed
}
