//! Faults a careless user, a script or a failing machine bring: damaged and foreign
//! results files fed to every reader, a hard kill of `collide run`, a study run away
//! from the checkout, results of several studies in one folder.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use collide::records::{self, Record};
use polars::prelude::{Column, DataFrame, ParquetWriter};

use crate::cli::{collide, scene_file};
use crate::study::{manifest, processes_mentioning, sample_records};

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Exit code 2 with a message that names `file`, and no panic.
fn assert_refused(output: &Output, file: &Path, what: &str) {
    let stderr = text(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{what}: {stderr}");
    assert!(!stderr.contains("panicked"), "{what}: {stderr}");
    let name = file.file_name().unwrap().to_str().unwrap();
    assert!(stderr.contains(name), "{what}: `{name}` not in {stderr}");
}

fn write_frame(path: &Path, frame: &mut DataFrame) {
    let file = std::fs::File::create(path).unwrap();
    ParquetWriter::new(file).finish(frame).unwrap();
}

/// Every kind of results file that is not one, by file name, in `dir`, with the
/// fragment of the reason each must be refused with.
fn damaged_files(dir: &Path, good: &Path) -> Vec<(PathBuf, &'static str)> {
    let bytes = std::fs::read(good).unwrap();
    let mut files = vec![
        (scene_file(dir, "empty.parquet", ""), "empty (0 bytes)"),
        (
            scene_file(dir, "text.parquet", "study,wall_s\nx,1\n"),
            "not a readable Parquet file",
        ),
    ];
    // Cut at the start, in the data and in the footer.
    for cut in [4, 12, bytes.len() / 2, bytes.len() - 9, bytes.len() - 1] {
        let path = dir.join(format!("cut-{cut}.parquet"));
        std::fs::write(&path, &bytes[..cut]).unwrap();
        files.push((path, "not a readable Parquet file"));
    }
    let zero_rows = dir.join("zero-rows.parquet");
    records::write(&zero_rows, &[]).unwrap();
    files.push((zero_rows, "holds no runs"));
    let foreign = dir.join("foreign.parquet");
    write_frame(
        &foreign,
        &mut DataFrame::new_infer_height(vec![Column::new("x".into(), vec![1.0, 2.0])]).unwrap(),
    );
    files.push((foreign, "no `schema_version` column"));
    let mut frame = records::to_frame(&sample_records()).unwrap();
    frame
        .with_column(Column::new("wall_s".into(), vec!["fast", "slow"]))
        .unwrap();
    let mistyped = dir.join("mistyped.parquet");
    write_frame(&mistyped, &mut frame);
    files.push((mistyped, "column `wall_s` does not hold a number"));
    files
}

#[test]
fn damaged_empty_and_foreign_results_files_never_panic_a_reader() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.parquet");
    records::write(&good, &sample_records()).unwrap();
    let bad = dir.path().join("bad");
    std::fs::create_dir(&bad).unwrap();
    let files = damaged_files(&bad, &good);
    // Named on its own, each is refused with its reason by both readers.
    for (file, reason) in &files {
        let out = dir.path().join("report");
        let file = file.to_str().unwrap();
        for args in [
            &["results", file][..],
            &["report", file, "--out", out.to_str().unwrap()],
        ] {
            let output = collide(args);
            assert_refused(&output, Path::new(file), args[0]);
            assert!(
                text(&output.stderr).contains(reason),
                "{file}: {}",
                text(&output.stderr)
            );
        }
    }
    // In a folder beside a good file, each is skipped with a warning naming it.
    std::fs::copy(&good, bad.join("good.parquet")).unwrap();
    let table = collide(&["results", bad.to_str().unwrap()]);
    let stderr = text(&table.stderr);
    assert!(table.status.success(), "{stderr}");
    assert!(
        text(&table.stdout).contains("rayon"),
        "{}",
        text(&table.stdout)
    );
    for (file, reason) in &files {
        let name = file.file_name().unwrap().to_str().unwrap();
        assert!(
            stderr
                .lines()
                .any(|l| l.starts_with("warning: skipped") && l.contains(name))
                && stderr.contains(reason),
            "{name}: {stderr}"
        );
    }
    let out = dir.path().join("report");
    let report = collide(&[
        "report",
        bad.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(report.status.success(), "{}", text(&report.stderr));
    assert!(out.join("report.md").exists());
    // A folder of nothing but damaged files is refused.
    std::fs::remove_file(bad.join("good.parquet")).unwrap();
    let nothing = collide(&["results", bad.to_str().unwrap()]);
    assert_eq!(nothing.status.code(), Some(2));
    assert!(
        text(&nothing.stderr).contains("no readable runs"),
        "{}",
        text(&nothing.stderr)
    );
}

#[test]
fn resume_passes_over_damaged_files_and_check_refuses_a_damaged_baseline() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results");
    let path = manifest(
        dir.path(),
        "repetitions = 2\nwarmups = 0\n[backends]\nserial = true\n",
    );
    let run = |extra: &[&str]| {
        collide(
            &[
                &[
                    "run",
                    path.as_str(),
                    "--quiet",
                    "--out",
                    out.to_str().unwrap(),
                ],
                extra,
            ]
            .concat(),
        )
    };
    assert!(run(&[]).status.success());
    let study = out.join("tiny");
    let good = records::files_in(&study).unwrap().remove(0);
    let rows = records::read(&good).unwrap();
    records::write(&good, &rows[..1]).unwrap();
    // Damaged files named to sort after (newer than) the good one.
    let files = damaged_files(&study, &good);
    for (file, _) in &files {
        std::fs::rename(
            file,
            study.join(format!("~{}", file.file_name().unwrap().to_str().unwrap())),
        )
        .unwrap();
    }
    let resumed = run(&["--resume"]);
    let stderr = text(&resumed.stderr);
    assert!(resumed.status.success(), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        text(&resumed.stdout).contains("1 kept"),
        "{}",
        text(&resumed.stdout)
    );
    assert!(
        stderr.contains("not resuming from") && stderr.contains("cut-4"),
        "{stderr}"
    );
    assert_eq!(records::read(&good).unwrap().len(), 2);

    // The committed baseline with its records replaced by a damaged file.
    let baseline = dir.path().join("baseline");
    std::fs::create_dir(&baseline).unwrap();
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    // Made to match this build, so that only its records stand in the way.
    let info = std::fs::read_to_string(repo.join("results/baseline/baseline.json")).unwrap();
    let mut info: serde_json::Value = serde_json::from_str(&info).unwrap();
    info["environment"]["features"] = if cfg!(feature = "mpi") { "mpi" } else { "" }.into();
    info["environment"]["profile"] = if cfg!(debug_assertions) {
        "debug"
    } else {
        "release"
    }
    .into();
    std::fs::write(baseline.join("baseline.json"), info.to_string()).unwrap();
    let records_file = baseline.join("records.parquet");
    std::fs::write(&records_file, b"PAR1 nothing here").unwrap();
    let check = collide(&[
        "check",
        "experiments/ci.toml",
        "--baseline",
        baseline.to_str().unwrap(),
        "--out",
        dir.path().join("check").to_str().unwrap(),
        "--quiet",
    ]);
    assert_refused(&check, &records_file, "check");
}

#[test]
fn a_hard_kill_of_collide_run_takes_its_measurement_child_with_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results");
    // Ten million steps: about a minute, unless its parent's death stops it.
    let path = manifest(
        dir.path(),
        "repetitions = 1\nwarmups = 0\n[sweep]\nsteps = [10000000]\n[backends]\nserial = true\n",
    );
    let mut study = Command::new(env!("CARGO_BIN_EXE_collide"))
        .args(["run", &path, "--quiet", "--out", out.to_str().unwrap()])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let scene = dir.path().join("scene.toml");
    let scene = scene.to_str().unwrap();
    let started = Instant::now();
    while processes_mentioning(scene).is_empty() {
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "no child started"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    study.kill().unwrap(); // SIGKILL: no handler runs.
    study.wait().unwrap();
    let killed = Instant::now();
    while !processes_mentioning(scene).is_empty() {
        assert!(
            killed.elapsed() < Duration::from_secs(5),
            "the child outlived its parent: {:?}",
            processes_mentioning(scene)
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The rows of the one results file of study `tiny` under `out`.
fn rows_of(out: &Path) -> Vec<Record> {
    records::read(&records::files_in(&out.join("tiny")).unwrap()[0]).unwrap()
}

#[test]
fn a_study_run_from_another_repository_records_the_commit_collide_was_built_from() {
    let dir = tempfile::tempdir().unwrap();
    // The study runs inside a repository of its own, with a commit of its own.
    let git = |args: &[&str]| {
        Command::new("git")
            .current_dir(dir.path())
            .args(["-c", "user.name=t", "-c", "user.email=t@t"])
            .args(args)
            .output()
            .map(|out| text(&out.stdout).trim().to_owned())
    };
    let path = manifest(
        dir.path(),
        "repetitions = 1\nwarmups = 0\n[backends]\nserial = true\n",
    );
    let other = git(&["init", "-q"])
        .and_then(|_| git(&["add", "."]))
        .and_then(|_| git(&["commit", "-qm", "other"]))
        .and_then(|_| git(&["rev-parse", "--short=12", "HEAD"]))
        .unwrap_or_default();
    let output = Command::new(env!("CARGO_BIN_EXE_collide"))
        .current_dir(dir.path())
        .args(["run", &path, "--quiet", "--out", "results"])
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", text(&output.stderr));
    let row = rows_of(&dir.path().join("results")).remove(0);
    assert_eq!(row.git_commit, env!("COLLIDE_GIT_COMMIT"));
    assert_eq!(row.git_dirty, env!("COLLIDE_GIT_DIRTY") == "true");
    assert_ne!(row.git_commit, other);
    // Built from this checkout, the commit is its HEAD's.
    let head = Command::new("git")
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["rev-parse", "--short=12", "HEAD"])
        .output()
        .unwrap();
    if head.status.success() {
        assert_eq!(row.git_commit, text(&head.stdout).trim());
    }
    assert!(
        row.build_id.starts_with(&row.git_commit),
        "{}",
        row.build_id
    );
}

#[test]
fn results_of_several_studies_are_shown_apart_and_never_reported_as_one() {
    let dir = tempfile::tempdir().unwrap();
    let mixed = dir.path().join("mixed");
    let parent = dir.path().join("parent");
    for (study, name) in [("alpha", "1.parquet"), ("beta", "2.parquet")] {
        let mut rows = sample_records();
        rows.iter_mut().for_each(|r| r.study = study.to_owned());
        for folder in [mixed.clone(), parent.join(study)] {
            std::fs::create_dir_all(&folder).unwrap();
            records::write(&folder.join(name), &rows).unwrap();
        }
    }
    let report_of = |path: &Path| {
        collide(&[
            "report",
            path.to_str().unwrap(),
            "--out",
            dir.path().join("r").to_str().unwrap(),
        ])
    };
    let mixed_report = report_of(&mixed);
    let stderr = text(&mixed_report.stderr);
    assert_eq!(mixed_report.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("2 studies (alpha, beta)"), "{stderr}");
    assert!(!dir.path().join("r").join("report.md").exists());

    let parent_report = report_of(&parent);
    let stderr = text(&parent_report.stderr);
    assert_eq!(parent_report.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("2 study folder(s)"), "{stderr}");
    for study in ["alpha", "beta"] {
        assert!(
            stderr.contains(&parent.join(study).display().to_string()),
            "{stderr}"
        );
    }

    for folder in [&mixed, &parent] {
        let table = collide(&["results", folder.to_str().unwrap()]);
        let stdout = text(&table.stdout);
        assert!(table.status.success(), "{}", text(&table.stderr));
        assert!(
            stdout.contains("2 studies") && stdout.contains("alpha, beta"),
            "{stdout}"
        );
        assert!(
            stdout.contains("study alpha:") && stdout.contains("study beta:"),
            "{stdout}"
        );
    }
}
