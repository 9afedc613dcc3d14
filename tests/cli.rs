//! The `collide` command as a user meets it: summaries, JSON, dumps and bad input.

use std::time::{Duration, Instant};

use crate::util::{collide, json_summary, scene_file};

const SEED_SCENE: &str = "experiments/scenes/seed-1000.toml";

#[test]
fn simulate_prints_a_readable_summary() {
    let out = collide(&["simulate", SEED_SCENE]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("1000 disks"), "{text}");
    assert!(text.contains("400 steps"), "{text}");
    assert!(text.contains("state hash"), "{text}");
}

#[test]
fn json_is_one_object_on_the_last_line_with_the_stable_fields() {
    let out = collide(&["simulate", SEED_SCENE, "--json", "--steps", "50"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let last = text.lines().last().unwrap();
    let json: serde_json::Value = serde_json::from_str(last).unwrap();
    for field in [
        "n",
        "steps",
        "dt",
        "backend",
        "workers",
        "threads",
        "ranks",
        "oversubscribed",
        "wall_s",
        "setup_s",
        "fps",
        "particle_steps_per_s",
        "integration_s",
        "broad_phase_s",
        "collision_s",
        "communication_s",
        "kinetic_energy_initial",
        "kinetic_energy_final",
        "momentum_initial",
        "momentum_final",
        "pair_collisions",
        "wall_collisions",
        "max_overlap",
        "max_wall_penetration",
        "state_hash",
    ] {
        assert!(json.get(field).is_some(), "missing {field} in {last}");
    }
    assert_eq!(json["n"], 1000);
    assert_eq!(json["steps"], 50);
    assert_eq!(json["backend"], "serial");
    assert_eq!(json["momentum_final"].as_array().unwrap().len(), 2);
    assert_eq!(json["state_hash"].as_str().unwrap().len(), 16);
}

#[test]
fn overrides_replace_scene_values() {
    let json = json_summary(&[
        "simulate",
        SEED_SCENE,
        "--n",
        "200",
        "--steps",
        "10",
        "--seed",
        "9",
        "--packing",
        "0.2",
        "--dt",
        "auto",
    ]);
    assert_eq!(json["n"], 200);
    assert_eq!(json["steps"], 10);
    assert_eq!(json["seed"], 9);
    assert!((json["packing"].as_f64().unwrap() - 0.2).abs() < 1e-12);
    // `--dt auto` without dt_fraction: the largest rung 4·2^-k within missed_tolerance.
    let fraction = json["dt_auto_fraction"].as_f64().unwrap();
    assert_eq!(fraction.log2().fract(), 0.0, "{fraction}");
    assert!(json["choice"].as_str().unwrap().contains("dt auto"));
}

#[test]
fn dump_writes_the_final_state_in_id_order() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("state.csv");
    let out = collide(&[
        "simulate",
        "experiments/scenes/two-disks-head-on.toml",
        "--dump",
        dump.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let csv = std::fs::read_to_string(&dump).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], "id,x,y,vx,vy,radius,mass");
    assert_eq!(lines.len(), 3);
    // Elastic head-on collision of equal disks: velocities exchanged exactly.
    assert!(
        lines[1].starts_with("0,") && lines[1].ends_with(",50,-1,0,1,1"),
        "{}",
        lines[1]
    );
    assert!(
        lines[2].starts_with("1,") && lines[2].ends_with(",50,1,0,1,1"),
        "{}",
        lines[2]
    );
}

/// Runs a bad scene; asserts a quick failure whose message names every fragment.
fn assert_rejected(args: &[&str], fragments: &[&str]) {
    let started = Instant::now();
    let out = collide(args);
    assert!(
        started.elapsed() < Duration::from_secs(1),
        "took {:?}",
        started.elapsed()
    );
    assert!(!out.status.success(), "{args:?} was accepted");
    let stderr = String::from_utf8(out.stderr).unwrap();
    for fragment in fragments {
        assert!(
            stderr.contains(fragment),
            "{args:?}: `{fragment}` not in: {stderr}"
        );
    }
}

const GAS: &str = "[scene]\nn = 100\npacking = 0.05\n[method]\ndt = 0.1\nsteps = 10\n";

#[test]
fn bad_scenes_are_rejected_with_file_line_field_and_fix() {
    let dir = tempfile::tempdir().unwrap();
    let cases: &[(&str, &str, &[&str])] = &[
        (
            "unknown.toml",
            "[scene]\nn = 100\npacking = 0.05\nradus = 1.0\n[method]\nsteps = 1\n",
            &["unknown.toml:4", "radus"],
        ),
        (
            "negative-radius.toml",
            "[scene]\nn = 100\npacking = 0.05\nradius = -1.0\n[method]\nsteps = 1\n",
            &["negative-radius.toml:4", "scene.radius", "radius > 0"],
        ),
        (
            "zero-n.toml",
            "[scene]\nn = 0\npacking = 0.05\n[method]\nsteps = 1\n",
            &["zero-n.toml:2", "scene.n", "at least 1"],
        ),
        (
            "restitution.toml",
            "[scene]\nn = 10\npacking = 0.05\nrestitution = 1.5\n[method]\nsteps = 1\n",
            &["restitution.toml:4", "scene.restitution", "[0, 1]"],
        ),
        (
            "packing.toml",
            "[scene]\nn = 10\npacking = 0.7\n[method]\nsteps = 1\n",
            &["packing.toml:3", "scene.packing", "lattice"],
        ),
        (
            "overlap.toml",
            "[scene]\nsize = [10.0, 10.0]\n[[scene.particle]]\nx = 5.0\ny = 5.0\n[[scene.particle]]\nx = 6.0\ny = 5.0\n[method]\nsteps = 1\n",
            &[
                "overlap.toml:6",
                "scene.particle[1]",
                "overlaps scene.particle[0]",
                "apart",
            ],
        ),
        (
            "radius-word.toml",
            "[scene]\nn = 10\npacking = 0.05\nradius = \"big\"\n[method]\nsteps = 1\n",
            &["radius-word.toml:4", "expected a radius", "min = 0.5"],
        ),
        (
            "boundary.toml",
            "[scene]\nn = 10\npacking = 0.05\nboundary = \"wall\"\n[method]\nsteps = 1\n",
            &["boundary.toml:4", "`walls` or `periodic`"],
        ),
        (
            "outside.toml",
            "[scene]\nsize = [10.0, 10.0]\n[[scene.particle]]\nx = 9.5\ny = 5.0\n[method]\nsteps = 1\n",
            &["outside.toml:3", "scene.particle[0]", "inside"],
        ),
    ];
    for (name, text, fragments) in cases {
        let path = scene_file(dir.path(), name, text);
        assert_rejected(&["simulate", path.to_str().unwrap()], fragments);
    }
}

#[test]
fn bad_overrides_and_missing_files_are_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let path = scene_file(dir.path(), "gas.toml", GAS);
    let path = path.to_str().unwrap();
    assert_rejected(&["simulate", path, "--n", "0"], &["--n", "scene.n"]);
    assert_rejected(&["simulate", path, "--dt", "-1"], &["--dt", "positive"]);
    assert_rejected(
        &["simulate", path, "--packing", "0.9"],
        &["--packing", "lattice"],
    );
    assert_rejected(
        &["simulate", "no/such/scene.toml"],
        &["no/such/scene.toml", "check the path"],
    );
}

#[test]
fn bad_worker_counts_are_rejected_with_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let path = scene_file(dir.path(), "gas.toml", GAS);
    let path = path.to_str().unwrap();
    for flag in ["--threads", "--ranks"] {
        assert_rejected(&["simulate", path, flag, "0"], &[flag, "at least 1"]);
    }
    assert_rejected(
        &["simulate", path, "--threads", "2"],
        &["--threads", "serial backend steps on one", "--backend mpi"],
    );
    assert_rejected(
        &["simulate", path, "--backend", "rayon", "--ranks", "2"],
        &["--ranks", "--backend mpi"],
    );
}

/// `collide simulate ARGS` with `COLLIDE_USABLE_CPUS=1` (a machine of one CPU, so at
/// most 8 workers): its output.
fn on_one_cpu(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_collide"))
        .arg("simulate")
        .args(args)
        .env("COLLIDE_USABLE_CPUS", "1")
        .output()
        .unwrap()
}

#[test]
fn mpi_ranks_times_threads_are_held_to_the_worker_ceiling_unless_insisted() {
    let dir = tempfile::tempdir().unwrap();
    let path = scene_file(dir.path(), "gas.toml", GAS);
    let path = path.to_str().unwrap();
    let hybrid = [path, "--backend", "mpi", "--ranks", "3", "--threads", "3"];
    let refused = on_one_cpu(&hybrid);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(2), "{stderr}");
    for fragment in [
        "--ranks × --threads asks for 9 workers",
        "add --oversubscribe",
    ] {
        assert!(stderr.contains(fragment), "`{fragment}` not in: {stderr}");
    }
    // Each count alone is within the ceiling: only their product is refused.
    let insisted = on_one_cpu(&[&hybrid[..], &["--oversubscribe", "--steps", "2"]].concat());
    let stderr = String::from_utf8_lossy(&insisted.stderr);
    assert!(!stderr.contains("asks for"), "{stderr}");
}

#[cfg(not(feature = "mpi"))]
#[test]
fn mpi_without_the_feature_says_how_to_build_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = scene_file(dir.path(), "gas.toml", GAS);
    for threads in [&[][..], &["--threads", "2"]] {
        assert_rejected(
            &[
                &["simulate", path.to_str().unwrap(), "--backend", "mpi"],
                threads,
            ]
            .concat(),
            &["without MPI support", "--features mpi", "libopenmpi-dev"],
        );
    }
}

#[test]
fn rayon_prints_the_serial_hash_and_its_worker_counts() {
    let dir = tempfile::tempdir().unwrap();
    let path = scene_file(dir.path(), "gas.toml", GAS);
    let path = path.to_str().unwrap();
    let summary = |extra: &[&str]| json_summary(&[&["simulate", path], extra].concat());
    let serial = summary(&[]);
    let rayon = summary(&["--backend", "rayon", "--threads", "3"]);
    assert_eq!(rayon["state_hash"], serial["state_hash"]);
    assert_eq!(rayon["backend"], "rayon");
    assert_eq!(
        (rayon["threads"].as_u64(), rayon["ranks"].as_u64()),
        (Some(3), Some(1))
    );
    for stage in [
        "integration_s",
        "broad_phase_s",
        "collision_s",
        "communication_s",
    ] {
        assert!(rayon[stage].as_f64().unwrap() >= 0.0, "{stage}");
    }
    assert!(rayon["oversubscribed"].is_boolean());
}

#[test]
fn a_jammed_random_placement_fails_fast_instead_of_looping() {
    let dir = tempfile::tempdir().unwrap();
    // A packing random addition cannot reach is refused before any try; a box too
    // narrow for one disk jams at the first disk tried.
    for (name, scene, says) in [
        ("dense.toml", "n = 2000\npacking = 0.54", "scene.packing"),
        (
            "narrow.toml",
            "n = 10\nsize = [1.5, 1000.0]",
            "jammed at disk",
        ),
    ] {
        let text = format!("[scene]\n{scene}\n[method]\nsteps = 1\n");
        let path = scene_file(dir.path(), name, &text);
        let started = Instant::now();
        let out = collide(&["simulate", path.to_str().unwrap()]);
        assert!(!out.status.success());
        assert!(
            started.elapsed() < Duration::from_secs(10),
            "took {:?}",
            started.elapsed()
        );
        let stderr = String::from_utf8(out.stderr).unwrap();
        assert!(
            stderr.contains(says) && stderr.contains("lattice"),
            "{stderr}"
        );
    }
}
