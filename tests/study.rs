//! `collide run` and `collide results`: manifests, the runner, Parquet records, resume,
//! and bad input.

use std::os::unix::fs::PermissionsExt;
use std::time::{Duration, Instant};

use collide::study::records::{self, Record, STATUS_TIMED_OUT};

use crate::util::{
    collide, interrupt_after_first_row, manifest, processes_mentioning, report_of, run_study,
    sample_records, scene_file,
};

const BACKENDS: &str = "[backends]\nserial = true\nrayon = [2]\n";

fn stderr_of(args: &[&str]) -> String {
    let started = Instant::now();
    let out = collide(args);
    assert!(
        started.elapsed() < Duration::from_secs(5),
        "{args:?} was slow"
    );
    assert!(!out.status.success(), "{args:?} was accepted");
    String::from_utf8(out.stderr).unwrap()
}

#[test]
fn bad_manifests_name_the_line_the_field_and_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let cases: &[(&str, &[&str])] = &[
        (
            "colour = 1\n[backends]\nserial = true\n",
            &[":2:", "colour"],
        ),
        (
            "[sweep]\nn = []\n[backends]\nserial = true\n",
            &["sweep.n", "empty"],
        ),
        (
            "[backends]\nrayon = [2, 2]\n",
            &["appears twice", "workers=2"],
        ),
        (
            "[sweep]\npacking = [0.9]\n[backends]\nserial = true\n",
            &["packing", "lattice"],
        ),
        (
            "[sweep]\nn = [1, 2]\nsteps = [5]\nzip = [\"n\", \"steps\"]\n[backends]\nserial = true\n",
            &["zip", "same length"],
        ),
        (
            "[backends]\nrayon = [0]\n",
            &["backends.rayon", "at least 1"],
        ),
        ("[backends]\n", &["runs nothing"]),
        (
            "[sweep]\nmethod = [\"step\", \"event\"]\n[backends]\nserial = true\nrayon = [2]\n",
            &[":3:", "serial backend only", "rayon"],
        ),
        (
            "[sweep]\nobserve = [\"everything\"]\n[backends]\nserial = true\n",
            &[":3:", "expected `timing` or `accuracy`"],
        ),
    ];
    for (body, fragments) in cases {
        let path = manifest(dir.path(), body);
        let stderr = stderr_of(&["run", &path, "--out", dir.path().to_str().unwrap()]);
        assert!(stderr.contains("tiny.toml:"), "{body}: {stderr}");
        for fragment in *fragments {
            assert!(
                stderr.contains(fragment),
                "{body}: `{fragment}` not in {stderr}"
            );
        }
    }
}

#[test]
fn a_study_records_every_repetition_and_resume_runs_only_what_is_missing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results");
    let path = manifest(
        dir.path(),
        &format!("repetitions = 2\nwarmups = 0\n{BACKENDS}"),
    );
    let run = |extra: &[&str]| run_study(&path, &out, extra);
    assert!(run(&[]).status.success());
    let parquet = records::files_in(&out.join("tiny")).unwrap();
    assert_eq!(parquet.len(), 1, "{parquet:?}");
    let rows = records::read(&parquet[0]).unwrap();
    assert_eq!(rows.len(), 4);
    let mode = std::fs::metadata(&parquet[0]).unwrap().permissions().mode();
    assert_eq!(mode & 0o777, 0o644, "results are ordinary readable files");
    assert!(rows.iter().all(|r| r.load_average_end.is_finite()));
    assert!(rows[0].rustc.starts_with("rustc "), "{}", rows[0].rustc);
    assert!(
        rows.iter()
            .all(|r| r.status == "ok" && r.study == "tiny" && r.n == 200)
    );
    assert!(rows.iter().all(|r| r.state_hash == rows[0].state_hash));
    assert_eq!(
        backend_repetitions(&rows),
        [("rayon", 0), ("rayon", 1), ("serial", 0), ("serial", 1)].map(|(b, r)| (b.to_owned(), r))
    );

    // As if the study had been killed after its first run: resume runs the other three.
    records::write(&parquet[0], &rows[..1]).unwrap();
    let resumed = run(&["--resume"]);
    let stdout = String::from_utf8(resumed.stdout).unwrap();
    assert!(
        resumed.status.success(),
        "{}",
        String::from_utf8_lossy(&resumed.stderr)
    );
    assert!(
        stdout.contains("3 runs measured") && stdout.contains("1 kept"),
        "{stdout}"
    );
    assert_eq!(records::read(&parquet[0]).unwrap().len(), 4);

    let table = collide(&["results", out.join("tiny").to_str().unwrap()]);
    let table = String::from_utf8(table.stdout).unwrap();
    assert!(
        table.contains("serial") && table.contains("rayon"),
        "{table}"
    );
    assert!(table.contains("all runs agree"), "{table}");
}

#[test]
fn repetitions_by_backend_measure_each_backend_as_often_as_asked() {
    let (_dir, _, rows) = tiny_study(&format!(
        "warmups = 0\nrepetitions = {{ serial = 3, rayon = 1 }}\n{BACKENDS}"
    ));
    assert_eq!(
        backend_repetitions(&rows),
        [("rayon", 0), ("serial", 0), ("serial", 1), ("serial", 2)].map(|(b, r)| (b.to_owned(), r))
    );
}

#[test]
fn an_accuracy_study_runs_both_methods_and_reports_pareto_and_stability_figures() {
    let (dir, results, rows) = tiny_study(
        "repetitions = 1\nwarmups = 0\n[sweep]\ndt = [0.5, 0.1, 0.1]\nsteps = [4, 20, 20]\n\
         method = [\"step\", \"step\", \"event\"]\n\
         observe = [\"accuracy\", \"accuracy\", \"timing\"]\n\
         zip = [\"dt\", \"steps\", \"method\", \"observe\"]\n[backends]\nserial = true\n",
    );
    let methods: Vec<(&str, &str)> = rows
        .iter()
        .map(|r| (r.method.as_str(), r.observe.as_str()))
        .collect();
    assert_eq!(
        methods,
        [
            ("step", "accuracy"),
            ("step", "accuracy"),
            ("event", "timing")
        ]
    );
    assert!(rows.iter().all(|r| r.rms_step_over_radius > 0.0));
    assert!(rows[0].missed_collisions.is_some() && rows[2].missed_collisions == Some(0));
    let reports = dir.path().join("reports");
    let text = report_of(&results, &reports);
    assert!(text.contains("## Accuracy"), "{text}");
    for figure in ["accuracy-pareto.png", "accuracy-stability.png"] {
        assert!(text.contains(figure), "{text}");
        assert!(reports.join(figure).exists(), "{figure}");
    }
}

#[test]
fn a_drawn_study_records_frames_with_drawing_and_reports_the_seeds_figure_5() {
    let (dir, results, rows) = tiny_study(
        "repetitions = 1\nwarmups = 0\n[sweep]\ndraw = [true]\n[backends]\nserial = true\nrayon = [1, 2]\n",
    );
    assert_eq!(rows.len(), 3);
    for row in &rows {
        assert!(row.config_key.ends_with(";draw=true"), "{}", row.config_key);
        assert!(row.drew() && row.draw_s > 0.0, "{row:?}");
        assert!(row.fps_with_drawing < row.fps, "{row:?}");
        assert_eq!(row.state_hash, rows[0].state_hash);
    }
    let reports = dir.path().join("reports");
    let text = report_of(&results, &reports);
    let figure = "setup-1-fps-drawing.png";
    assert!(text.contains(figure), "{text}");
    assert!(text.contains("frames/s with drawing"), "{text}");
    let image = image::open(reports.join(figure)).unwrap().to_rgb8();
    assert_eq!(image.dimensions(), (900, 560));
    let rayon = image.pixels().filter(|p| p.0 == [0x1f, 0x77, 0xb4]).count();
    assert!(rayon > 200, "rayon barely drawn ({rayon})");
}

#[test]
fn drawing_with_mpi_is_refused_in_a_manifest_and_on_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results");
    let path = manifest(
        dir.path(),
        "[sweep]\ndraw = [true]\n[backends]\nserial = true\nmpi = [2]\n",
    );
    let run = run_study(&path, &out, &[]);
    assert_eq!(run.status.code(), Some(2));
    let stderr = String::from_utf8(run.stderr).unwrap();
    for fragment in [
        "tiny.toml:3",
        "all the disks in one process",
        "`mpi = [...]`",
    ] {
        assert!(stderr.contains(fragment), "`{fragment}` not in {stderr}");
    }
    assert!(!out.join("tiny").exists(), "wrote a results folder");
    let scene = dir.path().join("scene.toml");
    // `--draw` alone, before the scene: a flag, not a flag taking the scene as its value.
    let simulate = collide(&[
        "simulate",
        "--draw",
        scene.to_str().unwrap(),
        "--backend",
        "mpi",
    ]);
    assert_eq!(simulate.status.code(), Some(2));
    let stderr = String::from_utf8(simulate.stderr).unwrap();
    assert!(
        stderr.contains("--draw") && stderr.contains("drop --backend mpi"),
        "{stderr}"
    );
}

/// The (backend, repetition) of every row, sorted.
fn backend_repetitions(rows: &[Record]) -> Vec<(String, u32)> {
    let mut reps: Vec<(String, u32)> = rows
        .iter()
        .map(|r| (r.backend.clone(), r.repetition))
        .collect();
    reps.sort();
    reps
}

/// The tiny study with `body` run in a temporary folder, which must succeed: the folder,
/// the study's results folder and its records.
fn tiny_study(body: &str) -> (tempfile::TempDir, std::path::PathBuf, Vec<Record>) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results");
    let run = run_study(&manifest(dir.path(), body), &out, &[]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let results = out.join("tiny");
    let rows = records::read(&records::files_in(&results).unwrap()[0]).unwrap();
    (dir, results, rows)
}

#[test]
fn a_run_over_its_timeout_is_recorded_as_timed_out_and_fails_the_study() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results");
    let path = manifest(
        dir.path(),
        // Ten million steps would take about a minute; the timeout kills the run at 0.2 s.
        "repetitions = 1\nwarmups = 0\ntimeout_s = 0.2\n[sweep]\nsteps = [10000000]\n\
         [backends]\nserial = true\n",
    );
    let result = run_study(&path, &out, &[]);
    assert!(!result.status.success());
    let stderr = String::from_utf8(result.stderr).unwrap();
    assert!(stderr.contains("1 run(s) failed"), "{stderr}");
    let rows = records::read(&records::files_in(&out.join("tiny")).unwrap()[0]).unwrap();
    assert_eq!(rows[0].status, STATUS_TIMED_OUT);
    assert!(rows[0].wall_s.is_nan() && rows[0].state_hash.is_empty());
}

#[test]
fn an_unwritable_results_folder_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = manifest(dir.path(), BACKENDS);
    let blocker = scene_file(dir.path(), "not-a-folder", "");
    let stderr = stderr_of(&["run", &path, "--out", blocker.to_str().unwrap()]);
    assert!(
        stderr.contains("is a file, not a folder") && stderr.contains("--out"),
        "{stderr}"
    );
}

#[test]
fn a_study_ends_in_its_scaling_table_and_its_report() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results");
    let reports = dir.path().join("reports");
    let path = manifest(
        dir.path(),
        "repetitions = 1\nwarmups = 0\n[backends]\nserial = true\nrayon = [1, 2]\nmpi = [2]\n",
    );
    let run = collide(&[
        "run",
        &path,
        "--out",
        out.to_str().unwrap(),
        "--reports",
        reports.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8(run.stdout).unwrap();
    let stderr = String::from_utf8(run.stderr).unwrap();
    assert!(run.status.success(), "{stderr}");
    // The seed's table: workers × median seconds per backend, speedup, efficiency.
    let header = stdout
        .lines()
        .find(|line| line.trim_start().starts_with("workers") && line.contains("serial"))
        .unwrap_or_else(|| panic!("no scaling table in {stdout}"));
    assert!(
        header.contains("rayon") && header.contains("S(p)") && header.contains("E(p)"),
        "{header}"
    );
    let report = reports.join("tiny").join("report.md");
    assert!(
        stdout.contains(&format!("report written to {}", report.display())),
        "{stdout}"
    );
    let text = std::fs::read_to_string(&report).unwrap();
    assert!(text.contains("Speedup, efficiency"), "{text}");
    assert!(reports.join("tiny").join("setup-1-speedup.png").exists());
    if cfg!(feature = "mpi") {
        assert!(header.contains("mpi"), "{header}");
    } else {
        // Said once, in one line, with how to get them.
        let warnings: Vec<&str> = stderr.lines().filter(|l| l.contains("MPI")).collect();
        assert_eq!(warnings.len(), 1, "{stderr}");
        assert!(
            warnings[0].contains("skipping 1 MPI configuration")
                && warnings[0].contains("--features mpi"),
            "{stderr}"
        );
    }
}

#[cfg(not(feature = "mpi"))]
#[test]
fn a_study_of_mpi_configurations_only_is_an_error_without_mpi() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results");
    let path = manifest(dir.path(), "[backends]\nmpi = [1, 2]\n");
    let run = run_study(&path, &out, &[]);
    assert_eq!(run.status.code(), Some(2));
    let stderr = String::from_utf8(run.stderr).unwrap();
    for fragment in [
        "tiny.toml",
        "every configuration uses the MPI backend",
        "--features mpi",
    ] {
        assert!(stderr.contains(fragment), "`{fragment}` not in {stderr}");
    }
    assert!(
        !stderr.contains(".parquet"),
        "names a file it never wrote: {stderr}"
    );
    assert!(
        !out.join("tiny").exists(),
        "wrote a results folder for nothing"
    );
}

#[test]
fn records_round_trip_through_parquet_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("r.parquet");
    let written = sample_records();
    records::write(&path, &written).unwrap();
    let read = records::read(&path).unwrap();
    // Debug text compares NaN equal to NaN and every other value exactly.
    assert_eq!(format!("{read:?}"), format!("{written:?}"));
}

#[test]
fn corrupt_foreign_and_old_results_are_refused_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let garbage = scene_file(dir.path(), "garbage.parquet", "not parquet at all");
    let stderr = stderr_of(&["results", garbage.to_str().unwrap()]);
    assert!(stderr.contains("not a readable Parquet file"), "{stderr}");

    let mut frame = records::to_frame(&sample_records()).unwrap();
    frame.drop_in_place("state_hash").unwrap();
    let foreign = dir.path().join("foreign.parquet");
    let file = std::fs::File::create(&foreign).unwrap();
    polars::prelude::ParquetWriter::new(file)
        .finish(&mut frame)
        .unwrap();
    let stderr = stderr_of(&["results", foreign.to_str().unwrap()]);
    assert!(stderr.contains("no `state_hash` column"), "{stderr}");

    let mut frame = records::to_frame(&sample_records()).unwrap();
    let old = polars::prelude::Column::new("schema_version".into(), vec![0u32; frame.height()]);
    frame.with_column(old).unwrap();
    let older = dir.path().join("older.parquet");
    let file = std::fs::File::create(&older).unwrap();
    polars::prelude::ParquetWriter::new(file)
        .finish(&mut frame)
        .unwrap();
    let stderr = stderr_of(&["results", older.to_str().unwrap()]);
    assert!(
        stderr.contains("schema version 0") && stderr.contains("re-run"),
        "{stderr}"
    );

    let empty = tempfile::tempdir().unwrap();
    let stderr = stderr_of(&["results", empty.path().to_str().unwrap()]);
    assert!(stderr.contains("no .parquet results"), "{stderr}");
}

#[test]
fn ctrl_c_stops_the_running_child_and_keeps_what_was_measured() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results");
    // A 20-step run, then one of ten million steps (about a minute) to interrupt.
    let path = manifest(
        dir.path(),
        "repetitions = 1\nwarmups = 0\n[sweep]\nsteps = [20, 10000000]\n[backends]\nserial = true\n",
    );
    let ended = interrupt_after_first_row(&path, &out, "tiny", rustix::process::Signal::INT);
    assert_eq!(ended.status.code(), Some(130));
    let rows = records::read(&records::files_in(&out.join("tiny")).unwrap()[0]).unwrap();
    assert_eq!(rows.len(), 1, "the finished run is kept");
    assert_eq!(rows[0].steps, 20);
    std::thread::sleep(Duration::from_millis(200));
    let scene = dir.path().join("scene.toml");
    let left = processes_mentioning(scene.to_str().unwrap());
    assert!(left.is_empty(), "children outlived the study: {left:?}");
}
