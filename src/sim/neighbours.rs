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

use super::grid::{Contact, StripGrid, StripLayout};
use super::particles::{DiskFigures, Particles, ReorderScratch};
use super::pieces::{MIN_STREAMING_PIECE, Pieces, split_at_ranges};
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

/// In scenes of [`EARLY_REBUILD_DISKS`] disks or more, lists serve on while at most one
/// disk in this many escaped. A query there reads the grid and the disks far beyond the
/// caches (from 10⁵ to 10⁷ disks the queries' cost per disk-step grew 1.9 times at
/// packing 0.3 and 3.3 times at 0.05, the rebuild's scan not at all), so rebuilding
/// sooner pays: at 2·10⁶ and 10⁷ disks the serial step ran 1.01–1.05 times as fast; at
/// 10⁶ and packing 0.3 it did not (0.98–1.00), at 10⁵ it ran slower (0.975)
/// (`docs/performance.md`).
const MAX_ESCAPEE_SHARE_LARGE: usize = 256;

/// Scenes from this many disks on rebuild their lists by [`MAX_ESCAPEE_SHARE_LARGE`]:
/// larger than the scenes the stepper re-stores more often (`sim::step`), since 10⁶ disks
/// at packing 0.3 did not gain.
const EARLY_REBUILD_DISKS: usize = 1 << 20;

/// Lists serve on while no disk moved further than this many skins (with queries for
/// the escapees); a query's reach, and cost, grows with the distance.
const MAX_PATCH_SKINS: f64 = 1.0;

/// A disk escapes a list once it moved this fraction of half the skin (less the
/// rounding of the recorded positions, [`Skin::rounding`]): the margin covers rounding
/// in the displacement and distance arithmetic.
const SAFE_SKIN_FRACTION: f64 = 0.999;

/// The skin of a scene's lists and the positions they were last built at.
#[derive(Clone, Debug, Default)]
pub struct Skin {
    width: f64,
    /// Positions at the last build, by storage index, rounded to f32: half the memory
    /// and half the reads of the move that measures the displacements.
    x_built: Vec<f32>,
    y_built: Vec<f32>,
    /// A bound on how far a recorded (rounded) position is from the disk's position at
    /// the build: every displacement measured from the record is within this of the
    /// true one, and the escape distance and the largest displacement allow for it.
    rounding: f64,
    /// Per block of [`DISPLACEMENT_BLOCK`] disks (by storage index): which of them had
    /// moved half the skin since the build, as of the last move (bit i: the block's
    /// disk i).
    escaped: Vec<u64>,
    /// Whether the last move marked `escaped` ([`Skin::tracking`]) and nothing read it
    /// yet.
    tracked: bool,
}

/// Disks per block of the displacement record: the bits of a `u64`.
pub const DISPLACEMENT_BLOCK: usize = 64;

/// A move's view of the lists' record (of one chunk of disks, starting at a block
/// boundary): where the disks were at the build, how far is half the skin, and the
/// blocks' marks to fill.
pub struct Displacements<'a> {
    pub x_built: &'a [f32],
    pub y_built: &'a [f32],
    /// The square of the distance at which a disk escapes the lists.
    pub escape_sq: f64,
    pub escaped: &'a mut [u64],
}

impl<'a> Displacements<'a> {
    /// The record cut into the chunks of `chunk` disks (a multiple of
    /// [`DISPLACEMENT_BLOCK`]) that moves in parallel take.
    pub fn into_chunks(self, chunk: usize) -> impl Iterator<Item = Displacements<'a>> {
        assert_eq!(chunk % DISPLACEMENT_BLOCK, 0, "chunks of whole blocks");
        let escape_sq = self.escape_sq;
        self.x_built
            .chunks(chunk)
            .zip(self.y_built.chunks(chunk))
            .zip(self.escaped.chunks_mut(chunk / DISPLACEMENT_BLOCK))
            .map(move |((x_built, y_built), escaped)| Displacements {
                x_built,
                y_built,
                escape_sq,
                escaped,
            })
    }

    /// Marks the escapees from the disks' positions now (`x`, `y`: the chunk's).
    pub fn measure(self, x: &[f64], y: &[f64], domain: &Domain) {
        match domain.boundary {
            Boundary::Walls => self.measure_in::<false>(x, y, domain),
            Boundary::Periodic => self.measure_in::<true>(x, y, domain),
        }
    }

    fn measure_in<const PERIODIC: bool>(self, x: &[f64], y: &[f64], domain: &Domain) {
        let blocks = x
            .chunks(DISPLACEMENT_BLOCK)
            .zip(y.chunks(DISPLACEMENT_BLOCK))
            .zip(self.x_built.chunks(DISPLACEMENT_BLOCK))
            .zip(self.y_built.chunks(DISPLACEMENT_BLOCK));
        for ((((x, y), x0), y0), escaped) in blocks.zip(self.escaped.iter_mut()) {
            *escaped = mark_escapees::<PERIODIC>(x, y, x0, y0, domain, self.escape_sq);
        }
    }
}

/// Which disks of one block (bit i: disk i) moved from (`x0`, `y0`) to (`x`, `y`) at
/// least √`escape_sq`, or went astray (NaN). Branch-free; later searches for escapees
/// read the bits instead of the positions.
#[inline(always)]
pub fn mark_escapees<const PERIODIC: bool>(
    x: &[f64],
    y: &[f64],
    x0: &[f32],
    y0: &[f32],
    domain: &Domain,
    escape_sq: f64,
) -> u64 {
    let n = x.len().min(DISPLACEMENT_BLOCK);
    let (x, y, x0, y0) = (&x[..n], &y[..n], &x0[..n], &y0[..n]);
    let mut escaped = 0;
    for i in 0..n {
        let (x0, y0) = (f64::from(x0[i]), f64::from(y0[i]));
        let (dx, dy) = domain.separation_in::<PERIODIC>(x0, y0, x[i], y[i]);
        escaped |= u64::from(has_escaped(dx * dx + dy * dy, escape_sq)) << i;
    }
    escaped
}

/// True when a disk that moved √`moved_sq` escaped lists whose escape distance is
/// √`escape_sq`; a disk gone astray (NaN) has escaped too. Branch-free.
#[inline(always)]
fn has_escaped(moved_sq: f64, escape_sq: f64) -> bool {
    moved_sq.is_nan() | (moved_sq >= escape_sq)
}

/// The larger of two squared distances, NaN winning (a disk gone astray makes the
/// lists stale: [`Skin::is_exceeded`]).
#[inline(always)]
fn larger(a: f64, b: f64) -> f64 {
    if a >= b || a.is_nan() { a } else { b }
}

impl Skin {
    /// The skin for `particles` in `domain` stepped by `dt`: wider in dilute gases
    /// ([`SKIN_RADII_DILUTE`], [`SKIN_RADII_DENSE`]), at most [`SKIN_STEPS`] steps of
    /// the fastest disk, and in a small periodic box narrow enough that the strips stay
    /// at least three to a side (no pair seen through two images). A width of 0 means
    /// the lists are rebuilt every step.
    pub fn for_scene(domain: &Domain, particles: &Particles, dt: f64) -> Skin {
        Skin::for_figures(domain, &particles.figures(), dt)
    }

    /// [`Skin::for_scene`] for a scene of these figures.
    pub fn for_figures(domain: &Domain, figures: &DiskFigures, dt: f64) -> Skin {
        let max_radius = figures.max_radius;
        let packing = figures.disk_area / domain.area();
        let dense = ((packing - 0.05) / (0.3 - 0.05)).clamp(0.0, 1.0);
        let radii = SKIN_RADII_DILUTE + dense * (SKIN_RADII_DENSE - SKIN_RADII_DILUTE);
        let longest_step = figures.max_speed * dt;
        let mut width = (radii * max_radius)
            .min(SKIN_STEPS * longest_step)
            .max(MIN_SKIN_RADII * max_radius);
        if domain.boundary == Boundary::Periodic {
            let widest = domain.width.min(domain.height) / 3.0 - 2.0 * max_radius;
            width = width.min(widest);
        }
        Skin::with_width(width.max(0.0))
    }

    /// The skin ([`Skin::for_figures`]) and the whole box's strip grid for it, built for
    /// `particles`, from one pass over the disks for their figures.
    pub fn with_grid(domain: &Domain, particles: &Particles, dt: f64) -> (Skin, StripGrid) {
        let figures = particles.figures();
        let skin = Skin::for_figures(domain, &figures, dt);
        let layout = StripLayout::for_figures(domain, &figures, skin.width());
        (skin, StripGrid::whole(domain, layout, particles))
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

    /// The square of the distance, measured from the recorded positions, at which a
    /// disk escapes the lists: half the skin, less a margin for rounding and less the
    /// rounding of the record, so that a disk that did not escape moved less than half
    /// the skin.
    fn escape_sq(&self) -> f64 {
        let half = (0.5 * SAFE_SKIN_FRACTION * self.width - self.rounding).max(0.0);
        half * half
    }

    /// True when a disk that moved √`largest_displacement_sq` makes the lists stale.
    pub fn is_exceeded(&self, largest_displacement_sq: f64) -> bool {
        has_escaped(largest_displacement_sq, self.escape_sq())
    }

    /// The slices a move fills in for the lists ([`crate::sim::step::advance_disks`]):
    /// the positions of the last build and the per-block marks of escapees. `None`
    /// before the first build, or when the move is of another number of disks
    /// (`n_particles`) than the build. What the move records is read by the next
    /// [`Skin::largest_displacement_sq`].
    pub fn tracking(&mut self, n_particles: usize) -> Option<Displacements<'_>> {
        if self.x_built.len() != n_particles {
            return None;
        }
        self.tracked = true;
        Some(self.displacements())
    }

    fn displacements(&mut self) -> Displacements<'_> {
        Displacements {
            x_built: &self.x_built,
            y_built: &self.y_built,
            escape_sq: self.escape_sq(),
            escaped: &mut self.escaped,
        }
    }

    /// A bound on the square of the largest distance a disk moved since the last
    /// build, if one escaped (the lists are stale: [`Skin::is_exceeded`]), and 0 if none
    /// did; infinite before the first build. Reads what the last move marked
    /// ([`Skin::tracking`]), or, if the disks were not moved through it since, marks
    /// now. Afterwards [`Skin::escapees`] may ask which disks escaped. The escapees are
    /// measured in `pieces`, their results taken together with [`larger`]: the same
    /// result however the disks are cut.
    pub fn largest_displacement_sq(
        &mut self,
        particles: &Particles,
        domain: &Domain,
        pieces: &impl Pieces,
    ) -> f64 {
        if !self.is_built_for(particles) {
            return f64::INFINITY;
        }
        if !std::mem::take(&mut self.tracked) {
            self.displacements()
                .measure(&particles.x, &particles.y, domain);
        }
        // Over the disks of a range (starting at a block boundary), the square of the
        // farthest escapee's displacement, 0 if none.
        let farthest = |range: Range<usize>| {
            let mut largest = 0.0;
            self.for_each_escapee(range, |idx| {
                let (x0, y0) = (f64::from(self.x_built[idx]), f64::from(self.y_built[idx]));
                let (dx, dy) = domain.separation(x0, y0, particles.x[idx], particles.y[idx]);
                largest = larger(largest, dx * dx + dy * dy);
            });
            largest
        };
        let ranges = pieces.cut(particles.len(), DISPLACEMENT_BLOCK, DISPLACEMENT_BLOCK);
        let largest = pieces.map(ranges, farthest).into_iter().fold(0.0, larger);
        if largest > 0.0 {
            // Measured from the rounded record: the true distance may be longer.
            let bound = largest.sqrt() + self.rounding;
            bound * bound
        } else {
            largest
        }
    }

    /// Appends the storage indices, in order, of the disks stored in `range` that moved
    /// half the skin since the last build: the lists may miss their pairs, and only
    /// theirs. Reads the marks of [`Skin::largest_displacement_sq`]. `range` starts at
    /// a block boundary.
    pub fn escapees(&self, range: Range<usize>, escapees: &mut Vec<u32>) {
        self.for_each_escapee(range, |idx| escapees.push(idx as u32));
    }

    /// Calls `visit` with the storage index of every escapee in `range` (which starts
    /// at a block boundary), in order.
    fn for_each_escapee(&self, range: Range<usize>, mut visit: impl FnMut(usize)) {
        debug_assert_eq!(range.start % DISPLACEMENT_BLOCK, 0);
        let blocks = range.start / DISPLACEMENT_BLOCK..range.end.div_ceil(DISPLACEMENT_BLOCK);
        for block in blocks {
            let mut marks = self.escaped[block];
            while marks != 0 {
                visit(block * DISPLACEMENT_BLOCK + marks.trailing_zeros() as usize);
                marks &= marks - 1;
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
        let share = if n_particles < EARLY_REBUILD_DISKS {
            MAX_ESCAPEE_SHARE
        } else {
            MAX_ESCAPEE_SHARE_LARGE
        };
        n_escapees * share <= n_particles && self.may_reach(largest_displacement_sq)
    }

    /// True when queries may serve disks that moved √`largest_displacement_sq`: at most
    /// [`MAX_PATCH_SKINS`] skins.
    pub fn may_reach(&self, largest_displacement_sq: f64) -> bool {
        let reach = self.patch_reach();
        largest_displacement_sq <= reach * reach
    }

    /// The furthest a disk may have moved while queries serve the escapees:
    /// [`MAX_PATCH_SKINS`] skins.
    pub fn patch_reach(&self) -> f64 {
        MAX_PATCH_SKINS * self.width
    }

    /// Records the disks' positions as those of a build, rounded in `pieces`.
    pub fn record(&mut self, particles: &Particles, pieces: &impl Pieces) {
        let n = particles.len();
        self.x_built.resize(n, 0.0);
        self.y_built.resize(n, 0.0);
        let ranges = pieces.cut(n, MIN_STREAMING_PIECE, 1);
        let x_built = split_at_ranges(&mut self.x_built, &ranges);
        let y_built = split_at_ranges(&mut self.y_built, &ranges);
        let cut = ranges.into_iter().zip(x_built).zip(y_built);
        let largest = pieces.map(cut, |((range, x_built), y_built)| {
            round_positions(
                &particles.x[range.clone()],
                &particles.y[range],
                x_built,
                y_built,
            )
        });
        let largest = largest.into_iter().fold(0.0, f64::max);
        // Rounding to f32 moves a coordinate by at most 2⁻²⁴ of its magnitude (or by a
        // subnormal step near 0), a position by √2 times that, within 2⁻²³.
        self.rounding = largest * 2.0_f64.powi(-23) + f64::from(f32::MIN_POSITIVE);
        self.escaped.clear();
        self.escaped.resize(n.div_ceil(DISPLACEMENT_BLOCK), 0);
        self.tracked = false;
    }
}

/// Rounds the positions `x`, `y` to f32 into `x_built`, `y_built` (as long), and
/// returns the largest magnitude of a coordinate, NaN coordinates left out (such a disk
/// escapes by its NaN displacement): what bounds the rounding. The same result however
/// the disks are cut into pieces, the largest of the pieces' being the whole's.
fn round_positions(x: &[f64], y: &[f64], x_built: &mut [f32], y_built: &mut [f32]) -> f64 {
    for (values, record) in [(x, x_built), (y, y_built)] {
        for (value, rounded) in values.iter().zip(record) {
            *rounded = *value as f32;
        }
    }
    // A pass of its own: folded into the rounding pass, the step measured 2.3% slower
    // (serial, 20,000 disks, the CI check's A/B).
    (x.iter().chain(y)).fold(0.0_f64, |largest, v| largest.max(v.abs()))
}

/// Listed pairs tested together by [`PairList::find_contacts`].
const FILTER_GROUP: usize = 4;

/// One list of candidate pairs (storage indices), in the order the grid found them.
#[derive(Clone, Debug, Default)]
pub struct PairList {
    pairs: Vec<[u32; 2]>,
    /// Disks the list was built for: every listed index is below it.
    n_particles: usize,
    /// Every disk had the same radius at the build (radii never change).
    equal_radii: bool,
    /// Pairs the list held when its memory was last released ([`PairList::release`]).
    released_len: usize,
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
        // Filled as a local: lists of other bands sit in the same cache line as this
        // one's length, which every candidate updates (false sharing between threads).
        let mut pairs = std::mem::take(&mut self.pairs);
        pairs.clear();
        // After a release, room for as many pairs as before and an eighth: growing by
        // doubling instead would copy the list and hold both copies at once, which at
        // 10⁷ disks raised the peak memory by 10 bytes per disk.
        pairs.reserve(self.released_len + self.released_len / 8);
        self.released_len = 0;
        grid.find_pairs_in(strips, particles, domain, skin.width(), &mut pairs);
        self.pairs = pairs;
        self.n_particles = particles.len();
        self.equal_radii = grid.layout().has_equal_radii();
    }

    /// Frees the list's memory (for the disks' re-storing to take), remembering how
    /// many pairs it held: the next [`PairList::rebuild`] makes room for about as many at
    /// once.
    pub fn release(&mut self) {
        self.released_len = self.pairs.len();
        self.pairs = Vec::new();
    }

    /// Appends the listed pairs that overlap now, in list order, with the grid's test.
    /// Disks appended after the build (a rank's reported escapees, which it queries
    /// for) are in no listed pair.
    pub fn find_contacts(
        &self,
        particles: &Particles,
        domain: &Domain,
        contacts: &mut Vec<Contact>,
    ) {
        assert!(
            self.n_particles <= particles.len(),
            "a list built for these disks ({}), not for {}",
            self.n_particles,
            particles.len()
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
        let (x, y) = (&particles.x[..], &particles.y[..]);
        let equal_contact = particles.radius.iter().next().map_or(0.0, |r| r + r);
        // Unequal radii are held one per disk.
        let radius = particles.radius.as_slice().unwrap_or_default();
        assert!(EQUAL_RADII || radius.len() == x.len(), "a radius per disk");
        // SAFETY: the list was built for disks of this count (asserted by the caller),
        // from storage indices below it; x, y and radius have that length.
        let overlaps = |[a, b]: [u32; 2]| unsafe {
            let (a, b) = (a as usize, b as usize);
            let contact = if EQUAL_RADII {
                equal_contact
            } else {
                radius.get_unchecked(a) + radius.get_unchecked(b)
            };
            let (xa, ya) = (*x.get_unchecked(a), *y.get_unchecked(a));
            let (xb, yb) = (*x.get_unchecked(b), *y.get_unchecked(b));
            let (dx, dy) = domain.separation_in::<PERIODIC>(xa, ya, xb, yb);
            dx * dx + dy * dy < contact * contact
        };
        // Few pairs overlap: a group of pairs is tested whole, and looked into only when
        // one of them does (one well-predicted branch per group instead of per pair).
        let mut groups = self.pairs.chunks_exact(FILTER_GROUP);
        for group in &mut groups {
            let hits: [bool; FILTER_GROUP] = std::array::from_fn(|k| overlaps(group[k]));
            if hits.iter().any(|&hit| hit) {
                // Every pair of the group written, the length moved on by the hits: no
                // branch per pair here either.
                contacts.reserve(FILTER_GROUP);
                for (&[a, b], hit) in group.iter().zip(hits) {
                    let len = contacts.len();
                    // SAFETY: `reserve` left room for the whole group; the length grows
                    // over a written contact only.
                    unsafe {
                        let contact = Contact { a, b };
                        contacts.as_mut_ptr().add(len).write(contact);
                        contacts.set_len(len + usize::from(hit));
                    }
                }
            }
        }
        for &[a, b] in groups.remainder() {
            if overlaps([a, b]) {
                contacts.push(Contact { a, b });
            }
        }
    }
}

/// Runs `work`, a re-storing of `n_disks` disks, in scratch memory, and leaves every one
/// of `lists` empty, to be rebuilt. A re-storing needs 12 bytes per disk: 4 for the new
/// order and 8 for a spare array of values (one in place, the serial stepper's once the
/// disks are near grid order, uses only the order: `Particles::store_in_order`). Lists
/// about to be rebuilt lend their memory when it holds that much: one list both parts
/// (the serial stepper's in a dense gas holds some 20 bytes per disk), or one the order
/// and another the values (the two band lists of two threads hold some 10 each). Then
/// the re-storing takes no memory and the lists, rebuilt into the same pages, wait for
/// no fresh ones (at 10⁷ disks the kernel's page faults made one scan in two a third
/// slower). A lone list too short (the serial stepper's or a rank's in a dilute gas,
/// some 4 bytes per disk) grows to 12 and keeps that room: fresh scratch for 10⁷ disks came from new pages at every
/// re-storing (too large for the allocator to keep), and a serial run at packing 0.05
/// took 1.09 times as long; the peak memory, set by the re-storing, is the same.
/// Otherwise every list is released and the scratch is fresh memory, taking their
/// place: the threads that fill it fault its pages in parallel.
pub fn with_reorder_scratch<R>(
    lists: &mut [PairList],
    n_disks: usize,
    work: impl FnOnce(ReorderScratch<'_>) -> R,
) -> R {
    if let [list] = lists {
        // Room for the order (n words) and n values (2n words, and one more should the
        // values need aligning): a list that long lends both. A shorter one (a dilute
        // gas's) grows to it, its pairs kept and only the rest written, and keeps the
        // room for the next re-storings and builds.
        let room = (3 * n_disks + 2).div_ceil(2);
        if list.pairs.len() < room {
            list.pairs.resize(room, [0, 0]);
        }
    }
    let result = match lent_scratch(lists, n_disks) {
        Some(scratch) => work(scratch),
        None => {
            lists.iter_mut().for_each(PairList::release);
            // Zeroed by the allocator: fresh pages, not a pass writing zeros.
            let (mut order, mut spare) = (vec![0; n_disks], vec![0.0; n_disks]);
            work(ReorderScratch {
                order: &mut order,
                spare: &mut spare,
            })
        }
    };
    for list in lists {
        list.pairs.clear();
        list.n_particles = 0;
    }
    result
}

/// The scratch of a re-storing of `n_disks` disks in the memory of `lists`, if they hold
/// enough ([`with_reorder_scratch`]): the order and then the values from the longest
/// list when it holds both, else the values from it and the order from the next longest.
fn lent_scratch(lists: &mut [PairList], n_disks: usize) -> Option<ReorderScratch<'_>> {
    let mut by_length: Vec<&mut [u32]> = lists
        .iter_mut()
        .map(|list| list.pairs.as_flattened_mut())
        .collect();
    by_length.sort_unstable_by_key(|words| std::cmp::Reverse(words.len()));
    let mut longest = by_length.into_iter();
    let first = longest.next()?;
    // The values start on a multiple of 8 bytes: in the longest list after the order
    // when both fit, else in the whole of it.
    let (order, values) = if first.len() > 3 * n_disks {
        let (order, rest) = first.split_at_mut(n_disks);
        (order, rest)
    } else {
        (longest.next()?.get_mut(..n_disks)?, first)
    };
    // SAFETY: every bit pattern of the words is a valid f64.
    let (_, aligned, _) = unsafe { values.align_to_mut::<f64>() };
    Some(ReorderScratch {
        order,
        spare: aligned.get_mut(..n_disks)?,
    })
}

#[cfg(test)]
mod tests {
    use crate::sim::grid::{Contact, StripGrid};
    use crate::sim::particles::Particles;
    use crate::sim::pieces::{Backwards, InTurn};
    use crate::sim::scene::Scene;
    use crate::sim::scene::{GasSpec, MassRule, RadiusDistribution, wrap_periodic};
    use crate::sim::{Boundary, Broadphase, Physics, StepParams, Stepper};

    /// A gas of 3000 disks of radii drawn from 0.5 to 1.5, mass by area, walls: the
    /// lists' hardest case (pairs of every contact distance).
    fn unequal_gas(packing: f64, seed: u64) -> GasSpec {
        GasSpec {
            radius: RadiusDistribution::Uniform { min: 0.5, max: 1.5 },
            mass: MassRule::Area,
            seed,
            ..GasSpec::unit(3000, packing)
        }
    }

    /// Lists serve on while one disk in 64 escaped, in a scene of 2²⁰ disks or more one
    /// in 256, and never once a disk moved further than the queries reach.
    #[test]
    fn large_scenes_rebuild_their_lists_after_fewer_escapees() {
        let skin = crate::sim::neighbours::Skin::with_width(2.0);
        let within = skin.patch_reach() * skin.patch_reach();
        let small = (1 << 20) - 1;
        assert!(skin.may_patch(small / 64, small, within));
        assert!(!skin.may_patch(small / 64 + 1, small, within));
        let large = 1 << 20;
        assert!(skin.may_patch(large / 256, large, within));
        assert!(!skin.may_patch(large / 256 + 1, large, within));
        assert!(!skin.may_patch(1, large, within * 1.01));
    }

    /// The marks of a block are the disks that moved at least the escape distance, or
    /// went astray, bit i for disk i: full blocks and short ones, at walls and through
    /// a periodic edge.
    #[test]
    fn escapee_marks_are_the_disks_that_moved_the_escape_distance() {
        use crate::sim::neighbours::mark_escapees;
        use crate::sim::scene::Domain;
        for boundary in [Boundary::Walls, Boundary::Periodic] {
            let domain = Domain {
                width: 100.0,
                height: 50.0,
                boundary,
            };
            for n in [1, 7, 8, 9, 31, 63, 64] {
                // Disk i moves by 0, 0.5, 1 or 1.5 (escaping at 0.9); disk 5 goes astray.
                let moved = |i: usize| 0.5 * (i % 4) as f64;
                let x0: Vec<f64> = (0..n).map(|i| 99.5 - 0.1 * i as f64).collect();
                let y0: Vec<f64> = (0..n).map(|i| 0.2 + 0.7 * i as f64).collect();
                let mut x: Vec<f64> = (0..n).map(|i| x0[i] + 0.6 * moved(i)).collect();
                let y: Vec<f64> = (0..n).map(|i| y0[i] - 0.8 * moved(i)).collect();
                if boundary == Boundary::Periodic {
                    // Across the east edge: the move is the same.
                    x.iter_mut()
                        .for_each(|x| *x = wrap_periodic(*x, domain.width));
                }
                if n > 5 {
                    x[5] = f64::NAN;
                }
                let expected = (0..n)
                    .filter(|&i| moved(i) >= 1.0 || i == 5)
                    .fold(0_u64, |bits, i| bits | 1 << i);
                // Recorded as the lists record them, rounded to f32.
                let x0: Vec<f32> = x0.iter().map(|&x| x as f32).collect();
                let y0: Vec<f32> = y0.iter().map(|&y| y as f32).collect();
                let marks = match boundary {
                    Boundary::Walls => mark_escapees::<false>(&x, &y, &x0, &y0, &domain, 0.81),
                    Boundary::Periodic => mark_escapees::<true>(&x, &y, &x0, &y0, &domain, 0.81),
                };
                assert_eq!(marks, expected, "{boundary:?}, {n} disks");
            }
        }
    }

    /// The record of build positions is rounded to f32, which far from the origin is
    /// coarse (steps of 1 just below x = 2²⁴): still, every disk that truly moved half the skin
    /// is marked, and the largest displacement reported bounds the true one, at walls
    /// and through a periodic edge.
    #[test]
    fn a_rounded_record_misses_no_escapee_far_from_the_origin() {
        use crate::sim::neighbours::Skin;
        use crate::sim::particles::Disk;
        use crate::sim::scene::Domain;
        for boundary in [Boundary::Walls, Boundary::Periodic] {
            let domain = Domain {
                width: 16_777_216.0,
                height: 64.0,
                boundary,
            };
            let skin_width = 12.0;
            // Disks along the east edge, at positions f32 cannot hold, each moving a
            // different fraction of 0 to 1.2 half skins in a different direction.
            let n = 500;
            let disk = |i: usize| {
                let x = domain.width - 1.0 - 0.3 * i as f64 - 0.1234567;
                Disk {
                    x,
                    y: 2.0 + 0.1 * i as f64,
                    vx: 0.0,
                    vy: 0.0,
                    radius: 1.0,
                    mass: 1.0,
                }
            };
            let built = Particles::from_disks(&(0..n).map(disk).collect::<Vec<_>>());
            let mut skin = Skin::with_width(skin_width);
            skin.record(&built, &InTurn);
            let mut moved = built.clone();
            let mut true_largest: f64 = 0.0;
            let mut escaped = Vec::new();
            for i in 0..n {
                let distance = 1.2 * 0.5 * skin_width * i as f64 / n as f64;
                let angle = 0.37 * i as f64;
                let x = built.x[i] + distance * angle.cos();
                moved.x[i] = match boundary {
                    Boundary::Walls => x,
                    Boundary::Periodic => wrap_periodic(x, domain.width),
                };
                moved.y[i] = built.y[i] + distance * angle.sin();
                true_largest = true_largest.max(distance);
                if distance >= 0.5 * skin_width {
                    escaped.push(i as u32);
                }
            }
            let largest_sq = skin.largest_displacement_sq(&moved, &domain, &InTurn);
            // As a parallel backend measures it: in pieces, the largest in the last.
            let in_pieces = skin.largest_displacement_sq(&moved, &domain, &Backwards(3));
            assert_eq!(
                in_pieces.to_bits(),
                largest_sq.to_bits(),
                "{boundary:?}: in pieces"
            );
            assert!(
                largest_sq >= true_largest * true_largest,
                "{boundary:?}: reported {} for a true {true_largest}",
                largest_sq.sqrt()
            );
            let mut marked = Vec::new();
            skin.escapees(0..n, &mut marked);
            for idx in &escaped {
                assert!(marked.contains(idx), "{boundary:?}: disk {idx} is marked");
            }
        }
    }

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
                        boundary,
                        physics: Physics::with_restitution(0.9),
                        ..unequal_gas(packing, 7)
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
                        assert_eq!(
                            sorted_keys(stepper.contacts(), &particles),
                            fresh_keys(&scene, &particles),
                            "{boundary:?} packing {packing} dt {dt} step {step}"
                        );
                        stepper.resolve_contacts(&mut particles);
                    }
                    assert!(rebuilt_or_patched > 0, "escapees were served at dt {dt}");
                }
            }
        }
    }

    /// Lists built in a run's set-up, before the first move ([`Stepper::build_lists`]),
    /// change no bit of what the steps give (inelastic disks, dilute and dense): the
    /// same disks by id, the same counters.
    #[test]
    fn lists_built_before_the_first_step_change_no_result() {
        for packing in [0.05, 0.35] {
            let scene = GasSpec {
                physics: Physics::with_restitution(0.9),
                ..unequal_gas(packing, 11)
            }
            .build()
            .expect("places");
            let params = StepParams {
                dt: 0.2,
                broadphase: Broadphase::Grid,
            };
            let run = |build_first: bool| {
                let mut particles = scene.particles.clone();
                let mut stepper = Stepper::for_scene(&scene, params);
                if build_first {
                    stepper.build_lists(&mut particles);
                }
                for _ in 0..60 {
                    stepper.step(&mut particles);
                }
                (particles.disks_by_id(), stepper.counters())
            };
            let (lazily, built_first) = (run(false), run(true));
            assert!(
                lazily.1.pair_collisions > 0,
                "packing {packing}: the disks collide"
            );
            assert_eq!(lazily, built_first, "packing {packing}");
        }
    }

    /// A re-storing that works in the lists' memory stores the disks as one in fresh
    /// memory does, bit for bit, with unequal radii and masses (six arrays to carry):
    /// a dense gas's list lends both parts of the scratch, the two lists of two bands
    /// one part each; a dilute gas's lists are too small and give up their memory
    /// instead, with the same result. Either way the disks are only reordered, and the
    /// lists are left empty.
    #[test]
    fn a_restoring_in_the_lists_memory_stores_the_disks_as_in_fresh_memory() {
        use crate::sim::neighbours::{PairList, Skin, lent_scratch, with_reorder_scratch};
        use crate::sim::particles::ReorderScratch;
        for packing in [0.05, 0.35] {
            let scene = unequal_gas(packing, 5).build().expect("places");
            let n = scene.particles.len();
            let skin = Skin::for_scene(&scene.domain, &scene.particles, 0.1);
            let mut grid = StripGrid::with_skin(&scene.domain, &scene.particles, skin.width());
            grid.build(&scene.particles);
            let mut in_fresh = scene.particles.clone();
            let (mut order, mut spare) = (vec![0; n], vec![0.0; n]);
            let scratch = ReorderScratch {
                order: &mut order,
                spare: &mut spare,
            };
            grid.clone()
                .store_in_grid_order(&mut in_fresh, scratch, &InTurn);
            let halves = grid.bands(2);
            assert_eq!(halves.len(), 2, "two bands");
            let built = |strips: &[std::ops::Range<usize>]| -> Vec<PairList> {
                strips
                    .iter()
                    .map(|strips| {
                        let mut list = PairList::default();
                        list.rebuild(
                            &grid,
                            strips.clone(),
                            &scene.particles,
                            &scene.domain,
                            &skin,
                        );
                        list
                    })
                    .collect()
            };
            for mut lists in [built(&[grid.owned()]), built(&halves)] {
                let lends = lent_scratch(&mut lists, n).is_some();
                assert_eq!(
                    lends,
                    packing > 0.3,
                    "packing {packing}, {} lists",
                    lists.len()
                );
                let mut in_lists = scene.particles.clone();
                with_reorder_scratch(&mut lists, n, |scratch| {
                    grid.clone()
                        .store_in_grid_order(&mut in_lists, scratch, &InTurn);
                });
                assert!(lists.iter().all(|list| list.pairs.is_empty()), "left empty");
                if let [list] = &lists[..] {
                    // The next re-storing finds the room in a lone list, lent or grown.
                    let bytes = list.pairs.capacity() * std::mem::size_of::<[u32; 2]>();
                    assert!(bytes >= 12 * n, "packing {packing}: {bytes} bytes kept");
                }
                assert_eq!(
                    in_lists,
                    in_fresh,
                    "packing {packing}, {} lists",
                    lists.len()
                );
            }
            assert_ne!(in_fresh.id, scene.particles.id, "the disks were reordered");
            assert_eq!(in_fresh.disks_by_id(), scene.particles.disks_by_id());
        }
    }

    /// The keys of the pairs a fresh search of the whole box finds, in canonical order.
    fn fresh_keys(scene: &Scene, particles: &Particles) -> Vec<u64> {
        let mut fresh = Vec::new();
        let grid = StripGrid::new(&scene.domain, particles);
        grid.find_contacts(particles, &scene.domain, &mut fresh);
        sorted_keys(&fresh, particles)
    }

    /// The keys of `contacts` (of `particles`) in canonical order.
    fn sorted_keys(contacts: &[Contact], particles: &Particles) -> Vec<u64> {
        let mut keys: Vec<u64> = contacts.iter().map(|c| c.key(&particles.id)).collect();
        keys.sort_unstable();
        keys
    }

    /// Disks moved other than by the stepper's move (which marks the escapees as it goes)
    /// are measured when contacts are asked for: a disk carried across the box, onto
    /// another, is found in contact with it.
    #[test]
    fn disks_moved_outside_the_step_are_measured_before_contacts_are_found() {
        let scene = GasSpec {
            seed: 11,
            ..GasSpec::unit(2000, 0.2)
        }
        .build()
        .expect("places");
        let params = StepParams {
            dt: 0.05,
            broadphase: Broadphase::Grid,
        };
        let mut particles = scene.particles.clone();
        let mut stepper = Stepper::for_scene(&scene, params);
        for _ in 0..3 {
            stepper.step(&mut particles);
        }
        // Carry the disk stored last next to the disk stored first.
        let last = particles.len() - 1;
        particles.x[last] = particles.x[0] + 1.5;
        particles.y[last] = particles.y[0];
        stepper.find_contacts(&mut particles);
        assert_eq!(
            sorted_keys(stepper.contacts(), &particles),
            fresh_keys(&scene, &particles)
        );
        assert!(!stepper.contacts().is_empty());
    }
}
