//! The yardstick our serial step is measured against: a cell-list code as a skilled
//! engineer writes it, with the same impulse law (`collide_pair`) and the same motion
//! (x += v·dt, then reflection at the walls), so that only the search for contacts and
//! the order of impulses differ. Boxes with walls and no field only.
//!
//! - Structure of arrays in f64 (x, y, vx, vy, radius, mass, and the disks' ids).
//! - A uniform grid whose cells are at least one contact diameter (2·r_max) wide and
//!   hold about two disks each in a dilute gas: side max(2·r_max, sqrt(2·area / N)).
//!   A column of empty cells at each side and a row of empty cells on top make every
//!   neighbour of a real cell exist, so the sweep has no edge tests.
//! - Every step a counting sort rebuilds the grid: one pass computes where each disk
//!   moves in this step (and whether a wall reflects it) and counts the disks per cell
//!   (cell index by multiplication with the inverse side); a second pass writes every
//!   disk, moved, with all its fields into the spare arrays in cell order, and the two
//!   sets of arrays swap. Pair tests read contiguous memory.
//! - A half-shell sweep in cell order: the rest of the disk's own cell and the east
//!   cell, which follow it in memory, then the north-west, north and north-east cells,
//!   which are contiguous too. So each disk scans two runs of consecutive disks.
//! - A pair that overlaps and approaches gets its impulse as soon as it is found.
//!
//! Variants measured and dropped (the bench's `COLLIDE_YARDSTICK_ONLY=1` mode, CPU-time
//! rates on a loaded 2-core machine, runs interleaved; M particle-steps/s, written
//! packing 0.05 / packing 0.3):
//! - A drift pass writing the moved disks back, then a copy into cell order, instead of
//!   the move computed in both passes of the sort: 29–36 / 32–36 at N = 10⁵ and
//!   28–33 / 24–30 at 10⁶, against 39–40 / 37 and 35–36 / 32 for the fused move (the
//!   copy writes each disk once, the counting pass only reads). Callgrind: 115 against
//!   148 instructions per disk for the sort, yet slower.
//! - Cells one contact diameter wide: 16 / 29 at 10⁵ and 14 / 22 at 10⁶ (dilute cells
//!   are mostly empty, and each is visited), against 31 / 27 and 32 / 27 for cells of
//!   about one disk.
//! - Cells of about one disk (side sqrt(area / N)): 35–40 / 29–38 at 10⁵ and 29–35 /
//!   29–32 at 10⁶; about two disks (side sqrt(2·area / N), kept): 39–41 / 37–38 and
//!   35–36 / 32–33; about four (side 2·sqrt(area / N)): 32 / 30 and 27 / 27.
//! - The first version (branchy wall tests, indexed loops over arrays of unrelated
//!   lengths, so bounds checks left in; one-disk cells; move fused): 23 / 22 and 22 / 19.
//!
//! Instruction counts are no guide on their own: callgrind (N = 10⁵, packing 0.3) counts
//! 147 instructions per disk and step in the sort and 197 in the sweep now, against 184
//! and 152 in the first version (cells of one disk: fewer candidates, more cells visited).

use collide::sim::collision::{PairSide, collide_pair};
use collide::sim::{Boundary, Physics, Scene};

/// The disks in structure-of-arrays form.
#[derive(Clone, Debug, Default)]
struct Arrays {
    x: Vec<f64>,
    y: Vec<f64>,
    vx: Vec<f64>,
    vy: Vec<f64>,
    radius: Vec<f64>,
    mass: Vec<f64>,
    id: Vec<u32>,
}

/// The uniform grid: square cells, real ones surrounded by empty ones.
#[derive(Clone, Copy, Debug)]
struct Grid {
    inv_cell: f64,
    /// Real columns and rows of cells.
    nx: usize,
    ny: usize,
    /// Cells per row, the two empty side columns included.
    stride: usize,
}

impl Grid {
    /// The cell of a point (real cells only: points outside go to the edge cells).
    #[inline(always)]
    fn cell(self, x: f64, y: f64) -> usize {
        // `as usize` saturates: a centre just outside the box lands in the edge cell.
        let cx = ((x * self.inv_cell) as usize).min(self.nx - 1);
        let cy = ((y * self.inv_cell) as usize).min(self.ny - 1);
        cy * self.stride + cx + 1
    }
}

/// The skilled cell list: the disks (two sets of arrays, swapped every step) and its grid.
pub struct CellListYardstick {
    dt: f64,
    physics: Physics,
    width: f64,
    height: f64,
    grid: Grid,
    disks: Arrays,
    spare: Arrays,
    /// The cell of each disk of `disks`, from the counting pass.
    cell_of: Vec<u32>,
    /// After the sort, the disks of cell c are `bounds[c]..bounds[c + 1]`.
    bounds: Vec<u32>,
    pair_impulses: u64,
}

impl CellListYardstick {
    /// A yardstick holding a copy of the scene's disks, stepped by `dt`.
    pub fn new(scene: &Scene, dt: f64) -> Self {
        assert_eq!(scene.domain.boundary, Boundary::Walls, "walls only");
        assert!(scene.physics.gravity.is_none(), "no field");
        let p = &scene.particles;
        let n = p.len();
        let diameter = 2.0 * p.max_radius();
        // About two disks per cell in a dilute gas (see the module's notes).
        let side = diameter.max((2.0 * scene.domain.area() / n as f64).sqrt());
        let nx = ((scene.domain.width / side) as usize).max(1);
        let ny = ((scene.domain.height / side) as usize).max(1);
        // Cells at least `side` wide: the box is cut into whole cells (x and y alike, a
        // square cell by the larger of the two sides).
        let side = (scene.domain.width / nx as f64).max(scene.domain.height / ny as f64);
        let stride = nx + 2;
        let n_cells = stride * (ny + 1);
        let disks = Arrays {
            x: p.x.clone(),
            y: p.y.clone(),
            vx: p.vx.clone(),
            vy: p.vy.clone(),
            radius: p.radius.iter().copied().collect(),
            mass: p.mass.iter().copied().collect(),
            id: p.id.clone(),
        };
        CellListYardstick {
            dt,
            physics: scene.physics,
            width: scene.domain.width,
            height: scene.domain.height,
            grid: Grid {
                inv_cell: 1.0 / side,
                nx,
                ny,
                stride,
            },
            spare: disks.clone(),
            disks,
            cell_of: vec![0; n],
            bounds: vec![0; n_cells + 2],
            pair_impulses: 0,
        }
    }

    /// Pair impulses applied since the start.
    pub fn pair_impulses(&self) -> u64 {
        self.pair_impulses
    }

    /// Total kinetic energy.
    pub fn kinetic_energy(&self) -> f64 {
        let d = &self.disks;
        d.mass
            .iter()
            .zip(d.vx.iter().zip(&d.vy))
            .map(|(m, (vx, vy))| 0.5 * m * (vx * vx + vy * vy))
            .sum()
    }

    /// One step: move and reflect, sort into cell order, sweep the half shells.
    pub fn step(&mut self) {
        self.sort_moved();
        self.sweep();
    }

    /// Moves the disks by one dt, reflects those touching a wall while moving outward,
    /// and stores them in cell order in the spare arrays, which then become the disks.
    // Not inlined, here and in `sweep`, so that profiles show the two halves apart.
    #[inline(never)]
    fn sort_moved(&mut self) {
        let (dt, grid, e_wall) = (self.dt, self.grid, self.physics.wall_restitution);
        let d = &mut self.disks;
        let n = d.x.len();
        let (width, height) = (self.width, self.height);
        // The same arithmetic as `collide::sim::step::advance_disks` without a field,
        // branch-free.
        let moved = |p: f64, v: f64, r: f64, length: f64| {
            let moved = p + v * dt;
            let outward = (moved - r < 0.0) & (v < 0.0) | (moved + r > length) & (v > 0.0);
            (moved, if outward { v * -e_wall } else { v })
        };
        let bounds = &mut self.bounds[..];
        bounds.fill(0);
        let cell_of = &mut self.cell_of[..n];
        let (x, y, vx, vy) = (&d.x[..n], &d.y[..n], &d.vx[..n], &d.vy[..n]);
        let (r, m, id) = (&d.radius[..n], &d.mass[..n], &d.id[..n]);
        for (i, cell) in cell_of.iter_mut().enumerate() {
            let (x, _) = moved(x[i], vx[i], r[i], width);
            let (y, _) = moved(y[i], vy[i], r[i], height);
            let c = grid.cell(x, y);
            *cell = c as u32;
            bounds[c + 2] += 1;
        }
        // Counts at c + 2, summed: bounds[c + 1] is where cell c starts; the copy moves
        // it on to where c ends, which is where c + 1 starts. bounds[0] stays 0.
        let mut total = 0;
        for b in bounds.iter_mut() {
            total += *b;
            *b = total;
        }
        // Slices of one length n: one bounds check per destination index.
        let s = &mut self.spare;
        let (sx, sy, svx, svy) = (&mut s.x[..n], &mut s.y[..n], &mut s.vx[..n], &mut s.vy[..n]);
        let (sr, sm, sid) = (&mut s.radius[..n], &mut s.mass[..n], &mut s.id[..n]);
        for (i, &c) in cell_of.iter().enumerate() {
            let slot = &mut bounds[c as usize + 1];
            let at = *slot as usize;
            *slot += 1;
            (sx[at], svx[at]) = moved(x[i], vx[i], r[i], width);
            (sy[at], svy[at]) = moved(y[i], vy[i], r[i], height);
            (sr[at], sm[at], sid[at]) = (r[i], m[i], id[i]);
        }
        std::mem::swap(&mut self.disks, &mut self.spare);
    }

    /// Tests each disk against the later disks of its cell, the east cell and the three
    /// cells above, resolving each overlapping, approaching pair as it is found.
    #[inline(never)]
    fn sweep(&mut self) {
        let physics = self.physics;
        let d = &mut self.disks;
        let n = d.x.len();
        let (x, y, radius, mass) = (&d.x[..n], &d.y[..n], &d.radius[..n], &d.mass[..n]);
        let (vx, vy) = (&mut d.vx[..n], &mut d.vy[..n]);
        let bounds = &self.bounds[..];
        let Grid { nx, ny, stride, .. } = self.grid;
        let mut impulses = 0;
        for row in 0..ny {
            let first = row * stride + 1;
            for c in first..first + nx {
                let (start, end) = (bounds[c] as usize, bounds[c + 1] as usize);
                if start == end {
                    continue;
                }
                let east_end = bounds[c + 2] as usize;
                let (above_start, above_end) = (
                    bounds[c + stride - 1] as usize,
                    bounds[c + stride + 2] as usize,
                );
                for i in start..end {
                    let (xi, yi, ri) = (x[i], y[i], radius[i]);
                    let mut scan = |from: usize, to: usize| {
                        let run = x[from..to].iter().zip(&y[from..to]).zip(&radius[from..to]);
                        for (k, ((&xj, &yj), &rj)) in run.enumerate() {
                            let (dx, dy) = (xj - xi, yj - yi);
                            let contact = ri + rj;
                            if dx * dx + dy * dy < contact * contact {
                                let hit =
                                    impulse(&physics, i, from + k, dx, dy, contact, mass, vx, vy);
                                impulses += u64::from(hit);
                            }
                        }
                    };
                    scan(i + 1, east_end);
                    scan(above_start, above_end);
                }
            }
        }
        self.pair_impulses += impulses;
    }
}

/// Applies our impulse law to the overlapping pair a, b (a before b in cell order);
/// returns whether it approached and so received an impulse.
#[cold]
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn impulse(
    physics: &Physics,
    a: usize,
    b: usize,
    dx: f64,
    dy: f64,
    contact: f64,
    mass: &[f64],
    vx: &mut [f64],
    vy: &mut [f64],
) -> bool {
    let side = |i: usize, vx: &[f64], vy: &[f64]| PairSide {
        mass: mass[i],
        vx: vx[i],
        vy: vy[i],
    };
    let (a_side, b_side) = (side(a, vx, vy), side(b, vx, vy));
    match collide_pair(physics, dx, dy, contact, a_side, b_side) {
        (_, Some([[vax, vay], [vbx, vby]])) => {
            (vx[a], vy[a], vx[b], vy[b]) = (vax, vay, vbx, vby);
            true
        }
        (_, None) => false,
    }
}
