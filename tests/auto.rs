//! `method = "auto"` and `dt = "auto"` under `missed_tolerance`: the
//! choice follows the stated cost model, gravity forces the step method, the chosen dt
//! keeps the missed fraction under the tolerance, the choice is deterministic, and bad
//! tolerances are input errors.

use std::path::Path;

use collide::backend::serial;
use collide::run::auto::cost_rates;
use collide::run::overrides::Overrides;
use collide::run::scene_file;
use collide::run::spec::{Method, MethodChoice, Observe};
use collide::run::summary::RunSummary;

use crate::util::{rayon_refuses, three_in_a_row_text};

/// A periodic gas of 2000 unit disks (r = m = v_rms = 1) at `packing`, with `method` lines.
fn gas(packing: f64, extra: &str) -> String {
    format!(
        "[scene]\nn = 2000\npacking = {packing}\nradius = 1.0\nmass = 1.0\nspeed_rms = 1.0\n\
         boundary = \"periodic\"\nseed = 7\n[method]\nsteps = 200\n{extra}"
    )
}

fn run(text: &str, overrides: &Overrides) -> RunSummary {
    let spec = scene_file::parse(Path::new("auto.toml"), text, overrides).unwrap();
    serial::run(&spec).unwrap().summary
}

/// The two cost estimates (seconds) the choice string states, step first.
fn stated_costs(choice: &str) -> (f64, f64) {
    let number_after = |label: &str| -> f64 {
        let start = choice.find(label).unwrap_or_else(|| panic!("{choice}")) + label.len();
        let rest = &choice[start..];
        rest[..rest.find(' ').unwrap()].parse().unwrap()
    };
    (number_after("): step "), number_after(" s, event "))
}

#[test]
fn method_auto_on_a_dilute_fast_gas_picks_what_the_cost_model_says() {
    // Dilute (packing 0.05) and fast (v_rms·dt/r of order 0.04 at the chosen dt): few
    // collisions per step, so events are far cheaper than particle-steps.
    let summary = run(&gas(0.05, "method = \"auto\"\n"), &Overrides::default());
    let choice = summary.choice.clone().expect("auto says what it chose");
    let (step_cost, event_cost) = stated_costs(&choice);
    // The cost model, recomputed from the summary: step = n·steps / R_step; the event
    // estimate is checked against this run's own event count (the pilot ran on the same
    // scene, so the count over the same time can differ only by the run being longer).
    let n = summary.n as f64;
    let rates = cost_rates(n, 0.05);
    let expected_step = n * summary.steps as f64 / rates.step_particle_steps_per_s;
    assert!((step_cost / expected_step - 1.0).abs() < 1e-3, "{choice}");
    let run_events = (summary.pair_collisions + summary.wall_collisions) as f64;
    // Tolerance 30%: the pilot's rate over ~25 time units against the run's over ~10.
    assert!(
        (event_cost
            / (run_events / rates.event_collisions_per_s
                + n * summary.steps as f64 / rates.event_observed_disks_per_s)
            - 1.0)
            .abs()
            < 0.3,
        "{choice}; run events {run_events}"
    );
    let expected = if step_cost <= event_cost {
        "step"
    } else {
        "event"
    };
    assert_eq!(summary.method, expected, "{choice}");
    assert_eq!(
        summary.method, "event",
        "a dilute gas favours events: {choice}"
    );
}

#[test]
fn method_auto_with_gravity_picks_the_step_method() {
    let text = "[scene]\nn = 200\npacking = 0.1\ngravity = [0.0, -1.0]\nseed = 3\n\
                [method]\nmethod = \"auto\"\nsteps = 20\n";
    let summary = run(text, &Overrides::default());
    assert_eq!(summary.method, "step");
    assert!(summary.choice.unwrap().contains("gravity"));
}

#[test]
fn method_auto_picks_the_step_method_when_the_event_pilot_collapses() {
    // Three disks in a row at e = 0.05 collapse without the TC guard (tests/accuracy.rs)
    // at t ≈ 8.4, inside the pilot's span (64 r/v_max = 64).
    let text = three_in_a_row_text(0.05).replace("method = \"event\"", "method = \"auto\"");
    let unguarded = Overrides {
        tc: Some(0.0),
        ..Overrides::default()
    };
    let summary = run(&text, &unguarded);
    let choice = summary.choice.clone().expect("auto says what it chose");
    assert_eq!(summary.method, "step", "{choice}");
    assert!(
        choice.contains("the event method collapsed in its pilot at t = 8."),
        "{choice}"
    );
    // With the guard on the event method does not collapse, and its pilot is costed.
    let summary = run(&text, &Overrides::default());
    let choice = summary.choice.expect("auto says what it chose");
    assert!(!choice.contains("collapsed"), "{choice}");
    assert!(choice.contains("cost model"), "{choice}");
}

#[test]
fn the_chosen_dt_keeps_the_missed_fraction_under_the_tolerance_on_a_fresh_run() {
    // Packing 0.3 misses more than 10⁻³ at the seed's step (docs/accuracy.md), so the ladder has to
    // come down. The fresh run covers the pilot's span (64 r_min / v_max, 64/f steps),
    // from the same initial state: the tolerance is a statement about that span.
    let text = gas(0.3, "dt = \"auto\"\nmissed_tolerance = 1e-3\n");
    let chosen = run(&text, &Overrides::default());
    let fraction = chosen.dt_auto_fraction.unwrap();
    assert!(fraction < 1.0, "{:?}", chosen.choice);
    let overrides = Overrides {
        steps: Some((64.0 / fraction) as i64),
        observe: Some(Observe::Accuracy),
        ..Overrides::default()
    };
    let fresh = run(&text, &overrides);
    assert_eq!(fresh.dt, chosen.dt);
    let missed = fresh.missed_collision_fraction.unwrap();
    assert!(missed <= 1e-3, "missed {missed}; {:?}", fresh.choice);
    // A looser tolerance allows a step at least as large.
    let loose = run(
        &gas(0.3, "dt = \"auto\"\nmissed_tolerance = 0.05\n"),
        &Overrides::default(),
    );
    assert!(loose.dt_auto_fraction.unwrap() >= fraction);
}

#[test]
fn the_choice_is_the_same_twice() {
    let text = gas(0.2, "method = \"auto\"\ndt = \"auto\"\n");
    let overrides = Overrides {
        steps: Some(20),
        ..Overrides::default()
    };
    let (a, b) = (run(&text, &overrides), run(&text, &overrides));
    assert_eq!(a.choice, b.choice);
    assert_eq!((a.method, a.dt), (b.method, b.dt));
    assert_eq!(a.state_hash, b.state_hash);
}

#[test]
fn dt_auto_chooses_the_same_dt_on_the_rayon_backend_and_ends_in_the_same_state() {
    let text = gas(0.2, "dt = \"auto\"\n");
    let overrides = Overrides {
        steps: Some(20),
        ..Overrides::default()
    };
    let spec = scene_file::parse(Path::new("auto.toml"), &text, &overrides).unwrap();
    let serial = serial::run(&spec).unwrap().summary;
    let two = std::num::NonZeroUsize::new(2).unwrap();
    let rayon = collide::backend::threads::run(&spec, two).unwrap().summary;
    assert_eq!((serial.dt, &serial.choice), (rayon.dt, &rayon.choice));
    assert_eq!(serial.state_hash, rayon.state_hash);
}

#[test]
fn dt_fraction_keeps_its_rule_and_explicit_choices_run_no_pilot() {
    let summary = run(
        &gas(0.2, "dt = \"auto\"\ndt_fraction = 0.1\n"),
        &Overrides {
            steps: Some(5),
            ..Overrides::default()
        },
    );
    assert_eq!(summary.dt_auto_fraction, Some(0.1));
    assert_eq!(summary.choice, None);
    let spec = scene_file::parse(
        Path::new("auto.toml"),
        &gas(0.2, ""),
        &Overrides {
            method: Some(MethodChoice::Fixed(Method::Event)),
            ..Overrides::default()
        },
    )
    .unwrap();
    assert_eq!(spec.prepare().unwrap().choice, None);
}

#[test]
fn bad_tolerances_are_input_errors_naming_the_line() {
    for bad in ["0", "1", "-1e-3", "2.0", "nan"] {
        let text = gas(
            0.1,
            &format!("method = \"auto\"\nmissed_tolerance = {bad}\n"),
        );
        let err = scene_file::parse(Path::new("auto.toml"), &text, &Overrides::default())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("auto.toml:12") && err.contains("method.missed_tolerance"),
            "{bad}: {err}"
        );
    }
    rayon_refuses("auto");
}
