//! What a careless user, a script and a shell pipeline do, one test per class of harm:
//! outputs that are not ours (devices, pipes, links, the input itself), closed and full
//! standard outputs, resuming after an edit, results folders holding copies, inputs
//! without bound, signals and leftovers, damaged baselines, names with markup and
//! escapes, environment overrides, and the messages bad values get.

use std::io::Read;
use std::os::unix::ffi::OsStrExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use collide::study::records;

use crate::util::{SCENE, collide, manifest, refused_in, run_study, scene_file};

/// `collide ARGS` run in `dir`, waited for.
fn collide_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_collide"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap()
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Makes a FIFO at `path`.
fn make_fifo(path: &Path) {
    let name = std::ffi::CString::new(path.as_os_str().as_bytes()).unwrap();
    // SAFETY: `name` is a valid NUL-terminated path that outlives the call.
    assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o600) }, 0);
}

/// A copy of the null device at `path` where this process may make device nodes (root)
/// and use them (not on a `nodev` mount), else `None`.
fn make_null_device(path: &Path) -> Option<()> {
    let name = std::ffi::CString::new(path.as_os_str().as_bytes()).unwrap();
    // SAFETY: `name` is a valid NUL-terminated path; 1:3 is the null device.
    let made = unsafe { libc::mknod(name.as_ptr(), libc::S_IFCHR | 0o666, libc::makedev(1, 3)) };
    let usable = made == 0 && std::fs::OpenOptions::new().write(true).open(path).is_ok();
    usable.then_some(())
}

/// A tiny scene file in `dir`, named `s.toml`.
fn tiny_scene(dir: &Path) -> PathBuf {
    scene_file(dir, "s.toml", SCENE)
}

#[test]
fn outputs_that_are_not_regular_files_are_written_through_and_inputs_never_replaced() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let scene_text = std::fs::read_to_string(&scene).unwrap();
    let s = scene.to_str().unwrap();

    // A device node stays a device node.
    let device = dir.path().join("null");
    if make_null_device(&device).is_some() {
        let out = collide(&["simulate", s, "--dump", device.to_str().unwrap()]);
        assert!(out.status.success(), "{}", stderr(&out));
        let kind = std::fs::symlink_metadata(&device).unwrap().file_type();
        assert!(std::os::unix::fs::FileTypeExt::is_char_device(&kind));
    }
    let out = collide(&["simulate", s, "--dump", "/dev/null"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!Path::new("/dev/null").is_file(), "/dev/null was replaced");

    // A FIFO is written through: its reader gets the CSV, and it stays a FIFO.
    let fifo = dir.path().join("fifo");
    make_fifo(&fifo);
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || {
            let mut text = String::new();
            std::fs::File::open(fifo)
                .unwrap()
                .read_to_string(&mut text)
                .unwrap();
            text
        })
    };
    let out = collide(&["simulate", s, "--dump", fifo.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        reader
            .join()
            .unwrap()
            .starts_with("id,x,y,vx,vy,radius,mass\n")
    );
    let kind = std::fs::symlink_metadata(&fifo).unwrap().file_type();
    assert!(std::os::unix::fs::FileTypeExt::is_fifo(&kind));

    // A link is followed: its target is written, the link stays a link (dangling or not).
    let link = dir.path().join("link.csv");
    std::os::unix::fs::symlink("target.csv", &link).unwrap();
    let out = collide(&["simulate", s, "--dump", link.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    let written = std::fs::read_to_string(dir.path().join("target.csv")).unwrap();
    assert!(written.starts_with("id,x,y"), "{written}");

    // The input itself, directly or through a link, and one file for two outputs: refused
    // before anything runs, and nothing is touched.
    let to_scene = dir.path().join("to-scene.toml");
    std::os::unix::fs::symlink(&scene, &to_scene).unwrap();
    for (args, says) in [
        (vec!["simulate", s, "--dump", s], "scene file itself"),
        (
            vec!["simulate", s, "--dump", to_scene.to_str().unwrap()],
            "scene file itself",
        ),
        (vec!["render", s, "--png", s], "scene file itself"),
        (
            vec!["render", s, "--png", "x.png", "--gif", "x.png"],
            "same file as --png",
        ),
    ] {
        let out = collide_in(dir.path(), &args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(stderr(&out).contains(says), "{args:?}: {}", stderr(&out));
    }
    assert_eq!(std::fs::read_to_string(&scene).unwrap(), scene_text);
    assert!(!dir.path().join("x.png").exists());
}

/// `collide ARGS` with its standard output closed before it prints: its exit code and
/// standard error.
fn with_stdout_closed(args: &[&str]) -> (Option<i32>, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_collide"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    (out.status.code(), stderr(&out))
}

#[test]
fn a_closed_stdout_ends_the_printing_quietly_and_a_full_one_is_said_in_words() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let s = scene.to_str().unwrap();
    let (code, err) = with_stdout_closed(&["simulate", s]);
    assert_eq!((code, err.as_str()), (Some(0), ""));

    // A study piped into `head` still writes its results and its report.
    let manifest = manifest(dir.path(), "repetitions = 1\n[backends]\nserial = true");
    let (out, reports) = (dir.path().join("r"), dir.path().join("reports"));
    let (code, err) = with_stdout_closed(&[
        "run",
        &manifest,
        "--out",
        out.to_str().unwrap(),
        "--reports",
        reports.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(reports.join("tiny").join("report.md").is_file());
    let (code, err) = with_stdout_closed(&["results", out.join("tiny").to_str().unwrap()]);
    assert_eq!((code, err.as_str()), (Some(0), ""));

    let full = Command::new(env!("CARGO_BIN_EXE_collide"))
        .args(["simulate", s])
        .stdout(std::fs::File::create("/dev/full").unwrap())
        .output()
        .unwrap();
    assert_eq!(full.status.code(), Some(2));
    assert!(stderr(&full).contains("no space left"), "{}", stderr(&full));
}

/// The rows of the newest results file in `dir`.
fn newest_rows(dir: &Path) -> Vec<records::Record> {
    let mut files = records::files_in(dir).unwrap();
    files.sort_by_key(|path| std::fs::metadata(path).unwrap().modified().unwrap());
    records::read(files.last().unwrap()).unwrap()
}

#[test]
fn resume_reuses_the_runs_of_the_same_workload_and_measures_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r");
    let manifest = manifest(dir.path(), "repetitions = 1\n[backends]\nserial = true");
    assert!(run_study(&manifest, &out, &[]).status.success());
    let study = out.join("tiny");

    // A comment and a raised repetition count: the first repetition is kept, one is run.
    let text = std::fs::read_to_string(&manifest).unwrap();
    let raised = text.replace("repetitions = 1\n", "# two now\nrepetitions = 2\n");
    std::fs::write(&manifest, raised).unwrap();
    let resumed = run_study(&manifest, &out, &["--resume"]);
    assert!(resumed.status.success(), "{}", stderr(&resumed));
    assert!(String::from_utf8_lossy(&resumed.stdout).contains("1 runs measured"));
    assert_eq!(records::files_in(&study).unwrap().len(), 1);
    assert_eq!(newest_rows(&study).len(), 2);

    // The scene edited: nothing of the old workload is reused, and its rows stay where
    // they were; the new file holds only the new workload.
    std::fs::write(
        dir.path().join("scene.toml"),
        SCENE.replace("n = 200", "n = 100"),
    )
    .unwrap();
    let edited = run_study(&manifest, &out, &["--resume"]);
    assert!(edited.status.success(), "{}", stderr(&edited));
    assert!(String::from_utf8_lossy(&edited.stdout).contains("2 runs measured"));
    let files = records::files_in(&study).unwrap();
    assert_eq!(files.len(), 2);
    let new = newest_rows(&study);
    assert!(new.iter().all(|row| row.n == 100), "{new:?}");
    let old: usize = files.iter().map(|f| records::read(f).unwrap().len()).sum();
    assert_eq!(
        old, 4,
        "the old workload's two rows are kept beside the new two"
    );
}

#[test]
fn inline_scenes_of_one_name_from_two_manifests_keep_their_own_copies() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r");
    let write = |file: &str, n: u32| {
        let text = format!(
            "name = \"same\"\nrepetitions = 1\n[backends]\nserial = true\n[[scenes]]\nname = \"gas\"\n[scenes.scene]\n\
             n = {n}\npacking = 0.1\n[scenes.method]\ndt = 0.1\nsteps = 5\n"
        );
        scene_file(dir.path(), file, &text)
            .to_str()
            .unwrap()
            .to_owned()
    };
    for (file, n) in [("a.toml", 100), ("b.toml", 200)] {
        let out = run_study(&write(file, n), &out, &[]);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let copies: Vec<String> = std::fs::read_dir(out.join("same").join("scenes"))
        .unwrap()
        .map(|entry| std::fs::read_to_string(entry.unwrap().path()).unwrap())
        .collect();
    assert_eq!(copies.len(), 2, "{copies:?}");
    assert!(copies.iter().any(|text| text.contains("n = 100")));
    assert!(copies.iter().any(|text| text.contains("n = 200")));
}

#[test]
fn a_results_folder_with_a_copy_counts_each_run_once_and_refuses_impossible_values() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r");
    let manifest = manifest(dir.path(), "repetitions = 2\n[backends]\nserial = true");
    assert!(run_study(&manifest, &out, &[]).status.success());
    let study = out.join("tiny");
    let file = records::files_in(&study).unwrap().remove(0);
    std::fs::copy(&file, study.join("backup.parquet")).unwrap();
    let shown = collide(&["results", study.to_str().unwrap(), "--format", "json"]);
    assert!(shown.status.success(), "{}", stderr(&shown));
    assert!(stderr(&shown).contains("2 row(s)"), "{}", stderr(&shown));
    let rows: serde_json::Value = serde_json::from_slice(&shown.stdout).unwrap();
    assert_eq!(rows[0]["backend"], "serial", "{rows}");
    assert_eq!(rows[0]["repetitions"], 2, "{rows}");

    let mut rows = records::read(&file).unwrap();
    rows[0].wall_s = -1.0;
    records::write(&study.join("backup.parquet"), &rows).unwrap();
    let refused = collide(&["results", study.join("backup.parquet").to_str().unwrap()]);
    assert_eq!(refused.status.code(), Some(2));
    assert!(
        stderr(&refused).contains("`wall_s` = -1"),
        "{}",
        stderr(&refused)
    );
}

#[test]
fn inputs_without_bound_are_refused_before_anything_is_allocated() {
    let dir = tempfile::tempdir().unwrap();
    tiny_scene(dir.path());
    let study = |name: &str, body: &str| {
        let backends = match body.contains("[backends]") {
            true => "",
            false => "\n[backends]\nserial = true",
        };
        let text = format!("name = \"{name}\"\n{body}{backends}\n[[scenes]]\nfile = \"s.toml\"\n");
        scene_file(dir.path(), &format!("{name}.toml"), &text)
            .to_str()
            .unwrap()
            .to_owned()
    };
    let cases = [
        (study("reps", "repetitions = 1000000000"), "1000000000 runs"),
        (
            study(
                "sweep",
                "[sweep]\nseed = [1,2,3,4,5,6,7,8,9,10]\ndt = [0.1,0.2,0.3,0.4,0.5,0.6,0.7,0.8,0.9,1.0]\n\
                 steps = [1,2,3,4,5,6,7,8,9,10]\nn = [10,20,30,40,50,60,70,80,90,100]\n\
                 packing = [0.01,0.02,0.03,0.04,0.05,0.06,0.07,0.08,0.09,0.1]",
            ),
            "more than 10000 points",
        ),
        (
            study("forever", "timeout_s = 1e300"),
            "`timeout_s` is 1000000000",
        ),
        (
            study(
                "huge",
                "scaling = \"weak\"\n[sweep]\nn = [4611686018427387904]\n[backends]\nrayon = [2, 4]",
            ),
            "beyond any count",
        ),
    ];
    for (manifest, says) in &cases {
        let err = refused_in(dir.path(), &["run", manifest, "--out", "r"]);
        assert!(err.contains(says), "{manifest}: {err}");
    }
    let fifo = dir.path().join("fifo.toml");
    make_fifo(&fifo);
    for args in [
        vec!["simulate", "/dev/zero"],
        vec!["run", "/dev/zero"],
        vec!["simulate", fifo.to_str().unwrap()],
    ] {
        let err = refused_in(dir.path(), &args);
        assert!(err.contains("not a regular file"), "{args:?}: {err}");
    }
    // A FIFO named like results in a results folder is passed over, not waited on.
    let results = dir.path().join("results");
    std::fs::create_dir(&results).unwrap();
    make_fifo(&results.join("zz.parquet"));
    let err = refused_in(dir.path(), &["results", "results"]);
    assert!(err.contains("named pipe"), "{err}");
}

/// Sends SIGTERM to `collide ARGS` (run in `dir`) once `ready` holds; its exit code.
fn terminated_when(dir: &Path, args: &[&str], ready: impl Fn() -> bool) -> Option<i32> {
    let mut child = Command::new(env!("CARGO_BIN_EXE_collide"))
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while !ready() {
        assert!(started.elapsed() < Duration::from_secs(30), "never ready");
        assert!(
            child.try_wait().unwrap().is_none(),
            "ended before the signal"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let pid = rustix::process::Pid::from_raw(child.id() as i32).unwrap();
    rustix::process::kill_process(pid, rustix::process::Signal::TERM).unwrap();
    child.wait().unwrap().code()
}

#[test]
fn sigterm_exits_130_and_leaves_no_unfinished_file() {
    let dir = tempfile::tempdir().unwrap();
    let long = scene_file(
        dir.path(),
        "long.toml",
        "[scene]\nn = 20000\npacking = 0.1\n[method]\ndt = 0.01\nsteps = 100000\n",
    );
    let started = Instant::now();
    let code = terminated_when(dir.path(), &["simulate", long.to_str().unwrap()], || {
        started.elapsed() > Duration::from_millis(500)
    });
    assert_eq!(code, Some(130));

    let partial = || {
        std::fs::read_dir(dir.path()).unwrap().any(|e| {
            e.unwrap()
                .file_name()
                .to_string_lossy()
                .ends_with(".partial")
        })
    };
    let gif = [
        "render",
        long.to_str().unwrap(),
        "--steps",
        "3000",
        "--frames",
        "1000",
        "--gif",
        "run.gif",
    ];
    assert_eq!(terminated_when(dir.path(), &gif, partial), Some(130));
    assert!(!partial(), "an interrupted GIF left its partial file");
    assert!(!dir.path().join("run.gif").exists());
}

#[test]
fn names_taken_from_file_names_pass_the_name_check() {
    let dir = tempfile::tempdir().unwrap();
    for stem in [
        "<img src=x onerror=alert(1)>",
        "# HEADING",
        "a | b",
        "tick`",
        "esc\u{1b}[31m",
    ] {
        let file = format!("{stem}.toml");
        std::fs::write(dir.path().join(&file), SCENE).unwrap();
        let text = format!(
            "name = \"named\"\n[backends]\nserial = true\n[[scenes]]\nfile = {}\n",
            toml::Value::String(file.clone())
        );
        let manifest = scene_file(dir.path(), "m.toml", &text);
        let err = refused_in(
            dir.path(),
            &["run", manifest.to_str().unwrap(), "--out", "r"],
        );
        assert!(err.contains("rename the file"), "{stem}: {err}");
        assert!(
            !err.contains('\u{1b}'),
            "an escape reached the terminal: {err:?}"
        );
    }
    assert!(!dir.path().join("r").exists());
}

#[test]
fn environment_overrides_are_checked_against_the_machine_and_named_when_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let s = scene.to_str().unwrap();
    let cores = std::fs::read_to_string("/sys/devices/system/cpu/online").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_collide"))
        .args([
            "simulate",
            s,
            "--backend",
            "rayon",
            "--json",
            "--oversubscribe",
        ])
        .args(["--threads", "64"])
        .env("COLLIDE_USABLE_CPUS", "100000")
        .output()
        .unwrap();
    assert!(out.status.success(), "{} ({cores})", stderr(&out));
    let json: serde_json::Value =
        serde_json::from_str(String::from_utf8_lossy(&out.stdout).lines().last().unwrap()).unwrap();
    assert_eq!(json["oversubscribed"], true, "{json}");

    // A timeout variable only MPI reads does not fail a serial run.
    let serial = Command::new(env!("CARGO_BIN_EXE_collide"))
        .args(["simulate", s])
        .env("COLLIDE_MPI_TIMEOUT", "abc")
        .output()
        .unwrap();
    assert!(serial.status.success(), "{}", stderr(&serial));
}

#[test]
fn bad_values_get_messages_that_say_what_is_wrong_and_where() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let s = scene.to_str().unwrap();
    for (args, says) in [
        (vec!["simulate", s, "--seed", "-1"], "a whole number from 0"),
        (vec!["view", s, "--max-fps", "-1"], "frames per second"),
        (vec!["view", s, "--max-fps", "1e-300"], "frames per second"),
        (vec!["check", "--noise", "-1"], "a fraction from 0"),
        (
            vec!["simulate", s, "--inject-slowdown", "1e300"],
            "a fraction from 0",
        ),
    ] {
        let err = refused_in(dir.path(), &args);
        assert!(err.contains(says), "{args:?}: {err}");
        assert!(!err.contains("unexpected argument"), "{args:?}: {err}");
    }
    std::fs::write(dir.path().join("latin1.toml"), b"name = \"caf\xe9\"\n").unwrap();
    let err = refused_in(dir.path(), &["run", "latin1.toml"]);
    assert!(err.contains("not UTF-8"), "{err}");

    let manifest = manifest(dir.path(), "repetitions = 1\n[backends]\nserial = true");
    std::os::unix::fs::symlink("nowhere", dir.path().join("dangling")).unwrap();
    for flag in ["--out", "--reports"] {
        let err = refused_in(dir.path(), &["run", &manifest, flag, "dangling"]);
        assert!(err.contains("which does not exist"), "{flag}: {err}");
    }
    assert!(!dir.path().join("results").exists(), "a run started anyway");

    let crowded = scene_file(
        dir.path(),
        "crowded.toml",
        "[scene]\nn = 100\nsize = [1.0, 1.0]\n[method]\ndt = 0.1\nsteps = 5\n",
    );
    let err = refused_in(dir.path(), &["simulate", crowded.to_str().unwrap()]);
    assert!(err.contains("crowded.toml:3"), "{err}");
    assert!(!err.contains("placement = \"lattice\""), "{err}");

    // Results two levels below the folder named.
    let out = dir.path().join("deep").join("results");
    assert!(run_study(&manifest, &out, &[]).status.success());
    let shown = collide(&["results", dir.path().join("deep").to_str().unwrap()]);
    assert!(shown.status.success(), "{}", stderr(&shown));
    assert!(String::from_utf8_lossy(&shown.stdout).contains("serial"));
}
