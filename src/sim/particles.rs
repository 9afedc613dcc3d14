//! Structure-of-arrays disk state: the one place particle data lives.
//!
//! Invariants (established by scene construction, kept by every stage):
//! all arrays have the same length, `id` is a permutation of `0..len`,
//! every radius and mass is finite and positive. Storage order is free:
//! stages may reorder the arrays together, and anything that must not
//! depend on storage order (pair order, hashes, sums) goes by `id`.

use super::collision::Properties;

/// Positions, velocities and properties of every disk, one `f64` array per quantity.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Particles {
    /// Stable identity of each disk, `0..len`, independent of storage order.
    pub id: Vec<u32>,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub vx: Vec<f64>,
    pub vy: Vec<f64>,
    pub radius: Vec<f64>,
    pub mass: Vec<f64>,
}

/// Values per disk in a packed buffer ([`Particles::pack`]).
pub const PACKED_LEN: usize = 7;

/// What the per-disk half of a step changes and reads: positions and velocities
/// (mutable) and radii, as equal-length slices of a run of disks.
#[derive(Debug)]
pub struct DiskSlices<'a> {
    pub x: &'a mut [f64],
    pub y: &'a mut [f64],
    pub vx: &'a mut [f64],
    pub vy: &'a mut [f64],
    pub radius: &'a [f64],
}

/// One disk, used to build and inspect [`Particles`] (not on hot paths).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Disk {
    pub x: f64,
    pub y: f64,
    pub vx: f64,
    pub vy: f64,
    pub radius: f64,
    pub mass: f64,
}

impl Particles {
    /// Builds the state from disks given in id order.
    pub fn from_disks(disks: &[Disk]) -> Self {
        let mut particles = Particles::with_capacity(disks.len());
        for disk in disks {
            particles.push(*disk);
        }
        particles
    }

    pub fn with_capacity(n_particles: usize) -> Self {
        Particles {
            id: Vec::with_capacity(n_particles),
            x: Vec::with_capacity(n_particles),
            y: Vec::with_capacity(n_particles),
            vx: Vec::with_capacity(n_particles),
            vy: Vec::with_capacity(n_particles),
            radius: Vec::with_capacity(n_particles),
            mass: Vec::with_capacity(n_particles),
        }
    }

    /// Appends a disk with the next id.
    pub fn push(&mut self, disk: Disk) {
        self.id.push(self.len() as u32);
        self.x.push(disk.x);
        self.y.push(disk.y);
        self.vx.push(disk.vx);
        self.vy.push(disk.vy);
        self.radius.push(disk.radius);
        self.mass.push(disk.mass);
    }

    /// All disks as [`DiskSlices`].
    pub fn disk_slices_mut(&mut self) -> DiskSlices<'_> {
        DiskSlices {
            x: &mut self.x,
            y: &mut self.y,
            vx: &mut self.vx,
            vy: &mut self.vy,
            radius: &self.radius,
        }
    }

    pub fn len(&self) -> usize {
        self.id.len()
    }

    pub fn is_empty(&self) -> bool {
        self.id.is_empty()
    }

    /// The disk stored at `idx` (a storage index, not an id).
    pub fn disk(&self, idx: usize) -> Disk {
        Disk {
            x: self.x[idx],
            y: self.y[idx],
            vx: self.vx[idx],
            vy: self.vy[idx],
            radius: self.radius[idx],
            mass: self.mass[idx],
        }
    }

    /// Storage indices in id order: `order[id]` is where disk `id` is stored (as `u32`,
    /// like the ids: half the memory of `usize` in a scene of 10⁸ disks).
    pub fn storage_index_by_id(&self) -> Vec<u32> {
        let mut order = vec![0; self.len()];
        for (idx, &id) in self.id.iter().enumerate() {
            order[id as usize] = idx as u32;
        }
        order
    }

    /// The disks in id order, whatever the storage order.
    pub fn disks_by_id(&self) -> Vec<Disk> {
        self.storage_index_by_id()
            .into_iter()
            .map(|idx| self.disk(idx as usize))
            .collect()
    }

    /// Stores the disks in a new order: `new_order` lists old storage indices, each once.
    pub fn reorder(&mut self, new_order: &[u32]) {
        debug_assert_eq!(new_order.len(), self.len());
        self.replace_arrays(
            |values| new_order.iter().map(|&idx| values[idx as usize]).collect(),
            |ids| new_order.iter().map(|&idx| ids[idx as usize]).collect(),
        );
    }

    /// Replaces every array with what `floats` (for the f64 arrays) or `ids` makes of it.
    pub fn replace_arrays(
        &mut self,
        mut floats: impl FnMut(&[f64]) -> Vec<f64>,
        ids: impl FnOnce(&[u32]) -> Vec<u32>,
    ) {
        self.id = ids(&self.id);
        for values in self.float_arrays_mut() {
            *values = floats(values);
        }
    }

    /// The f64 arrays in packing order: x, y, vx, vy, radius, mass. With `id`, the one
    /// place that lists the arrays, for operations that treat them all alike.
    fn float_arrays_mut(&mut self) -> [&mut Vec<f64>; 6] {
        [
            &mut self.x,
            &mut self.y,
            &mut self.vx,
            &mut self.vy,
            &mut self.radius,
            &mut self.mass,
        ]
    }

    fn float_arrays(&self) -> [&Vec<f64>; 6] {
        [
            &self.x,
            &self.y,
            &self.vx,
            &self.vy,
            &self.radius,
            &self.mass,
        ]
    }

    /// Appends the disk stored at `idx` to `out` as [`PACKED_LEN`] values: id, x, y, vx,
    /// vy, radius, mass (ids below 2^32 are exact in f64).
    pub fn pack(&self, idx: usize, out: &mut Vec<f64>) {
        out.push(f64::from(self.id[idx]));
        out.extend(self.float_arrays().map(|values| values[idx]));
    }

    /// Appends the disks packed in `packed` (records of [`Particles::pack`]), keeping ids.
    pub fn unpack_append(&mut self, packed: &[f64]) {
        for record in packed.chunks_exact(PACKED_LEN) {
            self.id.push(record[0] as u32);
            for (values, &value) in self.float_arrays_mut().into_iter().zip(&record[1..]) {
                values.push(value);
            }
        }
    }

    /// Removes the disk stored at `idx`, moving the last disk into its slot.
    pub fn swap_remove(&mut self, idx: usize) {
        self.id.swap_remove(idx);
        for values in self.float_arrays_mut() {
            values.swap_remove(idx);
        }
    }

    /// Keeps the first `len` disks in storage order.
    pub fn truncate(&mut self, len: usize) {
        self.id.truncate(len);
        for values in self.float_arrays_mut() {
            values.truncate(len);
        }
    }

    /// Σ π r²: the area the disks cover, summed in storage order.
    pub fn disk_area(&self) -> f64 {
        self.radius
            .iter()
            .map(|r| std::f64::consts::PI * r * r)
            .sum()
    }

    /// Largest radius, 0 for an empty set.
    pub fn max_radius(&self) -> f64 {
        self.radius.iter().copied().fold(0.0, f64::max)
    }

    /// The radius and mass of every disk, when all have the same (and there are some).
    pub fn common_properties(&self) -> Option<Properties> {
        let first = Properties {
            radius: *self.radius.first()?,
            mass: *self.mass.first()?,
        };
        let common = self.radius.iter().all(|&radius| radius == first.radius)
            && self.mass.iter().all(|&mass| mass == first.mass);
        common.then_some(first)
    }

    /// Smallest radius, infinite for an empty set.
    pub fn min_radius(&self) -> f64 {
        self.radius.iter().copied().fold(f64::INFINITY, f64::min)
    }

    /// Root-mean-square speed √⟨v²⟩, 0 for an empty set.
    pub fn rms_speed(&self) -> f64 {
        let n = self.vx.len().max(1) as f64;
        let sum: f64 = self
            .vx
            .iter()
            .zip(&self.vy)
            .map(|(vx, vy)| vx * vx + vy * vy)
            .sum();
        (sum / n).sqrt()
    }

    /// Largest speed, 0 for an empty set.
    pub fn max_speed(&self) -> f64 {
        self.vx
            .iter()
            .zip(&self.vy)
            .map(|(vx, vy)| vx.hypot(*vy))
            .fold(0.0, f64::max)
    }
}
