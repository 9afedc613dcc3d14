//! Criterion benches of the simulator's kernels: one full serial step, the broad phase
//! and the contact resolution at N = 100,000, and one full step of the serial and the
//! rayon (2 threads) backends at N = 1,000,000, for a dilute and a dense gas.
//!
//! Throughput is in disks per iteration, so criterion's "elem/s" is particle-steps per second;
//! in the `event` group it is collisions (pair and wall) per second of the event-driven
//! method at N = 10^4 and 10^5 in a periodic box.
//! Run: `cargo bench --bench kernels` (MPI runs need `mpirun`: see the README's Speed section).

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

use collide::backend::threads::ThreadedStepper;
use collide::sim::event::{EventParams, EventSim};
use collide::sim::scene::GasSpec;
use collide::sim::{Boundary, Broadphase, Particles, Scene, StepParams, Stepper};

/// r = 1 and v_rms = 1 stepped with dt = 0.1, so v_rms·dt = 0.1·r.
const PARAMS: StepParams = StepParams {
    dt: 0.1,
    broadphase: Broadphase::Grid,
};
const WARM_UP_STEPS: usize = 50;

fn gas(n_particles: usize, packing: f64) -> Scene {
    GasSpec {
        seed: 42,
        ..GasSpec::unit(n_particles, packing)
    }
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

/// Event-driven throughput: each iteration processes a fixed number of collisions (pair
/// and wall) of an elastic periodic gas after a warm-up of one collision per disk, so
/// "elem/s" is collisions per second on one core (cell crossings are work, not counted).
fn event_throughput(c: &mut Criterion) {
    const COLLISIONS: u64 = 100_000;
    let mut group = c.benchmark_group("event");
    group.throughput(Throughput::Elements(COLLISIONS));
    group.sample_size(10);
    for n in [10_000, 100_000] {
        for packing in [0.05, 0.3] {
            let scene = GasSpec {
                seed: 42,
                boundary: Boundary::Periodic,
                ..GasSpec::unit(n, packing)
            }
            .build()
            .expect("packings below jamming place");
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

criterion_group!(benches, serial_kernels, backend_steps, event_throughput);
criterion_main!(benches);
