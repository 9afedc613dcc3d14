//! Renders a [`Layout`] on a [`Site`] into what starts it: the launcher's words and the
//! ranks' variables ([`launch_line`]), and, for a batch scheduler, the whole job script
//! ([`job_script`]). Pure functions of their inputs: the golden tests in
//! `tests/cluster.rs` hold every launcher × scheduler pair.
//!
//! The traps each line avoids: `srun` inside a job does not inherit `--cpus-per-task`
//! (Slurm 22.05–23.02), so it is passed to `srun` too; OpenMPI binds a rank to one core
//! (np ≤ 2) or a socket unless told `--map-by …:PE=T`, and refuses to bind at all when
//! ranks × threads exceed the cores (so oversubscribed ranks are not bound); an
//! oversubscribed OpenMPI rank busy-polls unless `OMPI_MCA_mpi_yield_when_idle=1`; a job script ending in a
//! pipeline reports success when its ranks crashed, so scripts `set -euo pipefail` and
//! write their exit code from a `trap` on every exit.

use std::path::Path;

use crate::cluster::placement::Layout;
use crate::cluster::site::{Bind, Launcher, Scheduler, Site};

/// The variable that sets the size of each rank's rayon pool.
pub const THREADS_ENV: &str = "RAYON_NUM_THREADS";

/// The OpenMPI setting that makes a waiting rank yield its CPU (other MPIs ignore it).
pub const YIELD_WHEN_IDLE: &str = "OMPI_MCA_mpi_yield_when_idle";

/// What starts a layout's ranks: the launcher's words (the program and its arguments
/// follow) and the variables every rank gets.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Line {
    pub argv: Vec<String>,
    pub env: Vec<(String, String)>,
}

/// The launcher's words and the ranks' variables for `layout` on `site`.
pub fn launch_line(site: &Site, layout: Layout) -> Line {
    let Layout {
        nodes,
        ranks,
        threads,
    } = layout;
    let per_node = layout.ranks_per_node();
    let over = layout.oversubscribes(site);
    let pin = site.bind == Bind::Cores;
    let mut env = vec![(THREADS_ENV.to_owned(), threads.to_string())];
    if over {
        env.push((YIELD_WHEN_IDLE.to_owned(), "1".to_owned()));
    }
    env.extend(site.env.iter().map(|(k, v)| (k.clone(), v.clone())));
    let mut argv = site.command.clone();
    argv.extend(site.launcher_args.iter().cloned());
    let words: Vec<String> = match site.launcher {
        Launcher::Mpirun => {
            let mut words = vec!["-n".to_owned(), ranks.to_string()];
            // One node of one-thread ranks keeps OpenMPI's own placement.
            if nodes > 1 {
                words.extend([
                    "--map-by".into(),
                    format!("ppr:{per_node}:node:PE={threads}"),
                ]);
            } else if threads > 1 {
                words.extend(["--map-by".into(), format!("slot:PE={threads}")]);
            }
            if nodes > 1 || threads > 1 {
                // Oversubscribed, OpenMPI refuses to bind (each rank's PE=T cores are not
                // there: "binding more processes than cpus"), so the ranks are left
                // unbound and the kernel shares the cores among them.
                let to = if pin && !over { "core" } else { "none" };
                words.extend(["--bind-to".into(), to.into()]);
            }
            if over {
                words.push("--oversubscribe".into());
            }
            // Ranks on other nodes get only the variables named with -x.
            if nodes > 1 {
                for (name, _) in &env {
                    words.extend(["-x".into(), name.clone()]);
                }
            }
            words
        }
        Launcher::Mpiexec => {
            let mut words = vec!["-n".to_owned(), ranks.to_string()];
            if nodes > 1 {
                words.extend(["-ppn".into(), per_node.to_string()]);
            }
            if threads > 1 && pin {
                words.extend(["-bind-to".into(), format!("core:{threads}")]);
            }
            words
        }
        Launcher::Srun => {
            let mut words = vec![
                format!("--nodes={nodes}"),
                format!("--ntasks={ranks}"),
                format!("--ntasks-per-node={per_node}"),
                format!("--cpus-per-task={threads}"),
                format!("--cpu-bind={}", site.bind.name()),
            ];
            if over {
                words.push("--overcommit".into());
            }
            words
        }
        Launcher::Flux => vec![
            format!("--nodes={nodes}"),
            format!("--ntasks={ranks}"),
            format!("--cores-per-task={threads}"),
            "-o".to_owned(),
            format!("cpu-affinity={}", if pin { "per-task" } else { "off" }),
        ],
    };
    argv.extend(words);
    Line { argv, env }
}

/// What each rank of a batch job runs before the program (`$0 "$@"`): one line on its
/// error output with its rank, host, allowed CPUs and threads.
const RANK_REPORT: &str = "echo \"collide-rank: ${SLURM_PROCID:-${OMPI_COMM_WORLD_RANK:-${PMI_RANK:-0}}} \
     ${SLURMD_NODENAME:-$(hostname)} $(sed -n 's/^Cpus_allowed_list:[[:space:]]*//p' /proc/self/status) \
     ${RAYON_NUM_THREADS:-1}\" >&2; exec \"$0\" \"$@\"";

/// One batch job: its name, the folder its output and exit-code files go to (beside
/// the script), the folder it runs in, and the program each rank runs.
#[derive(Clone, Copy, Debug)]
pub struct Job<'a> {
    pub name: &'a str,
    pub dir: &'a Path,
    pub workdir: &'a Path,
    pub program: &'a [String],
}

/// The file a job writes its exit code to, from a `trap` on every exit.
pub fn exit_file(dir: &Path, name: &str) -> std::path::PathBuf {
    dir.join(format!("{name}.exit"))
}

/// The file a job's standard output (rank 0's JSON summary) goes to.
pub fn output_file(dir: &Path, name: &str) -> std::path::PathBuf {
    dir.join(format!("{name}.out"))
}

/// The job script for `job` with `layout` on `site` (whose scheduler is a batch one).
pub fn job_script(site: &Site, layout: Layout, job: &Job<'_>) -> String {
    let head = scheduler_directives(site, layout, job);
    let line = launch_line(site, layout);
    let exit = quote(&exit_file(job.dir, job.name).display().to_string());
    let mut script = vec!["#!/bin/bash".to_owned()];
    script.extend(head);
    script.push("set -euo pipefail".into());
    script.push(
        "# The exit code, written on every exit (a crash, a signal, the end): the job's \
         state alone can say COMPLETED when the ranks failed."
            .into(),
    );
    script.push(format!(
        "trap 'code=$?; echo \"$code\" > {exit}.tmp && mv {exit}.tmp {exit}' EXIT"
    ));
    script.push(format!("cd {}", quote(&job.workdir.display().to_string())));
    for (name, value) in &line.env {
        script.push(format!("export {name}={}", quote(value)));
    }
    // Each rank first says where it runs (read back by `placement::rank_cpus`).
    let report = ["bash", "-c", RANK_REPORT];
    let words: Vec<String> = line
        .argv
        .iter()
        .map(String::as_str)
        .chain(report)
        .chain(job.program.iter().map(String::as_str))
        .map(quote)
        .collect();
    script.push(words.join(" "));
    script.join("\n") + "\n"
}

/// The scheduler's directives at the head of a job script (`#SBATCH`, `#PBS`,
/// `#flux:`): the job's name, nodes, ranks and threads, its output files, and the
/// site's queue, account, time limit and extra options.
fn scheduler_directives(site: &Site, layout: Layout, job: &Job<'_>) -> Vec<String> {
    let out = output_file(job.dir, job.name).display().to_string();
    let err = job
        .dir
        .join(format!("{}.err", job.name))
        .display()
        .to_string();
    let mut head: Vec<String> = Vec::new();
    let per_node = layout.ranks_per_node();
    let over = layout.oversubscribes(site);
    match site.scheduler {
        Scheduler::Slurm => {
            let mut lines = vec![
                format!("--job-name={}", job.name),
                format!("--nodes={}", layout.nodes),
                format!("--ntasks={}", layout.ranks),
                format!("--ntasks-per-node={per_node}"),
                format!("--cpus-per-task={}", layout.threads),
                format!("--output={out}"),
                format!("--error={err}"),
            ];
            lines.extend(site.partition.iter().map(|p| format!("--partition={p}")));
            lines.extend(site.account.iter().map(|a| format!("--account={a}")));
            lines.extend(site.time_limit.iter().map(|t| format!("--time={t}")));
            if over {
                lines.push("--overcommit".into());
            }
            lines.extend(site.scheduler_args.iter().cloned());
            head.extend(lines.into_iter().map(|l| format!("#SBATCH {l}")));
        }
        Scheduler::Pbs => {
            let mut lines = vec![
                format!("-N {}", job.name),
                format!(
                    "-l select={}:ncpus={}:mpiprocs={per_node}:ompthreads={}",
                    layout.nodes,
                    per_node * layout.threads,
                    layout.threads
                ),
                format!("-o {out}"),
                format!("-e {err}"),
            ];
            lines.extend(site.partition.iter().map(|q| format!("-q {q}")));
            lines.extend(site.account.iter().map(|a| format!("-A {a}")));
            lines.extend(site.time_limit.iter().map(|t| format!("-l walltime={t}")));
            lines.extend(site.scheduler_args.iter().cloned());
            head.extend(lines.into_iter().map(|l| format!("#PBS {l}")));
        }
        Scheduler::Flux => {
            let mut lines = vec![
                format!("--job-name={}", job.name),
                format!("--nodes={}", layout.nodes),
                format!("--output={out}"),
                format!("--error={err}"),
            ];
            lines.extend(site.partition.iter().map(|q| format!("--queue={q}")));
            lines.extend(site.account.iter().map(|a| format!("--bank={a}")));
            lines.extend(
                site.time_limit
                    .iter()
                    .map(|t| format!("--time-limit={}s", seconds_of(t))),
            );
            lines.extend(site.scheduler_args.iter().cloned());
            head.extend(lines.into_iter().map(|l| format!("#flux: {l}")));
        }
        Scheduler::None => {}
    }
    head
}

/// `HH:MM:SS` or `D-HH:MM:SS` (validated by the site) in seconds.
fn seconds_of(limit: &str) -> u64 {
    let (days, clock) = limit.split_once('-').unwrap_or(("0", limit));
    let days: u64 = days.parse().unwrap_or(0);
    let part = |i: usize| -> u64 {
        clock
            .split(':')
            .nth(i)
            .and_then(|p| p.parse().ok())
            .unwrap_or(0)
    };
    ((days * 24 + part(0)) * 60 + part(1)) * 60 + part(2)
}

/// A word for the shell: as it is when it holds only safe characters, else in single
/// quotes.
pub fn quote(word: &str) -> String {
    let safe = !word.is_empty()
        && word
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c));
    match safe {
        true => word.to_owned(),
        false => format!("'{}'", word.replace('\'', r"'\''")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_limits_turn_into_seconds_and_odd_words_are_quoted() {
        assert_eq!(seconds_of("00:10:00"), 600);
        assert_eq!(seconds_of("1-00:00:30"), 86_430);
        assert_eq!(quote("a b"), "'a b'");
        assert_eq!(quote("it's"), r"'it'\''s'");
        assert_eq!(quote("--map-by=ppr:2:node"), "--map-by=ppr:2:node");
    }
}
