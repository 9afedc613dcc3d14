//! Structure-of-arrays disk state: the one place particle data lives.
//!
//! Invariants (established by scene construction, kept by every stage):
//! all arrays have the same length, `id` is a permutation of `0..len`,
//! every radius and mass is finite and positive. Storage order is free:
//! stages may reorder the arrays together, and anything that must not
//! depend on storage order (pair order, hashes, sums) goes by `id`.

use std::ops::{Index, Range};

use super::pieces::{InTurn, MIN_STREAMING_PIECE, Pieces, split_at_ranges};
use super::prefetch::prefetch;

/// Positions, velocities and properties of every disk, one `f64` array per quantity;
/// a property that every disk shares is held once ([`PerDisk`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Particles {
    /// Stable identity of each disk, `0..len`, independent of storage order.
    pub id: Vec<u32>,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub vx: Vec<f64>,
    pub vy: Vec<f64>,
    pub radius: PerDisk,
    pub mass: PerDisk,
}

/// A property of every disk (radius, mass), by storage index: one value when every
/// disk has the same, which costs no memory per disk (a scene of equal disks needs no
/// more), else one value per disk. Reads give the same values either way.
#[derive(Clone, Debug)]
pub enum PerDisk {
    /// `len` disks, each with `value`.
    Shared { value: f64, len: usize },
    /// One value per disk, in storage order.
    Each(Vec<f64>),
}

impl Default for PerDisk {
    fn default() -> Self {
        PerDisk::Shared { value: 0.0, len: 0 }
    }
}

impl PerDisk {
    /// Disks that can be appended without moving the values (any number when shared).
    fn room(&self) -> usize {
        match self {
            PerDisk::Shared { .. } => usize::MAX,
            PerDisk::Each(values) => values.capacity() - values.len(),
        }
    }

    /// Makes room for `additional` more values than held, exactly (nothing when shared).
    fn reserve_exact(&mut self, additional: usize) {
        if let PerDisk::Each(values) = self {
            values.reserve_exact(additional);
        }
    }

    /// The values of `values.len()` disks, held once when all are the same (bit for bit).
    pub fn from_values(values: Vec<f64>) -> PerDisk {
        match values.first() {
            Some(&first) if values.iter().all(|v| v.to_bits() == first.to_bits()) => {
                PerDisk::Shared {
                    value: first,
                    len: values.len(),
                }
            }
            _ => PerDisk::Each(values),
        }
    }

    /// Each disk's value passed through `f`.
    pub fn map(&self, f: impl Fn(f64) -> f64) -> PerDisk {
        match self {
            PerDisk::Shared { value, len } => PerDisk::Shared {
                value: f(*value),
                len: *len,
            },
            PerDisk::Each(values) => PerDisk::from_values(values.iter().map(|&v| f(v)).collect()),
        }
    }

    pub fn len(&self) -> usize {
        match self {
            PerDisk::Shared { len, .. } => *len,
            PerDisk::Each(values) => values.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The value every disk has, when held once.
    pub fn shared(&self) -> Option<f64> {
        match self {
            PerDisk::Shared { value, len } if *len > 0 => Some(*value),
            _ => None,
        }
    }

    /// The values one per disk, unless held once.
    pub fn as_slice(&self) -> Option<&[f64]> {
        match self {
            PerDisk::Shared { .. } => None,
            PerDisk::Each(values) => Some(values),
        }
    }

    /// The values of the disks stored in `range`.
    pub fn slice(&self, range: Range<usize>) -> PerDiskSlice<'_> {
        match self {
            PerDisk::Shared { value, len } => {
                assert!(range.start <= range.end && range.end <= *len, "in bounds");
                PerDiskSlice::Shared {
                    value: *value,
                    len: range.len(),
                }
            }
            PerDisk::Each(values) => PerDiskSlice::Each(&values[range]),
        }
    }

    pub fn iter(&self) -> PerDiskIter<'_> {
        match self {
            PerDisk::Shared { value, len } => PerDiskIter::Shared(std::iter::repeat_n(value, *len)),
            PerDisk::Each(values) => PerDiskIter::Each(values.iter()),
        }
    }

    /// Appends a disk's value; the first that differs from a shared value makes the
    /// values one per disk.
    pub fn push(&mut self, new: f64) {
        match self {
            PerDisk::Shared { len: 0, .. } => {
                *self = PerDisk::Shared { value: new, len: 1 };
            }
            PerDisk::Shared { value, len } if value.to_bits() == new.to_bits() => *len += 1,
            PerDisk::Shared { value, len } => {
                let mut values = vec![*value; *len];
                values.push(new);
                *self = PerDisk::Each(values);
            }
            PerDisk::Each(values) => values.push(new),
        }
    }

    /// Removes the disk stored at `idx`, moving the last disk into its slot.
    pub fn swap_remove(&mut self, idx: usize) {
        match self {
            PerDisk::Shared { len, .. } => {
                assert!(idx < *len, "in bounds");
                *len -= 1;
            }
            PerDisk::Each(values) => {
                values.swap_remove(idx);
            }
        }
    }

    /// Keeps the first `new_len` disks.
    pub fn truncate(&mut self, new_len: usize) {
        match self {
            PerDisk::Shared { len, .. } => *len = (*len).min(new_len),
            PerDisk::Each(values) => values.truncate(new_len),
        }
    }

    /// The values held one per disk, if they are (a shared value has none to reorder).
    fn values_mut(&mut self) -> Option<&mut Vec<f64>> {
        match self {
            PerDisk::Shared { .. } => None,
            PerDisk::Each(values) => Some(values),
        }
    }

    /// Asks the memory system for the value of the disk stored at `idx` (nothing to ask
    /// for a shared value).
    #[inline(always)]
    pub fn prefetch(&self, idx: usize) {
        if let PerDisk::Each(values) = self {
            prefetch(values.as_ptr().wrapping_add(idx));
        }
    }
}

impl Index<usize> for PerDisk {
    type Output = f64;

    #[inline(always)]
    fn index(&self, idx: usize) -> &f64 {
        match self {
            PerDisk::Shared { value, len } => {
                assert!(idx < *len, "index {idx} out of bounds for {len} disks");
                value
            }
            PerDisk::Each(values) => &values[idx],
        }
    }
}

/// Equal when the values are, however held.
impl PartialEq for PerDisk {
    fn eq(&self, other: &Self) -> bool {
        self.len() == other.len() && self.iter().eq(other.iter())
    }
}

impl<'a> IntoIterator for &'a PerDisk {
    type Item = &'a f64;
    type IntoIter = PerDiskIter<'a>;

    fn into_iter(self) -> PerDiskIter<'a> {
        self.iter()
    }
}

/// The values of [`PerDisk::iter`].
pub enum PerDiskIter<'a> {
    Shared(std::iter::RepeatN<&'a f64>),
    Each(std::slice::Iter<'a, f64>),
}

impl<'a> Iterator for PerDiskIter<'a> {
    type Item = &'a f64;

    fn next(&mut self) -> Option<&'a f64> {
        match self {
            PerDiskIter::Shared(values) => values.next(),
            PerDiskIter::Each(values) => values.next(),
        }
    }
}

/// The values of a run of disks ([`PerDisk::slice`]).
#[derive(Clone, Copy, Debug)]
pub enum PerDiskSlice<'a> {
    Shared { value: f64, len: usize },
    Each(&'a [f64]),
}

impl<'a> PerDiskSlice<'a> {
    pub fn len(&self) -> usize {
        match self {
            PerDiskSlice::Shared { len, .. } => *len,
            PerDiskSlice::Each(values) => values.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Consecutive runs of `chunk` disks (the last may be shorter).
    pub fn chunks(self, chunk: usize) -> impl Iterator<Item = PerDiskSlice<'a>> {
        let len = self.len();
        (0..len).step_by(chunk.max(1)).map(move |start| {
            let end = (start + chunk).min(len);
            match self {
                PerDiskSlice::Shared { value, .. } => PerDiskSlice::Shared {
                    value,
                    len: end - start,
                },
                PerDiskSlice::Each(values) => PerDiskSlice::Each(&values[start..end]),
            }
        })
    }
}

/// `pass(start, piece)` on the pieces of `values` that `pieces` cuts ([`Pieces::cut`]:
/// at least [`MIN_STREAMING_PIECE`] values each), `start` the index of a piece's first.
fn in_pieces<T: Send>(
    pieces: &impl Pieces,
    values: &mut [T],
    pass: impl Fn(usize, &mut [T]) + Sync,
) {
    let ranges = pieces.cut(values.len(), MIN_STREAMING_PIECE, 1);
    let starts = ranges.iter().map(|range| range.start);
    let mut cut: Vec<_> = starts.zip(split_at_ranges(values, &ranges)).collect();
    pieces.for_each(&mut cut, |(start, piece)| pass(*start, piece));
}

/// Fills `into` with the `values` at the indices `order` lists, in order (as many).
fn gather<T: Copy>(values: &[T], order: &[u32], into: &mut [T]) {
    debug_assert_eq!(order.len(), into.len());
    for (slot, &idx) in into.iter_mut().zip(order) {
        *slot = values[idx as usize];
    }
}

/// A re-storing in place ([`permute_in_place`]) gives way to gathering the arrays whole
/// when more than one disk in this many was stored far before its new slot.
const MAX_FAR_SHARE: usize = 64;

/// The furthest from its new slot a re-storing in place reads a disk from its ring
/// (a ring of 2¹⁶ disks, 2.6 MB of equal disks' values): a box only a few strips tall
/// has strips as long as the disks are many, and the ring is held whole.
const MAX_PERMUTE_REACH: usize = (1 << 15) - 1;

/// One disk's values in the `M` arrays of a re-storing in place, and its id.
type Held<const M: usize> = ([f64; M], u32);

/// The values and id of the disk stored at slot `j`.
fn held<const M: usize>(arrays: &[impl AsRef<[f64]>; M], ids: &[u32], j: usize) -> Held<M> {
    (std::array::from_fn(|k| arrays[k].as_ref()[j]), ids[j])
}

/// Puts into slot i of `arrays` and `ids` what was at `order[i]` (a permutation), in
/// place, and returns true; or, when a piece would save more than one disk in
/// [`MAX_FAR_SHARE`] of its slots from far off (a scene's first re-storing, from
/// placement order), returns false having written nothing.
///
/// The slots are cut into pieces ([`Pieces::cut`]), each written in one pass, the
/// pieces perhaps at once. The old values of a piece's slots within `reach` (or a
/// little more, at most [`MAX_PERMUTE_REACH`]) of the one written are held in a ring,
/// each saved before its slot is written, so a disk stored that near its new slot is
/// read from the ring; one stored further after it, in the same piece, is read from its
/// array (not yet written there); any other, from values saved before any piece writes
/// ([`save_out_of_reach`]). The ring, not the arrays, takes the scattered reads: at 10⁷
/// disks (packing 0.3) this took 4.4–4.7 ns per disk where gathering each array whole
/// into a spare one took 7.7.
fn permute_in_place<const M: usize>(
    arrays: [&mut [f64]; M],
    ids: &mut [u32],
    order: &[u32],
    reach: usize,
    pieces: &impl Pieces,
) -> bool {
    let n = order.len();
    assert!(arrays.iter().all(|values| values.len() == n) && ids.len() == n);
    let ring_len = (2 * reach.min(MAX_PERMUTE_REACH) + 2).next_power_of_two();
    // The ring holds the slots from `i - reach` to `i + reach` while slot i is written.
    let reach = ring_len / 2 - 1;
    // Pieces at least a ring long: the values saved across their edges stay few.
    let bounds = pieces.cut(n, ring_len, 1);
    let n_pieces = bounds.len();
    let mut saved: Vec<Option<Vec<Held<M>>>> = vec![None; n_pieces];
    {
        let arrays = arrays.each_ref().map(|values| &**values);
        let ids = &*ids;
        let mut saving: Vec<_> = bounds.iter().zip(&mut saved).collect();
        pieces.for_each(&mut saving, |(slots, saved)| {
            **saved = save_out_of_reach(&arrays, ids, order, (*slots).clone(), reach);
        });
    }
    let Some(saved) = saved.into_iter().collect::<Option<Vec<_>>>() else {
        return false;
    };
    let mut columns = arrays.map(|values| split_at_ranges(values, &bounds).into_iter());
    let ids = split_at_ranges(ids, &bounds);
    let mut writes: Vec<_> = (bounds.iter().zip(ids).zip(saved))
        .map(|((slots, ids), saved)| {
            let values = columns
                .each_mut()
                .map(|pieces| pieces.next().expect("a piece"));
            (slots.start, values, ids, &order[slots.clone()], saved)
        })
        .collect();
    pieces.for_each(&mut writes, |(first, arrays, ids, order, saved)| {
        let mut saved = std::mem::take(saved).into_iter();
        permute_piece(arrays, ids, order, *first, reach, ring_len, &mut saved);
    });
    true
}

/// Whether the disk stored at slot `j` is read from outside the ring and the arrays
/// by the piece of slots `first..first + len` when it writes slot `i` (both indices
/// within the piece's own: `i - first`, `j - first` wrapped): stored outside the piece,
/// or more than `reach` slots before `i`.
fn is_out_of_reach(i: usize, j: usize, len: usize, reach: usize) -> bool {
    j >= len || j + reach < i
}

/// The old values (and ids) that the piece of slots `slots` reads from outside its ring
/// and its own slots not yet written ([`is_out_of_reach`]), in the order it reads them;
/// `None` when more than one in [`MAX_FAR_SHARE`] of its slots would read so a disk
/// stored more than `reach` slots from it.
fn save_out_of_reach<const M: usize>(
    arrays: &[&[f64]; M],
    ids: &[u32],
    order: &[u32],
    slots: Range<usize>,
    reach: usize,
) -> Option<Vec<Held<M>>> {
    let mut saved = Vec::new();
    let mut far = 0;
    for (i, &j) in slots.clone().zip(&order[slots.clone()]) {
        let j = j as usize;
        let local = j.wrapping_sub(slots.start);
        if is_out_of_reach(i - slots.start, local, slots.len(), reach) {
            if j + reach < i || j > i + reach {
                far += 1;
                if far * MAX_FAR_SHARE > slots.len() {
                    return None;
                }
            }
            saved.push(held(arrays, ids, j));
        }
    }
    Some(saved)
}

/// Writes one piece of [`permute_in_place`]: slot `first + i` of the whole takes the
/// disk stored at `order[i]`, read from the ring, from the piece's slot not yet written,
/// or from `saved`.
fn permute_piece<const M: usize>(
    arrays: &mut [&mut [f64]; M],
    ids: &mut [u32],
    order: &[u32],
    first: usize,
    reach: usize,
    ring_len: usize,
    saved: &mut impl Iterator<Item = Held<M>>,
) {
    let n = order.len();
    let mask = ring_len - 1;
    let mut ring = vec![([0.0; M], 0_u32); ring_len];
    for (j, slot) in ring.iter_mut().enumerate().take(reach.min(n)) {
        *slot = held(arrays, ids, j);
    }
    for (i, &j) in order.iter().enumerate() {
        if i + reach < n {
            ring[(i + reach) & mask] = held(arrays, ids, i + reach);
        }
        let j = (j as usize).wrapping_sub(first);
        let (values, id) = if is_out_of_reach(i, j, n, reach) {
            saved
                .next()
                .expect("every disk read from outside the ring was saved")
        } else if j <= i + reach {
            ring[j & mask]
        } else {
            held(arrays, ids, j)
        };
        for (array, value) in arrays.iter_mut().zip(values) {
            array[i] = value;
        }
        ids[i] = id;
    }
}

/// Replaces each storage index in `slots` with the id of the disk stored there: the ids
/// in a new order, [`gather`] done in place into the order itself.
fn label_in_place(ids: &[u32], slots: &mut [u32]) {
    for slot in slots {
        *slot = ids[*slot as usize];
    }
}

/// Borrowed memory a re-storing works in ([`Particles::gather_arrays`]): the new order,
/// and room for one array of values, each as long as the disks.
#[derive(Debug)]
pub struct ReorderScratch<'a> {
    pub order: &'a mut [u32],
    pub spare: &'a mut [f64],
}

/// Arrays and scratch by storage index that grow as a worker's disks come and go keep
/// this share of their length spare: an MPI rank's count moves by a few disks a step.
pub const SPARE_SHARE: usize = 16;

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
    pub radius: PerDiskSlice<'a>,
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
            radius: PerDisk::default(),
            mass: PerDisk::default(),
        }
    }

    /// Disks that can be appended without moving any array.
    pub fn room(&self) -> usize {
        let motion = [&self.x, &self.y, &self.vx, &self.vy];
        let motion = motion.map(|values| values.capacity() - values.len());
        let others = [
            self.id.capacity() - self.id.len(),
            self.radius.room(),
            self.mass.room(),
        ];
        motion.into_iter().chain(others).min().unwrap_or(0)
    }

    /// Makes room for `additional` more disks than held, exactly: an append past the
    /// room moves every array to one twice as long.
    pub fn reserve_exact(&mut self, additional: usize) {
        self.id.reserve_exact(additional);
        let (motion, properties) = self.arrays_mut();
        for values in motion {
            values.reserve_exact(additional);
        }
        for values in properties {
            values.reserve_exact(additional);
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
            radius: self.radius.slice(0..self.id.len()),
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
        let mut spare = vec![0.0; self.len()];
        let scratch = ReorderScratch {
            order: &mut new_order.to_vec(),
            spare: &mut spare,
        };
        self.gather_arrays(scratch, &InTurn);
    }

    /// Stores the disks in the new order `scratch.order` (old storage indices, each
    /// once), most of them stored within `reach` slots of their new one: in place in one
    /// pass ([`permute_in_place`]), which reads and writes each array once; or, when too
    /// many were stored far from it (a scene's first re-storing, from placement order),
    /// by gathering the arrays one by one in the scratch ([`Particles::gather_arrays`]).
    /// Either leaves the same disks in the same slots, in one piece or many (`pieces`).
    pub fn store_in_order(
        &mut self,
        scratch: ReorderScratch<'_>,
        reach: usize,
        pieces: &impl Pieces,
    ) {
        let order = &*scratch.order;
        let Particles {
            id,
            x,
            y,
            vx,
            vy,
            radius,
            mass,
        } = &mut *self;
        let [x, y, vx, vy] = [&mut x[..], &mut y[..], &mut vx[..], &mut vy[..]];
        let in_place = match (radius, mass) {
            (PerDisk::Each(radius), PerDisk::Each(mass)) => {
                permute_in_place([x, y, vx, vy, radius, mass], id, order, reach, pieces)
            }
            (PerDisk::Each(values), PerDisk::Shared { .. })
            | (PerDisk::Shared { .. }, PerDisk::Each(values)) => {
                permute_in_place([x, y, vx, vy, values], id, order, reach, pieces)
            }
            (PerDisk::Shared { .. }, PerDisk::Shared { .. }) => {
                permute_in_place([x, y, vx, vy], id, order, reach, pieces)
            }
        };
        if !in_place {
            self.gather_arrays(scratch, pieces);
        }
    }

    /// Stores the disks in the new order `scratch.order` (old storage indices, each
    /// once), without taking memory: every f64 array (and property held one per disk)
    /// is gathered, in `pieces`, into a buffer whose values were already gathered (the
    /// first into `scratch.spare`, which is copied into the last freed buffer at the
    /// end); the order is turned into the ids ([`label_in_place`]) and copied over them.
    /// Both scratch slices are left holding values of no use.
    fn gather_arrays(&mut self, scratch: ReorderScratch<'_>, pieces: &impl Pieces) {
        let ReorderScratch { order, spare } = scratch;
        let n = self.len();
        assert_eq!(order.len(), n, "an order of every disk");
        assert_eq!(spare.len(), n, "a spare array of one value per disk");
        let floats = |values: &[f64], into: &mut [f64]| {
            in_pieces(pieces, into, |start, into| {
                gather(values, &order[start..start + into.len()], into)
            })
        };
        {
            let (motion, properties) = self.arrays_mut();
            let per_disk = properties.into_iter().filter_map(PerDisk::values_mut);
            let mut arrays = motion.into_iter().chain(per_disk);
            if let Some(first) = arrays.next() {
                floats(first, spare);
                // The first array's values are gathered: each next array goes into its
                // buffer and hands over its own, which the first then holds.
                for values in arrays {
                    floats(values, first);
                    std::mem::swap(first, values);
                }
                first.copy_from_slice(spare);
            }
        }
        let ids = &self.id;
        in_pieces(pieces, order, |_, slots| label_in_place(ids, slots));
        self.id.copy_from_slice(order);
    }

    /// The positions and velocities (x, y, vx, vy) and the properties (radius, mass), in
    /// packing order. With `id`, the one place that lists the arrays, for operations that
    /// treat them all alike.
    fn arrays_mut(&mut self) -> ([&mut Vec<f64>; 4], [&mut PerDisk; 2]) {
        let Particles {
            id: _,
            x,
            y,
            vx,
            vy,
            radius,
            mass,
        } = self;
        ([x, y, vx, vy], [radius, mass])
    }

    /// The positions and velocities in packing order ([`Particles::arrays_mut`]).
    fn motion_arrays_mut(&mut self) -> [&mut Vec<f64>; 4] {
        self.arrays_mut().0
    }

    /// The properties in packing order ([`Particles::arrays_mut`]).
    fn properties_mut(&mut self) -> [&mut PerDisk; 2] {
        self.arrays_mut().1
    }

    /// Appends the disk stored at `idx` to `out` as [`PACKED_LEN`] values: id, x, y, vx,
    /// vy, radius, mass (ids below 2^32 are exact in f64).
    pub fn pack(&self, idx: usize, out: &mut Vec<f64>) {
        out.push(f64::from(self.id[idx]));
        out.extend([&self.x, &self.y, &self.vx, &self.vy].map(|values| values[idx]));
        out.extend([&self.radius, &self.mass].map(|values| values[idx]));
    }

    /// Appends the disks packed in `packed` (records of [`Particles::pack`]), keeping ids.
    pub fn unpack_append(&mut self, packed: &[f64]) {
        for record in packed.chunks_exact(PACKED_LEN) {
            self.id.push(record[0] as u32);
            let (motion, properties) = record[1..].split_at(4);
            for (values, &value) in self.motion_arrays_mut().into_iter().zip(motion) {
                values.push(value);
            }
            for (values, &value) in self.properties_mut().into_iter().zip(properties) {
                values.push(value);
            }
        }
    }

    /// Removes the disk stored at `idx`, moving the last disk into its slot.
    pub fn swap_remove(&mut self, idx: usize) {
        self.id.swap_remove(idx);
        for values in self.motion_arrays_mut() {
            values.swap_remove(idx);
        }
        for values in self.properties_mut() {
            values.swap_remove(idx);
        }
    }

    /// Keeps the first `len` disks in storage order.
    pub fn truncate(&mut self, len: usize) {
        self.id.truncate(len);
        for values in self.motion_arrays_mut() {
            values.truncate(len);
        }
        for values in self.properties_mut() {
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

    /// What the strips and the lists' skin are sized by.
    pub fn figures(&self) -> DiskFigures {
        DiskFigures {
            n_disks: self.len(),
            disk_area: self.disk_area(),
            max_radius: self.max_radius(),
            min_radius: self.min_radius(),
            max_speed: self.max_speed(),
        }
    }
}

/// What sizes the strips, the lists' skin and a dt rule: of all the scene's disks, even
/// where a rank holds only some of them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiskFigures {
    pub n_disks: usize,
    /// Σ π r².
    pub disk_area: f64,
    pub max_radius: f64,
    pub min_radius: f64,
    pub max_speed: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::pieces::Backwards;

    fn disk(x: f64, radius: f64) -> Disk {
        Disk {
            x,
            y: 1.0,
            vx: 0.5,
            vy: -0.5,
            radius,
            mass: 2.0,
        }
    }

    /// Equal disks hold their radius and mass once, through every operation that keeps
    /// them equal; the first unequal disk makes them one per disk, with the same values.
    #[test]
    fn a_shared_property_stays_shared_until_a_disk_differs() {
        let mut particles = Particles::from_disks(&[disk(1.0, 0.5), disk(2.0, 0.5)]);
        assert_eq!(particles.radius.shared(), Some(0.5));
        assert_eq!(particles.mass.shared(), Some(2.0));
        let mut packed = Vec::new();
        particles.pack(1, &mut packed);
        particles.unpack_append(&packed);
        particles.reorder(&[2, 0, 1]);
        particles.swap_remove(0);
        assert_eq!(particles.radius.shared(), Some(0.5));
        assert_eq!(particles.len(), 2);
        assert_eq!(particles.radius.len(), 2);

        particles.push(disk(3.0, 0.75));
        assert_eq!(particles.radius.shared(), None);
        assert_eq!(particles.radius.as_slice(), Some(&[0.5, 0.5, 0.75][..]));
        assert_eq!(
            particles.mass.shared(),
            Some(2.0),
            "the masses are still equal"
        );
        particles.reorder(&[2, 0, 1]);
        assert_eq!(particles.radius.as_slice(), Some(&[0.75, 0.5, 0.5][..]));
        particles.truncate(1);
        assert_eq!(particles.disk(0), disk(3.0, 0.75));
    }

    /// Room made for k disks holds k appended disks where they are, in every array a
    /// disk has (unequal radii too); a shared property has room for any number.
    #[test]
    fn disks_appended_within_the_room_move_no_array() {
        let mut particles = Particles::from_disks(&[disk(1.0, 0.5), disk(2.0, 0.75)]);
        particles.reserve_exact(5);
        assert!(particles.room() >= 5);
        let addresses = |p: &Particles| {
            let radius = p.radius.as_slice().expect("unequal radii").as_ptr();
            [
                p.x.as_ptr(),
                p.y.as_ptr(),
                p.vx.as_ptr(),
                p.vy.as_ptr(),
                radius,
            ]
        };
        let (before, id_before) = (addresses(&particles), particles.id.as_ptr());
        let mut packed = Vec::new();
        for idx in [0, 1, 0, 1, 0] {
            particles.pack(idx, &mut packed);
        }
        particles.unpack_append(&packed);
        assert_eq!(particles.len(), 7);
        assert_eq!(addresses(&particles), before);
        assert_eq!(particles.id.as_ptr(), id_before);
        assert_eq!(particles.mass.shared(), Some(2.0));
        assert_eq!(particles.mass.room(), usize::MAX);
    }

    /// How a property is held does not change what it is: values, equality, slices.
    #[test]
    fn shared_and_per_disk_values_read_the_same() {
        let shared = PerDisk::from_values(vec![1.5; 5]);
        let each = PerDisk::Each(vec![1.5; 5]);
        assert_eq!(shared.shared(), Some(1.5));
        assert_eq!(shared, each);
        assert_ne!(shared, PerDisk::from_values(vec![1.5; 4]));
        assert_ne!(shared, PerDisk::from_values(vec![1.5, 1.5, 1.5, 1.5, 2.0]));
        for idx in 0..5 {
            assert_eq!(shared[idx].to_bits(), each[idx].to_bits());
        }
        let lens = |values: &PerDisk| -> Vec<usize> {
            values.slice(1..5).chunks(3).map(|c| c.len()).collect()
        };
        assert_eq!(lens(&shared), [3, 1]);
        assert_eq!(lens(&each), [3, 1]);
        assert_eq!(shared.map(|r| r * 2.0).shared(), Some(3.0));
    }

    /// A re-storing in place puts every disk where gathering each array whole does:
    /// disks stored a few slots either side of their new one and at the ring's edges
    /// (read from the ring), one slot past them (read in place ahead, saved before the
    /// pass behind) and far off, with shared or per-disk radii and masses; and an order
    /// that scatters every disk, which is gathered whole. The same in pieces (run in
    /// reverse), whose edges cut through disks read from the ring or ahead, and one that
    /// reads only from the pieces after it.
    #[test]
    fn a_restoring_in_place_stores_the_disks_as_gathering_does() {
        let n = 1000_u32;
        // A ring of 32 slots: those within 15 of the one written.
        let reach = 15;
        let mut near: Vec<u32> = (0..n).collect();
        for pair in near[..400].chunks_mut(2) {
            pair.swap(0, 1);
        }
        near[20..40].rotate_left(13);
        // Slot 500 takes the disk 15 before it, 485 the one 15 after it: the ring's edges.
        near.swap(485, 500);
        // One past the edges: 16 before, 16 after.
        near.swap(584, 600);
        // Far: slot 10 takes disk 900, slot 900 disk 10.
        near.swap(10, 900);
        // Across the edges of pieces: at 336 and 756 (84 slots each, as cut for three
        // workers), at 750 (125 each, two workers).
        near[325..345].rotate_right(7);
        near[740..760].rotate_left(12);
        let scattered: Vec<u32> = (0..n).map(|k| k * 7919 % n).collect();

        let values =
            |k: usize| -> Vec<f64> { (0..n).map(|i| f64::from(i) + k as f64 * 0.25).collect() };
        let first_ids: Vec<u32> = (0..n).map(|i| i * 3).collect();
        for workers in [1, 2, 3] {
            let mut arrays: [Vec<f64>; 5] = std::array::from_fn(values);
            let mut ids = first_ids.clone();
            let expected: Vec<Vec<f64>> = arrays
                .iter()
                .map(|a| near.iter().map(|&j| a[j as usize]).collect())
                .collect();
            let expected_ids: Vec<u32> = near.iter().map(|&j| ids[j as usize]).collect();
            let [a, b, c, d, e] = &mut arrays;
            let arrays_now = [&mut a[..], b, c, d, e];
            let cut = Backwards(workers);
            assert!(
                permute_in_place(arrays_now, &mut ids, &near, reach, &cut),
                "in place for {workers} workers"
            );
            assert_eq!(
                arrays.to_vec(),
                expected,
                "values in place, {workers} workers"
            );
            assert_eq!(ids, expected_ids, "ids in place, {workers} workers");
            // Scattered: given way to gathering, nothing written.
            let [a, b, c, d, e] = &mut arrays;
            let arrays_now = [&mut a[..], b, c, d, e];
            assert!(!permute_in_place(
                arrays_now, &mut ids, &scattered, reach, &cut
            ));
            assert_eq!(
                arrays.to_vec(),
                expected,
                "values untouched, {workers} workers"
            );
            assert_eq!(ids, expected_ids, "ids untouched, {workers} workers");
        }
        // Every disk one slot on: each piece's last slot reads the next piece's first.
        let shifted: Vec<u32> = (0..n).map(|k| (k + 1) % n).collect();
        let mut arrays: [Vec<f64>; 1] = [values(0)];
        let mut ids = first_ids.clone();
        let [a] = &mut arrays;
        assert!(permute_in_place(
            [&mut a[..]],
            &mut ids,
            &shifted,
            reach,
            &Backwards(2)
        ));
        assert_eq!(
            arrays[0],
            shifted.iter().map(|&j| f64::from(j)).collect::<Vec<_>>()
        );

        for unequal in [false, true] {
            let disks: Vec<Disk> = (0..n)
                .map(|k| Disk {
                    x: f64::from(k),
                    y: f64::from(k) * 0.5,
                    vx: -f64::from(k),
                    vy: f64::from(k) * 2.0,
                    radius: if unequal {
                        1.0 + f64::from(k) * 1e-3
                    } else {
                        1.0
                    },
                    mass: if unequal {
                        2.0 + f64::from(k) * 1e-3
                    } else {
                        2.0
                    },
                })
                .collect();
            for (order, pieces) in [&near, &scattered].into_iter().zip([1, 3]) {
                let mut gathered = Particles::from_disks(&disks);
                gathered.reorder(order);
                let mut in_place = Particles::from_disks(&disks);
                let scratch = ReorderScratch {
                    order: &mut order.clone(),
                    spare: &mut vec![0.0; n as usize],
                };
                in_place.store_in_order(scratch, reach, &Backwards(pieces));
                assert_eq!(in_place, gathered, "unequal disks: {unequal}");
            }
        }
    }
}
