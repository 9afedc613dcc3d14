//! Seeded placement of a gas in fixed bands, so that any number of ranks builds the
//! same disks, each rank only those of the bands it is given.
//!
//! The box is cut into horizontal bands at least [`ROWS_PER_BAND`] contact diameters
//! tall: their number follows from the box and the largest radius, never from the
//! ranks. Each band's share of the disks (a run of placement indices) follows from its
//! height. Disks are added at random (random sequential addition) from the band's own
//! generator, in colour phases: two bands of one colour are a band apart, so they never
//! touch, and a band is filled against the edge disks of its neighbours filled in
//! earlier phases. Ids run band by band and, inside a band, by rows one contact
//! diameter tall, then by x, so that neighbours get close ids. Radii come from fixed
//! blocks of placement indices, velocities from each band's own generator, and the sums
//! that normalise them (the drift, the rms speed) and size the box are exact, so their
//! bits do not depend on how the bands are shared out.

use std::ops::Range;

use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;
use xxhash_rust::xxh3::xxh3_64;

use super::exact_sum::ExactSum;
use super::particles::{Particles, PerDisk};
use super::scene::{
    Boundary, Domain, Extent, GasSpec, MAX_TRIES_PER_DISK, MassRule, Placement, PlacementError,
    RANDOM_MAX_PACKING, RadiusDistribution, check_periodic_box, minimum_image,
};

/// Bands are at least this many contact diameters tall: the band's edges, where its
/// disks meet the neighbours' of another phase, are then a small part of it.
pub const ROWS_PER_BAND: f64 = 32.0;

/// Radii are drawn in blocks of this many placement indices, each from its own generator.
const RADIUS_BLOCK: usize = 4096;

/// What a generator of the placement draws: each is seeded by the gas's seed, the
/// stream and an index (a radius block or a band).
#[derive(Clone, Copy)]
enum Stream {
    Radii = 1,
    Tries = 2,
    Velocities = 3,
}

/// The generator of `stream` number `index`: any one reached without the others.
fn generator(seed: u64, stream: Stream, index: usize) -> Xoshiro256PlusPlus {
    let mut key = [0u8; 24];
    key[..8].copy_from_slice(&seed.to_le_bytes());
    key[8..16].copy_from_slice(&(stream as u64).to_le_bytes());
    key[16..].copy_from_slice(&(index as u64).to_le_bytes());
    Xoshiro256PlusPlus::seed_from_u64(xxh3_64(&key))
}

impl GasSpec {
    /// How many blocks the radii are drawn in ([`GasSpec::area_of_blocks`]).
    pub fn radius_blocks(&self) -> usize {
        self.n_particles.div_ceil(RADIUS_BLOCK)
    }

    /// The total area of the disks whose placement indices lie in the radius blocks
    /// `blocks`, exactly: the sums of any split of the blocks merge into the gas's.
    pub fn area_of_blocks(&self, blocks: Range<usize>) -> ExactSum {
        let indices = (blocks.start * RADIUS_BLOCK).min(self.n_particles)
            ..(blocks.end * RADIUS_BLOCK).min(self.n_particles);
        let mut area = ExactSum::default();
        match self.radius {
            RadiusDistribution::Fixed(r) => {
                // n equal areas as an exact product: its rounded value and its error.
                let (n, each) = (indices.len() as f64, std::f64::consts::PI * r * r);
                let product = n * each;
                area.add(product);
                area.add(n.mul_add(each, -product));
            }
            RadiusDistribution::Uniform { .. } => {
                for r in self.radii(indices).unwrap_or_default() {
                    area.add(std::f64::consts::PI * r * r);
                }
            }
        }
        area
    }

    /// The radii of the disks of placement indices `indices`, or `None` when all are equal.
    fn radii(&self, indices: Range<usize>) -> Option<Vec<f64>> {
        let RadiusDistribution::Uniform { min, max } = self.radius else {
            return None;
        };
        let mut radii = Vec::with_capacity(indices.len());
        let mut idx = indices.start;
        while idx < indices.end {
            let block = idx / RADIUS_BLOCK;
            let mut rng = generator(self.seed, Stream::Radii, block);
            let block_end = ((block + 1) * RADIUS_BLOCK).min(self.n_particles);
            for drawn in block * RADIUS_BLOCK..block_end {
                let r = rng.random_range(min..=max);
                if drawn >= idx && drawn < indices.end {
                    radii.push(r);
                }
            }
            idx = block_end;
        }
        Some(radii)
    }

    /// The box, its bands and the disks' shares, from the disks' total area (the merged
    /// [`GasSpec::area_of_blocks`] of every block).
    pub fn plan(&self, disk_area: f64) -> Result<GasPlan, PlacementError> {
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
        let max_radius = self.radius.max();
        check_periodic_box(&domain, max_radius)?;
        let lattice = match self.placement {
            Placement::Random => {
                let packing = disk_area / domain.area();
                if packing > RANDOM_MAX_PACKING {
                    return Err(PlacementError::BeyondJamming { packing });
                }
                None
            }
            Placement::Lattice => Some(Lattice::fitting(&domain, self.n_particles, max_radius)?),
        };
        let tallest = ROWS_PER_BAND * 2.0 * max_radius;
        let mut n_bands = ((height / tallest).floor() as usize).max(1);
        if let Some(lattice) = &lattice {
            n_bands = n_bands.min(lattice.rows);
        }
        Ok(GasPlan {
            gas: *self,
            domain,
            max_radius,
            disk_area,
            n_bands,
            lattice,
        })
    }

    /// Places the whole gas in one process: [`GasPlan::place`] on every band, then
    /// [`GasPlan::particles`] and [`GasPlan::set_velocities`].
    pub(super) fn build_whole(&self) -> Result<(Domain, Particles), PlacementError> {
        let area = self.area_of_blocks(0..self.radius_blocks()).value();
        let plan = self.plan(area)?;
        let bands = plan.place(0..plan.n_bands(), &mut |_| {
            unreachable!("every band is placed here, so no neighbour is elsewhere")
        })?;
        let mut particles = plan.particles(bands);
        plan.set_velocities(&mut particles, &mut |local| local);
        Ok((plan.domain, particles))
    }
}

/// A square lattice as close to the box's aspect as possible, centred in the box.
#[derive(Clone, Copy, Debug)]
struct Lattice {
    columns: usize,
    rows: usize,
    spacing: f64,
    x0: f64,
    y0: f64,
}

impl Lattice {
    fn fitting(
        domain: &Domain,
        n_particles: usize,
        max_radius: f64,
    ) -> Result<Lattice, PlacementError> {
        let aspect = domain.width / domain.height;
        let columns = ((n_particles as f64 * aspect).sqrt().ceil() as usize).max(1);
        let rows = n_particles.div_ceil(columns).max(1);
        let spacing = (domain.width / columns as f64).min(domain.height / rows as f64);
        // Centred, a spacing of one diameter also keeps the outer disks half a spacing
        // (at least one radius) clear of walls and periodic images.
        if spacing < 2.0 * max_radius {
            return Err(PlacementError::LatticeTooDense {
                columns,
                rows,
                max_radius,
                width: domain.width,
                height: domain.height,
            });
        }
        Ok(Lattice {
            columns,
            rows,
            spacing,
            x0: 0.5 * (domain.width - spacing * (columns as f64 - 1.0)),
            y0: 0.5 * (domain.height - spacing * (rows as f64 - 1.0)),
        })
    }

    fn site(&self, idx: usize) -> (f64, f64) {
        let (col, row) = (idx % self.columns, idx / self.columns);
        (
            self.x0 + self.spacing * col as f64,
            self.y0 + self.spacing * row as f64,
        )
    }
}

/// A gas's box, bands and shares of disks: the same on every rank.
#[derive(Clone, Debug)]
pub struct GasPlan {
    gas: GasSpec,
    pub domain: Domain,
    /// The largest radius the gas may draw: bands, rows and edges are sized by it.
    max_radius: f64,
    /// The disks' total area, exactly rounded.
    pub disk_area: f64,
    n_bands: usize,
    lattice: Option<Lattice>,
}

/// One band's disks in id order: their first id, positions and radii (none when all
/// disks are equal).
#[derive(Clone, Debug, Default)]
pub struct Band {
    pub index: usize,
    first: usize,
    x: Vec<f64>,
    y: Vec<f64>,
    radius: Option<Vec<f64>>,
}

impl Band {
    pub fn len(&self) -> usize {
        self.x.len()
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    fn radius(&self, k: usize, equal: f64) -> f64 {
        self.radius.as_ref().map_or(equal, |radii| radii[k])
    }
}

/// The disks of some bands' edges that another rank needs, as (band, side, disks) with
/// each disk as x, y, radius; `side` 0 for a band's bottom edge, 1 for its top.
pub type Edges = Vec<(usize, usize, Vec<[f64; 3]>)>;

impl GasPlan {
    pub fn n_bands(&self) -> usize {
        self.n_bands
    }

    pub fn n_particles(&self) -> usize {
        self.gas.n_particles
    }

    /// The band's lower and upper height: whole rows of one contact diameter from the
    /// bottom ([`ROWS_PER_BAND`] of them; the last band takes what is left), so that ids
    /// in rows within bands are ids in rows of the whole box.
    fn bounds(&self, band: usize) -> (f64, f64) {
        let tall = ROWS_PER_BAND * 2.0 * self.max_radius;
        let top = match band + 1 == self.n_bands {
            true => self.domain.height,
            false => tall * (band + 1) as f64,
        };
        (tall * band as f64, top)
    }

    /// The first placement index of `band` (the gas's size past the last band). Random
    /// disks are shared out by the height where their centres may lie.
    pub fn first_index(&self, band: usize) -> usize {
        let n = self.gas.n_particles;
        if band >= self.n_bands {
            return n;
        }
        if let Some(lattice) = &self.lattice {
            let rows_before = lattice.rows * band / self.n_bands;
            return (rows_before * lattice.columns).min(n);
        }
        let (low, high) = match self.domain.boundary {
            Boundary::Periodic => (0.0, self.domain.height),
            Boundary::Walls => (self.max_radius, self.domain.height - self.max_radius),
        };
        let below = (self.bounds(band).0 - low) / (high - low);
        match below.is_finite() {
            true => ((n as f64 * below.clamp(0.0, 1.0)).floor() as usize).min(n),
            false => 0,
        }
    }

    /// Disks of `band`.
    pub fn count(&self, band: usize) -> usize {
        self.first_index(band + 1) - self.first_index(band)
    }

    /// The colour phase of `band`: bands of one colour are a band apart, and every
    /// band is filled after its neighbours of lower colours.
    fn colour(&self, band: usize) -> usize {
        let periodic = self.domain.boundary == Boundary::Periodic;
        match self.n_bands {
            1 => 0,
            n if periodic && n % 2 == 1 && band == n - 1 => 2,
            _ => band % 2,
        }
    }

    fn n_colours(&self) -> usize {
        (0..self.n_bands)
            .map(|band| self.colour(band))
            .max()
            .unwrap_or(0)
            + 1
    }

    /// The bands below and above `band`, across a periodic box's edge too (none for a
    /// single band).
    pub fn neighbours(&self, band: usize) -> [Option<usize>; 2] {
        let n = self.n_bands;
        let periodic = self.domain.boundary == Boundary::Periodic;
        if n == 1 {
            return [None, None];
        }
        let below = match band {
            0 => periodic.then_some(n - 1),
            _ => Some(band - 1),
        };
        let above = match band + 1 == n {
            true => periodic.then_some(0),
            false => Some(band + 1),
        };
        [below, above]
    }

    /// Places the disks of `bands` (a run of band indices), in colour phases. Between
    /// phases, when `bands` is not every band, `swap` sends the edges of the first and
    /// last band to whoever places the bands beside them, and returns theirs
    /// ([`Edges`]); it is called once per phase on every rank, in step.
    pub fn place(
        &self,
        bands: Range<usize>,
        swap: &mut dyn FnMut(Edges) -> Edges,
    ) -> Result<Vec<Band>, PlacementError> {
        let mut placed: Vec<Band> = bands
            .clone()
            .map(|index| Band {
                index,
                ..Band::default()
            })
            .collect();
        let whole = bands == (0..self.n_bands);
        let mut outside: Edges = Vec::new();
        let mut failure = None;
        for colour in 0..self.n_colours() {
            for band in bands.clone().filter(|&band| self.colour(band) == colour) {
                if failure.is_some() {
                    break;
                }
                // The band below shows its top edge, the band above its bottom edge.
                let [below, above] = self.neighbours(band);
                let below =
                    below.map(|below| self.edge_of(below, 1, band, &placed, &bands, &outside));
                let above =
                    above.map(|above| self.edge_of(above, 0, band, &placed, &bands, &outside));
                match self.place_band(band, below.unwrap_or_default(), above.unwrap_or_default()) {
                    Ok(disks) => placed[band - bands.start] = disks,
                    Err(error) => failure = Some(error),
                }
            }
            if !whole && !bands.is_empty() {
                let first = &placed[0];
                let last = &placed[placed.len() - 1];
                outside = swap(vec![
                    (first.index, 0, self.edge(first, 0)),
                    (last.index, 1, self.edge(last, 1)),
                ]);
            } else if !whole {
                outside = swap(Vec::new());
            }
        }
        match failure {
            Some(error) => Err(error),
            None => Ok(placed),
        }
    }

    /// The disks of `neighbour`'s edge on `side` (0 bottom, 1 top) that band `band`
    /// must avoid, moved across a periodic edge next to it: from the bands placed here
    /// or, for a band placed elsewhere, from `outside`.
    fn edge_of(
        &self,
        neighbour: usize,
        side: usize,
        band: usize,
        placed: &[Band],
        bands: &Range<usize>,
        outside: &Edges,
    ) -> Vec<[f64; 3]> {
        let mut disks = match bands.contains(&neighbour) {
            true => self.edge(&placed[neighbour - bands.start], side),
            false => outside
                .iter()
                .find(|(from, from_side, _)| (*from, *from_side) == (neighbour, side))
                .map(|(_, _, disks)| disks.clone())
                .unwrap_or_default(),
        };
        // Next to `band`: the band below it across a periodic edge moves down by the
        // box's height, the band above it across the edge up.
        let shift = match (side, neighbour > band, neighbour < band) {
            (1, true, _) => -self.domain.height,
            (0, _, true) => self.domain.height,
            _ => 0.0,
        };
        for disk in &mut disks {
            disk[1] += shift;
        }
        disks
    }

    /// The disks of `band` within a contact diameter of its bottom (`side` 0) or top
    /// edge: those a disk of the band beside may touch.
    fn edge(&self, band: &Band, side: usize) -> Vec<[f64; 3]> {
        let (low, high) = self.bounds(band.index);
        let reach = 2.0 * self.max_radius;
        let near = |y: f64| match side {
            0 => y < low + reach,
            _ => y >= high - reach,
        };
        (0..band.len())
            .filter(|&k| near(band.y[k]))
            .map(|k| [band.x[k], band.y[k], band.radius(k, self.max_radius)])
            .collect()
    }

    /// The empty grid of band `band`, for its `own` disks, holding the edge disks
    /// `below` and `above` of its neighbours (moved next to it).
    fn band_grid(
        &self,
        band: usize,
        own: usize,
        below: Vec<[f64; 3]>,
        above: Vec<[f64; 3]>,
    ) -> BandGrid {
        let domain = &self.domain;
        let (low, high) = self.bounds(band);
        let reach = 2.0 * self.max_radius;
        let periodic = domain.boundary == Boundary::Periodic;
        let mut grid = match self.n_bands {
            1 => BandGrid::new(
                domain.width,
                0.0,
                domain.height,
                reach,
                own,
                [periodic, periodic],
            ),
            _ => BandGrid::new(
                domain.width,
                low - reach,
                high - low + 2.0 * reach,
                reach,
                own + below.len() + above.len(),
                [periodic, false],
            ),
        };
        for [x, y, r] in below.into_iter().chain(above) {
            grid.insert(x, y, r);
        }
        grid
    }

    /// The disks of one band, against the edge disks `below` and `above` of its
    /// neighbours (moved next to it).
    fn place_band(
        &self,
        band: usize,
        below: Vec<[f64; 3]>,
        above: Vec<[f64; 3]>,
    ) -> Result<Band, PlacementError> {
        let (first, end) = (self.first_index(band), self.first_index(band + 1));
        let radius = self.gas.radii(first..end);
        if let Some(lattice) = &self.lattice {
            let (x, y) = (first..end).map(|idx| lattice.site(idx)).unzip();
            return Ok(Band {
                index: band,
                first,
                x,
                y,
                radius,
            });
        }
        let domain = &self.domain;
        let (low, high) = self.bounds(band);
        let reach = 2.0 * self.max_radius;
        let periodic = domain.boundary == Boundary::Periodic;
        let mut grid = self.band_grid(band, end - first, below, above);
        let mut rng = generator(self.gas.seed, Stream::Tries, band);
        let mut positions = Vec::with_capacity(end - first);
        for k in 0..end - first {
            let r = radius.as_ref().map_or(self.max_radius, |radii| radii[k]);
            let (lo_x, hi_x, lo_y, hi_y) = match periodic {
                true => (0.0, domain.width, low, high),
                false => (r, domain.width - r, low.max(r), high.min(domain.height - r)),
            };
            let mut tries = 0;
            let (x, y) = loop {
                if tries == MAX_TRIES_PER_DISK || lo_x > hi_x || lo_y > hi_y {
                    let band_area = domain.width * (high - low);
                    return Err(PlacementError::Jammed {
                        placed: first + k,
                        n_particles: self.gas.n_particles,
                        packing: grid.own_area / band_area,
                    });
                }
                tries += 1;
                let x = uniform_in(&mut rng, lo_x, hi_x);
                let y = uniform_in(&mut rng, lo_y, hi_y);
                if grid.is_free(x, y, r) {
                    break (x, y);
                }
            };
            grid.insert(x, y, r);
            grid.own_area += std::f64::consts::PI * r * r;
            positions.push([x, y]);
        }
        drop(grid);
        let order = row_order(&positions, reach, low);
        Ok(Band {
            index: band,
            first,
            x: order.iter().map(|&k| positions[k as usize][0]).collect(),
            y: order.iter().map(|&k| positions[k as usize][1]).collect(),
            radius: radius.map(|radii| order.iter().map(|&k| radii[k as usize]).collect()),
        })
    }

    /// The disks of `bands` (placed bands, in band order) with ids from the first
    /// band's first index on, masses by the gas's rule and, from each band's own
    /// generator, Maxwellian velocities at equipartition, not yet normalised
    /// ([`GasPlan::set_velocities`]). Each band is freed once copied.
    pub fn particles(&self, bands: Vec<Band>) -> Particles {
        let n: usize = bands.iter().map(Band::len).sum();
        let equal = self.gas.radius.max();
        let mass_of = |radius: f64| match self.gas.mass {
            MassRule::Fixed(m) => m,
            MassRule::Area => std::f64::consts::PI * radius * radius,
        };
        let mean_mass = match self.gas.mass {
            MassRule::Fixed(m) => m,
            MassRule::Area => self.disk_area / self.gas.n_particles as f64,
        };
        let mut particles = Particles {
            id: Vec::with_capacity(n),
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            vx: Vec::with_capacity(n),
            vy: Vec::with_capacity(n),
            ..Particles::default()
        };
        let mut radii = Vec::new();
        for band in bands {
            let mut rng = generator(self.gas.seed, Stream::Velocities, band.index);
            for k in 0..band.len() {
                let scale = (mean_mass / mass_of(band.radius(k, equal))).sqrt();
                let gx: f64 = rng.sample(StandardNormal);
                let gy: f64 = rng.sample(StandardNormal);
                particles.vx.push(gx * scale);
                particles.vy.push(gy * scale);
            }
            particles
                .id
                .extend((band.first..band.first + band.len()).map(|id| id as u32));
            particles.x.extend_from_slice(&band.x);
            particles.y.extend_from_slice(&band.y);
            if let Some(band_radii) = &band.radius {
                radii.extend_from_slice(band_radii);
            }
        }
        particles.radius = match self.gas.radius {
            RadiusDistribution::Fixed(r) => PerDisk::Shared { value: r, len: n },
            RadiusDistribution::Uniform { .. } => PerDisk::from_values(radii),
        };
        particles.mass = particles.radius.map(mass_of);
        particles
    }

    /// Removes the centre-of-mass drift and scales the rms speed to the gas's, over the
    /// whole gas: `reduce` turns this process's exact sums into the whole gas's (the
    /// identity when it holds every disk; on ranks, the merge of every rank's).
    pub fn set_velocities(
        &self,
        particles: &mut Particles,
        reduce: &mut dyn FnMut(Vec<ExactSum>) -> Vec<ExactSum>,
    ) {
        let n = self.gas.n_particles as f64;
        let total_mass = match self.gas.mass {
            MassRule::Fixed(m) => n * m,
            MassRule::Area => self.disk_area,
        };
        let mut momentum = [ExactSum::default(), ExactSum::default()];
        for idx in 0..particles.len() {
            let m = particles.mass[idx];
            momentum[0].add(m * particles.vx[idx]);
            momentum[1].add(m * particles.vy[idx]);
        }
        let momentum = reduce(momentum.to_vec());
        let drift = [0, 1].map(|axis| momentum[axis].value() / total_mass);
        let mut square = ExactSum::default();
        for idx in 0..particles.len() {
            particles.vx[idx] -= drift[0];
            particles.vy[idx] -= drift[1];
            let (vx, vy) = (particles.vx[idx], particles.vy[idx]);
            square.add(vx * vx + vy * vy);
        }
        let mean_square = reduce(vec![square])[0].value() / n;
        let scale = match mean_square > 0.0 {
            true => self.gas.speed_rms / mean_square.sqrt(),
            false => 0.0,
        };
        for idx in 0..particles.len() {
            particles.vx[idx] *= scale;
            particles.vy[idx] *= scale;
        }
    }
}

/// One cell of a band's grid, or one further disk of a cell. The first disk placed in a
/// cell is stored inline, so a try reads its 3×3 block of cells from three runs of
/// three cells; further disks of the cell (cells hold about one disk) are chained
/// through `more`, each in one cache line.
#[derive(Clone, Copy)]
#[repr(align(32))]
struct PlacementCell {
    x: f64,
    y: f64,
    /// NaN while the cell is empty: a NaN contact distance overlaps nothing.
    radius: f64,
    /// The next further disk of the cell (an index into `BandGrid::further`), or
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

/// The uniform grid of one band's placement: the band and a contact diameter of each
/// neighbour band (or the whole box, for a single band), with the disks placed so far.
///
/// The cells sit inside a frame one cell wide, so that every inner cell has a full 3×3
/// block and a try reads three rows of three cells, with no case for edges: the frame
/// stays empty along an edge that does not wrap; along one that does (a periodic box's
/// sides, and its top and bottom for a single band), each frame cell is a copy of the
/// inner cell it stands for across the box (kept by [`BandGrid::insert`]).
struct BandGrid {
    /// `(n_cols + 2) × (n_rows + 2)` cells, row after row, the frame included.
    cells: Vec<PlacementCell>,
    /// The disks not first in their cell, chained by cell.
    further: Vec<PlacementCell>,
    n_cols: usize,
    n_rows: usize,
    /// Cells from one row to the next: `n_cols + 2`.
    stride: usize,
    cell_w: f64,
    cell_h: f64,
    /// The grid's lowest height, and its width and height.
    y0: f64,
    size: [f64; 2],
    /// Whether the grid wraps across its sides and across its top and bottom.
    wraps: [bool; 2],
    /// The area of the band's own disks placed so far.
    own_area: f64,
}

impl BandGrid {
    /// A grid `width` × `height` from height `y0` up, cells at least `reach` wide, for
    /// about `n_disks` disks (sparse grids get wider cells, never more cells than disks).
    fn new(width: f64, y0: f64, height: f64, reach: f64, n_disks: usize, wraps: [bool; 2]) -> Self {
        let cell = reach.max((width * height / n_disks.max(1) as f64).sqrt());
        let n_cols = ((width / cell).floor() as usize).max(1);
        let n_rows = ((height / cell).floor() as usize).max(1);
        BandGrid {
            cells: vec![EMPTY_CELL; (n_cols + 2) * (n_rows + 2)],
            further: Vec::new(),
            n_cols,
            n_rows,
            stride: n_cols + 2,
            cell_w: width / n_cols as f64,
            cell_h: height / n_rows as f64,
            y0,
            size: [width, height],
            wraps,
            own_area: 0.0,
        }
    }

    /// The inner cell holding (x, y), as its column and row counted from 0.
    fn cell_of(&self, x: f64, y: f64) -> (usize, usize) {
        (
            ((x / self.cell_w) as usize).min(self.n_cols - 1),
            (((y - self.y0) / self.cell_h) as usize).min(self.n_rows - 1),
        )
    }

    /// Whether a disk of radius `r` at (x, y) overlaps no disk placed so far.
    fn is_free(&self, x: f64, y: f64, r: f64) -> bool {
        let along = |d: f64, axis: usize| match self.wraps[axis] {
            true => minimum_image(d, self.size[axis]),
            false => d,
        };
        let overlaps = |other: &PlacementCell| {
            let (sx, sy) = (along(other.x - x, 0), along(other.y - y, 1));
            let contact = r + other.radius;
            sx * sx + sy * sy < contact * contact
        };
        let (cx, cy) = self.cell_of(x, y);
        // The block's first cell is the inner cell's neighbour before it both ways: in
        // the framed grid, (cx, cy) itself.
        let first = cy * self.stride + cx;
        for row in [first, first + self.stride, first + 2 * self.stride] {
            for cell in &self.cells[row..row + 3] {
                if overlaps(cell) {
                    return false;
                }
                let mut next = cell.more;
                while next != NO_DISK {
                    let other = &self.further[next as usize];
                    if overlaps(other) {
                        return false;
                    }
                    next = other.more;
                }
            }
        }
        true
    }

    /// Adds a disk.
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
        if self.wraps.contains(&true) {
            self.copy_to_frame(cx, cy);
        }
    }

    /// Copies inner cell (cx, cy) to the frame cells that stand for it across the edges
    /// that wrap (none unless it lies on such an edge; three at a corner).
    fn copy_to_frame(&mut self, cx: usize, cy: usize) {
        let cell = self.cells[(cy + 1) * self.stride + cx + 1];
        // Where the cell stands along one axis of n cells, in framed coordinates: its
        // own place, and the frame across the box from an edge it is on.
        let places = |c: usize, n: usize, wraps: bool| {
            [
                Some(c + 1),
                (wraps && c == n - 1).then_some(0),
                (wraps && c == 0).then_some(n + 1),
            ]
            .into_iter()
            .flatten()
        };
        for row in places(cy, self.n_rows, self.wraps[1]) {
            for col in places(cx, self.n_cols, self.wraps[0]) {
                self.cells[row * self.stride + col] = cell;
            }
        }
    }
}

/// Uniform in `[low, high)`, or `low` when the interval is a single point.
fn uniform_in(rng: &mut Xoshiro256PlusPlus, low: f64, high: f64) -> f64 {
    if high > low {
        rng.random_range(low..high)
    } else {
        low
    }
}

/// Placement indices in storage order: by row of height `row_height` (counted from
/// y = `y0`), then by x, then by placement index, the order of a stable sort on
/// (row, x) with `f64::total_cmp`. A counting sort into row buckets (at most one per
/// disk), then one by x inside each row ([`BucketScratch::sort`]), keep it O(N) for a
/// gas of N disks.
fn row_order(positions: &[[f64; 2]], row_height: f64, y0: f64) -> Vec<u32> {
    let row_of = |position: &[f64; 2]| ((position[1] - y0) / row_height).floor();
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::scene::Scene;

    /// Whether any two disks of `scene` overlap, or a disk leaves the box.
    fn faults(scene: &Scene) -> Vec<String> {
        let (p, d) = (&scene.particles, &scene.domain);
        let periodic = d.boundary == Boundary::Periodic;
        let mut faults = Vec::new();
        for i in 0..p.len() {
            let r = p.radius[i];
            let inside = match periodic {
                true => (0.0..d.width).contains(&p.x[i]) && (0.0..d.height).contains(&p.y[i]),
                false => {
                    (r..=d.width - r).contains(&p.x[i]) && (r..=d.height - r).contains(&p.y[i])
                }
            };
            if !inside {
                faults.push(format!(
                    "disk {i} at ({}, {}) leaves the box",
                    p.x[i], p.y[i]
                ));
            }
            for j in i + 1..p.len() {
                let (dx, dy) = d.separation(p.x[i], p.y[i], p.x[j], p.y[j]);
                if dx * dx + dy * dy < (r + p.radius[j]).powi(2) {
                    faults.push(format!("disks {i} and {j} overlap"));
                }
            }
        }
        faults
    }

    /// Every kind of band layout (one band; two, three and five bands in a periodic box,
    /// where the last of an odd number gets a third colour; bands between walls; radii
    /// drawn; a lattice) places disks that do not overlap, inside the box, with ids in
    /// storage order, no drift and the asked rms speed.
    #[test]
    fn placed_disks_never_overlap_and_move_as_asked() {
        let periodic = |side: f64, n: usize| GasSpec {
            boundary: Boundary::Periodic,
            extent: Extent::Size {
                width: side,
                height: side,
            },
            ..GasSpec::unit(n, 0.0)
        };
        let cases = [
            ("one band", GasSpec::unit(1000, 0.3), 1),
            ("walls, four bands", GasSpec::unit(3000, 0.1), 4),
            ("periodic, two bands", periodic(150.0, 2000), 2),
            ("periodic, three bands", periodic(200.0, 3000), 3),
            ("periodic, five bands", periodic(330.0, 1700), 5),
            (
                "radii drawn, masses by area",
                GasSpec {
                    radius: RadiusDistribution::Uniform { min: 0.5, max: 1.5 },
                    mass: MassRule::Area,
                    speed_rms: 2.0,
                    ..GasSpec::unit(2000, 0.2)
                },
                1,
            ),
            (
                "lattice, two bands",
                GasSpec {
                    placement: Placement::Lattice,
                    ..GasSpec::unit(4000, 0.6)
                },
                2,
            ),
        ];
        for (name, gas, n_bands) in cases {
            let area = gas.area_of_blocks(0..gas.radius_blocks()).value();
            assert_eq!(gas.plan(area).unwrap().n_bands(), n_bands, "{name}");
            let scene = gas.build().unwrap();
            let p = &scene.particles;
            assert_eq!(p.len(), gas.n_particles, "{name}");
            assert!(
                p.id.iter().enumerate().all(|(k, &id)| id as usize == k),
                "{name}"
            );
            let faults = faults(&scene);
            assert!(faults.is_empty(), "{name}: {}", faults.join("; "));
            let m = |i: usize| p.mass[i];
            let px: f64 = (0..p.len()).map(|i| m(i) * p.vx[i]).sum();
            let py: f64 = (0..p.len()).map(|i| m(i) * p.vy[i]).sum();
            assert!(
                px.hypot(py) < 1e-10 * p.len() as f64,
                "{name}: drift {px} {py}"
            );
            let rms = p.rms_speed();
            assert!((rms - gas.speed_rms).abs() < 1e-12, "{name}: rms {rms}");
        }
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
}
