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

#[test]
fn a_site_that_does_not_pin_tells_each_launcher_so() {
    for (scheduler, launcher, unpinned) in [
        ("slurm", "srun", "--cpu-bind=none"),
        ("none", "mpirun", "--bind-to none"),
        ("flux", "flux run", "cpu-affinity=off"),
    ] {
        let site = Site {
            bind: collide::cluster::site::Bind::None,
            ..site(scheduler, launcher)
        };
        let argv = launch_line(&site, LAYOUTS[1]).argv.join(" ");
        assert!(argv.contains(unpinned), "{argv}");
    }
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
        // OpenMPI refuses to bind ranks × PE=threads beyond the cores: such ranks go
        // unbound.
        if launcher == "mpirun" {
            assert!(argv.contains("--bind-to none"), "{argv}");
        }
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

/// A fake Slurm in `dir/bin` (sbatch, squeue, scontrol, scancel, srun) with its state in
/// `dir/queue`: the n-th submission (ids from 101) follows line n of `queue/plan`:
/// `run` (runs at once; squeue lists it RUNNING until it ends, then only scontrol knows
/// it, COMPLETED), `hold` (PENDING until `queue/release` exists, then runs), `timeout`,
/// `cancelled` (squeue lists it so), `lost` (nobody knows it).
fn fake_slurm(dir: &Path, plan: &[&str]) -> std::ffi::OsString {
    let bin = dir.join("bin");
    let queue = dir.join("queue");
    std::fs::create_dir_all(&bin).unwrap();
    std::fs::create_dir_all(&queue).unwrap();
    std::fs::write(queue.join("plan"), plan.join("\n") + "\n").unwrap();
    let q = queue.display();
    let start = format!(
        "start() {{ mkdir {q}/$1.started 2>/dev/null || return 0; s=$(cat {q}/$1.script); \
         out=$(sed -n 's/^#SBATCH --output=//p' $s); err=$(sed -n 's/^#SBATCH --error=//p' $s); \
         (bash $s >$out 2>$err; touch {q}/$1.done) >/dev/null 2>&1 & }}\n"
    );
    let scripts = [
        (
            "sbatch",
            format!(
                "n=$(( $(cat {q}/next 2>/dev/null || echo 100) + 1 )); echo $n > {q}/next\n\
                 sed -n \"$((n - 100))p\" {q}/plan > {q}/$n.plan; echo \"${{@: -1}}\" > {q}/$n.script\n\
                 {start}[ \"$(cat {q}/$n.plan)\" = run ] && start $n\necho $n\n"
            ),
        ),
        (
            "squeue",
            format!(
                "{start}ids=${{@: -1}}\nfor n in ${{ids//,/ }}; do\n  plan=$(cat {q}/$n.plan)\n  \
                 if [ $plan = hold ] && [ -e {q}/release ]; then start $n; plan=run; fi\n  \
                 t='2026-11-29T04:00:00|2026-11-29T04:00:03'\n  case $plan in\n  \
                 run) [ -e {q}/$n.done ] || echo \"$n|RUNNING|None|n1|$t\" ;;\n  \
                 hold) echo \"$n|PENDING|Priority||2026-11-29T04:00:00|N/A\" ;;\n  \
                 timeout) echo \"$n|TIMEOUT|TimeLimit|n1|$t\" ;;\n  \
                 cancelled) echo \"$n|CANCELLED by 0|None|n1|$t\" ;;\n  esac\ndone\n"
            ),
        ),
        (
            "scontrol",
            format!(
                "n=$3\nif [ -e {q}/$n.done ]; then echo \"JobId=$n JobState=COMPLETED Reason=None \
                 NodeList=n1 SubmitTime=2026-11-29T04:00:00 StartTime=2026-11-29T04:00:03\"; \
                 else echo 'slurm_load_jobs error: Invalid job id specified' >&2; exit 1; fi\n"
            ),
        ),
        ("scancel", format!("echo \"$@\" >> {q}/cancelled\n")),
        (
            "srun",
            "while [[ $1 == -* ]]; do shift; done\nexec \"$@\"\n".to_owned(),
        ),
    ];
    for (name, body) in scripts {
        let path = bin.join(name);
        std::fs::write(&path, format!("#!/bin/bash\n{body}")).unwrap();
        std::fs::set_permissions(&path, std::os::unix::fs::PermissionsExt::from_mode(0o755))
            .unwrap();
    }
    let mut path = std::ffi::OsString::from(bin);
    path.push(":");
    path.push(std::env::var_os("PATH").unwrap());
    path
}

/// A study of `runs` serial runs (n = 100, 110, ...) and the fake site's file, in `dir`.
fn batch_study(dir: &Path, runs: usize) -> (std::path::PathBuf, std::path::PathBuf) {
    let n: Vec<String> = (0..runs).map(|i| (100 + 10 * i).to_string()).collect();
    let manifest = dir.join("study.toml");
    std::fs::write(
        &manifest,
        format!(
            "name = \"batch\"\nrepetitions = 1\nwarmups = 0\n[sweep]\nn = [{}]\n[backends]\n\
             serial = true\n[[scenes]]\nname = \"gas\"\n[scenes.scene]\npacking = 0.1\nseed = 3\n\
             [scenes.method]\ndt = 0.1\nsteps = 20\n",
            n.join(", ")
        ),
    )
    .unwrap();
    let site = dir.join("fake.toml");
    std::fs::write(&site, "scheduler = \"slurm\"\ncores_per_node = 2\n").unwrap();
    (manifest, site)
}

fn run_args(manifest: &Path, site: &Path, out: &Path) -> Vec<std::ffi::OsString> {
    vec![
        "run".into(),
        manifest.into(),
        "--system".into(),
        site.into(),
        "--out".into(),
        out.into(),
        "--no-report".into(),
        "--quiet".into(),
    ]
}

fn rows_of(out: &Path) -> Vec<collide::study::records::Record> {
    use collide::study::records;
    let mut rows = Vec::new();
    for file in records::files_in(&out.join("batch")).unwrap() {
        rows.extend(records::read(&file).unwrap());
    }
    rows.sort_by(|a, b| a.job_id.cmp(&b.job_id));
    rows
}

#[test]
fn batch_jobs_that_complete_time_out_are_cancelled_or_lost_each_leave_their_row() {
    let dir = tempfile::tempdir().unwrap();
    let path = fake_slurm(dir.path(), &["run", "timeout", "cancelled", "lost"]);
    let (manifest, site) = batch_study(dir.path(), 4);
    let out = dir.path().join("results");
    let ended = std::process::Command::new(env!("CARGO_BIN_EXE_collide"))
        .args(run_args(&manifest, &site, &out))
        .env("PATH", path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&ended.stderr);
    assert_eq!(ended.status.code(), Some(1), "three runs failed: {stderr}");
    let rows = rows_of(&out);
    let got: Vec<(&str, &str, &str)> = rows
        .iter()
        .map(|r| (r.status.as_str(), r.job_id.as_str(), r.node_list.as_str()))
        .collect();
    assert_eq!(
        got,
        [
            ("ok", "101", "n1"),
            ("timed_out", "102", "n1"),
            ("failed", "103", "n1"),
            ("failed", "104", "")
        ]
    );
    assert_eq!(rows[0].queue_wait_s, 3.0);
    // Its one rank said where it ran, before the program's own output.
    let jobs = out.join("batch").join("jobs");
    let err = std::fs::read_dir(&jobs)
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .filter(|path| path.extension().is_some_and(|ext| ext == "err"))
        .map(|path| std::fs::read_to_string(path).unwrap())
        .find(|text| text.contains("collide-rank: "))
        .expect("a rank reported its CPUs");
    assert!(err.starts_with("collide-rank: 0 "), "{err}");
    assert!(!rows[0].state_hash.is_empty());
    assert!(rows[1].error.contains("timed out"), "{}", rows[1].error);
    assert!(rows[2].error.contains("cancelled"), "{}", rows[2].error);
    assert!(
        rows[3].error.contains("neither squeue nor scontrol"),
        "{}",
        rows[3].error
    );
}

/// Starts `collide run` on the fake queue and waits until it has submitted `jobs` jobs.
fn submitted(
    path: &std::ffi::OsString,
    args: &[std::ffi::OsString],
    queue: &Path,
    jobs: usize,
) -> std::process::Child {
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_collide"))
        .args(args)
        .env("PATH", path)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    while std::fs::read_to_string(queue.join("next"))
        .ok()
        .as_deref()
        .map(str::trim)
        != Some(&(100 + jobs).to_string())
    {
        assert!(
            started.elapsed().as_secs() < 30,
            "the jobs were not submitted"
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    // The ids reach the study's state file just after the submission.
    std::thread::sleep(std::time::Duration::from_millis(300));
    child
}

#[test]
fn a_killed_study_resumes_its_submitted_jobs_by_id_and_ctrl_c_cancels_them() {
    let dir = tempfile::tempdir().unwrap();
    let queue = dir.path().join("queue");
    let path = fake_slurm(dir.path(), &["hold", "hold", "hold", "hold"]);
    let (manifest, site) = batch_study(dir.path(), 2);
    let out = dir.path().join("results");
    let args = run_args(&manifest, &site, &out);
    // Killed hard while both jobs wait: nothing is cancelled, the ids stay on disk.
    let mut child = submitted(&path, &args, &queue, 2);
    child.kill().unwrap();
    child.wait().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(300));
    assert!(
        !queue.join("cancelled").exists(),
        "a hard kill cancels nothing"
    );
    // Resumed once the queue lets them run: collected by id, none submitted again.
    std::fs::write(queue.join("release"), "").unwrap();
    let mut resume = args.clone();
    resume.push("--resume".into());
    let ended = std::process::Command::new(env!("CARGO_BIN_EXE_collide"))
        .args(&resume)
        .env("PATH", &path)
        .output()
        .unwrap();
    assert!(
        ended.status.success(),
        "{}",
        String::from_utf8_lossy(&ended.stderr)
    );
    assert_eq!(
        std::fs::read_to_string(queue.join("next")).unwrap().trim(),
        "102"
    );
    let ids: Vec<String> = rows_of(&out).into_iter().map(|r| r.job_id).collect();
    assert_eq!(ids, ["101", "102"]);
    // A new study held in the queue, then Ctrl-C: its two jobs are cancelled.
    std::fs::remove_file(queue.join("release")).unwrap();
    std::fs::remove_dir_all(&out).unwrap();
    let child = submitted(&path, &args, &queue, 4);
    rustix::process::kill_process(
        rustix::process::Pid::from_child(&child),
        rustix::process::Signal::INT,
    )
    .unwrap();
    let ended = child.wait_with_output().unwrap();
    assert_eq!(ended.status.code(), Some(130));
    std::thread::sleep(std::time::Duration::from_millis(500));
    let cancelled = std::fs::read_to_string(queue.join("cancelled")).unwrap();
    let mut ids: Vec<&str> = cancelled.split_whitespace().collect();
    ids.sort_unstable();
    assert_eq!(ids, ["103", "104"]);
}
