//! The instruction counts of `collide check`: each backend's first configuration of the
//! manifest, shrunk to a small run, under valgrind's callgrind (the whole process for a
//! backend that runs in one, rank 0's own code for MPI), a nearly noise-free second
//! signal beside the timings. Comparing the counts is `compare`'s.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output};

use anyhow::{Context, bail};
use serde::{Deserialize, Serialize};

use crate::run::backend_kind::{BackendKind, MPI_LAUNCHER};
use crate::study::manifest::Configuration;
use crate::study::runner::{self, Program};

/// The instruction workloads: the manifest's first configuration of each backend, this
/// small.
const INSTRUCTION_DISKS: i64 = 2000;
const INSTRUCTION_STEPS: i64 = 50;

/// Instructions executed by one small run of a backend under callgrind (rank 0's for MPI).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InstructionCount {
    /// The backend's name.
    pub backend: String,
    /// The `collide simulate` arguments after the program (without an injected slowdown).
    pub command: Vec<String>,
    pub instructions: u64,
}

/// The instructions of `program` in the first configuration of each backend, shrunk to
/// a small run, under callgrind (rank 0's, for MPI); empty (with a note) where valgrind
/// is not installed.
pub fn count(
    configurations: &[Configuration],
    scene_dir: &Path,
    program: &Program,
) -> anyhow::Result<Vec<InstructionCount>> {
    let valgrind = Command::new("valgrind").arg("--version").output();
    if !valgrind.is_ok_and(|out| out.status.success()) {
        eprintln!(
            "note: valgrind is not installed: no instruction counts (apt-get install valgrind)"
        );
        return Ok(Vec::new());
    }
    let mut counts = Vec::new();
    for kind in BackendKind::ALL {
        if !kind.is_available() {
            continue;
        }
        let Some(configuration) = configurations.iter().find(|c| c.backend == kind) else {
            continue;
        };
        let mut small = configuration.clone();
        small.overrides.n = Some(INSTRUCTION_DISKS);
        small.overrides.steps = Some(INSTRUCTION_STEPS);
        let scene = runner::materialize_scenes(scene_dir, &[&small])?.remove(0);
        let mut command = vec!["simulate".to_owned(), scene.display().to_string()];
        command.extend(small.simulate_args());
        let instructions = callgrind(program, &command, kind, small.layout.ranks, scene_dir)?;
        counts.push(InstructionCount {
            backend: kind.name().to_owned(),
            command,
            instructions,
        });
    }
    Ok(counts)
}

/// A run under callgrind: how it ended, and the count it gave or, failing that, the
/// text that says why.
type Counted = (Output, Result<u64, String>);

/// The instructions `program` executes for `command` (its `collide` arguments) under
/// callgrind: the whole process's for a backend that runs in one, rank 0's own for one
/// whose ranks the MPI launcher starts ([`count_ranks`]).
fn callgrind(
    program: &Program,
    command: &[String],
    kind: BackendKind,
    ranks: usize,
    work_dir: &Path,
) -> anyhow::Result<u64> {
    let slowdown = program.slowdown.simulate_args(kind);
    let (out, counted) = match kind.capabilities().mpi {
        true => count_ranks(program, command, &slowdown, ranks, work_dir)?,
        false => count_process(program, command, &slowdown)?,
    };
    match counted {
        Ok(instructions) if out.status.success() => Ok(instructions),
        counted => bail!(
            "callgrind of `{} {}` failed{}",
            program.exe.display(),
            command.join(" "),
            crate::system::process::tail(
                "its output",
                &format!(
                    "{}{}",
                    String::from_utf8_lossy(&out.stderr),
                    counted.err().unwrap_or_default()
                )
            )
        ),
    }
}

/// One process under callgrind, which runs its threads one at a time: the total it
/// reports on standard error.
fn count_process(
    program: &Program,
    command: &[String],
    slowdown: &[String],
) -> anyhow::Result<Counted> {
    let out = Command::new("valgrind")
        .args(["--tool=callgrind", "--callgrind-out-file=/dev/null"])
        .arg(&program.exe)
        .args(command)
        .args(slowdown)
        .output()
        .context("cannot run valgrind")?;
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let collected = stderr
        .lines()
        .find_map(|line| line.split_once("Collected :").map(|(_, n)| n.trim()))
        .and_then(|n| n.parse().ok());
    Ok((out, collected.ok_or(stderr)))
}

/// `ranks` MPI ranks started by [`MPI_LAUNCHER`], each under its own callgrind (files in
/// `work_dir`): rank 0's instructions in collide's own code only, because the MPI
/// library polls for messages while a rank waits, a count that varied by ±25% from run
/// to run.
fn count_ranks(
    program: &Program,
    command: &[String],
    slowdown: &[String],
    ranks: usize,
    work_dir: &Path,
) -> anyhow::Result<Counted> {
    let files = work_dir.join("callgrind");
    let rank = "%q{OMPI_COMM_WORLD_RANK}";
    let out = Command::new(MPI_LAUNCHER)
        .args(["-n", &ranks.to_string(), "valgrind", "--tool=callgrind"])
        .arg(format!(
            "--callgrind-out-file={}.out.{rank}",
            files.display()
        ))
        .arg(format!("--log-file={}.log.{rank}", files.display()))
        .arg(&program.exe)
        .args(command)
        .args(slowdown)
        // OpenMPI refuses root without these; harmless otherwise.
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .output()
        .with_context(|| format!("cannot run {MPI_LAUNCHER}"))?;
    let exe = std::fs::canonicalize(&program.exe)?;
    let counted = std::fs::read_to_string(files.with_extension("out.0"))
        .ok()
        .map(|text| instructions_in_object(&text, &exe.display().to_string()));
    let log = std::fs::read_to_string(files.with_extension("log.0")).unwrap_or_default();
    Ok((out, counted.ok_or(log)))
}

/// The instructions a callgrind output file (its text) counts in the object file
/// `object` itself (the self cost of its functions, not of what they call).
fn instructions_in_object(text: &str, object: &str) -> u64 {
    // Names are compressed: `ob=(3) /path` the first time, `ob=(3)` after.
    let mut names: BTreeMap<String, String> = BTreeMap::new();
    let mut name_of = |spec: &str| -> Option<String> {
        let (id, name) = spec.strip_prefix('(')?.split_once(')')?;
        let name = name.trim();
        match name.is_empty() {
            true => names.get(id).cloned(),
            false => {
                names.insert(id.to_owned(), name.to_owned());
                Some(name.to_owned())
            }
        }
    };
    let (mut counting, mut call_cost_next, mut total) = (false, false, 0);
    for line in text.lines() {
        if let Some(spec) = line.strip_prefix("ob=") {
            counting = name_of(spec).as_deref() == Some(object);
        } else if let Some(spec) = line.strip_prefix("cob=") {
            name_of(spec);
        } else if line.starts_with("calls=") {
            // The next cost line is what the call cost, inclusively: not self cost.
            call_cost_next = true;
        } else if line.starts_with(|c: char| c.is_ascii_digit() || "+-*".contains(c)) {
            let cost: u64 = match line.split_whitespace().nth(1) {
                Some(cost) => cost.parse().unwrap_or(0),
                None => 0,
            };
            if counting && !call_cost_next {
                total += cost;
            }
            call_cost_next = false;
        }
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn instructions_in_an_object_are_its_own_not_those_of_what_it_calls() {
        let text = "events: Ir\nsummary: 1111\n\n\
                    ob=(1) /bin/collide\nfl=(1) a.rs\nfn=(1) step\n10 100\n+2 5\n\
                    cob=(2) /lib/libmpi.so\ncfn=(2) MPI_Wait\ncalls=1 0\n12 900\n\
                    ob=(2)\nfn=(2)\n0 900\n\
                    ob=(1)\nfn=(3) collide\n* 6\n";
        assert_eq!(instructions_in_object(text, "/bin/collide"), 111);
        assert_eq!(instructions_in_object(text, "/lib/libmpi.so"), 900);
        assert_eq!(instructions_in_object(text, "/bin/other"), 0);
    }
}
