//! Running totals of what the time steps did: impulses, wall reflections, the largest
//! overlap and wall penetration, and the collision virial. Filled by the move
//! (`step`), by contact resolution (`resolve`) and by the event method; merged across
//! the workers of a parallel backend, with the same bits in any order.

use super::collision::ContactOutcome;

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
    /// Σ d·J over the impulses applied: the collision virial (for the pressure). Each
    /// term is put on the grid of [`VIRIAL_GRID`] first ([`virial_term`]), which makes
    /// the sum exact, and so the same bits in any order of addition (workers, ranks),
    /// while it stays below 2⁵³·[`VIRIAL_GRID`] ≈ 1.4·10¹¹.
    pub virial: f64,
}

/// The spacing of the grid the virial's terms are rounded to (2⁻¹⁶): a term of order 1
/// moves by at most 8·10⁻⁶, rounding to the nearest point, up and down alike.
pub const VIRIAL_GRID: f64 = 1.0 / 65536.0;

/// A virial term d·J rounded to the nearest point of [`VIRIAL_GRID`] (exact scaling by
/// powers of two).
#[inline(always)]
pub fn virial_term(value: f64) -> f64 {
    (value / VIRIAL_GRID).round() * VIRIAL_GRID
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
        self.virial += virial_term(outcome.virial);
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
