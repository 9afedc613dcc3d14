//! Criterion benches of the simulator's kernels: one full serial step, the broad phase
//! and the contact resolution, at N = 100,000 for a dilute and a dense gas.
//!
//! Throughput is in disks per iteration, so criterion's "elem/s" is particle-steps per second.
//! Run: `cargo bench --bench kernels`.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

use collide::sim::scene::{Extent, GasSpec, MassRule, Placement, RadiusDistribution};
use collide::sim::{Boundary, Broadphase, Particles, Physics, StepParams, Stepper};

const N_PARTICLES: usize = 100_000;

/// A gas with r = 1 and v_rms = 1 stepped with dt = 0.1, so v_rms·dt = 0.1·r,
/// after 50 warm-up steps (the first grid build sorts from scratch).
fn warmed_up(packing: f64) -> (Particles, Stepper) {
    let scene = GasSpec {
        n_particles: N_PARTICLES,
        extent: Extent::Packing(packing),
        radius: RadiusDistribution::Fixed(1.0),
        mass: MassRule::Fixed(1.0),
        speed_rms: 1.0,
        placement: Placement::Random,
        boundary: Boundary::Walls,
        physics: Physics {
            restitution: 1.0,
            wall_restitution: 1.0,
            gravity: None,
        },
        seed: 42,
    }
    .build()
    .expect("packings below jamming place");
    let mut particles = scene.particles.clone();
    let params = StepParams {
        dt: 0.1,
        broadphase: Broadphase::Grid,
    };
    let mut stepper = Stepper::for_scene(&scene, params);
    for _ in 0..50 {
        stepper.step(&mut particles);
    }
    (particles, stepper)
}

fn kernels(c: &mut Criterion) {
    let mut group = c.benchmark_group("serial");
    group.throughput(Throughput::Elements(N_PARTICLES as u64));
    group.sample_size(30);
    for packing in [0.05, 0.3] {
        let (mut particles, mut stepper) = warmed_up(packing);
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

criterion_group!(benches, kernels);
criterion_main!(benches);
