//! Runs a parsed command: the glue between the command line, the files and the backends.

use anyhow::Context;

use crate::backend::serial;
use crate::cli::{Cli, Command, SimulateArgs};
use crate::output::{write_atomically, write_state_csv};
use crate::scene_file;

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Simulate(args) => simulate(&args),
    }
}

fn simulate(args: &SimulateArgs) -> anyhow::Result<()> {
    let spec = scene_file::load(&args.scene, &args.overrides())?;
    let outcome = serial::run(&spec).with_context(|| format!("{}", args.scene.display()))?;
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
