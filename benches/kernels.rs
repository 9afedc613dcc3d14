//! Criterion benches of the simulator's kernels: one full serial step (and, as a
//! yardstick, one step of a straightforward cell list), the broad phase
//! (grid build and pair search) and the contact resolution at N = 100,000; one full step
//! of the serial and the rayon (2 threads) backends at N = 1,000,000; and one step of
//! the distributed backend on 2 ranks as threads (`ThreadComm`) at N = 100,000, through
//! the same stepping loop (`backend::step_loop`) that `collide simulate` and
//! `collide check` time. Each for a dilute and a dense gas.
//!
//! Throughput is in disks per iteration, so criterion's "elem/s" is particle-steps per second;
//! in the `event` group it is collisions (pair and wall) per second of the event-driven
//! method. The `step` and `event` groups run both methods on the same periodic gases at
//! N = 10^4, 10^5 and 10^6: they are the cost model of `method = "auto"`.
//! Run: `cargo bench --bench kernels` (MPI runs need `mpirun` and `--features mpi`: see docs/performance.md).

use std::time::{Duration, Instant};

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

use collide::backend::comm::ThreadComm;
use collide::backend::distributed;
use collide::backend::threads::ThreadedStepper;
use collide::sim::collision::resolve_contact;
use collide::sim::event::{EventParams, EventSim};
use collide::sim::scene::GasSpec;
use collide::sim::step::advance_disks;
use collide::sim::{Boundary, Broadphase, Domain, Particles, Physics, Scene, StepParams, Stepper};
use collide::spec::{InjectedSlowdown, MethodSpec, RunSpec, SceneSource};

/// r = 1 and v_rms = 1 stepped with dt = 0.1, so v_rms·dt = 0.1·r.
const PARAMS: StepParams = StepParams {
    dt: 0.1,
    broadphase: Broadphase::Grid,
};
const WARM_UP_STEPS: usize = 50;

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

/// The yardstick, "a straightforward cell-list code", benched beside our step so
/// that their ratio is measured in one run on one machine: square cells one contact
/// diameter wide rebuilt by a counting sort every step, each disk tested against the rest
/// of its cell and the four forward neighbour cells, contacts resolved as found (with
/// our impulse law and motion, so only the search and its order differ; walls only).
struct StraightforwardCellList {
    domain: Domain,
    physics: Physics,
    cell: f64,
    nx: usize,
    ny: usize,
    /// Start of each cell's disks in `order`, and one past the last.
    starts: Vec<usize>,
    order: Vec<usize>,
}

impl StraightforwardCellList {
    fn new(scene: &Scene) -> Self {
        let cell = 2.0 * scene.particles.max_radius();
        let nx = ((scene.domain.width / cell) as usize).max(1);
        let ny = ((scene.domain.height / cell) as usize).max(1);
        StraightforwardCellList {
            domain: scene.domain,
            physics: scene.physics,
            cell: scene.domain.width / nx as f64,
            nx,
            ny,
            starts: vec![0; nx * ny + 1],
            order: vec![0; scene.particles.len()],
        }
    }

    fn cell_of(&self, x: f64, y: f64) -> usize {
        let cx = ((x / self.cell) as usize).min(self.nx - 1);
        let cy = ((y / self.cell) as usize).min(self.ny - 1);
        cy * self.nx + cx
    }

    fn step(&mut self, particles: &mut Particles) {
        advance_disks(
            &self.domain,
            &self.physics,
            PARAMS.dt,
            particles.disk_slices_mut(),
        );
        self.starts.fill(0);
        for i in 0..particles.len() {
            let c = self.cell_of(particles.x[i], particles.y[i]);
            self.starts[c + 1] += 1;
        }
        for c in 0..self.nx * self.ny {
            self.starts[c + 1] += self.starts[c];
        }
        let mut next = self.starts.clone();
        for i in 0..particles.len() {
            let c = self.cell_of(particles.x[i], particles.y[i]);
            self.order[next[c]] = i;
            next[c] += 1;
        }
        let (domain, e) = (self.domain, self.physics.restitution);
        let test = |particles: &mut Particles, i: usize, j: usize| {
            let (dx, dy) = (
                particles.x[j] - particles.x[i],
                particles.y[j] - particles.y[i],
            );
            let contact = particles.radius[i] + particles.radius[j];
            if dx * dx + dy * dy < contact * contact {
                resolve_contact(particles, &domain, e, i, j);
            }
        };
        for cy in 0..self.ny {
            for cx in 0..self.nx {
                let here = self.starts[cy * self.nx + cx]..self.starts[cy * self.nx + cx + 1];
                for a in here.clone() {
                    let i = self.order[a];
                    for b in a + 1..here.end {
                        test(particles, i, self.order[b]);
                    }
                    for (ox, oy) in [(1, 0), (-1, 1), (0, 1), (1, 1)] {
                        let (nx, ny) = (cx as isize + ox, cy as isize + oy);
                        if nx < 0 || nx >= self.nx as isize || ny >= self.ny as isize {
                            continue;
                        }
                        let c = ny as usize * self.nx + nx as usize;
                        for b in self.starts[c]..self.starts[c + 1] {
                            test(particles, i, self.order[b]);
                        }
                    }
                }
            }
        }
    }
}

fn serial_kernels(c: &mut Criterion) {
    const N: usize = 100_000;
    let mut group = c.benchmark_group("serial");
    group.throughput(Throughput::Elements(N as u64));
    group.sample_size(30);
    for packing in [0.05, 0.3] {
        let (mut particles, mut stepper) = warmed_up_serial(&gas(N, packing));
        group.bench_function(BenchmarkId::new("step", packing), |b| {
            b.iter(|| stepper.step(&mut particles));
        });
        let scene = gas(N, packing);
        let mut yardstick = StraightforwardCellList::new(&scene);
        let mut plain = scene.particles.clone();
        for _ in 0..WARM_UP_STEPS {
            yardstick.step(&mut plain);
        }
        group.bench_function(
            BenchmarkId::new("straightforward_cell_list_step", packing),
            |b| {
                b.iter(|| yardstick.step(&mut plain));
            },
        );
        group.bench_function(BenchmarkId::new("broad_phase", packing), |b| {
            b.iter(|| stepper.find_contacts(&mut particles));
        });
        // Resolving the same contacts again finds them separating: this times the
        // canonical-order pass itself, not the impulses of fresh collisions.
        group.bench_function(BenchmarkId::new("resolve_contacts", packing), |b| {
            b.iter(|| stepper.resolve_contacts(&mut particles));
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
        group.bench_function(BenchmarkId::new("serial", packing), |b| {
            b.iter(|| stepper.step(&mut particles));
        });
        let mut particles = scene.particles.clone();
        let mut threaded = ThreadedStepper::new(scene.domain, scene.physics, PARAMS, &particles, 2);
        pool.install(|| {
            for _ in 0..WARM_UP_STEPS {
                threaded.step(&mut particles);
            }
        });
        group.bench_function(BenchmarkId::new("rayon_2_threads", packing), |b| {
            b.iter(|| pool.install(|| threaded.step(&mut particles)));
        });
    }
    group.finish();
}

/// The cost model of `method = "auto"` (`collide::auto::MEASURED`): both methods on the
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
                let wall_s = std::thread::scope(|scope| {
                    let ranks: Vec<_> = ThreadComm::group(RANKS)
                        .into_iter()
                        .map(|comm| scope.spawn(move || distributed::run(&comm, spec)))
                        .collect();
                    let outcomes: Vec<_> = ranks.into_iter().map(|r| r.join()).collect();
                    outcomes
                        .into_iter()
                        .find_map(|outcome| outcome.expect("a rank ran").expect("placed"))
                        .expect("rank 0 reports")
                        .summary
                        .wall_s
                });
                Duration::from_secs_f64(wall_s)
            });
        });
    }
    group.finish();
}

criterion_group!(
    benches,
    serial_kernels,
    backend_steps,
    distributed_step,
    cost_model
);
criterion_main!(benches);
