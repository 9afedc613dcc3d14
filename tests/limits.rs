//! Non-finite and out-of-range physics: every scene field, drawn from ordinary values,
//! extremes, zero, negatives, NaN and infinities, is either refused naming a field, or
//! runs to a finite energy with every disk in (or within one step of) its box.

use std::path::Path;

use collide::backend::serial;
use collide::run::overrides::Overrides;
use collide::run::scene_file;
use proptest::prelude::*;
use proptest::test_runner::{RngAlgorithm, TestCaseError, TestRng, TestRunner};

/// A value of any kind a careless user or script might write.
fn wild(ordinary: std::ops::Range<f64>) -> impl Strategy<Value = f64> {
    prop_oneof![
        30 => ordinary,
        1 => prop::sample::select(vec![
            0.0, -1.0, 1e-300, 1e300, 5e-324, f64::MAX, f64::NAN, f64::INFINITY,
            f64::NEG_INFINITY, 1e-12, 1e12,
        ]),
        1 => prop::num::f64::ANY,
    ]
}

/// `value` as TOML writes it.
fn toml(value: f64) -> String {
    match value {
        v if v.is_nan() => "nan".to_owned(),
        v if v == f64::INFINITY => "inf".to_owned(),
        v if v == f64::NEG_INFINITY => "-inf".to_owned(),
        v => format!("{v:?}"),
    }
}

/// A drawn radius: one for every disk, or a range random scenes draw from.
#[derive(Clone, Debug)]
enum RadiusDraw {
    Fixed(f64),
    Range(f64, f64),
}

/// A drawn mass: one for every disk, or proportional to the disk's area.
#[derive(Clone, Debug)]
enum MassDraw {
    Fixed(f64),
    Area,
}

/// One `[[scene.particle]]` entry: position, velocity, and its own radius and mass.
#[derive(Clone, Debug)]
struct DrawnDisk {
    x: f64,
    y: f64,
    vx: f64,
    vy: f64,
    radius: Option<f64>,
    mass: Option<f64>,
}

/// A scene file's text from drawn values: a random scene, or (with `disks`) one that
/// lists its disks, which takes no `n`, `packing`, `speed_rms`, `seed` or `placement`
/// and needs a `size` (100 × 100 when none was drawn).
#[derive(Clone, Debug)]
struct Drawn {
    n: i64,
    packing: f64,
    size: Option<(f64, f64)>,
    radius: RadiusDraw,
    mass: MassDraw,
    speed_rms: f64,
    restitution: f64,
    wall_restitution: f64,
    gravity: Option<(f64, f64)>,
    periodic: bool,
    /// `Some(true)`: a lattice; `Some(false)`: random addition; `None`: the default.
    lattice: Option<bool>,
    seed: u64,
    disks: Option<Vec<DrawnDisk>>,
    dt: f64,
    steps: i64,
}

impl Drawn {
    fn text(&self) -> String {
        let mut lines = vec!["[scene]".to_owned()];
        let size = |(w, h): (f64, f64)| format!("size = [{}, {}]", toml(w), toml(h));
        match (&self.disks, self.size) {
            (Some(_), extent) => lines.push(size(extent.unwrap_or((100.0, 100.0)))),
            (None, Some(extent)) => lines.push(size(extent)),
            (None, None) => lines.push(format!("packing = {}", toml(self.packing))),
        }
        if self.disks.is_none() {
            lines.push(format!("n = {}", self.n));
            lines.push(format!("speed_rms = {}", toml(self.speed_rms)));
            lines.push(format!("seed = {}", self.seed));
            if let Some(lattice) = self.lattice {
                let name = if lattice { "lattice" } else { "random" };
                lines.push(format!("placement = \"{name}\""));
            }
        }
        lines.push(match self.radius {
            RadiusDraw::Fixed(r) => format!("radius = {}", toml(r)),
            RadiusDraw::Range(min, max) => {
                format!("radius = {{ min = {}, max = {} }}", toml(min), toml(max))
            }
        });
        lines.push(match self.mass {
            MassDraw::Fixed(m) => format!("mass = {}", toml(m)),
            MassDraw::Area => "mass = \"area\"".to_owned(),
        });
        lines.push(format!("restitution = {}", toml(self.restitution)));
        lines.push(format!(
            "wall_restitution = {}",
            toml(self.wall_restitution)
        ));
        if let Some((gx, gy)) = self.gravity {
            lines.push(format!("gravity = [{}, {}]", toml(gx), toml(gy)));
        }
        let boundary = if self.periodic { "periodic" } else { "walls" };
        lines.push(format!("boundary = \"{boundary}\""));
        for disk in self.disks.iter().flatten() {
            lines.push("[[scene.particle]]".to_owned());
            lines.push(format!(
                "x = {}\ny = {}\nvx = {}\nvy = {}",
                toml(disk.x),
                toml(disk.y),
                toml(disk.vx),
                toml(disk.vy)
            ));
            if let Some(r) = disk.radius {
                lines.push(format!("radius = {}", toml(r)));
            }
            if let Some(m) = disk.mass {
                lines.push(format!("mass = {}", toml(m)));
            }
        }
        lines.push(format!(
            "[method]\ndt = {}\nsteps = {}\n",
            toml(self.dt),
            self.steps
        ));
        lines.join("\n")
    }
}

fn radius() -> impl Strategy<Value = RadiusDraw> {
    prop_oneof![
        4 => wild(0.1..2.0).prop_map(RadiusDraw::Fixed),
        1 => (wild(0.1..1.0), wild(0.5..2.0)).prop_map(|(min, max)| RadiusDraw::Range(min, max)),
    ]
}

fn mass() -> impl Strategy<Value = MassDraw> {
    prop_oneof![
        4 => wild(0.1..5.0).prop_map(MassDraw::Fixed),
        1 => Just(MassDraw::Area),
    ]
}

fn disk() -> impl Strategy<Value = DrawnDisk> {
    (
        (wild(1.0..99.0), wild(1.0..99.0)),
        (wild(-2.0..2.0), wild(-2.0..2.0)),
        prop::option::weighted(0.3, wild(0.1..2.0)),
        prop::option::weighted(0.3, wild(0.1..5.0)),
    )
        .prop_map(|((x, y), (vx, vy), radius, mass)| DrawnDisk {
            x,
            y,
            vx,
            vy,
            radius,
            mass,
        })
}

fn drawn() -> impl Strategy<Value = Drawn> {
    (
        (prop_oneof![8 => 1i64..120, 1 => -2i64..1], wild(0.01..0.4)),
        prop::option::weighted(0.2, (wild(5.0..100.0), wild(5.0..100.0))),
        (radius(), mass(), wild(0.0..3.0)),
        (wild(0.5..1.0), wild(0.5..1.0)),
        prop::option::weighted(0.2, (wild(-2.0..2.0), wild(-2.0..2.0))),
        (
            any::<bool>(),
            wild(0.001..0.5),
            prop_oneof![8 => 1i64..30, 1 => -1i64..1],
        ),
        (
            prop::option::weighted(0.3, any::<bool>()),
            // TOML integers are i64: a larger seed cannot be written.
            0..=i64::MAX as u64,
            prop::option::weighted(0.25, prop::collection::vec(disk(), 0..6)),
        ),
    )
        .prop_map(
            |(
                (n, packing),
                size,
                (radius, mass, speed_rms),
                (restitution, wall_restitution),
                gravity,
                (periodic, dt, steps),
                (lattice, seed, disks),
            )| Drawn {
                n,
                packing,
                size,
                radius,
                mass,
                speed_rms,
                restitution,
                wall_restitution,
                gravity,
                periodic,
                lattice,
                seed,
                disks,
                dt,
                steps,
            },
        )
}

/// Every field a refusal may name.
const FIELDS: &[&str] = &[
    "scene.n",
    "scene.packing",
    "scene.size",
    "scene.radius",
    "scene.mass",
    "scene.speed_rms",
    "scene.restitution",
    "scene.wall_restitution",
    "scene.gravity",
    "scene.placement",
    "scene.seed",
    "scene.particle",
    "method.dt",
    "method.steps",
    // Placement refusals name the packing the box could not hold, or the boundary whose
    // periodic box is too small for its disks.
    "packing",
    "boundary",
];

/// Refused naming a field (as `collide` would, with exit code 2), or run to a finite
/// energy with the disks in their box; the reason it is neither otherwise.
fn refused_or_sound(text: &str) -> Result<Outcome, String> {
    let refusal = |message: String| match FIELDS.iter().any(|field| message.contains(field)) {
        true => Ok(Outcome::Refused),
        false => Err(format!("refused without naming a field: {message}")),
    };
    let spec = match scene_file::parse(Path::new("wild.toml"), text, &Overrides::default()) {
        Err(err) => return refusal(err.to_string()),
        Ok(spec) => spec,
    };
    let outcome = match serial::run(&spec) {
        Err(err) => return refusal(err.to_string()),
        Ok(outcome) => outcome,
    };
    let summary = &outcome.summary;
    if !(summary.kinetic_energy_final.is_finite() && summary.kinetic_energy_initial.is_finite()) {
        return Err(format!(
            "energy {} → {}",
            summary.kinetic_energy_initial, summary.kinetic_energy_final
        ));
    }
    let prepared = spec.prepare().map_err(|e| e.to_string())?;
    let domain = prepared.scene.domain;
    let particles = outcome
        .final_state
        .as_ref()
        .expect("serial runs keep the final state");
    // Without a field energy never grows, so no disk is ever faster than v_bound, and a
    // disk at a wall overshoots it by at most one step before it is turned back (or
    // stopped there, with wall_restitution = 0). With a field, coarse steps let disks
    // sink through a wall step by step (a known limit of the step method, not checked
    // here); energy and positions must still be finite.
    let min_mass = particles
        .mass
        .iter()
        .fold(f64::INFINITY, |a: f64, &m| a.min(m));
    let v_bound = (2.0 * summary.kinetic_energy_initial / min_mass).sqrt();
    let max_radius = particles.radius.iter().fold(0.0, |a: f64, &r| a.max(r));
    let slack = match domain_has_field(&prepared) {
        true => f64::INFINITY,
        false => v_bound * summary.dt * (1.0 + 1e-9) + max_radius,
    };
    for i in 0..particles.len() {
        let (x, y) = (particles.x[i], particles.y[i]);
        let inside = |p: f64, length: f64| p.is_finite() && p >= -slack && p <= length + slack;
        if !(inside(x, domain.width) && inside(y, domain.height)) {
            return Err(format!(
                "disk {i} at ({x}, {y}) outside the {} × {} box",
                domain.width, domain.height
            ));
        }
    }
    Ok(Outcome::Ran)
}

fn domain_has_field(prepared: &collide::run::spec::PreparedRun) -> bool {
    prepared.scene.physics.gravity.is_some()
}

/// How a sound scene ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Outcome {
    Refused,
    Ran,
}

#[test]
fn every_scene_field_is_refused_by_name_or_runs_to_finite_physics() {
    // Each case places up to 120 disks and runs up to 30 steps: 300 cases take seconds.
    // A fixed seed: the same 300 scenes on every run and machine.
    let mut runner = TestRunner::new_with_rng(
        ProptestConfig {
            cases: 300,
            // The seed is fixed: a failing scene is printed, and recurs, without a file.
            failure_persistence: None,
            ..ProptestConfig::default()
        },
        TestRng::deterministic_rng(RngAlgorithm::ChaCha),
    );
    // Outcomes of random scenes, then of scenes that list their disks.
    let counts = std::cell::RefCell::new([[0usize; 2]; 2]);
    runner
        .run(&drawn(), |scene| {
            let text = scene.text();
            let outcome = refused_or_sound(&text)
                .map_err(|reason| TestCaseError::fail(format!("{reason}\n{text}")))?;
            counts.borrow_mut()[usize::from(scene.disks.is_some())][outcome as usize] += 1;
            Ok(())
        })
        .unwrap();
    let [[refused, ran], [refused_listed, ran_listed]] = counts.into_inner();
    eprintln!(
        "random scenes: {refused} refused naming a field, {ran} ran to finite physics; \
         listed disks: {refused_listed} refused, {ran_listed} ran"
    );
    // Both outcomes must be common, or the test stopped trying one of them.
    assert!(refused >= 40 && ran >= 40, "{refused} refused, {ran} ran");
    assert!(
        refused_listed >= 10 && ran_listed >= 10,
        "listed disks: {refused_listed} refused, {ran_listed} ran"
    );
}

#[test]
fn the_reported_non_finite_scenes_are_refused_naming_the_field() {
    let cases = [
        // Energy inf, Z NaN, disks at the origin before.
        ("speed_rms = 1e300\n", "dt = 1e300", "scene.speed_rms"),
        // Packing NaN before.
        ("radius = 1e-300\n", "dt = 0.1", "scene.radius"),
        ("radius = 1e200\n", "dt = 0.1", "scene.radius"),
        ("", "dt = 1e300", "method.dt"),
        ("", "dt = 1e-300", "method.dt"),
        ("gravity = [0.0, -1e300]\n", "dt = 0.1", "scene.gravity"),
    ];
    for (scene, dt, field) in cases {
        let text = format!("[scene]\nn = 50\npacking = 0.1\n{scene}[method]\n{dt}\nsteps = 5\n");
        let err = scene_file::parse(Path::new("s.toml"), &text, &Overrides::default())
            .expect_err(&text)
            .to_string();
        assert!(err.contains(field), "{field}: {err}");
    }
}
