//! The `collide` command: parse, run, map outcomes to exit codes (declared in
//! [`collide::exit`]).

use std::process::ExitCode;

use clap::Parser;

use collide::app::Outcome;
use collide::exit;

fn main() -> ExitCode {
    let cli = collide::cli::Cli::parse();
    let code = match collide::app::run(cli) {
        Ok(Outcome::Done) => exit::DONE,
        Ok(Outcome::Regressed) => exit::RUNS_FAILED,
        Err(err) => {
            eprintln!("error: {err:#}");
            match err.downcast_ref::<exit::RunsFailed>() {
                Some(_) => exit::RUNS_FAILED,
                None => exit::ERROR,
            }
        }
    };
    ExitCode::from(code.code)
}
