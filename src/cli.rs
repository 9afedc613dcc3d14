//! Command-line arguments (clap derive): raw values only, validated elsewhere.

use std::num::NonZeroUsize;
use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

use crate::cluster::site::LOCAL;
use crate::report::configurations::Format;
use crate::run::backend_kind::{BackendKind, MPI_LAUNCHER};
use crate::run::overrides::Overrides;

#[derive(Debug, Parser)]
#[command(
    name = "collide",
    version,
    about = "2D hard-disk collision simulator and scaling-study harness",
    after_help = top_help()
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

/// The top command's help ends in examples, then the exit-code table.
fn top_help() -> String {
    format!("{EXAMPLES}\n\n{}", crate::exit::help())
}

// Examples end each `--help`; a unit test parses every `collide ...` line of them.
const EXAMPLES: &str = "\
Examples:
  A scaling study (serial and rayon; MPI with --features mpi): table, records, report
    collide run experiments/quick.toml
  One run of the seed's scene (1000 disks, 400 steps) on two threads
    collide simulate experiments/scenes/seed-1000.toml --backend rayon --threads 2
  Run `collide help <COMMAND>` for each command's own examples.";

const SIMULATE_EXAMPLES: &str = "\
Examples:
  The seed's scene, summarised as text
    collide simulate experiments/scenes/seed-1000.toml
  20 times more disks on two threads, as one JSON object
    collide simulate experiments/scenes/seed-1000.toml --n 20000 --backend rayon --threads 2 --json
  2 MPI ranks of 2 threads each, 4 workers (needs --features mpi)
    collide simulate experiments/scenes/seed-1000.toml --backend mpi --ranks 2 --threads 2
  The exact event-driven reference, with the final state as CSV
    collide simulate experiments/scenes/two-disks-head-on.toml --method event --dump final.csv";

const RUN_EXAMPLES: &str = "\
Examples:
  Records in results/quick/, the table printed, the report in reports/quick/
    collide run experiments/quick.toml
  Continue a study that was interrupted, running only the missing repetitions
    collide run experiments/seed-report.toml --resume
  Records elsewhere, no report (write it later with `collide report`)
    collide run experiments/accuracy.toml --out /tmp/results --no-report
  Each run submitted as a Slurm job, as systems/slurm-local.toml describes the site
    collide run experiments/quick.toml --system slurm-local";

const RESULTS_EXAMPLES: &str = "\
Examples:
  Every recorded run of a study, then its speedup and efficiency per backend
    collide results results/seed-report/
  One results file
    collide results results/baseline/records.parquet
  Every configuration's times as CSV, for a spreadsheet or a script
    collide results results/accuracy/ --format csv";

const REPORT_EXAMPLES: &str = "\
Examples:
  report.md and its figures in reports/seed-report/
    collide report results/seed-report/
  The report of an accuracy study, written elsewhere
    collide report results/accuracy/ --out /tmp/accuracy-report";

const RENDER_EXAMPLES: &str = "\
Examples:
  2000 disks of the seed's gas, coloured by speed
    collide render experiments/scenes/seed-1000.toml --n 2000 --png scene.png
  An animated GIF of 200 steps in 40 frames
    collide render experiments/scenes/seed-1000.toml --steps 200 --gif run.gif --frames 40";

const VIEW_EXAMPLES: &str = "\
Examples:
  Watch the seed's 1000 disks, on 2 threads
    collide view experiments/scenes/seed-1000.toml --threads 2
  Measure the frame rate: 300 frames without a cap, figures to a JSON file
    collide view experiments/scenes/seed-1000.toml --n 100000 --frames 300 --max-fps 0 --stats view.json
  Without a screen, on a virtual display
    xvfb-run -a collide view experiments/scenes/seed-1000.toml --frames 100 --screenshot last.png";

const CHECK_EXAMPLES: &str = "\
Examples:
  Time experiments/ci.toml and compare it with results/baseline/
    collide check
  Also build the commit that recorded the baseline and run both builds interleaved (what CI runs)
    collide check --against
  Against the previous commit
    collide check --against HEAD~1
  Record a new baseline on purpose (then commit results/baseline/)
    collide check --update-baseline
  A looser noise threshold (10%)
    collide check experiments/ci.toml --noise 0.10";

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run one scene and print a summary of what happened.
    #[command(after_help = SIMULATE_EXAMPLES)]
    Simulate(SimulateArgs),
    /// Run a scaling study from a manifest, record every run in Parquet, then print the
    /// scaling table and write the report.
    #[command(after_help = RUN_EXAMPLES)]
    Run(RunArgs),
    /// Print a table of a study's recorded runs.
    #[command(after_help = RESULTS_EXAMPLES)]
    Results(ResultsArgs),
    /// Write a markdown scaling report of a study's recorded runs.
    #[command(after_help = REPORT_EXAMPLES)]
    Report(ReportArgs),
    /// Draw a scene: a PNG of its disks after the run, and/or a GIF of the run.
    #[command(after_help = RENDER_EXAMPLES)]
    Render(RenderArgs),
    /// Watch a scene run in a window: disks coloured by speed, frames and steps per
    /// second. Keys: space pause, . one step, [ ] steps per frame, + - zoom, arrows pan,
    /// 0 whole box, p screenshot, Esc quit.
    #[command(after_help = VIEW_EXAMPLES)]
    View(ViewArgs),
    /// CI timing check: run a small manifest and compare it with a recorded baseline
    /// (exit 0: nothing regressed, 1: a regression or failed runs, 2: an error).
    #[command(after_help = CHECK_EXAMPLES)]
    Check(CheckArgs),
    /// Measure the network between 2 MPI ranks (`--network`: latency and bandwidth from
    /// a ping-pong, and a small all-reduce) into a site file's `[network]`; without
    /// `--network`, time the fixed workload that `collide check` normalises by (JSON).
    #[command(after_help = CALIBRATE_EXAMPLES)]
    Calibrate(CalibrateArgs),
    /// Predict weak- and strong-scaling efficiency up to 10,000 ranks from a study's
    /// records and a site's network, as a band, with the model's error on the measured
    /// rank counts it was not fitted to.
    #[command(after_help = PREDICT_EXAMPLES)]
    Predict(PredictArgs),
}

const CALIBRATE_EXAMPLES: &str = "\
Examples:
  The network of this host (2 ranks under mpirun): the [network] lines to paste
    collide calibrate --network
  Measured between 2 nodes of a site and written into its file
    collide calibrate --network --system slurm-local --nodes 2";

const PREDICT_EXAMPLES: &str = "\
Examples:
  A study's prediction on an assumed InfiniBand-class network
    collide predict results/predict/
  On the network measured into a site file
    collide predict results/predict/ --system slurm-local";

#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// Measure the network between 2 MPI ranks instead of timing the workload.
    #[arg(long)]
    pub network: bool,
    /// The site whose launcher starts the 2 ranks, and whose file gets the `[network]`
    /// table: NAME for systems/NAME.toml or a path (`local`: printed, not written).
    #[arg(long, value_name = "NAME|PATH", default_value = LOCAL, requires = "network")]
    pub system: String,
    /// Nodes to put the 2 ranks on: 2 measures the network between nodes.
    #[arg(long, default_value_t = NonZeroUsize::MIN, value_parser = parse_workers, allow_negative_numbers = true, requires = "network")]
    pub nodes: NonZeroUsize,
}

#[derive(Debug, Args)]
pub struct PredictArgs {
    /// A study's results folder (results/NAME/) or one results file.
    pub path: PathBuf,
    /// The site whose `[network]` the prediction uses (NAME or path); without one, or
    /// without the table, an InfiniBand-class network is assumed and said so.
    #[arg(long, value_name = "NAME|PATH")]
    pub system: Option<String>,
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
    /// whole confidence interval of its time ratio lies above 1 + this (the default is
    /// chosen from A/A and injected-slowdown checks: docs/ci-check.md, Measured).
    #[arg(long, value_name = "FRACTION", default_value_t = 0.03, value_parser = parse_fraction, allow_negative_numbers = true)]
    pub noise: f64,
    /// Also build REV (any git revision; default: the commit that recorded the
    /// baseline) and run both builds interleaved: the paired ratios of this build to
    /// REV's decide, the baseline comparison is shown beside.
    #[arg(long, value_name = "REV", num_args = 0..=1, default_missing_value = "", conflicts_with = "update_baseline")]
    pub against: Option<String>,
    /// Folder to which each check appends its verdicts (`collide report DIR` draws them).
    #[arg(long, value_name = "DIR", default_value = "results/history")]
    pub history: PathBuf,
    /// Append nothing to the history.
    #[arg(long, conflicts_with = "history")]
    pub no_history: bool,
    /// Add this fraction of extra work to every step of this build's measured runs
    /// (testing only).
    #[arg(long, value_name = "FRACTION", default_value_t = 0.0, value_parser = parse_fraction, allow_negative_numbers = true, hide = true)]
    pub inject_slowdown: f64,
    /// Only into the runs of this backend (with --inject-slowdown; default: every backend).
    #[arg(
        long,
        value_enum,
        value_name = "BACKEND",
        requires = "inject_slowdown",
        hide = true
    )]
    pub inject_into: Option<BackendKind>,
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
    /// Frames of the GIF, spread evenly over the run (2 to 1000).
    #[arg(long, default_value_t = 60, value_parser = parse_gif_frames, allow_negative_numbers = true)]
    pub frames: u32,
    #[command(flatten)]
    pub overrides: Overrides,
}

#[derive(Debug, Args)]
pub struct ViewArgs {
    /// Scene file (TOML), e.g. experiments/scenes/seed-1000.toml.
    pub scene: PathBuf,
    /// Step with the rayon backend on this many threads (default: the serial backend).
    #[arg(long, value_parser = parse_workers, allow_negative_numbers = true)]
    pub threads: Option<NonZeroUsize>,
    /// Exit after this many frames.
    #[arg(long, value_name = "K", value_parser = parse_positive, allow_negative_numbers = true)]
    pub frames: Option<u64>,
    /// At exit, write frame and step rates and where the time went (JSON) to FILE.
    #[arg(long, value_name = "FILE")]
    pub stats: Option<PathBuf>,
    /// At exit, write the last frame to FILE (PNG); the p key writes there too.
    #[arg(long, value_name = "FILE.png")]
    pub screenshot: Option<PathBuf>,
    /// Pixels of the drawing, WIDTHxHEIGHT (the status line comes below it).
    #[arg(long, value_name = "WxH", default_value = "800x800", value_parser = parse_size)]
    pub size: (usize, usize),
    /// Frames per second at most; 0 draws as fast as it can (to measure).
    #[arg(long, value_name = "FPS", default_value_t = 60, value_parser = parse_max_fps, allow_negative_numbers = true)]
    pub max_fps: u32,
    /// Steps between two frames at the start ([ and ] halve and double it).
    #[arg(long, value_name = "STEPS", default_value_t = 1, value_parser = parse_positive, allow_negative_numbers = true)]
    pub steps_per_frame: u64,
    #[command(flatten)]
    pub overrides: Overrides,
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
    /// Continue the newest results file of this build: reuse its runs of the same
    /// configurations and scene contents, run only what is missing.
    #[arg(long)]
    pub resume: bool,
    /// No progress bar or notes (automatic when stdout is not a terminal).
    #[arg(long)]
    pub quiet: bool,
    /// Reports root: the report (report.md and its figures) goes to DIR/<study name>/.
    #[arg(long, value_name = "DIR", default_value = "reports")]
    pub reports: PathBuf,
    /// Write no report: print the table only (`collide report` writes it later).
    #[arg(long, conflicts_with = "reports")]
    pub no_report: bool,
    /// Where MPI runs go: `local` (this host, mpirun), NAME for systems/NAME.toml, or
    /// the path of a site file (docs/clusters.md); a batch scheduler's site submits each
    /// run as a job.
    #[arg(long, value_name = "NAME|PATH", default_value = LOCAL)]
    pub system: String,
}

#[derive(Debug, Args)]
pub struct ResultsArgs {
    /// A study's results folder (results/NAME/) or one results file.
    pub path: PathBuf,
    /// text (the terminal tables), csv or json (one row per configuration, times in
    /// seconds, for scripts), or markdown (to paste).
    #[arg(long, value_enum, default_value_t = Format::Text)]
    pub format: Format,
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
    pub overrides: Overrides,
    /// How to run the steps: serial (the reference), rayon (threads) or mpi (ranks).
    #[arg(long, value_enum, default_value_t = BackendKind::Serial)]
    pub backend: BackendKind,
    /// Threads of the rayon pool (with --backend rayon; default: the usable CPUs), or
    /// threads each MPI rank steps on (with --backend mpi; default: 1 when collide starts
    /// the ranks; under an MPI launcher, the ranks' RAYON_NUM_THREADS when set, else each
    /// rank's share of the CPUs it was bound to). --ranks × --threads CPUs are used.
    #[arg(long, value_parser = parse_workers, allow_negative_numbers = true)]
    pub threads: Option<NonZeroUsize>,
    /// MPI ranks to launch (with --backend mpi; default under mpirun: its world size).
    #[arg(long, value_parser = parse_workers, allow_negative_numbers = true)]
    pub ranks: Option<NonZeroUsize>,
    /// Allow more than 8 workers (threads, or ranks × threads) per usable CPU (refused
    /// otherwise: such a run measures the scheduler rather than the simulation).
    #[arg(long)]
    pub oversubscribe: bool,
    /// MPI launcher and its options, followed by `-n RANKS` and this program
    /// (e.g. "mpirun --bind-to core", or "mpiexec" for MPICH).
    #[arg(long, env = "COLLIDE_MPI_LAUNCHER", default_value = MPI_LAUNCHER)]
    pub launcher: String,
    /// Start the ranks as the site file at PATH (or systems/NAME.toml) says, instead of
    /// as --launcher says (with --backend mpi).
    #[arg(long, value_name = "NAME|PATH")]
    pub system: Option<String>,
    /// Nodes to spread the ranks over (with --backend mpi; a site's launcher places them).
    #[arg(long, value_parser = parse_workers, allow_negative_numbers = true)]
    pub nodes: Option<NonZeroUsize>,
    /// Seconds before a launched MPI run is killed with all its ranks [default: the
    /// environment's COLLIDE_MPI_TIMEOUT, else 3600]. Read only with --backend mpi.
    #[arg(long, value_parser = parse_seconds)]
    pub mpi_timeout: Option<f64>,
    /// Add this fraction of extra work to every step (testing `collide check` only).
    #[arg(long, value_name = "FRACTION", default_value_t = 0.0, value_parser = parse_fraction, allow_negative_numbers = true, hide = true)]
    pub inject_slowdown: f64,
}

fn parse_workers(text: &str) -> Result<NonZeroUsize, String> {
    text.parse::<NonZeroUsize>()
        .map_err(|_| format!("expected a whole number of at least 1, got \"{text}\""))
}

fn parse_size(text: &str) -> Result<(usize, usize), String> {
    let size = text.split_once('x').and_then(|(w, h)| {
        let (w, h) = (w.parse::<usize>().ok()?, h.parse::<usize>().ok()?);
        ((1..=16384).contains(&w) && (1..=16384).contains(&h)).then_some((w, h))
    });
    size.ok_or_else(|| {
        format!("expected WIDTHxHEIGHT in pixels, each 1 to 16384 (e.g. 800x800), got \"{text}\"")
    })
}

/// The longest timeout a flag or variable may set: a year, far inside what a
/// `Duration` holds.
const MAX_SECONDS: f64 = 365.0 * 86_400.0;

/// A timeout in seconds: positive, at most [`MAX_SECONDS`].
pub fn parse_seconds(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(seconds) if seconds > 0.0 && seconds <= MAX_SECONDS => Ok(seconds),
        _ => Err(format!(
            "expected a positive number of seconds, at most {MAX_SECONDS} (a year), got \"{text}\""
        )),
    }
}

/// The largest fraction a flag takes: 100 (10,000%).
const MAX_FRACTION: f64 = 100.0;

fn parse_fraction(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(fraction) if (0.0..=MAX_FRACTION).contains(&fraction) => Ok(fraction),
        _ => Err(format!(
            "expected a fraction from 0 to {MAX_FRACTION} (0.25 = 25%), got \"{text}\""
        )),
    }
}

fn parse_positive(text: &str) -> Result<u64, String> {
    text.parse::<u64>()
        .ok()
        .filter(|&count| count >= 1)
        .ok_or_else(|| format!("expected a whole number of at least 1, got \"{text}\""))
}

fn parse_gif_frames(text: &str) -> Result<u32, String> {
    text.parse::<u32>()
        .ok()
        .filter(|frames| (2..=1000).contains(frames))
        .ok_or_else(|| format!("expected a whole number of frames from 2 to 1000, got \"{text}\""))
}

fn parse_max_fps(text: &str) -> Result<u32, String> {
    text.parse::<u32>().map_err(|_| {
        format!(
            "expected a whole number of frames per second, 0 (as fast as it can) to {}, got \"{text}\"",
            u32::MAX
        )
    })
}

#[cfg(test)]
mod tests {
    use clap::{CommandFactory, Parser};

    use super::Cli;

    /// The `collide ...` lines of a help text's examples, split into words.
    fn examples(help: &str) -> Vec<Vec<&str>> {
        help.lines()
            .map(str::trim)
            .filter(|line| line.starts_with("collide "))
            .map(|line| line.split_whitespace().collect())
            .collect()
    }

    #[test]
    fn the_command_line_is_well_formed() {
        Cli::command().debug_assert();
    }

    #[test]
    fn every_help_ends_in_examples_that_parse_and_name_existing_files() {
        let top = Cli::command();
        let mut helps = vec![(None, top.get_after_help().map(ToString::to_string))];
        for sub in top.get_subcommands().filter(|sub| !sub.is_hide_set()) {
            helps.push((
                Some(sub.get_name().to_owned()),
                sub.get_after_help().map(ToString::to_string),
            ));
        }
        for (name, help) in helps {
            let help = help.unwrap_or_else(|| panic!("`collide {name:?} --help` has no examples"));
            let examples = examples(&help);
            assert!(
                examples.len() >= 2,
                "{name:?}: fewer than two examples in {help}"
            );
            for words in examples {
                if let Some(name) = &name {
                    assert_eq!(
                        words[1], name,
                        "an example of `{name}` runs another command"
                    );
                }
                if let Err(err) = Cli::try_parse_from(&words) {
                    panic!("the example `{}` does not parse: {err}", words.join(" "));
                }
                // Shipped scenes and manifests: an example must not name a missing one.
                for file in words.iter().filter(|w| w.ends_with(".toml")) {
                    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
                    assert!(
                        path.exists(),
                        "the example `{}` names a missing {file}",
                        words.join(" ")
                    );
                }
            }
        }
    }
}
