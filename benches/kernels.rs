//! Criterion benches of the simulator's kernels: one full serial step (and, as a
//! yardstick, one step of a skilled cell-list code: `yardstick/mod.rs`) at N = 100,000
//! (the stages of a step are not benched apart: the neighbour lists make a step's broad
//! phase depend on the steps before it; `collide simulate` reports each stage's time
//! over a run); one full step
//! of the serial and the rayon (2 threads) backends and of the yardstick at N = 1,000,000;
//! and one step of the distributed backend on 2 ranks as threads (`ThreadComm`) at
//! N = 100,000, through the same stepping loop (`backend::step_loop`) that
//! `collide simulate` and `collide check` time. Each for a dilute and a dense gas.
//!
//! Throughput is in disks per iteration, so criterion's "elem/s" is particle-steps per second;
//! in the `event` group it is collisions (pair and wall) per second of the event-driven
//! method. The `step` and `event` groups run both methods on the same periodic gases at
//! N = 10^4, 10^5 and 10^6: they are the cost model of `method = "auto"`. The
//! `event_walls` group runs the event method on the walled lattice gases of issue 54
//! (N = 10^5 and 10^6, packings 0.3, 0.5 and 0.7).
//! Run: `cargo bench --bench kernels` (MPI runs need `mpirun`: see `docs/performance.md`).
//! Before it is timed, the yardstick is checked against our step: same energy (elastic
//! gas) and the same number of pair impulses, to 0.5%, after the same 50 steps.
//! `COLLIDE_YARDSTICK_ONLY=1 cargo bench --bench kernels` prints only the yardstick's rate
//! (particle-steps per second of 50 steps, by wall time and by the thread's CPU time)
//! at N = 10^5 and 10^6 (or the comma-separated sizes of `COLLIDE_YARDSTICK_SIZES`),
//! packings 0.05 and 0.3, on the scenes `collide simulate` builds from a scene file with
//! n, packing, radius = 1, mass = 1, speed_rms = 1, boundary = "walls", restitution = 1,
//! seed = 42 and dt = 0.1.

use std::time::{Duration, Instant};

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group};

use collide::backend::comm::ThreadComm;
use collide::backend::distributed::{self, FinalState};
use collide::backend::team::with_team;
use collide::backend::threads::ThreadedStepper;
use collide::run::spec::{InjectedSlowdown, MethodSpec, RunSpec, SceneSource};
use collide::sim::event::{EventParams, EventSim};
use collide::sim::scene::{GasSpec, Placement};
use collide::sim::{Boundary, Broadphase, Particles, Scene, StepParams, Stepper};
use collide::system::machine::{CpuScope, cpu_seconds};

mod yardstick;
use yardstick::CellListYardstick;

/// r = 1 and v_rms = 1 stepped with dt = 0.1, so v_rms·dt = 0.1·r.
const PARAMS: StepParams = StepParams {
    dt: 0.1,
    broadphase: Broadphase::Grid,
};
const WARM_UP_STEPS: usize = 50;
/// The yardstick's name in the `serial` and `step_1e6` groups.
const YARDSTICK: &str = "cell_list_yardstick";

fn gas_spec(n_particles: usize, packing: f64) -> GasSpec {
    GasSpec {
        seed: 42,
        ..GasSpec::unit(n_particles, packing)
    }
}

fn gas(n_particles: usize, packing: f64) -> Scene {
    gas_spec(n_particles, packing)
        .build()
        .expect("packings below jamming place")
}

/// The scene's disks after the warm-up steps of a serial stepper, and that stepper.
fn warmed_up_serial(scene: &Scene) -> (Particles, Stepper) {
    let mut particles = scene.particles.clone();
    let mut stepper = Stepper::for_scene(scene, PARAMS);
    for _ in 0..WARM_UP_STEPS {
        stepper.step(&mut particles);
    }
    (particles, stepper)
}

/// The yardstick for `scene`, checked against our serial stepper after the same
/// [`WARM_UP_STEPS`] from the same scene (`ours`, not stepped since): the yardstick must conserve energy
/// (the gas is elastic) and apply about as many pair impulses as we do (the order of
/// impulses differs, so the trajectories do too, not the collision rate). The counts
/// agree to 0.03% on the bench's gases; a sweep that skips the east cell, or the three
/// cells above, applies 5% fewer impulses at packing 0.05: the bound of 0.5% catches it.
fn checked_yardstick(scene: &Scene, ours: &Stepper) -> CellListYardstick {
    let mut yardstick = CellListYardstick::new(scene, PARAMS.dt);
    let energy_before = yardstick.kinetic_energy();
    for _ in 0..WARM_UP_STEPS {
        yardstick.step();
    }
    let drift = (yardstick.kinetic_energy() / energy_before - 1.0).abs();
    assert!(
        drift < 1e-9,
        "the yardstick changed the energy by {drift:e}"
    );
    let (theirs, ours) = (
        yardstick.pair_impulses() as f64,
        ours.counters().pair_collisions as f64,
    );
    assert!(
        (theirs / ours - 1.0).abs() < 0.005,
        "the yardstick applied {theirs} pair impulses, our stepper {ours}"
    );
    eprintln!(
        "yardstick checked: {} disks, {WARM_UP_STEPS} steps, energy drift {drift:.1e}, \
         {theirs} pair impulses against our {ours}",
        scene.particles.len()
    );
    yardstick
}

fn serial_kernels(c: &mut Criterion) {
    const N: usize = 100_000;
    let mut group = c.benchmark_group("serial");
    group.throughput(Throughput::Elements(N as u64));
    group.sample_size(30);
    for packing in [0.05, 0.3] {
        let scene = gas(N, packing);
        let (mut particles, mut stepper) = warmed_up_serial(&scene);
        let mut yardstick = checked_yardstick(&scene, &stepper);
        group.bench_function(BenchmarkId::new("step", packing), |b| {
            b.iter(|| stepper.step(&mut particles));
        });
        group.bench_function(BenchmarkId::new(YARDSTICK, packing), |b| {
            b.iter(|| yardstick.step());
        });
    }
    group.finish();
}

/// One step of the serial reference and of the rayon backend on 2 threads, measured in
/// the same run so that their ratio is the speedup.
fn backend_steps(c: &mut Criterion) {
    const N: usize = 1_000_000;
    let mut group = c.benchmark_group("step_1e6");
    group.throughput(Throughput::Elements(N as u64));
    group.sample_size(10);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("a pool of 2 threads");
    for packing in [0.05, 0.3] {
        let scene = gas(N, packing);
        let (mut particles, mut stepper) = warmed_up_serial(&scene);
        let mut yardstick = checked_yardstick(&scene, &stepper);
        group.bench_function(BenchmarkId::new("serial", packing), |b| {
            b.iter(|| stepper.step(&mut particles));
        });
        group.bench_function(BenchmarkId::new(YARDSTICK, packing), |b| {
            b.iter(|| yardstick.step());
        });
        let mut particles = scene.particles.clone();
        let mut threaded = ThreadedStepper::new(scene.domain, scene.physics, PARAMS, &particles, 2);
        pool.install(|| {
            with_team(|team| {
                for _ in 0..WARM_UP_STEPS {
                    threaded.step(&mut particles, team);
                }
            })
        });
        // One team for each batch of steps, as `collide simulate` has one for its run.
        group.bench_function(BenchmarkId::new("rayon_2_threads", packing), |b| {
            b.iter_custom(|steps| {
                pool.install(|| {
                    with_team(|team| {
                        let start = Instant::now();
                        for _ in 0..steps {
                            threaded.step(&mut particles, team);
                        }
                        start.elapsed()
                    })
                })
            });
        });
    }
    group.finish();
}

/// The cost model of `method = "auto"` (`collide::run::auto::MEASURED`): both methods on the
/// same periodic gases of unit disks at N = 10⁴, 10⁵ and 10⁶, packing 0.05 and 0.3, in
/// one run. `step/…` is one serial step (elem/s: particle-steps per second); `event/n…`
/// processes a fixed number of collisions (pair and wall) after a warm-up of one
/// collision per disk (elem/s: collisions per second on one core; cell crossings are
/// work, not counted); `event/observe_n…` writes the state out, as every dt of a run
/// does, between bursts of collisions (elem/s: disks per second).
fn cost_model(c: &mut Criterion) {
    const COLLISIONS: u64 = 100_000;
    const SIZES: [usize; 3] = [10_000, 100_000, 1_000_000];
    let periodic_gas = |n: usize, packing: f64| {
        GasSpec {
            seed: 42,
            boundary: Boundary::Periodic,
            ..GasSpec::unit(n, packing)
        }
        .build()
        .expect("packings below jamming place")
    };
    let mut group = c.benchmark_group("step");
    group.sample_size(10);
    for n in SIZES {
        group.throughput(Throughput::Elements(n as u64));
        for packing in [0.05, 0.3] {
            let (mut particles, mut stepper) = warmed_up_serial(&periodic_gas(n, packing));
            group.bench_function(BenchmarkId::new(format!("n{n}"), packing), |b| {
                b.iter(|| stepper.step(&mut particles));
            });
        }
    }
    group.finish();
    let mut group = c.benchmark_group("event");
    group.sample_size(10);
    group.throughput(Throughput::Elements(COLLISIONS));
    let mut runs = Vec::new();
    for n in SIZES {
        for packing in [0.05, 0.3] {
            let scene = periodic_gas(n, packing);
            let params = EventParams { tc: 0.0 };
            let mut sim = EventSim::new(scene.domain, scene.physics, params, &scene.particles);
            sim.advance_collisions(n as u64);
            group.bench_function(BenchmarkId::new(format!("n{n}"), packing), |b| {
                b.iter(|| sim.advance_collisions(COLLISIONS));
            });
            runs.push((n, packing, sim, scene.particles));
        }
    }
    // Observing the state (every dt of a run): all disks brought to the current time
    // and written out; elem/s is disks per second. Timed alone, but after N/100
    // collisions each time (untimed), so that the state is out of the caches as in a
    // run: runs at v_rms·dt/r ≈ 0.04 bring N/600 (packing 0.05) to N/70 (0.3) per step.
    group.measurement_time(Duration::from_secs(2));
    for (n, packing, mut sim, mut particles) in runs {
        group.throughput(Throughput::Elements(n as u64));
        group.bench_function(BenchmarkId::new(format!("observe_n{n}"), packing), |b| {
            b.iter_custom(|observations| {
                let mut observing = Duration::ZERO;
                for _ in 0..observations {
                    sim.advance_collisions(n as u64 / 100);
                    let start = Instant::now();
                    sim.advance_to(&mut particles, sim.time());
                    observing += start.elapsed();
                }
                observing
            });
        });
    }
    group.finish();
}

/// One step of the distributed backend on 2 ranks that are threads of this process
/// (`ThreadComm` instead of MPI): each sample is one run of as many steps as criterion
/// asks for, timed by the run's own stepping loop (`wall_s`, the slowest rank), so the
/// set-up of the ranks is left out.
fn distributed_step(c: &mut Criterion) {
    const N: usize = 100_000;
    const RANKS: usize = 2;
    let mut group = c.benchmark_group("distributed_step");
    group.throughput(Throughput::Elements(N as u64));
    group.sample_size(10);
    for packing in [0.05, 0.3] {
        group.bench_function(BenchmarkId::new("2_ranks_as_threads", packing), |b| {
            b.iter_custom(|steps| {
                let spec = RunSpec {
                    scene: SceneSource::Gas(gas_spec(N, packing)),
                    method: MethodSpec::stepped(PARAMS.dt, steps.max(1), PARAMS.broadphase),
                    slowdown: InjectedSlowdown::NONE,
                };
                let spec = &spec;
                // One thread per rank: the ranks are the bench's threads.
                let outcomes = ThreadComm::run_group(RANKS, |comm| {
                    let one_thread = std::num::NonZeroUsize::MIN;
                    distributed::run(&comm, spec, FinalState::Summed, one_thread)
                });
                let wall_s = (outcomes.into_iter())
                    .find_map(|outcome| outcome.expect("placed"))
                    .expect("rank 0 reports")
                    .summary
                    .wall_s;
                Duration::from_secs_f64(wall_s)
            });
        });
    }
    group.finish();
}

/// The yardstick's rate outside criterion, for comparing with `collide simulate --json`
/// on the same scenes: for N = 10⁵ and 10⁶ and packings 0.05 and 0.3, the median of 3
/// runs of [`TIMED_STEPS`] steps (wall time, and the thread's CPU time, which a loaded
/// machine inflates less), each from the placed scene after [`UNTIMED_STEPS`] steps.
fn yardstick_rates() {
    const UNTIMED_STEPS: usize = 10;
    const TIMED_STEPS: usize = 50;
    let sizes: Vec<usize> = match std::env::var("COLLIDE_YARDSTICK_SIZES") {
        Ok(sizes) => sizes
            .split(',')
            .map(|n| {
                n.trim().parse().unwrap_or_else(|_| {
                    panic!(
                        "COLLIDE_YARDSTICK_SIZES: `{n}` is not a disk count (e.g. 100000,1000000)"
                    )
                })
            })
            .collect(),
        Err(_) => vec![100_000, 1_000_000],
    };
    println!("yardstick N packing steps rate_M/s cpu_rate_M/s");
    for n in sizes {
        for packing in [0.05, 0.3] {
            let scene = gas(n, packing);
            let particle_steps = (n * TIMED_STEPS) as f64;
            let (mut wall_s, mut cpu_s): (Vec<f64>, Vec<f64>) = (0..3)
                .map(|_| {
                    let mut yardstick = CellListYardstick::new(&scene, PARAMS.dt);
                    for _ in 0..UNTIMED_STEPS {
                        yardstick.step();
                    }
                    let (start, cpu_start) = (Instant::now(), thread_cpu_s());
                    for _ in 0..TIMED_STEPS {
                        yardstick.step();
                    }
                    (start.elapsed().as_secs_f64(), thread_cpu_s() - cpu_start)
                })
                .unzip();
            wall_s.sort_by(f64::total_cmp);
            cpu_s.sort_by(f64::total_cmp);
            println!(
                "yardstick {n} {packing} {TIMED_STEPS} {:.1} {:.1}",
                particle_steps / wall_s[1] / 1e6,
                particle_steps / cpu_s[1] / 1e6
            );
        }
    }
}

/// Issue 54's figure: the event method on the walled lattice gases `collide simulate
/// SCENE --method event --n N --packing P` starts from with `placement = "lattice"` (unit
/// disks, v_rms = 1, elastic), at N = 10⁵ and 10⁶ and packings 0.3, 0.5 and 0.7. Each
/// sample processes [`COLLISIONS`] collisions (pair and wall; walls are under 1% of them)
/// after a warm-up of one per disk; elem/s is collisions per second on one core (stale
/// events and cell crossings are work, not counted). The CLI also writes the state out
/// every dt, which the bench leaves out.
fn event_walls(c: &mut Criterion) {
    const COLLISIONS: u64 = 200_000;
    let mut group = c.benchmark_group("event_walls");
    group.sample_size(10);
    group.throughput(Throughput::Elements(COLLISIONS));
    for n in [100_000, 1_000_000] {
        for packing in [0.3, 0.5, 0.7] {
            let scene = GasSpec {
                seed: 42,
                placement: Placement::Lattice,
                ..GasSpec::unit(n, packing)
            }
            .build()
            .expect("a square lattice holds up to π/4");
            let params = EventParams { tc: 0.0 };
            let mut sim = EventSim::new(scene.domain, scene.physics, params, &scene.particles);
            sim.advance_collisions(n as u64);
            group.bench_function(BenchmarkId::new(format!("n{n}"), packing), |b| {
                b.iter(|| sim.advance_collisions(COLLISIONS));
            });
        }
    }
    group.finish();
}

criterion_group!(
    benches,
    serial_kernels,
    backend_steps,
    distributed_step,
    cost_model,
    event_walls
);

/// CPU seconds of the calling thread: on a loaded machine, close to what the thread
/// would have taken alone (caches are shared).
fn thread_cpu_s() -> f64 {
    cpu_seconds(CpuScope::Thread).expect("Linux has per-thread CPU clocks")
}

/// `criterion_main!`, unless `COLLIDE_YARDSTICK_ONLY=1` asks for the yardstick's rates only.
fn main() {
    if std::env::var_os("COLLIDE_YARDSTICK_ONLY").is_some_and(|v| v == "1") {
        yardstick_rates();
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
