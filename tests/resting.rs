//! Resting contact under gravity: a column and a pile settle inside their box, at two
//! time steps, over a long simulated time, with overlaps and wall penetration bounded
//! and not growing (regression tests for stacks that sank through the floor).

use collide::sim::observe::observe;
use collide::sim::resolve::SLOP;
use collide::sim::{
    Boundary, Broadphase, Disk, Domain, Particles, Physics, Scene, StepCounters, StepParams,
    Stepper,
};

/// The largest overlap (fraction of the contact distance) and wall penetration
/// (fraction of the radius) the tests allow, at any step.
const BOUND: f64 = 0.02;

const G: f64 = 9.81;

fn physics() -> Physics {
    Physics {
        gravity: Some([0.0, -G]),
        ..Physics::with_restitution(0.9)
    }
}

fn disk(x: f64, y: f64, radius: f64) -> Disk {
    Disk {
        x,
        y,
        vx: 0.0,
        vy: 0.0,
        radius,
        mass: radius * radius,
    }
}

/// 20 unit-diameter disks stacked with small gaps in a box barely wider than one.
fn column() -> Scene {
    let disks: Vec<Disk> = (0..20)
        .map(|k| disk(0.55, 0.5 + 1.05 * k as f64, 0.5))
        .collect();
    Scene {
        domain: Domain {
            width: 1.1,
            height: 30.0,
            boundary: Boundary::Walls,
        },
        physics: physics(),
        particles: Particles::from_disks(&disks),
    }
}

/// 60 disks of radii 0.4 to 0.6, in rows of four with staggered offsets, dropped into a
/// box 5.5 wide (about five diameters): a narrow pile a dozen disks deep.
fn pile() -> Scene {
    let disks: Vec<Disk> = (0..60)
        .map(|k| {
            let (row, col) = (k / 4, k % 4);
            let radius = 0.4 + 0.2 * ((k * 7919) % 13) as f64 / 12.0;
            let offset = if row % 2 == 0 { 0.0 } else { 0.45 };
            disk(
                0.7 + 1.2 * col as f64 + offset,
                0.7 + 1.3 * row as f64,
                radius,
            )
        })
        .collect();
    Scene {
        domain: Domain {
            width: 5.5,
            height: 30.0,
            boundary: Boundary::Walls,
        },
        physics: physics(),
        particles: Particles::from_disks(&disks),
    }
}

/// What a run saw in each half of its simulated time, and its state at the end.
struct Halves {
    first: StepCounters,
    last: StepCounters,
    end: Particles,
}

/// Runs `scene` for `duration` at `dt`, asserting after every step that every disk is
/// inside the box; a fresh stepper for each half gives each half its own maxima (a
/// stepper holds scratch memory only, so the state evolves exactly as with one).
fn run(scene: &Scene, dt: f64, duration: f64) -> Halves {
    let params = StepParams {
        dt,
        broadphase: Broadphase::Grid,
    };
    let half_steps = (duration / (2.0 * dt)).round() as u64;
    let mut particles = scene.particles.clone();
    let mut halves = Vec::new();
    for half in 0..2 {
        let mut stepper = Stepper::for_scene(scene, params);
        for step in 0..half_steps {
            stepper.step(&mut particles);
            for idx in 0..particles.len() {
                let (x, y, r) = (particles.x[idx], particles.y[idx], particles.radius[idx]);
                let inside =
                    |p: f64, length: f64| p - r >= -BOUND * r && p + r <= length + BOUND * r;
                assert!(
                    inside(x, scene.domain.width) && inside(y, scene.domain.height),
                    "dt {dt}: disk {} left the box in half {half}, step {step}: ({x}, {y}), \
                     velocity ({}, {})",
                    particles.id[idx],
                    particles.vx[idx],
                    particles.vy[idx]
                );
            }
        }
        halves.push(stepper.counters());
    }
    Halves {
        first: halves[0],
        last: halves[1],
        end: particles,
    }
}

/// The checks both scenes share: bounded and not growing, and at rest at the end.
fn assert_rests(name: &str, scene: &Scene, dt: f64, duration: f64) {
    let Halves { first, last, end } = run(scene, dt, duration);
    println!(
        "{name} dt {dt}: overlap {:.2e} → {:.2e}, wall penetration {:.2e} → {:.2e}",
        first.max_overlap, last.max_overlap, first.max_wall_penetration, last.max_wall_penetration
    );
    for (what, first, last) in [
        ("overlap", first.max_overlap, last.max_overlap),
        (
            "wall penetration",
            first.max_wall_penetration,
            last.max_wall_penetration,
        ),
    ] {
        assert!(
            last <= BOUND,
            "{name} dt {dt}: {what} {last} in the last half"
        );
        // Resting contacts settle at the slop the position projection leaves; beyond
        // that, the last half must not go deeper than the first.
        assert!(
            last <= 1.01 * first.max(SLOP),
            "{name} dt {dt}: {what} grew from {first} to {last}"
        );
    }
    // At rest: the kinetic energy per disk is a tiny fraction of m·g·r.
    let per_disk = observe(&end).kinetic_energy / end.len() as f64;
    let scale = end.mass[0] * G * end.radius[0];
    assert!(
        per_disk < 1e-3 * scale,
        "{name} dt {dt}: still moving, kinetic energy per disk {per_disk}"
    );
}

#[test]
fn a_column_of_20_disks_rests_on_the_floor_at_two_time_steps() {
    assert_rests("column", &column(), 1e-3, 40.0);
    assert_rests("column", &column(), 1e-4, 10.0);
}

#[test]
fn a_pile_in_a_narrow_box_rests_at_two_time_steps() {
    assert_rests("pile", &pile(), 1e-3, 40.0);
    assert_rests("pile", &pile(), 1e-4, 10.0);
}
