//! Helpers shared by the integration tests: running the `collide` binary, writing scene
//! and manifest files, sample records, and watching child processes.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use collide::run::backend_kind::BackendKind;
use collide::run::summary::RunSummary;
use collide::study::environment::Environment;
use collide::study::records::{self, Record, RecordContext, STATUS_TIMED_OUT};

/// The scene of [`manifest`]: 200 disks, 20 steps.
pub const SCENE: &str =
    "[scene]\nn = 200\npacking = 0.1\nseed = 3\n[method]\ndt = 0.1\nsteps = 20\n";

/// Runs `collide ARGS` in `dir`, which must fail with exit 2 within 5 s; its stderr. A
/// run still going then is killed first: a bad input that is accepted (say n = 10⁹) must
/// not go on to fill the machine.
pub fn refused_in(dir: &Path, args: &[&str]) -> String {
    let mut child = Command::new(env!("CARGO_BIN_EXE_collide"))
        .args(args)
        .current_dir(dir)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if started.elapsed() > Duration::from_secs(5) {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("{args:?} was still running after 5 s");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
    stderr
}

/// Runs the `collide` binary from the crate folder and waits for its output.
pub fn collide(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_collide"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("the collide binary runs")
}

/// The JSON summary of `collide ARGS --json`, which must succeed.
pub fn json_summary(args: &[&str]) -> serde_json::Value {
    let out = collide(&[args, &["--json"]].concat());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{args:?} failed: {stderr}");
    let stdout = String::from_utf8(out.stdout).unwrap();
    serde_json::from_str(stdout.lines().last().unwrap()).unwrap()
}

/// Writes `text` to `dir/name` and returns its path.
pub fn scene_file(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// `collide run MANIFEST --out OUT --no-report`, not started yet.
pub fn study_command(manifest: &str, out: &Path) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_collide"));
    command
        .args([
            "run",
            manifest,
            "--out",
            out.to_str().unwrap(),
            "--no-report",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"));
    command
}

/// `collide run MANIFEST --out OUT --no-report EXTRA...`, waited for.
pub fn run_study(manifest: &str, out: &Path, extra: &[&str]) -> Output {
    study_command(manifest, out)
        .args(extra)
        .output()
        .expect("the collide binary runs")
}

/// A manifest over `scene.toml` (written beside it) with the given extra text.
pub fn manifest(dir: &Path, body: &str) -> String {
    scene_file(dir, "scene.toml", SCENE);
    let text = format!("name = \"tiny\"\n{body}\n[[scenes]]\nfile = \"scene.toml\"\n");
    scene_file(dir, "tiny.toml", &text)
        .to_str()
        .unwrap()
        .to_owned()
}

/// Two records of a rayon run of the seed scene: one measured, one timed out.
pub fn sample_records() -> Vec<Record> {
    let environment = Environment::capture();
    let context = RecordContext {
        study: "s",
        manifest_hash: "m",
        build_id: "b",
        config_key: "k",
        scene: "seed",
        scene_hash: "0123456789abcdef",
        scaling: "strong",
        backend: BackendKind::Rayon,
        placement: BackendKind::Rayon.placement(2),
        repetition: 1,
        environment: &environment,
        study_started_utc: "2026-11-22T00:00:00Z",
    };
    let json = json_summary(&[
        "simulate",
        "experiments/scenes/seed-1000.toml",
        "--steps",
        "10",
    ]);
    let summary: RunSummary = serde_json::from_value(json).unwrap();
    vec![
        Record::measured(&context, &summary),
        Record::failed(&context, STATUS_TIMED_OUT, "killed after 1 s".into()),
    ]
}

/// Processes whose command line mentions `needle`.
/// The command lines of the running processes that contain `needle`.
pub fn processes_mentioning(needle: &str) -> Vec<String> {
    std::fs::read_dir("/proc")
        .unwrap()
        .filter_map(|entry| std::fs::read(entry.ok()?.path().join("cmdline")).ok())
        .map(|bytes| String::from_utf8_lossy(&bytes).replace('\0', " "))
        .filter(|cmdline| cmdline.contains(needle))
        .collect()
}

/// Starts `collide run MANIFEST --quiet --out OUT` in its own process group, waits until
/// it has written one more results file into `OUT/STUDY`, then sends `signal` to the
/// group as a terminal's Ctrl-C would (reaching it and not this test). Its output.
pub fn interrupt_after_first_row(
    manifest: &str,
    out: &Path,
    study: &str,
    signal: rustix::process::Signal,
) -> std::process::Output {
    use std::os::unix::process::CommandExt;

    let folder = out.join(study);
    let count = || records::files_in(&folder).map_or(0, |files| files.len());
    let before = count();
    let child = study_command(manifest, out)
        .arg("--quiet")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .process_group(0)
        .spawn()
        .unwrap();
    let started = Instant::now();
    while count() == before {
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "no results file appeared"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(300));
    let group = rustix::process::Pid::from_raw(child.id() as i32).unwrap();
    rustix::process::kill_process_group(group, signal).unwrap();
    child.wait_with_output().unwrap()
}

/// Three unit disks on one line in a 100 × 100 walled box, the outer two closing in on
/// the middle one (off centre, so no two collisions coincide), at restitution `e`: 100
/// intervals of 0.5 of the event method.
pub fn three_in_a_row_text(e: f64) -> String {
    format!(
        "[scene]\nsize = [100.0, 100.0]\nrestitution = {e}\n\
         [[scene.particle]]\nx = 40.0\ny = 50.0\nvx = 1.0\n\
         [[scene.particle]]\nx = 49.0\ny = 50.0\n\
         [[scene.particle]]\nx = 60.0\ny = 50.0\nvx = -1.0\n\
         [method]\nmethod = \"event\"\ndt = 0.5\nsteps = 100\n"
    )
}

/// `--method method` with the rayon backend is an input error: the event method (which
/// `auto` may choose) is serial only.
pub fn rayon_refuses(method: &str) {
    let out = collide(&[
        "simulate",
        "experiments/scenes/seed-1000.toml",
        "--method",
        method,
        "--backend",
        "rayon",
        "--threads",
        "2",
    ]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("serial backend only"), "{stderr}");
}

/// `collide report RESULTS --out REPORTS`, which must succeed; the text of its report.md.
pub fn report_of(results: &std::path::Path, reports: &std::path::Path) -> String {
    let report = collide(&[
        "report",
        results.to_str().unwrap(),
        "--out",
        reports.to_str().unwrap(),
    ]);
    assert!(
        report.status.success(),
        "{}",
        String::from_utf8_lossy(&report.stderr)
    );
    std::fs::read_to_string(reports.join("report.md")).unwrap()
}
