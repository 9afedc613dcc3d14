//! The rayon backend: the serial reference's stages split over bands of strips, on a
//! thread pool of exactly the requested size built for the run, giving the serial bits.
//! The pool's threads step as one [`Team`] (`backend::team`: why not rayon's parallel
//! iterators).
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

use crate::backend::bands::{
    BandLists, ESCAPEES_PER_PIECE, advance_in_pieces, largest_displacement_sq, split_into_bands,
};
use crate::backend::team::{Team, with_team};
use crate::backend::{
    Accuracy, BackendError, CpuScope, Measured, RunOutcome, StageSeconds, Workers, step_loop,
    summarize, timed,
};
use crate::draw::offscreen::{Offscreen, draw_step};
use crate::run::backend_kind::BackendKind;
use crate::run::spec::RunSpec;
use crate::sim::grid::{
    Contact, Mover, StripGrid, find_contacts_all_pairs_from, order_canonically, receive_band,
    refresh_band,
};
use crate::sim::neighbours::{Skin, with_reorder_scratch};
use crate::sim::observe::{SeriesRecorder, StateSums, block_end};
use crate::sim::pieces::Pieces;
use crate::sim::resolve::resolve_contacts;
use crate::sim::step::ReorderSchedule;
use crate::sim::{Broadphase, Domain, Particles, Physics, StepCounters, StepParams};

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
    let mut prepared = spec.prepare()?;
    let mut particles = prepared.take_particles();
    let scene = &prepared.scene;
    let mut stepper = ThreadedStepper::new(
        scene.domain,
        scene.physics,
        prepared.params,
        &particles,
        threads.get(),
    );
    let initial = prepared.initial.observables;
    let mut offscreen = Offscreen::when(spec.method.draw, &prepared.scene.domain, &particles);

    // The observables' blocks, recorded out of both clocks (as the serial backend does).
    let mut series = SeriesRecorder::new(initial.kinetic_energy, &scene.physics);
    let mut series_s = 0.0;
    let (setup_s, seconds) = pool.install(|| {
        with_team(|team| {
            stepper.build_lists(&mut particles, team);
            let setup_s = setup_start.elapsed().as_secs_f64();
            let seconds = step_loop(prepared.steps, spec.slowdown, CpuScope::Process, |step| {
                stepper.step(&mut particles, team);
                if let Some(time) = block_end(step, prepared.steps, prepared.params.dt) {
                    timed(&mut series_s, || {
                        series.close_block(time, &stepper.counters, &particles)
                    });
                }
                // The snapshot and the rasterizer are serial: drawing runs on this thread.
                draw_step(&mut offscreen, &particles);
                ControlFlow::Continue(())
            });
            (setup_s, seconds)
        })
    });

    // Drawing is out of both clocks: its own seconds (CPU the pool's waiting threads
    // spend spinning before they sleep stays in `cpu_s`).
    let draw_s = offscreen.map(|offscreen| offscreen.seconds);
    let apart = draw_s.unwrap_or(0.0) + series_s;
    let measured = Measured {
        setup_s,
        wall_s: seconds.wall - apart,
        cpu_s: seconds.cpu.map(|cpu| cpu - apart),
        stages: stepper.stages,
        counters: stepper.counters,
        initial,
        accuracy: Accuracy {
            series: Some(series.blocks()),
            ..Accuracy::default()
        },
        draw_s,
        traffic: None,
        balance: None,
    };
    let workers = Workers {
        backend: BackendKind::Rayon,
        threads: threads.get(),
        ranks: 1,
    };
    let last = StateSums::all(&particles, prepared.scene.physics.gravity);
    let summary = summarize(&prepared, workers, &measured, &last);
    Ok(RunOutcome {
        summary,
        final_state: Some(particles),
    })
}

/// The serial stepper's stages, each split over bands of strips and run by a [`Team`]
/// of the pool that should execute it (`ThreadPool::install`, then [`with_team`]).
#[derive(Debug)]
pub struct ThreadedStepper {
    domain: Domain,
    physics: Physics,
    params: StepParams,
    n_bands: usize,
    /// Strips tall enough for the neighbour lists' skin.
    grid: StripGrid,
    skin: Skin,
    /// One neighbour list per band, and each band's pairs of a step.
    bands: BandLists,
    /// Per disk: in a pair an escapee's query found this step (all false between steps).
    touched: Vec<bool>,
    reorder: ReorderSchedule,
    /// Per band: disks that left its strips in the last refresh.
    movers: Vec<Vec<Mover>>,
    /// Every band's handed-over pairs (with the seed's search, every pair), in
    /// canonical order.
    crossing: Vec<Contact>,
    /// Scratch for putting pairs in canonical order.
    keyed: Vec<(u64, Contact)>,
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
        let (skin, grid) = Skin::with_grid(&domain, particles, params.dt);
        ThreadedStepper {
            domain,
            physics,
            params,
            n_bands,
            grid,
            skin,
            bands: BandLists::default(),
            touched: Vec::new(),
            reorder: ReorderSchedule::for_scene(particles.len()),
            movers: Vec::new(),
            crossing: Vec::new(),
            keyed: Vec::new(),
            counters: StepCounters::default(),
            stages: StageSeconds::default(),
        }
    }

    /// Builds the neighbour lists at the disks' present positions, as
    /// [`crate::sim::Stepper::build_lists`] does: a run's set-up.
    pub fn build_lists(&mut self, particles: &mut Particles, team: &Team<'_>) {
        if self.params.broadphase == Broadphase::Grid && !self.skin.is_built_for(particles) {
            self.rebuild_lists(particles, team);
        }
    }

    /// One full step, the same as [`crate::sim::Stepper::step`] bit for bit.
    pub fn step(&mut self, particles: &mut Particles, team: &Team<'_>) {
        let mut stages = self.stages;
        timed(&mut stages.integration, || self.advance(particles, team));
        timed(&mut stages.broad_phase, || {
            self.find_contacts(particles, team)
        });
        timed(&mut stages.collisions, || {
            self.resolve_contacts(particles, team)
        });
        self.stages = stages;
    }

    fn advance(&mut self, particles: &mut Particles, team: &Team<'_>) {
        let (domain, physics, dt) = (&self.domain, &self.physics, self.params.dt);
        let walls = advance_in_pieces(domain, physics, dt, particles, &mut self.skin, team);
        self.counters.merge(&walls);
    }

    fn find_contacts(&mut self, particles: &mut Particles, team: &Team<'_>) {
        self.crossing.clear();
        match self.params.broadphase {
            Broadphase::Grid => {
                let escaped = self.contacts_of_escapees(particles, team);
                // A disk in a contact found by an escapee's query may also be in a
                // band's pairs: its chain goes to the crossing list too.
                let touched = &self.touched;
                let pinned = |disk: u32| touched[disk as usize];
                (self.bands).find_contacts(
                    particles,
                    &self.domain,
                    pinned,
                    &mut self.crossing,
                    team,
                );
                self.crossing.extend_from_slice(&escaped);
                // An escapee's pair may also be listed: kept once.
                order_canonically(&mut self.crossing, &particles.id, &mut self.keyed);
                for contact in &escaped {
                    self.touched[contact.a as usize] = false;
                    self.touched[contact.b as usize] = false;
                }
            }
            Broadphase::AllPairs => self.find_all_pairs(particles, team),
        }
    }

    /// Rebuilds the lists when they are stale, as the serial stepper does, or else finds
    /// the pairs of the disks that escaped them (queries in parallel chunks) and marks
    /// both disks of each in `touched`: their chains go to the crossing list. Returns
    /// those pairs.
    fn contacts_of_escapees(&mut self, particles: &mut Particles, team: &Team<'_>) -> Vec<Contact> {
        let n = particles.len();
        self.touched.resize(n, false);
        let largest_sq = largest_displacement_sq(&mut self.skin, particles, &self.domain, team);
        let (skin, domain, now) = (&self.skin, &self.domain, &*particles);
        if !skin.is_exceeded(largest_sq) {
            return Vec::new();
        }
        // The move marked the escapees: reading the marks is a short serial scan.
        let mut escapees = Vec::new();
        if skin.may_reach(largest_sq) {
            skin.escapees(0..n, &mut escapees);
        }
        if escapees.is_empty() || !skin.may_patch(escapees.len(), n, largest_sq) {
            self.rebuild_lists(particles, team);
            return Vec::new();
        }
        let grid = &self.grid;
        let moved = largest_sq.sqrt();
        let found = team.map(escapees.chunks(ESCAPEES_PER_PIECE), |movers| {
            let mut contacts = Vec::new();
            grid.find_contacts_of(movers, moved, now, domain, &mut contacts);
            contacts
        });
        let escaped = found.concat();
        for contact in &escaped {
            self.touched[contact.a as usize] = true;
            self.touched[contact.b as usize] = true;
        }
        escaped
    }

    /// Rebuilds the grid and, band by band in parallel, the neighbour lists, and records
    /// the positions they were built at.
    fn rebuild_lists(&mut self, particles: &mut Particles, team: &Team<'_>) {
        let bands = self.build_grid(particles, team);
        (self.bands).rebuild(
            &self.grid,
            &bands,
            particles,
            &self.domain,
            &self.skin,
            team,
        );
        self.skin.record(particles, team);
    }

    /// The grid build, band by band, and when the [`ReorderSchedule`] says so the disks
    /// re-stored in grid order (in parallel), exactly when the serial stepper does it.
    /// Returns the bands it used, cut by the disk counts before the refresh: the pair
    /// scan uses the same bands. The grid was first built for these disks with the
    /// stepper ([`StripGrid::with_skin`]): every build here is a refresh.
    fn build_grid(&mut self, particles: &mut Particles, team: &Team<'_>) -> Vec<Range<usize>> {
        assert_eq!(
            self.grid.len(),
            particles.len(),
            "the disks the stepper was made for"
        );
        let bands = self.grid.bands(self.n_bands);
        let layout = *self.grid.layout();
        let mut slices = split_into_bands(self.grid.owned_strips_mut(), &bands);
        self.movers.resize_with(bands.len(), Vec::new);
        let now = &*particles;
        let mut refreshes: Vec<_> = slices.iter_mut().zip(&mut self.movers).collect();
        team.for_each(&mut refreshes, |((first, band), band_movers)| {
            // A local, for the reason given in `find_contacts`.
            let mut movers = std::mem::take(*band_movers);
            movers.clear();
            refresh_band(&layout, band, *first, now, &mut movers);
            **band_movers = movers;
        });
        let movers: Vec<&[Mover]> = self.movers.iter().map(Vec::as_slice).collect();
        team.for_each(&mut slices, |(first, band)| {
            receive_band(band, *first, &movers)
        });
        if self.reorder.count_build() {
            // The lists are rebuilt next: the re-storing works in their memory, as the
            // serial stepper's does, in pieces over the team.
            let grid = &mut self.grid;
            with_reorder_scratch(self.bands.lists_mut(), particles.len(), |scratch| {
                grid.store_in_grid_order(particles, scratch, team);
            });
        }
        bands
    }

    /// The seed's O(N²) search with its rows split over the pool; the pairs are then
    /// resolved in canonical order by one worker.
    fn find_all_pairs(&mut self, particles: &Particles, team: &Team<'_>) {
        let n = particles.len();
        // Row i tests n − i − 1 pairs: cut rows so that each piece has the same work.
        let pieces = 8 * self.n_bands;
        let cuts: Vec<usize> = (0..=pieces)
            .map(|k| n - ((n as f64) * (1.0 - k as f64 / pieces as f64).sqrt()) as usize)
            .collect();
        let domain = &self.domain;
        let found = team.map(cuts.windows(2), |cut| {
            let mut contacts = Vec::new();
            find_contacts_all_pairs_from(cut[0]..cut[1], particles, domain, &mut contacts);
            contacts
        });
        self.crossing.extend(found.into_iter().flatten());
        order_canonically(&mut self.crossing, &particles.id, &mut self.keyed);
    }

    fn resolve_contacts(&mut self, particles: &mut Particles, team: &Team<'_>) {
        let (domain, physics, dt) = (&self.domain, &self.physics, self.params.dt);
        // The bands' own chains and the crossing ones share no disk: either order.
        (self.bands).resolve(particles, domain, physics, dt, &mut self.counters, team);
        resolve_contacts(
            particles,
            domain,
            physics,
            dt,
            &self.crossing,
            &mut self.counters,
            |_| {},
        );
    }
}
