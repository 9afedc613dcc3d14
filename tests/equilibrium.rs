//! The equilibration cut, the error bars and the reference comparison of a run's
//! pressure, end to end: a dense lattice start melts, the cut removes the melting, and
//! the rest agrees with the equation of state within its error bar; a run too short to
//! settle says so instead of printing a number; a manual discard sets the window instead,
//! and one that leaves nothing to average is refused with the field named; the seeds of
//! a study are compared as replicas in its records and report.

use crate::util::{collide, json_summary, refused_in, report_of, run_study, scene_file};

/// 1024 equal disks on a square lattice at `packing` in a periodic box (the event
/// method, T = 0.5), over `steps` intervals of `dt`.
fn dense_lattice(dir: &std::path::Path, packing: f64, dt: f64, steps: u64) -> String {
    dense_lattice_with(dir, packing, dt, steps, "")
}

/// [`dense_lattice`] with `extra` lines at the end of its `[method]`.
fn dense_lattice_with(
    dir: &std::path::Path,
    packing: f64,
    dt: f64,
    steps: u64,
    extra: &str,
) -> String {
    let text = format!(
        "[scene]\nn = 1024\npacking = {packing}\nradius = 1.0\nmass = 1.0\nspeed_rms = 1.0\n\
         boundary = \"periodic\"\nplacement = \"lattice\"\nseed = 1\n\n\
         [method]\nmethod = \"event\"\ndt = {dt}\nsteps = {steps}\n{extra}"
    );
    let path = scene_file(dir, "dense.toml", &text);
    path.to_str().unwrap().to_owned()
}

#[test]
fn a_melted_lattice_agrees_with_luding_within_its_error_bar() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dense_lattice(dir.path(), 0.6, 1.0, 500);
    let json = json_summary(&["simulate", &scene]);
    assert_eq!(json["equilibrated"], true, "{json}");
    let cut = json["equilibration_cut_time"].as_f64().unwrap();
    // The lattice melts within a few units of time; the cut removes that, not the run.
    assert!(cut > 0.0 && cut < 250.0, "cut at {cut}");
    let z = json["compressibility_z"].as_f64().unwrap();
    let se = json["compressibility_z_se"].as_f64().unwrap();
    let z_ref = json["z_reference"].as_f64().unwrap();
    let se_ref = json["z_reference_se"].as_f64().unwrap();
    assert!(
        json["z_reference_source"]
            .as_str()
            .unwrap()
            .starts_with("Luding")
    );
    let score = (z - z_ref) / (se * se + se_ref * se_ref).sqrt();
    assert!(
        score.abs() < 3.0,
        "Z = {z} ± {se} against {z_ref} ± {se_ref}"
    );
    // A real error bar: a fraction of a percent, from more than a few blocks.
    assert!(se > 0.0 && se < 0.01 * z, "SE {se}");
    assert!(json["compressibility_z_g"].as_f64().unwrap() >= 1.0);
    assert!(json["compressibility_z_n_eff"].as_f64().unwrap() > 20.0);
}

#[test]
fn a_run_too_short_to_melt_says_so_instead_of_printing_a_number() {
    let dir = tempfile::tempdir().unwrap();
    // At packing 0.72 the lattice melts over t ≈ 100: a run to t = 40 is transient
    // throughout.
    let scene = dense_lattice(dir.path(), 0.72, 0.5, 80);
    let json = json_summary(&["simulate", &scene]);
    assert_eq!(json["equilibrated"], false, "{json}");
    assert!(json["compressibility_z_se"].is_null());
    assert!(json["equilibration_cut_time"].is_null());
    let out = collide(&["simulate", &scene]);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("not equilibrated: run longer"), "{text}");
    assert!(!text.contains("z-score"), "{text}");
    // A manual discard averages the run's second half all the same, and is told that
    // MSER-5 sees the transient go on.
    let out = collide(&["simulate", &scene, "--discard", "50%"]);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("(manual discard)"), "{text}");
    assert!(
        text.contains("warning    MSER-5 finds no end of the transient in the run's first half"),
        "{text}"
    );
}

#[test]
fn a_manual_discard_sets_the_averaged_window_instead_of_mser5() {
    let dir = tempfile::tempdir().unwrap();
    // 500 steps in 128 blocks: block j ends at step ⌈500·j/128⌉.
    let scene = dense_lattice_with(dir.path(), 0.6, 1.0, 500, "discard = \"30%\"\n");
    let manual = json_summary(&["simulate", &scene]);
    assert_eq!(manual["equilibration_cut"], "manual", "{manual}");
    assert_eq!(manual["equilibrated"], true);
    // 30% of t = 500 is t = 150, inside block 39 (t = 149 to 153): cut at its end.
    assert_eq!(manual["equilibration_cut_time"], 153.0);
    let by_flag = json_summary(&["simulate", &scene, "--discard", "100"]);
    assert_eq!(by_flag["equilibration_cut_time"], 102.0, "{by_flag}");
    let automatic = json_summary(&["simulate", &scene, "--discard", "auto"]);
    assert_eq!(automatic["equilibration_cut"], "mser5");
    // MSER-5's own cut, wherever this gas's transient ends (its block ends are the same).
    let automatic_cut = automatic["equilibration_cut_time"].as_f64().unwrap();
    assert!(
        automatic_cut != 153.0 && automatic_cut <= 250.0,
        "{automatic}"
    );
    // Other windows, other means (the run is the same: the same final state).
    let z = |json: &serde_json::Value| json["compressibility_z"].as_f64().unwrap();
    assert_ne!(z(&manual), z(&automatic));
    assert_ne!(z(&by_flag), z(&manual));
    assert_eq!(manual["state_hash"], automatic["state_hash"]);
    // Nothing discarded: the average from t = 0.
    let none = json_summary(&["simulate", &scene, "--discard", "0%"]);
    assert_eq!(
        none["compressibility_z"],
        none["compressibility_z_from_zero"]
    );
    let text = String::from_utf8(collide(&["simulate", &scene]).stdout).unwrap();
    assert!(
        text.contains("equilibrium cut at t = 1.5300e2 (manual discard)"),
        "{text}"
    );
    // MSER-5's cut is kept beside a manual one, whichever rule cut, and a discard
    // shorter than it is flagged: nothing discarded keeps the whole melting.
    assert_eq!(manual["equilibration_mser5_cut_time"], automatic_cut);
    assert_eq!(none["equilibration_mser5_cut_time"], automatic_cut);
    let warning = "which MSER-5 counts as transient";
    let text = |discard: &str| {
        String::from_utf8(collide(&["simulate", &scene, "--discard", discard]).stdout).unwrap()
    };
    let kept_all = text("0%");
    assert!(
        kept_all.contains(&format!(
            "warning    the discard keeps t = 0.0000e0 to {automatic_cut:.4e}, {warning}"
        )),
        "{kept_all}"
    );
    // A discard past MSER-5's cut, and MSER-5's own cut, are not flagged.
    for discard in ["60%", "auto"] {
        let quiet = text(discard);
        assert!(!quiet.contains(warning), "{discard}: {quiet}");
    }
}

#[test]
fn a_discard_that_leaves_nothing_to_average_is_refused_with_the_field_named() {
    let dir = tempfile::tempdir().unwrap();
    let cases: &[(&str, &[&str])] = &[
        (
            "discard = \"100%\"",
            &["100%", "the whole run", "discard = \"30%\""],
        ),
        (
            "discard = 500.0",
            &["past the end of the run at t = 500", "at most 493"],
        ),
        (
            "discard = 499.0",
            &["fewer than 2 of the run's 128 blocks", "at most 493"],
        ),
        ("discard = \"99.5%\"", &["fewer than 2", "at most \"98%\""]),
        ("discard = -5.0", &["not a simulated time ≥ 0"]),
        (
            "discard = \"most\"",
            &["\"most\", neither a share of the run nor \"auto\""],
        ),
    ];
    for (line, fragments) in cases {
        let scene = dense_lattice_with(dir.path(), 0.6, 1.0, 500, &format!("{line}\n"));
        let stderr = refused_in(dir.path(), &["simulate", &scene]);
        // The file, the line (the last of the scene) and the field.
        assert!(
            stderr.contains("dense.toml:15: `method.discard`"),
            "{line}: {stderr}"
        );
        for fragment in *fragments {
            assert!(
                stderr.contains(fragment),
                "{line}: `{fragment}` not in {stderr}"
            );
        }
    }
    let scene = dense_lattice(dir.path(), 0.6, 1.0, 500);
    let stderr = refused_in(dir.path(), &["simulate", &scene, "--discard", "120%"]);
    assert!(
        stderr.contains("(from --discard): `method.discard` is 120%"),
        "{stderr}"
    );
    // The wrong kind of value is a syntax error on its line.
    let scene = dense_lattice_with(dir.path(), 0.6, 1.0, 500, "discard = true\n");
    let stderr = refused_in(dir.path(), &["simulate", &scene]);
    assert!(stderr.contains("dense.toml:15"), "{stderr}");
    // A manifest's swept discard, before anything runs.
    let scene = dense_lattice(dir.path(), 0.6, 1.0, 500);
    let manifest = scene_file(
        dir.path(),
        "sweep.toml",
        &format!(
            "name = \"sweep\"\n[[scenes]]\nfile = \"{scene}\"\n[sweep]\ndiscard = [\"10%\", \"120%\"]\n\
             [backends]\nserial = true\n"
        ),
    );
    let stderr = refused_in(dir.path(), &["run", manifest.to_str().unwrap()]);
    assert!(
        stderr.contains("discard = 120%") && stderr.contains("`method.discard` is 120%"),
        "{stderr}"
    );
}

#[test]
fn a_study_sweeps_the_discard_and_compares_its_seeds_as_replicas() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = scene_file(
        dir.path(),
        "replicas.toml",
        "name = \"replicas\"\nrepetitions = 1\nwarmups = 0\n\n[[scenes]]\nname = \"gas\"\n\
         [scenes.scene]\nn = 256\npacking = 0.4\nboundary = \"periodic\"\nplacement = \"lattice\"\n\
         [scenes.method]\nmethod = \"event\"\ndt = 0.5\nsteps = 256\n\n\
         [sweep]\nseed = [1, 2, 3]\ndiscard = [\"auto\", \"25%\"]\n\n[backends]\nserial = true\n",
    );
    let out = dir.path().join("results");
    let run = run_study(manifest.to_str().unwrap(), &out, &[]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let folder = out.join("replicas");
    let files = collide::study::records::files_in(&folder).unwrap();
    let rows = collide::study::records::read(&files[0]).unwrap();
    assert_eq!(rows.len(), 6);
    let manual = |row: &collide::study::records::Record| row.config_key.contains(";discard=25%");
    // Only runs with an error bar count: MSER-5 may find a seed of so small a gas still
    // moving.
    let settled = rows
        .iter()
        .filter(|r| !manual(r) && r.compressibility_z_se.is_finite())
        .count() as u64;
    for row in &rows {
        match manual(row) {
            true => {
                assert_eq!(row.equilibration_cut, "manual");
                // 25% of t = 128: the end of block 32 of 128.
                assert_eq!(row.equilibration_cut_time, 32.0, "{}", row.config_key);
                assert_eq!(row.replicas, Some(3), "{}", row.config_key);
            }
            false => {
                assert_eq!(row.equilibration_cut, "mser5");
                assert_eq!(row.replicas, (settled >= 2).then_some(settled));
            }
        }
    }
    let mean_of = |is_manual: bool| {
        let row = rows.iter().find(|r| manual(r) == is_manual);
        row.unwrap().compressibility_z_replica_mean
    };
    assert_ne!(mean_of(true), mean_of(false));
    let text = report_of(&folder, &dir.path().join("report"));
    assert!(
        text.contains("| gas n=256 discard=25% | 1, 2, 3 | Z |"),
        "{text}"
    );
    assert!(
        settled < 2 || text.contains("| gas n=256 discard=auto | "),
        "{text}"
    );
}
