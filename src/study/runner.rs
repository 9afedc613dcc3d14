//! Runs a study: every configuration in a fresh `collide simulate` process (MPI through
//! its launcher), warm-ups first, then the repetitions interleaved across
//! configurations so that drift of the machine hits all of them alike. An A/B check runs
//! two programs (two builds of collide) the same way, each repetition of a configuration
//! once by each, next to each other, in alternating order (A B, then B A). Each finished
//! repetition is written at once (the whole file, atomically), so a crash, a kill or
//! Ctrl-C loses nothing already measured, and `--resume` runs only what is missing.
//! One study at a time writes into a study folder (a lock a second run waits for), each
//! into a results file of its own, and each start removes what a killed one left unfinished.

use std::collections::BTreeSet;
use std::fs::{File, TryLockError};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use anyhow::{Context, anyhow, bail};
use indicatif::{ProgressBar, ProgressStyle};

use crate::cluster::placement::{mask_warnings, rank_cpus, rank_cpus_column};
use crate::cluster::render::{Job, job_script};
use crate::cluster::site::{LOCAL, Site};
use crate::cluster::slurm::JobState;
use crate::run::backend_kind::BackendKind;
use crate::run::summary::RunSummary;
use crate::study::batch::{self, BatchJob, JobEnd};
use crate::study::environment::Environment;
use crate::study::manifest::{Configuration, SceneInput, Study};
use crate::study::records::{
    self, Record, RecordContext, STATUS_FAILED, STATUS_OK, STATUS_TIMED_OUT,
};
use crate::system::input::{MAX_TEXT_BYTES, read_text};
use crate::system::output::{free_path, remove_leftovers, write_atomically};
use crate::system::process::{Ended, interrupt_note, run_with_timeout, tail};

/// How to run a study.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Results root: the study writes into `out/<study name>/`.
    pub out: PathBuf,
    /// Continue the newest results file of the same build: its rows of the runs still
    /// wanted are kept, the rest are measured.
    pub resume: bool,
    /// The command an interrupt suggests to continue (e.g. [`resume_command`]).
    pub continue_with: String,
    /// No progress bar or notes (also when stdout is not a terminal).
    pub quiet: bool,
    /// The programs that run every repetition, one after the other: this one alone in
    /// a study ([`Program::this`]); the build checked against and this one in an A/B check.
    pub programs: Vec<Program>,
    /// Time the calibration workload (`collide calibrate`) before every round of
    /// repetitions, interleaved with the configurations.
    pub calibrate: bool,
    /// Ask OpenMPI's ranks to yield the CPU while they wait ([`YIELD_WHEN_IDLE`]) instead
    /// of polling, unless the environment already says: the check's MPI timings vary
    /// less from run to run that way on a machine with as many cores as ranks.
    pub mpi_yields_when_idle: bool,
    /// Where MPI runs go (`--system`): `local`, a site's NAME or a site file's path; a
    /// batch scheduler's site submits every run as a job ([`crate::study::batch`]).
    pub system: String,
}

/// The OpenMPI setting (an environment variable `mpirun` passes to its ranks) that makes
/// a waiting rank yield the CPU; other MPIs ignore it.
pub const YIELD_WHEN_IDLE: &str = "OMPI_MCA_mpi_yield_when_idle";

/// A `collide` program that runs the repetitions of a study.
#[derive(Clone, Debug)]
pub struct Program {
    /// Its side of an A/B check (`A` the build checked against, `B` this one), recorded
    /// in the `ab_side` column; empty in a study.
    pub side: &'static str,
    pub exe: PathBuf,
    /// The commit it was built from, when it is not this build (recorded in the rows it
    /// ran instead of this build's commit).
    pub commit: Option<String>,
    /// Extra work in the runs of some configurations (testing the check only).
    pub slowdown: Slowdown,
}

impl Program {
    /// This program, with nothing injected.
    pub fn this() -> anyhow::Result<Program> {
        Ok(Program {
            side: "",
            exe: this_exe()?,
            commit: None,
            slowdown: Slowdown::default(),
        })
    }
}

/// This program's path.
pub fn this_exe() -> anyhow::Result<PathBuf> {
    std::env::current_exe().context("cannot find this program's path")
}

/// An injected slowdown (`--inject-slowdown FRACTION`) of the runs of one backend's
/// configurations, or of every configuration; none by default.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Slowdown {
    pub fraction: f64,
    /// The only backend slowed down; `None`: every backend.
    pub into: Option<BackendKind>,
}

impl Slowdown {
    /// The `collide simulate` arguments that slow down a run of `backend`.
    pub fn simulate_args(&self, backend: BackendKind) -> Vec<String> {
        match self.fraction > 0.0 && self.into.is_none_or(|into| into == backend) {
            true => vec!["--inject-slowdown".to_owned(), self.fraction.to_string()],
            false => Vec::new(),
        }
    }
}

/// The order in which the programs run repetition `rep` of configuration `c`: as given
/// and reversed in turn (A B, B A, A B, ...), so that neither always runs first.
fn run_order(programs: &[Program], rep: u32, c: usize) -> Vec<&Program> {
    let mut order: Vec<&Program> = programs.iter().collect();
    if (rep as usize + c) % 2 == 1 {
        order.reverse();
    }
    order
}

/// What a study run left behind.
#[derive(Clone, Debug)]
pub struct StudyOutcome {
    pub results: PathBuf,
    pub measured: usize,
    pub failed: usize,
    /// Runs already in the file when resuming.
    pub kept: usize,
    /// Each calibration run, in order (empty unless asked for).
    pub calibrations: Vec<Calibration>,
}

pub fn run_study(
    study: &Study,
    manifest_text: &str,
    options: &RunOptions,
) -> anyhow::Result<StudyOutcome> {
    // Ctrl-C stops the running child too; every finished repetition is already on disk.
    crate::system::process::stop_children_on_interrupt();
    let quiet = options.quiet || !std::io::stdout().is_terminal();
    let note = |text: &str| {
        if !quiet {
            crate::outln!("{text}");
        }
    };
    let configurations = runnable(study)?;
    let site = placed_on_site(study, &configurations, &options.system)?;
    let environment = Environment::capture();
    let dir = options.out.join(&study.name);
    let _held = open_results_folder(&dir, &note)?;
    let build_id = build_id(&environment);
    let scene_hashes = configurations
        .iter()
        .map(|configuration| scene_hash(&configuration.input))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let wanted = wanted_runs(study, &configurations, &scene_hashes);
    let identities: Vec<RunIdentity> = wanted.iter().map(|(_, _, id)| id.clone()).collect();
    let (results, rows) = match options.resume {
        false => (new_results_path(&dir, &environment), Vec::new()),
        // Jobs submitted before any row was written are resumed too.
        true if !site.is_batch() || !batch::has_submitted(&dir.join(JOBS)) || has_rows(&dir)? => {
            resumed(&dir, &build_id, &identities, &environment, &note)?
        }
        true => (new_results_path(&dir, &environment), Vec::new()),
    };
    let done: BTreeSet<RunIdentity> = rows.iter().map(RunIdentity::of).collect();
    let todo: Vec<(u32, usize)> = wanted
        .into_iter()
        .filter(|(_, _, identity)| !done.contains(identity))
        .map(|(rep, c, _)| (rep, c))
        .collect();
    note_configurations(&configurations, &environment, &note);
    let sitting = Sitting {
        study,
        scene_files: materialize_scenes(&dir, &configurations)?,
        configurations,
        scene_hashes,
        manifest_hash: text_hash(manifest_text),
        build_id,
        environment,
        started_utc: records::utc_now(),
        results,
    };
    match site.is_batch() {
        true => sitting.run_batch(&todo, rows, options, &site, &note),
        false => sitting.run(&todo, rows, options, quiet, &note),
    }
}

/// The folder of a study's batch jobs, in its results folder.
const JOBS: &str = "jobs";

/// Whether the study folder `dir` holds a results file.
fn has_rows(dir: &Path) -> anyhow::Result<bool> {
    Ok(!records::files_in(dir)?.is_empty())
}

/// The site `system` names, once every configuration's layout fits it (or insists).
fn placed_on_site(
    study: &Study,
    configurations: &[&Configuration],
    system: &str,
) -> anyhow::Result<Site> {
    let site = Site::find(system)?;
    // On `local`, the manifest's own checks against this machine hold; elsewhere the
    // site places MPI runs, and with a scheduler every run.
    let placed = configurations.iter().filter(|configuration| {
        system != LOCAL && (site.is_batch() || configuration.backend.capabilities().mpi)
    });
    for configuration in placed {
        configuration
            .layout
            .check(&site, configuration.oversubscribe)
            .map_err(|reason| {
                anyhow!(
                    "{}: {} on the site `{}`: {reason}",
                    study.manifest.display(),
                    configuration.key(),
                    site.name
                )
            })?;
    }
    Ok(site)
}

/// Every run a study asks for, round by round: (repetition, configuration index, its
/// identity).
fn wanted_runs(
    study: &Study,
    configurations: &[&Configuration],
    scene_hashes: &[String],
) -> Vec<(u32, usize, RunIdentity)> {
    (0..study.rounds())
        .flat_map(|rep| (0..configurations.len()).map(move |c| (rep, c)))
        .filter(|&(rep, c)| rep < configurations[c].repetitions)
        .map(|(rep, c)| {
            let identity = RunIdentity {
                config_key: configurations[c].key(),
                scene_hash: scene_hashes[c].clone(),
                repetition: rep,
            };
            (rep, c, identity)
        })
        .collect()
}

/// One sitting of a study: what all its runs share.
struct Sitting<'a> {
    study: &'a Study,
    configurations: Vec<&'a Configuration>,
    scene_hashes: Vec<String>,
    /// The scene file each configuration's process reads.
    scene_files: Vec<PathBuf>,
    manifest_hash: String,
    build_id: String,
    environment: Environment,
    started_utc: String,
    /// The results file the rows go to.
    results: PathBuf,
}

impl Sitting<'_> {
    /// Runs `todo` ((repetition, configuration index) pairs) after the warm-ups, adding
    /// each row to `rows` (the rows kept from before) and writing them all after each run.
    fn run(
        &self,
        todo: &[(u32, usize)],
        mut rows: Vec<Record>,
        options: &RunOptions,
        quiet: bool,
        note: &dyn Fn(&str),
    ) -> anyhow::Result<StudyOutcome> {
        let kept_note =
            |rows: &[Record]| interrupted_note(rows, &self.results, &options.continue_with);
        *interrupt_note() = kept_note(&rows);
        let kept = rows.len();
        let warm: BTreeSet<usize> = todo.iter().map(|&(_, c)| c).collect();
        let size = |c: usize| self.configurations[c].footprint.disk_steps();
        let warm_ups = warm.iter().map(|&c| (self.study.warmups as u64, size(c)));
        let measured_runs = todo.iter().map(|&(_, c)| (1, size(c)));
        let progress = Progress::new(
            quiet,
            warm_ups.chain(measured_runs),
            options.programs.len() as u64,
        );
        note(&self.announcement());
        let children = Children {
            exe: this_exe()?,
            timeout: self.study.timeout,
            system: (options.system != LOCAL).then(|| options.system.clone()),
            // The environment's own setting, if any, wins.
            mpi_yields_when_idle: options.mpi_yields_when_idle
                && std::env::var_os(YIELD_WHEN_IDLE).is_none(),
        };
        children.warm_up(
            &options.programs,
            &self.configurations,
            &self.scene_files,
            &warm,
            self.study.warmups,
            &progress,
        );
        let mut calibrations = Vec::new();
        let (mut measured, mut failed) = (0, 0);
        for (index, &(rep, c)) in todo.iter().enumerate() {
            if options.calibrate && (index == 0 || todo[index - 1].0 != rep) {
                progress.bar.set_message(format!("rep {rep}: calibration"));
                calibrations.push(children.calibrate()?);
            }
            let key = self.configurations[c].key();
            progress.bar.set_message(format!("rep {rep}: {key}"));
            for program in run_order(&options.programs, rep, c) {
                let record = self.measure(&children, program, rep, c, &key);
                if record.status == STATUS_OK {
                    measured += 1;
                } else {
                    failed += 1;
                    (progress.bar).suspend(|| eprintln!("run failed: {key}: {}", record.error));
                }
                rows.push(record);
                let mut interrupted = interrupt_note();
                records::write(&self.results, &rows)?;
                *interrupted = kept_note(&rows);
                drop(interrupted);
                progress.ran(size(c));
            }
        }
        progress.bar.finish_and_clear();
        self.finish(todo, rows, kept, (measured, failed), calibrations)
    }

    /// The study's outcome once every run of `todo` has its row in `rows` (`kept` of
    /// them from before): the load at the end recorded in the rows measured now.
    fn finish(
        &self,
        todo: &[(u32, usize)],
        mut rows: Vec<Record>,
        kept: usize,
        (measured, failed): (usize, usize),
        calibrations: Vec<Calibration>,
    ) -> anyhow::Result<StudyOutcome> {
        if !todo.is_empty() {
            record_load_at_end(&self.results, &mut rows, kept)?;
        }
        Ok(StudyOutcome {
            results: self.results.clone(),
            measured,
            failed,
            kept,
            calibrations,
        })
    }

    /// What the study is about to do, in one line.
    fn announcement(&self) -> String {
        let counts = self.configurations.iter().map(|c| c.repetitions);
        let (fewest, most) = (counts.clone().min().unwrap_or(0), counts.max().unwrap_or(0));
        format!(
            "study {}: {} configurations × {} repetitions (+{} warm-up each) → {}",
            self.study.name,
            self.configurations.len(),
            match fewest == most {
                true => most.to_string(),
                false => format!("{fewest}–{most}"),
            },
            self.study.warmups,
            self.results.display()
        )
    }

    /// Repetition `rep` of configuration `c` (its key `key`) by `program`: its row.
    fn measure(
        &self,
        children: &Children,
        program: &Program,
        rep: u32,
        c: usize,
        key: &str,
    ) -> Record {
        let configuration = self.configurations[c];
        let context = self.context(rep, c, key);
        children.measure(program, configuration, &self.scene_files[c], &context)
    }

    /// What the row of repetition `rep` of configuration `c` (its key `key`) records
    /// besides the run's own result.
    fn context<'s>(&'s self, rep: u32, c: usize, key: &'s str) -> RecordContext<'s> {
        let configuration = self.configurations[c];
        RecordContext {
            study: &self.study.name,
            manifest_hash: &self.manifest_hash,
            build_id: &self.build_id,
            config_key: key,
            scene: &configuration.scene,
            scene_hash: &self.scene_hashes[c],
            scaling: self.study.scaling.name(),
            backend: configuration.backend,
            placement: configuration.placement(),
            repetition: rep,
            environment: &self.environment,
            study_started_utc: &self.started_utc,
        }
    }

    /// Runs `todo` as batch jobs on `site`'s queue (no warm-ups: every job is a fresh
    /// allocation), adding each row to `rows` as its job ends and writing them all.
    fn run_batch(
        &self,
        todo: &[(u32, usize)],
        mut rows: Vec<Record>,
        options: &RunOptions,
        site: &Site,
        note: &dyn Fn(&str),
    ) -> anyhow::Result<StudyOutcome> {
        let kept_note =
            |rows: &[Record]| interrupted_note(rows, &self.results, &options.continue_with);
        *interrupt_note() = kept_note(&rows);
        let kept = rows.len();
        note(&self.announcement());
        let workdir = std::env::current_dir().context("cannot read the working folder")?;
        let folder = self.results.parent().unwrap_or(Path::new("."));
        let dir = workdir.join(folder).join(JOBS);
        let mut site = site.clone();
        // Without a limit of its own, a job gets the study's timeout, in whole minutes.
        let minutes = self.study.timeout.as_secs().div_ceil(60).max(1);
        site.time_limit
            .get_or_insert_with(|| format!("{:02}:{:02}:00", minutes / 60, minutes % 60));
        let jobs = self.batch_jobs(todo, &site, &dir, &workdir)?;
        let (mut measured, mut failed) = (0, 0);
        let mut collect = |index: usize, end: JobEnd| -> anyhow::Result<()> {
            let (rep, c) = todo[index];
            let key = self.configurations[c].key();
            let record = self.record_of_job(rep, c, end);
            if record.status == STATUS_OK {
                measured += 1;
            } else {
                failed += 1;
                eprintln!("run failed: {key}: {}", record.error);
            }
            rows.push(record);
            let mut interrupted = interrupt_note();
            records::write(&self.results, &rows)?;
            *interrupted = kept_note(&rows);
            Ok(())
        };
        batch::run_jobs(&dir, &jobs, &mut collect, note)?;
        self.finish(todo, rows, kept, (measured, failed), Vec::new())
    }

    /// The job of each run of `todo`: its name (the configuration's key hashed, and the
    /// repetition) and its script on `site`, started in `workdir`, writing into `dir`.
    fn batch_jobs(
        &self,
        todo: &[(u32, usize)],
        site: &Site,
        dir: &Path,
        workdir: &Path,
    ) -> anyhow::Result<Vec<BatchJob>> {
        let exe = this_exe()?.display().to_string();
        Ok(todo
            .iter()
            .map(|&(rep, c)| {
                let configuration = self.configurations[c];
                let name = format!("{}-r{rep}", text_hash(&configuration.key()));
                let mut program = vec![
                    exe.clone(),
                    "simulate".to_owned(),
                    self.scene_files[c].display().to_string(),
                ];
                program.extend(configuration.simulate_args());
                let job = Job {
                    name: &name,
                    dir,
                    workdir,
                    program: &program,
                };
                let script = job_script(site, configuration.layout, &job);
                BatchJob { name, script }
            })
            .collect())
    }

    /// The row of repetition `rep` of configuration `c` from how its job ended: its
    /// summary when it wrote an exit code, else why it ended without one; with the job's
    /// id, nodes and queue wait, and a warning for each rank whose CPUs were too few or
    /// shared.
    fn record_of_job(&self, rep: u32, c: usize, end: JobEnd) -> Record {
        let key = self.configurations[c].key();
        let context = self.context(rep, c, &key);
        let mut record = match end.code {
            Some(code) => {
                let ended = Ended::Exited {
                    status: std::os::unix::process::ExitStatusExt::from_raw(code << 8),
                    stdout: end.stdout.clone(),
                    stderr: end.stderr.clone(),
                };
                record_of(&context, Ok(ended), self.study.timeout)
            }
            None => {
                let status = match end.info.state {
                    JobState::TimedOut => STATUS_TIMED_OUT,
                    _ => STATUS_FAILED,
                };
                Record::failed(&context, status, batch::no_exit_code(&end))
            }
        };
        let ranks = rank_cpus(&end.stderr);
        for warning in mask_warnings(&ranks) {
            eprintln!("warning: {key}, job {}: {warning}", end.id);
        }
        record.rank_cpus = rank_cpus_column(&ranks);
        record.job_id = end.id;
        record.node_list = end.info.nodes;
        record.queue_wait_s = end.info.queue_wait_s.unwrap_or(f64::NAN);
        record
    }
}

/// What makes two runs the same measurement: the configuration (its key), the scene's
/// contents, and the repetition. `--resume` reuses a row only when all three match.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct RunIdentity {
    config_key: String,
    scene_hash: String,
    repetition: u32,
}

impl RunIdentity {
    fn of(record: &Record) -> RunIdentity {
        RunIdentity {
            config_key: record.config_key.clone(),
            scene_hash: record.scene_hash.clone(),
            repetition: record.repetition,
        }
    }
}

/// The results file a resumed study writes and the rows it reuses: the successful rows of
/// the last file of this build in `dir` that match a run still `wanted`. When that file
/// holds nothing else, the study continues in it; when it also holds rows of runs no
/// longer wanted (a scene or a sweep was edited since), those stay where they are and the
/// study continues in a new file that starts with the reused rows. An error when no
/// file of this build exists.
fn resumed(
    dir: &Path,
    build_id: &str,
    wanted: &[RunIdentity],
    environment: &Environment,
    note: &dyn Fn(&str),
) -> anyhow::Result<(PathBuf, Vec<Record>)> {
    let Some((path, rows)) = resumable(dir, build_id)? else {
        bail!(
            "nothing to resume in {}: no results file of this build; run without --resume",
            dir.display()
        );
    };
    let wanted: BTreeSet<&RunIdentity> = wanted.iter().collect();
    let total = rows.len();
    // A row of a run no longer wanted (a scene or sweep edited since) is never dropped.
    let stale = rows
        .iter()
        .any(|row| !wanted.contains(&RunIdentity::of(row)));
    let mut seen = BTreeSet::new();
    let reused: Vec<Record> = rows
        .into_iter()
        .filter(|row| row.status == STATUS_OK && seen.insert(RunIdentity::of(row)))
        .filter(|row| wanted.contains(&RunIdentity::of(row)))
        .collect();
    if !stale {
        return Ok((path, reused));
    }
    let fresh = new_results_path(dir, environment);
    note(&format!(
        "resuming: {} of the {total} rows of {} match this manifest and its scenes; the others \
         ran a workload since changed and stay in that file; continuing in {}",
        reused.len(),
        path.display(),
        fresh.display()
    ));
    Ok((fresh, reused))
}

/// What an interrupt prints: the measured runs kept in `results` and the command that
/// continues the study; nothing while none is kept.
fn interrupted_note(rows: &[Record], results: &Path, continue_with: &str) -> Option<String> {
    let ok = rows.iter().filter(|r| r.status == STATUS_OK).count();
    (ok > 0).then(|| {
        format!(
            "interrupted: {ok} run{} kept in {}; continue with {continue_with}",
            if ok == 1 { "" } else { "s" },
            results.display()
        )
    })
}

/// The programs' `simulate` and this program's `calibrate`, run as child processes
/// under the study's timeout.
struct Children {
    exe: PathBuf,
    timeout: Duration,
    /// The site MPI runs start on, when not `local` (`--system`).
    system: Option<String>,
    /// Start MPI runs with [`YIELD_WHEN_IDLE`] set.
    mpi_yields_when_idle: bool,
}

impl Children {
    /// One run of `configuration` on the scene file `scene` by `program`.
    fn simulate(
        &self,
        program: &Program,
        configuration: &Configuration,
        scene: &Path,
    ) -> std::io::Result<Ended> {
        let mut command = Command::new(&program.exe);
        command
            .arg("simulate")
            .arg(scene)
            .args(configuration.simulate_args())
            .args(program.slowdown.simulate_args(configuration.backend));
        if self.mpi_yields_when_idle && configuration.backend.capabilities().mpi {
            command.env(YIELD_WHEN_IDLE, "1");
        }
        if let Some(system) = self.system.as_ref()
            && configuration.backend.capabilities().mpi
        {
            command.args(["--system", system]);
        }
        run_with_timeout(command, self.timeout)
    }

    /// `warmups` runs by every program of each configuration in `warm` (indices into
    /// `configurations`, run on `scene_files`), unrecorded: a warm-up that fails will
    /// fail again when measured, and be recorded then.
    fn warm_up(
        &self,
        programs: &[Program],
        configurations: &[&Configuration],
        scene_files: &[PathBuf],
        warm: &BTreeSet<usize>,
        warmups: u32,
        progress: &Progress,
    ) {
        for &c in warm {
            for program in programs {
                for _ in 0..warmups {
                    (progress.bar).set_message(format!("warm-up {}", configurations[c].key()));
                    let _ = self.simulate(program, configurations[c], &scene_files[c]);
                    progress.ran(configurations[c].footprint.disk_steps());
                }
            }
        }
    }

    /// The row of one measured run of `configuration` by `program`, in `context`; a
    /// run by the build checked against records that build's commit.
    fn measure(
        &self,
        program: &Program,
        configuration: &Configuration,
        scene: &Path,
        context: &RecordContext<'_>,
    ) -> Record {
        let ended = self.simulate(program, configuration, scene);
        let mut record = record_of(context, ended, self.timeout);
        record.ab_side = program.side.to_owned();
        if let Some(commit) = &program.commit {
            (record.git_commit, record.git_dirty) = (commit.clone(), false);
        }
        record
    }

    /// One measurement of the calibration workload.
    fn calibrate(&self) -> anyhow::Result<Calibration> {
        let mut command = Command::new(&self.exe);
        command.arg("calibrate");
        match run_with_timeout(command, self.timeout)? {
            Ended::Exited { status, stdout, .. } if status.success() => {
                serde_json::from_str(stdout.trim())
                    .context("`collide calibrate` printed no calibration time")
            }
            _ => bail!("the calibration workload (`collide calibrate`) failed"),
        }
    }
}

/// Creates the study's results folder and holds it for this study alone (the open,
/// locked folder returned: released when dropped); removes what a killed study left
/// unfinished there.
fn open_results_folder(dir: &Path, note: &dyn Fn(&str)) -> anyhow::Result<File> {
    std::fs::create_dir_all(dir).with_context(|| {
        format!(
            "cannot create the results folder {}; check the path or choose another with --out",
            dir.display()
        )
    })?;
    let held = hold_folder(dir)?;
    // No other study writes here now: anything unfinished is a killed run's.
    let removed = remove_leftovers(dir)? + remove_leftovers(&dir.join("scenes"))?;
    if removed > 0 {
        note(&format!(
            "note: removed {removed} unfinished file(s) a stopped study left in {}",
            dir.display()
        ));
    }
    Ok(held)
}

/// Commit, dirty flag, profile and features: `--resume` only continues the same build.
fn build_id(environment: &Environment) -> String {
    format!(
        "{}{}-{}-[{}]",
        environment.git_commit,
        if environment.git_dirty { "-dirty" } else { "" },
        environment.profile,
        environment.features
    )
}

/// Says which configurations are oversubscribed and which place their disks slowly.
fn note_configurations(
    configurations: &[&Configuration],
    environment: &Environment,
    note: &dyn Fn(&str),
) {
    for configuration in configurations {
        let workers = configuration.placement().workers();
        if configuration.backend.is_parallel() && workers > environment.usable_cpus {
            note(&format!(
                "note: {} is oversubscribed ({} workers on the {} CPUs this study may use); \
                 its rows say so",
                configuration.key(),
                workers,
                environment.usable_cpus
            ));
        }
    }
    for configuration in configurations {
        if let Some(placement) = crate::run::limits::placement_note(&configuration.footprint) {
            note(&format!("{placement} ({}, every run)", configuration.key()));
        }
    }
}

/// The study's progress bar: runs done of all, and the time left as the disk-steps
/// (disks × steps) still to run at the rate of those run so far, so that a run of 10⁶
/// disks weighs a thousand times one of 10³ (hidden when quiet).
struct Progress {
    bar: ProgressBar,
    runs: u64,
    done: std::cell::Cell<u64>,
}

impl Progress {
    /// A bar over `runs` ((count, disk-steps of each) pairs), each run by `programs`
    /// programs.
    fn new(quiet: bool, runs: impl Iterator<Item = (u64, u64)>, programs: u64) -> Progress {
        let (count, disk_steps) = runs.fold((0, 0u64), |(count, total), (runs, size)| {
            (
                count + runs,
                total.saturating_add(runs.saturating_mul(size)),
            )
        });
        let bar = match quiet {
            true => ProgressBar::hidden(),
            false => ProgressBar::new(disk_steps.saturating_mul(programs)),
        };
        bar.set_style(
            ProgressStyle::with_template("{bar:30} {prefix}, {elapsed} gone, ~{eta} left  {msg}")
                .expect("a valid progress template"),
        );
        let progress = Progress {
            bar,
            runs: count * programs,
            done: std::cell::Cell::new(0),
        };
        progress.show_count();
        progress
    }

    /// One more run done, of `disk_steps`.
    fn ran(&self, disk_steps: u64) {
        self.done.set(self.done.get() + 1);
        self.show_count();
        self.bar.inc(disk_steps);
    }

    fn show_count(&self) {
        (self.bar).set_prefix(format!("{}/{} runs", self.done.get(), self.runs));
    }
}

/// Records the load average at the study's end in the rows measured now (from
/// `measured_from` on) and writes every row.
fn record_load_at_end(
    results: &Path,
    rows: &mut [Record],
    measured_from: usize,
) -> anyhow::Result<()> {
    let end = crate::study::environment::load_average();
    for row in rows.iter_mut().skip(measured_from) {
        row.load_average_end = end;
    }
    let _writing = interrupt_note();
    records::write(results, rows)
}

/// The row of one run from how its process ended: measured if it exited 0 with a
/// summary on its last line; failed otherwise, keeping why and the end of its output.
fn record_of(
    context: &RecordContext<'_>,
    ended: std::io::Result<Ended>,
    timeout: Duration,
) -> Record {
    match ended {
        Err(e) => Record::failed(context, STATUS_FAILED, format!("cannot start collide: {e}")),
        Ok(Ended::TimedOut { stderr }) => Record::failed(
            context,
            STATUS_TIMED_OUT,
            format!(
                "killed after {} s{}",
                timeout.as_secs_f64(),
                tail("its output", &stderr)
            ),
        ),
        Ok(Ended::Exited {
            status,
            stdout,
            stderr,
        }) => match (status.success(), RunSummary::from_last_line(&stdout)) {
            (true, Ok(summary)) => Record::measured(context, &summary),
            (true, Err(e)) => Record::failed(
                context,
                STATUS_FAILED,
                format!(
                    "it exited 0 but printed no summary on its last line ({e}){}{}",
                    tail("its output", &stdout),
                    tail("its error output", &stderr)
                ),
            ),
            (false, _) => Record::failed(
                context,
                STATUS_FAILED,
                format!("{status}{}", tail("its output", &stderr)),
            ),
        },
    }
}

/// What `collide calibrate` prints: one JSON object, the wall and CPU seconds of the
/// calibration workload of `collide check`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
pub struct Calibration {
    /// Wall seconds.
    pub calibration_s: f64,
    /// CPU seconds; null where unknown.
    pub calibration_cpu_s: Option<f64>,
}

/// How to get MPI support into a build without the `mpi` feature (completes "to run
/// them, ...").
pub const ENABLE_MPI: &str = "install OpenMPI and libclang (`sudo apt-get install libopenmpi-dev \
     openmpi-bin libclang-dev`) and add `--features mpi` to the cargo command";

/// The configurations this build can run: without the `mpi` feature the MPI ones are
/// skipped with a one-line warning, and a study left with nothing to run is an error.
fn runnable(study: &Study) -> anyhow::Result<Vec<&Configuration>> {
    let mut configurations: Vec<&Configuration> = study.configurations.iter().collect();
    let before = configurations.len();
    configurations.retain(|c| c.backend.is_available());
    let skipped = before - configurations.len();
    if configurations.is_empty() {
        bail!(
            "{}: every configuration uses the MPI backend, and this collide was built without \
             MPI, so nothing was run or written; {ENABLE_MPI}, or list other backends under \
             `[backends]` (`serial = true`, `rayon = [1, 2]`)",
            study.manifest.display()
        );
    }
    if skipped > 0 {
        // Not a progress note: the study measures less than its manifest asks.
        eprintln!(
            "warning: skipping {skipped} MPI configuration(s), as this collide was built \
             without MPI; to run them, {ENABLE_MPI}"
        );
    }
    Ok(configurations)
}

/// xxh3 of a text, in hex: a manifest's as recorded in `manifest_hash`, a scene's in
/// `scene_hash`.
pub fn text_hash(text: &str) -> String {
    format!("{:016x}", xxhash_rust::xxh3::xxh3_64(text.as_bytes()))
}

/// Holds the study folder `dir` for this process until the file returned is dropped (or
/// the process ends, however it ends): a second study into the same folder waits, so
/// studies never share the machine's cores nor a results file.
fn hold_folder(dir: &Path) -> anyhow::Result<File> {
    let folder = File::open(dir)
        .with_context(|| format!("cannot open the results folder {}", dir.display()))?;
    match folder.try_lock() {
        Ok(()) => {}
        Err(TryLockError::WouldBlock) => {
            eprintln!(
                "waiting: another collide run is writing into {}; this study starts when it ends (Ctrl-C stops waiting)",
                dir.display()
            );
            folder
                .lock()
                .with_context(|| format!("cannot lock the results folder {}", dir.display()))?;
        }
        // Some network file systems cannot lock: results files stay apart by name.
        Err(TryLockError::Error(err)) => eprintln!(
            "warning: cannot lock the results folder {} ({}); do not run two studies into it at once",
            dir.display(),
            crate::system::output::io_reason(&err)
        ),
    }
    Ok(folder)
}

/// The command that continues a study: `collide run MANIFEST [--out OUT] --resume`.
pub fn resume_command(manifest: &Path, out: &Path) -> String {
    let word = |path: &Path| {
        let text = path.display().to_string();
        if text
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./".contains(c))
        {
            text
        } else {
            format!("'{}'", text.replace('\'', r"'\''"))
        }
    };
    let out = if out == Path::new("results") {
        String::new()
    } else {
        format!(" --out {}", word(out))
    };
    format!("collide run {}{out} --resume", word(manifest))
}

/// `<dir>/<UTC timestamp>-<host>-<commit>.parquet`, or with `-2`, `-3`, ... before
/// `.parquet` when a study started in the same second already took that name (the
/// caller holds the folder, so no other study is choosing at the same time).
fn new_results_path(dir: &Path, environment: &Environment) -> PathBuf {
    let stamp: String = records::utc_now()
        .chars()
        .filter(|c| c.is_ascii_alphanumeric())
        .collect();
    let host: String = environment
        .hostname
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    free_path(
        dir,
        &format!("{stamp}-{host}-{}", environment.git_commit),
        "parquet",
    )
}

/// The results file in `dir` last written by the same build, with its rows; files that
/// cannot be read are passed over with a warning naming them.
fn resumable(dir: &Path, build_id: &str) -> anyhow::Result<Option<(PathBuf, Vec<Record>)>> {
    let mut files = records::files_in(dir)?;
    // Last written first; names (oldest first) break ties, e.g. two studies in one second.
    let modified = |path: &PathBuf| std::fs::metadata(path).and_then(|m| m.modified()).ok();
    files.sort_by(|a, b| modified(b).cmp(&modified(a)).then_with(|| b.cmp(a)));
    for path in files {
        let rows = match records::read(&path) {
            Ok(rows) => rows,
            Err(err) => {
                eprintln!("warning: not resuming from {}: {err:#}", path.display());
                continue;
            }
        };
        if rows.first().is_some_and(|r| r.build_id == build_id) {
            return Ok(Some((path, rows)));
        }
    }
    Ok(None)
}

/// xxh3 of the scene's text: the file's as it is now, or the inline scene's.
fn scene_hash(input: &SceneInput) -> anyhow::Result<String> {
    let text = match input {
        SceneInput::File(path) => read_text(path, MAX_TEXT_BYTES)
            .map_err(|reason| anyhow!("cannot read scene file {}: {reason}", path.display()))?,
        SceneInput::Inline(text) => text.clone(),
    };
    Ok(text_hash(&text))
}

/// The scene file each configuration's process reads: its own file, or its inline scene
/// written to `<dir>/scenes/<scene>-<scene_hash>.toml`, kept beside the results it
/// produced. The name holds the contents' hash, so a copy that rows refer to is never
/// replaced by another manifest's scene of the same name.
pub fn materialize_scenes(
    dir: &Path,
    configurations: &[&Configuration],
) -> anyhow::Result<Vec<PathBuf>> {
    let scenes = dir.join("scenes");
    configurations
        .iter()
        .map(|configuration| match &configuration.input {
            SceneInput::File(path) => Ok(path.clone()),
            SceneInput::Inline(text) => {
                std::fs::create_dir_all(&scenes)
                    .with_context(|| format!("cannot create {}", scenes.display()))?;
                let hash = scene_hash(&configuration.input)?;
                let path = scenes.join(format!("{}-{hash}.toml", configuration.scene));
                if !path.exists() {
                    write_atomically(&path, |out| out.write_all(text.as_bytes()))?;
                }
                Ok(path)
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use std::os::unix::process::ExitStatusExt;
    use std::process::ExitStatus;

    use super::*;

    #[test]
    fn a_run_that_exits_0_without_a_summary_keeps_the_reason_and_what_it_printed() {
        let environment = Environment::capture();
        let context = records::serial_context(&environment);
        let ended = |code: i32, stdout: &str| Ended::Exited {
            status: ExitStatus::from_raw(code << 8),
            stdout: stdout.to_owned(),
            stderr: "a warning\n".to_owned(),
        };
        let timeout = Duration::from_secs(1);
        let quiet = record_of(&context, Ok(ended(0, "step 10\nall done\n")), timeout);
        assert_eq!(quiet.status, STATUS_FAILED);
        for fragment in ["exited 0", "no summary", "all done", "a warning"] {
            assert!(
                quiet.error.contains(fragment),
                "{fragment}: {}",
                quiet.error
            );
        }
        let failed = record_of(&context, Ok(ended(3, "")), timeout);
        assert!(failed.error.contains("exit status: 3") && failed.error.contains("a warning"));
    }

    #[test]
    fn programs_take_turns_to_run_first_and_slowdowns_stay_in_their_backend() {
        let program = |side| Program {
            side,
            exe: PathBuf::from(side),
            commit: None,
            slowdown: Slowdown::default(),
        };
        let programs = [program("A"), program("B")];
        let sides = |rep, c| -> Vec<&str> {
            run_order(&programs, rep, c)
                .iter()
                .map(|p| p.side)
                .collect()
        };
        assert_eq!(sides(0, 0), ["A", "B"]);
        assert_eq!(sides(1, 0), ["B", "A"]);
        assert_eq!(sides(2, 0), ["A", "B"]);
        assert_eq!(sides(0, 1), ["B", "A"]);
        let rayon = Slowdown {
            fraction: 0.05,
            into: Some(BackendKind::Rayon),
        };
        assert_eq!(
            rayon.simulate_args(BackendKind::Rayon),
            ["--inject-slowdown", "0.05"]
        );
        assert!(rayon.simulate_args(BackendKind::Serial).is_empty());
        let everywhere = Slowdown {
            into: None,
            ..rayon
        };
        assert_eq!(everywhere.simulate_args(BackendKind::Mpi).len(), 2);
        assert!(
            Slowdown::default()
                .simulate_args(BackendKind::Serial)
                .is_empty()
        );
    }
}
