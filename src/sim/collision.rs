//! The impulse law: the one place the physics of a contact lives.
//!
//! The seed report's equations 3–4, corrected: along the line of centres
//! `u1' = ((m1 − e·m2)·u1 + (1+e)·m2·u2)/(m1+m2)` and
//! `u2' = ((1+e)·m1·u1 + (m2 − e·m1)·u2)/(m1+m2)`; tangential components are unchanged.

use super::particles::Particles;
use super::scene::Domain;

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
}

/// Resolves the pair stored at `a` and `b` if the disks overlap and approach.
///
/// A pair that overlaps but already separates (v_rel · n ≥ 0) is left alone, so
/// overlapping disks never stick or jitter. Coincident centres have no line of
/// centres and are left alone too. `a` must be the disk with the lower id: the
/// orientation is part of the canonical order that makes results reproducible.
#[inline]
pub fn resolve_contact(
    particles: &mut Particles,
    domain: &Domain,
    restitution: f64,
    a: usize,
    b: usize,
) -> ContactOutcome {
    let (dx, dy) = domain.separation(
        particles.x[a],
        particles.y[a],
        particles.x[b],
        particles.y[b],
    );
    let contact = particles.radius[a] + particles.radius[b];
    let distance_sq = dx * dx + dy * dy;
    if distance_sq >= contact * contact || distance_sq == 0.0 {
        return ContactOutcome {
            overlap_fraction: 0.0,
            collided: false,
        };
    }
    let distance = distance_sq.sqrt();
    let overlap_fraction = (contact - distance) / contact;
    let (dvx, dvy) = (
        particles.vx[b] - particles.vx[a],
        particles.vy[b] - particles.vy[a],
    );
    if dvx * dx + dvy * dy >= 0.0 {
        return ContactOutcome {
            overlap_fraction,
            collided: false,
        };
    }
    let (nx, ny) = (dx / distance, dy / distance);
    let (vax, vay, vbx, vby) = (
        particles.vx[a],
        particles.vy[a],
        particles.vx[b],
        particles.vy[b],
    );
    let ua = vax * nx + vay * ny;
    let ub = vbx * nx + vby * ny;
    let (ua_after, ub_after) =
        normal_velocities_after(particles.mass[a], particles.mass[b], restitution, ua, ub);
    // v' = v_t + u'·n with v_t = v − u·n: along an axis the tangential part is exactly zero,
    // so a head-on exchange of equal masses swaps the bits exactly.
    particles.vx[a] = (vax - ua * nx) + ua_after * nx;
    particles.vy[a] = (vay - ua * ny) + ua_after * ny;
    particles.vx[b] = (vbx - ub * nx) + ub_after * nx;
    particles.vy[b] = (vby - ub * ny) + ub_after * ny;
    ContactOutcome {
        overlap_fraction,
        collided: true,
    }
}
