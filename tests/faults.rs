//! Faults a careless user, a script or a failing machine bring: damaged and foreign
//! results files fed to every reader, a hard kill of `collide run`, a study run away
//! from the checkout, results of several studies in one folder.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use collide::study::records::{self, Record};
use polars::prelude::{Column, DataFrame, ParquetWriter};

use crate::util::{
    collide, manifest, processes_mentioning, run_study, sample_records, scene_file, study_command,
};

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
    let run = |extra: &[&str]| run_study(&path, &out, &[&["--quiet"], extra].concat());
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
    // The processes that name the scene once the run is under way: the child `collide
    // simulate`, and with MPI also its launcher and the launcher's two ranks.
    let mut backends = vec![("serial = true", 1)];
    if cfg!(feature = "mpi") {
        backends.push(("mpi = [2]", 4));
    }
    for (backend, n_processes) in backends {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("results");
        // Ten million steps: about a minute, unless its parent's death stops it.
        let path = manifest(
            dir.path(),
            &format!(
                "repetitions = 1\nwarmups = 0\n[sweep]\nsteps = [10000000]\n[backends]\n{backend}\n"
            ),
        );
        let mut study = study_command(&path, &out)
            .arg("--quiet")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let scene = dir.path().join("scene.toml");
        let scene = scene.to_str().unwrap();
        let started = Instant::now();
        while processes_mentioning(scene).len() < n_processes {
            assert!(
                started.elapsed() < Duration::from_secs(20),
                "{backend}: not all of the run's {n_processes} processes started: {:?}",
                processes_mentioning(scene)
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        study.kill().unwrap(); // SIGKILL: no handler runs.
        study.wait().unwrap();
        let killed = Instant::now();
        // The run would last a minute; its launcher and ranks end within a second on an
        // idle machine, and took over 5 s once while the rest of the suite (ranks as
        // threads, up to 64 of them) kept both cores busy.
        while !processes_mentioning(scene).is_empty() {
            assert!(
                killed.elapsed() < Duration::from_secs(20),
                "{backend}: processes outlived collide run: {:?}",
                processes_mentioning(scene)
            );
            std::thread::sleep(Duration::from_millis(50));
        }
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
        .args(["run", &path, "--no-report", "--quiet", "--out", "results"])
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

#[test]
fn each_exit_code_of_the_table_is_the_one_stated_in_help_and_the_docs() {
    let help = text(&collide(&["--help"]).stdout);
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let docs = ["README.md", "docs/guide.md"].map(|doc| {
        let text = std::fs::read_to_string(repo.join(doc)).unwrap();
        (doc, text)
    });
    for code in collide::exit::ALL {
        let line = format!("{:<4} {}", code.code, code.meaning);
        assert!(help.contains(&line), "{help}");
        for (doc, text) in &docs {
            assert!(
                text.lines().any(|l| l == line),
                "{doc} does not state the exit code table as `collide --help` does: `{line}`"
            );
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results");
    let run = |body: &str| {
        let path = manifest(dir.path(), body);
        collide(&[
            "run",
            &path,
            "--no-report",
            "--quiet",
            "--out",
            out.to_str().unwrap(),
        ])
    };
    let measured = run("repetitions = 1\nwarmups = 0\n[backends]\nserial = true\n");
    assert_eq!(
        measured.status.code(),
        Some(i32::from(collide::exit::DONE.code))
    );
    // A run killed at its timeout: the study ran, a run failed.
    let failed = run(
        "repetitions = 1\nwarmups = 0\ntimeout_s = 0.2\n[sweep]\nsteps = [10000000]\n\
         [backends]\nserial = true\n",
    );
    assert_eq!(
        failed.status.code(),
        Some(i32::from(collide::exit::RUNS_FAILED.code)),
        "{}",
        text(&failed.stderr)
    );
    let refused = run("[backends]\n");
    assert_eq!(
        refused.status.code(),
        Some(i32::from(collide::exit::ERROR.code))
    );
    // Interrupted (130): `ctrl_c_stops_the_running_child_and_keeps_what_was_measured`.
}

#[test]
fn blank_scene_names_are_refused_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results");
    for name in ["", "   "] {
        let path = scene_file(
            dir.path(),
            "blank.toml",
            &format!(
                "name = \"blank\"\n[backends]\nserial = true\n[[scenes]]\nname = \"{name}\"\n\
                 [scenes.scene]\nn = 10\npacking = 0.1\n"
            ),
        );
        let output = collide(&[
            "run",
            "--no-report",
            path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        let stderr = text(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{stderr}");
        assert!(
            stderr.contains("blank.toml:") && stderr.contains("is blank"),
            "{stderr}"
        );
        assert!(!out.exists(), "something was written for {name:?}");
    }
}

/// A tmpfs of 64 KiB mounted on a fresh folder, filled to the last byte; unmounted
/// when dropped. None where this process may not mount (not root, no capability).
struct FullDisk {
    dir: tempfile::TempDir,
}

impl FullDisk {
    fn mount() -> Option<FullDisk> {
        let dir = tempfile::tempdir().unwrap();
        let mounted = Command::new("mount")
            .args(["-t", "tmpfs", "-o", "size=64k", "tmpfs"])
            .arg(dir.path())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|status| status.success());
        if !mounted {
            return None;
        }
        let disk = FullDisk { dir };
        let mut filler = std::fs::File::create(disk.path().join("filler")).unwrap();
        let block = vec![0u8; 4096];
        while std::io::Write::write_all(&mut filler, &block).is_ok() {}
        Some(disk)
    }

    fn path(&self) -> &Path {
        self.dir.path()
    }
}

impl Drop for FullDisk {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(self.dir.path()).status();
    }
}

#[test]
fn on_a_full_disk_every_output_fails_in_words_and_leaves_no_partial_file() {
    let Some(disk) = FullDisk::mount() else {
        // The same message is tested with a writer that fails in `output`'s unit tests.
        eprintln!("cannot mount a tmpfs here: the full-disk test is skipped");
        return;
    };
    let full = disk.path();
    let dir = tempfile::tempdir().unwrap();
    let results = dir.path().join("results.parquet");
    records::write(&results, &sample_records()).unwrap();
    let scene = "experiments/scenes/seed-1000.toml";
    let study = manifest(
        dir.path(),
        "repetitions = 1\nwarmups = 0\n[backends]\nserial = true\n",
    );
    let target = |name: &str| full.join(name).to_str().unwrap().to_owned();
    let cases: Vec<Vec<String>> = vec![
        vec![
            "render".into(),
            scene.into(),
            "--steps".into(),
            "1".into(),
            "--png".into(),
            target("scene.png"),
        ],
        vec![
            "render".into(),
            scene.into(),
            "--steps".into(),
            "2".into(),
            "--frames".into(),
            "2".into(),
            "--gif".into(),
            target("run.gif"),
        ],
        vec![
            "simulate".into(),
            scene.into(),
            "--steps".into(),
            "1".into(),
            "--dump".into(),
            target("state.csv"),
        ],
        vec![
            "report".into(),
            results.to_str().unwrap().into(),
            "--out".into(),
            full.to_str().unwrap().into(),
        ],
        vec![
            "run".into(),
            "--no-report".into(),
            study,
            "--quiet".into(),
            "--out".into(),
            full.to_str().unwrap().into(),
        ],
    ];
    for args in &cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let output = collide(&args);
        let stderr = text(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(
            stderr.contains("is full") && stderr.contains(full.to_str().unwrap()),
            "{args:?}: {stderr}"
        );
        assert!(
            !stderr.contains("Os {") && !stderr.contains("Error("),
            "{args:?}: {stderr}"
        );
    }
    // Nothing but the filler (and the study's empty folder) is left: no half files.
    let mut left: Vec<String> = walk(full);
    left.sort();
    assert_eq!(left, ["filler"], "{left:?}");
}

/// The files under `dir`, as paths relative to it.
fn walk(dir: &Path) -> Vec<String> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap().flatten() {
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if path.is_dir() {
            files.extend(walk(&path).into_iter().map(|f| format!("{name}/{f}")));
        } else {
            files.push(name);
        }
    }
    files
}

#[test]
fn under_taskset_workers_default_to_the_allowed_cpus_and_more_are_oversubscribed() {
    let taskset = |args: &[&str]| {
        let output = Command::new("taskset")
            .args(["-c", "0", env!("CARGO_BIN_EXE_collide")])
            .args(args)
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .expect("taskset (util-linux) runs");
        assert!(
            output.status.success(),
            "{args:?}: {}",
            text(&output.stderr)
        );
        output
    };
    let summary = |extra: &[&str]| -> serde_json::Value {
        let scene = [
            "simulate",
            "experiments/scenes/seed-1000.toml",
            "--steps",
            "2",
        ];
        let output = taskset(&[&scene[..], &["--backend", "rayon", "--json"], extra].concat());
        serde_json::from_str(text(&output.stdout).lines().last().unwrap()).unwrap()
    };
    let default = summary(&[]);
    assert_eq!(default["threads"], 1, "{default}");
    assert_eq!(default["oversubscribed"], false, "{default}");
    let two = summary(&["--threads", "2"]);
    assert_eq!(two["oversubscribed"], true, "{two}");
    // The ceiling on workers counts the allowed CPUs too: 8 threads on 1 CPU run, 9 are
    // refused before anything runs.
    summary(&["--threads", "8"]);
    let refused = Command::new("taskset")
        .args(["-c", "0", env!("CARGO_BIN_EXE_collide")])
        .args(["simulate", "experiments/scenes/seed-1000.toml"])
        .args(["--backend", "rayon", "--threads", "9"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("taskset (util-linux) runs");
    let stderr = text(&refused.stderr);
    assert_eq!(refused.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("more than 8 per CPU this process may use (1 here: at most 8)"),
        "{stderr}"
    );

    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results");
    let path = manifest(
        dir.path(),
        "repetitions = 1\nwarmups = 0\n[backends]\nrayon = [2]\n",
    );
    taskset(&[
        "run",
        &path,
        "--no-report",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    let row = rows_of(&out).remove(0);
    assert_eq!((row.usable_cpus, row.cpu_affinity.as_str()), (Some(1), "0"));
    assert!(row.oversubscribed);
}
