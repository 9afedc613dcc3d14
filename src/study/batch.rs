//! A study's runs as batch jobs on a scheduler's queue (Slurm): one job per run
//! (configuration × repetition), so that a job that fails, times out or is lost costs
//! one row, a restarted `collide run --resume` needs only the job ids to find what
//! finished, and the queue's fair share sees small jobs. Each job's script (rendered by
//! [`crate::cluster::render::job_script`]) writes its output and its exit code beside
//! it, in `<results>/jobs/`; `state.json` there keeps the ids of the jobs submitted and
//! not yet collected. Ctrl-C cancels them (`scancel`); a hard kill leaves them queued
//! for `--resume`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use anyhow::Context;

use crate::cluster::render::{exit_file, output_file};
use crate::cluster::slurm::{self, JobInfo, JobState};
use crate::system::output::write_atomically;
use crate::system::process::run_with_timeout;

/// The file of the jobs submitted and not yet collected (name → id).
const STATE: &str = "state.json";

/// The ids of `state.json` alone, one a line.
const IDS: &str = "ids";

/// While this file exists, the watcher that cancels the jobs on Ctrl-C runs.
const WATCHING: &str = "watching";

/// The longest wait between two polls of the queue (the first waits half a second).
const MAX_POLL: Duration = Duration::from_secs(10);

/// How long a job the queue calls ended may take to show its exit-code file (a shared
/// file system's delay) before it is collected without one.
const EXIT_FILE_GRACE: Duration = Duration::from_secs(5);

/// One run to submit: a name unique in the study (its files' stem) and its script.
pub struct BatchJob {
    pub name: String,
    pub script: String,
}

/// How a job ended: its exit code (from its exit-code file; `None` when it wrote none:
/// killed by the scheduler, lost), what it printed, and what the queue last said.
pub struct JobEnd {
    pub id: String,
    pub code: Option<i32>,
    pub stdout: String,
    pub stderr: String,
    pub info: JobInfo,
}

/// Submits the `jobs` not already submitted (by name, in `dir/state.json`), follows all
/// of them, and calls `done(index, end)` for each as it ends, in the order they end.
pub fn run_jobs(
    dir: &Path,
    jobs: &[BatchJob],
    done: &mut dyn FnMut(usize, JobEnd) -> anyhow::Result<()>,
    note: &dyn Fn(&str),
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the jobs folder {}", dir.display()))?;
    let mut state = read_state(dir);
    let watching = dir.join(WATCHING);
    std::fs::write(&watching, "")
        .with_context(|| format!("cannot write {}", watching.display()))?;
    let watcher = watch_for_interrupt(dir);
    let (mut waiting, submitted, reattached) = submit(dir, jobs, &mut state)?;
    note(&format!(
        "{submitted} job(s) submitted{}; following them in {}",
        match reattached {
            0 => String::new(),
            n => format!(", {n} found still submitted from before"),
        },
        dir.display()
    ));
    let mut poll = Duration::from_millis(500);
    let mut ended_at: BTreeMap<String, Instant> = BTreeMap::new();
    while !waiting.is_empty() {
        std::thread::sleep(poll);
        poll = (poll * 2).min(MAX_POLL);
        let ids: Vec<String> = waiting.keys().cloned().collect();
        let infos = slurm::poll(&ids);
        for (id, info) in infos {
            let index = waiting[&id];
            let name = &jobs[index].name;
            let code = std::fs::read_to_string(exit_file(dir, name))
                .ok()
                .and_then(|text| text.trim().parse::<i32>().ok());
            let gone = info.state.is_final()
                && ended_at
                    .entry(id.clone())
                    .or_insert_with(Instant::now)
                    .elapsed()
                    > EXIT_FILE_GRACE;
            if code.is_none() && !gone {
                continue;
            }
            let read = |suffix: &str| {
                std::fs::read_to_string(dir.join(format!("{name}.{suffix}"))).unwrap_or_default()
            };
            let end = JobEnd {
                id: id.clone(),
                code,
                stdout: read("out"),
                stderr: read("err"),
                info,
            };
            done(index, end)?;
            waiting.remove(&id);
            state.remove(name);
            write_state(dir, &state)?;
        }
    }
    let _ = std::fs::remove_file(&watching);
    let _ = watcher.join();
    Ok(())
}

/// Submits the jobs not yet submitted (the others, found in `state` by name, are
/// followed again), noting each new id in `state` at once. Returns the job of each id,
/// and how many were submitted now and found from before.
fn submit(
    dir: &Path,
    jobs: &[BatchJob],
    state: &mut BTreeMap<String, String>,
) -> anyhow::Result<(BTreeMap<String, usize>, usize, usize)> {
    let mut waiting: BTreeMap<String, usize> = BTreeMap::new();
    let (mut reattached, mut submitted) = (0, 0);
    for (index, job) in jobs.iter().enumerate() {
        let id = match state.get(&job.name) {
            Some(id) => {
                reattached += 1;
                id.clone()
            }
            None => {
                for stale in [exit_file(dir, &job.name), output_file(dir, &job.name)] {
                    let _ = std::fs::remove_file(stale);
                }
                let script = dir.join(format!("{}.sh", job.name));
                write_atomically(&script, |out| out.write_all(job.script.as_bytes()))?;
                let id = slurm::submit(&script).map_err(anyhow::Error::msg)?;
                state.insert(job.name.clone(), id.clone());
                write_state(dir, state)?;
                submitted += 1;
                id
            }
        };
        waiting.insert(id, index);
    }
    Ok((waiting, submitted, reattached))
}

/// The reason a job that wrote no exit code ended, for its row's `error`.
pub fn no_exit_code(end: &JobEnd) -> String {
    let state = match &end.info.state {
        JobState::TimedOut => "timed out (the site's `time_limit`)".to_owned(),
        JobState::Cancelled => "was cancelled".to_owned(),
        JobState::Lost => "is known to neither squeue nor scontrol any more".to_owned(),
        other => format!("ended {other:?}"),
    };
    format!(
        "job {} {state} without writing its exit code{}",
        end.id,
        crate::system::process::tail("its error output", &end.stderr)
    )
}

/// Whether jobs submitted from `dir` await collection (`--resume` then continues even
/// before any row was written).
pub fn has_submitted(dir: &Path) -> bool {
    !read_state(dir).is_empty()
}

fn read_state(dir: &Path) -> BTreeMap<String, String> {
    std::fs::read_to_string(dir.join(STATE))
        .ok()
        .and_then(|text| serde_json::from_str(&text).ok())
        .unwrap_or_default()
}

/// Writes `state.json`, and the ids alone, one a line, to `ids` (what the watcher cancels).
fn write_state(dir: &Path, state: &BTreeMap<String, String>) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(state)?;
    write_atomically(&dir.join(STATE), |out| out.write_all(text.as_bytes()))?;
    let ids: String = state.values().map(|id| format!("{id}\n")).collect();
    write_atomically(&dir.join(IDS), |out| out.write_all(ids.as_bytes()))
}

/// A child that cancels the jobs in `dir/ids` when collide is interrupted (the
/// interrupt handler signals every child's group) and ends on its own once `watching`
/// is removed or collide is gone: a hard kill of collide cancels nothing.
fn watch_for_interrupt(dir: &Path) -> std::thread::JoinHandle<()> {
    let dir: PathBuf = dir.to_owned();
    std::thread::spawn(move || {
        // SIGTERM (sent when collide dies, however) is ignored so that an interrupt's
        // scancel finishes; the loop ends when collide is gone or done.
        let script = "trap '' TERM\n\
                      trap 'ids=$(cat ids); [ -n \"$ids\" ] && scancel $ids; exit 0' INT\n\
                      while [ -e watching ] && kill -0 $PPID 2>/dev/null; do sleep 0.2; done";
        let mut command = Command::new("bash");
        command.arg("-c").arg(script).current_dir(&dir);
        let _ = run_with_timeout(command, Duration::from_secs(365 * 86_400));
    })
}
