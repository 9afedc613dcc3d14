//! Starting MPI ranks for `collide simulate --backend mpi --ranks N`: runs the launcher
//! (`mpirun` unless configured) on this very binary, under a timeout, and reads rank
//! 0's JSON summary from the last line of its output.

use std::ffi::OsString;
use std::io::Read;
use std::os::unix::process::CommandExt;
use std::process::{Command, ExitStatus, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use crate::backend::{BackendError, machine_cores};
use crate::summary::RunSummary;

/// How to start the ranks.
#[derive(Clone, Debug, PartialEq)]
pub struct Launch {
    pub ranks: usize,
    /// The launcher and its own options, split at whitespace, e.g. `mpirun --bind-to core`;
    /// `-n RANKS`, this binary and its arguments follow.
    pub launcher: String,
    pub timeout: Duration,
}

/// Runs the ranks with `args` (this process's arguments, asking for `--json`) and
/// returns rank 0's summary. A launcher that fails, or outlives the timeout (it is
/// killed with all its ranks), is an error that quotes the end of its output.
pub fn launch(launch: &Launch, args: &[OsString]) -> Result<RunSummary, BackendError> {
    let mut words = launch.launcher.split_whitespace();
    let program = words
        .next()
        .ok_or_else(|| BackendError::Mpi("the MPI launcher command is empty".into()))?;
    let exe = std::env::current_exe()
        .map_err(|e| BackendError::Mpi(format!("cannot find this program's path: {e}")))?;
    let mut command = Command::new(program);
    command
        .args(words)
        .arg("-n")
        .arg(launch.ranks.to_string())
        .arg(exe)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        // Its own process group, so that a timeout kills every rank too.
        .process_group(0);
    if running_as_root() {
        // OpenMPI refuses root without these; other MPIs ignore them.
        command
            .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
            .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1");
    }
    if launch.ranks > machine_cores() {
        // More ranks than cores: allowed (and flagged in the summary), not refused.
        command.env("OMPI_MCA_rmaps_base_oversubscribe", "1");
    }
    let mut child = command.spawn().map_err(|e| {
        BackendError::Mpi(format!(
            "cannot start `{program}`: {e}; install OpenMPI (`apt-get install openmpi-bin`) \
             or name your launcher with --launcher or COLLIDE_MPI_LAUNCHER"
        ))
    })?;
    let stdout = read_in_background(child.stdout.take());
    let stderr = read_in_background(child.stderr.take());
    let status = wait_with_timeout(&mut child, launch.timeout)?;
    let stdout = stdout.join().unwrap_or_default();
    let stderr = stderr.join().unwrap_or_default();
    let Some(status) = status else {
        return Err(BackendError::Mpi(format!(
            "the {} ranks did not finish within {} s and were killed; raise --mpi-timeout \
             (or COLLIDE_MPI_TIMEOUT) if the run is just long{}",
            launch.ranks,
            launch.timeout.as_secs_f64(),
            tail("their last output", &stderr)
        )));
    };
    if !status.success() {
        return Err(BackendError::Mpi(format!(
            "`{}` failed ({status}){}",
            launch.launcher,
            tail("its output", &stderr)
        )));
    }
    let last_line = stdout.lines().last().unwrap_or_default();
    serde_json::from_str(last_line).map_err(|e| {
        BackendError::Mpi(format!(
            "rank 0 printed no JSON summary on its last line ({e}){}",
            tail("its output", &stdout)
        ))
    })
}

fn running_as_root() -> bool {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata("/proc/self").is_ok_and(|meta| meta.uid() == 0)
}

fn read_in_background(pipe: Option<impl Read + Send + 'static>) -> thread::JoinHandle<String> {
    thread::spawn(move || {
        let mut text = String::new();
        if let Some(mut pipe) = pipe {
            // Output that is not UTF-8 is reported as missing rather than failing the run.
            let _ = pipe.read_to_string(&mut text);
        }
        text
    })
}

/// Waits for the child; on timeout kills its whole process group and returns `None`.
fn wait_with_timeout(
    child: &mut std::process::Child,
    timeout: Duration,
) -> Result<Option<ExitStatus>, BackendError> {
    let started = Instant::now();
    loop {
        match child.try_wait() {
            Ok(Some(status)) => return Ok(Some(status)),
            Ok(None) if started.elapsed() > timeout => {
                // The launcher leads its own group (process_group(0)): kill(-pid) reaches
                // every rank it started. A failure means the group is already gone.
                let _ = rustix::process::kill_process_group(
                    rustix::process::Pid::from_child(child),
                    rustix::process::Signal::KILL,
                );
                let _ = child.kill();
                let _ = child.wait();
                return Ok(None);
            }
            Ok(None) => thread::sleep(Duration::from_millis(20)),
            Err(e) => return Err(BackendError::Mpi(format!("lost the MPI launcher: {e}"))),
        }
    }
}

/// The last lines of `text`, for an error message.
fn tail(what: &str, text: &str) -> String {
    let lines: Vec<&str> = text.lines().collect();
    if lines.is_empty() {
        return String::new();
    }
    let last = &lines[lines.len().saturating_sub(12)..];
    format!("; {what} ended:\n{}", last.join("\n"))
}
