//! The markdown summary of `collide check` (printed, and written to `summary.md`): the
//! headline verdict, who was compared with whom and how, and one table row per compared
//! configuration and instruction count. The rows and their verdicts are `compare`'s;
//! where the text goes is the caller's.

use std::fmt::Write as _;

use crate::check::baseline::BaselineInfo;
use crate::check::compare::{CONFIDENCE, INSTRUCTIONS, Row};
use crate::check::{AbCheck, CheckOptions, against};
use crate::stats::{self, Verdict, median};
use crate::study::runner::Calibration;

/// The summary of a check of `new_info` against the baseline `old_info` (its `rows`),
/// and against A's build in an A/B check (`ab`, whose rows then decide).
pub fn markdown(
    options: &CheckOptions,
    old_info: &BaselineInfo,
    new_info: &BaselineInfo,
    rows: &[Row],
    ab: Option<&AbCheck>,
    timings_decide: bool,
    notes: &[String],
) -> String {
    // In an A/B check its rows decide, and the baseline's are shown only.
    let (deciding, shown): (Vec<&Row>, Vec<&Row>) = match ab {
        Some(ab) => (ab.rows.iter().collect(), rows.iter().collect()),
        None => rows.iter().partition(|row| row.decides(timings_decide)),
    };
    let count =
        |rows: &[&Row], verdict: Verdict| rows.iter().filter(|r| r.verdict == verdict).count();
    let regressed = count(&deciding, Verdict::Regressed);
    let improved = count(&deciding, Verdict::Improved);
    let advisory = count(&shown, Verdict::Regressed);
    let mut out = String::new();
    let _ = writeln!(
        out,
        "# collide check: {}\n",
        match (regressed, advisory) {
            (0, 0) => "no regression".to_owned(),
            (0, n) =>
                format!("no regression ({n} regression(s) against the baseline shown, not judged)"),
            (n, _) => format!("{n} REGRESSED"),
        }
    );
    let _ = writeln!(out, "- manifest: `{}`", options.manifest.display());
    let _ = writeln!(out, "- this build (B): {}", describe(new_info));
    for note in notes {
        let _ = writeln!(out, "- {note}");
    }
    if let Some(ab) = ab {
        write_ab(&mut out, options, ab);
    }
    let _ = writeln!(
        out,
        "- baseline `{}`: {}",
        options.baseline.display(),
        describe(old_info)
    );
    write_method(&mut out, options, old_info, ab.is_some(), timings_decide);
    write_table(&mut out, rows, ("baseline median", "median now"));
    if new_info.instructions.is_empty() {
        let _ = writeln!(
            out,
            "\nNo instruction counts: valgrind is not installed on this machine."
        );
    }
    let _ = writeln!(
        out,
        "\nverdict: {regressed} regressed, {improved} improved, {} unchanged{}",
        deciding.len() - regressed - improved,
        match advisory {
            0 => String::new(),
            n => format!(", and {n} regression(s) against the baseline shown, not judged"),
        }
    );
    out
}

/// The A/B part: the build checked against, how the two were compared, their table; the
/// baseline's part follows under its own heading.
fn write_ab(out: &mut String, options: &CheckOptions, ab: &AbCheck) {
    let _ = writeln!(
        out,
        "- checked against (A): commit {}, {}",
        against::short(&ab.rev.commit),
        ab.rev.reason
    );
    let _ = writeln!(
        out,
        "- A/B: both builds ran every repetition, next to each other in alternating order \
         (A B, then B A), each run a fresh process; measure: the wall seconds of the \
         stepping loop (`wall_s`, the slowest rank's for MPI); ratio = the median of the \
         paired ratios B/A with its {:.0}% bootstrap interval ({} resamples of the pairs); \
         regressed when the whole interval lies above {:.3}, improved when it lies below \
         {:.3}; instruction counts of both builds (callgrind) compared beside. These \
         verdicts decide.\n",
        100.0 * CONFIDENCE,
        stats::RESAMPLES,
        1.0 + options.noise,
        1.0 / (1.0 + options.noise),
    );
    write_table(out, &ab.rows, ("A median", "B median"));
    let _ = writeln!(out, "\n## Against the baseline (shown, not judged)\n");
}

/// Where and how a set of records was measured, for the summary's header.
fn describe(info: &BaselineInfo) -> String {
    let env = &info.environment;
    let calibration = |pick: fn(&Calibration) -> Option<f64>| {
        let mut values: Vec<f64> = info.calibrations.iter().filter_map(pick).collect();
        match values.is_empty() {
            true => "—".to_owned(),
            false => format!("{:.4} s", median(&mut values)),
        }
    };
    format!(
        "{} on {} ({}, {} logical cores), commit {}{}, recorded {}{}; calibration median \
         {} CPU, {} wall over {} rounds",
        env.profile,
        env.hostname,
        env.cpu_model,
        env.logical_cores,
        env.git_commit,
        if env.git_dirty { " (dirty)" } else { "" },
        info.recorded_utc,
        match info.inject_slowdown > 0.0 {
            true => format!(", with an injected slowdown of {}", info.inject_slowdown),
            false => String::new(),
        },
        calibration(|c| c.calibration_cpu_s),
        calibration(|c| Some(c.calibration_s)),
        info.calibrations.len()
    )
}

/// The summary's lines on what is measured, how it is compared and what decides.
fn write_method(
    out: &mut String,
    options: &CheckOptions,
    old_info: &BaselineInfo,
    ab: bool,
    timings_decide: bool,
) {
    let _ = writeln!(
        out,
        "- measure: the CPU seconds of each run's stepping loop (`cpu_s`, summed over threads \
         and ranks; time spent waiting for a CPU is not counted), divided by the CPU seconds of \
         the calibration workload (`collide calibrate`, fixed work that is not simulator code) \
         timed just before the run's round of repetitions; wall seconds (`wall_s`) divided by \
         the calibration's wall seconds where CPU time is unknown, and shown beside it"
    );
    let _ = writeln!(
        out,
        "- ratio = median normalised time now / in the baseline, with its {:.0}% bootstrap \
         interval ({} resamples); regressed when the whole interval lies above {:.3}, improved \
         when it lies below {:.3} (noise threshold {:.0}%)\n",
        100.0 * CONFIDENCE,
        stats::RESAMPLES,
        1.0 + options.noise,
        1.0 / (1.0 + options.noise),
        100.0 * options.noise
    );
    let _ = writeln!(
        out,
        "- {}\n",
        match (ab, timings_decide) {
            (true, _) =>
                "these verdicts are shown, not judged: the A/B verdicts above decide".to_owned(),
            (false, true) =>
                "timing verdicts decide: the baseline was recorded on this machine since \
                     its last boot"
                    .to_owned(),
            (false, false) => format!(
                "timing verdicts are shown, not judged: the baseline was recorded on another \
                 machine or boot ({}), where the normalised times of the same build differ by \
                 up to about 20%; the instruction count (callgrind, the same on any machine) \
                 decides. Record a baseline here (`--update-baseline`) to judge timings",
                old_info.environment.cpu_model
            ),
        }
    );
}

/// The summary's table: one row per configuration and measure.
fn write_table(out: &mut String, rows: &[Row], (old, new): (&str, &str)) {
    let _ = writeln!(
        out,
        "| configuration | measure | {old} | {new} | ratio | {:.0}% interval | verdict | wall ratio (interval) | note |",
        100.0 * CONFIDENCE
    );
    let _ = writeln!(
        out,
        "| --- | --- | ---: | ---: | ---: | --- | --- | --- | --- |"
    );
    for row in rows {
        let digits = if row.unit == INSTRUCTIONS { 0 } else { 4 };
        let _ = writeln!(
            out,
            "| {} | {} | {:.digits$} | {:.digits$} | {:.3} | {:.3}–{:.3} | {} | {} | {} |",
            row.what,
            row.unit,
            row.old,
            row.new,
            row.ratio.point,
            row.ratio.lower,
            row.ratio.upper,
            match row.verdict {
                Verdict::Regressed => "**regressed**",
                verdict => verdict.name(),
            },
            row.wall.map_or_else(String::new, |wall| format!(
                "{:.3} ({:.3}–{:.3})",
                wall.point, wall.lower, wall.upper
            )),
            row.note
        );
    }
}
