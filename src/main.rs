//! The `collide` command: parse, run, map outcomes to exit codes (declared in
//! [`collide::exit`]).

use std::process::ExitCode;

use clap::Parser;

use collide::app::Outcome;
use collide::exit;
use collide::system::console::{self, Stdout};

fn main() -> ExitCode {
    let cli = collide::cli::Cli::parse();
    // Ctrl-C and SIGTERM exit with code 130 whatever the command, leaving no partial file.
    collide::system::process::stop_children_on_interrupt();
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
    // A closed pipe ended the printing quietly; any other failure to print is said here,
    // after every file was written.
    let code = match console::state() {
        Stdout::Failed(reason) if code == exit::DONE => {
            eprintln!("error: {reason}");
            exit::ERROR
        }
        _ => code,
    };
    ExitCode::from(code.code)
}
