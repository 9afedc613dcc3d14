//! The distributed backend, generic over a [`Communicator`]: a domain decomposition
//! that gives the serial bits for any rank count.
//!
//! Each rank owns a slab of whole strips (cut so that the initial disks are shared out
//! evenly; counts need not divide the box) and talks in a step to its peers, the ranks
//! beside it. Per step a rank moves its disks and, on the steps the ranks foresaw
//! together at the last step, rebuilds its lists: it refreshes its strips and hands the
//! disks that left its slab to their new owners (migration); otherwise the disks that
//! escaped the lists are served by queries, on every peer whose strips they may reach.
//! Each rank sends the disks of its first strip to the rank below as ghosts (halo), with
//! its reported escapees to every peer, and finds the pairs its strips scan (its last
//! strip scans the ghosts above it). One small all-reduce per step tells every rank
//! whether a disk went further than foreseen (then the ranks find the step's contacts
//! again, on rebuilt lists), whether a shared chain reached past a rank's peers, and
//! what to foresee for the next step. Chains of contacts with no ghost, no other rank's
//! escapee and no disk another rank sees (exported or reported) are the rank's alone
//! and resolved there, in canonical order. Every other chain may span ranks: the ranks
//! that hold it resolve it, in canonical order, from their own and their peers'
//! contacts (`backend::shared`), or, when it reaches past the peers, every rank from
//! all ranks' gathered contacts. So every chain sees its contacts in the serial order,
//! which is why the bits agree.

use std::collections::{HashMap, HashSet};
use std::num::NonZeroUsize;
use std::ops::{ControlFlow, Range};
use std::time::Instant;

use crate::backend::bands::{
    BandLists, ESCAPEES_PER_PIECE, advance_in_pieces, largest_displacement_sq, split_into_bands,
};
use crate::backend::comm::{Communicator, Counting, RankTraffic, Traffic};
use crate::backend::setup::{self, cut_slabs, owners};
use crate::backend::shared::{Neighbourhood, Resolution, Seen, SharedChains, pack_shared_disk};
use crate::backend::team::with_team_beside;
use crate::backend::{
    Accuracy, BackendError, Balance, CpuScope, Measured, RunOutcome, StageSeconds, Workers,
    step_loop, summarize, timed,
};
use crate::run::backend_kind::BackendKind;
use crate::run::spec::{InjectedSlowdown, RunSpec};
use crate::sim::exact_sum::{EXACT_SUM_WORDS, ExactSum};
use crate::sim::grid::{
    Contact, Mover, StripGrid, StripLayout, receive_band, refresh_band, sort_movers,
};
use crate::sim::neighbours::{Skin, with_reorder_scratch};
use crate::sim::observe::{Block, Observables, SeriesRecorder, StateSums, block_end, kinetic_of};
use crate::sim::particles::{PACKED_LEN, SPARE_SHARE};
use crate::sim::pieces::{InTurn, Pieces};
use crate::sim::resolve::resolve_contacts;
use crate::sim::schedule::{ContactSchedule, DiskSet};
use crate::sim::step::ReorderSchedule;
use crate::sim::{Boundary, Particles, StepCounters};
use crate::system::machine::LoopSeconds;

/// Runs `spec` on every rank of `comm` (all ranks call this together), each rank
/// stepping its slab on a pool of `threads` threads. Rank 0 returns the summary, and the
/// whole final state when `final_state` asks for it; the other ranks return `None`.
pub fn run<C: Communicator>(
    comm: &C,
    spec: &RunSpec,
    final_state: FinalState,
    threads: NonZeroUsize,
) -> Result<Option<RunOutcome>, BackendError> {
    let setup_start = Instant::now();
    let comm = &Counting::new(comm);
    let start = setup::start(comm, spec)?;
    let (prepared, most_held) = (start.prepared, start.most_held);
    let initial = prepared.initial.observables;
    let mut rank = RankState::new(
        &prepared.scene,
        start.own,
        start.whole.state.disks as usize,
        start.layout,
        &start.slabs,
        start.skin,
        comm.rank(),
        threads.get(),
    );
    let mut series = RankSeries::new(&prepared.scene.physics, initial.kinetic_energy);
    let stepping = Stepping {
        comm,
        steps: prepared.steps,
        dt: prepared.params.dt,
        slowdown: spec.slowdown,
        setup_start,
    };
    let (setup_s, seconds, sent_before) = stepping.run_on(threads, &mut rank, &mut series)?;
    let sent = comm.traffic().since(&sent_before);
    let series_parts = series.gather_on_first(comm);

    // Each rank sums its own disks; the sums merge exactly, in any order, into the
    // serial run's figures and state hash. The disks themselves go to rank 0 only when
    // asked for.
    let own = StateSums::of(
        &rank.particles,
        0..rank.n_own,
        prepared.scene.physics.gravity,
    );
    let mut figures = rank_figures(&rank, &seconds, &sent, most_held).to_vec();
    figures.extend(own.to_words());
    let all_figures = comm.all_gather(&figures);
    let states = (final_state == FinalState::Gathered).then(|| rank.gather_on_first(comm));
    if comm.rank() != 0 {
        return Ok(None);
    }
    let mut last = StateSums::default();
    for figures in &all_figures {
        last.merge(&StateSums::from_words(&figures[RANK_FIGURES..]));
    }
    let mut measured = merge_figures(&all_figures, rank.shared_counters, setup_s, initial);
    measured.accuracy.series = Some(series.merged(&series_parts));
    measured.balance = rank.balance(&all_figures);
    let workers = Workers {
        backend: BackendKind::Mpi,
        threads: threads.get(),
        ranks: comm.size(),
    };
    Ok(Some(RunOutcome {
        summary: summarize(&prepared, workers, &measured, &last),
        final_state: states.map(|states| {
            let mut whole = Particles::with_capacity(last.disks as usize);
            for packed in &states {
                whole.unpack_append(packed);
            }
            whole
        }),
    }))
}

/// What every rank's stepping loop needs besides its own state.
struct Stepping<'a, C> {
    comm: &'a Counting<'a, C>,
    steps: u64,
    dt: f64,
    slowdown: InjectedSlowdown,
    setup_start: Instant,
}

impl<C: Communicator> Stepping<'_, C> {
    /// [`Stepping::run`] on `threads` threads: the rank's own thread alone, or leading a
    /// team of the others (MPI is only ever called from it).
    fn run_on(
        &self,
        threads: NonZeroUsize,
        rank: &mut RankState,
        series: &mut RankSeries,
    ) -> Result<(f64, LoopSeconds, Traffic), BackendError> {
        Ok(match NonZeroUsize::new(threads.get() - 1) {
            None => self.run(rank, series, &InTurn, CpuScope::Thread),
            Some(others) => {
                let members = super::threads::pool(others)?;
                with_team_beside(&members, |team| {
                    self.run(rank, series, team, CpuScope::Process)
                })
            }
        })
    }

    /// Builds the rank's lists, then steps it, its pieces of work over `pieces`, and
    /// notes its blocks of the series. Returns the set-up's seconds, the loop's, and
    /// what the rank had sent before the loop.
    fn run(
        &self,
        rank: &mut RankState,
        series: &mut RankSeries,
        pieces: &impl Pieces,
        scope: CpuScope,
    ) -> (f64, LoopSeconds, Traffic) {
        let comm = self.comm;
        rank.build_lists(comm, pieces);
        // The ranks start their clocks together: a rank whose set-up ended first would
        // otherwise count its wait for the slowest one (as much as a fifth of the
        // stepping time at 10⁶ disks) as stepping and communication. The wait is set-up.
        comm.barrier();
        let setup_s = self.setup_start.elapsed().as_secs_f64();
        // What the stepping loop sends: set-up and the reductions after it are not
        // counted, as they are not timed.
        let sent_before = comm.traffic();
        let (steps, dt) = (self.steps, self.dt);
        let seconds = step_loop(steps, self.slowdown, scope, |step| {
            rank.step(comm, dt, pieces);
            if let Some(time) = block_end(step, steps, dt) {
                series.close_block(time, rank, comm.rank() == 0);
            }
            ControlFlow::Continue(())
        });
        (setup_s, seconds, sent_before)
    }
}

/// A rank's share of the run's block series: at each block's end its running counters
/// (with the shared chains' on rank 0, which counts them) and, where the series reads
/// the kinetic energy, the exact sum over its own disks. Rank 0 merges the ranks' shares
/// into the serial run's blocks, bit for bit, after the loop: no message in a step.
struct RankSeries {
    recorder: SeriesRecorder,
    /// Per block: its end, the counters' pair and wall collisions and virial, and the
    /// kinetic energy's exact sum ([`EXACT_SUM_WORDS`]) if the recorder reads it.
    values: Vec<f64>,
}

/// Values of [`RankSeries`] per block before the kinetic energy.
const BLOCK_COUNTS: usize = 4;

impl RankSeries {
    fn new(physics: &crate::sim::Physics, initial_kinetic_energy: f64) -> RankSeries {
        RankSeries {
            recorder: SeriesRecorder::new(initial_kinetic_energy, physics),
            values: Vec::new(),
        }
    }

    fn block_len(&self) -> usize {
        BLOCK_COUNTS
            + if self.recorder.reads_energy() {
                EXACT_SUM_WORDS
            } else {
                0
            }
    }

    fn close_block(&mut self, time: f64, rank: &RankState, counts_shared: bool) {
        let mut counters = rank.counters;
        if counts_shared {
            counters.merge(&rank.shared_counters);
        }
        // Counts below 2⁵³: exact as f64.
        self.values.extend([
            time,
            counters.pair_collisions as f64,
            counters.wall_collisions as f64,
            counters.virial,
        ]);
        if self.recorder.reads_energy() {
            let own = 0..rank.n_own;
            let sum: ExactSum = own.map(|idx| kinetic_of(&rank.particles, idx)).collect();
            self.values.extend(sum.to_words());
        }
    }

    /// Every rank's values on rank 0, in rank order (all ranks call this together).
    fn gather_on_first<C: Communicator>(&self, comm: &C) -> Vec<Vec<f64>> {
        let mut to_first = vec![Vec::new(); comm.size()];
        to_first[0].clone_from(&self.values);
        comm.exchange(&to_first)
    }

    /// The run's blocks from every rank's values.
    fn merged(mut self, parts: &[Vec<f64>]) -> Vec<Block> {
        let len = self.block_len();
        for block in 0..self.values.len() / len {
            let span = block * len..(block + 1) * len;
            let mut counters = StepCounters::default();
            let mut kinetic = ExactSum::default();
            for values in parts.iter().map(|part| &part[span.clone()]) {
                counters.pair_collisions += values[1] as u64;
                counters.wall_collisions += values[2] as u64;
                counters.virial += values[3];
                if len > BLOCK_COUNTS {
                    kinetic.merge(&ExactSum::from_words(&values[BLOCK_COUNTS..]));
                }
            }
            let time = self.values[span.start];
            self.recorder
                .close_block_with(time, &counters, || kinetic.value());
        }
        self.recorder.blocks()
    }
}

/// Whether a distributed run sends its whole final state to rank 0 (`--dump`), or
/// only the sums every figure of its summary comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FinalState {
    Gathered,
    Summed,
}

/// Values of [`rank_figures`].
const RANK_FIGURES: usize = 16;

/// What a rank tells the others after the loop, in one gathered array: its counters,
/// its stage and loop seconds, and what it sent.
fn rank_figures(
    rank: &RankState,
    seconds: &LoopSeconds,
    sent: &Traffic,
    most_held: usize,
) -> [f64; RANK_FIGURES] {
    let c = &rank.counters;
    let s = &rank.stages;
    [
        c.pair_collisions as f64,
        c.wall_collisions as f64,
        c.max_overlap,
        seconds.wall,
        s.integration,
        s.broad_phase,
        s.collisions,
        s.communication,
        c.overlap_sum,
        c.virial,
        seconds.cpu.unwrap_or(f64::NAN),
        c.max_wall_penetration,
        // Counts below 2⁵³: exact as f64.
        sent.messages as f64,
        sent.bytes as f64,
        sent.collectives as f64,
        most_held as f64,
    ]
}

/// The run's measurements from every rank's [`rank_figures`] (in rank order) and the
/// counters the ranks share.
fn merge_figures(
    all_figures: &[Vec<f64>],
    shared_counters: StepCounters,
    setup_s: f64,
    initial: Observables,
) -> Measured {
    let mut counters = shared_counters;
    let mut stages = StageSeconds::default();
    let mut slowest_wall_s = 0.0_f64;
    // Summed in rank order: the same total on every run of the same measurements.
    let mut cpu_s = 0.0_f64;
    let mut sent_by_rank = Vec::with_capacity(all_figures.len());
    for f in all_figures {
        counters.merge(&StepCounters {
            pair_collisions: f[0] as u64,
            wall_collisions: f[1] as u64,
            max_overlap: f[2],
            max_wall_penetration: f[11],
            overlap_sum: f[8],
            virial: f[9],
        });
        // The slowest rank sets the pace: report its time, and each stage's longest.
        slowest_wall_s = slowest_wall_s.max(f[3]);
        stages.integration = stages.integration.max(f[4]);
        stages.broad_phase = stages.broad_phase.max(f[5]);
        stages.collisions = stages.collisions.max(f[6]);
        stages.communication = stages.communication.max(f[7]);
        cpu_s += f[10];
        sent_by_rank.push(Traffic {
            messages: f[12] as u64,
            bytes: f[13] as u64,
            collectives: f[14] as u64,
        });
    }
    Measured {
        setup_s,
        wall_s: slowest_wall_s,
        cpu_s: Some(cpu_s).filter(|s| s.is_finite()),
        stages,
        counters,
        initial,
        accuracy: Accuracy::default(),
        // Drawing needs every disk in one process: refused before an MPI run starts.
        draw_s: None,
        traffic: Some(RankTraffic::over(&sent_by_rank)),
        balance: None,
    }
}

/// The slabs are cut again, at a rebuild, when the rank holding most disks holds more
/// than this many times the mean: disks that settle (a pile under gravity) or drift
/// leave the first cut's ranks uneven, and a step lasts as long as its busiest rank's.
const REBALANCE_ABOVE: f64 = 1.1;

/// ... and more than this above the busiest share the last cut made: whole strips may
/// not allow an even cut, and cutting again cannot do better than the disks allow.
const REBALANCE_GAIN: f64 = 0.05;

/// One rank's part of a cut of the strips into slabs: its slab, every strip's owner,
/// the ranks near it, the rank its ghosts come from, and its slab's grid, filled with
/// the disks given.
struct SlabPart {
    slab: Range<usize>,
    owner: Vec<usize>,
    hood: Neighbourhood,
    ghosts_from: Option<usize>,
    grid: StripGrid,
}

impl SlabPart {
    fn new(
        slabs: &[Range<usize>],
        domain: &crate::sim::Domain,
        layout: StripLayout,
        me: usize,
        particles: &Particles,
    ) -> SlabPart {
        let slab = slabs[me].clone();
        let owner = owners(slabs, layout.n_strips);
        let mut grid = StripGrid::window(domain, layout, slab.clone());
        grid.fill(particles, 0..particles.len());
        let periodic = domain.boundary == Boundary::Periodic;
        let ghosts_from =
            (grid.ghost_strip()).and_then(|strip| Some(owner[strip]).filter(|&rank| rank != me));
        let peers = peers_of(&owner, &slab, periodic, me);
        let hood = Neighbourhood::new(slabs, &owner, periodic, me, peers);
        SlabPart {
            slab,
            owner,
            hood,
            ghosts_from,
            grid,
        }
    }
}

/// One rank's disks, grid and scratch memory.
struct RankState {
    domain: crate::sim::Domain,
    physics: crate::sim::Physics,
    layout: StripLayout,
    slab: Range<usize>,
    /// Owner rank of each strip.
    owner: Vec<usize>,
    /// Rank that sends the ghost strip, if any.
    ghosts_from: Option<usize>,
    /// This rank's peers, the ranks whose strips lie within [`PEER_STRIPS`] strips of
    /// its slab: the only ranks it talks to in a step, but when chains or migrants reach
    /// further (see [`RankState::share_chains`] and [`RankState::redistribute`]). Also
    /// the rank below every rank, which sees that rank's first strip.
    hood: Neighbourhood,
    /// The rank's own disks; during a step, ghosts follow them.
    particles: Particles,
    /// How many of `particles` are the rank's own (the rest are this step's ghosts).
    n_own: usize,
    /// Strips tall enough for the neighbour list's skin.
    grid: StripGrid,
    /// The skin and the own disks' positions at the last build of the list.
    skin: Skin,
    /// The bands of strips the slab's threads step side by side: one per thread.
    n_bands: usize,
    /// One neighbour list per band (own disks, then ghosts, at the last build), and
    /// each band's own chains of a step.
    bands: BandLists,
    /// Per disk: in a pair an escapee's query found this step (all false between steps).
    touched: Vec<bool>,
    /// The own disks in the slab's first strip at the last build, when a rank below
    /// sees them as its ghosts.
    exported: DiskSet,
    /// This step's own disks that escaped the list (storage indices, in order).
    escapees: Vec<u32>,
    /// Those of them reported to the peers, whose strips their queries may reach.
    sent: DiskSet,
    /// The reported escapees, packed.
    reported: Vec<f64>,
    /// Where the peers' reported escapees start among `particles`, after the ghosts,
    /// and the rank that sent each.
    first_reported: usize,
    reported_from: Vec<usize>,
    /// When the own disks are next stored in grid order: the scene's schedule.
    reorder: ReorderSchedule,
    /// Per band: the disks that left their strips in the last refresh.
    movers: Vec<Vec<Mover>>,
    /// The pairs the bands handed over and those of the escapees; after the split, the
    /// rank's own chains among them, in resolution order.
    crossing: Vec<Contact>,
    /// The pairs of the chains another rank may hold too.
    shared: Vec<Contact>,
    schedule: ContactSchedule,
    /// What this rank's own steps did.
    counters: StepCounters,
    /// What the resolution of shared chains did: the same on every rank, counted once.
    shared_counters: StepCounters,
    stages: StageSeconds,
    /// Disks in the whole scene.
    n_disks: usize,
    /// The busiest rank's disks over the mean, summed over the steps (the same on every
    /// rank), and the steps.
    busiest_share_sum: f64,
    steps: u64,
    /// Times [`RankState::rebalance`] ran.
    recuts: u64,
    /// The busiest rank's disks over the mean, at the last step's summary.
    busiest_share: f64,
    /// Whether the ranks rebuild their lists at the next step
    /// ([`RankState::foresee_rebuild`]), how far the farthest disk had moved since the
    /// build at the last step, and this rank's escapees then.
    rebuild_next: bool,
    last_moved: f64,
    last_escapees: usize,
    /// Per rank: disks that left the slab for a rank not a peer at a rebuild, held until
    /// the ranks exchange with all others.
    held: Vec<Vec<f64>>,
    /// The busiest rank's disks over the mean just after the last cut (1 before any).
    cut_share: f64,
}

/// How far from its slab a rank looks for the ranks it talks to in a step: a disk that
/// left its slab by less than a strip, queried with a reach of at most a strip, reads
/// strips at most this many beyond the slab.
const PEER_STRIPS: usize = 2;

/// What every rank learns of every rank in a step's one small all-reduce, after the
/// contacts are found and the shared ones swapped with the peers: the largest
/// displacement since the build, whether some rank has too many escapees for queries
/// (both decide the next step's rebuild), the most disks a rank owns (for the balance
/// of the slabs), whether some rank had a shared chain that reaches past its peers, and
/// whether some rank found this step's contacts on lists that could not serve it.
struct StepSummary {
    moved_sq: f64,
    crowded: bool,
    most_disks: usize,
    open: bool,
    astray: bool,
}

impl StepSummary {
    fn values(&self) -> [f64; 5] {
        [
            self.moved_sq,
            f64::from(self.crowded),
            // Counts below 2⁵³: exact as f64.
            self.most_disks as f64,
            f64::from(self.open),
            f64::from(self.astray),
        ]
    }

    /// The summary of all ranks, from the largest of each rank's [`values`](Self::values).
    fn of_largest(largest: &[f64]) -> StepSummary {
        StepSummary {
            moved_sq: largest[0],
            crowded: largest[1] > 0.0,
            most_disks: largest[2] as usize,
            open: largest[3] > 0.0,
            astray: largest[4] > 0.0,
        }
    }
}

/// What a rank's own escapees tell the others: the largest displacement since the
/// build (infinite for a disk gone astray) and whether the rank will have too many
/// escapees for queries at the next step.
struct OwnEscapees {
    moved_sq: f64,
    crowded_next: bool,
}

/// What a rank received in a step's swap with its peers ([`RankState::swap_halo`]):
/// one message from each peer, in the peers' order, and the farthest a disk of this
/// rank or of a peer may have moved since the build.
struct Swapped {
    messages: Vec<Vec<f64>>,
    /// Which message holds the ghosts from the rank above, if there is one.
    from_above: Option<usize>,
    moved: f64,
}

impl Swapped {
    /// A message's ghosts, packed, and the escapees its sender reported.
    fn split(message: &[f64]) -> (&[f64], &[f64]) {
        message[HALO_HEAD..].split_at(message[0] as usize)
    }

    /// The ghosts from the rank above, packed (empty when there is none).
    fn ghosts(&self) -> &[f64] {
        (self.from_above).map_or(&[], |at| Swapped::split(&self.messages[at]).0)
    }

    /// The escapees each peer reported, packed, in the peers' order.
    fn reports(&self) -> Vec<&[f64]> {
        (self.messages.iter())
            .map(|message| Swapped::split(message).1)
            .collect()
    }
}

/// A rank's shared contacts of a step, sent to its peers, and what it made of its
/// own and theirs before the ranks learn whether a chain reached further.
struct SharedStep {
    mine: Vec<f64>,
    own_slots: HashMap<u32, usize>,
    resolution: Option<Resolution>,
}

/// Values at the head of a message of [`RankState::swap_halo`]: the ghosts' count of
/// values, and how far the sender's disks may have moved.
const HALO_HEAD: usize = 2;

/// What a rank foresees the next step to add to the farthest displacement and to its
/// escapees, in multiples of what the last step added ([`RankState::foresee_rebuild`]):
/// twice, a margin for disks that speed up.
const FORESIGHT: f64 = 2.0;

/// The ranks owning the strips within [`PEER_STRIPS`] of `slab`, but `me`, in rank
/// order. Two ranks are each other's peers or neither: the relation is the distance
/// between their slabs.
fn peers_of(owner: &[usize], slab: &Range<usize>, periodic: bool, me: usize) -> Vec<usize> {
    let n_strips = owner.len() as i64;
    let near = (slab.start as i64 - PEER_STRIPS as i64)..(slab.end + PEER_STRIPS) as i64;
    let mut peers: Vec<usize> = near
        .filter_map(|strip| match periodic {
            true => Some(strip.rem_euclid(n_strips)),
            false => Some(strip).filter(|strip| (0..n_strips).contains(strip)),
        })
        .map(|strip| owner[strip as usize])
        .filter(|&rank| rank != me)
        .collect();
    peers.sort_unstable();
    peers.dedup();
    peers
}

impl RankState {
    /// How evenly the ranks held the disks, from this rank's steps (the same on every
    /// rank) and every rank's figures; `None` before any step.
    fn balance(&self, all_figures: &[Vec<f64>]) -> Option<Balance> {
        (self.steps > 0).then(|| Balance {
            imbalance: self.busiest_share_sum / self.steps as f64,
            recuts: self.recuts,
            setup_disks_max: (all_figures.iter())
                .map(|figures| figures[RANK_FIGURES - 1] as u64)
                .max()
                .unwrap_or(0),
        })
    }

    /// Sends the own disks, packed, to rank 0 (all ranks call this together): rank 0
    /// gets every rank's in rank order, the others nothing.
    fn gather_on_first<C: Communicator>(&self, comm: &C) -> Vec<Vec<f64>> {
        let mut to_first = vec![Vec::new(); comm.size()];
        to_first[0].reserve_exact(self.n_own * PACKED_LEN);
        for idx in 0..self.n_own {
            self.particles.pack(idx, &mut to_first[0]);
        }
        comm.exchange(&to_first)
    }

    /// Rank `me`'s state, from its disks (`particles`, all in its slab) of a scene of
    /// `n_disks`, for a slab stepped in `n_bands` bands.
    #[allow(clippy::too_many_arguments)]
    fn new(
        scene: &crate::sim::Scene,
        particles: Particles,
        n_disks: usize,
        layout: StripLayout,
        slabs: &[Range<usize>],
        skin: Skin,
        me: usize,
        n_bands: usize,
    ) -> RankState {
        let SlabPart {
            slab,
            owner,
            hood,
            ghosts_from,
            grid,
        } = SlabPart::new(slabs, &scene.domain, layout, me, &particles);
        RankState {
            domain: scene.domain,
            physics: scene.physics,
            layout,
            ghosts_from,
            hood,
            slab,
            owner,
            n_own: particles.len(),
            particles,
            grid,
            skin,
            n_bands,
            bands: BandLists::default(),
            touched: Vec::new(),
            reorder: ReorderSchedule::for_scene(n_disks),
            movers: Vec::new(),
            crossing: Vec::new(),
            shared: Vec::new(),
            exported: DiskSet::default(),
            escapees: Vec::new(),
            sent: DiskSet::default(),
            reported: Vec::new(),
            first_reported: 0,
            reported_from: Vec::new(),
            schedule: ContactSchedule::default(),
            counters: StepCounters::default(),
            shared_counters: StepCounters::default(),
            stages: StageSeconds::default(),
            n_disks,
            busiest_share_sum: 0.0,
            steps: 0,
            recuts: 0,
            cut_share: 1.0,
            busiest_share: 1.0,
            rebuild_next: false,
            last_moved: 0.0,
            last_escapees: 0,
            held: Vec::new(),
        }
    }

    fn step<C: Communicator>(&mut self, comm: &C, dt: f64, pieces: &impl Pieces) {
        let mut stages = self.stages;
        timed(&mut stages.integration, || {
            let (domain, physics) = (&self.domain, &self.physics);
            let walls = advance_in_pieces(
                domain,
                physics,
                dt,
                &mut self.particles,
                &mut self.skin,
                pieces,
            );
            self.counters.merge(&walls);
        });
        let own = timed(&mut stages.broad_phase, || self.escapee_report(pieces));
        // The ranks rebuild their lists together, on the step the last step's summary
        // foresaw; until then, disks stay with the rank that held them at the build,
        // the ghosts are the same disks in the same order, and the disks that escaped
        // the lists are served by queries, on every peer whose strips they may reach.
        // Where that fails (a disk went further than queries serve, or further than a
        // peer at a rebuild), the step's summary says so, and the ranks find the
        // contacts again on lists rebuilt with every rank. When the lists are rebuilt
        // does not change the contacts found, so neither the bits.
        let mut rebuild = self.rebuild_next;
        let mut everywhere = false;
        let (summary, shared) = loop {
            if rebuild {
                self.redistribute(comm, &mut stages, everywhere, pieces);
                let uneven = REBALANCE_ABOVE.max(self.cut_share + REBALANCE_GAIN);
                if !everywhere && self.busiest_share > uneven {
                    timed(&mut stages.communication, || self.rebalance(comm, pieces));
                }
            }
            let swapped = timed(&mut stages.communication, || {
                self.swap_halo(comm, (!rebuild).then_some(&own))
            });
            timed(&mut stages.broad_phase, || {
                self.find_contacts(swapped, rebuild, pieces)
            });
            let shared = self.share_with_peers(comm, &mut stages, dt);
            let mine = StepSummary {
                moved_sq: own.moved_sq,
                // A rebuild leaves no escapee.
                crowded: own.crowded_next && !rebuild,
                most_disks: self.n_own,
                open: shared.resolution.is_none(),
                astray: (!rebuild && !self.skin.may_reach(own.moved_sq))
                    || self.held.iter().any(|held| !held.is_empty()),
            };
            let all = timed(&mut stages.communication, || {
                StepSummary::of_largest(&comm.max_all(&mine.values()))
            });
            if rebuild {
                self.last_escapees = 0;
            }
            if !all.astray {
                break (all, shared);
            }
            self.particles.truncate(self.n_own);
            // A rebuild fails only on held-back disks, which moved over two strips: the
            // exchange with every rank that sends them cannot fail again.
            everywhere = rebuild || !self.is_within_a_strip(all.moved_sq);
            rebuild = true;
        };
        self.busiest_share = summary.most_disks as f64 * comm.size() as f64 / self.n_disks as f64;
        self.busiest_share_sum += self.busiest_share;
        self.steps += 1;
        self.rebuild_next = self.foresee_rebuild(&summary, rebuild);
        timed(&mut stages.collisions, || {
            self.resolve_own_chains(dt, pieces)
        });
        self.settle_shared_chains(comm, &mut stages, summary.open, shared, dt);
        self.stages = stages;
    }

    /// Whether the ranks rebuild their lists at the next step, from this step's
    /// summary (the same on every rank) and whether this step rebuilt them: when some
    /// rank will have too many escapees for queries, or a disk will have moved further
    /// than queries serve. Both are foreseen from their growth over this step, with a
    /// margin ([`FORESIGHT`]). A disk that goes further unforeseen makes its step find
    /// the contacts twice; too many escapees unforeseen only make a step slower.
    fn foresee_rebuild(&mut self, summary: &StepSummary, rebuilt: bool) -> bool {
        // How far the farthest disk moved since the build, if one escaped (else 0).
        let moved = summary.moved_sq.sqrt();
        let growth = (moved - self.last_moved).max(0.0);
        let next = if rebuilt { 0.0 } else { moved } + FORESIGHT * growth;
        // Where the next step's growth is measured from: exactly 0 after a rebuild,
        // at most half the skin while no disk escaped.
        self.last_moved = match (rebuilt, moved > 0.0) {
            (true, _) => 0.0,
            (false, true) => moved,
            (false, false) => 0.5 * self.skin.width(),
        };
        summary.crowded || !self.skin.may_reach(next * next)
    }

    /// Whether no disk moved as far as a strip since the build, if the farthest moved
    /// √`moved_sq`: then a disk that left the slab went to a peer.
    fn is_within_a_strip(&self, moved_sq: f64) -> bool {
        moved_sq.sqrt() < self.layout.height() / self.layout.n_strips as f64
    }

    /// Sends the shared contacts to the peers, and resolves, from the rank's and the
    /// peers', the shared chains of the own disks if all of them are closed
    /// ([`SharedChains::resolve_closed_chains`]); the new states are applied by
    /// [`RankState::settle_shared_chains`], once the ranks know whether some chain
    /// reached further.
    fn share_with_peers<C: Communicator>(
        &self,
        comm: &C,
        stages: &mut StageSeconds,
        dt: f64,
    ) -> SharedStep {
        let mine = timed(&mut stages.collisions, || self.pack_shared_for_peers());
        let theirs = timed(&mut stages.communication, || {
            self.swap_with_peers(comm, &mine)
        });
        // Without shared contacts here or at a peer, no own disk is in a shared chain.
        let any = !mine.is_empty() || theirs.iter().any(|buffer| !buffer.is_empty());
        let own_slots = match any {
            true => self.own_shared_slots(),
            false => HashMap::new(),
        };
        let resolution = timed(&mut stages.collisions, || {
            let mut buffers = vec![&mine[..]];
            buffers.extend(theirs.iter().map(Vec::as_slice));
            (self.shared_chains(dt)).resolve_closed_chains(&buffers, &own_slots)
        });
        SharedStep {
            mine,
            own_slots,
            resolution,
        }
    }

    /// The rule by which this rank resolves shared chains.
    fn shared_chains(&self, dt: f64) -> SharedChains<'_, impl Fn(f64, f64) -> bool + '_> {
        let (grid, hood, owner, reach) =
            (&self.grid, &self.hood, &self.owner, self.skin.patch_reach());
        SharedChains {
            hood,
            query_is_near: move |y, radius| {
                (grid.strips_queried(y, radius, reach, &self.domain))
                    .all(|strip| hood.is_near(owner[strip]))
            },
            domain: &self.domain,
            physics: &self.physics,
            dt,
        }
    }

    /// Applies the shared chains' resolution. When some rank had a chain that reaches
    /// past its peers (`open`, from the step's summary), every rank gathers every
    /// shared contact instead and resolves them all
    /// ([`SharedChains::resolve_all_chains`]). Either way the ghosts and reported
    /// escapees are dropped.
    fn settle_shared_chains<C: Communicator>(
        &mut self,
        comm: &C,
        stages: &mut StageSeconds,
        open: bool,
        shared: SharedStep,
        dt: f64,
    ) {
        let resolution = match shared.resolution.filter(|_| !open) {
            Some(resolution) => resolution,
            None => {
                let all = timed(&mut stages.communication, || comm.all_gather(&shared.mine));
                timed(&mut stages.collisions, || {
                    let buffers: Vec<&[f64]> = all.iter().map(Vec::as_slice).collect();
                    (self.shared_chains(dt)).resolve_all_chains(&buffers, &shared.own_slots)
                })
            }
        };
        resolution.apply(&mut self.particles);
        let counters = match open {
            false => &mut self.counters,
            // Every rank resolves every chain: counted once, as rank 0's.
            true => &mut self.shared_counters,
        };
        counters.merge(&resolution.counters);
        self.particles.truncate(self.n_own);
    }

    /// Sends `data` to every peer and returns what each sent, in the peers' order.
    fn swap_with_peers<C: Communicator>(&self, comm: &C, data: &[f64]) -> Vec<Vec<f64>> {
        let peers = self.hood.peers();
        let sends: Vec<(usize, &[f64])> = peers.iter().map(|&peer| (peer, data)).collect();
        comm.send_receive(&sends, peers)
    }

    /// The shared contacts, both disks of each, with their owner and how other ranks saw
    /// them ([`pack_shared_disk`]).
    fn pack_shared_for_peers(&self) -> Vec<f64> {
        let (particles, n_own, first_reported) = (&self.particles, self.n_own, self.first_reported);
        // Escapees the rank above reported, which may be ghosts here too.
        let reported_above: HashSet<u32> = (first_reported..particles.len())
            .filter(|&idx| Some(self.reported_from[idx - first_reported]) == self.ghosts_from)
            .map(|idx| particles.id[idx])
            .collect();
        let about = |idx: usize| match idx {
            _ if idx < n_own => (
                self.hood.rank(),
                Seen {
                    exported: self.exported.contains(idx as u32),
                    reported: self.sent.contains(idx as u32),
                },
            ),
            _ if idx < first_reported => (
                self.ghosts_from.expect("ghosts come from the rank above"),
                Seen {
                    exported: true,
                    reported: reported_above.contains(&particles.id[idx]),
                },
            ),
            _ => (
                self.reported_from[idx - first_reported],
                Seen {
                    exported: false,
                    reported: true,
                },
            ),
        };
        let mut packed = Vec::with_capacity(self.shared.len() * 2 * (PACKED_LEN + 2));
        for contact in &self.shared {
            for idx in [contact.a as usize, contact.b as usize] {
                let (owner, seen) = about(idx);
                pack_shared_disk(particles, idx, owner, seen, &mut packed);
            }
        }
        packed
    }

    /// The storage index, by id, of every own disk that may be in a shared chain: those
    /// of this rank's shared contacts, and the exported and reported ones, which another
    /// rank's contacts may hold.
    fn own_shared_slots(&self) -> HashMap<u32, usize> {
        let n_own = self.n_own;
        let mut own_slots: HashMap<u32, usize> = HashMap::new();
        for contact in &self.shared {
            for idx in [contact.a as usize, contact.b as usize] {
                if idx < n_own {
                    own_slots.insert(self.particles.id[idx], idx);
                }
            }
        }
        if self.hood.export_to().is_some() {
            for entry in self.grid.strip_entries(self.slab.start) {
                let idx = entry.idx() as usize;
                own_slots.insert(self.particles.id[idx], idx);
            }
        }
        for &idx in self.escapees.iter().filter(|&&idx| self.sent.contains(idx)) {
            own_slots.insert(self.particles.id[idx as usize], idx as usize);
        }
        own_slots
    }

    /// The first half of a rebuild, on every rank together: the disks that left the
    /// slab go to their strips' ranks, the slab is re-sorted (and re-stored when the
    /// [`ReorderSchedule`] says so), and the positions are recorded for the lists.
    /// While no disk moved as far as a strip since the last build, the disks that left
    /// went to peers, and the ranks send to their peers only; a rank holds back those
    /// that went further (and says so in the step's summary). With `everywhere`, the
    /// ranks exchange with all others, the held-back disks too, so no disk is lost.
    fn redistribute<C: Communicator>(
        &mut self,
        comm: &C,
        stages: &mut StageSeconds,
        everywhere: bool,
        pieces: &impl Pieces,
    ) {
        let mut emigrants = timed(&mut stages.broad_phase, || {
            self.refresh(comm.size(), pieces)
        });
        let immigrants = timed(&mut stages.communication, || match everywhere {
            false => {
                let peers = self.hood.peers();
                self.held.resize_with(comm.size(), Vec::new);
                for (rank, (gone, held)) in emigrants.iter_mut().zip(&mut self.held).enumerate() {
                    if !gone.is_empty() && peers.binary_search(&rank).is_err() {
                        held.append(gone);
                    }
                }
                let sends: Vec<(usize, &[f64])> = (peers.iter())
                    .map(|&peer| (peer, &emigrants[peer][..]))
                    .collect();
                comm.send_receive(&sends, peers)
            }
            true => {
                for (gone, held) in emigrants.iter_mut().zip(&mut self.held) {
                    gone.append(held);
                }
                comm.exchange(&emigrants)
            }
        });
        timed(&mut stages.broad_phase, || {
            self.migrate(&immigrants, pieces);
            self.skin.record(&self.particles, pieces);
            self.mark_exported();
        });
    }

    /// Cuts the slabs again by the disks each strip holds now (on every rank together,
    /// after the disks migrated at a rebuild): every rank learns every strip's count
    /// (an all-gather of a few numbers per strip), cuts as at set-up, and sends the
    /// disks of strips that changed owner to their new ranks (an all-to-all). Where the
    /// disks are held never changes the bits.
    fn rebalance<C: Communicator>(&mut self, comm: &C, pieces: &impl Pieces) {
        self.recuts += 1;
        let me = comm.rank();
        let counts: Vec<f64> = (self.slab.clone())
            .map(|strip| self.grid.strip_entries(strip).len() as f64)
            .collect();
        // The slabs lie in rank order: the ranks' counts, one after another, are the strips'.
        let per_strip: Vec<usize> = (comm.all_gather(&counts).iter().flatten())
            .map(|&count| count as usize)
            .collect();
        debug_assert_eq!(per_strip.len(), self.layout.n_strips);
        let slabs = cut_slabs(&per_strip, comm.size());
        let most = (slabs.iter())
            .map(|slab| per_strip[slab.clone()].iter().sum::<usize>())
            .max()
            .unwrap_or(0);
        self.cut_share = most as f64 * comm.size() as f64 / self.n_disks as f64;
        let new_owner = owners(&slabs, self.layout.n_strips);
        let mut outgoing = vec![Vec::new(); comm.size()];
        for idx in 0..self.particles.len() {
            let to = new_owner[self.layout.strip_of(self.particles.y[idx])];
            self.particles.pack(idx, &mut outgoing[to]);
        }
        let staying = std::mem::take(&mut outgoing[me]);
        let arrived = comm.exchange(&outgoing);
        drop(outgoing);
        let n_own = staying.len() / PACKED_LEN
            + arrived
                .iter()
                .map(|packed| packed.len() / PACKED_LEN)
                .sum::<usize>();
        let mut particles = Particles::with_capacity(n_own + n_own / SPARE_SHARE);
        particles.unpack_append(&staying);
        for packed in &arrived {
            particles.unpack_append(packed);
        }
        let part = SlabPart::new(&slabs, &self.domain, self.layout, me, &particles);
        (
            self.slab,
            self.owner,
            self.hood,
            self.ghosts_from,
            self.grid,
        ) = (
            part.slab,
            part.owner,
            part.hood,
            part.ghosts_from,
            part.grid,
        );
        self.particles = particles;
        self.n_own = self.particles.len();
        // As at set-up: the strips sorted, the positions recorded for the lists, the
        // disks the rank below sees noted.
        let none_left = self.refresh(comm.size(), pieces);
        debug_assert!(none_left.iter().all(Vec::is_empty));
        self.migrate(&[], pieces);
        self.skin.record(&self.particles, pieces);
        self.mark_exported();
    }

    /// Builds the lists at the disks' present positions, on every rank together, as the
    /// first step would (the serial `Stepper::build_lists`): a run's set-up, untimed.
    fn build_lists<C: Communicator>(&mut self, comm: &C, pieces: &impl Pieces) {
        let mut untimed = StageSeconds::default();
        // Every disk starts in its rank's slab.
        self.redistribute(comm, &mut untimed, false, pieces);
        debug_assert!(self.held.iter().all(Vec::is_empty));
        let swapped = self.swap_halo(comm, None);
        self.take_ghosts(swapped.ghosts(), true, pieces);
        // The first step brings the ghosts again, in the same order.
        self.particles.truncate(self.n_own);
    }

    /// What the other ranks need to know of this rank's disks that escaped the list;
    /// notes the own escapees in `escapees`, and packs in `reported` those whose queries
    /// may read another rank's strips (marked in `sent`).
    fn escapee_report(&mut self, pieces: &impl Pieces) -> OwnEscapees {
        let n_own = self.particles.len();
        let moved_sq =
            largest_displacement_sq(&mut self.skin, &self.particles, &self.domain, pieces);
        self.escapees.clear();
        self.sent.clear(n_own);
        self.reported.clear();
        if self.skin.is_exceeded(moved_sq) && self.skin.may_reach(moved_sq) {
            self.skin.escapees(0..n_own, &mut self.escapees);
        }
        // Queries serve escapees only while none moved further than this.
        let moved = self.skin.patch_reach();
        for &idx in &self.escapees {
            let (y, radius) = (
                self.particles.y[idx as usize],
                self.particles.radius[idx as usize],
            );
            if self.grid.query_leaves_owned(y, radius, moved, &self.domain) {
                self.particles.pack(idx as usize, &mut self.reported);
                self.sent.insert(idx);
            }
        }
        let n_escapees = self.escapees.len();
        let last = std::mem::replace(&mut self.last_escapees, n_escapees);
        let next = n_escapees + FORESIGHT as usize * n_escapees.saturating_sub(last);
        OwnEscapees {
            // A disk gone astray (NaN) makes every rank's lists stale, as in the serial
            // run; the reduction's largest of NaN and a number is not defined.
            moved_sq: if moved_sq.is_nan() {
                f64::INFINITY
            } else {
                moved_sq
            },
            crowded_next: !self.skin.may_patch(next, n_own, 0.0),
        }
    }

    /// Re-sorts the slab after the disks moved; returns, packed per destination rank,
    /// the disks that left it (their slots are freed by [`RankState::migrate`]).
    fn refresh(&mut self, n_ranks: usize, pieces: &impl Pieces) -> Vec<Vec<f64>> {
        let bands = self.grid.bands(self.n_bands);
        let (layout, now) = (&self.layout, &self.particles);
        let mut slices = split_into_bands(self.grid.owned_strips_mut(), &bands);
        self.movers.resize_with(bands.len(), Vec::new);
        let mut refreshes: Vec<_> = slices.iter_mut().zip(&mut self.movers).collect();
        pieces.for_each(&mut refreshes, |((first, band), band_movers)| {
            // A local: the lengths of the bands' vectors share cache lines.
            let mut movers = std::mem::take(*band_movers);
            movers.clear();
            refresh_band(layout, band, *first, now, &mut movers);
            **band_movers = movers;
        });
        // Each band takes in the disks that moved into its strips from any band; the
        // disks that left the slab go to their strips' ranks.
        let movers: Vec<&[Mover]> = self.movers.iter().map(Vec::as_slice).collect();
        pieces.for_each(&mut slices, |(first, band)| {
            receive_band(band, *first, &movers)
        });
        let mut outgoing = vec![Vec::new(); n_ranks];
        for mover in self.movers.iter().flatten() {
            if !self.slab.contains(&mover.strip()) {
                let to = self.owner[mover.strip()];
                self.particles.pack(mover.idx() as usize, &mut outgoing[to]);
            }
        }
        outgoing
    }

    /// Frees the slots of the disks that left and takes in the disks that arrived; when
    /// the [`ReorderSchedule`] says so, re-stores the disks in grid order.
    fn migrate(&mut self, immigrants: &[Vec<f64>], pieces: &impl Pieces) {
        let staying = self.slab.clone();
        let mut leaving: Vec<u32> = self
            .movers
            .iter()
            .flatten()
            .filter(|mover| !staying.contains(&mover.strip()))
            .map(Mover::idx)
            .collect();
        // Highest slots first, so the last disk moved into a freed slot is never one
        // that is itself leaving.
        leaving.sort_unstable_by(|a, b| b.cmp(a));
        for idx in leaving {
            let last = self.particles.len() - 1;
            if idx as usize != last {
                self.grid.relabel(self.particles.y[last], last as u32, idx);
            }
            self.particles.swap_remove(idx as usize);
        }
        self.make_room(immigrants.iter().map(Vec::as_slice));
        let first_new = self.particles.len();
        for packed in immigrants {
            self.particles.unpack_append(packed);
        }
        let mut arrived: Vec<Mover> = (first_new..self.particles.len())
            .map(|idx| self.grid.mover(&self.particles, idx))
            .collect();
        sort_movers(&mut arrived);
        receive_band(self.grid.owned_strips_mut(), self.slab.start, &[&arrived]);

        if self.reorder.count_build() {
            // The lists are rebuilt next: they lend their memory, as the serial stepper's
            // does.
            let (grid, particles) = (&mut self.grid, &mut self.particles);
            with_reorder_scratch(self.bands.lists_mut(), particles.len(), |scratch| {
                grid.store_in_grid_order(particles, scratch, pieces);
            });
        }
    }

    /// Notes which own disks the rank below will see as ghosts until the next build.
    fn mark_exported(&mut self) {
        self.exported.clear(self.particles.len());
        if self.hood.export_to().is_some() {
            for entry in self.grid.strip_entries(self.slab.start) {
                self.exported.insert(entry.idx());
            }
        }
        debug_assert!(
            (0..self.particles.len()).all(|disk| {
                let first = self.layout.strip_of(self.particles.y[disk]) == self.slab.start;
                self.exported.contains(disk as u32) == (self.hood.export_to().is_some() && first)
            }),
            "the first strip's entries are the own disks built there"
        );
    }

    /// Sends to every peer how far this rank's disks may have moved since the build
    /// and, with `escaped` (the own escapees' summary, on a step without a rebuild), the
    /// escapees reported to the peers; to the rank below also the disks of the slab's
    /// first strip, in x order. Returns the ghosts from the rank above, what each peer
    /// reported, and the farthest any of them or this rank's disks may have moved.
    fn swap_halo<C: Communicator>(&self, comm: &C, escaped: Option<&OwnEscapees>) -> Swapped {
        // A disk that did not escape moved less than half the skin.
        let moved_sq = escaped.map_or(0.0, |own| own.moved_sq);
        let moved = (0.5 * self.skin.width()).max(moved_sq.sqrt());
        let reported: &[f64] = if escaped.is_some() {
            &self.reported
        } else {
            &[]
        };
        let peers = self.hood.peers();
        let messages: Vec<Vec<f64>> = (peers.iter())
            .map(|&peer| {
                let mut message = vec![0.0, moved];
                if Some(peer) == self.hood.export_to() {
                    for entry in self.grid.strip_entries(self.slab.start) {
                        self.particles.pack(entry.idx() as usize, &mut message);
                    }
                    message[0] = (message.len() - HALO_HEAD) as f64;
                }
                message.extend_from_slice(reported);
                message
            })
            .collect();
        let sends: Vec<(usize, &[f64])> = (peers.iter().copied())
            .zip(messages.iter().map(Vec::as_slice))
            .collect();
        let messages = comm.send_receive(&sends, peers);
        let moved = (messages.iter()).fold(moved, |farthest, message| farthest.max(message[1]));
        Swapped {
            messages,
            from_above: (self.ghosts_from).and_then(|above| peers.iter().position(|&p| p == above)),
            moved,
        }
    }

    /// Appends the ghosts after the own disks and, with `rebuild`, rebuilds the bands'
    /// lists with them.
    fn take_ghosts(&mut self, ghosts: &[f64], rebuild: bool, pieces: &impl Pieces) {
        let n_own = self.particles.len();
        self.n_own = n_own;
        if rebuild {
            // The disks were re-stored: this step's escapees are served by the new list.
            self.escapees.clear();
            self.sent.clear(n_own);
        }
        self.make_room([ghosts]);
        self.particles.unpack_append(ghosts);
        if rebuild {
            if self.ghosts_from.is_some() {
                self.grid
                    .set_ghosts(&self.particles, n_own..self.particles.len());
            }
            let bands = self.grid.bands(self.n_bands);
            let (grid, particles, domain, skin) =
                (&self.grid, &self.particles, &self.domain, &self.skin);
            (self.bands).rebuild(grid, &bands, particles, domain, skin, pieces);
        }
    }

    /// [`RankState::take_ghosts`], then finds the listed pairs that overlap and, unless
    /// the lists were rebuilt, the pairs of the own and the peers' reported escapees
    /// that involve an own disk, and splits them into chains of the rank's own (each
    /// band's, and the crossing ones) and chains to share.
    fn find_contacts(&mut self, swapped: Swapped, rebuild: bool, pieces: &impl Pieces) {
        self.take_ghosts(swapped.ghosts(), rebuild, pieces);
        self.first_reported = self.particles.len();
        self.reported_from.clear();
        let reports = swapped.reports();
        let queried =
            !rebuild && (!self.escapees.is_empty() || reports.iter().any(|r| !r.is_empty()));
        let escaped = match queried {
            true => self.find_contacts_of_escapees(&reports, swapped.moved, pieces),
            false => Vec::new(),
        };
        self.touched.resize(self.particles.len(), false);
        for contact in &escaped {
            self.touched[contact.a as usize] = true;
            self.touched[contact.b as usize] = true;
        }
        let n_own = self.n_own;
        let (particles, exported, sent) = (&self.particles, &self.exported, &self.sent);
        // Ghosts, the other ranks' escapees, exported disks (those of the first strip at
        // the build) and escapees sent to other ranks are seen by another rank too:
        // their chains are shared.
        let seen_elsewhere =
            |disk: u32| disk as usize >= n_own || exported.contains(disk) || sent.contains(disk);
        // A disk in an escapee's pair may be in a band's pairs too: the band hands its
        // chain over, to be put together with the escapee's.
        let (touched, any_touched) = (&self.touched, !escaped.is_empty());
        let pinned = |disk: u32| (any_touched && touched[disk as usize]) || seen_elsewhere(disk);
        self.crossing.clear();
        (self.bands).find_contacts(particles, &self.domain, pinned, &mut self.crossing, pieces);
        self.crossing.extend_from_slice(&escaped);
        for contact in &escaped {
            self.touched[contact.a as usize] = false;
            self.touched[contact.b as usize] = false;
        }
        self.shared.clear();
        self.schedule.split(
            &particles.id,
            &mut self.crossing,
            &mut self.shared,
            seen_elsewhere,
        );
    }

    /// Appends the peers' reported escapees after the ghosts, and returns the pairs
    /// that queries around every escapee (own and reported) find in this rank's grid and
    /// that hold an own disk (the others are another rank's to find). A reported
    /// escapee may be a ghost here too: the same disk under two storage indices, never
    /// paired with itself.
    fn find_contacts_of_escapees(
        &mut self,
        reports: &[&[f64]],
        moved: f64,
        pieces: &impl Pieces,
    ) -> Vec<Contact> {
        let first_reported = self.particles.len();
        self.make_room(reports.iter().copied());
        for (report, &from) in reports.iter().zip(self.hood.peers()) {
            self.particles.unpack_append(report);
            let n_disks = report.len() / PACKED_LEN;
            self.reported_from
                .extend(std::iter::repeat_n(from, n_disks));
        }
        let mut queried = self.escapees.clone();
        queried.extend(first_reported as u32..self.particles.len() as u32);
        let (grid, particles, domain) = (&self.grid, &self.particles, &self.domain);
        let found = pieces.map(queried.chunks(ESCAPEES_PER_PIECE), |movers| {
            let mut contacts = Vec::new();
            grid.find_contacts_of(movers, moved, particles, domain, &mut contacts);
            contacts
        });
        let (n_own, id) = (self.n_own, &self.particles.id);
        (found.into_iter().flatten())
            .filter(|contact| {
                let (a, b) = (contact.a as usize, contact.b as usize);
                (a < n_own || b < n_own) && id[a] != id[b]
            })
            .collect()
    }

    /// Makes room, when there is too little, for the disks packed in `incoming` and a
    /// spare share ([`SPARE_SHARE`]) of all the rank then holds. An append past the
    /// room would move every array to one twice as long in the middle of a step: at 10⁶
    /// disks on 2 ranks, the first reported escapees cost the top rank, built without
    /// ghosts and so without room, 5.5 ms (two steps' time) while the other waited.
    fn make_room<'a>(&mut self, incoming: impl IntoIterator<Item = &'a [f64]>) {
        let incoming = (incoming.into_iter())
            .map(|packed| packed.len() / PACKED_LEN)
            .sum();
        let particles = &mut self.particles;
        if particles.room() < incoming {
            let spare = (particles.len() + incoming) / SPARE_SHARE;
            particles.reserve_exact(incoming + spare);
        }
    }

    /// Resolves the rank's own chains: each band's, the bands at once, then the
    /// crossing ones (they share no disk).
    fn resolve_own_chains(&mut self, dt: f64, pieces: &impl Pieces) {
        let (domain, physics) = (&self.domain, &self.physics);
        let counters = &mut self.counters;
        (self.bands).resolve(&mut self.particles, domain, physics, dt, counters, pieces);
        resolve_contacts(
            &mut self.particles,
            domain,
            physics,
            dt,
            &self.crossing,
            counters,
            |_| {},
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::comm::ThreadComm;
    use crate::backend::serial;
    use crate::run::spec::{InjectedSlowdown, MethodSpec, PreparedRun, SceneSource};
    use crate::sim::scene::{GasSpec, MassRule, RadiusDistribution};
    use crate::sim::{Broadphase, Physics};

    fn spec(boundary: Boundary, restitution: f64, packing: f64) -> RunSpec {
        RunSpec {
            scene: SceneSource::Gas(GasSpec {
                radius: RadiusDistribution::Uniform { min: 0.6, max: 1.4 },
                mass: MassRule::Area,
                boundary,
                physics: Physics::with_restitution(restitution),
                seed: 17,
                ..GasSpec::unit(2000, packing)
            }),
            method: MethodSpec::stepped(0.05, 300, Broadphase::Grid),
            slowdown: InjectedSlowdown::NONE,
        }
    }

    /// The inelastic gas of [`spec`] falling under gravity into a pile that comes to
    /// rest on the floor.
    fn pile() -> RunSpec {
        let mut pile = spec(Boundary::Walls, 0.5, 0.3);
        if let SceneSource::Gas(gas) = &mut pile.scene {
            gas.physics.gravity = Some([0.0, -1.0]);
        }
        pile.method = MethodSpec::stepped(0.05, 600, Broadphase::Grid);
        pile
    }

    fn run_on_threads(spec: &RunSpec, ranks: usize) -> RunOutcome {
        run_on_threads_with(spec, ranks, 1, FinalState::Summed)
    }

    /// `ranks` ranks as threads, each stepping on a team of `threads` threads.
    fn run_on_threads_with(
        spec: &RunSpec,
        ranks: usize,
        threads: usize,
        final_state: FinalState,
    ) -> RunOutcome {
        let threads = NonZeroUsize::new(threads).unwrap();
        let outcomes = ThreadComm::run_group(ranks, |comm| {
            run(&comm, spec, final_state, threads).unwrap()
        });
        assert!(outcomes[1..].iter().all(Option::is_none));
        outcomes.into_iter().next().unwrap().unwrap()
    }

    #[test]
    fn ranks_as_threads_give_the_serial_hash() {
        for boundary in [Boundary::Walls, Boundary::Periodic] {
            for restitution in [1.0, 0.8] {
                for packing in [0.05, 0.35] {
                    let spec = spec(boundary, restitution, packing);
                    let reference = serial::run(&spec).unwrap().summary;
                    for ranks in [1, 2, 3, 4] {
                        let summary = run_on_threads(&spec, ranks).summary;
                        let case =
                            format!("{boundary:?} e={restitution} η={packing} {ranks} ranks");
                        assert_eq!(summary.state_hash, reference.state_hash, "{case}");
                        assert_eq!(summary.pair_collisions, reference.pair_collisions, "{case}");
                        assert_eq!(summary.wall_collisions, reference.wall_collisions, "{case}");
                        assert_eq!(summary.max_overlap, reference.max_overlap, "{case}");
                        assert_eq!(summary.n, reference.n);
                        // Each rank sums its own disks; the sums merge into the same bits.
                        let figures = |s: &crate::run::summary::RunSummary| {
                            [
                                s.kinetic_energy_final,
                                s.momentum_final[0],
                                s.momentum_final[1],
                            ]
                            .map(f64::to_bits)
                        };
                        assert_eq!(figures(&summary), figures(&reference), "{case}");
                    }
                }
            }
        }
    }

    /// Ranks × threads: each rank steps its slab in bands, one per thread, and hands the
    /// chains that reach a band's first strip to its own crossing chains or, when
    /// another rank may hold them, to the shared ones. Walls and periodic, elastic and
    /// inelastic, dilute and dense, unequal disks, and a pile under gravity.
    #[test]
    fn ranks_of_several_threads_give_the_serial_hash() {
        let mut cases = vec![("pile", pile())];
        for boundary in [Boundary::Walls, Boundary::Periodic] {
            for (restitution, packing) in [(1.0, 0.05), (0.8, 0.35)] {
                cases.push(("gas", spec(boundary, restitution, packing)));
            }
        }
        for (name, spec) in &cases {
            let reference = serial::run(spec).unwrap().summary;
            for (ranks, threads) in [(1, 2), (2, 2), (3, 2), (2, 3)] {
                let summary = run_on_threads_with(spec, ranks, threads, FinalState::Summed).summary;
                let case = format!("{name} {:?} {ranks} × {threads}", summary.boundary);
                assert_eq!(summary.state_hash, reference.state_hash, "{case}");
                assert_eq!(summary.pair_collisions, reference.pair_collisions, "{case}");
                assert_eq!(summary.max_overlap, reference.max_overlap, "{case}");
                assert_eq!(
                    (summary.ranks, summary.threads, summary.workers),
                    (ranks, threads, ranks * threads),
                    "{case}"
                );
            }
        }
    }

    /// Rank 0 holds every disk at the end only when the run is asked for its final
    /// state (`--dump`): then it is the serial run's, disk for disk.
    #[test]
    fn the_final_state_reaches_rank_0_only_when_asked_for() {
        let spec = spec(Boundary::Walls, 0.8, 0.35);
        let reference = serial::run(&spec).unwrap();
        let summed = run_on_threads_with(&spec, 3, 1, FinalState::Summed);
        assert!(summed.final_state.is_none());
        let gathered = run_on_threads_with(&spec, 3, 2, FinalState::Gathered);
        let disks = |outcome: &RunOutcome| outcome.final_state.as_ref().unwrap().disks_by_id();
        assert_eq!(disks(&gathered), disks(&reference));
        assert_eq!(gathered.summary.state_hash, summed.summary.state_hash);
    }

    #[test]
    fn ranks_as_threads_give_the_serial_hash_for_a_pile_resting_under_gravity() {
        let spec = pile();
        let reference = serial::run(&spec).unwrap().summary;
        assert!(reference.max_wall_penetration > 0.0);
        for ranks in [2, 8] {
            let summary = run_on_threads(&spec, ranks).summary;
            assert_eq!(summary.state_hash, reference.state_hash, "{ranks} ranks");
            assert_eq!(
                summary.max_wall_penetration, reference.max_wall_penetration,
                "{ranks} ranks"
            );
            // The pile, a third of the box, is one chain: across more than a rank and its
            // peers from 8 ranks on, and then the ranks gather it on some steps. Per
            // step 1 collective; per re-cut of the slabs 2 more.
            let collectives = summary.collectives_per_step.unwrap() * summary.steps as f64;
            let recuts = summary.recuts.unwrap() as f64;
            let gathered = collectives > summary.steps as f64 + 2.0 * recuts;
            assert_eq!(gathered, ranks >= 8, "{ranks} ranks: {summary}");
        }
    }

    /// A dense gas (packing 0.6, placed on a lattice, elastic and inelastic): its chains
    /// are long and cross the slabs' edges every step.
    #[test]
    fn ranks_as_threads_give_the_serial_hash_for_a_dense_gas() {
        for restitution in [1.0, 0.8] {
            let mut spec = spec(Boundary::Periodic, restitution, 0.6);
            if let SceneSource::Gas(gas) = &mut spec.scene {
                gas.placement = crate::sim::scene::Placement::Lattice;
                gas.radius = RadiusDistribution::Fixed(1.0);
                gas.mass = MassRule::Fixed(1.0);
            }
            spec.method = MethodSpec::stepped(0.02, 200, Broadphase::Grid);
            let reference = serial::run(&spec).unwrap().summary;
            assert!(reference.pair_collisions > 1000, "{reference}");
            for ranks in [2, 3, 4] {
                let summary = run_on_threads(&spec, ranks).summary;
                let case = format!("e = {restitution}, {ranks} ranks");
                assert_eq!(summary.state_hash, reference.state_hash, "{case}");
                assert_eq!(summary.pair_collisions, reference.pair_collisions, "{case}");
                assert_eq!(summary.max_overlap, reference.max_overlap, "{case}");
            }
        }
    }

    /// Up to 64 ranks, on boxes tall enough for them: an elastic gas of equal disks in
    /// a periodic box, and an inelastic gas of unequal disks between walls.
    #[test]
    fn many_ranks_as_threads_give_the_serial_hash() {
        for (boundary, restitution) in [(Boundary::Periodic, 1.0), (Boundary::Walls, 0.8)] {
            let mut spec = tall_gas(16);
            if let SceneSource::Gas(gas) = &mut spec.scene {
                gas.boundary = boundary;
                gas.physics = Physics::with_restitution(restitution);
                if restitution < 1.0 {
                    gas.radius = RadiusDistribution::Uniform { min: 0.6, max: 1.4 };
                    gas.mass = MassRule::Area;
                }
            }
            spec.method = MethodSpec::stepped(0.05, 100, Broadphase::Grid);
            let reference = serial::run(&spec).unwrap().summary;
            for ranks in [6, 8, 16, 64] {
                let summary = run_on_threads(&spec, ranks).summary;
                let case = format!("{boundary:?}, {ranks} ranks");
                assert_eq!(summary.state_hash, reference.state_hash, "{case}");
                assert_eq!(summary.pair_collisions, reference.pair_collisions, "{case}");
                assert_eq!(summary.max_overlap, reference.max_overlap, "{case}");
            }
        }
    }

    /// A gas `height` tall and 40 wide, at packing 0.3: at `height` = 100·P, a slab of
    /// the same size and as many disks (about 380) on every rank.
    fn tall_gas(n_ranks: usize) -> RunSpec {
        let (width, height) = (40.0, 100.0 * n_ranks as f64);
        let n_particles = (0.3 * width * height / std::f64::consts::PI) as usize;
        RunSpec {
            scene: SceneSource::Gas(GasSpec {
                extent: crate::sim::scene::Extent::Size { width, height },
                boundary: Boundary::Periodic,
                seed: 5,
                ..GasSpec::unit(n_particles, 0.3)
            }),
            method: MethodSpec::stepped(0.05, 400, Broadphase::Grid),
            slowdown: InjectedSlowdown::NONE,
        }
    }

    /// What a rank sends per step, by the [`Communicator`] docs' count, at the same
    /// disks per rank for 4 to 32 ranks. A step calls one small all-reduce (the step's
    /// summary: ⌈log₂ P⌉ messages) and sends to each of its peers, the two ranks
    /// beside: the halo with the reported escapees (1 message each), the shared
    /// contacts (1 each), and, on rebuild steps, the migrants (1 each). So without
    /// chains that reach past a peer, 4 to 6 messages besides the reduction, and bytes
    /// that do not grow with P: the mean over ranks within 10%, the busiest rank's
    /// within 30% of it (which rank is busiest varies with the gas).
    #[test]
    fn at_the_same_disks_per_rank_a_rank_sends_as_much_for_any_rank_count() {
        let mut mean_bytes = Vec::new();
        for ranks in [4, 8, 16, 32] {
            let summary = run_on_threads(&tall_gas(ranks), ranks).summary;
            let case = format!("{ranks} ranks: {summary}");
            assert_eq!(
                summary.collectives_per_step,
                Some(1.0),
                "no all-gather: {case}"
            );
            // The reduction: of 5 values, to ⌈log₂ P⌉ ranks.
            let partners = (ranks as f64).log2().ceil();
            let to_peers = summary.messages_per_step_max.unwrap() - partners;
            assert!((4.0..=6.0).contains(&to_peers), "{case}");
            // The first cut holds: no rank far above the mean, no cut again.
            assert!(summary.load_imbalance.unwrap() <= 1.15, "{case}");
            assert_eq!(summary.recuts, Some(0), "{case}");
            let [mean, max] = [summary.bytes_per_step_mean, summary.bytes_per_step_max]
                .map(|bytes| bytes.unwrap() - 5.0 * 8.0 * partners);
            assert!(max <= 1.3 * mean, "{case}");
            mean_bytes.push(mean);
        }
        let (least, most) =
            (mean_bytes.iter()).fold((f64::MAX, 0.0_f64), |(lo, hi), &b| (lo.min(b), hi.max(b)));
        assert!(most <= 1.1 * least, "mean bytes per step: {mean_bytes:?}");
    }

    /// A gas falling to the bottom of a tall box: the first cut, made for the gas spread
    /// over the box, would leave the lowest rank with most of the pile (over twice the
    /// mean, asserted from the serial run's last state). The ranks cut their slabs
    /// again as the disks fall, keep the busiest rank within 1.15 times the mean over
    /// the steps, and keep the serial bits.
    #[test]
    fn ranks_cut_their_slabs_again_as_a_gas_falls_into_a_pile() {
        let ranks = 4;
        let spec = RunSpec {
            scene: SceneSource::Gas(GasSpec {
                extent: crate::sim::scene::Extent::Size {
                    width: 10.0,
                    height: 600.0,
                },
                physics: Physics {
                    gravity: Some([0.0, -0.5]),
                    ..Physics::with_restitution(0.5)
                },
                seed: 3,
                ..GasSpec::unit(600, 0.0)
            }),
            method: MethodSpec::stepped(0.02, 2500, Broadphase::Grid),
            slowdown: InjectedSlowdown::NONE,
        };
        let (layout, first_cut) = first_slabs(&spec.prepare().unwrap(), ranks);
        let reference = serial::run(&spec).unwrap();
        let most_in_first_cut = (first_cut.iter())
            .map(|slab| {
                let last = reference.final_state.as_ref().unwrap();
                (last.y.iter())
                    .filter(|&&y| slab.contains(&layout.strip_of(y)))
                    .count()
            })
            .max()
            .unwrap();
        let mean = 600.0 / ranks as f64;
        assert!(
            most_in_first_cut as f64 > 2.0 * mean,
            "{most_in_first_cut} disks"
        );
        let summary = run_on_threads(&spec, ranks).summary;
        let case = format!("{summary}");
        assert_eq!(summary.state_hash, reference.summary.state_hash, "{case}");
        assert!(summary.recuts.unwrap() > 0, "{case}");
        let imbalance = summary.load_imbalance.unwrap();
        assert!((1.0..=1.15).contains(&imbalance), "{case}");
    }

    /// A pile on 16 ranks (disks placed on a lattice in a tall box, settled first by the
    /// serial run): the slabs, cut by the disks of each strip, hold at most 1.15 times
    /// the mean each, with the bits of the serial run.
    #[test]
    fn a_settled_pile_on_sixteen_ranks_is_shared_out_evenly() {
        let ranks = 16;
        let mut spec = RunSpec {
            scene: SceneSource::Gas(GasSpec {
                extent: crate::sim::scene::Extent::Size {
                    width: 10.0,
                    height: 1000.0,
                },
                placement: crate::sim::scene::Placement::Lattice,
                speed_rms: 0.1,
                physics: Physics {
                    gravity: Some([0.0, -0.05]),
                    ..Physics::with_restitution(0.5)
                },
                seed: 4,
                ..GasSpec::unit(1500, 0.0)
            }),
            method: MethodSpec::stepped(0.02, 6000, Broadphase::Grid),
            slowdown: InjectedSlowdown::NONE,
        };
        let settled = serial::run(&spec).unwrap().final_state.unwrap();
        let settled_top = settled.y.iter().fold(0.0_f64, |a, &b| a.max(b));
        let prepared = spec.prepare().unwrap();
        spec.scene = SceneSource::Explicit(crate::sim::Scene {
            particles: settled,
            ..prepared.scene
        });
        spec.method = MethodSpec::stepped(0.02, 20, Broadphase::Grid);
        let reference = serial::run(&spec).unwrap().summary;
        // A pile: every disk in the lower part of the box, the top third empty.
        let top = settled_top;
        assert!(top < 1000.0 * 2.0 / 3.0, "the highest disk at {top}");
        let summary = run_on_threads(&spec, ranks).summary;
        let case = format!("{summary}");
        assert_eq!(summary.state_hash, reference.state_hash, "{case}");
        let imbalance = summary.load_imbalance.unwrap();
        assert!((1.0..=1.15).contains(&imbalance), "{case}");
    }

    #[test]
    fn peers_are_mutual_and_the_ranks_beside_when_slabs_are_two_strips_or_more() {
        // Ten strips: slabs of 1, 1, 3 and 5 strips.
        let owner = [0, 1, 2, 2, 2, 3, 3, 3, 3, 3];
        let slabs = [0..1, 1..2, 2..5, 5..10];
        for periodic in [false, true] {
            let peers: Vec<Vec<usize>> = (0..4)
                .map(|me| peers_of(&owner, &slabs[me], periodic, me))
                .collect();
            for (a, theirs) in peers.iter().enumerate() {
                for &b in theirs {
                    assert!(peers[b].contains(&a), "{a} and {b}, periodic {periodic}");
                }
            }
            // Rank 1's slab is one strip: ranks 0 and 2 are two strips apart, peers.
            assert_eq!(peers[2], vec![0, 1, 3]);
            let wrapped = |walls: Vec<usize>, periodic_: Vec<usize>| match periodic {
                true => periodic_,
                false => walls,
            };
            assert_eq!(peers[0], wrapped(vec![1, 2], vec![1, 2, 3]));
            assert_eq!(peers[3], wrapped(vec![2], vec![0, 1, 2]));
        }
    }

    /// Ten columns of unit disks at rest, `rows` of them.
    struct Lattice {
        first: [f64; 2],
        spacing: [f64; 2],
        rows: usize,
    }

    /// A walled box of `size` holding `lattice` and unit disks moving up or down
    /// (`movers`: x, y, vy), stepped `steps` times by dt = 0.05.
    fn lattice_with_movers(
        lattice: Lattice,
        movers: &[[f64; 3]],
        size: [f64; 2],
        steps: u64,
    ) -> RunSpec {
        use crate::sim::Scene;
        use crate::sim::particles::Disk;
        use crate::sim::scene::Domain;
        let disk = |[x, y, vy]: [f64; 3]| Disk {
            x,
            y,
            vx: 0.0,
            vy,
            radius: 0.5,
            mass: 1.0,
        };
        let Lattice {
            first,
            spacing,
            rows,
        } = lattice;
        let at_rest = (0..10 * rows).map(|k| {
            let (column, row) = ((k % 10) as f64, (k / 10) as f64);
            [
                first[0] + spacing[0] * column,
                first[1] + spacing[1] * row,
                0.0,
            ]
        });
        let disks: Vec<Disk> = at_rest.chain(movers.iter().copied()).map(disk).collect();
        let scene = Scene {
            domain: Domain {
                width: size[0],
                height: size[1],
                boundary: Boundary::Walls,
            },
            physics: Physics::with_restitution(1.0),
            particles: Particles::from_disks(&disks),
        };
        RunSpec {
            scene: SceneSource::Explicit(scene),
            method: MethodSpec::stepped(0.05, steps, Broadphase::Grid),
            slowdown: InjectedSlowdown::NONE,
        }
    }

    /// A fast disk of one rank's slab, two strips above the boundary, escapes the lists
    /// and meets a slow disk of the rank below before the lists are rebuilt. Neither
    /// rank's list holds the pair, and neither rank holds both disks: only the escapee's
    /// report to the rank below finds it, as the serial stepper's query does.
    #[test]
    fn an_escapee_meets_a_disk_of_the_rank_below_as_in_the_serial_run() {
        // Disks at rest on the left, so that the escapee is one of few (the lists then
        // serve it by queries); skin 12·|v|·dt = 0.6, strips 1.6 tall; the ranks meet
        // at y = 19.2, with the slow disk in the strip below and the fast one in the
        // second strip above.
        let spec = lattice_with_movers(
            Lattice {
                first: [1.5, 1.5],
                spacing: [2.0, 3.8],
                rows: 10,
            },
            &[[30.0, 19.1, 0.45], [30.0, 20.9, -1.0]],
            [40.0, 40.0],
            20,
        );
        let reference = serial::run(&spec).unwrap().summary;
        assert_eq!(reference.pair_collisions, 1, "the two disks meet");
        let summary = run_on_threads(&spec, 2).summary;
        assert_eq!(summary.pair_collisions, 1);
        assert_eq!(summary.state_hash, reference.state_hash);
    }

    /// A disk that crosses a slab or more per step: its first step is unforeseen (it
    /// moved further than queries serve, and the ranks find the contacts again on
    /// rebuilt lists), and at the rebuilds after it, it leaves for a rank that is not a
    /// peer (held back, then sent in an exchange with every rank). The bits stay the
    /// serial run's; the second looks show as collectives beyond one per step.
    #[test]
    fn a_disk_that_crosses_slabs_in_a_step_gives_the_serial_hash() {
        // Off the lattice's columns: it bounces between the walls, 15 a step, until a
        // wall sends it into a disk.
        let spec = lattice_with_movers(
            Lattice {
                first: [1.0, 1.0],
                spacing: [2.0, 4.0],
                rows: 16,
            },
            &[[20.5, 30.0, 300.0]],
            [22.0, 64.0],
            60,
        );
        let reference = serial::run(&spec).unwrap().summary;
        for ranks in [2, 16] {
            let summary = run_on_threads(&spec, ranks).summary;
            assert_eq!(summary.state_hash, reference.state_hash, "{ranks} ranks");
            let steps = summary.steps as f64;
            let collectives = summary.collectives_per_step.unwrap() * steps;
            let recuts = summary.recuts.unwrap() as f64;
            assert!(
                collectives > steps + 2.0 * recuts,
                "{ranks} ranks: {summary}"
            );
        }
    }

    /// No rank holds more than its share of the disks, set-up included: each rank
    /// places only its own bands (64 of them here) and then hands the disks to the
    /// ranks whose slabs hold them.
    #[test]
    fn no_rank_holds_more_than_its_share_of_the_disks_at_set_up() {
        let n = 270_000;
        let spec = RunSpec {
            scene: SceneSource::Gas(GasSpec::unit(n, 0.05)),
            method: MethodSpec::stepped(0.05, 1, Broadphase::Grid),
            slowdown: InjectedSlowdown::NONE,
        };
        for ranks in [2, 4, 8, 16] {
            let held = run_on_threads(&spec, ranks)
                .summary
                .setup_disks_max
                .unwrap();
            let share = n as f64 / ranks as f64;
            assert!(
                held as f64 <= 1.25 * share,
                "{ranks} ranks: a rank held {held} disks, {:.3}× its share",
                held as f64 / share
            );
        }
    }

    /// The strips of `prepared`'s run and the slabs set-up cuts them into for `ranks`.
    fn first_slabs(prepared: &PreparedRun, ranks: usize) -> (StripLayout, Vec<Range<usize>>) {
        let (scene, dt) = (&prepared.scene, prepared.params.dt);
        let skin = Skin::for_scene(&scene.domain, &scene.particles, dt);
        let layout = StripLayout::with_skin(&scene.domain, &scene.particles, skin.width());
        let mut per_strip = vec![0; layout.n_strips];
        for &y in &scene.particles.y {
            per_strip[layout.strip_of(y)] += 1;
        }
        let slabs = cut_slabs(&per_strip, ranks);
        (layout, slabs)
    }

    #[test]
    fn more_ranks_than_strips_is_refused_with_the_limit() {
        let spec = spec(Boundary::Walls, 1.0, 0.05);
        let (layout, cut) = first_slabs(&spec.prepare().unwrap(), 3);
        assert_eq!((cut[0].start, cut[2].end), (0, layout.n_strips));
        assert!(
            cut.windows(2)
                .all(|w| w[0].end == w[1].start && !w[1].is_empty())
        );
        let spec = &spec;
        let errors = ThreadComm::run_group(layout.n_strips + 1, |comm| {
            let refused = run(&comm, spec, FinalState::Summed, NonZeroUsize::MIN).err();
            refused.expect("refused").to_string()
        });
        assert!(
            errors.iter().all(|error| error.contains("use at most")),
            "{errors:?}"
        );
    }
}
