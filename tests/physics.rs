//! Physics over many steps: conservation, determinism, broad-phase equivalence, walls,
//! and an elastic gas under gravity.

use collide::backend::serial;
use collide::run::spec::{InjectedSlowdown, MethodSpec, RunSpec, SceneSource};
use collide::run::summary::RunSummary;
use collide::sim::observe::{observe, potential_energy, temperature};
use collide::sim::scene::{Extent, GasSpec, Placement, RadiusDistribution};
use collide::sim::{Boundary, Broadphase, Particles, Physics, StepParams, Stepper};

fn gas(
    n_particles: usize,
    packing: f64,
    boundary: Boundary,
    restitution: f64,
    seed: u64,
) -> GasSpec {
    GasSpec {
        boundary,
        physics: Physics::with_restitution(restitution),
        seed,
        ..GasSpec::unit(n_particles, packing)
    }
}

fn spec(gas: GasSpec, dt: f64, steps: u64, broadphase: Broadphase) -> RunSpec {
    RunSpec {
        scene: SceneSource::Gas(gas),
        method: MethodSpec::stepped(dt, steps, broadphase),
        slowdown: InjectedSlowdown::NONE,
    }
}

/// Runs a gas on the serial backend and returns its summary.
fn summary_of(gas: GasSpec, dt: f64, steps: u64, broadphase: Broadphase) -> RunSummary {
    serial::run(&spec(gas, dt, steps, broadphase))
        .unwrap()
        .summary
}

fn relative(a: f64, b: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs())
}

#[test]
fn dilute_elastic_periodic_gas_conserves_momentum_and_energy_over_10000_steps() {
    let s = &summary_of(
        gas(400, 0.05, Boundary::Periodic, 1.0, 7),
        0.1,
        10_000,
        Broadphase::Grid,
    );
    assert!(
        s.pair_collisions > 1000,
        "the test must exercise collisions: {}",
        s.pair_collisions
    );
    // Each collision conserves energy to a few ulps; 10^4 collisions of random sign
    // accumulate to ~1e-14 relative. 1e-12 leaves room and still catches any real leak.
    assert!(
        relative(s.kinetic_energy_initial, s.kinetic_energy_final) < 1e-12,
        "energy {} → {}",
        s.kinetic_energy_initial,
        s.kinetic_energy_final
    );
    // Momentum starts at ~1e-14 (drift removed): compare with the momentum scale Σ m|v|.
    let scale = 400.0 * 1.0;
    for axis in 0..2 {
        let drift = (s.momentum_final[axis] - s.momentum_initial[axis]).abs() / scale;
        assert!(
            drift < 1e-12,
            "momentum axis {axis} drifted by {drift} relative"
        );
    }
}

#[test]
fn dilute_elastic_walled_gas_conserves_energy() {
    let s = &summary_of(
        gas(400, 0.05, Boundary::Walls, 1.0, 3),
        0.1,
        5_000,
        Broadphase::Grid,
    );
    assert!(s.wall_collisions > 100 && s.pair_collisions > 500);
    assert!(relative(s.kinetic_energy_initial, s.kinetic_energy_final) < 1e-12);
}

#[test]
fn grid_and_all_pairs_give_bitwise_identical_runs() {
    for boundary in [Boundary::Walls, Boundary::Periodic] {
        for restitution in [1.0, 0.8] {
            for (packing, dt) in [(0.05, 0.1), (0.4, 0.05)] {
                let gas = gas(300, packing, boundary, restitution, 11);
                let grid = summary_of(gas, dt, 600, Broadphase::Grid);
                let all_pairs = summary_of(gas, dt, 600, Broadphase::AllPairs);
                assert!(
                    grid.pair_collisions > 50,
                    "{boundary:?} e={restitution} packing={packing}"
                );
                assert_eq!(
                    grid.state_hash, all_pairs.state_hash,
                    "{boundary:?} e={restitution} packing={packing}"
                );
                assert_eq!(grid.pair_collisions, all_pairs.pair_collisions);
                assert_eq!(grid.max_overlap, all_pairs.max_overlap);
            }
        }
    }
}

#[test]
fn same_seed_same_hash_different_seed_different_hash() {
    let run = |seed| {
        summary_of(
            gas(500, 0.1, Boundary::Walls, 1.0, seed),
            0.1,
            200,
            Broadphase::Grid,
        )
        .state_hash
    };
    assert_eq!(run(1), run(1));
    assert_ne!(run(1), run(2));
}

#[test]
fn no_disk_leaves_a_walled_box_dense_and_inelastic() {
    for (packing, restitution, placement) in [
        (0.5, 0.3, Placement::Random),
        (0.7, 0.0, Placement::Lattice),
        (0.05, 1.0, Placement::Random),
    ] {
        let mut gas = gas(500, packing, Boundary::Walls, restitution, 5);
        gas.placement = placement;
        gas.speed_rms = 3.0;
        let scene = gas.build().unwrap();
        let mut particles = scene.particles.clone();
        let params = collide::sim::StepParams {
            dt: 0.03,
            broadphase: Broadphase::Grid,
        };
        let mut stepper = Stepper::for_scene(&scene, params);
        for step in 0..3000 {
            stepper.step(&mut particles);
            for idx in 0..particles.len() {
                let (x, y) = (particles.x[idx], particles.y[idx]);
                assert!(
                    (0.0..=scene.domain.width).contains(&x)
                        && (0.0..=scene.domain.height).contains(&y),
                    "packing {packing}, e {restitution}: disk {} left the box at step {step}: ({x}, {y})",
                    particles.id[idx]
                );
            }
        }
        assert!(stepper.counters().wall_collisions > 0);
    }
}

#[test]
fn gravity_uses_verlet_and_a_disk_bounces_back_to_its_height() {
    // One disk dropped from rest under g = 9.81 onto an elastic floor: constant-acceleration
    // Verlet is exact between bounces, so energy stays to rounding and it returns to its height.
    let toml = r#"
        [scene]
        size = [10.0, 10.0]
        gravity = [0.0, -9.81]
        [[scene.particle]]
        x = 5.0
        y = 8.0
        radius = 0.5
        [method]
        dt = 0.0001
        steps = 50000
    "#;
    let spec = collide::run::scene_file::parse(
        std::path::Path::new("drop.toml"),
        toml,
        &Default::default(),
    )
    .unwrap();
    let prepared = spec.prepare().unwrap();
    let mut particles = prepared.scene.particles.clone();
    let mut stepper = Stepper::for_scene(&prepared.scene, prepared.params);
    let mut highest_after_bounce = 0.0_f64;
    let mut bounced = false;
    for _ in 0..prepared.steps {
        stepper.step(&mut particles);
        bounced |= stepper.counters().wall_collisions > 0;
        if bounced {
            highest_after_bounce = highest_after_bounce.max(particles.y[0]);
        }
    }
    assert_eq!(
        stepper.counters().wall_collisions,
        2,
        "the drop takes 1.2 s, the run 5 s"
    );
    // A bounce is detected up to one step late: the height error is O(g·dt·v·dt).
    assert!(
        (highest_after_bounce - 8.0).abs() < 2e-3,
        "returned to {highest_after_bounce}"
    );
}

#[test]
fn storage_order_never_changes_the_result() {
    // Pairs are resolved in id order and sums run in id order, so storing the same disks
    // backwards must give the same bits (the grid also re-stores them as it goes).
    let scene = gas(400, 0.3, Boundary::Periodic, 0.9, 21).build().unwrap();
    let run = |mut particles: collide::sim::Particles| {
        let params = collide::sim::StepParams {
            dt: 0.05,
            broadphase: Broadphase::Grid,
        };
        let mut stepper = Stepper::new(scene.domain, scene.physics, params, &particles);
        for _ in 0..500 {
            stepper.step(&mut particles);
        }
        assert!(stepper.counters().pair_collisions > 100);
        collide::sim::observe::state_hash(&particles)
    };
    let mut reversed = scene.particles.clone();
    let backwards: Vec<u32> = (0..reversed.len() as u32).rev().collect();
    reversed.reorder(&backwards);
    assert_ne!(reversed.id[0], scene.particles.id[0]);
    assert_eq!(run(scene.particles.clone()), run(reversed));
}

/// The elastic gas under gravity of `experiments/scenes/gravity-gas.toml`: 2000 disks of
/// radius 0.5 (m = 1, v_rms = 1) in a walled box 1000 × 200, g = 0.01, e = 1 for pairs and
/// walls. It settles from uniform into a barometric profile of scale height about 80.
fn gas_under_gravity() -> collide::sim::Scene {
    GasSpec {
        extent: Extent::Size {
            width: 1000.0,
            height: 200.0,
        },
        radius: RadiusDistribution::Fixed(0.5),
        physics: Physics {
            gravity: Some([0.0, -0.01]),
            ..Physics::elastic()
        },
        seed: 7,
        ..GasSpec::unit(2000, 0.0)
    }
    .build()
    .unwrap()
}

/// Kinetic plus potential energy.
fn total_energy(particles: &Particles, gravity: Option<[f64; 2]>) -> f64 {
    observe(particles).kinetic_energy + potential_energy(particles, gravity)
}

/// An elastic gas under gravity keeps its total energy: only contacts slower than the
/// resting speed are treated as resting (`sim::resolve`). When every contact was (sweeps
/// without restitution, walls stopping disks, the projection lifting them out of the
/// floor), this gas lost energy in steps once settled: 2.1% at dt = 0.05 and 0.68% at
/// dt = 0.01 by t = 1000. What is left is the rare projection of a disk that an impact
/// drove deeper into a wall than it leaves in a step (1.4e-7 at dt = 0.05; up to 1.3e-6
/// with other orders of the same impulses), and rounding (4e-14 at dt = 0.01).
#[test]
fn an_elastic_gas_under_gravity_keeps_its_energy_to_t_1000() {
    let scene = gas_under_gravity();
    let gravity = scene.physics.gravity;
    let initial = total_energy(&scene.particles, gravity);
    for (dt, bound) in [(0.05, 1e-5), (0.01, 1e-6)] {
        let mut particles = scene.particles.clone();
        let params = StepParams {
            dt,
            broadphase: Broadphase::Grid,
        };
        let mut stepper = Stepper::for_scene(&scene, params);
        for _ in 0..(1000.0 / dt).round() as u64 {
            stepper.step(&mut particles);
        }
        let error = relative(total_energy(&particles, gravity), initial);
        println!("dt {dt}: |ΔE/E| = {error:.2e}");
        assert!(
            stepper.counters().pair_collisions > 10_000,
            "the test must exercise collisions"
        );
        assert!(
            error <= bound,
            "dt {dt}: energy changed by {error:.2e} relative"
        );
    }
}

/// The summary's `energy_relative_error` counts the energy in the field: the elastic gas
/// under gravity falls, gaining 63% in kinetic energy in its first 100 time units, and
/// keeps its total.
#[test]
fn the_summary_measures_the_energy_a_gas_under_gravity_conserves() {
    let summary = crate::util::json_summary(&[
        "simulate",
        "experiments/scenes/gravity-gas.toml",
        "--steps",
        "2000",
    ]);
    let kinetic = ["kinetic_energy_initial", "kinetic_energy_final"]
        .map(|field| summary[field].as_f64().unwrap());
    let traded = (kinetic[1] - kinetic[0]).abs() / kinetic[0];
    assert!(traded > 0.05, "the kinetic energy changes by {traded:.3}");
    let error = summary["energy_relative_error"].as_f64().unwrap();
    assert!(error.abs() < 1e-6, "energy_relative_error {error:.2e}");
}

/// Settled, the elastic gas under gravity has the barometric profile: its number density
/// n falls with height with the scale height λ = kT/(m·g), kT the kinetic energy per disk.
/// The disks crowd a little at the floor (packing 0.02), where by the second virial
/// coefficient B₂ = 2πr² the pressure is n·kT·(1 + B₂·n), so ln n + 2B₂·n, not ln n
/// alone, falls as −y/λ (the crowding lengthens the plain fit's λ by 3.6% on average).
/// Heights are counted every 10 time units over t = 500 to 2500 (the fall across the box
/// takes 200) in ten layers; a least-squares line through the layers, weighted by their
/// counts, gives the measured λ. Over seeds 1 to 10 it is within 1.8% of kT/(m·g)
/// (standard deviation 1.1%); the test allows 4%.
#[test]
fn an_elastic_gas_under_gravity_settles_into_the_barometric_profile() {
    const LAYERS: usize = 10;
    let scene = gas_under_gravity();
    let ([_, g], r) = (scene.physics.gravity.unwrap(), scene.particles.radius[0]);
    let params = StepParams {
        dt: 0.05,
        broadphase: Broadphase::Grid,
    };
    let mut particles = scene.particles.clone();
    let mut stepper = Stepper::for_scene(&scene, params);
    let (mut counts, mut kinetic, mut samples) = ([0.0_f64; LAYERS], 0.0, 0);
    // Centres lie in [r, height − r] × [r, width − r]: the layers cut that span evenly.
    let layer_height = (scene.domain.height - 2.0 * r) / LAYERS as f64;
    let layer_area = (scene.domain.width - 2.0 * r) * layer_height;
    for step in 1..=50_000 {
        stepper.step(&mut particles);
        if step >= 10_000 && step % 200 == 0 {
            for &y in &particles.y {
                let layer = ((y - r) / layer_height)
                    .floor()
                    .clamp(0.0, LAYERS as f64 - 1.0);
                counts[layer as usize] += 1.0;
            }
            kinetic += temperature(&particles);
            samples += 1;
        }
    }
    let expected = kinetic / samples as f64 / -g;
    let b2 = 2.0 * std::f64::consts::PI * r * r;
    // (height of the layer's middle, ln n + 2B₂·n, weight)
    let points: Vec<[f64; 3]> = counts
        .iter()
        .enumerate()
        .map(|(k, &count)| {
            let density = count / (samples as f64 * layer_area);
            let height = r + (k as f64 + 0.5) * layer_height;
            [height, density.ln() + 2.0 * b2 * density, count]
        })
        .collect();
    let weight: f64 = points.iter().map(|p| p[2]).sum();
    let mean = |axis: usize| points.iter().map(|p| p[2] * p[axis]).sum::<f64>() / weight;
    let (mean_height, mean_log) = (mean(0), mean(1));
    let covariance: f64 = points
        .iter()
        .map(|p| p[2] * (p[0] - mean_height) * (p[1] - mean_log))
        .sum();
    let variance: f64 = points
        .iter()
        .map(|p| p[2] * (p[0] - mean_height).powi(2))
        .sum();
    let measured = -variance / covariance;
    println!("scale height {measured:.2} measured, kT/(mg) = {expected:.2}; layers {counts:?}");
    assert!(
        relative(measured, expected) < 0.04,
        "scale height {measured} against kT/(mg) = {expected}"
    );
}
