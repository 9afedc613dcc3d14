//! Runs a parsed command: the glue between the command line, the files and the backends.

use std::num::NonZeroUsize;

use std::path::Path;

use anyhow::{Context, bail};

use crate::backend::{BackendSpec, RunOutcome, serial, threads};
use crate::check::calibrate;
use crate::check::{CheckOptions, CheckOutcome};
use crate::cli::{
    CalibrateArgs, CheckArgs, Cli, Command, RenderArgs, ReportArgs, RunArgs, SimulateArgs, ViewArgs,
};
use crate::cluster::network::Band;
use crate::cluster::site::Site;
use crate::exit::RunsFailed;
use crate::report::figures;
use crate::report::{accuracy, analysis, markdown, prediction, tables as results};
use crate::run::backend_kind::BackendKind;
use crate::run::limits::{Machine, WorkerSource, check_memory, check_workers, placement_note};
use crate::run::scene_file;
use crate::run::spec::InjectedSlowdown;
#[cfg(feature = "mpi")]
use crate::run::summary::RunSummary;
use crate::study::records::{self, Record, STATUS_OK};
use crate::study::runner::{Calibration, RunOptions, Slowdown};
use crate::study::{manifest, runner};
use crate::system::output::{
    check_distinct, check_output_file, check_output_folder, write_atomically, write_state_csv,
};
use crate::view::render;
use crate::view::window::ViewOptions;
use crate::{check, view};

/// How a command that did its job ended: `main` maps this to the exit code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    Done,
    /// `collide check` found a regression ([`crate::exit::RUNS_FAILED`]).
    Regressed,
}

pub fn run(cli: Cli) -> anyhow::Result<Outcome> {
    let done = match cli.command {
        Command::Simulate(args) => simulate(&args),
        Command::Run(args) => run_study(&args),
        Command::Results(args) => {
            crate::out!("{}", results::show(&args.path, args.format)?);
            Ok(())
        }
        Command::Report(args) => write_report(&args),
        Command::Render(args) => render_scene(&args),
        Command::View(args) => view_scene(&args),
        Command::Check(args) => return run_check(&args),
        Command::Calibrate(args) if args.network => calibrate_network(&args),
        Command::Calibrate(_) => {
            let seconds = calibrate::workload_seconds();
            let calibration = Calibration {
                calibration_s: seconds.wall,
                calibration_cpu_s: seconds.cpu,
            };
            crate::outln!("{}", serde_json::to_string(&calibration)?);
            Ok(())
        }
        Command::Predict(args) => {
            let records = results::load(&args.path)?;
            let band = network_band(args.system.as_deref())?;
            let predicted = prediction::predict(&records, &band).map_err(|reason| {
                anyhow::anyhow!("{}: no prediction: {reason}", args.path.display())
            })?;
            crate::out!("{}", prediction::markdown(&predicted, None));
            Ok(())
        }
    };
    done.map(|()| Outcome::Done)
}

/// The network band of the site `system` names (its `[network]`, else assumed), or the
/// assumed band without a site.
fn network_band(system: Option<&str>) -> anyhow::Result<Band> {
    Ok(match system {
        Some(system) => Site::find(system)?.network_band(),
        None => crate::cluster::network::assumed_band(),
    })
}

/// `collide calibrate --network`: as a rank, the ping-pong; otherwise 2 ranks launched
/// on the site, their measurement fitted and written into the site file's `[network]`
/// (printed for `local`, which has no file).
#[cfg(feature = "mpi")]
fn calibrate_network(args: &CalibrateArgs) -> anyhow::Result<()> {
    use crate::backend::{launcher, mpi};
    use crate::cluster::network::{self, Measured};
    if mpi::launched_by_mpi() {
        if let Some(measured) = mpi::measure_network()? {
            crate::outln!("{}", serde_json::to_string(&measured)?);
        }
        return Ok(());
    }
    let site = Site::find(&args.system)?;
    let layout = crate::cluster::placement::Layout {
        nodes: args.nodes.get(),
        ranks: 2,
        threads: 1,
    };
    layout
        .check(&site, true)
        .map_err(|reason| anyhow::anyhow!("--nodes: {reason}"))?;
    let launch = launcher::Launch {
        layout,
        site,
        timeout: std::time::Duration::from_secs(600),
    };
    let forwarded: Vec<std::ffi::OsString> = std::env::args_os().skip(1).collect();
    let (measured, _): (Measured, String) =
        launcher::launch_for(&launch, &forwarded, "measurement")?;
    let note = format!(
        "collide calibrate --network: 2 ranks on {} node(s) by {} from {}, {}",
        layout.nodes,
        launch.site.launcher.name(),
        crate::study::environment::Environment::capture().hostname,
        records::utc_now()
    );
    let fitted = network::fit(&measured, note)
        .ok_or_else(|| anyhow::anyhow!("the ping-pong's sizes gave no fit: {measured:?}"))?;
    crate::outln!("bytes        one-way µs   fitted µs");
    for sample in &measured.samples {
        crate::outln!(
            "{:>9}  {:>12.3}  {:>10.3}",
            sample.bytes,
            sample.seconds * 1e6,
            (fitted.alpha_s + fitted.beta_s_per_byte * sample.bytes) * 1e6
        );
    }
    crate::outln!(
        "all-reduce of 3 values on 2 ranks: {:.3} µs\n{}\n",
        measured.allreduce_s * 1e6,
        fitted.band().label
    );
    let table = network::table(&fitted);
    match Site::file_of(&args.system) {
        None => crate::outln!(
            "{table}\nthe `local` site has no file to keep these in: paste them into a site \
             file (docs/clusters.md) and name it with --system"
        ),
        Some(path) => {
            let text = crate::system::input::read_text(&path, crate::system::input::MAX_TEXT_BYTES)
                .map_err(|reason| anyhow::anyhow!("cannot read {} ({reason})", path.display()))?;
            let updated = network::with_table(&text, &table);
            // What is written must read back as the same site with this network.
            crate::cluster::site::parse(&path, &updated)?;
            write_atomically(&path, |file| file.write_all(updated.as_bytes()))?;
            crate::outln!("{table}\nwritten into {}", path.display());
        }
    }
    Ok(())
}

#[cfg(not(feature = "mpi"))]
fn calibrate_network(_: &CalibrateArgs) -> anyhow::Result<()> {
    bail!(
        "this collide was built without MPI support; to measure the network, {}",
        runner::ENABLE_MPI
    )
}

fn run_check(args: &CheckArgs) -> anyhow::Result<Outcome> {
    let options = CheckOptions {
        manifest: args.manifest.clone(),
        baseline: args.baseline.clone(),
        update_baseline: args.update_baseline,
        out: args.out.clone(),
        noise: args.noise,
        slowdown: Slowdown {
            fraction: args.inject_slowdown,
            into: args.inject_into,
        },
        against: args.against.clone(),
        history: (!args.no_history && !args.update_baseline).then(|| args.history.clone()),
        quiet: args.quiet,
    };
    Ok(match check::run(&options)? {
        CheckOutcome::Passed => Outcome::Done,
        CheckOutcome::Regressed => Outcome::Regressed,
    })
}

fn render_scene(args: &RenderArgs) -> anyhow::Result<()> {
    if args.png.is_none() && args.gif.is_none() {
        bail!(
            "nothing to draw; add --png FILE (the disks after the run) and/or --gif FILE (the run)"
        );
    }
    check_outputs(&args.scene, &[("--png", &args.png), ("--gif", &args.gif)])?;
    let spec = scene_file::load(&args.scene, &args.overrides)?;
    check_fits(&args.scene, &spec, 1, &Machine::this())?;
    let prepared = spec
        .prepare()
        .with_context(|| format!("{}", args.scene.display()))?;
    if let Some(path) = &args.png {
        render::png_after_run(&prepared, path)?;
        crate::outln!(
            "{} disks after {} steps drawn to {}",
            prepared.scene.particles.len(),
            prepared.steps,
            path.display()
        );
    }
    if let Some(path) = &args.gif {
        render::gif_of_run(&prepared, path, args.frames)?;
        crate::outln!(
            "{} steps animated in {} frames to {}",
            prepared.steps,
            args.frames,
            path.display()
        );
    }
    Ok(())
}

fn view_scene(args: &ViewArgs) -> anyhow::Result<()> {
    check_outputs(
        &args.scene,
        &[("--stats", &args.stats), ("--screenshot", &args.screenshot)],
    )?;
    let spec = scene_file::load(&args.scene, &args.overrides)?;
    if spec.method.draw {
        bail!(
            "--draw times offscreen drawing in `collide simulate` and studies; `collide view` \
             draws every frame already: drop --draw"
        );
    }
    if spec.method.method.may_be_event() && args.threads.is_some() {
        bail!(
            "{}: the event method (which method auto may choose) runs on the serial backend \
             only; drop --threads, or use --method step",
            args.scene.display()
        );
    }
    let prepared = spec
        .prepare()
        .with_context(|| format!("{}", args.scene.display()))?;
    let options = ViewOptions {
        width: args.size.0,
        height: args.size.1,
        threads: args.threads,
        frames: args.frames,
        max_fps: (args.max_fps > 0).then_some(args.max_fps),
        steps_per_frame: args.steps_per_frame,
        stats: args.stats.clone(),
        screenshot: args.screenshot.clone(),
    };
    let stats = view::window::run(prepared, &options)?;
    crate::outln!(
        "{} frames at {:.1} frames/s; {} steps at {:.1} steps/s; state {}",
        stats.frames,
        stats.frames_per_s,
        stats.steps,
        stats.steps_per_s,
        stats.state_hash
    );
    Ok(())
}

/// The scene picture a report links when it lies beside it (`collide render --png`).
const SCENE_PICTURE: &str = "scene.png";

fn write_report(args: &ReportArgs) -> anyhow::Result<()> {
    if crate::study::history::is_history(&args.path) {
        return write_history_report(args);
    }
    let records = results::load(&args.path)?;
    let study = results::one_study(&records, &args.path)?;
    let out = match &args.out {
        Some(out) => out.clone(),
        None => {
            // The name comes from a file, which anyone may have written.
            crate::study::names::check_name(study).map_err(|reason| {
                anyhow::anyhow!(
                    "{}: the study name {reason}; choose the report folder with --out",
                    args.path.display()
                )
            })?;
            Path::new("reports").join(study)
        }
    };
    report_into(&records, &args.path, &out, "--out", None)
}

/// The report of a check history folder: its figure and table in `--out` (default
/// reports/history/).
fn write_history_report(args: &ReportArgs) -> anyhow::Result<()> {
    let entries = crate::study::history::read(&args.path)?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| Path::new("reports").join("history"));
    std::fs::create_dir_all(&out).with_context(|| {
        format!(
            "cannot create the report folder {}; choose another with --out",
            out.display()
        )
    })?;
    let history = figures::Analysed {
        history: Some(&entries),
        ..Default::default()
    };
    figures::draw(&history, &out)?;
    let path = out.join("report.md");
    let text = markdown::history(&entries, &args.path);
    write_atomically(&path, |file| file.write_all(text.as_bytes()))?;
    crate::outln!(
        "history of {} checks drawn: {}",
        figures::history::checks(&entries).len(),
        path.display()
    );
    Ok(())
}

/// Writes the report of `records` (read from `source`) into the folder `out`, which the
/// option `flag` chose: report.md and its figures, with a scaling prediction on the
/// network of the site `system` names (else an assumed one) where the study has MPI
/// runs; prints where.
fn report_into(
    records: &[Record],
    source: &Path,
    out: &Path,
    flag: &str,
    system: Option<&str>,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| {
        format!(
            "cannot create the report folder {}; choose another with {flag}",
            out.display()
        )
    })?;
    let setups = analysis::analyse(records)?;
    let groups = accuracy::is_accuracy_study(records).then(|| accuracy::analyse(records));
    let cooling = match groups {
        Some(_) => accuracy::cooling(records),
        None => Vec::new(),
    };
    let predicted = prediction::predict(records, &network_band(system)?).ok();
    let analysed = figures::Analysed {
        setups: &setups,
        accuracy: groups.as_deref(),
        cooling: &cooling,
        history: None,
        prediction: predicted.as_ref(),
    };
    let drawn = figures::draw(&analysed, out)?;
    let pictures = markdown::Pictures {
        figures: drawn.by_setup(setups.len()),
        scene: out
            .join(SCENE_PICTURE)
            .exists()
            .then(|| SCENE_PICTURE.to_owned()),
        accuracy: groups.map(|groups| markdown::AccuracySection {
            groups,
            figures: drawn.accuracy(),
            cooling,
        }),
    };
    let path = out.join("report.md");
    let mut text = markdown::markdown(records, &setups, &source.display().to_string(), &pictures);
    if let Some(predicted) = &predicted {
        text += "\n";
        text += &prediction::markdown(predicted, Some(figures::prediction::FILE_NAME));
    }
    write_atomically(&path, |file| file.write_all(text.as_bytes()))?;
    crate::outln!(
        "report written to {}, its figures beside it",
        path.display()
    );
    Ok(())
}

fn run_study(args: &RunArgs) -> anyhow::Result<()> {
    let (study, text) = manifest::load(&args.manifest)?;
    let reports = args.reports.join(&study.name);
    // Refused before the first run, not after the last.
    check_output_folder(&args.out, "--out")?;
    if !args.no_report {
        check_output_folder(&reports, "--reports")?;
    }
    let options = RunOptions {
        out: args.out.clone(),
        resume: args.resume,
        continue_with: runner::resume_command(&args.manifest, &args.out),
        quiet: args.quiet,
        programs: vec![runner::Program::this()?],
        calibrate: false,
        mpi_yields_when_idle: false,
        system: args.system.clone(),
    };
    let outcome = runner::run_study(&study, &text, &options)?;
    crate::outln!(
        "{} runs measured, {} failed{} → {}",
        outcome.measured,
        outcome.failed,
        if outcome.kept > 0 {
            format!(", {} kept from before", outcome.kept)
        } else {
            String::new()
        },
        outcome.results.display()
    );
    // What the study was for: its table, and its report (failed runs are left out of both).
    let records = records::read(&outcome.results)?;
    if records.iter().any(|r| r.status == STATUS_OK) {
        crate::out!("\n{}", results::summary(&records)?);
        if args.no_report {
            crate::outln!(
                "\nno report written (--no-report); write it with `collide report {}`",
                outcome.results.display()
            );
        } else {
            crate::outln!();
            report_into(
                &records,
                &outcome.results,
                &reports,
                "--reports",
                Some(&args.system),
            )?;
        }
    }
    if outcome.failed > 0 {
        return Err(RunsFailed(format!(
            "{} run(s) failed; their rows in {} say why (status, error)",
            outcome.failed,
            outcome.results.display()
        ))
        .into());
    }
    Ok(())
}

fn simulate(args: &SimulateArgs) -> anyhow::Result<()> {
    let machine = Machine::this();
    let backend = backend_spec(args, &machine)?;
    check_outputs(&args.scene, &[("--dump", &args.dump)])?;
    let mut spec = scene_file::load(&args.scene, &args.overrides)?;
    let capabilities = args.backend.capabilities();
    let copies = match (capabilities.scene_in_every_process, backend) {
        (true, BackendSpec::Mpi { ranks, .. }) => {
            spec.whole_scene_copies(ranks.map_or_else(usable_cpus, NonZeroUsize::get))
        }
        _ => 1,
    };
    check_fits(&args.scene, &spec, copies, &machine)?;
    if spec.method.method.may_be_event() && !capabilities.event_method {
        bail!(
            "{}: the event method (which method auto may choose) runs on the serial backend \
             only; drop --backend {} (and --threads/--ranks), or use --method step",
            args.scene.display(),
            args.backend.name()
        );
    }
    if spec.method.draw && !capabilities.draws {
        bail!(
            "{}: --draw draws every step, which needs all the disks in one process; drop \
             --backend mpi (and --ranks) for serial or rayon, or drop --draw",
            args.scene.display()
        );
    }
    spec.slowdown = InjectedSlowdown::new(args.inject_slowdown)
        .context("--inject-slowdown takes a fraction of 0 or more")?;
    let context = || format!("{}", args.scene.display());
    let finished = match backend {
        BackendSpec::Serial => Finished::Here(serial::run(&spec).with_context(context)?),
        BackendSpec::Rayon { threads } => {
            Finished::Here(threads::run(&spec, threads).with_context(context)?)
        }
        BackendSpec::Mpi { ranks, threads } => {
            run_mpi(args, &spec, ranks, threads).with_context(context)?
        }
    };
    let summary = match finished {
        Finished::Here(outcome) => {
            if let (Some(path), Some(state)) = (&args.dump, &outcome.final_state) {
                write_atomically(path, |out| write_state_csv(out, state))?;
            }
            outcome.summary
        }
        #[cfg(feature = "mpi")]
        Finished::Launched(summary) => summary,
        #[cfg(feature = "mpi")]
        Finished::OtherRank => return Ok(()),
    };
    if args.json {
        crate::outln!("{}", serde_json::to_string(&summary)?);
    } else {
        crate::outln!("{summary}");
        if let Some(path) = &args.dump {
            crate::outln!("final state written to {}", path.display());
        }
    }
    Ok(())
}

/// Checks, before any work, the output files a command was given (each with its flag):
/// each can be written, and none is the scene file nor another output.
fn check_outputs(
    scene: &Path,
    outputs: &[(&str, &Option<std::path::PathBuf>)],
) -> anyhow::Result<()> {
    let given: Vec<(&str, &Path)> = outputs
        .iter()
        .filter_map(|(flag, path)| path.as_deref().map(|path| (*flag, path)))
        .collect();
    for (flag, path) in &given {
        check_output_file(path, flag)?;
    }
    check_distinct(&[("scene file", scene)], &given)
}

/// Refuses a run whose memory cannot fit the machine, and announces a long placement.
fn check_fits(
    scene: &std::path::Path,
    spec: &crate::run::spec::RunSpec,
    copies: usize,
    machine: &Machine,
) -> anyhow::Result<()> {
    let footprint = spec.footprint(copies);
    check_memory(&footprint, machine)
        .map_err(|reason| anyhow::anyhow!("{}: `n`: {reason}", scene.display()))?;
    if let Some(note) = placement_note(&footprint) {
        eprintln!("{note}");
    }
    Ok(())
}

/// Where a run ended.
enum Finished {
    /// In this process, with the final state.
    Here(RunOutcome),
    /// In ranks this process launched; rank 0 wrote any `--dump` file.
    #[cfg(feature = "mpi")]
    Launched(RunSummary),
    /// This process is an MPI rank other than 0: rank 0 reports.
    #[cfg(feature = "mpi")]
    OtherRank,
}

/// Runs `spec` on MPI ranks, each stepping on `threads` threads (`--threads`): as one
/// rank when an MPI launcher started this process, else by launching them.
#[cfg(feature = "mpi")]
fn run_mpi(
    args: &SimulateArgs,
    spec: &crate::run::spec::RunSpec,
    ranks: Option<NonZeroUsize>,
    threads: Option<NonZeroUsize>,
) -> anyhow::Result<Finished> {
    use crate::backend::distributed::FinalState;
    use crate::backend::{launcher, mpi};
    if mpi::launched_by_mpi() {
        let final_state = match args.dump {
            Some(_) => FinalState::Gathered,
            None => FinalState::Summed,
        };
        return Ok(
            match mpi::run_rank(
                spec,
                ranks.map(NonZeroUsize::get),
                final_state,
                rank_threads(threads)?,
            )? {
                Some(outcome) => Finished::Here(outcome),
                None => Finished::OtherRank,
            },
        );
    }
    let site = match &args.system {
        Some(system) => crate::cluster::site::Site::find(system)?,
        None => crate::cluster::site::Site::from_launcher(&args.launcher)
            .map_err(|reason| anyhow::anyhow!("--launcher: {reason}"))?,
    };
    let layout = crate::cluster::placement::Layout {
        nodes: args.nodes.map_or(1, NonZeroUsize::get),
        ranks: ranks.map_or_else(usable_cpus, NonZeroUsize::get),
        threads: threads.map_or(1, NonZeroUsize::get),
    };
    layout
        .check(&site, true)
        .map_err(|reason| anyhow::anyhow!("--nodes, --ranks and --threads: {reason}"))?;
    let launch = launcher::Launch {
        layout,
        site,
        timeout: std::time::Duration::from_secs_f64(mpi_timeout(args)?),
    };
    // The ranks run this same command line; rank 0 answers in JSON.
    let mut forwarded: Vec<std::ffi::OsString> = std::env::args_os().skip(1).collect();
    if !args.json {
        forwarded.push("--json".into());
    }
    Ok(Finished::Launched(launcher::launch(&launch, &forwarded)?))
}

/// The threads a rank was told to step on: `--threads`, else [`THREADS_ENV`] (which
/// collide's launch line sets for every rank it starts); `None` when neither says, and
/// the rank takes its share of its CPUs ([`crate::backend::mpi::run_rank`]). A bad
/// variable is named as such.
#[cfg(feature = "mpi")]
fn rank_threads(given: Option<NonZeroUsize>) -> anyhow::Result<Option<NonZeroUsize>> {
    use crate::cluster::render::THREADS_ENV;
    if let Some(threads) = given {
        return Ok(Some(threads));
    }
    let Some(text) = std::env::var_os(THREADS_ENV) else {
        return Ok(None);
    };
    text.to_str()
        .and_then(|text| text.trim().parse::<NonZeroUsize>().ok())
        .map(Some)
        .ok_or_else(|| {
            anyhow::anyhow!(
                "the environment variable {THREADS_ENV}={text:?} sets the threads of each MPI \
                 rank when --threads is not given, and is not a whole number of at least 1; \
                 fix or unset it, or give --threads"
            )
        })
}

/// The variable that sets `--mpi-timeout` when the flag is not given.
#[cfg(feature = "mpi")]
const MPI_TIMEOUT_ENV: &str = "COLLIDE_MPI_TIMEOUT";

/// Seconds before a launched MPI run is stopped: `--mpi-timeout`, else
/// [`MPI_TIMEOUT_ENV`], else an hour; a bad variable is named as such.
#[cfg(feature = "mpi")]
fn mpi_timeout(args: &SimulateArgs) -> anyhow::Result<f64> {
    if let Some(seconds) = args.mpi_timeout {
        return Ok(seconds);
    }
    match std::env::var(MPI_TIMEOUT_ENV) {
        Ok(text) => crate::cli::parse_seconds(&text).map_err(|reason| {
            anyhow::anyhow!(
                "the environment variable {MPI_TIMEOUT_ENV}={text:?}: {reason}; fix or unset it"
            )
        }),
        Err(_) => Ok(3600.0),
    }
}

#[cfg(not(feature = "mpi"))]
fn run_mpi(
    _: &SimulateArgs,
    _: &crate::run::spec::RunSpec,
    _: Option<NonZeroUsize>,
    _: Option<NonZeroUsize>,
) -> anyhow::Result<Finished> {
    bail!(
        "this collide was built without MPI support; to use --backend mpi, {}",
        runner::ENABLE_MPI
    )
}

/// The default worker count: the CPUs this process may run on.
fn usable_cpus() -> usize {
    crate::system::machine::usable_cpus()
}

/// The backend the flags ask for; worker counts only go with the backend they count, and
/// the workers (threads, or MPI ranks × threads per rank) stay under the machine's
/// ceiling unless `--oversubscribe` insists.
fn backend_spec(args: &SimulateArgs, machine: &Machine) -> anyhow::Result<BackendSpec> {
    let name = args.backend;
    if args.threads.is_some() && !name.is_parallel() {
        bail!(
            "--threads sets the threads of the rayon pool (--backend rayon) or of each MPI \
             rank (--backend mpi), and the serial backend steps on one; add `--backend rayon` \
             or `--backend mpi`, or drop --threads"
        );
    }
    if args.ranks.is_some() && name != BackendKind::Mpi {
        bail!("--ranks sets the MPI process count; add `--backend mpi` or drop --ranks");
    }
    if args.nodes.is_some() && name != BackendKind::Mpi {
        bail!("--nodes spreads MPI ranks over nodes; add `--backend mpi` or drop --nodes");
    }
    // The workers the flags ask for, named by the flags that set them.
    let asked = match (name, args.ranks, args.threads) {
        (BackendKind::Mpi, ranks, Some(threads)) => Some((
            "--ranks × --threads",
            // Without --ranks, collide launches one rank per usable CPU.
            ranks.map_or_else(usable_cpus, NonZeroUsize::get) * threads.get(),
        )),
        (_, Some(ranks), _) => Some(("--ranks", ranks.get())),
        (_, None, Some(threads)) => Some(("--threads", threads.get())),
        (_, None, None) => None,
    };
    if let Some((field, workers)) = asked {
        let source = WorkerSource {
            field,
            insist: "add --oversubscribe",
        };
        check_workers(workers, machine, args.oversubscribe, source).map_err(anyhow::Error::msg)?;
    }
    Ok(match name {
        BackendKind::Serial => BackendSpec::Serial,
        BackendKind::Rayon => BackendSpec::Rayon {
            threads: args
                .threads
                .unwrap_or_else(|| NonZeroUsize::new(usable_cpus()).unwrap_or(NonZeroUsize::MIN)),
        },
        BackendKind::Mpi => BackendSpec::Mpi {
            ranks: args.ranks,
            threads: args.threads,
        },
    })
}
