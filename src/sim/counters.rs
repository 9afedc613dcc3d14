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

/// A virial term d·J rounded to the nearest point of [`VIRIAL_GRID`], ties to even
/// (exact scaling by powers of two). Below 2⁵¹ grid points, adding and taking away
/// 1.5·2⁵² rounds to an integer in two additions: `f64::round_ties_even` is a call into
/// libm on x86-64's baseline, and every impulse pays for it. Larger terms (above 3·10¹⁰)
/// take that call.
#[inline(always)]
pub fn virial_term(value: f64) -> f64 {
    const ROUNDER: f64 = 1.5 * (1u64 << 52) as f64;
    const TWO_ADDITIONS_BELOW: f64 = (1u64 << 51) as f64;
    let points = value / VIRIAL_GRID;
    let rounded = match points.abs() < TWO_ADDITIONS_BELOW {
        true => (points + ROUNDER) - ROUNDER,
        false => points.round_ties_even(),
    };
    rounded * VIRIAL_GRID
}

impl StepCounters {
    /// Counts one resolved pair.
    #[inline(always)]
    pub fn record(&mut self, outcome: ContactOutcome) {
        self.pair_collisions += u64::from(outcome.collided);
        self.max_overlap = self.max_overlap.max(outcome.overlap_fraction);
        // A pair left alone has no virial: only impulses add to it.
        if outcome.collided {
            self.overlap_sum += outcome.overlap_fraction;
            self.virial += virial_term(outcome.virial);
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// The two-addition rounding is round-half-to-even onto the grid, for small, large,
    /// negative and tie values, and sums of rounded terms have the same bits in any order.
    #[test]
    fn virial_terms_round_to_the_nearest_grid_point_and_sum_alike_in_any_order() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let mut terms: Vec<f64> = (0..10_000)
            .map(|k| {
                let magnitude = 10f64.powi(rng.random_range(-9..12));
                let sign = if k % 3 == 0 { -1.0 } else { 1.0 };
                sign * magnitude * rng.random::<f64>()
            })
            .collect();
        terms.extend([
            0.5 * VIRIAL_GRID,
            1.5 * VIRIAL_GRID,
            -2.5 * VIRIAL_GRID,
            1e300,
        ]);
        for &term in &terms {
            let expected = (term / VIRIAL_GRID).round_ties_even() * VIRIAL_GRID;
            // The same number; a tiny negative term may come out as +0 instead of −0,
            // which adds nothing either way.
            assert_eq!(virial_term(term), expected, "{term:e}");
        }
        let small: Vec<f64> = terms
            .iter()
            .map(|&t| virial_term(t))
            .filter(|t| t.abs() < 1e9)
            .collect();
        let forward: f64 = small.iter().sum();
        let backward: f64 = small.iter().rev().sum();
        assert_eq!(forward.to_bits(), backward.to_bits());
    }
}
