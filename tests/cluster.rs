//! Studies on a cluster without a cluster: golden snapshots of every launcher line and
//! job script a site renders (each scheduler × launcher that can go together), for one
//! node of one-thread ranks, threaded ranks on two nodes, and an oversubscribed node.

use std::path::Path;

use collide::cluster::placement::Layout;
use collide::cluster::render::{Job, job_script, launch_line};
use collide::cluster::site::{Site, parse};

/// A site file of `scheduler` and `launcher` with every optional key set.
fn site(scheduler: &str, launcher: &str) -> Site {
    let text = format!(
        "scheduler = \"{scheduler}\"\nlauncher = \"{launcher}\"\ncores_per_node = 4\n\
         max_nodes = 2\npartition = \"debug\"\naccount = \"proj42\"\ntime_limit = \"00:10:00\"\n\
         scheduler_args = [\"--exclusive\"]\nlauncher_args = [\"--extra\"]\n\
         [env]\nOMPI_MCA_btl = \"self,tcp\"\n"
    );
    parse(Path::new("systems/golden.toml"), &text).unwrap()
}

const LAYOUTS: [Layout; 3] = [
    Layout {
        nodes: 1,
        ranks: 2,
        threads: 1,
    },
    Layout {
        nodes: 2,
        ranks: 4,
        threads: 2,
    },
    // 6 ranks × 2 threads on one node of 4 cores.
    Layout {
        nodes: 1,
        ranks: 6,
        threads: 2,
    },
];

/// Every rendering of `site`: its launcher line for each layout, and its job script for
/// each when it has a batch scheduler.
fn rendered(site: &Site) -> String {
    let program = [
        "/opt/collide/bin/collide".to_owned(),
        "simulate".to_owned(),
        "scene file.toml".to_owned(),
        "--json".to_owned(),
    ];
    let mut text = String::new();
    for layout in LAYOUTS {
        let line = launch_line(site, layout);
        let env: Vec<String> = line.env.iter().map(|(k, v)| format!("{k}={v}")).collect();
        text += &format!("# {layout}\n{}\n{}\n", env.join(" "), line.argv.join(" "));
        if site.is_batch() {
            let job = Job {
                name: "collide-golden-0",
                dir: Path::new("/scratch/results/golden/jobs"),
                workdir: Path::new("/scratch"),
                program: &program,
            };
            text += &format!("## job script\n{}", job_script(site, layout, &job));
        }
        text += "\n";
    }
    text
}

#[test]
fn every_launcher_line_and_job_script_matches_its_snapshot() {
    for (scheduler, launcher) in [
        ("none", "mpirun"),
        ("none", "mpiexec"),
        ("slurm", "srun"),
        ("slurm", "mpirun"),
        ("pbs", "mpirun"),
        ("pbs", "mpiexec"),
        ("flux", "flux run"),
    ] {
        let name = format!("{scheduler}-{}", launcher.replace(' ', "-"));
        insta::assert_snapshot!(name, rendered(&site(scheduler, launcher)));
    }
}

#[test]
fn threads_and_oversubscription_reach_every_launcher() {
    for (scheduler, launcher, threads_flag) in [
        ("none", "mpirun", "--map-by slot:PE=2"),
        ("none", "mpiexec", "-bind-to core:2"),
        ("slurm", "srun", "--cpus-per-task=2"),
        ("flux", "flux run", "--cores-per-task=2"),
    ] {
        let site = site(scheduler, launcher);
        let line = launch_line(&site, LAYOUTS[2]);
        let argv = line.argv.join(" ");
        assert!(argv.contains(threads_flag), "{launcher}: {argv}");
        assert!(
            line.env
                .contains(&("OMPI_MCA_mpi_yield_when_idle".into(), "1".into())),
            "{launcher}: oversubscribed ranks must yield: {:?}",
            line.env
        );
        assert!(line.env.contains(&("RAYON_NUM_THREADS".into(), "2".into())));
        // Within the cores, no rank is told to yield.
        let fits = launch_line(&site, LAYOUTS[0]);
        assert!(
            !fits
                .env
                .iter()
                .any(|(k, _)| k == "OMPI_MCA_mpi_yield_when_idle")
        );
    }
}

#[test]
fn a_job_script_fails_on_any_failed_command_and_always_writes_its_exit_code() {
    let site = site("slurm", "srun");
    let program = ["false".to_owned()];
    let dir = tempfile::tempdir().unwrap();
    let job = Job {
        name: "j",
        dir: dir.path(),
        workdir: dir.path(),
        program: &program,
    };
    let script = job_script(&site, LAYOUTS[0], &job);
    // Run it by bash, with srun replaced by a stand-in that runs the program once.
    let fake = dir.path().join("srun");
    std::fs::write(
        &fake,
        "#!/bin/bash\nwhile [[ $1 == -* ]]; do shift; done\nexec \"$@\"\n",
    )
    .unwrap();
    std::fs::set_permissions(&fake, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let path = format!(
        "{}:{}",
        dir.path().display(),
        std::env::var("PATH").unwrap()
    );
    let status = std::process::Command::new("bash")
        .arg("-c")
        .arg(&script)
        .env("PATH", path)
        .status()
        .unwrap();
    // The failing rank fails the job, and the trap wrote its code.
    assert_eq!(status.code(), Some(1));
    let code = std::fs::read_to_string(dir.path().join("j.exit")).unwrap();
    assert_eq!(code.trim(), "1");
}
