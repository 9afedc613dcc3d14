//! Starting MPI ranks for `collide simulate --backend mpi --ranks N` (and the ping-pong
//! of `collide calibrate --network`): renders the site's launcher line for the ranks'
//! layout (`mpirun` on this host unless `--system` or `--launcher` says otherwise:
//! [`crate::cluster::render`]), runs it on this very binary under a timeout, and reads
//! rank 0's JSON answer from the last line of its output.

use std::ffi::OsString;
use std::process::Command;
use std::time::Duration;

use crate::backend::BackendError;
use crate::cluster::placement::{Layout, mask_warnings, rank_cpus, rank_cpus_column};
use crate::cluster::render::launch_line;
use crate::cluster::site::Site;
use crate::run::summary::RunSummary;
use crate::system::machine::{USABLE_CPUS_ENV, usable_cpus};
use crate::system::process::{Ended, run_with_timeout, stop_children_on_interrupt, tail};

/// How to start the ranks.
#[derive(Clone, Debug, PartialEq)]
pub struct Launch {
    /// Nodes, ranks and threads per rank.
    pub layout: Layout,
    /// The site whose launcher starts them: `--system`, or the site `--launcher` means.
    pub site: Site,
    pub timeout: Duration,
}

/// Runs the ranks with `args` (this process's arguments, asking for `--json`) and
/// returns rank 0's summary. A launcher that fails, or outlives the timeout (it is
/// killed with all its ranks), is an error that quotes the end of its output.
pub fn launch(launch: &Launch, args: &[OsString]) -> Result<RunSummary, BackendError> {
    let (mut summary, stderr): (RunSummary, String) = launch_for(launch, args, "summary")?;
    let ranks = rank_cpus(&stderr);
    for warning in mask_warnings(&ranks) {
        eprintln!("warning: {warning}");
    }
    summary.rank_cpus = (!ranks.is_empty()).then(|| rank_cpus_column(&ranks));
    Ok(summary)
}

/// Runs the ranks with `args` and reads rank 0's answer, `what` it is in words, from
/// the last line of their output (JSON); returns it with the ranks' error output.
pub fn launch_for<T: serde::de::DeserializeOwned>(
    launch: &Launch,
    args: &[OsString],
    what: &str,
) -> Result<(T, String), BackendError> {
    let line = launch_line(&launch.site, launch.layout);
    let shown = line.argv.join(" ");
    let (program, words) = line
        .argv
        .split_first()
        .ok_or_else(|| BackendError::Mpi("the MPI launcher command is empty".into()))?;
    let exe = std::env::current_exe()
        .map_err(|e| BackendError::Mpi(format!("cannot find this program's path: {e}")))?;
    let mut command = Command::new(program);
    command.args(words).arg(exe).args(args).envs(line.env);
    if running_as_root() {
        // OpenMPI refuses root without these; other MPIs ignore them.
        command
            .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
            .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1");
    }
    let cpus = usable_cpus();
    if launch.layout.ranks > cpus {
        // More ranks than CPUs: allowed (and flagged in the summary), not refused.
        command.env("OMPI_MCA_rmaps_base_oversubscribe", "1");
    }
    // Rank 0 judges oversubscription by the CPUs this launch may use, not its own.
    command.env(USABLE_CPUS_ENV, cpus.to_string());
    // Ctrl-C (or a study's timeout, which interrupts this process) stops the ranks too.
    stop_children_on_interrupt();
    let ended = run_with_timeout(command, launch.timeout).map_err(|e| {
        BackendError::Mpi(format!(
            "cannot start `{program}`: {e}; install OpenMPI (`apt-get install openmpi-bin`) \
             or name your launcher with --launcher, COLLIDE_MPI_LAUNCHER or --system"
        ))
    })?;
    let (status, stdout, stderr) = match ended {
        Ended::Exited {
            status,
            stdout,
            stderr,
        } => (status, stdout, stderr),
        Ended::TimedOut { stderr } => {
            return Err(BackendError::Mpi(format!(
                "the {} ranks did not finish within {} s and were killed; raise --mpi-timeout \
                 (or COLLIDE_MPI_TIMEOUT) if the run is just long{}",
                launch.layout.ranks,
                launch.timeout.as_secs_f64(),
                tail("their last output", &stderr)
            )));
        }
    };
    if !status.success() {
        return Err(BackendError::Mpi(format!(
            "`{shown}` failed ({status}){}",
            tail("its output", &stderr)
        )));
    }
    let answer = serde_json::from_str(stdout.lines().last().unwrap_or_default()).map_err(|e| {
        BackendError::Mpi(format!(
            "rank 0 printed no JSON {what} on its last line ({e}){}",
            tail("its output", &stdout)
        ))
    })?;
    Ok((answer, stderr))
}

fn running_as_root() -> bool {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata("/proc/self").is_ok_and(|meta| meta.uid() == 0)
}
