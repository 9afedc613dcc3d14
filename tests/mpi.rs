//! The MPI backend through real `mpirun`: the serial hash at 1, 2, 3 and 4 ranks, and
//! clear errors when the launcher fails or hangs. Built only with `--features mpi`.

use std::os::unix::fs::PermissionsExt;
use std::time::{Duration, Instant};

use crate::util::{collide, json_summary as summary, scene_file};

#[test]
fn mpi_at_1_2_3_and_4_ranks_gives_the_serial_hash() {
    let dir = tempfile::tempdir().unwrap();
    for boundary in ["walls", "periodic"] {
        for restitution in [1.0, 0.8] {
            for packing in [0.05, 0.35] {
                let text = format!(
                    "[scene]\nn = 1500\npacking = {packing}\nradius = {{ min = 0.6, max = 1.4 }}\n\
                     mass = \"area\"\nrestitution = {restitution}\nwall_restitution = {restitution}\n\
                     boundary = \"{boundary}\"\nseed = 4\n[method]\ndt = 0.05\nsteps = 200\n"
                );
                let name = format!("{boundary}-{restitution}-{packing}.toml");
                let path = scene_file(dir.path(), &name, &text);
                let path = path.to_str().unwrap();
                let serial = summary(&["simulate", path]);
                assert!(serial["pair_collisions"].as_u64().unwrap() > 50, "{name}");
                for ranks in ["1", "2", "3", "4"] {
                    let mpi = summary(&["simulate", path, "--backend", "mpi", "--ranks", ranks]);
                    assert_eq!(
                        mpi["state_hash"], serial["state_hash"],
                        "{name} {ranks} ranks"
                    );
                    assert_eq!(mpi["pair_collisions"], serial["pair_collisions"], "{name}");
                    // The ranks' exact sums and block series, read back by the launcher
                    // to the bit.
                    for field in [
                        "kinetic_energy_final",
                        "momentum_final",
                        "compressibility_z",
                    ] {
                        assert_eq!(mpi[field], serial[field], "{name} {ranks} ranks: {field}");
                    }
                    assert_eq!(mpi["ranks"].as_u64(), Some(ranks.parse().unwrap()));
                    assert_eq!(mpi["backend"], "mpi");
                }
            }
        }
    }
}

/// MPI ranks count what they send as ranks run as threads do: the count is written once,
/// around any `Communicator`, and reaches the JSON summary through the launcher.
#[test]
fn mpi_ranks_count_what_they_send_as_ranks_run_as_threads_do() {
    use collide::backend::comm::ThreadComm;
    use collide::backend::distributed::{self, FinalState};
    use collide::run::overrides::Overrides;
    use collide::run::scene_file;

    let scene = "experiments/scenes/seed-1000.toml";
    let spec = &scene_file::load(std::path::Path::new(scene), &Overrides::default()).unwrap();
    for ranks in [2, 3] {
        let outcomes = ThreadComm::run_group(ranks, |comm| {
            let one_thread = std::num::NonZeroUsize::MIN;
            distributed::run(&comm, spec, FinalState::Summed, one_thread).unwrap()
        });
        let threads = serde_json::to_value(&outcomes[0].as_ref().unwrap().summary).unwrap();
        let mpi = summary(&[
            "simulate",
            scene,
            "--backend",
            "mpi",
            "--ranks",
            &ranks.to_string(),
        ]);
        assert!(mpi["messages_per_step_max"].as_f64().unwrap() > 0.0);
        for field in [
            "messages_per_step_max",
            "messages_per_step_mean",
            "bytes_per_step_max",
            "bytes_per_step_mean",
            "collectives_per_step",
            "load_imbalance",
            "recuts",
            "setup_disks_max",
        ] {
            assert_eq!(mpi[field], threads[field], "{field} at {ranks} ranks");
        }
    }
}

#[test]
fn mpi_gives_the_serial_hash_for_a_pile_resting_under_gravity() {
    let scene = "experiments/scenes/granular-pile.toml";
    let serial = summary(&["simulate", scene, "--steps", "3000"]);
    assert!(serial["max_wall_penetration"].as_f64().unwrap() > 0.0);
    for ranks in ["2", "3"] {
        let mpi = summary(&[
            "simulate",
            scene,
            "--steps",
            "3000",
            "--backend",
            "mpi",
            "--ranks",
            ranks,
        ]);
        assert_eq!(mpi["state_hash"], serial["state_hash"], "{ranks} ranks");
        assert_eq!(
            mpi["max_wall_penetration"], serial["max_wall_penetration"],
            "{ranks} ranks"
        );
        for field in [
            "kinetic_energy_final",
            "compressibility_z",
            "compressibility_z_se",
            "temperature",
            "equilibration_cut_time",
        ] {
            assert_eq!(mpi[field], serial[field], "{ranks} ranks: {field}");
        }
    }
}

#[test]
fn mpi_dump_is_written_by_rank_0_in_id_order() {
    let dir = tempfile::tempdir().unwrap();
    let serial_csv = dir.path().join("serial.csv");
    let mpi_csv = dir.path().join("mpi.csv");
    let scene = "experiments/scenes/seed-1000.toml";
    summary(&["simulate", scene, "--dump", serial_csv.to_str().unwrap()]);
    summary(&[
        "simulate",
        scene,
        "--backend",
        "mpi",
        "--ranks",
        "2",
        "--dump",
        mpi_csv.to_str().unwrap(),
    ]);
    let serial = std::fs::read_to_string(serial_csv).unwrap();
    assert_eq!(serial.lines().count(), 1001);
    assert_eq!(std::fs::read_to_string(mpi_csv).unwrap(), serial);
}

/// A fake launcher: a shell script with the given body.
fn launcher(dir: &std::path::Path, body: &str) -> String {
    let path = dir.join("fake-mpirun");
    std::fs::write(&path, format!("#!/bin/sh\n{body}\n")).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    path.to_str().unwrap().to_owned()
}

#[test]
fn a_hung_launch_is_killed_at_the_timeout_and_a_failed_one_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let scene = "experiments/scenes/seed-1000.toml";
    let hung = launcher(dir.path(), "echo starting ranks >&2; sleep 30");
    let started = Instant::now();
    let out = collide(&[
        "simulate",
        scene,
        "--backend",
        "mpi",
        "--ranks",
        "2",
        "--launcher",
        &hung,
        "--mpi-timeout",
        "1",
    ]);
    assert!(
        started.elapsed() < Duration::from_secs(10),
        "{:?}",
        started.elapsed()
    );
    assert!(!out.status.success());
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(stderr.contains("did not finish within 1 s"), "{stderr}");
    assert!(stderr.contains("starting ranks"), "{stderr}");

    let dies = launcher(dir.path(), "echo 'rank 1 exited on signal 9' >&2; exit 137");
    let out = collide(&["simulate", scene, "--backend", "mpi", "--launcher", &dies]);
    assert!(!out.status.success());
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(
        stderr.contains("failed") && stderr.contains("signal 9"),
        "{stderr}"
    );

    let missing = collide(&[
        "simulate",
        scene,
        "--backend",
        "mpi",
        "--launcher",
        "no-such-mpirun",
    ]);
    let stderr = String::from_utf8(missing.stderr).unwrap();
    assert!(stderr.contains("cannot start `no-such-mpirun`"), "{stderr}");
    assert!(stderr.contains("COLLIDE_MPI_LAUNCHER"), "{stderr}");
}

#[test]
fn mpi_ranks_of_two_threads_give_the_serial_hash_and_count_their_workers() {
    let scene = "experiments/scenes/seed-1000.toml";
    let serial = summary(&["simulate", scene, "--steps", "50"]);
    // 2 ranks × 2 threads: more than this 2-CPU machine holds, so insisted on.
    let hybrid = summary(&[
        "simulate",
        scene,
        "--steps",
        "50",
        "--backend",
        "mpi",
        "--ranks",
        "2",
        "--threads",
        "2",
        "--oversubscribe",
    ]);
    assert_eq!(hybrid["state_hash"], serial["state_hash"]);
    let placed = ["ranks", "threads", "workers"].map(|field| hybrid[field].as_u64());
    assert_eq!(placed, [Some(2), Some(2), Some(4)], "{hybrid}");
}

/// `mpirun -n RANKS collide simulate ... --backend mpi` started by hand, unbound, with
/// `RAYON_NUM_THREADS` set to `threads` (unset for `None`): its output.
fn ranks_under_mpirun(ranks: usize, threads: Option<&str>) -> std::process::Output {
    let mut mpirun = std::process::Command::new("mpirun");
    mpirun
        .args([
            "-n",
            &ranks.to_string(),
            "--oversubscribe",
            "--bind-to",
            "none",
        ])
        .arg(env!("CARGO_BIN_EXE_collide"))
        .args([
            "simulate",
            "experiments/scenes/seed-1000.toml",
            "--steps",
            "20",
        ])
        .args(["--backend", "mpi", "--json"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1");
    match threads {
        Some(threads) => mpirun.env("RAYON_NUM_THREADS", threads),
        None => mpirun.env_remove("RAYON_NUM_THREADS"),
    };
    mpirun.output().unwrap()
}

/// The JSON summary rank 0 printed, after checking that the ranks succeeded.
fn summary_of(out: &std::process::Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(stdout.lines().last().unwrap()).unwrap()
}

/// Told no thread count, an unbound rank takes the CPUs it may run on, shared evenly
/// with the other ranks of its node.
#[test]
fn ranks_told_no_threads_take_their_share_of_the_cpus() {
    let mask = std::thread::available_parallelism().unwrap().get();
    let online = std::fs::read_to_string("/sys/devices/system/cpu/online").unwrap();
    let cores: usize = (online.trim().split(','))
        .map(|span| match span.split_once('-') {
            Some((low, high)) => high.parse::<usize>().unwrap() - low.parse::<usize>().unwrap() + 1,
            None => 1,
        })
        .sum();
    for ranks in [1, 2] {
        let json = summary_of(&ranks_under_mpirun(ranks, None));
        let share = mask.min(cores / ranks).max(1);
        assert_eq!(
            json["threads"].as_u64(),
            Some(share as u64),
            "{ranks} ranks: {json}"
        );
    }
}

#[test]
fn ranks_without_threads_take_rayon_num_threads_and_name_it_when_wrong() {
    let json = summary_of(&ranks_under_mpirun(2, Some("2")));
    assert_eq!(json["threads"].as_u64(), Some(2), "{json}");
    assert_eq!(json["workers"].as_u64(), Some(4), "{json}");
    let out = ranks_under_mpirun(2, Some("two"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("RAYON_NUM_THREADS=\"two\"") && stderr.contains("--threads"),
        "{stderr}"
    );
}
