//! Every backend gives the serial reference's bits: same scene, same `state_hash`.

use std::num::NonZeroUsize;

use collide::backend::comm::ThreadComm;
use collide::backend::distributed::{self, FinalState};
use collide::backend::{serial, threads};
use collide::run::spec::{InjectedSlowdown, MethodSpec, RunSpec, SceneSource};
use collide::run::summary::RunSummary;
use collide::sim::scene::{GasSpec, MassRule, RadiusDistribution};
use collide::sim::{Boundary, Broadphase, Physics};

/// Dilute and dense, walls and periodic, elastic and inelastic.
fn scenes() -> Vec<(String, RunSpec)> {
    let mut scenes = Vec::new();
    for boundary in [Boundary::Walls, Boundary::Periodic] {
        for restitution in [1.0, 0.8] {
            for packing in [0.05, 0.35] {
                let gas = GasSpec {
                    radius: RadiusDistribution::Uniform { min: 0.6, max: 1.4 },
                    mass: MassRule::Area,
                    boundary,
                    physics: Physics::with_restitution(restitution),
                    seed: 99,
                    ..GasSpec::unit(3000, packing)
                };
                let name = format!("{} e={restitution} packing={packing}", boundary.name());
                scenes.push((name, run_spec(gas, Broadphase::Grid)));
            }
        }
    }
    scenes
}

fn run_spec(gas: GasSpec, broadphase: Broadphase) -> RunSpec {
    RunSpec {
        scene: SceneSource::Gas(gas),
        method: MethodSpec::stepped(0.05, 300, broadphase),
        slowdown: InjectedSlowdown::NONE,
    }
}

fn threads(n: usize) -> NonZeroUsize {
    NonZeroUsize::new(n).unwrap()
}

#[test]
fn rayon_at_1_2_3_4_and_8_threads_gives_the_serial_hash() {
    for (name, spec) in scenes() {
        let reference = serial::run(&spec).unwrap().summary;
        assert!(
            reference.pair_collisions > 100,
            "{name}: too few collisions to test"
        );
        for n in [1, 2, 3, 4, 8] {
            let summary = threads::run(&spec, threads(n)).unwrap().summary;
            assert_eq!(
                summary.state_hash, reference.state_hash,
                "{name}, {n} threads"
            );
            assert_eq!(summary.pair_collisions, reference.pair_collisions, "{name}");
            assert_eq!(summary.wall_collisions, reference.wall_collisions, "{name}");
            assert_eq!(summary.max_overlap, reference.max_overlap, "{name}");
            assert_eq!(
                observable_bits(&summary),
                observable_bits(&reference),
                "{name}, {n} threads: the observables from the block series"
            );
            assert_eq!(summary.equilibrated, reference.equilibrated, "{name}");
            assert_eq!((summary.threads, summary.ranks), (n, 1));
        }
    }
}

/// Each rank records its share of the block series (its counters, the exact kinetic
/// energy of its own disks) and rank 0 merges the shares after the run: the same blocks,
/// cut and error bars as the serial run's.
#[test]
fn ranks_as_threads_give_the_serial_observables() {
    for (name, spec) in scenes() {
        let reference = serial::run(&spec).unwrap().summary;
        for ranks in [1, 2, 3] {
            let spec = &spec;
            let outcomes = ThreadComm::run_group(ranks, |comm| {
                distributed::run(&comm, spec, FinalState::Summed, NonZeroUsize::MIN).unwrap()
            });
            let summary = outcomes.into_iter().next().unwrap().unwrap().summary;
            assert_eq!(
                summary.state_hash, reference.state_hash,
                "{name}, {ranks} ranks"
            );
            assert_eq!(
                observable_bits(&summary),
                observable_bits(&reference),
                "{name}, {ranks} ranks: the observables from the block series"
            );
            assert_eq!(summary.equilibrated, reference.equilibrated, "{name}");
        }
    }
}

/// The bits of every observable the summary computes from the block series (the
/// virial's blocks, the collision counts and the kinetic-energy integrals): equal bits
/// here mean equal series, cut and error bars.
fn observable_bits(summary: &RunSummary) -> Vec<Option<u64>> {
    [
        summary.compressibility_z,
        summary.compressibility_z_from_zero,
        summary.compressibility_z_se,
        summary.compressibility_z_g,
        summary.equilibration_cut_time,
        summary.collision_rate,
        summary.collision_rate_se,
        summary.temperature,
        summary.temperature_se,
        summary.pressure,
    ]
    .iter()
    .map(|value| value.map(f64::to_bits))
    .collect()
}

/// Steps of over half a radius for the rms disk: disks escape the neighbour lists
/// between rebuilds, and their pairs come from queries that any band's disks may be in.
#[test]
fn rayon_with_coarse_steps_gives_the_serial_hash() {
    for (name, mut spec) in scenes() {
        spec.method = MethodSpec::stepped(0.6, 200, Broadphase::Grid);
        let reference = serial::run(&spec).unwrap().summary;
        for n in [1, 2, 3] {
            let summary = threads::run(&spec, threads(n)).unwrap().summary;
            assert_eq!(
                summary.state_hash, reference.state_hash,
                "{name}, {n} threads"
            );
        }
    }
}

/// A scene large enough for the rayon backend to measure the lists' largest
/// displacement in parallel pieces, with steps coarse enough that disks escape the lists
/// and queries reach as far as that displacement says.
#[test]
fn rayon_on_a_large_scene_with_coarse_steps_gives_the_serial_hash() {
    let gas = GasSpec {
        seed: 5,
        ..GasSpec::unit(70_000, 0.3)
    };
    let spec = RunSpec {
        method: MethodSpec::stepped(0.6, 30, Broadphase::Grid),
        ..run_spec(gas, Broadphase::Grid)
    };
    let reference = serial::run(&spec).unwrap().summary;
    for n in [2, 3] {
        let summary = threads::run(&spec, threads(n)).unwrap().summary;
        assert_eq!(summary.state_hash, reference.state_hash, "{n} threads");
    }
}

#[test]
fn rayon_all_pairs_and_gravity_give_the_serial_hash() {
    let mut gas = GasSpec {
        physics: Physics {
            gravity: Some([0.0, -1.0]),
            ..Physics::with_restitution(0.9)
        },
        seed: 5,
        ..GasSpec::unit(800, 0.3)
    };
    for broadphase in [Broadphase::Grid, Broadphase::AllPairs] {
        let spec = run_spec(gas, broadphase);
        let reference = serial::run(&spec).unwrap().summary;
        for n in [2, 3] {
            let summary = threads::run(&spec, threads(n)).unwrap().summary;
            assert_eq!(summary.state_hash, reference.state_hash, "{broadphase:?}");
        }
    }
    gas.physics.gravity = None;
    let grid = serial::run(&run_spec(gas, Broadphase::Grid)).unwrap();
    let all_pairs = threads::run(&run_spec(gas, Broadphase::AllPairs), threads(2)).unwrap();
    assert_eq!(grid.summary.state_hash, all_pairs.summary.state_hash);
}

/// A gas falling into a pile on the floor of a walled box: resting contact (the sweeps
/// and the position projection) on every band and across bands gives the serial bits.
#[test]
fn rayon_gives_the_serial_hash_for_a_pile_resting_under_gravity() {
    let gas = GasSpec {
        radius: RadiusDistribution::Uniform { min: 0.6, max: 1.4 },
        mass: MassRule::Area,
        boundary: Boundary::Walls,
        physics: Physics {
            gravity: Some([0.0, -1.0]),
            ..Physics::with_restitution(0.5)
        },
        seed: 8,
        ..GasSpec::unit(800, 0.3)
    };
    let spec = RunSpec {
        scene: SceneSource::Gas(gas),
        method: MethodSpec::stepped(0.05, 600, Broadphase::Grid),
        slowdown: InjectedSlowdown::NONE,
    };
    let reference = serial::run(&spec).unwrap().summary;
    assert!(reference.max_wall_penetration > 0.0);
    for n in [2, 3, 4] {
        let summary = threads::run(&spec, threads(n)).unwrap().summary;
        assert_eq!(summary.state_hash, reference.state_hash, "{n} threads");
        assert_eq!(summary.max_overlap, reference.max_overlap, "{n} threads");
        assert_eq!(
            summary.max_wall_penetration, reference.max_wall_penetration,
            "{n} threads"
        );
    }
}

#[test]
fn drawing_every_step_leaves_the_state_and_reports_frames_with_drawing() {
    let (name, spec) = scenes().swap_remove(0);
    let reference = serial::run(&spec).unwrap().summary;
    assert_eq!(
        (reference.draw_s, reference.fps_with_drawing),
        (None, None),
        "{name}: a run that did not draw"
    );
    let mut drawn = spec.clone();
    drawn.method.draw = true;
    for (backend, summary) in [
        ("serial", serial::run(&drawn).unwrap().summary),
        ("rayon", threads::run(&drawn, threads(2)).unwrap().summary),
    ] {
        assert_eq!(
            summary.state_hash, reference.state_hash,
            "{name}, {backend}"
        );
        let draw_s = summary.draw_s.unwrap();
        let fps_with_drawing = summary.fps_with_drawing.unwrap();
        assert!(draw_s > 0.0, "{backend}: {draw_s}");
        // Frames with drawing: the same steps over the stepping and the drawing time.
        let expected = summary.steps as f64 / (summary.wall_s + draw_s);
        assert!(
            (fps_with_drawing - expected).abs() <= 1e-9 * expected,
            "{backend}: {fps_with_drawing} against {expected}"
        );
        assert!(fps_with_drawing < summary.fps, "{backend}");
    }
}
