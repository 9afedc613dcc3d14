//! Nothing lost, nothing written where it should not be: names that would escape their
//! folder, studies started together, runs too large for the machine, worker counts
//! beyond any sense, interrupted and killed studies, and output paths that cannot be
//! written. Each bad input is refused with exit 2 before anything runs, or recovered.

use std::path::Path;
use std::process::Stdio;

use collide::run::backend_kind::BackendKind;
use collide::run::limits::{MAX_WORKERS_PER_CPU, Machine};
use collide::study::records;
use rustix::process::Signal;

use crate::util::{
    SCENE, collide, interrupt_after_first_row, refused_in, run_study, scene_file, study_command,
};

/// An inline scene entry named `name` (TOML-escaped by the caller).
fn inline_scene(name: &str) -> String {
    format!(
        "[[scenes]]\nname = \"{name}\"\n[scenes.scene]\nn = 100\npacking = 0.1\n\
         [scenes.method]\ndt = 0.1\nsteps = 5\n"
    )
}

/// Runs `collide ARGS` from the crate folder, which must be refused: see [`refused_in`].
fn refused(args: &[&str]) -> String {
    refused_in(Path::new(env!("CARGO_MANIFEST_DIR")), args)
}

/// `collide run MANIFEST --out OUT`, which must be refused; its stderr.
fn run_refused(manifest: &Path, out: &Path) -> String {
    refused(&[
        "run",
        manifest.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ])
}

/// No Rust debug text (`IoError(Os { code: 20, .. })`) and no reason said twice.
fn assert_in_words(stderr: &str) {
    for debug in ["Os {", "code:", "kind:", "Error(", "Custom {"] {
        assert!(!stderr.contains(debug), "debug text `{debug}` in: {stderr}");
    }
    let reasons = [
        "Is a directory",
        "Not a directory",
        "No such file or directory",
        "Permission denied",
    ];
    for reason in reasons {
        assert!(
            stderr.matches(reason).count() <= 1,
            "`{reason}` said twice: {stderr}"
        );
    }
}

#[test]
fn names_that_would_escape_the_results_folder_are_refused_before_anything_runs() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("deep/er/results");
    let victim = dir.path().join("victim.toml");
    let bad_names = [
        "../../../../victim",
        "../victim",
        "..",
        ".",
        "",
        "   ",
        ".hidden",
        "a/b",
        "/etc/victim",
        "a\\\\b",
        "two words",
        "tab\\there",
    ];
    for name in bad_names {
        // As an inline scene's name, then as the study's name.
        let as_scene = format!(
            "name = \"tiny\"\n[backends]\nserial = true\n{}",
            inline_scene(name)
        );
        let as_study = format!(
            "name = \"{name}\"\n[backends]\nserial = true\n{}",
            inline_scene("gas")
        );
        for (text, field, line) in [
            (as_scene, "`scenes.name`", ":5:"),
            (as_study, "`name`", ":1:"),
        ] {
            let manifest = scene_file(dir.path(), "m.toml", &text);
            let stderr = run_refused(&manifest, &out);
            assert!(
                stderr.contains(&format!("m.toml{line}"))
                    && stderr.contains(field)
                    && stderr.contains("letters, digits, - and _"),
                "{name:?}: {stderr}"
            );
        }
    }
    assert!(!out.exists(), "a refused study created {}", out.display());
    assert!(!victim.exists());

    // A results file can carry any study name: the report's default folder refuses it.
    let rows = vec![sample_row("../../escaped")];
    let file = dir.path().join("foreign.parquet");
    records::write(&file, &rows).unwrap();
    let stderr = refused(&["report", file.to_str().unwrap()]);
    assert!(
        stderr.contains("foreign.parquet") && stderr.contains("--out"),
        "{stderr}"
    );
    assert!(
        !Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("escaped")
            .exists()
    );
}

/// A measured-looking row of study `study`, from the study tests' fixed summary.
fn sample_row(study: &str) -> records::Record {
    let environment = collide::study::environment::Environment::capture();
    let context = records::RecordContext {
        study,
        manifest_hash: "0",
        build_id: "b",
        config_key: "k",
        scene: "s",
        scene_hash: "0123456789abcdef",
        scaling: "strong",
        backend: BackendKind::Serial,
        placement: BackendKind::Serial.placement(1),
        repetition: 0,
        environment: &environment,
        study_started_utc: "2025-01-01T00:00:00Z",
    };
    records::Record::failed(&context, records::STATUS_FAILED, "test row".into())
}

#[test]
fn output_paths_that_cannot_be_written_are_refused_first_in_words_once() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene_file(dir.path(), "gas.toml", SCENE);
    let scene = scene.to_str().unwrap();
    let file = scene_file(dir.path(), "plain.txt", "not a folder");
    let in_file = file.join("x.png");
    let missing = dir.path().join("no/such/folder/x.png");
    let folder = dir.path().to_str().unwrap();
    let cases: Vec<(Vec<&str>, &[&str])> = vec![
        (
            vec!["render", scene, "--png", "/etc/passwd/x.png"],
            &["--png /etc/passwd/x.png", "is a file, not a folder"],
        ),
        (
            vec!["render", scene, "--png", in_file.to_str().unwrap()],
            &["plain.txt", "is a file, not a folder"],
        ),
        (
            vec!["render", scene, "--gif", missing.to_str().unwrap()],
            &["--gif", "No such file or directory", "create it first"],
        ),
        (
            vec!["render", scene, "--png", folder],
            &["is a folder", "give a file name"],
        ),
        (
            vec!["simulate", scene, "--dump", folder],
            &["--dump", "is a folder"],
        ),
        (
            vec!["simulate", scene, "--dump", missing.to_str().unwrap()],
            &["--dump", "No such file or directory"],
        ),
        (
            vec!["simulate", scene, "--dump", in_file.to_str().unwrap()],
            &["--dump", "is a file, not a folder"],
        ),
        // Checked before a window opens (and so also where there is no display).
        (
            vec!["view", scene, "--stats", in_file.to_str().unwrap()],
            &["--stats", "is a file, not a folder"],
        ),
        (
            vec!["view", scene, "--screenshot", folder],
            &["--screenshot", "is a folder"],
        ),
    ];
    for (args, fragments) in &cases {
        let stderr = refused(args);
        assert_in_words(&stderr);
        for fragment in *fragments {
            assert!(
                stderr.contains(fragment),
                "{args:?}: `{fragment}` not in {stderr}"
            );
        }
    }
    // A study's report folder is checked before its first run, not after its last.
    let text = format!(
        "name = \"tiny\"\n[backends]\nserial = true\n{}",
        inline_scene("gas")
    );
    let manifest = scene_file(dir.path(), "tiny.toml", &text);
    let out = dir.path().join("results");
    let reports = file.join("reports");
    let stderr = refused(&[
        "run",
        manifest.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--reports",
        reports.to_str().unwrap(),
    ]);
    assert_in_words(&stderr);
    assert!(
        stderr.contains("--reports") && stderr.contains("is a file, not a folder"),
        "{stderr}"
    );
    assert!(
        !out.exists(),
        "the study ran before refusing its report folder"
    );
    // A folder the user may not write into (root may write anywhere: skip the case).
    let locked = dir.path().join("locked");
    std::fs::create_dir(&locked).unwrap();
    std::fs::set_permissions(&locked, std::os::unix::fs::PermissionsExt::from_mode(0o500)).unwrap();
    if std::fs::write(locked.join("probe"), "x").is_err() {
        let target = locked.join("x.png");
        let stderr = refused(&["render", scene, "--png", target.to_str().unwrap()]);
        assert_in_words(&stderr);
        assert!(stderr.contains("Permission denied"), "{stderr}");
    }
}

#[test]
fn unreadable_scenes_and_manifests_are_named_with_their_reason_once() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.toml");
    let missing = missing.to_str().unwrap();
    let folder = dir.path().to_str().unwrap();
    let cases: [(&[&str], &str); 4] = [
        (&["simulate", missing], "No such file or directory"),
        (&["simulate", folder], "is a folder, not a regular file"),
        (&["run", missing], "No such file or directory"),
        (&["run", folder], "is a folder, not a regular file"),
    ];
    for (args, reason) in cases {
        let stderr = refused(args);
        assert_in_words(&stderr);
        assert!(
            stderr.contains(args[1]) && stderr.contains(reason) && !stderr.contains("os error"),
            "{args:?}: {stderr}"
        );
    }
}

#[test]
fn runs_too_large_for_the_machine_are_refused_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene_file(dir.path(), "gas.toml", SCENE);
    let scene = scene.to_str().unwrap();
    for args in [
        vec!["simulate", scene, "--n", "1000000000"],
        vec!["simulate", scene, "--n", "1000000000", "--method", "event"],
        vec!["render", scene, "--n", "1000000000", "--png", "x.png"],
    ] {
        let stderr = refused(&args);
        assert!(
            stderr.contains("gas.toml")
                && stderr.contains("n = 1000000000 disks need about")
                && stderr.contains("GB of memory")
                && stderr.contains("this machine has")
                && stderr.contains("lower n to at most about"),
            "{args:?}: {stderr}"
        );
    }
    // A study checks every configuration before its first run.
    let out = dir.path().join("results");
    let text = format!(
        "name = \"big\"\n[sweep]\nn = [100, 1000000000]\n[backends]\nserial = true\n{}",
        inline_scene("gas")
    );
    let manifest = scene_file(dir.path(), "big.toml", &text);
    let stderr = run_refused(&manifest, &out);
    assert!(
        stderr.contains("big.toml:6:")
            && stderr.contains("n = 1000000000")
            && stderr.contains("GB of memory"),
        "{stderr}"
    );
    assert!(!out.exists(), "the study ran before refusing");
    // MPI ranks place a seeded gas in parts, so the estimate is the run's; a run whose
    // dt is chosen by pilots on the whole scene is built whole by every rank, and its
    // ranks multiply the estimate.
    let machine = Machine {
        usable_cpus: 64,
        memory_bytes: 8_000_000_000,
    };
    let ranks = |dt: &str| {
        format!(
            "name = \"m\"\n[sweep]\nn = [20000000]\n[backends]\nmpi = [2, 4]\n{}",
            inline_scene("gas").replace("dt = 0.1", dt)
        )
    };
    let in_parts =
        collide::study::manifest::parse(Path::new("m.toml"), &ranks("dt = 0.1"), &machine);
    assert!(in_parts.is_ok(), "{in_parts:?}");
    let whole = ranks("dt = \"auto\"");
    let err = collide::study::manifest::parse(Path::new("m.toml"), &whole, &machine)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("4 MPI ranks") && err.contains("fewer ranks"),
        "{err}"
    );
}

#[test]
fn worker_counts_above_the_ceiling_are_refused_unless_insisted_on() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene_file(dir.path(), "gas.toml", SCENE);
    let scene = scene.to_str().unwrap();
    let ceiling = MAX_WORKERS_PER_CPU * collide::system::machine::usable_cpus();
    let over = (ceiling + 1).to_string();
    for count in [over.as_str(), "3000", "10000"] {
        let stderr = refused(&["simulate", scene, "--backend", "rayon", "--threads", count]);
        assert!(
            stderr.contains(&format!("--threads asks for {count} workers"))
                && stderr.contains(&format!("at most {ceiling}"))
                && stderr.contains("--oversubscribe"),
            "{stderr}"
        );
    }
    let insisted = collide(&[
        "simulate",
        scene,
        "--backend",
        "rayon",
        "--threads",
        &over,
        "--oversubscribe",
        "--steps",
        "2",
    ]);
    assert!(
        insisted.status.success(),
        "{}",
        String::from_utf8_lossy(&insisted.stderr)
    );

    // In a manifest, against a posed machine of 2 cores.
    let machine = Machine {
        usable_cpus: 2,
        memory_bytes: 1 << 34,
    };
    let manifest = |backends: &str| {
        format!(
            "name = \"m\"\n[backends]\n{backends}\n{}",
            inline_scene("gas")
        )
    };
    for backends in ["rayon = [2, 17]", "rayon = [10000]", "mpi = [4, 100]"] {
        let err =
            collide::study::manifest::parse(Path::new("m.toml"), &manifest(backends), &machine)
                .unwrap_err()
                .to_string();
        assert!(
            err.starts_with("m.toml:2: `backends.")
                && err.contains("at most 16")
                && err.contains("oversubscribe = true"),
            "{err}"
        );
    }
    let insisted = collide::study::manifest::parse(
        Path::new("m.toml"),
        &manifest("rayon = [10000]\noversubscribe = true"),
        &machine,
    )
    .unwrap();
    let args = insisted.configurations[0].simulate_args();
    assert!(args.contains(&"--oversubscribe".to_owned()), "{args:?}");
}

fn spawn_study(manifest: &str, out: &Path) -> std::process::Child {
    study_command(manifest, out)
        .arg("--quiet")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

#[test]
fn studies_started_together_into_one_folder_both_keep_all_their_rows() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results");
    scene_file(dir.path(), "scene.toml", SCENE);
    let text = "name = \"tiny\"\nrepetitions = 2\nwarmups = 0\n[[scenes]]\nfile = \"scene.toml\"\n\
                [backends]\nserial = true\nrayon = [2]\n";
    let manifest = scene_file(dir.path(), "tiny.toml", text);
    let manifest = manifest.to_str().unwrap();
    let studies = [spawn_study(manifest, &out), spawn_study(manifest, &out)];
    let mut said = Vec::new();
    for study in studies {
        let done = study.wait_with_output().unwrap();
        let stdout = String::from_utf8(done.stdout).unwrap();
        assert!(
            done.status.success(),
            "{}",
            String::from_utf8_lossy(&done.stderr)
        );
        let named = stdout.lines().find_map(|line| line.split_once("→ "));
        said.push(
            named
                .expect("the study names its results file")
                .1
                .trim()
                .to_owned(),
        );
    }
    assert_ne!(said[0], said[1], "both studies named the same file");
    let files = records::files_in(&out.join("tiny")).unwrap();
    assert_eq!(files.len(), 2, "{files:?}");
    for file in &files {
        let rows = records::read(file).unwrap();
        assert_eq!(rows.len(), 4, "{}", file.display());
        assert!(rows.iter().all(|r| r.status == "ok"));
        assert!(said.contains(&file.display().to_string()), "{said:?}");
    }
    // Resuming continues the file written last, which has nothing left to run.
    let resumed = collide(&[
        "run",
        manifest,
        "--no-report",
        "--out",
        out.to_str().unwrap(),
        "--resume",
    ]);
    let stdout = String::from_utf8(resumed.stdout).unwrap();
    assert!(
        resumed.status.success() && stdout.contains("0 runs measured") && stdout.contains("4 kept"),
        "{stdout}"
    );
    assert_eq!(records::files_in(&out.join("tiny")).unwrap().len(), 2);
}

#[test]
fn an_interrupted_study_says_what_it_kept_and_how_to_continue() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out folder");
    scene_file(dir.path(), "scene.toml", SCENE);
    // A 20-step run, then one of ten million steps (about a minute) to interrupt.
    let text = "name = \"tiny\"\nrepetitions = 1\nwarmups = 0\n[[scenes]]\nfile = \"scene.toml\"\n\
                [sweep]\nsteps = [20, 10000000]\n[backends]\nserial = true\n";
    let manifest = scene_file(dir.path(), "tiny.toml", text);
    for signal in [Signal::TERM, Signal::INT] {
        let ended = interrupt_after_first_row(manifest.to_str().unwrap(), &out, "tiny", signal);
        assert_eq!(ended.status.code(), Some(130), "{signal:?}");
        let stderr = String::from_utf8(ended.stderr).unwrap();
        let newest = records::files_in(&out.join("tiny"))
            .unwrap()
            .into_iter()
            .max_by_key(|f| std::fs::metadata(f).unwrap().modified().unwrap())
            .unwrap();
        assert_eq!(
            stderr.trim(),
            format!(
                "interrupted: 1 run kept in {}; continue with collide run {} --out '{}' --resume",
                newest.display(),
                manifest.display(),
                out.display()
            ),
            "{signal:?}"
        );
        assert_eq!(records::read(&newest).unwrap().len(), 1);
    }
}

#[test]
fn unfinished_files_of_a_killed_study_are_never_results_and_are_removed_next_time() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results");
    let text = format!(
        "name = \"tiny\"\nrepetitions = 1\nwarmups = 0\n[backends]\nserial = true\n{}",
        inline_scene("gas")
    );
    let manifest = scene_file(dir.path(), "tiny.toml", &text);
    let run = |extra: &[&str]| run_study(manifest.to_str().unwrap(), &out, extra);
    assert!(run(&[]).status.success());
    let study = out.join("tiny");
    let results = records::files_in(&study).unwrap();
    assert_eq!(results.len(), 1);
    // What a study killed in the middle of its writes leaves: a complete but unrenamed
    // results file, an empty one, and a half-written scene file.
    let leftovers = [
        study.join(".collide-a1b2c3.partial"),
        study.join(".collide-d4e5f6.partial"),
        study.join("scenes/.collide-g7h8i9.partial"),
    ];
    std::fs::copy(&results[0], &leftovers[0]).unwrap();
    std::fs::write(&leftovers[1], "").unwrap();
    std::fs::write(&leftovers[2], "[scene]\nn =").unwrap();
    // A file of the user's is no leftover.
    let own = study.join(".notes");
    std::fs::write(&own, "mine").unwrap();
    let table = collide(&["results", study.to_str().unwrap(), "--format", "json"]);
    assert!(
        table.status.success(),
        "{}",
        String::from_utf8_lossy(&table.stderr)
    );
    let rows: serde_json::Value = serde_json::from_slice(&table.stdout).unwrap();
    assert!(
        rows.as_array()
            .unwrap()
            .iter()
            .any(|row| row["backend"] == "serial" && row["repetitions"] == 1 && row["failed"] == 0),
        "{rows}"
    );
    let resumed = run(&["--resume"]);
    assert!(
        resumed.status.success(),
        "{}",
        String::from_utf8_lossy(&resumed.stderr)
    );
    for leftover in &leftovers {
        assert!(!leftover.exists(), "{} is still there", leftover.display());
    }
    assert!(own.exists(), "a file that was not collide's was removed");
}
