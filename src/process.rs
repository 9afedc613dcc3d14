//! Child processes under a timeout: output captured, and on timeout the whole process
//! group killed (an MPI launcher's ranks included).

use std::io::Read;
use std::os::unix::process::CommandExt;
use std::process::{Command, ExitStatus, Stdio};
use std::thread;
use std::time::{Duration, Instant};

/// How a child process ended.
#[derive(Debug)]
pub enum Ended {
    Exited {
        status: ExitStatus,
        stdout: String,
        stderr: String,
    },
    /// Killed at the timeout, with what it had printed to stderr.
    TimedOut { stderr: String },
}

/// Runs `command` (stdin closed, output captured) in its own process group; kills the
/// group if it runs longer than `timeout`. Fails only if the program cannot start.
pub fn run_with_timeout(mut command: Command, timeout: Duration) -> std::io::Result<Ended> {
    command
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .process_group(0);
    let mut child = command.spawn()?;
    let stdout = read_in_background(child.stdout.take());
    let stderr = read_in_background(child.stderr.take());
    let started = Instant::now();
    let status = loop {
        match child.try_wait()? {
            Some(status) => break Some(status),
            None if started.elapsed() > timeout => {
                // The child leads its own group (process_group(0)): kill(-pid) reaches
                // everything it started. A failure means the group is already gone.
                let _ = rustix::process::kill_process_group(
                    rustix::process::Pid::from_child(&child),
                    rustix::process::Signal::KILL,
                );
                let _ = child.kill();
                let _ = child.wait();
                break None;
            }
            None => thread::sleep(Duration::from_millis(10)),
        }
    };
    let stdout = stdout.join().unwrap_or_default();
    let stderr = stderr.join().unwrap_or_default();
    Ok(match status {
        Some(status) => Ended::Exited {
            status,
            stdout,
            stderr,
        },
        None => Ended::TimedOut { stderr },
    })
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

/// The last lines of `text` for an error message, introduced by `what`; "" if empty.
pub fn tail(what: &str, text: &str) -> String {
    let lines: Vec<&str> = text.lines().collect();
    if lines.is_empty() {
        return String::new();
    }
    let last = &lines[lines.len().saturating_sub(12)..];
    format!("; {what} ended:\n{}", last.join("\n"))
}
