//! Backends: drivers that run a prepared scene with the pure core and time it.
//!
//! The serial backend is the reference; the threaded (rayon) and distributed (MPI)
//! backends must reproduce its `state_hash` bit for bit.

mod bands;
pub mod comm;
pub mod distributed;
#[cfg(feature = "mpi")]
pub mod launcher;
#[cfg(feature = "mpi")]
pub mod mpi;
pub mod serial;
mod setup;
mod shared;
pub mod team;
pub mod threads;

use std::num::NonZeroUsize;
use std::ops::ControlFlow;
use std::time::Instant;

use crate::backend::comm::RankTraffic;
use crate::run::backend_kind::BackendKind;
use crate::run::spec::{InjectedSlowdown, Method, PreparedRun};
use crate::run::summary::RunSummary;
use crate::sim::observe::{
    Block, Observables, StateSums, Thermodynamics, ends_interval, thermodynamics,
};
use crate::sim::scene::PlacementError;
use crate::sim::{Boundary, Particles, StepCounters};
use crate::stats::observables::analyse;
use crate::stats::reference::hard_disk_z;
pub use crate::system::machine::{CpuScope, timed};
use crate::system::machine::{LoopSeconds, cpu_seconds, usable_cpus};

/// Which backend runs the steps, with its worker count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackendSpec {
    Serial,
    /// A rayon pool of exactly this many threads, built for the run.
    Rayon {
        threads: NonZeroUsize,
    },
    /// MPI ranks: launched by collide itself (`Some`), or taken from the MPI world when
    /// collide already runs under `mpirun` (`None`); each steps on `threads` threads
    /// (`None`: as the rank's environment says, else one).
    Mpi {
        ranks: Option<NonZeroUsize>,
        threads: Option<NonZeroUsize>,
    },
}

#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    #[error(transparent)]
    Placement(#[from] PlacementError),
    #[error("cannot start a pool of {threads} threads: {source}")]
    ThreadPool {
        threads: usize,
        source: rayon::ThreadPoolBuildError,
    },
    #[error("{0}")]
    Mpi(String),
}

/// What a run leaves behind: its summary and the final state (for `--dump`), which an
/// MPI run gathers only when asked.
#[derive(Clone, Debug)]
pub struct RunOutcome {
    pub summary: RunSummary,
    pub final_state: Option<Particles>,
}

/// Seconds spent in each stage of the stepping loop, summed over the steps.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageSeconds {
    /// Moving the disks and applying the boundary.
    pub integration: f64,
    /// Building the grid and finding (and ordering) the overlapping pairs.
    pub broad_phase: f64,
    /// Applying the impulse law to the pairs.
    pub collisions: f64,
    /// Exchanging disks and results between ranks (MPI only).
    pub communication: f64,
}

/// The stepping loop every backend times: `step(1)` to `step(steps)`, each followed by
/// the injected extra work (none in real runs). A step returning `Break` ends the loop
/// after it (the event method at a detected collapse).
///
/// The extra work is integer arithmetic on the calling thread, counted on the clock that
/// `collide check` judges, the wall clock: after each step it runs until the wall time
/// has grown by `fraction` of what the step itself took. A fraction of 0.1 therefore
/// makes the loop's wall time 10% larger on every backend (on the parallel ones the
/// other threads or ranks wait meanwhile, as behind a serialised stage); what one step
/// overshoots, the next one owes less. `scope` is the CPU time the loop reports.
pub fn step_loop(
    steps: u64,
    slowdown: InjectedSlowdown,
    scope: CpuScope,
    mut step: impl FnMut(u64) -> ControlFlow<()>,
) -> LoopSeconds {
    let fraction = slowdown.fraction();
    let cpu_start = cpu_seconds(scope);
    let loop_start = Instant::now();
    if fraction > 0.0 {
        let clock = || loop_start.elapsed().as_secs_f64();
        let mut owed = 0.0;
        for number in 1..=steps {
            let before = clock();
            let flow = step(number);
            let mut now = clock();
            owed += fraction * (now - before);
            while owed > 0.0 {
                busy_rounds(BUSY_ROUNDS);
                let later = clock();
                owed -= later - now;
                now = later;
            }
            if flow.is_break() {
                break;
            }
        }
    } else {
        for number in 1..=steps {
            if step(number).is_break() {
                break;
            }
        }
    }
    let wall = loop_start.elapsed().as_secs_f64();
    let cpu = cpu_seconds(scope)
        .zip(cpu_start)
        .map(|(end, start)| end - start);
    LoopSeconds { wall, cpu }
}

/// Rounds of injected work between two looks at the clock (a few microseconds).
const BUSY_ROUNDS: u64 = 2000;

/// Integer work that touches no memory of the simulation.
fn busy_rounds(rounds: u64) {
    let mut x = 1_u64;
    for _ in 0..rounds {
        x = std::hint::black_box(x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1));
    }
}

/// Where a run's workers went: the backend and its threads and ranks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Workers {
    pub backend: BackendKind,
    pub threads: usize,
    pub ranks: usize,
}

/// What the stepping loop measured, for [`summarize`].
#[derive(Clone, Debug)]
pub struct Measured {
    pub setup_s: f64,
    pub wall_s: f64,
    /// CPU seconds of the stepping loop, summed over threads and ranks.
    pub cpu_s: Option<f64>,
    pub stages: StageSeconds,
    pub counters: StepCounters,
    pub initial: Observables,
    pub accuracy: Accuracy,
    /// Seconds drawing every step offscreen (`draw = true`), outside `wall_s`; `None`
    /// when the run did not draw.
    pub draw_s: Option<f64>,
    /// What the ranks sent in the stepping loop (MPI only).
    pub traffic: Option<RankTraffic>,
    /// How evenly the ranks held the disks (MPI only).
    pub balance: Option<Balance>,
}

/// How evenly the ranks of a run held the disks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Balance {
    /// The most disks a rank held over the mean over ranks, averaged over the steps.
    pub imbalance: f64,
    /// Times the ranks cut their slabs again during the stepping loop.
    pub recuts: u64,
    /// The most disks a rank held during set-up (placed, or in its slab).
    pub setup_disks_max: u64,
}

/// What a backend observed beyond the counters; `None` where it does not observe it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Accuracy {
    /// Missed collisions (exact swept test; 0 for the event method).
    pub missed_collisions: Option<u64>,
    /// Event method: collisions the TC model made elastic, and its time.
    pub collapse_guard: Option<(u64, f64)>,
    /// Event method: the inelastic collapse that ended the run early.
    pub collapse: Option<Collapse>,
    /// [t, kinetic energy per disk] at t = 0 and at up to [`CURVE_SAMPLES`] steps.
    pub temperature_curve: Option<Vec<[f64; 2]>>,
    /// The run's observables in up to `SERIES_BLOCKS` blocks (serial, rayon and MPI: the
    /// same bits).
    pub series: Option<Vec<Block>>,
}

/// Where a run of the event method stopped at a detected inelastic collapse.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Collapse {
    /// The simulated time of the collapse (where the state was left).
    pub time: f64,
    /// Intervals of dt stepped, the last one the interval the collapse fell in.
    pub steps: u64,
}

/// Samples of the temperature curve after t = 0.
pub const CURVE_SAMPLES: u64 = 40;

/// The steps after which the temperature curve is sampled: up to [`CURVE_SAMPLES`],
/// evenly spread, the last one the final step.
pub fn is_curve_sample(step: u64, steps: u64) -> bool {
    ends_interval(step, steps, CURVE_SAMPLES)
}

/// The summary of a finished run; `last` holds the sums over every disk of the final
/// state (taken in the scene's field), however they were divided.
pub fn summarize(
    prepared: &PreparedRun,
    workers: Workers,
    measured: &Measured,
    last: &StateSums,
) -> RunSummary {
    let outcome = Outcome::of(prepared, measured, last);
    let (steps, wall_s) = (outcome.steps, measured.wall_s);
    let accuracy = &measured.accuracy;
    let counters = &measured.counters;
    let per_step = |total: f64| (steps > 0).then(|| total / steps as f64);
    let traffic = measured.traffic.as_ref();
    RunSummary {
        n: outcome.n,
        steps,
        dt: prepared.params.dt,
        dt_auto_fraction: prepared.dt_auto_fraction,
        backend: workers.backend.name().to_owned(),
        workers: workers.threads * workers.ranks,
        threads: workers.threads,
        ranks: workers.ranks,
        oversubscribed: workers.threads * workers.ranks > usable_cpus(),
        boundary: prepared.scene.domain.boundary.name().to_owned(),
        broadphase: prepared.params.broadphase.name().to_owned(),
        packing: prepared.initial.packing,
        seed: prepared.seed,
        wall_s,
        cpu_s: measured.cpu_s,
        setup_s: measured.setup_s,
        fps: steps as f64 / wall_s,
        draw_s: measured.draw_s,
        fps_with_drawing: measured
            .draw_s
            .map(|draw_s| steps as f64 / (wall_s + draw_s)),
        particle_steps_per_s: (outcome.n as f64 * steps as f64) / wall_s,
        integration_s: measured.stages.integration,
        broad_phase_s: measured.stages.broad_phase,
        collision_s: measured.stages.collisions,
        communication_s: measured.stages.communication,
        messages_per_step_max: traffic.and_then(|t| per_step(t.messages_max as f64)),
        messages_per_step_mean: traffic.and_then(|t| per_step(t.messages_mean)),
        bytes_per_step_max: traffic.and_then(|t| per_step(t.bytes_max as f64)),
        bytes_per_step_mean: traffic.and_then(|t| per_step(t.bytes_mean)),
        collectives_per_step: traffic.and_then(|t| per_step(t.collectives as f64)),
        load_imbalance: measured.balance.map(|balance| balance.imbalance),
        recuts: measured.balance.map(|balance| balance.recuts),
        setup_disks_max: measured.balance.map(|balance| balance.setup_disks_max),
        kinetic_energy_initial: measured.initial.kinetic_energy,
        kinetic_energy_final: outcome.last.kinetic_energy,
        momentum_initial: measured.initial.momentum,
        momentum_final: outcome.last.momentum,
        pair_collisions: measured.counters.pair_collisions,
        wall_collisions: measured.counters.wall_collisions,
        max_overlap: measured.counters.max_overlap,
        max_wall_penetration: measured.counters.max_wall_penetration,
        state_hash: last.state_hash(),
        method: prepared.method.name().to_owned(),
        observe: prepared.observe.name().to_owned(),
        events_per_s: outcome
            .is_event
            .then(|| (counters.pair_collisions + counters.wall_collisions) as f64 / wall_s),
        missed_collisions: outcome.missed,
        missed_collision_fraction: missed_fraction(outcome.missed, counters.pair_collisions),
        mean_overlap: (counters.pair_collisions > 0)
            .then(|| counters.overlap_sum / counters.pair_collisions as f64),
        energy_relative_error: outcome.energy_relative_error,
        collapse_guard_fired: outcome.collapse_guard.map(|(fired, _)| fired),
        collapse_tc: outcome.collapse_guard.map(|(_, tc)| tc),
        collapse_time: accuracy.collapse.map(|collapse| collapse.time),
        time_reached: Some(outcome.duration),
        tc: outcome.is_event.then_some(prepared.event.tc),
        temperature_curve: accuracy.temperature_curve.clone(),
        rms_step_over_radius: rms_step_over_radius(prepared),
        choice: prepared.choice.clone(),
        ..observed_summary(prepared, measured, &outcome, last)
    }
}

/// The summary's observables: from the run's block series after the equilibration cut
/// where the backend recorded one and the run settled, else from t = 0 (flagged: not
/// equilibrated), else from the counters; with their error bars and the reference Z.
fn observed_summary(
    prepared: &PreparedRun,
    measured: &Measured,
    outcome: &Outcome,
    last: &StateSums,
) -> RunSummary {
    let counters = &measured.counters;
    let observed = (measured.accuracy.series.as_deref())
        .and_then(|blocks| analyse(blocks, outcome.n, prepared.discard));
    let production = observed.and_then(|o| o.settled);
    let means = production.or(observed.map(|o| o.from_zero));
    let area = prepared.scene.domain.area();
    let reference = hard_disk_fluid(prepared, last)
        .then(|| hard_disk_z(prepared.initial.packing))
        .flatten();
    RunSummary {
        collision_rate: means.map(|p| p.collision_rate.mean).or(Some(
            2.0 * counters.pair_collisions as f64 / (outcome.n.max(1) as f64 * outcome.duration),
        )),
        temperature: means
            .map(|p| p.temperature.mean)
            .or(Some(outcome.thermo.temperature)),
        pressure: means
            .map(|p| p.compressibility_z.mean * outcome.n as f64 * p.temperature.mean / area)
            .or(Some(outcome.thermo.pressure)),
        compressibility_z: means
            .map(|p| p.compressibility_z.mean)
            .or(outcome.thermo.compressibility_z),
        equilibrated: observed.map(|o| o.settled.is_some()),
        equilibration_cut: observed.map(|o| o.discard.rule().to_owned()),
        equilibration_cut_time: production.map(|p| p.cut_time),
        equilibration_mser5_cut_time: observed.and_then(|o| o.mser5_cut_time),
        compressibility_z_from_zero: observed.map(|o| o.from_zero.compressibility_z.mean),
        compressibility_z_se: production.map(|p| p.compressibility_z.se),
        compressibility_z_g: production.map(|p| p.compressibility_z.g),
        compressibility_z_n_eff: production.map(|p| p.compressibility_z.n_eff()),
        compressibility_z_plateau: production.map(|p| p.compressibility_z.plateau),
        collision_rate_se: production.map(|p| p.collision_rate.se),
        collision_rate_g: production.map(|p| p.collision_rate.g),
        temperature_se: production.map(|p| p.temperature.se),
        temperature_g: production.map(|p| p.temperature.g),
        z_reference: reference.map(|r| r.z),
        z_reference_se: reference.map(|r| r.se),
        z_reference_source: reference.map(|r| r.source.to_owned()),
        ..RunSummary::default()
    }
}

/// What a finished run reached, derived once for the summary's fields.
struct Outcome {
    n: usize,
    /// Steps done: as asked, or fewer where a detected collapse ended the run early.
    steps: u64,
    /// The simulated time the state reached.
    duration: f64,
    last: Observables,
    thermo: Thermodynamics,
    is_event: bool,
    missed: Option<u64>,
    /// Collisions the TC guard made elastic, and its time.
    collapse_guard: Option<(u64, f64)>,
    energy_relative_error: Option<f64>,
}

impl Outcome {
    fn of(prepared: &PreparedRun, measured: &Measured, last: &StateSums) -> Outcome {
        let n = last.disks as usize;
        let accuracy = &measured.accuracy;
        let (steps, duration) = match accuracy.collapse {
            Some(collapse) => (collapse.steps, collapse.time),
            None => (prepared.steps, prepared.steps as f64 * prepared.params.dt),
        };
        let physics = &prepared.scene.physics;
        let last_potential = last.potential_energy();
        let last = last.observables();
        let initial_energy = measured.initial.kinetic_energy;
        let thermo = thermodynamics(
            n,
            prepared.scene.domain.area(),
            duration,
            measured.counters.virial,
            accuracy.temperature_curve.as_deref(),
            [initial_energy, last.kinetic_energy],
        );
        let is_event = prepared.method == Method::Event;
        Outcome {
            n,
            steps,
            duration,
            thermo,
            is_event,
            // The event method finds every collision: it misses none by construction.
            missed: is_event.then_some(0).or(accuracy.missed_collisions),
            // The TC guard matters only where collisions lose energy.
            collapse_guard: accuracy
                .collapse_guard
                .filter(|_| physics.restitution < 1.0),
            energy_relative_error: conserved_energy_error(
                prepared,
                [initial_energy, last.kinetic_energy],
                last_potential,
            ),
            last,
        }
    }
}

/// Whether the run is the fluid the reference equations of state describe: equal
/// elastic disks in a periodic box without a field.
fn hard_disk_fluid(prepared: &PreparedRun, last: &StateSums) -> bool {
    let scene = &prepared.scene;
    scene.domain.boundary == Boundary::Periodic
        && scene.physics.is_elastic()
        && scene.physics.gravity.is_none()
        && last.max_radius == prepared.initial.min_radius
}

/// (E_final − E_initial)/E_initial of the energy a scene should conserve: kinetic plus,
/// in a field, potential energy. `None` where it need not be conserved: collisions that
/// lose energy, or a field in a periodic box, where a disk crossing the edge jumps in
/// height; and where E_initial is not positive.
fn conserved_energy_error(
    prepared: &PreparedRun,
    [initial_kinetic, last_kinetic]: [f64; 2],
    last_potential: f64,
) -> Option<f64> {
    let scene = &prepared.scene;
    let field_in_periodic_box =
        scene.physics.gravity.is_some() && scene.domain.boundary == Boundary::Periodic;
    let initial = initial_kinetic + prepared.initial.potential_energy;
    (scene.physics.is_elastic() && !field_in_periodic_box && initial > 0.0)
        .then(|| (last_kinetic + last_potential - initial) / initial)
}

/// Missed collisions as a fraction of all that should have happened; `None` when
/// unknown or when there were none.
fn missed_fraction(missed: Option<u64>, pair_collisions: u64) -> Option<f64> {
    missed
        .filter(|m| m + pair_collisions > 0)
        .map(|m| m as f64 / (m + pair_collisions) as f64)
}

/// How far the rms disk moves per step, in smallest radii; `None` for a state at rest.
fn rms_step_over_radius(prepared: &PreparedRun) -> Option<f64> {
    let step = prepared.initial.rms_speed * prepared.params.dt;
    (step > 0.0).then(|| step / prepared.initial.min_radius)
}
