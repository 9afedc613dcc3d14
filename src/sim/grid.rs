//! Broad phase: which disks overlap, found by a cell list (or all pairs, for comparison).
//!
//! Both searches report the same set of overlapping pairs, tested with the same
//! arithmetic ([`Domain::separation_in`]), so the two broad phases give bit-identical
//! runs. The order in which pairs are found is not canonical; the stepper sorts them.

use super::particles::Particles;
use super::scene::{Boundary, Domain};

/// An overlapping pair. `a` is the storage index of the disk with the lower id.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Contact {
    /// `(lower id << 32) | higher id`: sorting by key gives the canonical pair order.
    pub key: u64,
    pub a: u32,
    pub b: u32,
}

impl Contact {
    /// The contact between the disks stored at `i` and `j`, oriented by id.
    #[inline(always)]
    pub fn new(particles: &Particles, i: usize, j: usize) -> Contact {
        let (id_i, id_j) = (particles.id[i], particles.id[j]);
        let (lo, hi, a, b) = if id_i < id_j {
            (id_i, id_j, i, j)
        } else {
            (id_j, id_i, j, i)
        };
        Contact {
            key: (u64::from(lo) << 32) | u64::from(hi),
            a: a as u32,
            b: b as u32,
        }
    }
}

/// Average number of disks per cell the grid aims for. Cells are never narrower than
/// one contact diameter; in dilute scenes wider cells cut the cost of visiting empty ones.
const TARGET_DISKS_PER_CELL: f64 = 1.0;

/// A uniform cell list rebuilt every step by a counting sort.
///
/// Scratch memory only: the caller owns the particles. Positions and radii are copied in
/// cell order so the pair scan reads memory sequentially.
#[derive(Clone, Debug)]
pub struct CellGrid {
    n_cols: usize,
    n_rows: usize,
    inv_cell_width: f64,
    inv_cell_height: f64,
    /// `cell_start[c]..cell_start[c + 1]` are the sorted slots of cell `c`.
    cell_start: Vec<u32>,
    /// Next free slot per cell during the scatter.
    cursor: Vec<u32>,
    /// Cell of each disk, by storage index.
    cell_of: Vec<u32>,
    /// Storage index of the disk in each sorted slot.
    order: Vec<u32>,
    sorted_x: Vec<f64>,
    sorted_y: Vec<f64>,
    sorted_radius: Vec<f64>,
}

impl CellGrid {
    /// A grid for `n_particles` disks no larger than `max_radius` in `domain`.
    ///
    /// A periodic domain must be at least three contact diameters across
    /// (`scene::check_periodic_box`), so the half stencil never visits a cell twice.
    pub fn new(domain: &Domain, max_radius: f64, n_particles: usize) -> CellGrid {
        let contact = 2.0 * max_radius;
        let target = (domain.area() * TARGET_DISKS_PER_CELL / n_particles.max(1) as f64).sqrt();
        let cell = contact.max(target);
        let min_cells = match domain.boundary {
            Boundary::Walls => 1,
            Boundary::Periodic => 3,
        };
        let cells_along = |length: f64| {
            let widest = ((length / contact).floor() as usize).max(1);
            ((length / cell).floor() as usize).clamp(min_cells.min(widest), widest)
        };
        let (n_cols, n_rows) = (cells_along(domain.width), cells_along(domain.height));
        let n_cells = n_cols * n_rows;
        CellGrid {
            n_cols,
            n_rows,
            inv_cell_width: n_cols as f64 / domain.width,
            inv_cell_height: n_rows as f64 / domain.height,
            cell_start: vec![0; n_cells + 1],
            cursor: vec![0; n_cells],
            cell_of: Vec::with_capacity(n_particles),
            order: vec![0; n_particles],
            sorted_x: vec![0.0; n_particles],
            sorted_y: vec![0.0; n_particles],
            sorted_radius: vec![0.0; n_particles],
        }
    }

    pub fn n_cells(&self) -> usize {
        self.n_cols * self.n_rows
    }

    /// Sorts the disks into cells. Disks outside a walled box go to the nearest edge cell,
    /// which still holds every disk they can touch.
    pub fn build(&mut self, particles: &Particles) {
        let n_particles = particles.len();
        self.order.resize(n_particles, 0);
        self.sorted_x.resize(n_particles, 0.0);
        self.sorted_y.resize(n_particles, 0.0);
        self.sorted_radius.resize(n_particles, 0.0);
        self.cell_of.clear();
        self.cell_start.fill(0);
        let (max_col, max_row) = (self.n_cols - 1, self.n_rows - 1);
        for (&x, &y) in particles.x.iter().zip(&particles.y) {
            // `as usize` saturates: negative coordinates (and NaN) land in cell 0.
            let col = ((x * self.inv_cell_width) as usize).min(max_col);
            let row = ((y * self.inv_cell_height) as usize).min(max_row);
            let cell_idx = row * self.n_cols + col;
            self.cell_of.push(cell_idx as u32);
            self.cell_start[cell_idx + 1] += 1;
        }
        let n_cells = self.n_cells();
        for cell_idx in 0..n_cells {
            self.cell_start[cell_idx + 1] += self.cell_start[cell_idx];
        }
        self.cursor.copy_from_slice(&self.cell_start[..n_cells]);
        for (idx, &cell_idx) in self.cell_of.iter().enumerate() {
            let slot = self.cursor[cell_idx as usize] as usize;
            self.cursor[cell_idx as usize] += 1;
            self.order[slot] = idx as u32;
            self.sorted_x[slot] = particles.x[idx];
            self.sorted_y[slot] = particles.y[idx];
            self.sorted_radius[slot] = particles.radius[idx];
        }
    }

    /// Appends every overlapping pair to `contacts` (in no particular order).
    /// Call [`CellGrid::build`] first with the same particles.
    pub fn find_contacts(
        &self,
        particles: &Particles,
        domain: &Domain,
        contacts: &mut Vec<Contact>,
    ) {
        match domain.boundary {
            Boundary::Walls => self.scan::<false>(particles, domain, contacts),
            Boundary::Periodic => self.scan::<true>(particles, domain, contacts),
        }
    }

    /// Visits each cell and the four neighbours after it (east, north-west, north,
    /// north-east), so every adjacent pair of cells is scanned exactly once.
    fn scan<const PERIODIC: bool>(
        &self,
        particles: &Particles,
        domain: &Domain,
        contacts: &mut Vec<Contact>,
    ) {
        let (n_cols, n_rows) = (self.n_cols, self.n_rows);
        for row in 0..n_rows {
            let north = if row + 1 < n_rows {
                Some(row + 1)
            } else if PERIODIC {
                Some(0)
            } else {
                None
            };
            for col in 0..n_cols {
                let cell_idx = row * n_cols + col;
                let (start, end) = (
                    self.cell_start[cell_idx] as usize,
                    self.cell_start[cell_idx + 1] as usize,
                );
                if start == end {
                    continue;
                }
                let east = if col + 1 < n_cols {
                    Some(col + 1)
                } else if PERIODIC {
                    Some(0)
                } else {
                    None
                };
                let west = if col > 0 {
                    Some(col - 1)
                } else if PERIODIC {
                    Some(n_cols - 1)
                } else {
                    None
                };
                for slot_a in start..end {
                    for slot_b in slot_a + 1..end {
                        self.test_pair::<PERIODIC>(particles, domain, slot_a, slot_b, contacts);
                    }
                }
                let neighbours = [
                    east.map(|c| row * n_cols + c),
                    north.and_then(|r| west.map(|c| r * n_cols + c)),
                    north.map(|r| r * n_cols + col),
                    north.and_then(|r| east.map(|c| r * n_cols + c)),
                ];
                for neighbour in neighbours.into_iter().flatten() {
                    let (other_start, other_end) = (
                        self.cell_start[neighbour] as usize,
                        self.cell_start[neighbour + 1] as usize,
                    );
                    for slot_a in start..end {
                        for slot_b in other_start..other_end {
                            self.test_pair::<PERIODIC>(particles, domain, slot_a, slot_b, contacts);
                        }
                    }
                }
            }
        }
    }

    #[inline(always)]
    fn test_pair<const PERIODIC: bool>(
        &self,
        particles: &Particles,
        domain: &Domain,
        slot_a: usize,
        slot_b: usize,
        contacts: &mut Vec<Contact>,
    ) {
        let (dx, dy) = domain.separation_in::<PERIODIC>(
            self.sorted_x[slot_a],
            self.sorted_y[slot_a],
            self.sorted_x[slot_b],
            self.sorted_y[slot_b],
        );
        let contact = self.sorted_radius[slot_a] + self.sorted_radius[slot_b];
        if dx * dx + dy * dy < contact * contact {
            contacts.push(Contact::new(
                particles,
                self.order[slot_a] as usize,
                self.order[slot_b] as usize,
            ));
        }
    }
}

/// The seed report's O(N²) search: every pair tested once. Kept to check the grid.
pub fn find_contacts_all_pairs(
    particles: &Particles,
    domain: &Domain,
    contacts: &mut Vec<Contact>,
) {
    match domain.boundary {
        Boundary::Walls => all_pairs::<false>(particles, domain, contacts),
        Boundary::Periodic => all_pairs::<true>(particles, domain, contacts),
    }
}

fn all_pairs<const PERIODIC: bool>(
    particles: &Particles,
    domain: &Domain,
    contacts: &mut Vec<Contact>,
) {
    let (x, y, radius) = (&particles.x, &particles.y, &particles.radius);
    for i in 0..particles.len() {
        for j in i + 1..particles.len() {
            let (dx, dy) = domain.separation_in::<PERIODIC>(x[i], y[i], x[j], y[j]);
            let contact = radius[i] + radius[j];
            if dx * dx + dy * dy < contact * contact {
                contacts.push(Contact::new(particles, i, j));
            }
        }
    }
}
