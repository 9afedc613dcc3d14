//! Accuracy against theory and exact cases: the event-driven reference against 2D
//! Maxwell–Boltzmann, Henderson's equation of state, Enskog's collision rate and Haff's
//! cooling law; exact two-disk cases; the step method's missed collisions.
//!
//! Each tolerance is stated where it is used, with why. Runs are seeded: a test passes
//! or fails the same way every time.

use std::f64::consts::PI;
use std::path::Path;

use collide::backend::serial;
use collide::run::overrides::Overrides;
use collide::run::scene_file;
use collide::run::spec::{Method, MethodChoice, Observe, SceneSource};
use collide::sim::event::{EventParams, EventSim};
use collide::sim::scene::{GasSpec, Placement};
use collide::sim::{Boundary, Particles, Physics, Scene};

use crate::util::{
    collide as run_collide, json_summary, rayon_refuses, scene_file as write_scene,
    three_in_a_row_text,
};

/// A periodic gas of unit disks (r = 1, m = 1, v_rms = 1, so T = 0.5) at packing `eta`.
fn periodic_gas(n: usize, eta: f64, restitution: f64, seed: u64) -> Scene {
    GasSpec {
        boundary: Boundary::Periodic,
        physics: Physics::with_restitution(restitution),
        placement: if eta > 0.45 {
            Placement::Lattice
        } else {
            Placement::Random
        },
        seed,
        ..GasSpec::unit(n, eta)
    }
    .build()
    .unwrap()
}

fn event_sim(scene: &Scene) -> (EventSim, Particles) {
    let sim = EventSim::new(
        scene.domain,
        scene.physics,
        EventParams { tc: 1e-6 },
        &scene.particles,
    );
    (sim, scene.particles.clone())
}

/// Kinetic energy per disk: the 2D temperature with k_B = 1.
fn temperature(particles: &Particles) -> f64 {
    let sum: f64 = (0..particles.len())
        .map(|i| 0.5 * particles.mass[i] * (particles.vx[i].powi(2) + particles.vy[i].powi(2)))
        .sum();
    sum / particles.len() as f64
}

/// Henderson's contact value g(σ) = (1 − 7η/16)/(1 − η)² for hard disks.
fn henderson_contact_value(eta: f64) -> f64 {
    (1.0 - 7.0 * eta / 16.0) / (1.0 - eta).powi(2)
}

/// Enskog's collision frequency per disk, ω = 2·n·σ·g(σ)·√(π·T/m), for unit disks.
fn enskog_rate(eta: f64, temperature: f64) -> f64 {
    let n = eta / PI; // disks per unit area: η = n·π·r² with r = 1
    let sigma = 2.0;
    2.0 * n * sigma * henderson_contact_value(eta) * (PI * temperature).sqrt()
}

fn relative(measured: f64, expected: f64) -> f64 {
    (measured - expected).abs() / expected.abs()
}

#[test]
fn event_method_matches_henderson_pressure_and_enskog_collision_rate() {
    // N = 1000 in a periodic box; about 15 collisions per disk to equilibrate (and melt
    // the lattice at η = 0.5), then about 150 per disk measured: ~75,000 collisions, so
    // the statistical error of the virial and of the rate is about 0.4%.
    // Tolerance 2%: Henderson's equation (and its contact value, which Enskog's rate
    // uses) is itself within about 1% of simulation results up to η = 0.5, and a
    // finite system of 1000 disks adds O(1/N).
    let n = 1000;
    for (eta, seed) in [(0.1, 1), (0.2, 2), (0.3, 3), (0.4, 4), (0.5, 5)] {
        let scene = periodic_gas(n, eta, 1.0, seed);
        let (mut sim, mut particles) = event_sim(&scene);
        let omega = enskog_rate(eta, 0.5);
        let t_equilibrate = 15.0 / omega;
        sim.advance_to(&mut particles, t_equilibrate);
        let before = sim.counters();
        let duration = 150.0 / omega;
        sim.advance_to(&mut particles, t_equilibrate + duration);
        let after = sim.counters();
        let t = temperature(&particles);
        // Z = P·A/(N·T) = 1 + Σ d·J / (2·N·T·t): the collision virial.
        let z = 1.0 + (after.virial - before.virial) / (2.0 * n as f64 * t * duration);
        let henderson = (1.0 + eta * eta / 8.0) / (1.0 - eta).powi(2);
        assert!(
            relative(z, henderson) < 0.02,
            "η = {eta}: Z = {z:.4}, Henderson {henderson:.4}"
        );
        let collisions = (after.pair_collisions - before.pair_collisions) as f64;
        let rate = 2.0 * collisions / (n as f64 * duration);
        let enskog = enskog_rate(eta, t);
        assert!(
            relative(rate, enskog) < 0.02,
            "η = {eta}: collision rate {rate:.4}, Enskog {enskog:.4}"
        );
        // Elastic: energy is conserved to rounding over ~10^5 collisions.
        assert!(relative(t, 0.5) < 1e-10, "η = {eta}: T = {t}");
    }
}

/// Kolmogorov–Smirnov distance of the speeds from 2D Maxwell–Boltzmann at temperature
/// `t` (unit masses): F(v) = 1 − exp(−v²/2T).
fn ks_distance_from_maxwell(particles: &Particles, t: f64) -> f64 {
    let mut speeds: Vec<f64> = (0..particles.len())
        .map(|i| particles.vx[i].hypot(particles.vy[i]))
        .collect();
    speeds.sort_by(f64::total_cmp);
    let count = speeds.len() as f64;
    speeds
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let cdf = 1.0 - (-v * v / (2.0 * t)).exp();
            (cdf - i as f64 / count)
                .abs()
                .max((cdf - (i + 1) as f64 / count).abs())
        })
        .fold(0.0, f64::max)
}

#[test]
fn elastic_gas_relaxes_to_the_2d_maxwell_boltzmann_speed_distribution() {
    // Start far from equilibrium: every disk at unit speed (random directions, drift
    // removed), then let the event method run about 20 collisions per disk.
    let n = 2000;
    let mut scene = periodic_gas(n, 0.2, 1.0, 8);
    let p = &mut scene.particles;
    for i in 0..n {
        let speed = p.vx[i].hypot(p.vy[i]);
        p.vx[i] /= speed;
        p.vy[i] /= speed;
    }
    for v in [&mut p.vx, &mut p.vy] {
        let mean = v.iter().sum::<f64>() / n as f64;
        v.iter_mut().for_each(|x| *x -= mean);
    }
    let t = temperature(p);
    // KS critical value at 1% significance for one sample of n: 1.63/√n (0.036 here).
    let critical = 1.63 / (n as f64).sqrt();
    let d_start = ks_distance_from_maxwell(p, t);
    assert!(
        d_start > 5.0 * critical,
        "the start must fail the test: D = {d_start}"
    );
    let (mut sim, mut particles) = event_sim(&scene);
    sim.advance_to(&mut particles, 20.0 / enskog_rate(0.2, t));
    let d_end = ks_distance_from_maxwell(&particles, t);
    assert_eq!(sim.collapse_time(), None);
    assert!(
        d_end < critical,
        "after relaxation D = {d_end:.4}, critical {critical:.4} (start {d_start:.3})"
    );
}

#[test]
fn inelastic_gas_cools_by_haffs_law_early_on() {
    // Homogeneous cooling: dT/dt = −(1 − e²)·ω(T)·T/2 with ω ∝ √T gives
    // T(t) = T₀/(1 + t/t₀)² with t₀ = 4/((1 − e²)·ω₀) (2D, ω₀ Enskog's at T₀).
    // Run to t = t₀ (T falls to a quarter), before clusters form at this size.
    // Tolerance 4%: Enskog's contact value is good to about 1% at η = 0.1, and the
    // cooling state's velocity distribution is not exactly Maxwellian (a few % on the rate
    // at e = 0.9, less on T since the error accumulates slowly); finite N adds noise.
    let (eta, e, n) = (0.1, 0.9, 4000);
    let scene = periodic_gas(n, eta, e, 9);
    let (mut sim, mut particles) = event_sim(&scene);
    let t0_temperature = temperature(&particles);
    let t0 = 4.0 / ((1.0 - e * e) * enskog_rate(eta, t0_temperature));
    for k in 1..=10 {
        let time = t0 * f64::from(k) / 10.0;
        sim.advance_to(&mut particles, time);
        let haff = t0_temperature / (1.0 + time / t0).powi(2);
        let measured = temperature(&particles);
        assert!(
            relative(measured, haff) < 0.04,
            "t = {time:.1} ({k}/10 of t₀): T = {measured:.5}, Haff {haff:.5}"
        );
    }
    assert!(temperature(&particles) < 0.3 * t0_temperature);
    // The TC guard exists for collapse; in this dilute early stage it must be rare.
    assert!(sim.collapse_guard_fired() * 1000 < sim.counters().pair_collisions);
    assert_eq!(sim.collapse_time(), None);
}

/// The three disks of [`three_in_a_row_text`] in an event simulation with TC time `tc`.
fn three_in_a_row(e: f64, tc: f64) -> (EventSim, Particles) {
    let text = three_in_a_row_text(e);
    let spec = scene_file::parse(Path::new("three.toml"), &text, &Overrides::default()).unwrap();
    let SceneSource::Explicit(scene) = spec.scene else {
        panic!("explicit disks")
    };
    let sim = EventSim::new(
        scene.domain,
        scene.physics,
        EventParams { tc },
        &scene.particles,
    );
    (sim, scene.particles)
}

#[test]
fn three_disks_in_a_row_collapse_without_the_guard_and_not_with_it() {
    // In 1D three equal disks collapse (infinitely many collisions in finite time, all
    // gaps closing) for e < 7 − 4√3 ≈ 0.072 (McNamara and Young 1992). At e = 0.05 the
    // middle disk rattles between the outer two at geometrically shorter intervals.
    let (mut sim, mut particles) = three_in_a_row(0.05, 0.0);
    sim.advance_to(&mut particles, 100.0);
    let collapse = sim
        .collapse_time()
        .expect("e = 0.05 without the guard collapses");
    // The first collision is at t = 7 (gap 7 closed at speed 1); the rattling then
    // converges within a few time units. The state is left at the collapse.
    assert!(
        collapse > 7.0 && collapse < 20.0,
        "collapse at t = {collapse}"
    );
    assert_eq!(sim.time(), collapse);
    // At a collapse every gap has closed (to rounding) and, the total momentum being 0,
    // the three have all but stopped: their speeds fell from 1 by about the factor the
    // detector's criterion (1e-6) demands of the collision intervals.
    let gaps = [
        particles.x[1] - particles.x[0] - 2.0,
        particles.x[2] - particles.x[1] - 2.0,
    ];
    assert!(gaps.iter().all(|g| g.abs() < 1e-6), "gaps {gaps:?}");
    assert!(
        particles.vx.iter().all(|v| v.abs() < 1e-4),
        "{:?}",
        particles.vx
    );
    // Nothing more is processed after it.
    let collisions = sim.counters().pair_collisions;
    sim.advance_to(&mut particles, 200.0);
    assert_eq!(sim.counters().pair_collisions, collisions);
    assert_eq!(sim.time(), collapse);

    // With the TC guard a re-collision within tc is elastic: the cluster bounces apart
    // and the run reaches its end.
    let (mut sim, mut particles) = three_in_a_row(0.05, 1e-3);
    sim.advance_to(&mut particles, 100.0);
    assert_eq!(sim.collapse_time(), None);
    assert!(sim.collapse_guard_fired() > 0);
    assert_eq!(sim.time(), 100.0);

    // Above the threshold there is no collapse even without the guard.
    let (mut sim, mut particles) = three_in_a_row(0.2, 0.0);
    sim.advance_to(&mut particles, 100.0);
    assert_eq!(sim.collapse_time(), None);
}

#[test]
fn a_perfectly_inelastic_dense_gas_runs_to_the_end() {
    // Regression: with e = 0 a pair is left touching at zero normal speed; rounding then
    // made it "collide" again at once with zero impulse, forever. Such pairs are now
    // touching, not colliding; clusters still collapse, and the TC guard acts.
    let scene = periodic_gas(500, 0.6, 0.0, 10);
    let (mut sim, mut particles) = event_sim(&scene);
    let t0 = temperature(&particles);
    sim.advance_to(&mut particles, 50.0);
    assert!(sim.collapse_guard_fired() > 0);
    assert_eq!(sim.collapse_time(), None);
    assert!(temperature(&particles) < 0.1 * t0);
    // Overlaps stay at rounding level.
    assert!(
        sim.counters().max_overlap < 1e-9,
        "{}",
        sim.counters().max_overlap
    );
}

#[test]
fn a_collapsed_run_ends_early_with_status_ok_and_says_when() {
    // The three disks of the test above, through the serial backend: 100 intervals of
    // 0.5 asked for, the collapse (t ≈ 8.4) falls in interval 17.
    let text = three_in_a_row_text(0.05);
    let run = |tc: f64| {
        let overrides = Overrides {
            tc: Some(tc),
            ..Overrides::default()
        };
        let spec = scene_file::parse(Path::new("three.toml"), &text, &overrides).unwrap();
        serial::run(&spec).unwrap().summary
    };
    let collapsed = run(0.0);
    let time = collapsed.collapse_time.expect("collapse detected");
    assert_eq!(collapsed.time_reached, Some(time));
    assert_eq!(collapsed.tc, Some(0.0));
    assert_eq!(collapsed.steps, (time / 0.5).ceil() as u64);
    let curve = collapsed.temperature_curve.as_ref().unwrap();
    assert_eq!(
        curve.last().unwrap()[0],
        time,
        "the cooling curve ends at the collapse"
    );
    assert!(
        collapsed.to_string().contains(&format!(
            "inelastic collapse detected at t = {time:.6e}: the event method stopped there, in step {}",
            collapsed.steps
        )),
        "{collapsed}"
    );
    let guarded = run(1e-3);
    assert_eq!(guarded.collapse_time, None);
    assert_eq!((guarded.steps, guarded.time_reached), (100, Some(50.0)));
}

fn run_scene_text(
    text: &str,
    method: Method,
    observe: Observe,
) -> collide::run::summary::RunSummary {
    let overrides = Overrides {
        method: Some(MethodChoice::Fixed(method)),
        observe: Some(observe),
        ..Overrides::default()
    };
    let spec = scene_file::parse(Path::new("test.toml"), text, &overrides).unwrap();
    serial::run(&spec).unwrap().summary
}

#[test]
fn two_disks_head_on_meet_at_the_exact_time_with_the_exact_velocities() {
    // Gap 18 closed at relative speed 2: contact at t = 9, velocities exchanged, so at
    // t = 12 the disks are at 49 − 3 = 46 and 51 + 3 = 54.
    let text = std::fs::read_to_string("experiments/scenes/two-disks-head-on.toml").unwrap();
    let overrides = Overrides {
        method: Some(MethodChoice::Fixed(Method::Event)),
        ..Overrides::default()
    };
    let spec = scene_file::parse(Path::new("head-on.toml"), &text, &overrides).unwrap();
    let outcome = serial::run(&spec).unwrap();
    let s = &outcome.summary;
    assert_eq!((s.pair_collisions, s.wall_collisions), (1, 0));
    assert_eq!(s.missed_collisions, Some(0));
    let disks = outcome.final_state.unwrap().disks_by_id();
    assert_eq!((disks[0].vx, disks[1].vx), (-1.0, 1.0));
    // dt = 0.001 over 12,000 intervals: each interval's end is k·dt, so the positions
    // carry only rounding (a few ulps of 50 per interval at most).
    assert!((disks[0].x - 46.0).abs() < 1e-9, "{}", disks[0].x);
    assert!((disks[1].x - 54.0).abs() < 1e-9, "{}", disks[1].x);
    assert_eq!(s.energy_relative_error, Some(0.0));
}

/// Two disks of radius 1 closing at 60 per unit time with a gap of 19: one step of
/// dt = 1 carries them through each other.
const TUNNELLING: &str = r#"
[scene]
size = [100.0, 100.0]
[[scene.particle]]
x = 40.0
y = 50.0
vx = 30.0
[[scene.particle]]
x = 61.0
y = 50.0
vx = -30.0
[method]
dt = 1.0
steps = 1
"#;

#[test]
fn large_steps_tunnel_and_the_step_method_reports_the_missed_collision() {
    let step = run_scene_text(TUNNELLING, Method::Step, Observe::Accuracy);
    assert_eq!(step.pair_collisions, 0, "the step method cannot see it");
    assert_eq!(step.missed_collisions, Some(1));
    assert_eq!(step.missed_collision_fraction, Some(1.0));
    let event = run_scene_text(TUNNELLING, Method::Event, Observe::Timing);
    assert_eq!(event.pair_collisions, 1);
    assert_eq!(event.missed_collisions, Some(0));
    // Timing runs of the step method do not pay for the swept test: null, not 0.
    let timing = run_scene_text(TUNNELLING, Method::Step, Observe::Timing);
    assert_eq!(timing.missed_collisions, None);
}

#[test]
fn event_and_small_step_methods_agree_on_a_dilute_gas() {
    // The seed scene (1000 disks, packing 0.05, walls) for 100 time units: about 4300
    // collisions. With v_rms·dt = 0.01·r a step misses only grazing contacts shorter than
    // a step (a fraction ~(v·dt/σ)²/8 of them), so the counts differ by chaos alone:
    // the trajectories decorrelate, and two independent counts of ~4300 differ by
    // ~1.5·√2 % at one σ. Tolerance 5%, about 2.5 σ. The step run must also miss
    // fewer than 1e-3 of its collisions (the default `missed_tolerance`).
    let text = std::fs::read_to_string("experiments/scenes/seed-1000.toml")
        .unwrap()
        .replace("dt = 0.1", "dt = 0.01")
        .replace("steps = 400", "steps = 10000");
    let step = run_scene_text(&text, Method::Step, Observe::Accuracy);
    let event = run_scene_text(&text, Method::Event, Observe::Timing);
    assert!(event.pair_collisions > 3000, "{}", event.pair_collisions);
    let (a, b) = (step.pair_collisions as f64, event.pair_collisions as f64);
    assert!(relative(a, b) < 0.05, "step {a}, event {b}");
    assert!(
        step.missed_collision_fraction.unwrap() < 1e-3,
        "{:?}",
        step.missed_collisions
    );
    // Walls: the virial pressure is a bulk estimate; both methods give the same one.
    let (za, zb) = (
        step.compressibility_z.unwrap(),
        event.compressibility_z.unwrap(),
    );
    assert!(relative(za, zb) < 0.05, "Z step {za}, event {zb}");
}

/// A scene file in a fresh temporary folder, which lives as long as the returned guard.
fn temp_scene(name: &str, text: &str) -> (tempfile::TempDir, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = write_scene(dir.path(), name, text);
    (dir, path.to_str().unwrap().to_owned())
}

#[test]
fn the_event_method_refuses_gravity_and_parallel_backends_with_clear_errors() {
    let (_dir, falling) = temp_scene(
        "falling.toml",
        "[scene]\nn = 10\npacking = 0.1\ngravity = [0.0, -9.81]\n[method]\nmethod = \"event\"\nsteps = 5\n",
    );
    let out = run_collide(&["simulate", &falling]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("falling.toml:4") && stderr.contains("scene.gravity"),
        "{stderr}"
    );
    rayon_refuses("event");
}

/// The JSON summary of 50 steps of the seed scene with more flags.
fn seed_scene_summary(flags: &[&str]) -> serde_json::Value {
    let base = [
        "simulate",
        "experiments/scenes/seed-1000.toml",
        "--steps",
        "50",
    ];
    json_summary(&[&base[..], flags].concat())
}

#[test]
fn the_json_summary_carries_the_accuracy_fields_of_both_methods() {
    for method in ["step", "event"] {
        let json = seed_scene_summary(&["--method", method]);
        assert_eq!(json["method"], method);
        for field in [
            "collision_rate",
            "temperature",
            "pressure",
            "compressibility_z",
            "mean_overlap",
            "energy_relative_error",
        ] {
            assert!(json[field].is_f64(), "{method}: {field} = {}", json[field]);
        }
        assert_eq!(json["events_per_s"].is_f64(), method == "event");
        assert_eq!(json["missed_collisions"].is_u64(), method == "event");
        // Elastic scene: no cooling curve, no collapse guard, no collapse.
        assert!(json["temperature_curve"].is_null());
        assert!(json["collapse_guard_fired"].is_null());
        assert!(json["collapse_time"].is_null());
        assert_eq!(json["tc"].is_f64(), method == "event");
        assert!(json["time_reached"].is_f64());
    }
    let json = seed_scene_summary(&[
        "--method",
        "event",
        "--packing",
        "0.3",
        "--n",
        "500",
        "--dt",
        "0.5",
    ]);
    assert!(json["energy_relative_error"].as_f64().unwrap().abs() < 1e-12);
    let (_dir, cooling) = temp_scene(
        "cooling.toml",
        "[scene]\nn = 500\npacking = 0.2\nrestitution = 0.8\nboundary = \"periodic\"\n[method]\nmethod = \"event\"\ndt = 0.5\nsteps = 100\n",
    );
    let json = json_summary(&["simulate", &cooling]);
    let curve = json["temperature_curve"].as_array().unwrap();
    assert_eq!(curve.len(), 41);
    let first = curve[0][1].as_f64().unwrap();
    let last = curve[40][1].as_f64().unwrap();
    assert_eq!(curve[40][0].as_f64().unwrap(), 50.0);
    assert!(last < 0.5 * first, "{first} → {last}");
    assert!(json["collapse_guard_fired"].is_u64());
    assert!(json["energy_relative_error"].is_null());
    // Guarded (default tc): no collapse, the run reaches its end.
    assert!(json["collapse_time"].is_null());
    assert_eq!(json["time_reached"].as_f64(), Some(50.0));
    assert_eq!(json["steps"].as_u64(), Some(100));
}
