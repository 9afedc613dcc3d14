//! The `collide` command: parse, run, map outcomes to exit codes (0 done, 1 a timing
//! regression found by `collide check`, 2 an error).

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let cli = collide::cli::Cli::parse();
    match collide::app::run(cli) {
        Ok(collide::app::Outcome::Done) => ExitCode::SUCCESS,
        Ok(collide::app::Outcome::Regressed) => ExitCode::from(1),
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::from(2)
        }
    }
}
