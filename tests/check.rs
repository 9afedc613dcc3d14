//! `collide check`: exit codes, a known injected slowdown caught, a known speed-up seen.
//! (The verdict function itself is unit-tested on fixed numbers in `src/stats.rs`.)

use std::path::Path;
use std::process::Output;

use crate::util::{collide, json_summary, scene_file};

const SCENE: &str = "[scene]\nn = 3000\npacking = 0.3\nseed = 5\n[method]\ndt = 0.1\nsteps = 300\n";

/// A tiny check manifest (serial only, a few tens of milliseconds per run) in `dir`.
fn tiny_manifest(dir: &Path) -> String {
    scene_file(dir, "scene.toml", SCENE);
    let text = "name = \"tiny-ci\"\nrepetitions = 7\nwarmups = 1\n\
                [[scenes]]\nfile = \"scene.toml\"\n[backends]\nserial = true\n";
    scene_file(dir, "ci.toml", text)
        .to_str()
        .unwrap()
        .to_owned()
}

/// `collide check MANIFEST --baseline DIR/BASELINE --out DIR/out --quiet --history
/// DIR/history EXTRA...`.
fn check(dir: &Path, manifest: &str, baseline: &str, extra: &[&str]) -> Output {
    let baseline = dir.join(baseline);
    let out = dir.join("out");
    let history = dir.join("history");
    let args = [
        &[
            "check",
            manifest,
            "--baseline",
            baseline.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--quiet",
            "--history",
            history.to_str().unwrap(),
        ],
        extra,
    ]
    .concat();
    collide(&args)
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn a_missing_or_incompatible_baseline_is_an_error_with_exit_code_2() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = tiny_manifest(dir.path());
    let missing = check(dir.path(), &manifest, "nowhere", &[]);
    assert_eq!(missing.status.code(), Some(2), "{}", text(&missing.stderr));
    assert!(text(&missing.stderr).contains("--update-baseline"));

    let old = dir.path().join("old");
    std::fs::create_dir_all(&old).unwrap();
    std::fs::write(old.join("baseline.json"), "{\"format\": 99}").unwrap();
    let incompatible = check(dir.path(), &manifest, "old", &[]);
    assert_eq!(incompatible.status.code(), Some(2));
    assert!(text(&incompatible.stderr).contains("--update-baseline"));
}

/// The README's build has no MPI, and the shipped baseline was recorded by one with it:
/// the check compares what both can run and names the runs it skipped, instead of
/// refusing the baseline.
#[cfg(not(feature = "mpi"))]
#[test]
fn a_build_without_mpi_checks_a_baseline_recorded_with_it_and_names_what_it_skipped() {
    let dir = tempfile::tempdir().unwrap();
    scene_file(dir.path(), "scene.toml", SCENE);
    let manifest_text = "name = \"tiny-ci\"\nrepetitions = 5\nwarmups = 1\n\
                [[scenes]]\nfile = \"scene.toml\"\n[backends]\nserial = true\nmpi = [2]\n";
    let manifest = scene_file(dir.path(), "ci.toml", manifest_text);
    let manifest = manifest.to_str().unwrap();
    let record = check(dir.path(), manifest, "with-mpi", &["--update-baseline"]);
    assert!(record.status.success(), "{}", text(&record.stderr));
    // As a build with MPI records it (its MPI rows aside: this build has none to give).
    let info_path = dir.path().join("with-mpi/baseline.json");
    let info = std::fs::read_to_string(&info_path).unwrap();
    let mut info: serde_json::Value = serde_json::from_str(&info).unwrap();
    info["environment"]["features"] = serde_json::json!("mpi");
    std::fs::write(&info_path, info.to_string()).unwrap();

    let checked = check(dir.path(), manifest, "with-mpi", &[]);
    assert_ne!(checked.status.code(), Some(2), "{}", text(&checked.stderr));
    let stdout = text(&checked.stdout);
    assert!(
        stdout.contains("serial ×1"),
        "the serial runs compared: {stdout}"
    );
    assert!(
        stdout.contains("not checked: the manifest's mpi runs")
            && stdout.contains("--features mpi"),
        "{stdout}"
    );
    // Counted by builds that load different libraries: not compared.
    assert!(
        stdout.contains("instruction counts not compared"),
        "{stdout}"
    );
    assert!(!stdout.contains("instructions (callgrind) |"), "{stdout}");
}

/// The injections are a whole step's time (1.0, not 0.25): this test runs beside the
/// rest of the suite on a shared 2-core machine, where a few tens of milliseconds per
/// run can swing by 25% on their own. docs/ci-check.md gives the smallest slowdown the real
/// manifest catches.
#[test]
fn an_injected_slowdown_regresses_and_an_injected_speed_up_improves() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = tiny_manifest(dir.path());
    let record = check(dir.path(), &manifest, "plain", &["--update-baseline"]);
    assert!(record.status.success(), "{}", text(&record.stderr));
    assert!(dir.path().join("plain/baseline.json").exists());
    assert!(dir.path().join("plain/records.parquet").exists());

    let same = check(dir.path(), &manifest, "plain", &[]);
    let slower = check(
        dir.path(),
        &manifest,
        "plain",
        &["--inject-slowdown", "1.0"],
    );
    assert_eq!(slower.status.code(), Some(1), "{}", text(&slower.stderr));
    let stdout = text(&slower.stdout);
    assert!(stdout.contains("**regressed**"), "{stdout}");
    assert!(dir.path().join("out/summary.md").exists());
    // Every comparing check appended its verdicts to the history, each to a file of its own.
    let histories = std::fs::read_dir(dir.path().join("history"))
        .unwrap()
        .count();
    assert_eq!(histories, 2);
    // Not asserted: the A/A verdict, which is a measured rate (docs/ci-check.md), not a certainty.
    assert_ne!(same.status.code(), Some(2), "{}", text(&same.stderr));

    // A baseline with the slowdown injected, then the plain build: a speed-up.
    let slow = check(
        dir.path(),
        &manifest,
        "slow",
        &["--update-baseline", "--inject-slowdown", "1.0"],
    );
    assert!(slow.status.success(), "{}", text(&slow.stderr));
    let faster = check(dir.path(), &manifest, "slow", &[]);
    assert_eq!(faster.status.code(), Some(0), "{}", text(&faster.stderr));
    let stdout = text(&faster.stdout);
    assert!(stdout.contains("| improved |"), "{stdout}");
}

#[test]
fn an_injected_slowdown_changes_no_bits() {
    let scene = "experiments/scenes/seed-1000.toml";
    let run =
        |extra: &[&str]| json_summary(&[&["simulate", scene, "--steps", "100"], extra].concat());
    for backend in [
        &["--backend", "serial"][..],
        &["--backend", "rayon", "--threads", "2"],
    ] {
        let plain = run(backend);
        let slowed = run(&[backend, &["--inject-slowdown", "0.5"]].concat());
        assert_eq!(plain["state_hash"], slowed["state_hash"], "{backend:?}");
    }
}
