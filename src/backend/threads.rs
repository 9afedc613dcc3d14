//! The rayon backend: the serial reference's stages split over bands of strips, on a
//! thread pool of exactly the requested size built for the run, giving the serial bits.
//!
//! Per step: disks move in parallel chunks; the grid is refreshed band by band (each
//! band re-sorts its strips and hands disks that changed strip to the band that now
//! holds them); each band finds the pairs its strips scan and splits them into chains
//! (`sim::schedule`). A disk in a band's first strip may also be in the pairs of another
//! band; chains without such a disk are resolved by their band, in canonical order, and
//! the others afterwards, together, in canonical order. Every chain
//! therefore sees its contacts in the serial order, which is why the bits agree.

use std::num::NonZeroUsize;
use std::ops::{ControlFlow, Range};
use std::time::Instant;

use rayon::prelude::*;

use crate::backend::{
    Accuracy, BackendError, CpuScope, Measured, RunOutcome, StageSeconds, Workers, step_loop,
    summarize, timed,
};
use crate::sim::collision::{PairSide, collide_pair};
use crate::sim::grid::{
    Contact, Entry, StripGrid, find_contacts_all_pairs_from, number_slots, receive_band,
    refresh_band,
};
use crate::sim::observe::observe;
use crate::sim::schedule::ContactSchedule;
use crate::sim::step::{
    FIRST_BUILDS_SINCE_REORDER, REORDER_INTERVAL, advance_disks, resolve_in_order,
};
use crate::sim::{Broadphase, DiskSlices, Domain, Particles, Physics, StepCounters, StepParams};
use crate::spec::RunSpec;

/// Disks per parallel chunk of the per-disk stage: large enough to amortise scheduling.
const MIN_CHUNK: usize = 4096;

/// A pool of exactly `threads` threads for one run (never the global pool).
pub fn pool(threads: NonZeroUsize) -> Result<rayon::ThreadPool, BackendError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.get())
        .thread_name(|index| format!("collide-worker-{index}"))
        .build()
        .map_err(|source| BackendError::ThreadPool {
            threads: threads.get(),
            source,
        })
}

/// Builds the scene, steps it on a pool of `threads` threads, and measures the run.
pub fn run(spec: &RunSpec, threads: NonZeroUsize) -> Result<RunOutcome, BackendError> {
    let setup_start = Instant::now();
    let pool = pool(threads)?;
    let prepared = spec.prepare()?;
    let mut particles = prepared.scene.particles.clone();
    let scene = &prepared.scene;
    let mut stepper = ThreadedStepper::new(
        scene.domain,
        scene.physics,
        prepared.params,
        &particles,
        threads.get(),
    );
    let setup_s = setup_start.elapsed().as_secs_f64();
    let initial = observe(&particles);

    let seconds = pool.install(|| {
        step_loop(prepared.steps, spec.slowdown, CpuScope::Process, |_| {
            stepper.step(&mut particles);
            ControlFlow::Continue(())
        })
    });

    let measured = Measured {
        setup_s,
        wall_s: seconds.wall,
        cpu_s: seconds.cpu,
        stages: stepper.stages,
        counters: stepper.counters,
        initial,
        accuracy: Accuracy::default(),
    };
    let workers = Workers {
        backend: "rayon",
        threads: threads.get(),
        ranks: 1,
    };
    let summary = summarize(&prepared, workers, &measured, &particles);
    Ok(RunOutcome {
        summary,
        final_state: particles,
    })
}

/// The serial stepper's stages, each split over bands of strips. Run it inside the
/// pool that should execute it (`ThreadPool::install`).
#[derive(Debug)]
pub struct ThreadedStepper {
    domain: Domain,
    physics: Physics,
    params: StepParams,
    n_bands: usize,
    grid: StripGrid,
    builds_since_reorder: u32,
    /// Per band: disks that left its strips in the last refresh.
    movers: Vec<Vec<Entry>>,
    /// Per band: the pairs its strips found, then those of chains it resolves alone.
    contacts: Vec<Vec<Contact>>,
    /// Per band: the pairs of its chains that reach a band's first strip.
    handed_over: Vec<Vec<Contact>>,
    /// Every band's handed-over pairs, in canonical order.
    crossing: Vec<Contact>,
    /// Per band: union–find scratch.
    schedules: Vec<ContactSchedule>,
    pub counters: StepCounters,
    pub stages: StageSeconds,
}

impl ThreadedStepper {
    pub fn new(
        domain: Domain,
        physics: Physics,
        params: StepParams,
        particles: &Particles,
        n_bands: usize,
    ) -> Self {
        ThreadedStepper {
            domain,
            physics,
            params,
            n_bands,
            grid: StripGrid::new(&domain, particles.max_radius(), particles.len()),
            builds_since_reorder: FIRST_BUILDS_SINCE_REORDER,
            movers: Vec::new(),
            contacts: Vec::new(),
            handed_over: Vec::new(),
            crossing: Vec::new(),
            schedules: Vec::new(),
            counters: StepCounters::default(),
            stages: StageSeconds::default(),
        }
    }

    /// One full step, the same as [`crate::sim::Stepper::step`] bit for bit.
    pub fn step(&mut self, particles: &mut Particles) {
        let mut stages = self.stages;
        timed(&mut stages.integration, || self.advance(particles));
        timed(&mut stages.broad_phase, || self.find_contacts(particles));
        timed(&mut stages.collisions, || self.resolve_contacts(particles));
        self.stages = stages;
    }

    fn advance(&mut self, particles: &mut Particles) {
        let (domain, physics, dt) = (&self.domain, &self.physics, self.params.dt);
        let chunk = particles.len().div_ceil(4 * self.n_bands).max(MIN_CHUNK);
        let DiskSlices {
            x,
            y,
            vx,
            vy,
            radius,
        } = particles.disk_slices_mut();
        let hits: u64 = x
            .par_chunks_mut(chunk)
            .zip(y.par_chunks_mut(chunk))
            .zip(vx.par_chunks_mut(chunk))
            .zip(vy.par_chunks_mut(chunk))
            .zip(radius.par_chunks(chunk))
            .map(|((((x, y), vx), vy), radius)| {
                advance_disks(
                    domain,
                    physics,
                    dt,
                    DiskSlices {
                        x,
                        y,
                        vx,
                        vy,
                        radius,
                    },
                )
            })
            .sum();
        self.counters.wall_collisions += hits;
    }

    fn find_contacts(&mut self, particles: &mut Particles) {
        self.crossing.clear();
        match self.params.broadphase {
            Broadphase::Grid => {
                let bands = self.build_grid(particles);
                let n_bands = bands.len();
                self.contacts.resize_with(n_bands, Vec::new);
                self.handed_over.resize_with(n_bands, Vec::new);
                self.schedules
                    .resize_with(n_bands, ContactSchedule::default);
                // A disk in a band's first strip may also be in the contacts of the band
                // below (its north strip), or of the last band (periodic wrap).
                let layout = *self.grid.layout();
                let mut first_of_band = vec![false; layout.n_strips];
                for band in bands.iter().filter(|_| n_bands > 1) {
                    first_of_band[band.start] = true;
                }
                let pinned = |disk: u32| first_of_band[layout.strip_of(particles.y[disk as usize])];
                let (grid, domain, particles) = (&self.grid, &self.domain, &*particles);
                bands
                    .par_iter()
                    .zip(self.contacts.par_iter_mut())
                    .zip(self.handed_over.par_iter_mut())
                    .zip(self.schedules.par_iter_mut())
                    .for_each(|(((band, contacts), handed_over), schedule)| {
                        contacts.clear();
                        handed_over.clear();
                        grid.find_contacts_in(band.clone(), particles, domain, contacts);
                        // Split while the pairs are in scan order, close in memory.
                        schedule.split(particles.len(), contacts, handed_over, pinned);
                        contacts.sort_unstable_by_key(|contact| contact.key);
                    });
                self.crossing.extend(self.handed_over.iter().flatten());
                self.crossing.sort_unstable_by_key(|contact| contact.key);
            }
            Broadphase::AllPairs => self.find_all_pairs(particles),
        }
    }

    /// The grid build, band by band, and every [`REORDER_INTERVAL`] builds the disks
    /// re-stored in grid order (in parallel), exactly when the serial stepper does it.
    /// Returns the bands it used, cut by the disk counts before the refresh (a first
    /// build, from scratch, cuts them afterwards): the pair scan uses the same bands.
    fn build_grid(&mut self, particles: &mut Particles) -> Vec<Range<usize>> {
        let bands = if self.grid.len() != particles.len() {
            self.grid.build(particles);
            self.grid.bands(self.n_bands)
        } else {
            let bands = self.grid.bands(self.n_bands);
            let layout = *self.grid.layout();
            let mut slices = split_into_bands(self.grid.owned_strips_mut(), &bands);
            self.movers.resize_with(bands.len(), Vec::new);
            let particles = &*particles;
            slices
                .par_iter_mut()
                .zip(self.movers.par_iter_mut())
                .for_each(|((first, band), movers)| {
                    movers.clear();
                    refresh_band(&layout, band, *first, particles, movers);
                });
            let movers: Vec<&[Entry]> = self.movers.iter().map(Vec::as_slice).collect();
            slices
                .par_iter_mut()
                .for_each(|(first, band)| receive_band(band, *first, &movers));
            bands
        };
        self.builds_since_reorder += 1;
        if self.builds_since_reorder >= REORDER_INTERVAL {
            let strips = self.grid.owned_strips_mut();
            let order: Vec<u32> = strips
                .par_iter()
                .flat_map_iter(|strip| strip.iter().map(Entry::idx))
                .collect();
            particles.replace_arrays(
                |values| order.par_iter().map(|&idx| values[idx as usize]).collect(),
                |ids| order.par_iter().map(|&idx| ids[idx as usize]).collect(),
            );
            let mut first_slots = Vec::with_capacity(strips.len());
            let mut slot = 0;
            for strip in strips.iter() {
                first_slots.push(slot);
                slot += strip.len();
            }
            strips
                .par_iter_mut()
                .zip(first_slots)
                .for_each(|(strip, first_slot)| number_slots(strip, first_slot));
            self.builds_since_reorder = 0;
        }
        bands
    }

    /// The seed's O(N²) search with its rows split over the pool; the pairs are then
    /// resolved in canonical order by one worker.
    fn find_all_pairs(&mut self, particles: &Particles) {
        let n = particles.len();
        // Row i tests n − i − 1 pairs: cut rows so that each piece has the same work.
        let pieces = 8 * self.n_bands;
        let cuts: Vec<usize> = (0..=pieces)
            .map(|k| n - ((n as f64) * (1.0 - k as f64 / pieces as f64).sqrt()) as usize)
            .collect();
        let domain = &self.domain;
        let found: Vec<Vec<Contact>> = cuts
            .par_windows(2)
            .map(|cut| {
                let mut contacts = Vec::new();
                find_contacts_all_pairs_from(cut[0]..cut[1], particles, domain, &mut contacts);
                contacts
            })
            .collect();
        self.contacts.resize_with(1, Vec::new);
        self.contacts[0].clear();
        self.contacts[0].extend(found.into_iter().flatten());
        self.contacts[0].par_sort_unstable_by_key(|contact| contact.key);
    }

    fn resolve_contacts(&mut self, particles: &mut Particles) {
        let (domain, e) = (&self.domain, self.physics.restitution);
        let n_lists = self.contacts.len();
        if n_lists == 1 {
            resolve_in_order(particles, domain, e, &self.contacts[0], &mut self.counters);
        } else {
            let view = VelocityView::new(particles);
            let band_counters = self.contacts[..n_lists]
                .par_iter()
                .map(|contacts| {
                    let mut counters = StepCounters::default();
                    for contact in contacts {
                        // SAFETY: after `ContactSchedule::split`, a band's list holds only
                        // chains with no disk in any band's first strip. A band's pairs
                        // touch disks of its own strips and of the next band's first
                        // strip, so these chains' disks belong to this band's strips
                        // and to no other band's pairs: two bands never hold contacts of
                        // the same disk. Each disk's velocity is therefore read and
                        // written by one thread only; positions, radii and masses are
                        // only read.
                        counters.record(unsafe { view.resolve(domain, e, contact) });
                    }
                    counters
                })
                .reduce(StepCounters::default, |mut a, b| {
                    a.merge(&b);
                    a
                });
            self.counters.merge(&band_counters);
            resolve_in_order(particles, domain, e, &self.crossing, &mut self.counters);
        }
    }
}

/// Cuts the owned strips (global index 0 first) into the given bands, each with the
/// global index of its first strip.
fn split_into_bands<'a>(
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

/// Shared read access to every disk and write access to velocities through raw
/// pointers, for bands that resolve disjoint chains of contacts at once.
#[derive(Clone, Copy)]
struct VelocityView<'a> {
    x: &'a [f64],
    y: &'a [f64],
    radius: &'a [f64],
    mass: &'a [f64],
    vx: *mut f64,
    vy: *mut f64,
}

// SAFETY: the raw pointers come from a `&mut Particles` borrowed for the view's whole
// life; `VelocityView::resolve` states the rule that makes concurrent use sound.
unsafe impl Send for VelocityView<'_> {}
unsafe impl Sync for VelocityView<'_> {}

impl<'a> VelocityView<'a> {
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
        VelocityView {
            x,
            y,
            radius,
            mass,
            vx: vx.as_mut_ptr(),
            vy: vy.as_mut_ptr(),
        }
    }

    /// Resolves one contact with the shared impulse law.
    ///
    /// # Safety
    /// While this runs, no other thread may read or write the velocities of disks
    /// `contact.a` and `contact.b`. Both indices are in bounds (they index `x`).
    #[inline]
    unsafe fn resolve(
        &self,
        domain: &Domain,
        restitution: f64,
        contact: &Contact,
    ) -> crate::sim::collision::ContactOutcome {
        let (a, b) = (contact.a as usize, contact.b as usize);
        let (dx, dy) = domain.separation(self.x[a], self.y[a], self.x[b], self.y[b]);
        // SAFETY: a and b index `x`, which has the length of `vx` and `vy`; the caller
        // guarantees that no other thread touches these two disks' velocities.
        unsafe {
            let side = |idx: usize| PairSide {
                mass: self.mass[idx],
                vx: *self.vx.add(idx),
                vy: *self.vy.add(idx),
            };
            let contact_distance = self.radius[a] + self.radius[b];
            let (outcome, velocities) =
                collide_pair(restitution, dx, dy, contact_distance, side(a), side(b));
            if let Some([[vax, vay], [vbx, vby]]) = velocities {
                *self.vx.add(a) = vax;
                *self.vy.add(a) = vay;
                *self.vx.add(b) = vbx;
                *self.vy.add(b) = vby;
            }
            outcome
        }
    }
}
