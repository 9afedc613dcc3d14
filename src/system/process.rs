//! Child processes under a timeout: output captured, each child in its own process
//! group so that everything it starts (an MPI launcher's ranks) can be stopped with it,
//! on timeout or when collide itself is interrupted (Ctrl-C, SIGTERM), which then says
//! what was kept, and tied to collide's life so that a hard kill (`kill -9`, the OOM
//! killer) leaves no orphan.

use std::collections::BTreeSet;
use std::io::{Read, Write};
use std::os::unix::process::CommandExt;
use std::process::{Command, ExitStatus, Stdio};
use std::sync::{Mutex, MutexGuard, PoisonError};
use std::thread;
use std::time::{Duration, Instant};

use rustix::process::{Pid, Signal, kill_process_group};

/// How a child process ended.
#[derive(Debug)]
pub enum Ended {
    Exited {
        status: ExitStatus,
        stdout: String,
        stderr: String,
    },
    /// Stopped at the timeout, with what it had printed to stderr.
    TimedOut { stderr: String },
}

/// Time a child gets to stop its own children after SIGINT before it is killed.
const GRACE: Duration = Duration::from_secs(2);

/// Process groups of the children now running, for [`stop_children_on_interrupt`].
static RUNNING: Mutex<BTreeSet<i32>> = Mutex::new(BTreeSet::new());

/// What to print when interrupted; `None`: [`NOTHING_KEPT`].
static INTERRUPT_NOTE: Mutex<Option<String>> = Mutex::new(None);

/// What an interrupt says before anything is written.
const NOTHING_KEPT: &str = "interrupted: no run had finished; nothing was written";

/// The note an interrupt prints (e.g. what was kept and how to continue). Hold the guard
/// while writing results and set the note once they are written: an interrupt waits for
/// the guard, so it never lands in the middle of a write nor reports a stale count.
pub fn interrupt_note() -> MutexGuard<'static, Option<String>> {
    INTERRUPT_NOTE
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
}

/// On Ctrl-C or SIGTERM, waits for any write of results to finish, interrupts every
/// running child's group (a child that launched MPI ranks stops them in turn), prints
/// the [`interrupt_note`], removes the temporary files of unfinished writes, then exits
/// with code 130 ([`crate::exit::INTERRUPTED`]).
/// Call once, early.
pub fn stop_children_on_interrupt() {
    let installed = ctrlc::set_handler(|| {
        let note = interrupt_note();
        let groups: Vec<i32> = RUNNING
            .lock()
            .map_or_else(|_| Vec::new(), |g| g.iter().copied().collect());
        for group in groups {
            signal_group(group, Signal::INT);
        }
        crate::system::output::remove_in_flight();
        // Not eprintln!, which panics (and so never exits) when stderr's reader is gone.
        let _ = writeln!(
            std::io::stderr(),
            "{}",
            note.as_deref().unwrap_or(NOTHING_KEPT)
        );
        std::process::exit(i32::from(crate::exit::INTERRUPTED.code));
    });
    // A second call in the same process fails; the first handler stays, which is right.
    let _ = installed;
}

fn signal_group(group: i32, signal: Signal) {
    if let Some(pid) = Pid::from_raw(group) {
        // A failure means the group is already gone.
        let _ = kill_process_group(pid, signal);
    }
}

/// Runs `command` (stdin closed, output captured) in its own process group. If it runs
/// longer than `timeout`, its group is interrupted (SIGINT) and, after a grace period,
/// killed. Fails only if the program cannot start.
pub fn run_with_timeout(mut command: Command, timeout: Duration) -> std::io::Result<Ended> {
    command
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .process_group(0);
    die_with_this_process(&mut command);
    let mut child = command.spawn()?;
    // The child leads its own group (process_group(0)): its pid is the group id.
    let group = child.id() as i32;
    if let Ok(mut running) = RUNNING.lock() {
        running.insert(group);
    }
    let stdout = read_in_background(child.stdout.take());
    let stderr = read_in_background(child.stderr.take());
    let started = Instant::now();
    let mut interrupted_at = None;
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break Some(status);
        }
        match interrupted_at {
            None if started.elapsed() > timeout => {
                signal_group(group, Signal::INT);
                interrupted_at = Some(Instant::now());
            }
            Some(at) if at.elapsed() > GRACE => {
                signal_group(group, Signal::KILL);
                let _ = child.kill();
                let _ = child.wait();
                break None;
            }
            _ => thread::sleep(Duration::from_millis(10)),
        }
    };
    // No group signal after a normal exit: the child is reaped, so its pid (the group
    // id) may already belong to someone else.
    if let Ok(mut running) = RUNNING.lock() {
        running.remove(&group);
    }
    let stdout = stdout.join().unwrap_or_default();
    let stderr = stderr.join().unwrap_or_default();
    Ok(match (status, interrupted_at) {
        (Some(status), None) => Ended::Exited {
            status,
            stdout,
            stderr,
        },
        _ => Ended::TimedOut { stderr },
    })
}

/// Makes the child receive SIGTERM when this process dies, however it dies: a child
/// `collide simulate` then ends, and an MPI launcher stops its ranks (a child that
/// launched one passes the signal on through [`stop_children_on_interrupt`]). Linux
/// delivers it when the spawning thread ends: collide spawns from its main thread.
#[cfg(target_os = "linux")]
fn die_with_this_process(command: &mut Command) {
    use rustix::process::{getpid, getppid, set_parent_process_death_signal};
    let parent = getpid();
    // SAFETY: the closure runs in the forked child before exec; it only makes two
    // system calls (prctl, getppid), allocates nothing and takes no lock.
    unsafe {
        command.pre_exec(move || {
            set_parent_process_death_signal(Some(Signal::TERM))?;
            // If collide died between fork and prctl the signal will never come.
            if getppid() != Some(parent) {
                return Err(std::io::Error::other("collide ended while starting a run"));
            }
            Ok(())
        });
    }
}

/// Elsewhere a hard kill of collide may leave its running child behind.
#[cfg(not(target_os = "linux"))]
fn die_with_this_process(_: &mut Command) {}

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

/// The last lines of `text` for an error message, introduced by `what`; "" if empty.
pub fn tail(what: &str, text: &str) -> String {
    let lines: Vec<&str> = text.lines().collect();
    if lines.is_empty() {
        return String::new();
    }
    let last = &lines[lines.len().saturating_sub(12)..];
    format!("; {what} ended:\n{}", last.join("\n"))
}
