//! Observables of a state: energy, momentum and the bitwise state hash.
//!
//! Sums run in id order so that they do not depend on storage order or on how
//! disks were divided among workers.

use xxhash_rust::xxh3::Xxh3;

use super::particles::Particles;

/// Whole-system quantities measured at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observables {
    /// Σ ½ m v².
    pub kinetic_energy: f64,
    /// Σ m v, as [px, py].
    pub momentum: [f64; 2],
}

pub fn observe(particles: &Particles) -> Observables {
    let mut kinetic_energy = 0.0;
    let mut momentum = [0.0, 0.0];
    // Fixed order (by id): floating-point sums are not associative.
    for idx in particles.storage_index_by_id() {
        let (m, vx, vy) = (particles.mass[idx], particles.vx[idx], particles.vy[idx]);
        kinetic_energy += 0.5 * m * (vx * vx + vy * vy);
        momentum[0] += m * vx;
        momentum[1] += m * vy;
    }
    Observables {
        kinetic_energy,
        momentum,
    }
}

/// Hex xxh3-64 of the exact bits of x, y, vx, vy of every disk in id order
/// (little-endian). Equal hashes mean bitwise-identical states.
pub fn state_hash(particles: &Particles) -> String {
    let mut hasher = Xxh3::new();
    for idx in particles.storage_index_by_id() {
        for value in [
            particles.x[idx],
            particles.y[idx],
            particles.vx[idx],
            particles.vy[idx],
        ] {
            hasher.update(&value.to_le_bytes());
        }
    }
    format!("{:016x}", hasher.digest())
}
