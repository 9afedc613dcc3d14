//! Uniform cells over the box and each cell's neighbourhood with the periodic image
//! shift of every neighbour ([`CellGrid`]), and singly linked member lists over them
//! ([`CellList`]): the broad phase of the event-driven method (`sim::event`, which keeps
//! its members' links in its own per-disk state) and of the swept missed-collision test
//! (`sim::observe`). The time-stepped method has its own strips (`sim::grid`).

use super::scene::{Boundary, Domain};

/// End of a member list.
pub const NONE: u32 = u32::MAX;

/// A neighbouring cell and the shift that turns a position stored in it into the image
/// seen from the centre cell (non-zero only across a periodic edge).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Neighbour {
    pub cell: usize,
    pub shift_x: f64,
    pub shift_y: f64,
}

/// `n_cols × n_rows` cells covering `[0, width] × [0, height]`, each at least as wide
/// as asked.
#[derive(Clone, Debug)]
pub struct CellGrid {
    pub n_cols: usize,
    pub n_rows: usize,
    pub cell_width: f64,
    pub cell_height: f64,
    width: f64,
    height: f64,
    periodic: bool,
}

impl CellGrid {
    /// Cells at least `min_side` across for `n_particles` disks. A sparse box gets
    /// wider cells, so that there are never more than about 4 cells per disk.
    pub fn new(domain: &Domain, min_side: f64, n_particles: usize) -> CellGrid {
        let max_cells = 4.0 * n_particles as f64 + 16.0;
        let side = min_side.max((domain.area() / max_cells).sqrt());
        let n_cols = ((domain.width / side).floor() as usize).max(1);
        let n_rows = ((domain.height / side).floor() as usize).max(1);
        CellGrid {
            n_cols,
            n_rows,
            cell_width: domain.width / n_cols as f64,
            cell_height: domain.height / n_rows as f64,
            width: domain.width,
            height: domain.height,
            periodic: domain.boundary == Boundary::Periodic,
        }
    }

    /// Column and row of a point; points outside the box go to the nearest edge cell
    /// (`as usize` saturates negative values to 0).
    #[inline(always)]
    pub fn cell_of(&self, x: f64, y: f64) -> (usize, usize) {
        (
            ((x / self.cell_width) as usize).min(self.n_cols - 1),
            ((y / self.cell_height) as usize).min(self.n_rows - 1),
        )
    }

    #[inline(always)]
    pub fn index(&self, col: usize, row: usize) -> usize {
        row * self.n_cols + col
    }

    /// Cells in all.
    pub fn len(&self) -> usize {
        self.n_cols * self.n_rows
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The cell at `(col + d_col, row + d_row)` with its image shift, `None` beyond a wall.
    #[inline]
    pub fn offset(&self, col: usize, row: usize, d_col: i64, d_row: i64) -> Option<Neighbour> {
        let (c, shift_x) = wrap(col as i64 + d_col, self.n_cols, self.width, self.periodic)?;
        let (r, shift_y) = wrap(row as i64 + d_row, self.n_rows, self.height, self.periodic)?;
        Some(Neighbour {
            cell: self.index(c, r),
            shift_x,
            shift_y,
        })
    }

    /// The 3 × 3 cells around `(col, row)` (fewer beside a wall), each with its shift.
    /// In a periodic box narrower than 3 cells a cell appears once per image.
    pub fn neighbourhood(&self, col: usize, row: usize) -> impl Iterator<Item = Neighbour> + '_ {
        (-1..=1).flat_map(move |d_row| {
            (-1..=1).filter_map(move |d_col| self.offset(col, row, d_col, d_row))
        })
    }
}

/// A [`CellGrid`] with the disks (by index) in each cell, as singly linked lists.
#[derive(Clone, Debug)]
pub struct CellList {
    pub grid: CellGrid,
    head: Vec<u32>,
    next: Vec<u32>,
}

impl CellList {
    /// Empty cells at least `min_side` across for `n_particles` disks (see [`CellGrid::new`]).
    pub fn new(domain: &Domain, min_side: f64, n_particles: usize) -> CellList {
        let grid = CellGrid::new(domain, min_side, n_particles);
        CellList {
            head: vec![NONE; grid.len()],
            next: vec![NONE; n_particles],
            grid,
        }
    }

    /// Adds disk `disk` to cell `cell`.
    #[inline]
    pub fn insert(&mut self, disk: u32, cell: usize) {
        self.next[disk as usize] = self.head[cell];
        self.head[cell] = disk;
    }

    /// The first disk of a cell ([`NONE`] when empty); follow with [`CellList::next_in_cell`].
    #[inline(always)]
    pub fn first_in_cell(&self, cell: usize) -> u32 {
        self.head[cell]
    }

    #[inline(always)]
    pub fn next_in_cell(&self, disk: u32) -> u32 {
        self.next[disk as usize]
    }
}

/// A column (or row) index moved off the grid: wrapped with the shift of its image in a
/// periodic box, `None` beyond a wall.
#[inline(always)]
fn wrap(index: i64, count: usize, length: f64, periodic: bool) -> Option<(usize, f64)> {
    let count = count as i64;
    if (0..count).contains(&index) {
        Some((index as usize, 0.0))
    } else if !periodic {
        None
    } else if index < 0 {
        Some(((index + count) as usize, -length))
    } else {
        Some(((index - count) as usize, length))
    }
}
