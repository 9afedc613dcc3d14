//! Contact resolution within one step: the one function the serial stepper and every
//! parallel backend call on a canonical list of contacts (all of a step's contacts, or
//! whole chains of them, `sim::schedule`). It leaves out finding the contacts.
//!
//! Without a field, a step gives each overlapping, approaching pair one impulse, in
//! canonical order: the seed's method, kept bit for bit.
//!
//! With gravity, disks rest on each other and on the walls, and one pass is not enough:
//! each step the floor turns back only the bottom disk, the impulses above push it down
//! again, and a stack sinks through the floor at the rate of its weight. So, as the
//! sequential-impulse solvers of Box2D and Rapier do, the step tells resting contacts
//! from impacts by how fast they close ([`RESTING_SPEED_STEPS`]): an impact gets the
//! scene's restitution, a resting contact none, in the first pass and after it. Then it
//! 1. iterates Gauss–Seidel sweeps over the same contacts, in the same canonical order,
//!    with the walls as contacts too (a disk of the list that touches a wall and moves
//!    into it is turned back), until a sweep applies no impulse or [`MAX_SWEEPS`] sweeps
//!    are done. A pair still closing after the first pass is a multi-body impact (a disk
//!    struck and pressed into a third in the same step) and bounces again, so an elastic
//!    gas under gravity keeps its energy; resting contacts are stopped, which makes them
//!    hold;
//! 2. projects positions: a pair overlapping by more than the slop is pushed apart along
//!    its normal (split by inverse mass, so the centre of mass stays), then a disk of the
//!    list inside a wall by more than the slop is put back at the slop ([`SLOP`]), as
//!    Box2D's position solver does, unless the motion clears the overlap within the next
//!    step (an impact parting). The velocity sweeps alone cannot undo the sinking that
//!    gravity adds within a step; without the projection it accumulates.
//!
//! Determinism: a chain of contacts sharing disks is independent of every other chain,
//! and a sweep that applies no impulse to a chain leaves it unchanged. So sweeping all
//! contacts until none applies an impulse (or the cap is reached) gives the same bits as
//! sweeping each chain on its own: a backend may call this on any union of whole chains.

use super::collision::{ContactOutcome, DiskState, resolve_contact};
use super::counters::{StepCounters, virial_term};
use super::grid::Contact;
use super::scene::{Boundary, Domain, Physics, wrap_periodic};

/// Most resting-contact sweeps per step (Box2D defaults to 8 velocity iterations; a
/// narrow pile under gravity needs more to hold its bottom disks within the slop).
/// Gauss–Seidel converges slowly along a tall stack (a few per cent per sweep for 20
/// disks), so a deep pile uses them all; what is left is small, and the position
/// projection and the next step's sweeps take it up.
pub const MAX_SWEEPS: u32 = 32;

/// Overlap left uncorrected by the position projection: a fraction of the pair's
/// contact distance `r_a + r_b`, or of the radius for a wall. Leaving a sliver keeps
/// resting contacts touching, so the sweeps see them every step (Box2D's linear slop).
pub const SLOP: f64 = 0.005;

/// Contacts closing slower than this many times |g|·dt (the speed the field adds in one
/// step) are resting and get no restitution; faster ones are impacts (Box2D's
/// restitution threshold, 1 m/s, is about 6 of these at 60 Hz). A disk held by a support
/// closes on it at |g|·dt, and at up to (1 + e_wall)·|g|·dt on a disk the floor has just
/// turned back: the column and the piles of `tests/resting.rs` settled with at most 1 in
/// 2000 of their contacts closing faster than 4. A disk that falls for n steps lands at
/// n·|g|·dt: only a fall from below 8·|g|·dt² lands slower than the resting speed.
pub const RESTING_SPEED_STEPS: f64 = 4.0;

/// A sweep impulse is applied only above this approach speed, as a fraction of `|g|·dt`
/// (the speed the field adds in one step): rounding noise below it would otherwise keep
/// every sweep busy until the cap.
const SWEEP_TOLERANCE: f64 = 1e-3;

/// Contacts ahead of the one being resolved whose disks are fetched into the caches.
/// Past the last-level cache a fetch takes longer than resolving eight contacts: 16
/// ahead instead of 8 ran 1.023× as fast at 10⁶ disks and packing 0.3, and 0.990–0.998×
/// in smaller or more dilute scenes (`docs/performance.md`, Resolution order).
const PREFETCH_AHEAD: usize = 16;

/// Resolves `contacts` (whole chains, each in canonical order, [`Contact::key`]: see
/// `sim::schedule::ResolutionOrder`) for one step of `dt`:
/// one pass of pair impulses with the scene's restitution (with gravity, for impacts
/// only), calling `collided` with each pair that received one; then, with gravity,
/// resting contact (module docs). Counts into `counters`.
pub fn resolve_contacts<S: DiskState>(
    disks: &mut S,
    domain: &Domain,
    physics: &Physics,
    dt: f64,
    contacts: &[Contact],
    counters: &mut StepCounters,
    mut collided: impl FnMut(&Contact),
) {
    let bounce = Bounce::for_step(physics, dt);
    for (pos, contact) in contacts.iter().enumerate() {
        if let Some(ahead) = contacts.get(pos + PREFETCH_AHEAD) {
            for disk in [ahead.a as usize, ahead.b as usize] {
                disks.prefetch_motion(disk);
                disks.prefetch_properties(disk);
            }
        }
        let (a, b) = (contact.a as usize, contact.b as usize);
        // Without a field every approaching pair is an impact: the approach speed is
        // not needed, and the seed's arithmetic is kept bit for bit.
        let outcome = match &bounce {
            None => resolve_contact(disks, domain, physics, a, b),
            Some(bounce) => {
                let law = bounce.pair(physics, approach_speed(disks, domain, a, b));
                resolve_contact(disks, domain, &law, a, b)
            }
        };
        counters.record(outcome);
        if outcome.collided {
            collided(contact);
        }
    }
    if let Some(bounce) = bounce {
        for _ in 0..MAX_SWEEPS {
            if !sweep(disks, domain, physics, contacts, &bounce, counters) {
                break;
            }
        }
        project(disks, domain, contacts, dt);
    }
}

/// What a contact's approach speed makes of it in a scene with gravity: faster than
/// the resting speed ([`RESTING_SPEED_STEPS`]·|g|·dt) it is an impact and gets the
/// scene's restitution; slower it is resting contact and gets none.
#[derive(Clone, Copy, Debug)]
struct Bounce {
    walls: f64,
    resting_speed: f64,
    /// Approach speeds below this get no sweep impulse ([`SWEEP_TOLERANCE`]).
    tolerance: f64,
}

impl Bounce {
    /// The rule for a step of `dt`; `None` without a field.
    fn for_step(physics: &Physics, dt: f64) -> Option<Bounce> {
        let [gx, gy] = physics.gravity?;
        let speed_per_step = gx.hypot(gy) * dt;
        Some(Bounce {
            walls: physics.wall_restitution,
            resting_speed: RESTING_SPEED_STEPS * speed_per_step,
            tolerance: SWEEP_TOLERANCE * speed_per_step,
        })
    }

    /// The contact law of a pair approaching at `speed`: the scene's, or the scene's
    /// without restitution for a resting contact.
    #[inline]
    fn pair(&self, physics: &Physics, speed: f64) -> Physics {
        if speed > self.resting_speed {
            *physics
        } else {
            Physics {
                restitution: 0.0,
                ..*physics
            }
        }
    }

    /// The restitution of a wall hit at `speed`.
    #[inline]
    fn wall(&self, speed: f64) -> f64 {
        if speed > self.resting_speed {
            self.walls
        } else {
            0.0
        }
    }
}

/// One Gauss–Seidel sweep: pairs in the order given, then walls, each that still
/// approaches given an impulse by the [`Bounce`] rule. Returns whether it applied any.
/// The pair impulses add to the virial (they carry the weight, which the pressure must
/// see); they are not counted as collisions.
fn sweep<S: DiskState>(
    disks: &mut S,
    domain: &Domain,
    physics: &Physics,
    contacts: &[Contact],
    bounce: &Bounce,
    counters: &mut StepCounters,
) -> bool {
    let mut applied = false;
    for contact in contacts {
        let (a, b) = (contact.a as usize, contact.b as usize);
        let speed = approach_speed(disks, domain, a, b);
        if speed > bounce.tolerance {
            let ContactOutcome { virial, .. } =
                resolve_contact(disks, domain, &bounce.pair(physics, speed), a, b);
            counters.virial += virial_term(virial);
            applied = true;
        }
    }
    if domain.boundary == Boundary::Walls {
        // Each disk's wall rule reads and writes that disk only, and a second visit finds
        // it no longer moving into the wall: the order among disks and repeated disks do
        // not matter.
        for contact in contacts {
            for idx in [contact.a as usize, contact.b as usize] {
                applied |= bounce_at_walls(disks, domain, idx, bounce);
            }
        }
    }
    applied
}

/// How fast the disks at `a` and `b` approach each other along their line of centres
/// (negative when they separate), if they overlap; 0 otherwise.
#[inline]
fn approach_speed<S: DiskState>(disks: &S, domain: &Domain, a: usize, b: usize) -> f64 {
    let ([xa, ya], [xb, yb]) = (disks.position(a), disks.position(b));
    let (dx, dy) = domain.separation(xa, ya, xb, yb);
    let distance_sq = dx * dx + dy * dy;
    let contact = disks.radius(a) + disks.radius(b);
    if distance_sq >= contact * contact || distance_sq == 0.0 {
        return 0.0;
    }
    let ([vax, vay], [vbx, vby]) = (disks.velocity(a), disks.velocity(b));
    -((vbx - vax) * dx + (vby - vay) * dy) / distance_sq.sqrt()
}

/// Turns back the normal motion of the disk at `idx` into any wall it touches (faster
/// than the sweep tolerance): reflected with the wall's restitution if it is an impact,
/// stopped if it is resting ([`Bounce::wall`]). Returns whether it did.
#[inline]
fn bounce_at_walls<S: DiskState>(
    disks: &mut S,
    domain: &Domain,
    idx: usize,
    bounce: &Bounce,
) -> bool {
    let (position, mut velocity, r) = (disks.position(idx), disks.velocity(idx), disks.radius(idx));
    let tolerance = bounce.tolerance;
    let mut turned = false;
    for (axis, length) in [domain.width, domain.height].into_iter().enumerate() {
        let (p, v) = (position[axis], velocity[axis]);
        if (p - r < 0.0 && v < -tolerance) || (p + r > length && v > tolerance) {
            velocity[axis] = -bounce.wall(v.abs()) * v;
            turned = true;
        }
    }
    if turned {
        disks.set_velocity(idx, velocity);
    }
    turned
}

/// The position projection: pairs in the order given pushed apart to the slop, then
/// disks of the list put back inside the walls to the slop; but an overlap that the
/// pair's separation, or the disk's motion out of the wall, clears within the next step
/// is left to it. That is an impact resolving itself, as it does without a field:
/// moving it would shift its flight, and lifting a disk out of the floor would add
/// potential energy. Resting contacts neither approach nor separate, so they are always
/// projected.
fn project<S: DiskState>(disks: &mut S, domain: &Domain, contacts: &[Contact], dt: f64) {
    for contact in contacts {
        let (a, b) = (contact.a as usize, contact.b as usize);
        let ([xa, ya], [xb, yb]) = (disks.position(a), disks.position(b));
        let (dx, dy) = domain.separation(xa, ya, xb, yb);
        let distance = dx.hypot(dy);
        let contact_distance = disks.radius(a) + disks.radius(b);
        let excess = contact_distance * (1.0 - SLOP) - distance;
        if excess <= 0.0 || distance == 0.0 {
            continue;
        }
        // The same bits with a and b swapped: both differences change sign exactly.
        let ([vax, vay], [vbx, vby]) = (disks.velocity(a), disks.velocity(b));
        if ((vbx - vax) * dx + (vby - vay) * dy) * dt >= excess * distance {
            continue;
        }
        let (ma, mb) = (disks.mass(a), disks.mass(b));
        let (nx, ny) = (dx / distance, dy / distance);
        let (share_a, share_b) = (excess * mb / (ma + mb), excess * ma / (ma + mb));
        let place = |x: f64, y: f64| match domain.boundary {
            Boundary::Walls => [x, y],
            Boundary::Periodic => [
                wrap_periodic(x, domain.width),
                wrap_periodic(y, domain.height),
            ],
        };
        disks.set_position(a, place(xa - nx * share_a, ya - ny * share_a));
        disks.set_position(b, place(xb + nx * share_b, yb + ny * share_b));
    }
    if domain.boundary == Boundary::Walls {
        for contact in contacts {
            for idx in [contact.a as usize, contact.b as usize] {
                let (mut position, velocity) = (disks.position(idx), disks.velocity(idx));
                let inside = disks.radius(idx) * (1.0 - SLOP);
                for (axis, length) in [domain.width, domain.height].into_iter().enumerate() {
                    let (p, v) = (position[axis], velocity[axis]);
                    let clears = (p < inside && p + v * dt >= inside)
                        || (p > length - inside && p + v * dt <= length - inside);
                    if !clears {
                        position[axis] = p.clamp(inside, length - inside);
                    }
                }
                disks.set_position(idx, position);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::grid::find_contacts_all_pairs;
    use crate::sim::particles::{Disk, Particles};

    /// Contacts carry no orientation (`sim::grid::Contact`): a heap of disks of unequal
    /// masses resting under gravity on a walled floor, resolved with every pair given
    /// the other way round, ends with the same bits and the same counters, through the
    /// sweeps and the projection as through the first pass.
    #[test]
    fn a_heap_under_gravity_resolves_to_the_same_bits_with_its_pairs_swapped() {
        let domain = Domain {
            width: 20.0,
            height: 20.0,
            boundary: Boundary::Walls,
        };
        let physics = Physics {
            gravity: Some([0.0, -1.0]),
            ..Physics::with_restitution(0.4)
        };
        // Three staggered rows, the lowest 0.03 into the floor, every disk overlapping its
        // neighbours in its row (by 0.05) and in the rows next to it (by 0.09), falling.
        let disks: Vec<Disk> = (0..18)
            .map(|k| {
                let (row, col) = ((k / 6) as f64, (k % 6) as f64);
                Disk {
                    x: 2.0 + 1.95 * col + 0.97 * (row % 2.0),
                    y: 0.97 + 1.65 * row,
                    vx: 0.01 * (col - 2.5),
                    vy: -0.3 - 0.05 * row,
                    radius: 1.0,
                    mass: 1.0 + 0.25 * col,
                }
            })
            .collect();
        let mut forward = Particles::from_disks(&disks);
        let mut contacts = Vec::new();
        find_contacts_all_pairs(&forward, &domain, &mut contacts);
        assert!(contacts.len() > 20, "a heap with many contacts");
        let swapped: Vec<Contact> = contacts
            .iter()
            .map(|c| Contact { a: c.b, b: c.a })
            .collect();
        let mut backward = forward.clone();
        let (mut there, mut back) = (StepCounters::default(), StepCounters::default());
        resolve_contacts(
            &mut forward,
            &domain,
            &physics,
            0.05,
            &contacts,
            &mut there,
            |_| {},
        );
        resolve_contacts(
            &mut backward,
            &domain,
            &physics,
            0.05,
            &swapped,
            &mut back,
            |_| {},
        );
        assert_eq!(forward, backward);
        assert_eq!(there, back);
        assert_eq!(there.virial.to_bits(), back.virial.to_bits());
    }
}
