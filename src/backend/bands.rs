//! The parts of a step that bands of strips run side by side, shared by the rayon
//! backend's stepper and by each MPI rank, which steps its slab the same way on its own
//! threads: the move in chunks, one neighbour list per band, the split of each band's
//! pairs into the chains it resolves alone and those it hands over, and the resolution
//! of every band's own chains at once.
//!
//! A band's list holds the pairs of its strips and of the first strip of the band above
//! it, so only a disk of a band's first strip can be in two bands' pairs. Such disks
//! are pinned, with any the caller names (disks other workers or ranks may also touch):
//! a chain holding a pinned disk is handed over, whole, to be resolved afterwards, in
//! canonical order, in one place (`sim::schedule`). Every chain thus sees its contacts
//! in the serial order, whichever band resolved it.

use std::ops::Range;

use crate::sim::collision::DiskState;
use crate::sim::grid::{Contact, Entry, StripGrid};
use crate::sim::neighbours::{DISPLACEMENT_BLOCK, Displacements, PairList, Skin};
use crate::sim::pieces::{InTurn, MIN_STREAMING_PIECE, Pieces};
use crate::sim::prefetch::prefetch;
use crate::sim::resolve::resolve_contacts;
use crate::sim::schedule::{ContactSchedule, DiskSet};
use crate::sim::step::advance_disks;
use crate::sim::{DiskSlices, Domain, Particles, PerDisk, Physics, StepCounters};

/// Moves every disk of `particles` by one `dt` ([`advance_disks`]) in chunks over
/// `pieces`, each chunk with its whole blocks of the lists' displacement record;
/// returns the walls' counts and maxima, the same in any order.
pub fn advance_in_pieces(
    domain: &Domain,
    physics: &Physics,
    dt: f64,
    particles: &mut Particles,
    skin: &mut Skin,
    pieces: &impl Pieces,
) -> StepCounters {
    if pieces.workers() == 1 {
        let n_particles = particles.len();
        let tracking = skin.tracking(n_particles);
        return advance_disks(domain, physics, dt, particles.disk_slices_mut(), tracking);
    }
    let chunk = pieces.piece_len(particles.len(), MIN_STREAMING_PIECE, DISPLACEMENT_BLOCK);
    let n_chunks = particles.len().div_ceil(chunk);
    let displacements: Vec<Option<Displacements>> = match skin.tracking(particles.len()) {
        Some(record) => record.into_chunks(chunk).map(Some).collect(),
        None => (0..n_chunks).map(|_| None).collect(),
    };
    let DiskSlices {
        x,
        y,
        vx,
        vy,
        radius,
    } = particles.disk_slices_mut();
    let chunks = x
        .chunks_mut(chunk)
        .zip(y.chunks_mut(chunk))
        .zip(vx.chunks_mut(chunk))
        .zip(vy.chunks_mut(chunk))
        .zip(radius.chunks(chunk))
        .map(|((((x, y), vx), vy), radius)| DiskSlices {
            x,
            y,
            vx,
            vy,
            radius,
        })
        .zip(displacements);
    let walls = pieces.map(chunks, |(disks, displacements)| {
        advance_disks(domain, physics, dt, disks, displacements)
    });
    let mut counters = StepCounters::default();
    walls.iter().for_each(|walls| counters.merge(walls));
    counters
}

/// Scenes from this many disks on measure the largest displacement since the lists'
/// build in pieces over the team: on one thread it took 0.14–0.16 ns per disk-step at
/// 10⁶ disks and packing 0.3, in pieces 0.06 (`docs/performance.md`). At 2·10⁴ disks,
/// runs with the pieces went 0.971–0.978 times as fast as runs without (there the part
/// takes a few µs a step on one thread; another phase of the team costing as much is
/// the likely reason, not measured alone).
const PARALLEL_LARGEST_DISKS: usize = 1 << 16;

/// Escapees whose pairs one piece of work queries.
pub const ESCAPEES_PER_PIECE: usize = 256;

/// The square of the farthest any disk of `particles` moved since the lists' build
/// (`Skin::largest_displacement_sq`), in pieces over `pieces` from
/// [`PARALLEL_LARGEST_DISKS`] disks on, else on this thread.
pub fn largest_displacement_sq(
    skin: &mut Skin,
    particles: &Particles,
    domain: &Domain,
    pieces: &impl Pieces,
) -> f64 {
    if particles.len() >= PARALLEL_LARGEST_DISKS {
        skin.largest_displacement_sq(particles, domain, pieces)
    } else {
        skin.largest_displacement_sq(particles, domain, &InTurn)
    }
}

/// Cuts the owned strips (global index 0 first) into the given bands, each with the
/// global index of its first strip.
pub fn split_into_bands<'a>(
    mut strips: &'a mut [Vec<Entry>],
    bands: &[Range<usize>],
) -> Vec<(usize, &'a mut [Vec<Entry>])> {
    let mut slices = Vec::with_capacity(bands.len());
    for band in bands {
        let (head, rest) = strips.split_at_mut(band.len());
        slices.push((band.start, head));
        strips = rest;
    }
    slices
}

/// One neighbour list per band of strips, and each band's pairs of a step: those of
/// the chains it resolves alone, and scratch for splitting them from the rest.
#[derive(Debug, Default)]
pub struct BandLists {
    /// Per band of the last build: the candidate pairs its strips found.
    lists: Vec<PairList>,
    /// The disks in the first strip of a band at the last build (with more than one
    /// band). Only such a disk can be in two bands' lists.
    in_first_strips: DiskSet,
    /// Per band: the pairs its strips found, then those of the chains it resolves alone.
    contacts: Vec<Vec<Contact>>,
    /// Per band: the pairs of its chains that hold a pinned disk.
    handed_over: Vec<Vec<Contact>>,
    /// Per band: union–find scratch.
    schedules: Vec<ContactSchedule>,
}

impl BandLists {
    /// The lists, whose memory the re-storing of the disks borrows
    /// (`sim::neighbours::with_reorder_scratch`).
    pub fn lists_mut(&mut self) -> &mut [PairList] {
        &mut self.lists
    }

    /// Rebuilds one list per band of `bands` (global strip indices of `grid`, in order)
    /// at the disks' present positions, in parallel over `pieces`, and notes the disks
    /// of each band's first strip.
    pub fn rebuild(
        &mut self,
        grid: &StripGrid,
        bands: &[Range<usize>],
        particles: &Particles,
        domain: &Domain,
        skin: &Skin,
        pieces: &impl Pieces,
    ) {
        self.in_first_strips.clear(particles.len());
        for band in bands.iter().filter(|_| bands.len() > 1) {
            for entry in grid.strip_entries(band.start) {
                self.in_first_strips.insert(entry.idx());
            }
        }
        debug_assert!(
            (0..grid.len()).all(|disk| {
                let strip = grid.layout().strip_of(particles.y[disk]);
                let first = bands.len() > 1 && bands.iter().any(|band| band.start == strip);
                self.in_first_strips.contains(disk as u32) == first
            }),
            "the first strips' entries are the disks built there"
        );
        self.lists.resize_with(bands.len(), PairList::default);
        let mut lists: Vec<_> = self.lists.iter_mut().zip(bands).collect();
        pieces.for_each(&mut lists, |(list, band)| {
            list.rebuild(grid, (*band).clone(), particles, domain, skin)
        });
    }

    /// Finds each band's overlapping pairs and keeps those of the chains it may resolve
    /// alone, in resolution order; appends the pairs of the chains that hold a disk of a
    /// band's first strip, or one `pinned` names, to `handed_over`.
    pub fn find_contacts(
        &mut self,
        particles: &Particles,
        domain: &Domain,
        pinned: impl Fn(u32) -> bool + Sync,
        handed_over: &mut Vec<Contact>,
        pieces: &impl Pieces,
    ) {
        let n_lists = self.lists.len();
        self.contacts.resize_with(n_lists, Vec::new);
        self.handed_over.resize_with(n_lists, Vec::new);
        self.schedules
            .resize_with(n_lists, ContactSchedule::default);
        // With one band no disk is in two bands' lists.
        let (in_first_strips, several) = (&self.in_first_strips, n_lists > 1);
        let pinned = |disk: u32| (several && in_first_strips.contains(disk)) || pinned(disk);
        let mut bands: Vec<_> = self
            .lists
            .iter()
            .zip(&mut self.contacts)
            .zip(&mut self.handed_over)
            .zip(&mut self.schedules)
            .collect();
        pieces.for_each(
            &mut bands,
            |(((list, band_contacts), band_handed_over), schedule)| {
                // Filled as locals: the lengths of the bands' vectors share cache
                // lines, and each push would bounce them between threads.
                let mut contacts = std::mem::take(*band_contacts);
                let mut band_out = std::mem::take(*band_handed_over);
                contacts.clear();
                band_out.clear();
                list.find_contacts(particles, domain, &mut contacts);
                // Split while the pairs are in list order, close in memory.
                schedule.split(&particles.id, &mut contacts, &mut band_out, pinned);
                **band_contacts = contacts;
                **band_handed_over = band_out;
            },
        );
        handed_over.extend(self.handed_over.iter().flatten());
    }

    /// Resolves every band's own chains (kept by [`BandLists::find_contacts`]), the
    /// bands at once over `pieces`, and adds what they did to `counters`.
    pub fn resolve(
        &self,
        particles: &mut Particles,
        domain: &Domain,
        physics: &Physics,
        dt: f64,
        counters: &mut StepCounters,
        pieces: &impl Pieces,
    ) {
        let n_lists = self.lists.len();
        if n_lists <= 1 {
            for contacts in &self.contacts[..n_lists] {
                resolve_contacts(particles, domain, physics, dt, contacts, counters, |_| {});
            }
            return;
        }
        let shared = SharedDisks::new(particles);
        let band_counters = pieces.map(&self.contacts[..n_lists], |contacts| {
            // SAFETY: after `ContactSchedule::split`, a band's list holds only whole
            // chains with no disk in any band's first strip. A band's pairs touch disks
            // of its own strips and of the next band's first strip, so these chains'
            // disks belong to this band's strips and to no other band's pairs: two
            // bands never hold contacts of the same disk, and resolution touches only
            // the disks of its contacts.
            let mut disks = unsafe { shared.claim() };
            let mut counters = StepCounters::default();
            resolve_contacts(
                &mut disks,
                domain,
                physics,
                dt,
                contacts,
                &mut counters,
                |_| {},
            );
            counters
        });
        // Summed in band order, whichever thread resolved which band, then added.
        let mut bands = StepCounters::default();
        band_counters.iter().for_each(|band| bands.merge(band));
        counters.merge(&bands);
    }
}

/// Every disk's state through raw pointers, for bands that resolve disjoint chains of
/// contacts at once. Radii and masses are only read.
#[derive(Clone, Copy)]
struct SharedDisks<'a> {
    radius: &'a PerDisk,
    mass: &'a PerDisk,
    x: *mut f64,
    y: *mut f64,
    vx: *mut f64,
    vy: *mut f64,
}

// SAFETY: the raw pointers come from a `&mut Particles` borrowed for the view's whole
// life; `SharedDisks::claim` states the rule that makes concurrent use sound.
unsafe impl Send for SharedDisks<'_> {}
unsafe impl Sync for SharedDisks<'_> {}

impl<'a> SharedDisks<'a> {
    fn new(particles: &'a mut Particles) -> Self {
        let Particles {
            x,
            y,
            vx,
            vy,
            radius,
            mass,
            ..
        } = particles;
        SharedDisks {
            radius,
            mass,
            x: x.as_mut_ptr(),
            y: y.as_mut_ptr(),
            vx: vx.as_mut_ptr(),
            vy: vy.as_mut_ptr(),
        }
    }

    /// A handle for one worker's contact resolution.
    ///
    /// # Safety
    /// While the handle lives, no other thread may read or write the position or
    /// velocity of a disk that this handle is used to access, and the handle is used only
    /// with storage indices in bounds (below the number of disks).
    unsafe fn claim(&self) -> ChainDisks<'a> {
        ChainDisks(*self)
    }
}

/// One worker's access to the disks of its chains ([`SharedDisks::claim`]).
struct ChainDisks<'a>(SharedDisks<'a>);

// SAFETY (every method): `idx` is in bounds and the disk is this worker's alone, as
// `SharedDisks::claim` requires; `radius` has the length of the pointed-to arrays.
impl DiskState for ChainDisks<'_> {
    #[inline(always)]
    fn position(&self, idx: usize) -> [f64; 2] {
        assert!(idx < self.0.radius.len());
        unsafe { [*self.0.x.add(idx), *self.0.y.add(idx)] }
    }
    #[inline(always)]
    fn velocity(&self, idx: usize) -> [f64; 2] {
        assert!(idx < self.0.radius.len());
        unsafe { [*self.0.vx.add(idx), *self.0.vy.add(idx)] }
    }
    #[inline(always)]
    fn radius(&self, idx: usize) -> f64 {
        self.0.radius[idx]
    }
    #[inline(always)]
    fn mass(&self, idx: usize) -> f64 {
        self.0.mass[idx]
    }
    #[inline(always)]
    fn set_position(&mut self, idx: usize, [x, y]: [f64; 2]) {
        assert!(idx < self.0.radius.len());
        unsafe {
            *self.0.x.add(idx) = x;
            *self.0.y.add(idx) = y;
        }
    }
    #[inline(always)]
    fn set_velocity(&mut self, idx: usize, [vx, vy]: [f64; 2]) {
        assert!(idx < self.0.radius.len());
        unsafe {
            *self.0.vx.add(idx) = vx;
            *self.0.vy.add(idx) = vy;
        }
    }
    #[inline(always)]
    fn prefetch_motion(&self, idx: usize) {
        let disks = &self.0;
        for values in [disks.x, disks.y, disks.vx, disks.vy] {
            prefetch(values.wrapping_add(idx));
        }
    }
    #[inline(always)]
    fn prefetch_properties(&self, idx: usize) {
        self.0.radius.prefetch(idx);
        self.0.mass.prefetch(idx);
    }
}
