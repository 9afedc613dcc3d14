//! The box, its boundary, the contact physics, and seeded initial conditions.
//!
//! Everything here is pure: a [`GasSpec`] and its seed always give the same disks.
//! (Placement gives the memory system hints, prefetches and huge pages, that change
//! how fast the disks come, never which.)
//! Parsing scene files lives in `crate::run::scene_file`; this module only builds state.

use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::{Deserialize, Serialize};

use super::particles::{Particles, PerDisk};
use super::prefetch::prefetch;

/// Random sequential addition of equal disks jams near this area fraction in 2D.
pub const RSA_JAMMING_PACKING: f64 = 0.547;

/// Consecutive failed random tries for one disk before placement gives up.
const MAX_TRIES_PER_DISK: u32 = 20_000;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Boundary {
    /// Hard walls at x = 0, x = width, y = 0, y = height.
    Walls,
    /// The box wraps around in both directions; pairs interact through the minimum image.
    Periodic,
}

impl Boundary {
    pub fn name(self) -> &'static str {
        match self {
            Boundary::Walls => "walls",
            Boundary::Periodic => "periodic",
        }
    }
}

/// The simulation box `[0, width] × [0, height]` and what happens at its edges.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Domain {
    pub width: f64,
    pub height: f64,
    pub boundary: Boundary,
}

impl Domain {
    /// Vector from disk a to disk b; the minimum image in a periodic box.
    ///
    /// Swapping a and b negates the result exactly, so a pair's distance has the
    /// same bits whichever way round it is found.
    #[inline(always)]
    pub fn separation(&self, xa: f64, ya: f64, xb: f64, yb: f64) -> (f64, f64) {
        match self.boundary {
            Boundary::Walls => self.separation_in::<false>(xa, ya, xb, yb),
            Boundary::Periodic => self.separation_in::<true>(xa, ya, xb, yb),
        }
    }

    /// [`Domain::separation`] with the boundary fixed at compile time, for hot loops.
    /// Both give the same bits: they are the same arithmetic.
    #[inline(always)]
    pub fn separation_in<const PERIODIC: bool>(
        &self,
        xa: f64,
        ya: f64,
        xb: f64,
        yb: f64,
    ) -> (f64, f64) {
        let dx = xb - xa;
        let dy = yb - ya;
        if PERIODIC {
            (
                minimum_image(dx, self.width),
                minimum_image(dy, self.height),
            )
        } else {
            (dx, dy)
        }
    }

    pub fn area(&self) -> f64 {
        self.width * self.height
    }
}

/// `d` as its shortest periodic image along a side of `length`: in f64 for positions,
/// and in f32 for the strip grid's rounded entries ([`crate::sim::grid`]).
#[inline(always)]
pub fn minimum_image<T>(d: T, length: T) -> T
where
    T: Copy
        + PartialOrd
        + From<f32>
        + std::ops::Add<Output = T>
        + std::ops::Sub<Output = T>
        + std::ops::Mul<Output = T>
        + std::ops::Neg<Output = T>,
{
    let half = T::from(0.5) * length;
    if d > half {
        d - length
    } else if d < -half {
        d + length
    } else {
        d
    }
}

/// Maps a coordinate back into `[0, length)` after a periodic disk crossed an edge.
#[inline(always)]
pub fn wrap_periodic(coordinate: f64, length: f64) -> f64 {
    let wrapped = if coordinate >= length {
        coordinate - length
    } else if coordinate < 0.0 {
        coordinate + length
    } else {
        return coordinate;
    };
    // One box length covers any sane step; rem_euclid covers a disk that crossed more.
    let wrapped = if (0.0..=length).contains(&wrapped) {
        wrapped
    } else {
        coordinate.rem_euclid(length)
    };
    // -1e-20 + length rounds to length itself: that point belongs at 0.
    if wrapped < length { wrapped } else { 0.0 }
}

/// Contact laws and external field of a scene: the one struct a physical scene field is
/// declared in. The scene file fills it (`run::scene_file`), and it travels whole down
/// to the kernels (`sim::collision`, the wall rules), so a new field reaches them
/// without changing a signature.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Physics {
    /// Pair restitution e in [0, 1].
    pub restitution: f64,
    /// Wall restitution in [0, 1]: the fraction of normal speed a wall gives back.
    pub wall_restitution: f64,
    /// Constant acceleration, `None` when the scene has no field (then a step is a pure drift).
    pub gravity: Option<[f64; 2]>,
}

/// What a scene file that says nothing of physics gets: elastic pairs and walls, no field.
impl Default for Physics {
    fn default() -> Physics {
        Physics {
            restitution: 1.0,
            wall_restitution: 1.0,
            gravity: None,
        }
    }
}

impl Physics {
    /// Restitution `e` for pairs and walls alike, no field.
    pub fn with_restitution(e: f64) -> Physics {
        Physics {
            restitution: e,
            wall_restitution: e,
            ..Physics::default()
        }
    }

    /// Elastic pairs and walls, no field.
    pub fn elastic() -> Physics {
        Physics::default()
    }

    /// Pairs and walls give back all their normal speed: the kinetic energy is conserved.
    pub fn is_elastic(&self) -> bool {
        self.restitution == 1.0 && self.wall_restitution == 1.0
    }
}

/// A complete initial condition: box, physics and disks.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub domain: Domain,
    pub physics: Physics,
    pub particles: Particles,
}

impl Scene {
    /// Area fraction covered by disks.
    pub fn packing(&self) -> f64 {
        self.particles.disk_area() / self.domain.area()
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RadiusDistribution {
    Fixed(f64),
    /// Uniform in `[min, max]`.
    Uniform {
        min: f64,
        max: f64,
    },
}

impl RadiusDistribution {
    pub fn max(&self) -> f64 {
        match *self {
            RadiusDistribution::Fixed(r) => r,
            RadiusDistribution::Uniform { max, .. } => max,
        }
    }

    /// Mean disk area π⟨r²⟩.
    pub fn mean_area(&self) -> f64 {
        let mean_r2 = match *self {
            RadiusDistribution::Fixed(r) => r * r,
            RadiusDistribution::Uniform { min, max } => (min * min + min * max + max * max) / 3.0,
        };
        std::f64::consts::PI * mean_r2
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MassRule {
    Fixed(f64),
    /// Mass equals the disk's area π r² (unit areal density).
    Area,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Placement {
    /// Random sequential addition: uniform random non-overlapping positions.
    Random,
    /// A square lattice filling the box, for packings random addition cannot reach.
    Lattice,
}

impl Placement {
    pub fn name(self) -> &'static str {
        match self {
            Placement::Random => "random",
            Placement::Lattice => "lattice",
        }
    }

    /// The largest area fraction this placement reaches: random sequential addition jams,
    /// a square lattice holds at most π/4.
    pub fn max_packing(self) -> f64 {
        match self {
            Placement::Random => RSA_JAMMING_PACKING,
            Placement::Lattice => std::f64::consts::FRAC_PI_4,
        }
    }
}

/// How big the box is: by area fraction (square box) or by explicit size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Extent {
    Packing(f64),
    Size { width: f64, height: f64 },
}

/// A seeded random gas.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GasSpec {
    pub n_particles: usize,
    pub extent: Extent,
    pub radius: RadiusDistribution,
    pub mass: MassRule,
    /// Root-mean-square speed of the initial velocities.
    pub speed_rms: f64,
    pub placement: Placement,
    pub boundary: Boundary,
    pub physics: Physics,
    pub seed: u64,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlacementError {
    #[error(
        "packing {packing} is above {RSA_JAMMING_PACKING}, where random sequential addition jams; \
         use placement = \"lattice\" or a lower packing"
    )]
    BeyondJamming { packing: f64 },
    #[error(
        "random placement jammed at disk {placed} of {n_particles} (packing {packing:.3}) after \
         {MAX_TRIES_PER_DISK} tries; lower the packing or use placement = \"lattice\""
    )]
    Jammed {
        placed: usize,
        n_particles: usize,
        packing: f64,
    },
    #[error(
        "a {columns}×{rows} lattice of disks of radius {max_radius} does not fit in a {width}×{height} box; \
         lower n or the packing, or enlarge the box"
    )]
    LatticeTooDense {
        columns: usize,
        rows: usize,
        max_radius: f64,
        width: f64,
        height: f64,
    },
    #[error(
        "a periodic box must be at least 3 contact diameters ({min_side}) across, got {width}×{height}; \
         enlarge the box or use boundary = \"walls\""
    )]
    PeriodicBoxTooSmall {
        min_side: f64,
        width: f64,
        height: f64,
    },
}

impl GasSpec {
    /// The reference gas of benches and tests: `n_particles` disks of radius 1 and mass
    /// 1 at area fraction `packing`, v_rms = 1, random placement, elastic walls, seed 0.
    /// Change any field with struct-update syntax.
    pub fn unit(n_particles: usize, packing: f64) -> GasSpec {
        GasSpec {
            n_particles,
            extent: Extent::Packing(packing),
            radius: RadiusDistribution::Fixed(1.0),
            mass: MassRule::Fixed(1.0),
            speed_rms: 1.0,
            placement: Placement::Random,
            boundary: Boundary::Walls,
            physics: Physics::elastic(),
            seed: 0,
        }
    }

    /// Draws radii, positions and velocities from the seed.
    ///
    /// Set-up holds at most as much as the finished [`Particles`] plus small scratch:
    /// disks are placed into placement-order arrays, and each array moves into storage
    /// order in turn.
    pub fn build(&self) -> Result<Scene, PlacementError> {
        let n_particles = self.n_particles;
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(self.seed);
        let radii = match self.radius {
            RadiusDistribution::Fixed(r) => Radii::Fixed(r),
            RadiusDistribution::Uniform { min, max } => Radii::Drawn(
                (0..n_particles)
                    .map(|_| rng.random_range(min..=max))
                    .collect(),
            ),
        };
        let disk_area = radii.area_of_first(n_particles);
        let (width, height) = match self.extent {
            Extent::Packing(packing) => {
                let side = (disk_area / packing).sqrt();
                (side, side)
            }
            Extent::Size { width, height } => (width, height),
        };
        let domain = Domain {
            width,
            height,
            boundary: self.boundary,
        };
        let max_radius = (0..n_particles)
            .map(|idx| radii.of(idx))
            .fold(0.0, f64::max);
        check_periodic_box(&domain, max_radius)?;
        let positions = match self.placement {
            Placement::Random => {
                let packing = disk_area / domain.area();
                if packing > RSA_JAMMING_PACKING {
                    return Err(PlacementError::BeyondJamming { packing });
                }
                place_random(&domain, &radii, n_particles, &mut rng)?
            }
            Placement::Lattice => place_lattice(&domain, n_particles, max_radius)?,
        };
        // Ids in row order (rows one contact diameter tall, then x): canonical pair order
        // goes by id, so numbering neighbours close together keeps every pass over the
        // contacts close in memory. Placement order is random in space.
        let order = row_order(&positions, 2.0 * max_radius);
        let (x, y) = moved_to_storage_order(&order, positions);
        let mass_of = |radius: f64| match self.mass {
            MassRule::Fixed(m) => m,
            MassRule::Area => std::f64::consts::PI * radius * radius,
        };
        let velocities = maxwellian_velocities(
            n_particles,
            |idx| mass_of(radii.of(idx)),
            self.speed_rms,
            &mut rng,
        );
        let (vx, vy) = moved_to_storage_order(&order, velocities);
        // Equal disks hold their radius and mass once.
        let radius = match radii {
            Radii::Fixed(r) => PerDisk::Shared {
                value: r,
                len: n_particles,
            },
            Radii::Drawn(_) => {
                PerDisk::from_values(order.iter().map(|&idx| radii.of(idx as usize)).collect())
            }
        };
        drop((order, radii));
        let mass = radius.map(mass_of);
        Ok(Scene {
            domain,
            physics: self.physics,
            particles: Particles {
                id: (0..n_particles as u32).collect(),
                x,
                y,
                vx,
                vy,
                radius,
                mass,
            },
        })
    }
}

/// The radii in placement order: one value for equal disks, else one per disk.
enum Radii {
    Fixed(f64),
    Drawn(Vec<f64>),
}

impl Radii {
    #[inline(always)]
    fn of(&self, idx: usize) -> f64 {
        match self {
            Radii::Fixed(r) => *r,
            Radii::Drawn(radii) => radii[idx],
        }
    }

    /// Total area of the first `n_disks` disks, summed in placement order.
    fn area_of_first(&self, n_disks: usize) -> f64 {
        (0..n_disks)
            .map(|idx| {
                let r = self.of(idx);
                std::f64::consts::PI * r * r
            })
            .sum()
    }
}

/// The pairs `pairs[order[k]]` for every k as two arrays: positions or velocities moved
/// from placement order into storage order, both coordinates in one pass over memory.
/// The placement-order pairs are freed at once, so one copy is in flight at a time.
fn moved_to_storage_order(order: &[u32], pairs: Vec<[f64; 2]>) -> (Vec<f64>, Vec<f64>) {
    order
        .iter()
        .map(|&idx| pairs[idx as usize])
        .map(|[a, b]| (a, b))
        .unzip()
}

/// Placement indices in storage order: by row of height `row_height` (counted from
/// y = 0), then by x, then by placement index, the order of a stable sort on
/// (row, x) with `f64::total_cmp`. A counting sort into row buckets (at most one per
/// disk), then one by x inside each row ([`BucketScratch::sort`]), keep it O(N) for a
/// gas of N disks.
fn row_order(positions: &[[f64; 2]], row_height: f64) -> Vec<u32> {
    let row_of = |position: &[f64; 2]| (position[1] / row_height).floor();
    let max_row = positions.iter().map(row_of).fold(0.0, f64::max);
    // Rows ascend with y, and buckets with rows (the map below never decreases), so
    // sorting each bucket sorts the whole.
    let n_buckets = (positions.len() as f64).min(max_row + 1.0).max(1.0);
    let bucket_of = |position: &[f64; 2]| {
        ((row_of(position) / (max_row + 1.0) * n_buckets) as usize).min(n_buckets as usize - 1)
    };
    // Sort keys scattered straight into their buckets, so that sorting reads no
    // positions at random: (row, x, placement index), unique, so an unstable sort is
    // stable. With the positions they take 40 bytes per disk, less than the finished disks.
    let (mut starts, mut keys) = (Vec::new(), Vec::new());
    counting_sort(
        positions,
        n_buckets as usize,
        bucket_of,
        |idx, position| {
            (
                total_order_key(row_of(position)),
                total_order_key(position[0]),
                idx as u32,
            )
        },
        &mut starts,
        &mut keys,
    );
    let mut scratch = BucketScratch::default();
    for bucket in starts.windows(2) {
        scratch.sort(&mut keys[bucket[0] as usize..bucket[1] as usize]);
    }
    keys.into_iter().map(|key| key.2).collect()
}

/// A sort key of [`row_order`]: (row, x, placement index), the first two as
/// [`total_order_key`]s.
type RowKey = (i64, i64, u32);

/// The bins and the copy [`BucketScratch::sort`] reuses from bucket to bucket.
#[derive(Default)]
struct BucketScratch {
    starts: Vec<u32>,
    sorted: Vec<RowKey>,
}

impl BucketScratch {
    /// Sorts one bucket of [`row_order`]'s keys. A bucket of one row (the rule: a
    /// row per bucket) is counting-sorted by x into about one bin per key, and each bin
    /// then sorted in full: O(keys) for disks spread along the row, where a comparison
    /// sort of a row of 2,000 disks takes a dozen passes. Binning by x keeps the order,
    /// since the bin only grows with x; anything else is sorted as it is.
    fn sort(&mut self, keys: &mut [RowKey]) {
        const SMALL: usize = 32;
        if keys.len() <= SMALL || keys.iter().any(|key| key.0 != keys[0].0) {
            keys.sort_unstable();
            return;
        }
        let x_of = |key: &RowKey| f64::from_bits(total_order_key_inverse(key.1));
        let (lo, hi) = keys
            .iter()
            .map(x_of)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                (lo.min(x), hi.max(x))
            });
        if !(hi - lo).is_normal() {
            keys.sort_unstable();
            return;
        }
        let n_bins = keys.len();
        let scale = n_bins as f64 / (hi - lo);
        let bin_of = |key: &RowKey| (((x_of(key) - lo) * scale) as usize).min(n_bins - 1);
        counting_sort(
            keys,
            n_bins,
            bin_of,
            |_, key| *key,
            &mut self.starts,
            &mut self.sorted,
        );
        for bin in self.starts.windows(2) {
            self.sorted[bin[0] as usize..bin[1] as usize].sort_unstable();
        }
        keys.copy_from_slice(&self.sorted);
    }
}

/// A stable counting sort: `make(idx, item)` for every item (`idx` its index), grouped by
/// `bin_of(item)` (below `n_bins`) in bin order, into `out`. `starts` ends as each bin's
/// first slot, with the number of items last.
fn counting_sort<T, U>(
    items: &[T],
    n_bins: usize,
    bin_of: impl Fn(&T) -> usize,
    make: impl Fn(usize, &T) -> U,
    starts: &mut Vec<u32>,
    out: &mut Vec<U>,
) {
    starts.clear();
    starts.resize(n_bins + 1, 0);
    for item in items {
        starts[bin_of(item) + 1] += 1;
    }
    for bin in 1..=n_bins {
        starts[bin] += starts[bin - 1];
    }
    out.clear();
    out.reserve(items.len());
    let slots = out.spare_capacity_mut();
    for (idx, item) in items.iter().enumerate() {
        let slot = &mut starts[bin_of(item)];
        slots[*slot as usize].write(make(idx, item));
        *slot += 1;
    }
    // SAFETY: the bins' slots are consecutive from 0 and each bin received exactly its
    // counted items, so every one of the `items.len()` slots was written once.
    unsafe { out.set_len(items.len()) };
    // Each bin's slot has moved on to its end, the next bin's start: shift them back.
    starts.copy_within(0..n_bins, 1);
    starts[0] = 0;
}

/// An integer that orders like `f64::total_cmp` (the same bit trick).
fn total_order_key(value: f64) -> i64 {
    let bits = value.to_bits() as i64;
    bits ^ (((bits >> 63) as u64) >> 1) as i64
}

/// The bits of the value whose [`total_order_key`] is `key`: the trick undoes itself
/// (it keeps the sign bit, and flips the others only when that is set).
fn total_order_key_inverse(key: i64) -> u64 {
    (key ^ (((key >> 63) as u64) >> 1) as i64) as u64
}

/// Periodic boxes need three cells of one contact diameter each way: the cell list
/// and the minimum image both assume a disk never meets two images of another.
pub fn check_periodic_box(domain: &Domain, max_radius: f64) -> Result<(), PlacementError> {
    let min_side = 3.0 * 2.0 * max_radius;
    if domain.boundary == Boundary::Periodic
        && (domain.width < min_side || domain.height < min_side)
    {
        return Err(PlacementError::PeriodicBoxTooSmall {
            min_side,
            width: domain.width,
            height: domain.height,
        });
    }
    Ok(())
}

/// One cell of the placement grid, or one further disk of a cell. The first disk placed
/// in a cell is stored inline, so a try reads its 3×3 block of cells from three runs of
/// three cells (two cache lines each) that can be fetched ahead; further disks of the
/// cell (cells hold about one disk) are chained through `more`, each in one cache line.
#[derive(Clone, Copy)]
#[repr(align(32))]
struct PlacementCell {
    x: f64,
    y: f64,
    /// NaN while the cell is empty: a NaN contact distance overlaps nothing.
    radius: f64,
    /// The next further disk of the cell (an index into `PlacementGrid::further`), or
    /// [`NO_DISK`].
    more: u32,
}

const NO_DISK: u32 = u32::MAX;

const EMPTY_CELL: PlacementCell = PlacementCell {
    x: 0.0,
    y: 0.0,
    radius: f64::NAN,
    more: NO_DISK,
};

/// Tries whose cells are fetched ahead of the try that reads them; the further disks
/// listed in those cells are fetched half as far ahead, once the cells have arrived.
const PREFETCH_TRIES_AHEAD: usize = 16;

/// One random try at placing a disk: where it lands and the 3×3 block of cells that
/// says whether it is free, as the index of the block's first cell.
#[derive(Clone, Copy)]
struct Try {
    x: f64,
    y: f64,
    block: usize,
}

impl Try {
    fn at(x: f64, y: f64, grid: &PlacementGrid) -> Try {
        let (cx, cy) = grid.cell_of(x, y);
        // The block's first cell is the inner cell's neighbour before it in both
        // directions: in the framed grid, (cx, cy) itself.
        Try {
            x,
            y,
            block: cy * grid.stride + cx,
        }
    }
}

/// A copy of the placement generator running [`PREFETCH_TRIES_AHEAD`] tries ahead, with
/// the tries it drew since and the generator's state before each.
///
/// With equal disks every try lands within the same bounds, so placement takes its
/// tries from here ([`Lookahead::next`]) and draws nothing itself; with unequal disks
/// the bounds depend on the disk, and the tries here only guide the prefetches.
struct Lookahead {
    rng: Xoshiro256PlusPlus,
    /// Where tries land: the bounds of the largest disk.
    bounds: (f64, f64, f64, f64),
    upcoming: [(Try, Xoshiro256PlusPlus); PREFETCH_TRIES_AHEAD],
    /// The slot of the oldest try, the next one [`Lookahead::next`] hands out.
    oldest: usize,
}

impl Lookahead {
    fn new(rng: &Xoshiro256PlusPlus, bounds: (f64, f64, f64, f64), grid: &PlacementGrid) -> Self {
        let nowhere = Try::at(f64::NAN, f64::NAN, grid);
        let mut lookahead = Lookahead {
            rng: rng.clone(),
            bounds,
            upcoming: std::array::from_fn(|_| (nowhere, rng.clone())),
            oldest: 0,
        };
        for _ in 0..PREFETCH_TRIES_AHEAD {
            lookahead.next(grid);
        }
        lookahead
    }

    /// Hands out the oldest try and draws one more in its place: prefetches the new
    /// try's cells, and the further disks listed in the cells of the try half as far
    /// ahead.
    fn next(&mut self, grid: &PlacementGrid) -> Try {
        let (lo_x, hi_x, lo_y, hi_y) = self.bounds;
        let before = self.rng.clone();
        let x = uniform_in(&mut self.rng, lo_x, hi_x);
        let y = uniform_in(&mut self.rng, lo_y, hi_y);
        let new = Try::at(x, y, grid);
        grid.prefetch_block(&new);
        let (oldest, _) = std::mem::replace(&mut self.upcoming[self.oldest], (new, before));
        self.oldest = (self.oldest + 1) % PREFETCH_TRIES_AHEAD;
        let halfway =
            &self.upcoming[(self.oldest + PREFETCH_TRIES_AHEAD / 2) % PREFETCH_TRIES_AHEAD].0;
        if !halfway.x.is_nan() {
            grid.prefetch_listed(halfway);
        }
        oldest
    }

    /// The generator as it would be had placement drawn every try it took itself: its
    /// state before the oldest try not handed out.
    fn into_generator(self) -> Xoshiro256PlusPlus {
        self.upcoming[self.oldest].1.clone()
    }
}

/// The uniform grid of [`place_random`] and the disks placed so far.
///
/// The grid's cells sit inside a frame one cell wide, so that every inner cell has a
/// full 3×3 block and a try reads three rows of three cells, with no case for edges:
/// between walls the frame stays empty; in a periodic box each frame cell is a copy of
/// the inner cell it stands for across the box (kept by [`PlacementGrid::insert`]).
/// A block so reads exactly the disks the wrapped or cut-off block would.
struct PlacementGrid {
    /// `(n_cols + 2) × (n_rows + 2)` cells, row after row, the frame included.
    cells: Vec<PlacementCell>,
    /// The disks not first in their cell, in placement order, chained by cell.
    further: Vec<PlacementCell>,
    /// Positions by placement index.
    positions: Vec<[f64; 2]>,
    n_cols: usize,
    n_rows: usize,
    /// Cells from one row to the next: `n_cols + 2`.
    stride: usize,
    cell_w: f64,
    cell_h: f64,
    periodic: bool,
}

impl PlacementGrid {
    fn new(domain: &Domain, max_radius: f64, n_particles: usize) -> PlacementGrid {
        // At least one contact diameter; wider in sparse boxes, so the grid never has
        // more cells than disks.
        let cell = (2.0 * max_radius).max((domain.area() / n_particles as f64).sqrt());
        let n_cols = ((domain.width / cell).floor() as usize).max(1);
        let n_rows = ((domain.height / cell).floor() as usize).max(1);
        let n_cells = (n_cols + 2) * (n_rows + 2);
        let mut cells = with_huge_pages(n_cells);
        cells.resize(n_cells, EMPTY_CELL);
        PlacementGrid {
            cells,
            further: with_huge_pages(n_particles),
            positions: with_huge_pages(n_particles),
            n_cols,
            n_rows,
            stride: n_cols + 2,
            cell_w: domain.width / n_cols as f64,
            cell_h: domain.height / n_rows as f64,
            periodic: domain.boundary == Boundary::Periodic,
        }
    }

    /// The inner cell holding (x, y), as its column and row counted from 0.
    fn cell_of(&self, x: f64, y: f64) -> (usize, usize) {
        (
            ((x / self.cell_w) as usize).min(self.n_cols - 1),
            ((y / self.cell_h) as usize).min(self.n_rows - 1),
        )
    }

    /// The three rows of a try's block, each as its first cell's index.
    #[inline(always)]
    fn block_rows(&self, tried: &Try) -> [usize; 3] {
        let first = tried.block;
        [first, first + self.stride, first + 2 * self.stride]
    }

    /// Asks the memory system for the 3×3 block of cells of a try: each row's first and
    /// last cell, whose lines hold the middle one too (cells are 32-byte aligned).
    fn prefetch_block(&self, tried: &Try) {
        for row in self.block_rows(tried) {
            prefetch(&self.cells[row]);
            prefetch(&self.cells[row + 2]);
        }
    }

    /// Asks the memory system for the first further disk listed in each cell of the
    /// 3×3 block of a try.
    fn prefetch_listed(&self, tried: &Try) {
        for row in self.block_rows(tried) {
            for cell in &self.cells[row..row + 3] {
                if cell.more != NO_DISK {
                    prefetch(&self.further[cell.more as usize]);
                }
            }
        }
    }

    /// Whether a disk of radius `r` at a try overlaps no disk placed so far.
    fn is_free(&self, domain: &Domain, tried: &Try, r: f64) -> bool {
        let overlaps = |ox: f64, oy: f64, other_r: f64| {
            let (sx, sy) = domain.separation(tried.x, tried.y, ox, oy);
            let contact = r + other_r;
            sx * sx + sy * sy < contact * contact
        };
        for row in self.block_rows(tried) {
            for cell in &self.cells[row..row + 3] {
                if overlaps(cell.x, cell.y, cell.radius) {
                    return false;
                }
                let mut next = cell.more;
                while next != NO_DISK {
                    let other = &self.further[next as usize];
                    if overlaps(other.x, other.y, other.radius) {
                        return false;
                    }
                    next = other.more;
                }
            }
        }
        true
    }

    /// Adds the next disk.
    fn insert(&mut self, x: f64, y: f64, r: f64) {
        let (cx, cy) = self.cell_of(x, y);
        let inner = (cy + 1) * self.stride + cx + 1;
        let cell = &mut self.cells[inner];
        let disk = PlacementCell {
            x,
            y,
            radius: r,
            more: NO_DISK,
        };
        if cell.radius.is_nan() {
            *cell = disk;
        } else {
            let more = std::mem::replace(&mut cell.more, self.further.len() as u32);
            self.further.push(PlacementCell { more, ..disk });
        }
        self.positions.push([x, y]);
        if self.periodic {
            self.copy_to_frame(cx, cy);
        }
    }

    /// Copies inner cell (cx, cy) to the frame cells that stand for it across a
    /// periodic box (none unless it lies on an edge; three at a corner).
    fn copy_to_frame(&mut self, cx: usize, cy: usize) {
        let on_edge = |c: usize, n: usize| c == 0 || c == n - 1;
        if !on_edge(cx, self.n_cols) && !on_edge(cy, self.n_rows) {
            return;
        }
        let cell = self.cells[(cy + 1) * self.stride + cx + 1];
        // Where the cell stands along one axis of n cells, in framed coordinates: its
        // own place, and the frame across the box from an edge it is on.
        let places = |c: usize, n: usize| {
            [
                Some(c + 1),
                (c == n - 1).then_some(0),
                (c == 0).then_some(n + 1),
            ]
            .into_iter()
            .flatten()
        };
        for row in places(cy, self.n_rows) {
            for col in places(cx, self.n_cols) {
                self.cells[row * self.stride + col] = cell;
            }
        }
    }
}

/// An empty vector with room for `capacity` items, backed by huge pages where the
/// system offers them on request (Linux's transparent huge pages in `madvise` mode):
/// random reads all over a big grid then miss the TLB far less. A hint only.
fn with_huge_pages<T>(capacity: usize) -> Vec<T> {
    let values = Vec::with_capacity(capacity);
    #[cfg(target_os = "linux")]
    {
        const PAGE: usize = 4096;
        let start = values.as_ptr() as usize;
        let end = start + capacity * std::mem::size_of::<T>();
        // Whole pages inside the allocation only.
        let (first_page, end_page) = (start.next_multiple_of(PAGE), end / PAGE * PAGE);
        if end_page > first_page {
            // SAFETY: the range lies inside this vector's allocation, and the advice
            // changes no contents (it only allows the kernel to back it with huge pages).
            // Failure (an old kernel, no huge pages) leaves ordinary pages: ignored.
            unsafe {
                libc::madvise(
                    first_page as *mut libc::c_void,
                    end_page - first_page,
                    libc::MADV_HUGEPAGE,
                );
            }
        }
    }
    values
}

/// Where random tries for a disk of radius `r` may land: the whole box when periodic,
/// else clear of the walls, as (lo_x, hi_x, lo_y, hi_y).
fn placement_bounds(domain: &Domain, r: f64) -> (f64, f64, f64, f64) {
    if domain.boundary == Boundary::Periodic {
        (0.0, domain.width, 0.0, domain.height)
    } else {
        (r, domain.width - r, r, domain.height - r)
    }
}

/// Random sequential addition on a uniform grid (O(1) per try), positions in placement
/// order.
///
/// The tries come from the seeded generator in a fixed sequence, two numbers each, and
/// with equal disks try k lands where it lands whatever the earlier tries did. So a copy
/// of the generator runs [`PREFETCH_TRIES_AHEAD`] tries ahead and prefetches the cells
/// they will read (with unequal disks it uses the largest radius's bounds: a prefetch
/// only needs to be about right). The generator ends as if placement had drawn every
/// try itself.
fn place_random(
    domain: &Domain,
    radii: &Radii,
    n_particles: usize,
    rng: &mut Xoshiro256PlusPlus,
) -> Result<Vec<[f64; 2]>, PlacementError> {
    let max_radius = (0..n_particles)
        .map(|idx| radii.of(idx))
        .fold(0.0, f64::max);
    let mut grid = PlacementGrid::new(domain, max_radius, n_particles);
    let mut lookahead = Lookahead::new(rng, placement_bounds(domain, max_radius), &grid);
    let equal = matches!(radii, Radii::Fixed(_));
    for idx in 0..n_particles {
        let r = radii.of(idx);
        let (lo_x, hi_x, lo_y, hi_y) = placement_bounds(domain, r);
        let mut tries = 0;
        let tried = loop {
            if tries == MAX_TRIES_PER_DISK || lo_x > hi_x || lo_y > hi_y {
                return Err(PlacementError::Jammed {
                    placed: idx,
                    n_particles,
                    packing: radii.area_of_first(idx) / domain.area(),
                });
            }
            tries += 1;
            let ahead = lookahead.next(&grid);
            let tried = match equal {
                true => ahead,
                false => {
                    let x = uniform_in(rng, lo_x, hi_x);
                    let y = uniform_in(rng, lo_y, hi_y);
                    Try::at(x, y, &grid)
                }
            };
            if grid.is_free(domain, &tried, r) {
                break tried;
            }
        };
        grid.insert(tried.x, tried.y, r);
    }
    if equal {
        *rng = lookahead.into_generator();
    }
    Ok(grid.positions)
}

/// Uniform in `[low, high)`, or `low` when the interval is a single point.
fn uniform_in(rng: &mut Xoshiro256PlusPlus, low: f64, high: f64) -> f64 {
    if high > low {
        rng.random_range(low..high)
    } else {
        low
    }
}

/// Disk centres on a square lattice as close to the box's aspect as possible.
fn place_lattice(
    domain: &Domain,
    n_particles: usize,
    max_radius: f64,
) -> Result<Vec<[f64; 2]>, PlacementError> {
    let aspect = domain.width / domain.height;
    let columns = ((n_particles as f64 * aspect).sqrt().ceil() as usize).max(1);
    let rows = n_particles.div_ceil(columns).max(1);
    let spacing = (domain.width / columns as f64).min(domain.height / rows as f64);
    // The lattice sits centred in the box, so a spacing of one diameter also keeps the
    // outer disks half a spacing (at least one radius) clear of walls and periodic images.
    if spacing < 2.0 * max_radius {
        return Err(PlacementError::LatticeTooDense {
            columns,
            rows,
            max_radius,
            width: domain.width,
            height: domain.height,
        });
    }
    let x0 = 0.5 * (domain.width - spacing * (columns as f64 - 1.0));
    let y0 = 0.5 * (domain.height - spacing * (rows as f64 - 1.0));
    Ok((0..n_particles)
        .map(|i| {
            let (col, row) = (i % columns, i / columns);
            [x0 + spacing * col as f64, y0 + spacing * row as f64]
        })
        .collect())
}

/// Maxwellian velocities at equipartition for disks of mass `mass_of(idx)`, as [vx, vy]
/// in placement order, with the centre-of-mass drift removed and the rms speed scaled to
/// exactly `speed_rms`. Every sum runs in placement order.
fn maxwellian_velocities(
    n_particles: usize,
    mass_of: impl Fn(usize) -> f64,
    speed_rms: f64,
    rng: &mut Xoshiro256PlusPlus,
) -> Vec<[f64; 2]> {
    let total_mass: f64 = (0..n_particles).map(&mass_of).sum();
    let mean_mass = total_mass / n_particles as f64;
    let mut velocities: Vec<[f64; 2]> = (0..n_particles)
        .map(|idx| {
            let scale = (mean_mass / mass_of(idx)).sqrt();
            let gx: f64 = rng.sample(StandardNormal);
            let gy: f64 = rng.sample(StandardNormal);
            [gx * scale, gy * scale]
        })
        .collect();
    let (px, py) = velocities
        .iter()
        .enumerate()
        .fold((0.0, 0.0), |(px, py), (idx, v)| {
            let m = mass_of(idx);
            (px + m * v[0], py + m * v[1])
        });
    let (drift_x, drift_y) = (px / total_mass, py / total_mass);
    for v in &mut velocities {
        v[0] -= drift_x;
        v[1] -= drift_y;
    }
    let mean_square = velocities
        .iter()
        .map(|v| v[0] * v[0] + v[1] * v[1])
        .sum::<f64>()
        / n_particles as f64;
    let scale = if mean_square > 0.0 {
        speed_rms / mean_square.sqrt()
    } else {
        0.0
    };
    for v in &mut velocities {
        v[0] *= scale;
        v[1] *= scale;
    }
    velocities
}

#[cfg(test)]
mod tests {
    use xxhash_rust::xxh3::Xxh3;

    use super::*;

    /// Hex xxh3-64 of every array of the built disks (ids, positions, velocities, radii,
    /// masses) in storage order, and of the box: equal hashes mean the same scene bit for bit.
    fn scene_hash(gas: &GasSpec) -> String {
        let scene = gas.build().expect("the gas places");
        let particles = &scene.particles;
        let mut hasher = Xxh3::new();
        for &id in &particles.id {
            hasher.update(&id.to_le_bytes());
        }
        let p = particles;
        let motion = [&p.x, &p.y, &p.vx, &p.vy].map(|values| values.iter());
        let properties = [&p.radius, &p.mass].map(|values| values.iter());
        for value in motion
            .into_iter()
            .flatten()
            .chain(properties.into_iter().flatten())
        {
            hasher.update(&value.to_le_bytes());
        }
        for value in [scene.domain.width, scene.domain.height] {
            hasher.update(&value.to_le_bytes());
        }
        format!("{:016x}", hasher.digest())
    }

    /// The placed scene is part of every recorded run (its `state_hash`, the CI baseline,
    /// the shipped results): building it faster must not change a bit. These hashes were
    /// recorded with the first, straightforward placement.
    #[test]
    fn placement_gives_the_recorded_scenes_bit_for_bit() {
        let uniform = RadiusDistribution::Uniform { min: 0.5, max: 1.5 };
        let cases = [
            (
                "walls, fixed r, packing 0.05",
                GasSpec::unit(1000, 0.05),
                "07c04ced0ba38b3c",
            ),
            (
                "walls, fixed r, packing 0.3",
                GasSpec::unit(20_000, 0.3),
                "c2bcea67c4a69616",
            ),
            (
                "periodic, fixed r, packing 0.3",
                GasSpec {
                    boundary: Boundary::Periodic,
                    seed: 7,
                    ..GasSpec::unit(10_000, 0.3)
                },
                "c1fd7ae01e149fad",
            ),
            (
                "walls, fixed r, packing 0.5 (near jamming)",
                GasSpec {
                    seed: 3,
                    ..GasSpec::unit(2000, 0.5)
                },
                "6fc5038adae5a01b",
            ),
            (
                "walls, lattice, packing 0.5",
                GasSpec {
                    placement: Placement::Lattice,
                    ..GasSpec::unit(10_000, 0.5)
                },
                "533d686477129f0a",
            ),
            (
                "walls, uniform r, mass by area, packing 0.3",
                GasSpec {
                    radius: uniform,
                    mass: MassRule::Area,
                    seed: 11,
                    ..GasSpec::unit(5000, 0.3)
                },
                "91ec5649f3dead32",
            ),
            (
                "periodic, uniform r, packing 0.05",
                GasSpec {
                    radius: uniform,
                    boundary: Boundary::Periodic,
                    seed: 5,
                    ..GasSpec::unit(5000, 0.05)
                },
                "9b472947163f9089",
            ),
            (
                "periodic, fewer cells than the 3x3 block",
                GasSpec {
                    boundary: Boundary::Periodic,
                    ..GasSpec::unit(5, 0.05)
                },
                "d956c3dda4592449",
            ),
            (
                "walls, a wide explicit box",
                GasSpec {
                    extent: Extent::Size {
                        width: 400.0,
                        height: 9.0,
                    },
                    speed_rms: 2.5,
                    ..GasSpec::unit(300, 0.0)
                },
                "05dff41a6f878bfc",
            ),
        ];
        let mut failures = Vec::new();
        for (name, gas, recorded) in cases {
            let hash = scene_hash(&gas);
            if hash != recorded {
                failures.push(format!("{name}: built {hash}, recorded {recorded}"));
            }
        }
        assert!(failures.is_empty(), "{}", failures.join("\n"));
    }

    /// The bucket sort of the storage order gives what a full sort gives: rows of
    /// spread x's, of equal x's, of signed zeros and negative x's, of a few keys, and
    /// buckets holding several rows.
    #[test]
    fn a_row_sorts_by_its_bins_as_by_a_full_sort() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
        let mut uniform = move || rng.random::<f64>();
        let key =
            |row: f64, x: f64, idx: usize| (total_order_key(row), total_order_key(x), idx as u32);
        let spread: Vec<RowKey> = (0..500).map(|k| key(3.0, 1e4 * uniform(), k)).collect();
        // Placement indices falling, so that equal x's must be put in order.
        let lumpy: Vec<RowKey> = (0..500)
            .rev()
            .map(|k| key(3.0, (uniform() * 10.0).floor() - 5.0, k))
            .collect();
        let zeros: Vec<RowKey> = (0..100)
            .rev()
            .map(|k| key(0.0, [0.0, -0.0, 1.0, -1e-300][k % 4], k))
            .collect();
        let few: Vec<RowKey> = (0..5).map(|k| key(1.0, uniform(), k)).collect();
        let rows: Vec<RowKey> = (0..300)
            .map(|k| key((k % 3) as f64, uniform(), k))
            .collect();
        let mut scratch = BucketScratch::default();
        for keys in [spread, lumpy, zeros, few, rows] {
            let mut expected = keys.clone();
            expected.sort_unstable();
            let mut sorted = keys;
            scratch.sort(&mut sorted);
            assert_eq!(sorted, expected);
        }
        assert_eq!(
            total_order_key_inverse(total_order_key(-2.5)),
            (-2.5_f64).to_bits()
        );
    }

    #[test]
    fn periodic_wrap_lands_in_the_box_from_either_side_and_any_distance() {
        assert_eq!(wrap_periodic(3.5, 10.0), 3.5);
        assert_eq!(wrap_periodic(10.0, 10.0), 0.0);
        assert_eq!(wrap_periodic(12.5, 10.0), 2.5);
        assert_eq!(wrap_periodic(-2.5, 10.0), 7.5);
        assert_eq!(wrap_periodic(-1e-20, 10.0), 0.0);
        assert_eq!(wrap_periodic(35.0, 10.0), 5.0);
        assert_eq!(wrap_periodic(-25.0, 10.0), 5.0);
    }
}
