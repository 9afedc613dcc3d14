//! Verlet neighbour lists: the pairs within a skin of touching, found by the strip grid
//! and reused over several steps, so that most steps test a short list of candidate
//! pairs instead of searching the box.
//!
//! Exactness: a list holds every pair whose centres were closer than `r_a + r_b + skin`
//! when it was built. While no disk has moved half the skin since then, every pair that
//! overlaps now is in the list: `|p_a − p_b|_then ≤ |p_a − p_b|_now + d_a + d_b <
//! r_a + r_b + skin`. The overlap test itself is the grid's arithmetic, so the contacts
//! found are exactly the grid's, bit for bit: a run's results do not depend on the skin
//! or on when the lists are rebuilt, only its speed does.
//!
//! [`Skin`] holds the positions of the last build and says when to rebuild;
//! [`PairList`] holds one list of candidate pairs (the serial stepper has one, a
//! threaded stepper one per band of strips).

use std::ops::Range;

use super::grid::{Contact, StripGrid};
use super::particles::Particles;
use super::scene::{Boundary, Domain};

/// The skin, in largest radii, in dilute gases (area fraction 0.05 and below) and in
/// dense ones (0.3 and above), interpolated in between. A wider skin lists more pairs
/// (about `ρ·π·(2r + skin)²/2` per disk) and is rebuilt less often: measured on gases at
/// v_rms·dt = 0.1·r, these were the fastest (`docs/performance.md`).
const SKIN_RADII_DILUTE: f64 = 4.0;
const SKIN_RADII_DENSE: f64 = 2.0;

/// At most this many times the longest step a disk takes (its speed times dt): a list
/// then lasts a few steps of the fastest disk. Slow scenes need only a thin skin.
const SKIN_STEPS: f64 = 12.0;

/// At least this many largest radii, so that a scene at rest (whose disks gravity will
/// speed up) still gets a list that lasts a few steps.
const MIN_SKIN_RADII: f64 = 0.25;

/// Lists serve on while at most one disk in this many has moved half the skin (their
/// pairs found by queries), and are rebuilt after.
const MAX_ESCAPEE_SHARE: usize = 64;

/// A disk escapes a list once it moved this fraction of half the skin: the margin
/// covers rounding in the displacement and distance arithmetic.
const SAFE_SKIN_FRACTION: f64 = 0.999;

/// The skin of a scene's lists and the positions they were last built at.
#[derive(Clone, Debug, Default)]
pub struct Skin {
    width: f64,
    /// Positions at the last build, by storage index.
    x_built: Vec<f64>,
    y_built: Vec<f64>,
}

impl Skin {
    /// The skin for `particles` in `domain` stepped by `dt`: wider in dilute gases
    /// ([`SKIN_RADII_DILUTE`], [`SKIN_RADII_DENSE`]), at most [`SKIN_STEPS`] steps of
    /// the fastest disk, and in a small periodic box narrow enough that the strips stay
    /// at least three to a side (no pair seen through two images). A width of 0 means
    /// the lists are rebuilt every step.
    pub fn for_scene(domain: &Domain, particles: &Particles, dt: f64) -> Skin {
        let max_radius = particles.max_radius();
        let packing = particles.disk_area() / domain.area();
        let dense = ((packing - 0.05) / (0.3 - 0.05)).clamp(0.0, 1.0);
        let radii = SKIN_RADII_DILUTE + dense * (SKIN_RADII_DENSE - SKIN_RADII_DILUTE);
        let longest_step = particles.max_speed() * dt;
        let mut width = (radii * max_radius)
            .min(SKIN_STEPS * longest_step)
            .max(MIN_SKIN_RADII * max_radius);
        if domain.boundary == Boundary::Periodic {
            let widest = domain.width.min(domain.height) / 3.0 - 2.0 * max_radius;
            width = width.min(widest);
        }
        Skin::with_width(width.max(0.0))
    }

    /// A skin `width` wide (finite, not negative).
    fn with_width(width: f64) -> Skin {
        Skin {
            width,
            ..Skin::default()
        }
    }

    pub fn width(&self) -> f64 {
        self.width
    }

    /// True when the recorded positions are of as many disks as `particles` holds.
    pub fn is_built_for(&self, particles: &Particles) -> bool {
        self.x_built.len() == particles.len()
    }

    /// True when a disk that moved √`largest_displacement_sq` makes the lists stale.
    pub fn is_exceeded(&self, largest_displacement_sq: f64) -> bool {
        let half = 0.5 * SAFE_SKIN_FRACTION * self.width;
        // NaN (a disk gone astray) counts as stale too.
        largest_displacement_sq.is_nan() || largest_displacement_sq >= half * half
    }

    /// The square of the largest distance a disk stored in `range` moved since the last
    /// build. The recorded positions must be of these disks ([`Skin::is_built_for`]).
    pub fn largest_displacement_sq(
        &self,
        range: Range<usize>,
        particles: &Particles,
        domain: &Domain,
    ) -> f64 {
        match domain.boundary {
            Boundary::Walls => self.largest_displacement_in::<false>(range, particles, domain),
            Boundary::Periodic => self.largest_displacement_in::<true>(range, particles, domain),
        }
    }

    fn largest_displacement_in<const PERIODIC: bool>(
        &self,
        range: Range<usize>,
        particles: &Particles,
        domain: &Domain,
    ) -> f64 {
        let moved_sq = |x0: f64, y0: f64, x: f64, y: f64| {
            let (dx, dy) = domain.separation_in::<PERIODIC>(x0, y0, x, y);
            dx * dx + dy * dy
        };
        // NaN propagates: a comparison that fails keeps the NaN (see `is_exceeded`).
        let larger = |a: f64, b: f64| if a >= b || a.is_nan() { a } else { b };
        let (x, y) = (&particles.x[range.clone()], &particles.y[range.clone()]);
        let (x0, y0) = (&self.x_built[range.clone()], &self.y_built[range]);
        // Four independent running maxima (selects, not `f64::max` with its NaN rules),
        // so the loop vectorises; then the largest of the four.
        let mut largest = [0.0_f64; 4];
        let (x4, y4) = (x.chunks_exact(4), y.chunks_exact(4));
        let (x04, y04) = (x0.chunks_exact(4), y0.chunks_exact(4));
        let tail = x4.remainder().iter().zip(y4.remainder());
        let built_tail = x04.remainder().iter().zip(y04.remainder());
        for (((x, y), x0), y0) in x4.zip(y4).zip(x04).zip(y04) {
            for lane in 0..4 {
                let d_sq = moved_sq(x0[lane], y0[lane], x[lane], y[lane]);
                largest[lane] = larger(largest[lane], d_sq);
            }
        }
        for ((&x, &y), (&x0, &y0)) in tail.zip(built_tail) {
            largest[0] = larger(largest[0], moved_sq(x0, y0, x, y));
        }
        largest.into_iter().fold(0.0, larger)
    }

    /// Appends the storage indices, in order, of the disks stored in `range` that moved
    /// half the skin since the last build: the lists may miss their pairs, and only theirs.
    pub fn escapees(
        &self,
        range: Range<usize>,
        particles: &Particles,
        domain: &Domain,
        escapees: &mut Vec<u32>,
    ) {
        let half = 0.5 * SAFE_SKIN_FRACTION * self.width;
        for idx in range {
            let (x0, y0) = (self.x_built[idx], self.y_built[idx]);
            let (dx, dy) = domain.separation(x0, y0, particles.x[idx], particles.y[idx]);
            let moved_sq = dx * dx + dy * dy;
            if moved_sq.is_nan() || moved_sq >= half * half {
                escapees.push(idx as u32);
            }
        }
    }

    /// True when a list may serve `n_escapees` disks that moved at most
    /// √`largest_displacement_sq`, with their pairs found by queries around them
    /// (`StripGrid::find_contacts_of`): few of them, and not much further than the skin
    /// (a query's cost grows with its reach). Otherwise the lists are rebuilt.
    pub fn may_patch(
        &self,
        n_escapees: usize,
        n_particles: usize,
        largest_displacement_sq: f64,
    ) -> bool {
        n_escapees * MAX_ESCAPEE_SHARE <= n_particles
            && largest_displacement_sq <= self.width * self.width
    }

    /// Records the disks' positions as those of a build.
    pub fn record(&mut self, particles: &Particles) {
        self.x_built.clone_from(&particles.x);
        self.y_built.clone_from(&particles.y);
    }

    /// Where the disk stored at `idx` was at the last build: `(x, y)`.
    pub fn built_position(&self, idx: usize) -> (f64, f64) {
        (self.x_built[idx], self.y_built[idx])
    }
}

/// One list of candidate pairs (storage indices), in the order the grid found them.
#[derive(Clone, Debug, Default)]
pub struct PairList {
    pairs: Vec<[u32; 2]>,
    /// Disks the list was built for: every listed index is below it.
    n_particles: usize,
    /// Every disk had the same radius at the build (radii never change).
    equal_radii: bool,
}

impl PairList {
    /// Rebuilds the list from the pairs the owned strips `strips` of `grid` find within
    /// `skin` of touching. `grid` must be built for these disks' current positions, with
    /// strips at least `2 · max_radius + skin` tall.
    pub fn rebuild(
        &mut self,
        grid: &StripGrid,
        strips: Range<usize>,
        particles: &Particles,
        domain: &Domain,
        skin: &Skin,
    ) {
        self.pairs.clear();
        grid.find_pairs_in(strips, domain, skin.width(), &mut self.pairs);
        self.n_particles = particles.len();
        self.equal_radii = grid.layout().has_equal_radii();
    }

    /// Appends the listed pairs that overlap now, in list order, with the grid's test.
    pub fn find_contacts(
        &self,
        particles: &Particles,
        domain: &Domain,
        contacts: &mut Vec<Contact>,
    ) {
        assert_eq!(
            self.n_particles,
            particles.len(),
            "a list built for these disks"
        );
        match (domain.boundary, self.equal_radii) {
            (Boundary::Walls, true) => self.filter::<false, true>(particles, domain, contacts),
            (Boundary::Walls, false) => self.filter::<false, false>(particles, domain, contacts),
            (Boundary::Periodic, true) => self.filter::<true, true>(particles, domain, contacts),
            (Boundary::Periodic, false) => self.filter::<true, false>(particles, domain, contacts),
        }
    }

    /// The overlap test of every listed pair. With `EQUAL_RADII` the contact distance
    /// is read once: `r + r` has the same bits for every pair.
    fn filter<const PERIODIC: bool, const EQUAL_RADII: bool>(
        &self,
        particles: &Particles,
        domain: &Domain,
        contacts: &mut Vec<Contact>,
    ) {
        let (x, y, radius) = (&particles.x[..], &particles.y[..], &particles.radius[..]);
        let equal_contact = radius.first().map_or(0.0, |r| r + r);
        for &[a, b] in &self.pairs {
            let (a, b) = (a as usize, b as usize);
            // SAFETY: the list was built for disks of this count (asserted by the
            // caller), from storage indices below it; x, y and radius have that length.
            let (xa, ya, xb, yb, contact) = unsafe {
                let contact = if EQUAL_RADII {
                    equal_contact
                } else {
                    radius.get_unchecked(a) + radius.get_unchecked(b)
                };
                (
                    *x.get_unchecked(a),
                    *y.get_unchecked(a),
                    *x.get_unchecked(b),
                    *y.get_unchecked(b),
                    contact,
                )
            };
            let (dx, dy) = domain.separation_in::<PERIODIC>(xa, ya, xb, yb);
            if dx * dx + dy * dy < contact * contact {
                contacts.push(Contact::new(particles, a, b));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::sim::grid::StripGrid;
    use crate::sim::scene::{GasSpec, MassRule, RadiusDistribution};
    use crate::sim::{Boundary, Broadphase, Physics, StepParams, Stepper};

    /// Every step, the stepper's lists (with their rebuilds and escapee queries) find
    /// exactly the pairs a fresh search of the whole box finds: walls and periodic,
    /// unequal radii, dilute and dense, and steps long enough (up to half a radius for
    /// the rms disk) that disks escape the lists often.
    #[test]
    fn listed_contacts_are_exactly_those_of_a_fresh_search_every_step() {
        for boundary in [Boundary::Walls, Boundary::Periodic] {
            for packing in [0.05, 0.35] {
                for dt in [0.1, 0.5] {
                    let scene = GasSpec {
                        radius: RadiusDistribution::Uniform { min: 0.5, max: 1.5 },
                        mass: MassRule::Area,
                        boundary,
                        physics: Physics::with_restitution(0.9),
                        seed: 7,
                        ..GasSpec::unit(3000, packing)
                    }
                    .build()
                    .expect("places");
                    let params = StepParams {
                        dt,
                        broadphase: Broadphase::Grid,
                    };
                    let mut particles = scene.particles.clone();
                    let mut stepper = Stepper::for_scene(&scene, params);
                    let mut rebuilt_or_patched = 0;
                    for step in 0..150 {
                        stepper.advance(&mut particles);
                        stepper.find_contacts(&mut particles);
                        rebuilt_or_patched += usize::from(!stepper.escapees.is_empty());
                        let mut fresh = Vec::new();
                        let mut grid = StripGrid::new(&scene.domain, &particles);
                        grid.build(&particles);
                        grid.find_contacts(&particles, &scene.domain, &mut fresh);
                        fresh.sort_unstable_by_key(|contact| contact.key);
                        let keys = |contacts: &[_]| -> Vec<u64> {
                            contacts
                                .iter()
                                .map(|c: &crate::sim::grid::Contact| c.key)
                                .collect()
                        };
                        assert_eq!(
                            keys(stepper.contacts()),
                            keys(&fresh),
                            "{boundary:?} packing {packing} dt {dt} step {step}"
                        );
                        stepper.resolve_contacts(&mut particles);
                    }
                    assert!(rebuilt_or_patched > 0, "escapees were served at dt {dt}");
                }
            }
        }
    }
}
