//! `collide report`: a study's records as a markdown report in the shape of the seed's
//! results (its Cuadro 1, speedup, efficiency, FPS), with the environment, warnings and
//! findings drawn from the data, linking the figures drawn beside it (`figures`); and
//! the check history's report (its verdicts over commits).

use std::fmt::Write as _;
use std::path::Path;

use crate::report::accuracy::{
    AccuracyPoint, Breakdown, CoolingCurve, FAILURE_MISSED_FRACTION, FLAG_WALL_PENETRATION,
    HAFF_BREAKDOWN, PackingGroup, method_label,
};
use crate::report::analysis::{Baseline, MIN_WORKER_COUNTS, Setup, TIMING_CONFIDENCE, TOO_SHORT_S};
use crate::report::figures::cooling::COOLING_FILE;
use crate::report::figures::history::{HISTORY_FILE, checks};
use crate::report::figures::scaling::Figure;
use crate::report::units::{TimeUnit, duration, significant};
use crate::run::backend_kind::BackendKind;
use crate::study::history::Entry;
use crate::study::manifest::Scaling;
use crate::study::records::{Record, STATUS_OK};
use crate::study::replicas::{self, DISAGREEMENT, OBSERVABLES, ReplicaGroup};

/// The seed report's Cuadro 1: 1000 disks, 400 cycles.
const SEED_N: u64 = 1000;
const SEED_STEPS: u64 = 400;
const SEED_SERIAL_S: f64 = 33.8;
const SEED_MPI_12_S: f64 = 2.16;
/// Parallel efficiency below this is called out in the findings.
const EFFICIENCY_FLOOR: f64 = 0.75;
/// Repetitions whose max/min time exceeds this are called noisy.
const NOISY_SPREAD: f64 = 1.5;

/// What a report shows besides the records: where they came from and its pictures.
#[derive(Clone, Debug, Default)]
pub struct Pictures {
    /// `figures[i]`: the PNG files (relative to the report) of setup i.
    pub figures: Vec<Vec<(Figure, String)>>,
    /// A picture of the scene (`collide render --png`), if one lies beside the report.
    pub scene: Option<String>,
    /// An accuracy study's analysis and its figures (relative to the report).
    pub accuracy: Option<AccuracySection>,
}

/// What the accuracy section shows ([`crate::report::accuracy::analyse`], `figures`).
#[derive(Clone, Debug, Default)]
pub struct AccuracySection {
    pub groups: Vec<PackingGroup>,
    /// The speed-vs-accuracy and stability figures.
    pub figures: Vec<String>,
    /// The e < 1 runs' cooling curves (empty for elastic studies); drawn as
    /// [`COOLING_FILE`] beside the report.
    pub cooling: Vec<CoolingCurve>,
}

/// The report of one study's records, analysed into `setups` ([`crate::report::analysis::analyse`]);
/// `source` names where they were read from.
pub fn markdown(records: &[Record], setups: &[Setup], source: &str, pictures: &Pictures) -> String {
    let mut out = String::new();
    let Some(first) = records.first() else {
        return "# Empty study\n\nNo records.\n".to_owned();
    };
    // A study of one backend at one worker count per setup (an accuracy study) has no
    // scaling to report: its timings are in the accuracy tables.
    let scales = setups.iter().any(Setup::scales);
    let accuracy_only = pictures.accuracy.is_some() && !scales;
    let kind = if accuracy_only { "Accuracy" } else { "Scaling" };
    let _ = writeln!(out, "# {kind} report: study `{}`\n", first.study);
    let _ = writeln!(
        out,
        "Regenerate with `collide run experiments/{}.toml`, then {}.\n",
        first.study,
        inline_code(&format!("collide report {source}"))
    );
    if let Some(scene) = &pictures.scene {
        let _ = writeln!(
            out,
            "The scene picture comes from `collide render SCENE --png {scene}` in the report's folder.\n"
        );
        let _ = writeln!(
            out,
            "![The scene: disks to scale, coloured by speed from blue (at rest) to red (twice the rms speed)]({scene})\n"
        );
    }
    environment(&mut out, first, records);
    warnings(&mut out, records, setups);
    let groups: Vec<ReplicaGroup> = replicas::checks(records)
        .into_iter()
        .map(|(_, group)| group)
        .collect();
    replica_warnings(&mut out, &groups);
    replica_section(&mut out, &groups);
    if let Some(section) = &pictures.accuracy {
        accuracy_section(&mut out, section);
    }
    if accuracy_only {
        return out;
    }
    for (index, setup) in setups.iter().enumerate() {
        setup_section(&mut out, setup);
        for (figure, file) in pictures.figures.get(index).into_iter().flatten() {
            let _ = writeln!(out, "![{}]({file})\n", figure.file_stem());
        }
    }
    findings(&mut out, setups);
    out
}

fn environment(out: &mut String, first: &Record, records: &[Record]) {
    let ok = records.iter().filter(|r| r.status == STATUS_OK).count();
    let dirty = if first.git_dirty {
        " (uncommitted changes)"
    } else {
        ""
    };
    let _ = writeln!(out, "## Environment\n");
    let _ = writeln!(out, "| | |\n| --- | --- |");
    let usable = match usable_cpus(first) {
        cpus if cpus == first.logical_cores => String::new(),
        cpus => format!("; the study could use {cpus}: {}", first.cpu_affinity),
    };
    let _ = writeln!(
        out,
        "| CPU | {} ({} logical, {} physical cores{usable}) |",
        first.cpu_model, first.logical_cores, first.physical_cores
    );
    let _ = writeln!(
        out,
        "| Memory | {:.1} GiB |",
        first.memory_bytes as f64 / (1u64 << 30) as f64
    );
    let _ = writeln!(out, "| OS | {} |", first.os);
    let _ = writeln!(out, "| Host | {} |", first.hostname);
    let _ = writeln!(
        out,
        "| Build | {}, {} profile, features [{}] |",
        first.rustc, first.profile, first.features
    );
    let _ = writeln!(out, "| Commit | `{}`{dirty} |", first.git_commit);
    let _ = writeln!(out, "| MPI | {} |", first.mpi_library);
    let _ = writeln!(out, "| Started | {} |", first.study_started_utc);
    // The machine's other work distorts timings: say how busy it was.
    let busiest = peak_load_average(records);
    let _ = writeln!(
        out,
        "| Load | 1-minute load average {:.2} at the start, at most {:.2} after a run, {} at the end |",
        first.load_average_start,
        busiest,
        if first.load_average_end.is_finite() {
            format!("{:.2}", first.load_average_end)
        } else {
            "not recorded (the study did not finish)".to_owned()
        }
    );
    let _ = writeln!(
        out,
        "| Runs | {ok} measured, {} failed |\n",
        records.len() - ok
    );
}

fn warnings(out: &mut String, records: &[Record], setups: &[Setup]) {
    let mut oversubscribed: Vec<String> = records
        .iter()
        .filter(|r| r.oversubscribed && r.status == STATUS_OK)
        .map(Record::placement_label)
        .collect();
    oversubscribed.sort();
    oversubscribed.dedup();
    if !oversubscribed.is_empty() {
        let _ = writeln!(
            out,
            "> **Warning: oversubscribed.** More workers than the {} CPUs the study could use: \
             {}. Their times measure contention, not scaling.\n",
            usable_cpus(&records[0]),
            oversubscribed.join(", ")
        );
    }
    for setup in setups.iter().filter(|s| s.distinct_hashes > 1) {
        let _ = writeln!(
            out,
            "> **Warning: backends disagree.** {} distinct final states (`state_hash`) for {}; \
             speedups compare different computations.\n",
            setup.distinct_hashes,
            describe(setup)
        );
    }
    noise_warning(out, records, setups);
    choice_note(out, records);
    let failed = records.iter().filter(|r| r.status != STATUS_OK).count();
    if failed > 0 {
        let _ = writeln!(
            out,
            "> **Warning: {failed} run(s) failed or timed out**; they are left out of every figure below.\n"
        );
    }
}

/// Calls out each observable whose spread over seeds disagrees with the runs' own
/// error bars by more than [`DISAGREEMENT`]× ([`replicas`]).
fn replica_warnings(out: &mut String, groups: &[ReplicaGroup]) {
    for group in groups {
        for (observable, check) in OBSERVABLES.iter().zip(&group.checks) {
            if !check.disagrees() {
                continue;
            }
            let ratio = check.ratio();
            let meaning = match ratio > DISAGREEMENT {
                true => {
                    "the runs' blocked error bars are too small (correlations longer than \
                         their blocks): trust the replica SE, or run longer"
                }
                false => {
                    "the seeds agree better than their error bars say (with few seeds \
                          the replica SE is itself uncertain): add seeds before trusting \
                          either"
                }
            };
            let _ = writeln!(
                out,
                "> **Warning: error bars disagree with the spread over seeds.** {} of {} \
                 over {} seeds: replica SE {}, {}× the within-run SE {}; {meaning}.\n",
                observable.name,
                group.label,
                group.seeds.len(),
                significant(check.replica.se, 3),
                significant(ratio, 2),
                significant(check.within_se, 3),
            );
        }
    }
}

/// The observables of each setup run with several seeds: their replica mean, its
/// standard error and 95% interval, beside the within-run error ([`replicas`]).
fn replica_section(out: &mut String, groups: &[ReplicaGroup]) {
    if groups.is_empty() {
        return;
    }
    let _ = writeln!(out, "## Replicas: the spread over seeds\n");
    let _ = writeln!(
        out,
        "Runs of one setup that differ only in their seed are independent measurements. The \
         replica SE is the standard deviation of the seeds' means over √R, the 95% interval \
         Student's t with R − 1 degrees of freedom; the within-run SE, √(Σ SE_r²)/R, is what \
         the runs' own blocked error bars say of the same mean. Only runs that equilibrated \
         count. A ratio beyond {DISAGREEMENT}× either way is **bold**.\n"
    );
    let _ = writeln!(
        out,
        "| setup | seeds | observable | replica mean ± SE | 95% | within-run SE | ratio |\n\
         | --- | --- | --- | ---: | ---: | ---: | ---: |"
    );
    for group in groups {
        let seeds: Vec<String> = group.seeds.iter().map(u64::to_string).collect();
        for (observable, check) in OBSERVABLES.iter().zip(&group.checks) {
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} ± {} | ± {} | {} | {} |",
                group.label,
                seeds.join(", "),
                observable.name,
                significant(check.replica.mean, 6),
                significant(check.replica.se, 3),
                significant(check.replica.half_width_95, 3),
                significant(check.within_se, 3),
                bold_if(check.disagrees(), significant(check.ratio(), 2)),
            );
        }
    }
    let _ = writeln!(out);
}

/// The CPUs a study could run on; the machine's logical cores in files that did not
/// record them.
fn usable_cpus(record: &Record) -> u64 {
    record.usable_cpus.unwrap_or(record.logical_cores)
}

/// The highest 1-minute load average recorded after a run (NaN if none was).
fn peak_load_average(records: &[Record]) -> f64 {
    records
        .iter()
        .map(|r| r.load_average)
        .filter(|l| l.is_finite())
        .fold(f64::NAN, f64::max)
}

/// Calls out a study measured on a busy machine: a load average above the core count
/// during the runs, or repetitions whose slowest took much longer than the fastest.
fn noise_warning(out: &mut String, records: &[Record], setups: &[Setup]) {
    let cores = records[0].logical_cores as f64;
    let busiest = peak_load_average(records);
    let mut spread: Vec<String> = setups
        .iter()
        .flat_map(|setup| {
            setup.backends.iter().flat_map(move |b| {
                b.points
                    .iter()
                    .filter(|p| p.reps > 1 && p.max_s > NOISY_SPREAD * p.min_s)
                    .map(move |p| {
                        format!(
                            "{} × {} (n = {}, packing {:.3})",
                            b.label(),
                            p.workers,
                            setup.n,
                            setup.packing
                        )
                    })
            })
        })
        .collect();
    // Setups that differ only in what this list does not name (dt, method) appear once.
    let mut seen = std::collections::HashSet::new();
    spread.retain(|label| seen.insert(label.clone()));
    if busiest > cores || !spread.is_empty() {
        let spread = if spread.is_empty() {
            String::new()
        } else {
            format!(
                " The slowest repetition took over {NOISY_SPREAD}× the fastest for {}.",
                spread.join(", ")
            )
        };
        let _ = writeln!(
            out,
            "> **Warning: noisy measurements.** The 1-minute load average reached {busiest:.2} \
             on {cores} logical cores during the study.{spread} Medians resist some of this, \
             but speedups here are uncertain; re-run on a quiet machine to confirm them.\n"
        );
    }
}

/// Says what `method = "auto"` / `dt = "auto"` chose, once per scene and choice.
fn choice_note(out: &mut String, records: &[Record]) {
    let mut choices: Vec<(&str, &str)> = records
        .iter()
        .filter(|r| r.status == STATUS_OK && !r.choice.is_empty())
        .map(|r| (r.scene.as_str(), r.choice.as_str()))
        .collect();
    choices.sort_unstable();
    choices.dedup();
    for (scene, choice) in choices {
        let _ = writeln!(
            out,
            "> **Chosen automatically** for scene `{scene}` (`method`/`dt = \"auto\"`): {choice}.\n"
        );
    }
}

/// `text` in markdown bold when `bold`.
fn bold_if(bold: bool, text: String) -> String {
    if bold { format!("**{text}**") } else { text }
}

/// One line naming a setup: scene, n, steps, dt, packing, broad phase.
pub fn describe(setup: &Setup) -> String {
    let n = match setup.scaling {
        Scaling::Strong => format!("n = {}", setup.n),
        Scaling::Weak => format!("weak scaling, n = {} × workers", setup.n),
    };
    let drawn = if setup.drawn {
        ", every step drawn offscreen"
    } else {
        ""
    };
    let settings = match setup.settings.is_empty() {
        true => String::new(),
        false => format!(", {}", setup.settings.join(", ")),
    };
    format!(
        "scene `{}`, {n}, {} steps of dt = {}, packing {:.3}, {} broad phase{settings}{drawn}",
        setup.scene, setup.steps, setup.dt, setup.packing, setup.broadphase
    )
}

fn setup_section(out: &mut String, setup: &Setup) {
    let _ = writeln!(out, "## {}\n", describe(setup));
    if setup.distinct_hashes == 1 {
        let _ = writeln!(
            out,
            "Every run ended in the same state (one `state_hash`).\n"
        );
    }
    seconds_table(out, setup);
    speedup_table(out, setup);
}

/// The seed's Cuadro 1: workers × median time per run of each backend, each backend's
/// column in the unit that fits its fastest time.
fn seconds_table(out: &mut String, setup: &Setup) {
    let workers = setup.worker_counts();
    let units: Vec<TimeUnit> = (setup.backends.iter())
        .map(|b| TimeUnit::for_column(b.points.iter().map(|p| p.min_s)))
        .collect();
    let _ = writeln!(out, "### Time per run (the seed's Cuadro 1)\n");
    let _ = write!(out, "| workers |");
    for (backend, unit) in setup.backends.iter().zip(&units) {
        let _ = write!(out, " {} [{}] |", backend.label(), unit.symbol());
    }
    let _ = write!(out, "\n| ---: |");
    for _ in &setup.backends {
        let _ = write!(out, " ---: |");
    }
    let _ = writeln!(out);
    for &p in &workers {
        let _ = write!(out, "| {p} |");
        for (backend, unit) in setup.backends.iter().zip(&units) {
            match backend.points.iter().find(|point| point.workers == p) {
                Some(point) => {
                    let _ = write!(
                        out,
                        " {} [{}, {}] ({}–{}, {} runs){}{} |",
                        unit.number(point.median_s),
                        unit.number(point.median_ci_s[0]),
                        unit.number(point.median_ci_s[1]),
                        unit.number(point.min_s),
                        unit.number(point.max_s),
                        point.reps,
                        if point.oversubscribed { " ⚠" } else { "" },
                        if point.too_short() { " ⏱" } else { "" }
                    );
                }
                None => {
                    let _ = write!(out, " |");
                }
            }
        }
        let _ = writeln!(out);
    }
    let _ = writeln!(
        out,
        "\nMedian of the repetitions with its {:.0}% bootstrap interval (seeded) in brackets, \
         and their min–max, in the unit its column names; ⚠ marks oversubscribed runs, ⏱ a \
         median under {:.0} ms of stepping, too short to time well: run more steps.\n",
        100.0 * TIMING_CONFIDENCE,
        1e3 * TOO_SHORT_S
    );
}

/// Speedup, efficiency, Karp–Flatt and steps per second of every backend and worker
/// count, what each speedup is against, and the Amdahl fits.
fn speedup_table(out: &mut String, setup: &Setup) {
    let _ = writeln!(out, "### Speedup, efficiency and FPS\n");
    speedup_baselines(out, setup);
    // What the busiest rank sent, beside the timings, where any MPI run counted it.
    let sent =
        (setup.backends.iter()).any(|b| b.points.iter().any(|p| p.messages_per_step.is_finite()));
    speedup_rows(out, setup, sent);
    // A blank line ends the table, whatever follows it.
    let _ = writeln!(out);
    speedup_notes(out, setup, sent);
}

/// What each backend's speedup is measured against, and for weak scaling what the
/// measures mean.
fn speedup_baselines(out: &mut String, setup: &Setup) {
    if setup.scaling == Scaling::Weak {
        let _ = writeln!(
            out,
            "Weak scaling: each worker has {} disks, so the ideal time stays that of one worker. \
             Efficiency is E(p) = T(1, N₀)/T(p, p·N₀); speedup is the scaled speedup p·E(p) \
             (Gustafson); Karp–Flatt and Amdahl's law describe strong scaling and are not \
             given.\n",
            setup.n
        );
    }
    for backend in &setup.backends {
        let baseline = match backend.baseline {
            Baseline::Serial(t) => format!("the serial backend ({})", duration(t)),
            Baseline::OneWorker(t) => format!("{} at 1 worker ({})", backend.backend, duration(t)),
            Baseline::Missing => "nothing (no serial or 1-worker run)".to_owned(),
        };
        let _ = writeln!(
            out,
            "- **{}**: speedup against {baseline}.",
            backend.label()
        );
    }
}

/// The table: one row per backend and worker count, with frames/s with drawing and
/// the busiest rank's messages where the runs have them (`sent`).
fn speedup_rows(out: &mut String, setup: &Setup, sent: bool) {
    let (drawn_header, drawn_rule) = if setup.drawn {
        (" frames/s with drawing |", " ---: |")
    } else {
        ("", "")
    };
    let (sent_header, sent_rule) = if sent {
        (" messages/step | KiB/step |", " ---: | ---: |")
    } else {
        ("", "")
    };
    let _ = writeln!(
        out,
        "\n| backend | workers | speedup S(p) | efficiency E(p) | Karp–Flatt e(p) | steps/s |{drawn_header}{sent_header}\n| --- | ---: | ---: | ---: | ---: | ---: |{drawn_rule}{sent_rule}"
    );
    for backend in &setup.backends {
        for point in &backend.points {
            let karp_flatt = finite_or_dash(point.karp_flatt, format!("{:.3}", point.karp_flatt));
            let drawn = if setup.drawn {
                format!(" {:.0} |", point.fps_with_drawing)
            } else {
                String::new()
            };
            let sent = if sent {
                let (messages, bytes) = (point.messages_per_step, point.bytes_per_step);
                format!(
                    " {} | {} |",
                    finite_or_dash(messages, format!("{messages:.1}")),
                    finite_or_dash(bytes, format!("{:.1}", bytes / 1024.0))
                )
            } else {
                String::new()
            };
            let _ = writeln!(
                out,
                "| {} | {} | {:.2} | {:.0}% | {karp_flatt} | {:.0} |{drawn}{sent}",
                backend.label(),
                point.workers,
                point.speedup,
                100.0 * point.efficiency,
                point.fps
            );
        }
    }
}

/// What the optional columns count, and the Amdahl fits.
fn speedup_notes(out: &mut String, setup: &Setup, sent: bool) {
    if sent {
        let _ = writeln!(
            out,
            "Messages/step and KiB/step: what the MPI rank that sent most sent per step of \
             the stepping loop (median of the repetitions), counted as MPI's algorithms \
             send them (see `messages_per_step_max` in docs/records.md).\n"
        );
    }
    if setup.drawn {
        let _ = writeln!(
            out,
            "Every step of these runs was drawn offscreen, whole box at 800 × 800 pixels with \
             the live view's renderer: steps/s counts the stepping alone, frames/s with drawing \
             also the snapshot and the drawing of each step (the seed's Figure 5: the \
             `fps-drawing` figure).\n"
        );
    }
    let fits: Vec<String> = setup
        .backends
        .iter()
        .filter_map(|b| {
            b.amdahl.as_ref().ok().map(|fit| {
                let residuals: Vec<String> = fit
                    .residuals
                    .iter()
                    .map(|(p, r)| format!("{p}: {:+.1}%", 100.0 * r))
                    .collect();
                format!(
                    "{}: f = {:.3} (R² = {:.3}; residuals {})",
                    b.label(),
                    fit.serial_fraction,
                    fit.r_squared,
                    residuals.join(", ")
                )
            })
        })
        .collect();
    if !fits.is_empty() {
        let _ = writeln!(
            out,
            "Amdahl fit T(p) = T₁·(f + (1 − f)/p), least squares on the medians: {}. An R² \
             far below 1, or residuals beyond the runs' spread, means Amdahl's law does not \
             describe these times (oversubscription, communication that grows with p).\n",
            fits.join("; ")
        );
    }
    // Where a fit could be asked for (a parallel backend at several worker counts), why not.
    let not_shown: Vec<String> = setup
        .backends
        .iter()
        .filter(|b| b.points.len() > 1)
        .filter_map(|b| {
            b.amdahl
                .as_ref()
                .err()
                .map(|why| format!("{}: {}", b.label(), why.reason()))
        })
        .collect();
    if !not_shown.is_empty() {
        let _ = writeln!(
            out,
            "No serial fraction (Amdahl or Karp–Flatt) is shown for {}. Karp–Flatt e(p) is \
             shown only for a backend with at least {MIN_WORKER_COUNTS} worker counts and where \
             it lies within [0, 1].\n",
            not_shown.join("; ")
        );
    }
}

fn findings(out: &mut String, setups: &[Setup]) {
    let _ = writeln!(out, "## Findings\n");
    for setup in setups {
        let all = setup
            .backends
            .iter()
            .flat_map(|b| b.points.iter().map(move |p| (b.label(), p)));
        if let Some((backend, best)) = all
            .clone()
            .min_by(|a, b| a.1.median_s.total_cmp(&b.1.median_s))
        {
            let _ = writeln!(
                out,
                "- {}: fastest is {backend} with {} worker(s), median {} ({:.0} steps/s).",
                describe(setup),
                best.workers,
                duration(best.median_s),
                best.fps
            );
        }
        for backend in &setup.backends {
            let low: Vec<String> = backend
                .points
                .iter()
                .filter(|p| p.workers > 1 && p.efficiency < EFFICIENCY_FLOOR)
                .map(|p| format!("{} workers ({:.0}%)", p.workers, 100.0 * p.efficiency))
                .collect();
            if !low.is_empty() {
                let _ = writeln!(
                    out,
                    "- {} efficiency falls below {:.0}% at {}.",
                    backend.label(),
                    100.0 * EFFICIENCY_FLOOR,
                    low.join(", ")
                );
            }
        }
        if setup.n == SEED_N && setup.steps == SEED_STEPS {
            let serial = setup
                .backends
                .iter()
                .find(|b| b.backend == BackendKind::Serial.name())
                .and_then(|b| b.points.first());
            let mpi_12 = setup
                .backends
                .iter()
                .find(|b| b.backend == BackendKind::Mpi.name())
                .and_then(|b| b.points.iter().find(|p| p.workers == 12));
            if let Some(serial) = serial {
                let _ = writeln!(
                    out,
                    "- Against the seed report (1000 disks, 400 cycles): serial {} here against \
                     its {SEED_SERIAL_S} s, {:.0}× faster.",
                    duration(serial.median_s),
                    SEED_SERIAL_S / serial.median_s
                );
            }
            if let Some(mpi) = mpi_12 {
                let _ = writeln!(
                    out,
                    "- MPI with 12 ranks: {} here against the seed's {SEED_MPI_12_S} s{}.",
                    duration(mpi.median_s),
                    if mpi.oversubscribed {
                        " (oversubscribed here, so not a scaling measurement)"
                    } else {
                        ""
                    }
                );
            }
        }
    }
}

fn accuracy_section(out: &mut String, section: &AccuracySection) {
    let _ = writeln!(
        out,
        "## Accuracy: the step method against the event-driven reference
"
    );
    let _ = writeln!(
        out,
        "Each row is the median of its repetitions. Errors of the pressure (Z = P·A/(N·T)) and \
         of the collision rate ω are relative to the event method at the same packing and \
         the same initial state; a step fails (**bold**) when it misses more than \
         {FAILURE_MISSED_FRACTION:e} of its collisions; a wall penetration is **bold** above \
         {FLAG_WALL_PENETRATION} of the radius. Speed is simulated time per wall \
         second (every run simulates the same time, so it compares methods at equal \
         physics); particle-steps/s counts each method's own steps. ΔE/E is the change of \
         an elastic scene's energy over the run (kinetic plus potential under gravity): \
         0 up to rounding for the event method, and for the step method without a field.\n"
    );
    for group in &section.groups {
        let _ = writeln!(out, "### Packing {:.2}\n", group.packing);
        let _ = writeln!(
            out,
            "| method | dt | v_rms·dt/r | wall s | sim time / s | particle-steps/s | missed fraction | max overlap | max wall penetration | Z ± SE | Z error | ω | ω error | ΔE/E |\n| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
        );
        if let Some(reference) = &group.reference {
            accuracy_row(out, reference, true);
        }
        for point in group.events.iter().chain(&group.steps) {
            accuracy_row(out, point, false);
        }
        let _ = writeln!(out);
        failure_line(out, group);
    }
    for figure in &section.figures {
        let _ = writeln!(out, "![{figure}]({figure})\n");
    }
    if !section.cooling.is_empty() {
        cooling_section(out, &section.cooling);
    }
}

/// One row of an accuracy table. The event method has no step (exact times), misses
/// nothing and overlaps only by rounding; the reference has no error of its own.
fn accuracy_row(out: &mut String, p: &AccuracyPoint, is_reference: bool) {
    let is_event = p.method == "event";
    let missed = match p.missed_fraction {
        _ if is_event => "0".to_owned(),
        0.0 => "0".to_owned(),
        m => finite_or_dash(m, format!("{m:.2e}")),
    };
    let missed = bold_if(p.failed(), missed);
    let method = match p.collapse_time {
        t if t.is_finite() => format!(
            "{}, **collapsed at t = {t:.4}**",
            method_label(&p.method, p.tc)
        ),
        _ => method_label(&p.method, p.tc),
    };
    let (dt, step, overlap) = if is_event {
        (
            "exact".to_owned(),
            "—".to_owned(),
            format!("{:.1e}", p.max_overlap),
        )
    } else {
        (
            p.dt.to_string(),
            finite_or_dash(p.step_over_radius, format!("{:.3}", p.step_over_radius)),
            format!("{:.3}", p.max_overlap),
        )
    };
    let wall = bold_if(
        p.deep_in_walls(),
        finite_or_dash(
            p.max_wall_penetration,
            format!("{:.3}", p.max_wall_penetration),
        ),
    );
    let error = |value: f64| {
        if is_reference {
            "reference".to_owned()
        } else {
            finite_or_dash(value, format!("{:+.2}%", 100.0 * value))
        }
    };
    // Z with its error bar where the runs equilibrated.
    let z = match p.z_se {
        se if se.is_finite() => format!("{:.4} ± {se:.4}", p.compressibility_z),
        _ => format!("{:.4}", p.compressibility_z),
    };
    let _ = writeln!(
        out,
        "| {method} | {dt} | {step} | {:.4} | {:.1} | {:.3e} | {missed} | {overlap} | {wall} | {z} | {} | {:.4} | {} | {} |",
        p.wall_s,
        p.sim_time_per_s,
        p.particle_steps_per_s,
        error(p.z_error),
        p.collision_rate,
        error(p.rate_error),
        finite_or_dash(p.energy_error, format!("{:+.1e}", p.energy_error)),
    );
}

/// Where the step method starts failing in a group, and its largest passing step.
fn failure_line(out: &mut String, group: &PackingGroup) {
    match group.steps.iter().rev().find(|p| p.failed()) {
        Some(worst_ok) => {
            let largest_ok = group
                .steps
                .iter()
                .find(|p| p.missed_fraction.is_finite() && !p.failed());
            let _ = writeln!(
                out,
                "The step method fails at v_rms·dt/r ≥ {:.3}{}.\n",
                worst_ok.step_over_radius,
                largest_ok.map_or_else(String::new, |p| {
                    let against = match &group.reference {
                        Some(reference) => format!(
                            "Z error {:+.2}%, {:.1}× the event method's speed",
                            100.0 * p.z_error,
                            p.sim_time_per_s / reference.sim_time_per_s
                        ),
                        None => "no event reference to measure its errors against".to_owned(),
                    };
                    format!(
                        "; the largest passing step is v_rms·dt/r = {:.3} ({against})",
                        p.step_over_radius
                    )
                })
            );
        }
        None => {
            let _ = writeln!(out, "No measured step fails here.\n");
        }
    }
}

/// `text`, or a dash where `value` is not finite.
fn finite_or_dash(value: f64, text: String) -> String {
    if value.is_finite() {
        text
    } else {
        "—".to_owned()
    }
}

/// The e < 1 runs against Haff's law: a table saying whether and when each run broke
/// down, and the cooling figure.
fn cooling_section(out: &mut String, curves: &[CoolingCurve]) {
    let _ = writeln!(
        out,
        "## Cooling (e < 1): energy against time and Haff's law\n\n\
         T = kinetic energy per disk, sampled at 40 steps. Haff's law T₀/(1 + t/t₀)² with \
         t₀ fitted to the guarded event run of each packing (least squares on \
         √(T₀/T) − 1 = t/t₀). A run breaks down (**bold**) where its T first departs from \
         the law by more than {:.0}%, or, for the event method, where it detects inelastic \
         collapse (infinitely many collisions in finite time: with the TC guard off, \
         tc = 0, the method itself fails there and the run stops).\n",
        100.0 * HAFF_BREAKDOWN
    );
    let _ = writeln!(
        out,
        "| packing | method | dt | v_rms·dt/r | t_end/t₀ | T_end/T₀ | Haff's T_end/T₀ | max deviation from Haff | TC guard fired | broke down |\n\
         | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |"
    );
    for curve in curves {
        let [t_end, temperature_end] = curve.points[curve.points.len() - 1];
        let t_zero = curve.points[0][1];
        let deviation = format!("{:.2}%", 100.0 * curve.haff_deviation);
        let deviation = bold_if(curve.haff_deviation > HAFF_BREAKDOWN, deviation);
        let t0 = curve.haff_t0;
        let breakdown = match curve.breakdown() {
            None => format!("no (to t/t₀ = {:.3})", t_end / t0),
            Some(Breakdown::Collapse { time }) => {
                format!("**collapsed at t/t₀ = {:.3}** (t = {time:.4})", time / t0)
            }
            Some(Breakdown::OffHaff { time }) => {
                format!(
                    "**off Haff by > {:.0}% from t/t₀ = {:.3}**",
                    100.0 * HAFF_BREAKDOWN,
                    time / t0
                )
            }
        };
        let _ = writeln!(
            out,
            "| {:.2} | {} | {} | {:.3} | {:.3} | {:.4} | {:.4} | {deviation} | {} | {breakdown} |",
            curve.packing,
            method_label(&curve.method, curve.tc),
            curve.dt,
            curve.step_over_radius,
            t_end / t0,
            temperature_end / t_zero,
            curve.haff(t_end) / t_zero,
            curve
                .collapse_guard_fired
                .map_or_else(|| "—".to_owned(), |n| n.to_string()),
        );
    }
    let _ = writeln!(out, "\n![{COOLING_FILE}]({COOLING_FILE})\n");
}

/// `text` (a path the user chose, which may hold anything) as a Markdown code span:
/// control characters escaped, and fenced by more backticks than it holds in a row, so
/// nothing in it is read as Markdown or HTML, nor sent to a terminal as a command.
pub fn inline_code(text: &str) -> String {
    let text: String = text
        .chars()
        .flat_map(|c| match c.is_control() {
            true => c.escape_default().collect::<Vec<_>>(),
            false => vec![c],
        })
        .collect();
    let longest = text.split(|c| c != '`').map(str::len).max().unwrap_or(0);
    let fence = "`".repeat(longest + 1);
    let pad = if text.starts_with('`') || text.ends_with('`') {
        " "
    } else {
        ""
    };
    format!("{fence}{pad}{text}{pad}{fence}")
}

/// The report of a check history (read from `source`): its figure, then one row per
/// verdict, oldest check first.
pub fn history(entries: &[Entry], source: &Path) -> String {
    let mut out = format!(
        "# collide check history\n\nFrom {}: {} verdict(s) of {} check(s). Ratio = this \
         build over what the check compared it with (the build it was checked against in an \
         A/B check, or the baseline), with its 95% interval.\n\n![ratios over commits]({})\n\n\
         | checked (UTC) | commit | compared with | configuration | measure | ratio | 95% interval | verdict |\n\
         | --- | --- | --- | --- | --- | ---: | --- | --- |\n",
        inline_code(&source.display().to_string()),
        entries.len(),
        checks(entries).len(),
        HISTORY_FILE,
    );
    for e in entries {
        let _ = writeln!(
            out,
            "| {} | {}{} | {} | {} | {} | {:.3} | {:.3}–{:.3} | {} |",
            e.checked_utc,
            e.commit,
            if e.dirty { " (dirty)" } else { "" },
            e.against,
            e.what,
            e.measure,
            e.ratio,
            e.lower,
            e.upper,
            match e.verdict.as_str() {
                "regressed" => "**regressed**",
                verdict => verdict,
            }
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::inline_code;

    #[test]
    fn a_path_with_backticks_markup_and_escapes_stays_one_code_span() {
        assert_eq!(inline_code("results/tiny"), "`results/tiny`");
        assert_eq!(inline_code("a`b``c"), "```a`b``c```");
        assert_eq!(inline_code("`x"), "`` `x ``");
        let escaped = inline_code("r/\u{1b}[31m<b>|");
        assert!(!escaped.contains('\u{1b}'), "{escaped}");
        assert_eq!(escaped, "`r/\\u{1b}[31m<b>|`");
    }
}
