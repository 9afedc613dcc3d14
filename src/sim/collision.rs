//! The impulse law: the one place the physics of a contact lives.
//!
//! The seed report's equations 3–4, corrected: along the line of centres
//! `u1' = ((m1 − e·m2)·u1 + (1+e)·m2·u2)/(m1+m2)` and
//! `u2' = ((1+e)·m1·u1 + (m2 − e·m1)·u2)/(m1+m2)`; tangential components are unchanged.

use super::particles::Particles;
use super::prefetch::prefetch;
use super::scene::{Domain, Physics};

/// Post-collision normal velocities of two disks (corrected equations 3–4).
///
/// `u1`, `u2` are the components along the line of centres before the impact.
#[inline(always)]
pub fn normal_velocities_after(m1: f64, m2: f64, e: f64, u1: f64, u2: f64) -> (f64, f64) {
    let total = m1 + m2;
    (
        ((m1 - e * m2) * u1 + (1.0 + e) * m2 * u2) / total,
        ((1.0 + e) * m1 * u1 + (m2 - e * m1) * u2) / total,
    )
}

/// What resolving one overlapping pair did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactOutcome {
    /// Overlap depth as a fraction of the contact distance `r_a + r_b` (0 when just touching).
    pub overlap_fraction: f64,
    /// True when the pair was approaching and an impulse was applied.
    pub collided: bool,
    /// The pair's collision virial `d·J`: centre distance times the normal impulse
    /// (0 when no impulse was applied). Summed over time it gives the pressure.
    pub virial: f64,
}

/// What one disk of a pair brings to a collision: its mass and velocity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairSide {
    pub mass: f64,
    pub vx: f64,
    pub vy: f64,
}

/// The impulse law along the unit normal `(nx, ny)` pointing from a to b: returns the
/// new velocities `[vx, vy]` of a and b and the normal impulse J ≥ 0 given to b (a gets
/// −J), for a pair that approaches. The time-stepped contact ([`collide_pair`]) and the
/// event-driven collision (`sim::event`) both apply it: one law, one place.
///
/// Swapping a and b (and so the normal's sign) gives the same bits, swapped: each
/// product and sum is formed from the same two values in either order, and negation
/// is exact. J is therefore written `m_a·m_b·(1+e)·(u_a − u_b)/(m_a + m_b)`, not
/// `m_a·(u_a − u_a')`, which is the same number but rounds differently when seen from
/// b. So a contact needs no orientation (`sim::grid::Contact`).
#[inline(always)]
pub fn exchange_along(
    physics: &Physics,
    nx: f64,
    ny: f64,
    a: PairSide,
    b: PairSide,
) -> ([[f64; 2]; 2], f64) {
    let ua = a.vx * nx + a.vy * ny;
    let ub = b.vx * nx + b.vy * ny;
    let restitution = physics.restitution;
    let (ua_after, ub_after) = normal_velocities_after(a.mass, b.mass, restitution, ua, ub);
    // v' = v_t + u'·n with v_t = v − u·n: along an axis the tangential part is exactly zero,
    // so a head-on exchange of equal masses swaps the bits exactly.
    let velocities = [
        [
            (a.vx - ua * nx) + ua_after * nx,
            (a.vy - ua * ny) + ua_after * ny,
        ],
        [
            (b.vx - ub * nx) + ub_after * nx,
            (b.vy - ub * ny) + ub_after * ny,
        ],
    ];
    let impulse = a.mass * b.mass * (1.0 + restitution) * (ua - ub) / (a.mass + b.mass);
    (velocities, impulse)
}

/// The impulse law applied to one pair, on values only, so every backend (serial,
/// threads, ranks) runs the same arithmetic.
///
/// `dx, dy` is the separation from a to b ([`Domain::separation`]), `contact` is
/// `r_a + r_b`. Returns the outcome and, when an impulse was applied, the new
/// velocities `[vx, vy]` of a and b. A pair that overlaps but already separates
/// (v_rel · n ≥ 0) is left alone, so overlapping disks never stick or jitter.
/// Coincident centres have no line of centres and are left alone too.
#[inline(always)]
pub fn collide_pair(
    physics: &Physics,
    dx: f64,
    dy: f64,
    contact: f64,
    a: PairSide,
    b: PairSide,
) -> (ContactOutcome, Option<[[f64; 2]; 2]>) {
    let distance_sq = dx * dx + dy * dy;
    if distance_sq >= contact * contact || distance_sq == 0.0 {
        let outcome = ContactOutcome {
            overlap_fraction: 0.0,
            collided: false,
            virial: 0.0,
        };
        return (outcome, None);
    }
    let distance = distance_sq.sqrt();
    let overlap_fraction = (contact - distance) / contact;
    let (dvx, dvy) = (b.vx - a.vx, b.vy - a.vy);
    if dvx * dx + dvy * dy >= 0.0 {
        let outcome = ContactOutcome {
            overlap_fraction,
            collided: false,
            virial: 0.0,
        };
        return (outcome, None);
    }
    let (nx, ny) = (dx / distance, dy / distance);
    let (velocities, impulse) = exchange_along(physics, nx, ny, a, b);
    let outcome = ContactOutcome {
        overlap_fraction,
        collided: true,
        virial: distance * impulse,
    };
    (outcome, Some(velocities))
}

/// Read and write access to the disks a contact resolution touches, by storage index.
///
/// [`Particles`] is the plain implementation; a parallel backend may implement it on a
/// view that lets several workers resolve disjoint chains of contacts at once. Masses and
/// radii are only read.
pub trait DiskState {
    fn position(&self, idx: usize) -> [f64; 2];
    fn velocity(&self, idx: usize) -> [f64; 2];
    fn radius(&self, idx: usize) -> f64;
    fn mass(&self, idx: usize) -> f64;
    fn set_position(&mut self, idx: usize, position: [f64; 2]);
    fn set_velocity(&mut self, idx: usize, velocity: [f64; 2]);
    /// Asks the caches for the position and velocity of the disk at `idx` ahead of
    /// their use (a hint: no effect on results). Resolution reads chains of contacts in
    /// the canonical order of their ids, which is random in storage; fetching a few
    /// contacts ahead hides the misses.
    #[inline(always)]
    fn prefetch_motion(&self, _idx: usize) {}
    /// [`DiskState::prefetch_motion`] for the radius and mass (held once for equal
    /// disks: nothing to fetch).
    #[inline(always)]
    fn prefetch_properties(&self, _idx: usize) {}
}

impl DiskState for Particles {
    #[inline(always)]
    fn position(&self, idx: usize) -> [f64; 2] {
        [self.x[idx], self.y[idx]]
    }
    #[inline(always)]
    fn velocity(&self, idx: usize) -> [f64; 2] {
        [self.vx[idx], self.vy[idx]]
    }
    #[inline(always)]
    fn radius(&self, idx: usize) -> f64 {
        self.radius[idx]
    }
    #[inline(always)]
    fn mass(&self, idx: usize) -> f64 {
        self.mass[idx]
    }
    #[inline(always)]
    fn set_position(&mut self, idx: usize, [x, y]: [f64; 2]) {
        self.x[idx] = x;
        self.y[idx] = y;
    }
    #[inline(always)]
    fn set_velocity(&mut self, idx: usize, [vx, vy]: [f64; 2]) {
        self.vx[idx] = vx;
        self.vy[idx] = vy;
    }
    #[inline(always)]
    fn prefetch_motion(&self, idx: usize) {
        for values in [&self.x, &self.y, &self.vx, &self.vy] {
            prefetch(values.as_ptr().wrapping_add(idx));
        }
    }
    #[inline(always)]
    fn prefetch_properties(&self, idx: usize) {
        self.radius.prefetch(idx);
        self.mass.prefetch(idx);
    }
}

/// Resolves the pair stored at `a` and `b` with [`collide_pair`]. Either disk may come
/// first: the result has the same bits ([`exchange_along`]).
#[inline]
pub fn resolve_contact<S: DiskState>(
    disks: &mut S,
    domain: &Domain,
    physics: &Physics,
    a: usize,
    b: usize,
) -> ContactOutcome {
    let ([xa, ya], [xb, yb]) = (disks.position(a), disks.position(b));
    let (dx, dy) = domain.separation(xa, ya, xb, yb);
    let side = |idx: usize| {
        let [vx, vy] = disks.velocity(idx);
        PairSide {
            mass: disks.mass(idx),
            vx,
            vy,
        }
    };
    let contact = disks.radius(a) + disks.radius(b);
    let (outcome, velocities) = collide_pair(physics, dx, dy, contact, side(a), side(b));
    if let Some([after_a, after_b]) = velocities {
        disks.set_velocity(a, after_a);
        disks.set_velocity(b, after_b);
    }
    outcome
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::particles::Disk;
    use crate::sim::scene::{Boundary, wrap_periodic};
    use rand::{RngExt, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;

    const OPEN_BOX: Domain = Domain {
        width: 100.0,
        height: 100.0,
        boundary: Boundary::Walls,
    };

    fn disk(x: f64, y: f64, vx: f64, vy: f64, mass: f64) -> Disk {
        Disk {
            x,
            y,
            vx,
            vy,
            radius: 1.0,
            mass,
        }
    }

    /// Resolves a two-disk scene and returns the disks after.
    fn collide(a: Disk, b: Disk, e: f64) -> (Disk, Disk, ContactOutcome) {
        let mut particles = Particles::from_disks(&[a, b]);
        let outcome = resolve_contact(
            &mut particles,
            &OPEN_BOX,
            &Physics::with_restitution(e),
            0,
            1,
        );
        (particles.disk(0), particles.disk(1), outcome)
    }

    fn momentum(disks: &[Disk]) -> (f64, f64) {
        disks.iter().fold((0.0, 0.0), |(px, py), d| {
            (px + d.mass * d.vx, py + d.mass * d.vy)
        })
    }

    fn energy(disks: &[Disk]) -> f64 {
        disks
            .iter()
            .map(|d| 0.5 * d.mass * (d.vx * d.vx + d.vy * d.vy))
            .sum()
    }

    /// Contacts carry no orientation (`sim::grid::Contact`): resolving a pair as (b, a)
    /// must give the bits of (a, b), swapped, and the same virial, for any masses and
    /// restitution, in a walled box and across a periodic edge.
    #[test]
    fn a_pair_resolved_either_way_round_gives_the_same_bits() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
        let mut uniform = move || rng.random::<f64>();
        let periodic = Domain {
            boundary: Boundary::Periodic,
            ..OPEN_BOX
        };
        let mut collided = 0;
        for round in 0..2000 {
            let (domain, x) = match round % 2 {
                0 => (OPEN_BOX, 50.0),
                _ => (periodic, 99.5),
            };
            // Every restitution with both boundaries.
            let e = [0.0, 0.37, 0.9, 1.0][round / 2 % 4];
            let a = disk(x, 50.0, uniform() - 0.5, uniform() - 0.5, 0.1 + uniform());
            let angle = std::f64::consts::TAU * uniform();
            let (dx, dy) = (1.9 * angle.cos(), 1.9 * angle.sin());
            let b_x = if domain.boundary == Boundary::Periodic {
                wrap_periodic(x + dx, domain.width)
            } else {
                x + dx
            };
            let b = disk(
                b_x,
                50.0 + dy,
                uniform() - 0.5,
                uniform() - 0.5,
                0.1 + uniform(),
            );
            let mut forward = Particles::from_disks(&[a, b]);
            let mut backward = forward.clone();
            let physics = Physics::with_restitution(e);
            let there = resolve_contact(&mut forward, &domain, &physics, 0, 1);
            let back = resolve_contact(&mut backward, &domain, &physics, 1, 0);
            assert_eq!(forward.disk(0), backward.disk(0), "round {round}");
            assert_eq!(forward.disk(1), backward.disk(1), "round {round}");
            assert_eq!(
                there.virial.to_bits(),
                back.virial.to_bits(),
                "round {round}"
            );
            assert_eq!(there.collided, back.collided);
            collided += usize::from(there.collided);
        }
        assert!(collided > 500, "only {collided} of the pairs approached");
    }

    #[test]
    fn head_on_equal_masses_elastic_exchange_velocities_exactly() {
        let (a, b, outcome) = collide(
            disk(50.0, 50.0, 0.3, 0.0, 2.0),
            disk(51.9, 50.0, -0.7, 0.0, 2.0),
            1.0,
        );
        assert!(outcome.collided);
        assert_eq!((a.vx, a.vy), (-0.7, 0.0));
        assert_eq!((b.vx, b.vy), (0.3, 0.0));
    }

    #[test]
    fn perfectly_inelastic_pair_leaves_with_centre_of_mass_velocity() {
        let (a, b, _) = collide(
            disk(50.0, 50.0, 0.3, 0.0, 1.0),
            disk(51.9, 50.0, -0.7, 0.0, 3.0),
            0.0,
        );
        let centre_of_mass = (1.0 * 0.3 + 3.0 * -0.7) / 4.0;
        assert_eq!(a.vx, b.vx);
        assert!(
            (a.vx - centre_of_mass).abs() < 1e-15,
            "{} vs {centre_of_mass}",
            a.vx
        );
    }

    #[test]
    fn unequal_masses_partial_restitution_match_closed_form() {
        let (m1, m2, e, u1, u2) = (1.5, 4.0, 0.6, 2.0, -1.0);
        let (a, b, _) = collide(
            disk(50.0, 50.0, u1, 0.0, m1),
            disk(51.5, 50.0, u2, 0.0, m2),
            e,
        );
        // Closed form: the centre-of-mass velocity minus e times the relative velocity share.
        let v_cm = (m1 * u1 + m2 * u2) / (m1 + m2);
        let expected_a = v_cm - e * m2 * (u1 - u2) / (m1 + m2);
        let expected_b = v_cm + e * m1 * (u1 - u2) / (m1 + m2);
        assert!(
            (a.vx - expected_a).abs() < 1e-14,
            "{} vs {expected_a}",
            a.vx
        );
        assert!(
            (b.vx - expected_b).abs() < 1e-14,
            "{} vs {expected_b}",
            b.vx
        );
        // Restitution: separation speed is e times approach speed.
        assert!(((b.vx - a.vx) - e * (u1 - u2)).abs() < 1e-14);
    }

    #[test]
    fn oblique_collision_keeps_tangential_components_and_conserves() {
        for e in [0.0, 0.35, 1.0] {
            // Line of centres at 30°; masses unequal.
            let angle = std::f64::consts::FRAC_PI_6;
            let (nx, ny) = (angle.cos(), angle.sin());
            let before = [
                disk(50.0, 50.0, 1.2, -0.4, 1.0),
                disk(50.0 + 1.9 * nx, 50.0 + 1.9 * ny, -0.8, 0.5, 2.5),
            ];
            let (a, b, outcome) = collide(before[0], before[1], e);
            assert!(outcome.collided);
            // The line of centres is rebuilt from rounded positions, so the tangent here and
            // the one the law uses differ in the last bits: compare to a few ulps of unit speed.
            let tangential = |d: &Disk| -d.vx * ny + d.vy * nx;
            assert!(
                (tangential(&a) - tangential(&before[0])).abs() < 1e-14,
                "{}",
                tangential(&a) - tangential(&before[0])
            );
            assert!(
                (tangential(&b) - tangential(&before[1])).abs() < 1e-14,
                "{}",
                tangential(&b) - tangential(&before[1])
            );
            let (p0, p1) = (momentum(&before), momentum(&[a, b]));
            assert!(
                (p0.0 - p1.0).abs() < 1e-15 && (p0.1 - p1.1).abs() < 1e-15,
                "e = {e}"
            );
            if e == 1.0 {
                let (e0, e1) = (energy(&before), energy(&[a, b]));
                assert!((e0 - e1).abs() <= 4.0 * f64::EPSILON * e0, "{e0} vs {e1}");
            } else {
                assert!(energy(&[a, b]) < energy(&before));
            }
        }
    }

    #[test]
    fn separating_or_distant_pairs_are_left_alone() {
        let separating = collide(
            disk(50.0, 50.0, -1.0, 0.0, 1.0),
            disk(51.0, 50.0, 1.0, 0.0, 1.0),
            1.0,
        );
        assert!(!separating.2.collided);
        assert_eq!(separating.0.vx, -1.0);
        assert!((separating.2.overlap_fraction - 0.5).abs() < 1e-15);
        let apart = collide(
            disk(50.0, 50.0, 1.0, 0.0, 1.0),
            disk(52.5, 50.0, -1.0, 0.0, 1.0),
            1.0,
        );
        assert!(!apart.2.collided);
        assert_eq!(apart.2.overlap_fraction, 0.0);
    }
}
