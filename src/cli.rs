//! Command-line arguments (clap derive): raw values only, validated elsewhere.

use std::num::NonZeroUsize;
use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

use crate::scene_file::{DtValue, Overrides};
use crate::sim::Broadphase;
use crate::spec::{MethodChoice, Observe};

#[derive(Debug, Parser)]
#[command(
    name = "collide",
    version,
    about = "2D hard-disk collision simulator and scaling-study harness",
    after_help = crate::exit::help()
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run one scene and print a summary of what happened.
    Simulate(SimulateArgs),
    /// Run a scaling study from a manifest and record every run in Parquet.
    Run(RunArgs),
    /// Print a table of a study's recorded runs.
    Results(ResultsArgs),
    /// Write a markdown scaling report of a study's recorded runs.
    Report(ReportArgs),
    /// Draw a scene: a PNG of its disks after the run, and/or a GIF of the run.
    Render(RenderArgs),
    /// CI timing check: run a small manifest and compare it with a recorded baseline
    /// (exit 0: nothing regressed, 1: a regression or failed runs, 2: an error).
    Check(CheckArgs),
    /// Time the fixed calibration workload that `collide check` normalises by.
    #[command(hide = true)]
    Calibrate,
}

#[derive(Debug, Args)]
pub struct CheckArgs {
    /// The manifest to time.
    #[arg(default_value = "experiments/ci.toml")]
    pub manifest: PathBuf,
    /// The baseline folder (committed; written only with --update-baseline).
    #[arg(long, value_name = "DIR", default_value = "results/baseline")]
    pub baseline: PathBuf,
    /// Record this run as the new baseline instead of comparing with the old one.
    #[arg(long)]
    pub update_baseline: bool,
    /// Folder for this run's records and its markdown summary (summary.md).
    #[arg(long, value_name = "DIR", default_value = "results/check")]
    pub out: PathBuf,
    /// Relative change that counts as noise: a configuration regressed only when the
    /// whole confidence interval of its time ratio lies above 1 + this.
    #[arg(long, value_name = "FRACTION", default_value_t = 0.10, value_parser = parse_fraction)]
    pub noise: f64,
    /// Add this fraction of extra work to every step of the measured runs (testing only).
    #[arg(long, value_name = "FRACTION", default_value_t = 0.0, value_parser = parse_fraction, hide = true)]
    pub inject_slowdown: f64,
    /// No progress bar or notes.
    #[arg(long)]
    pub quiet: bool,
}

#[derive(Debug, Args)]
pub struct RenderArgs {
    /// Scene file (TOML), e.g. experiments/scenes/seed-1000.toml.
    pub scene: PathBuf,
    /// Write a PNG of the disks after the scene's steps (`--steps 1`: nearly the start).
    #[arg(long, value_name = "FILE")]
    pub png: Option<PathBuf>,
    /// Write an animated GIF of the run, from the start to the last step.
    #[arg(long, value_name = "FILE")]
    pub gif: Option<PathBuf>,
    /// Frames of the GIF, spread evenly over the run.
    #[arg(long, default_value_t = 60, value_parser = clap::value_parser!(u32).range(2..=1000))]
    pub frames: u32,
    #[command(flatten)]
    pub overrides: OverrideArgs,
}

#[derive(Debug, Args)]
pub struct ReportArgs {
    /// A study's results folder (results/NAME/) or one results file.
    pub path: PathBuf,
    /// Folder for report.md (default: reports/<study name>/).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub struct RunArgs {
    /// Experiment manifest (TOML), e.g. experiments/quick.toml.
    pub manifest: PathBuf,
    /// Results root; the study writes into OUT/<study name>/.
    #[arg(long, value_name = "DIR", default_value = "results")]
    pub out: PathBuf,
    /// Continue the newest results file of this manifest and build, running only what is missing.
    #[arg(long)]
    pub resume: bool,
    /// No progress bar or notes (automatic when stdout is not a terminal).
    #[arg(long)]
    pub quiet: bool,
}

#[derive(Debug, Args)]
pub struct ResultsArgs {
    /// A study's results folder (results/NAME/) or one results file.
    pub path: PathBuf,
}

#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Scene file (TOML), e.g. experiments/scenes/seed-1000.toml.
    pub scene: PathBuf,
    /// Print one JSON object on the last line of stdout instead of the text summary.
    #[arg(long)]
    pub json: bool,
    /// Write the final state as CSV (id,x,y,vx,vy,radius,mass) to FILE.
    #[arg(long, value_name = "FILE")]
    pub dump: Option<PathBuf>,
    #[command(flatten)]
    pub overrides: OverrideArgs,
    /// How to run the steps: serial (the reference), rayon (threads) or mpi (ranks).
    #[arg(long, value_enum, default_value_t = BackendName::Serial)]
    pub backend: BackendName,
    /// Threads of the rayon pool (with --backend rayon; default: the logical cores).
    #[arg(long, value_parser = parse_workers)]
    pub threads: Option<NonZeroUsize>,
    /// MPI ranks to launch (with --backend mpi; default under mpirun: its world size).
    #[arg(long, value_parser = parse_workers)]
    pub ranks: Option<NonZeroUsize>,
    /// MPI launcher and its options, followed by `-n RANKS` and this program
    /// (e.g. "mpirun --bind-to core", or "mpiexec" for MPICH).
    #[arg(long, env = "COLLIDE_MPI_LAUNCHER", default_value = "mpirun")]
    pub launcher: String,
    /// Seconds before a launched MPI run is killed with all its ranks.
    #[arg(long, env = "COLLIDE_MPI_TIMEOUT", default_value_t = 3600.0, value_parser = parse_seconds)]
    pub mpi_timeout: f64,
    /// Add this fraction of extra work to every step (testing `collide check` only).
    #[arg(long, value_name = "FRACTION", default_value_t = 0.0, value_parser = parse_fraction, hide = true)]
    pub inject_slowdown: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum BackendName {
    Serial,
    Rayon,
    Mpi,
}

impl BackendName {
    pub fn name(self) -> &'static str {
        match self {
            BackendName::Serial => "serial",
            BackendName::Rayon => "rayon",
            BackendName::Mpi => "mpi",
        }
    }
}

/// Flags that replace a scene file's values.
#[derive(Debug, Args)]
pub struct OverrideArgs {
    /// Number of disks (random scenes).
    #[arg(long, allow_hyphen_values = true)]
    pub n: Option<i64>,
    /// Number of steps.
    #[arg(long, allow_hyphen_values = true)]
    pub steps: Option<i64>,
    /// Seed of the random initial state.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Time step, or "auto".
    #[arg(long, value_parser = parse_dt, allow_hyphen_values = true)]
    pub dt: Option<DtValue>,
    /// Area fraction of disks (random scenes; the box becomes square).
    #[arg(long, allow_hyphen_values = true)]
    pub packing: Option<f64>,
    /// Broad phase: grid (default) or allpairs (the seed's O(N²) search).
    #[arg(long, value_parser = parse_broadphase)]
    pub broadphase: Option<Broadphase>,
    /// Method: step (time steps of dt, the default), event (the exact event-driven
    /// reference; serial backend only) or auto (the cheaper one within the scene's
    /// missed_tolerance; serial backend only).
    #[arg(long, value_parser = parse_method)]
    pub method: Option<MethodChoice>,
    /// What to measure besides time: timing (default) or accuracy (also the step
    /// method's exact missed-collision count, outside `wall_s`; serial backend only).
    #[arg(long, value_parser = parse_observe)]
    pub observe: Option<Observe>,
    /// TC model time of the event method's inelastic-collapse guard (0 turns it off;
    /// default 1e-4 · r_min / v_rms).
    #[arg(long, allow_hyphen_values = true)]
    pub tc: Option<f64>,
}

impl OverrideArgs {
    pub fn overrides(&self) -> Overrides {
        Overrides {
            n: self.n,
            steps: self.steps,
            seed: self.seed,
            dt: self.dt.clone(),
            packing: self.packing,
            broadphase: self.broadphase,
            method: self.method,
            observe: self.observe,
            tc: self.tc,
        }
    }
}

fn parse_dt(text: &str) -> Result<DtValue, String> {
    if text == "auto" {
        return Ok(DtValue::Word(text.to_owned()));
    }
    text.parse::<f64>()
        .map(DtValue::Seconds)
        .map_err(|_| format!("expected a number or \"auto\", got \"{text}\""))
}

fn parse_workers(text: &str) -> Result<NonZeroUsize, String> {
    text.parse::<NonZeroUsize>()
        .map_err(|_| format!("expected a whole number of at least 1, got \"{text}\""))
}

fn parse_seconds(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(seconds) if seconds > 0.0 && seconds.is_finite() => Ok(seconds),
        _ => Err(format!(
            "expected a positive number of seconds, got \"{text}\""
        )),
    }
}

fn parse_fraction(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(fraction) if fraction >= 0.0 && fraction.is_finite() => Ok(fraction),
        _ => Err(format!(
            "expected a fraction of 0 or more (0.25 = 25%), got \"{text}\""
        )),
    }
}

fn parse_broadphase(text: &str) -> Result<Broadphase, String> {
    match text {
        "grid" => Ok(Broadphase::Grid),
        "allpairs" => Ok(Broadphase::AllPairs),
        _ => Err(format!("expected grid or allpairs, got \"{text}\"")),
    }
}

fn parse_method(text: &str) -> Result<MethodChoice, String> {
    text.parse()
}

fn parse_observe(text: &str) -> Result<Observe, String> {
    match text {
        "timing" => Ok(Observe::Timing),
        "accuracy" => Ok(Observe::Accuracy),
        _ => Err(format!("expected timing or accuracy, got \"{text}\"")),
    }
}
