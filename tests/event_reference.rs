//! The event method's answers pinned: fixed scenes (walls and periodic, elastic and
//! inelastic, one and two radii, packings 0.3 to 0.7) run to a few collisions per disk,
//! compared with the collision counts and final states in `tests/fixtures/event-reference/`,
//! recorded from the method before its neighbour lists (issue 54). The event method is the
//! reference every stepped run is judged against, so a faster version must give the same
//! collisions and the same final state; only rounding may differ (predictions made at
//! other events round differently), and hard-disk dynamics amplify it, hence a few
//! collisions per disk and [`TOLERANCE`].
//!
//! The scenes are built here, without `GasSpec`: disks on a square lattice, velocities
//! from a small LCG, so that changes to random placement leave them alone.
//! `COLLIDE_RECORD_EVENT_REFERENCE=1 cargo test --release --test tests event_reference`
//! records the fixtures afresh (only when the method's answers are meant to change).

use std::fmt::Write as _;
use std::path::PathBuf;

use collide::sim::event::{EventParams, EventSim};
use collide::sim::observe::state_hash;
use collide::sim::particles::{Disk, Particles};
use collide::sim::scene::{Boundary, Domain, Physics};

/// Largest difference allowed in any coordinate or velocity component (boxes are 40 to
/// 90 radii wide, speeds about 1): rounding amplified by a few collisions per disk.
const TOLERANCE: f64 = 1e-8;

/// One fixed scene.
struct Reference {
    name: &'static str,
    /// Disks per side of the square lattice.
    side: usize,
    packing: f64,
    boundary: Boundary,
    restitution: f64,
    /// Every other disk's radius over the first's (1: one radius).
    radius_ratio: f64,
    tc: f64,
    t_end: f64,
}

const SCENES: [Reference; 5] = [
    Reference {
        name: "walls-elastic-0.3",
        side: 20,
        packing: 0.3,
        boundary: Boundary::Walls,
        restitution: 1.0,
        radius_ratio: 1.0,
        tc: 0.0,
        t_end: 8.0,
    },
    Reference {
        name: "periodic-elastic-0.7",
        side: 24,
        packing: 0.7,
        boundary: Boundary::Periodic,
        restitution: 1.0,
        radius_ratio: 1.0,
        tc: 0.0,
        t_end: 1.0,
    },
    Reference {
        name: "walls-elastic-0.7",
        side: 20,
        packing: 0.7,
        boundary: Boundary::Walls,
        restitution: 1.0,
        radius_ratio: 1.0,
        tc: 0.0,
        t_end: 1.0,
    },
    Reference {
        name: "walls-inelastic-0.5-two-radii",
        side: 22,
        packing: 0.5,
        boundary: Boundary::Walls,
        restitution: 0.8,
        radius_ratio: 0.7,
        tc: 1e-4,
        t_end: 4.0,
    },
    Reference {
        name: "periodic-inelastic-0.5",
        side: 22,
        packing: 0.5,
        boundary: Boundary::Periodic,
        restitution: 0.9,
        radius_ratio: 1.0,
        tc: 1e-4,
        t_end: 4.0,
    },
];

/// A 64-bit LCG (Knuth's MMIX constants): uniform in [-1, 1) from the top 53 bits.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// The scene's disks on a square lattice (the larger radius 1; area fraction `packing`
/// of the square box) with velocities uniform in [-1, 1)², and its domain.
fn build(scene: &Reference) -> (Domain, Particles) {
    let n = scene.side * scene.side;
    let radius = |idx: usize| {
        if idx.is_multiple_of(2) {
            1.0
        } else {
            scene.radius_ratio
        }
    };
    let disk_area: f64 = (0..n)
        .map(|idx| std::f64::consts::PI * radius(idx).powi(2))
        .sum();
    let width = (disk_area / scene.packing).sqrt();
    let spacing = width / scene.side as f64;
    assert!(spacing > 2.0, "{}: the lattice overlaps", scene.name);
    let mut lcg = Lcg(0x5eed_0054 + n as u64);
    let disks: Vec<Disk> = (0..n)
        .map(|idx| Disk {
            x: (idx % scene.side) as f64 * spacing + spacing / 2.0,
            y: (idx / scene.side) as f64 * spacing + spacing / 2.0,
            vx: lcg.next(),
            vy: lcg.next(),
            radius: radius(idx),
            mass: radius(idx).powi(2),
        })
        .collect();
    let domain = Domain {
        width,
        height: width,
        boundary: scene.boundary,
    };
    (domain, Particles::from_disks(&disks))
}

/// What the event method ends with: the counts, the state hash and every disk's state.
fn run(scene: &Reference) -> (u64, u64, String, Vec<[f64; 4]>) {
    let (domain, mut particles) = build(scene);
    let physics = Physics::with_restitution(scene.restitution);
    let params = EventParams { tc: scene.tc };
    let mut sim = EventSim::new(domain, physics, params, &particles);
    sim.advance_to(&mut particles, scene.t_end);
    let counters = sim.counters();
    let state = (0..particles.len())
        .map(|idx| {
            [
                particles.x[idx],
                particles.y[idx],
                particles.vx[idx],
                particles.vy[idx],
            ]
        })
        .collect();
    (
        counters.pair_collisions,
        counters.wall_collisions,
        state_hash(&particles),
        state,
    )
}

fn fixture(scene: &Reference) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/event-reference")
        .join(format!("{}.txt", scene.name))
}

#[test]
fn event_reference_keeps_its_collisions_and_final_states() {
    let record = std::env::var_os("COLLIDE_RECORD_EVENT_REFERENCE").is_some();
    for scene in &SCENES {
        let (pairs, walls, hash, state) = run(scene);
        let path = fixture(scene);
        if record {
            let mut text = format!("{pairs} {walls} {hash}\n");
            for [x, y, vx, vy] in &state {
                writeln!(text, "{x:?} {y:?} {vx:?} {vy:?}").unwrap();
            }
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(&path, text).unwrap();
            continue;
        }
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|error| panic!("{}: {error}", path.display()));
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap().split(' ').collect();
        let (want_pairs, want_walls, want_hash): (u64, u64, &str) = (
            header[0].parse().unwrap(),
            header[1].parse().unwrap(),
            header[2],
        );
        assert_eq!(
            (pairs, walls),
            (want_pairs, want_walls),
            "{}: collisions",
            scene.name
        );
        let mut worst = 0.0f64;
        for (disk, (line, got)) in lines.zip(&state).enumerate() {
            let want: Vec<f64> = line.split(' ').map(|v| v.parse().unwrap()).collect();
            for (component, (&w, &g)) in want.iter().zip(got).enumerate() {
                let difference = (w - g).abs();
                assert!(
                    difference <= TOLERANCE,
                    "{}: disk {disk} component {component}: {g} against {w}",
                    scene.name
                );
                worst = worst.max(difference);
            }
        }
        println!(
            "{}: {pairs} pair and {walls} wall collisions as recorded; largest difference \
             {worst:e}; bitwise {}",
            scene.name,
            hash == want_hash
        );
    }
}
