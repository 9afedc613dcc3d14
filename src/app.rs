//! Runs a parsed command: the glue between the command line, the files and the backends.

use std::num::NonZeroUsize;

use anyhow::{Context, bail};

use crate::backend::{BackendSpec, serial, threads};
use crate::cli::{BackendName, Cli, Command, SimulateArgs};
use crate::output::{write_atomically, write_state_csv};
use crate::scene_file;

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Simulate(args) => simulate(&args),
    }
}

fn simulate(args: &SimulateArgs) -> anyhow::Result<()> {
    let backend = backend_spec(args)?;
    let spec = scene_file::load(&args.scene, &args.overrides())?;
    let outcome = match backend {
        BackendSpec::Serial => serial::run(&spec),
        BackendSpec::Rayon { threads } => threads::run(&spec, threads),
        BackendSpec::Mpi { .. } => bail!(
            "this collide was built without MPI support; rebuild it with \
             `cargo build --release --features mpi` after installing OpenMPI \
             (`apt-get install libopenmpi-dev openmpi-bin libclang-dev`)"
        ),
    }
    .with_context(|| format!("{}", args.scene.display()))?;
    if let Some(path) = &args.dump {
        write_atomically(path, |out| write_state_csv(out, &outcome.final_state))?;
    }
    if args.json {
        println!("{}", serde_json::to_string(&outcome.summary)?);
    } else {
        println!("{}", outcome.summary);
        if let Some(path) = &args.dump {
            println!("final state written to {}", path.display());
        }
    }
    Ok(())
}

/// The backend the flags ask for; worker counts only go with the backend they count.
fn backend_spec(args: &SimulateArgs) -> anyhow::Result<BackendSpec> {
    let name = args.backend;
    if args.threads.is_some() && name != BackendName::Rayon {
        bail!("--threads sets the rayon pool size; add `--backend rayon` or drop --threads");
    }
    if args.ranks.is_some() && name != BackendName::Mpi {
        bail!("--ranks sets the MPI process count; add `--backend mpi` or drop --ranks");
    }
    Ok(match name {
        BackendName::Serial => BackendSpec::Serial,
        BackendName::Rayon => BackendSpec::Rayon {
            threads: args.threads.unwrap_or_else(|| {
                std::thread::available_parallelism().unwrap_or(NonZeroUsize::MIN)
            }),
        },
        BackendName::Mpi => BackendSpec::Mpi { ranks: args.ranks },
    })
}
