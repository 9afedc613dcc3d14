//! The check history's figure: each check's ratio (this build over what it was compared
//! with) and its interval, one series per configuration and instruction count, over the
//! checks in the order they ran, labelled by commit; a regression is marked by a red
//! triangle up, an improvement by a green triangle down.

use anyhow::anyhow;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::report::figures::{Analysed, Chart, FONT, Link, PALETTE, draw_legend, titled_canvas};
use crate::study::history::Entry;
use crate::system::output::Canvas;

/// The figure of a check history's entries (oldest check first).
pub struct History<'a>(pub &'a [Entry]);

impl<'a> Chart<'a> for History<'a> {
    /// One figure for a check history, linked at the top of its report.
    fn of(analysed: &Analysed<'a>) -> Vec<(Link, Self)> {
        analysed
            .history
            .map(|entries| (Link::OwnSection, History(entries)))
            .into_iter()
            .collect()
    }

    fn file_name(&self) -> String {
        HISTORY_FILE.to_owned()
    }

    fn size(&self) -> (u32, u32) {
        (1400, 700)
    }

    fn draw(&self, canvas: &Canvas<'_>) -> anyhow::Result<()> {
        plot_history(self.0, canvas)
    }
}

/// File name of the history figure.
pub const HISTORY_FILE: &str = "check-history.png";

/// The checks in the order they ran: (when, commit), each once.
pub fn checks(entries: &[Entry]) -> Vec<(&str, &str)> {
    let mut checks: Vec<(&str, &str)> = Vec::new();
    for entry in entries {
        let check = (entry.checked_utc.as_str(), entry.commit.as_str());
        if !checks.contains(&check) {
            checks.push(check);
        }
    }
    checks
}

/// The chart: checks (by position, oldest first) against the ratio.
type Ratios<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

fn plot_history(entries: &[Entry], canvas: &Canvas<'_>) -> anyhow::Result<()> {
    let root = titled_canvas(
        canvas,
        "collide check over commits: ratio to what each check compared with (95% interval); \
         ▲ regressed, ▼ improved",
        20,
    )?;
    let checks = checks(entries);
    let mut chart = ratio_axes(&root, entries, &checks)?;
    let series = series(entries);
    for (number, &(key, what)) in series.iter().enumerate() {
        // Series side by side within a check, so their intervals do not hide each other.
        let offset = 0.3 * (number as f64 / series.len().max(1) as f64 - 0.5);
        let points: Vec<(&Entry, (f64, f64))> = entries
            .iter()
            .filter(|e| e.key == key)
            .map(|e| (e, (check_index(&checks, e) + offset, e.ratio)))
            .collect();
        draw_ratios(&mut chart, &points, what, PALETTE[number % PALETTE.len()])?;
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperLeft, 14)
}

/// The position of `entry`'s check among `checks`.
fn check_index(checks: &[(&str, &str)], entry: &Entry) -> f64 {
    checks
        .iter()
        .position(|&(when, commit)| when == entry.checked_utc && commit == entry.commit)
        .unwrap_or(0) as f64
}

/// The series of the figure: (key, what it measures) of each configuration and
/// measure, in the order they first appear.
fn series(entries: &[Entry]) -> Vec<(&str, &str)> {
    let mut series: Vec<(&str, &str)> = Vec::new();
    for entry in entries {
        if !series.iter().any(|(key, _)| *key == entry.key) {
            series.push((&entry.key, &entry.what));
        }
    }
    series
}

/// The axes over every interval (at least 0.9 to 1.1), the checks labelled by commit,
/// and the line at ratio 1.
fn ratio_axes<'a, 'b>(
    root: &'a Canvas<'b>,
    entries: &[Entry],
    checks: &[(&str, &str)],
) -> anyhow::Result<Ratios<'a, 'b>> {
    let finite = entries
        .iter()
        .filter(|e| e.lower.is_finite() && e.upper.is_finite());
    let low = finite.clone().map(|e| e.lower).fold(0.9_f64, f64::min);
    let high = finite.map(|e| e.upper).fold(1.1_f64, f64::max);
    let right = checks.len() as f64 - 0.5;
    let mut chart = ChartBuilder::on(root)
        .margin(16)
        .x_label_area_size(60)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5..right, low * 0.98..high * 1.02)
        .map_err(|e| anyhow!("{e}"))?;
    let label = |x: &f64| {
        let at = x.round();
        match (at - x).abs() < 1e-6 && at >= 0.0 {
            true => checks
                .get(at as usize)
                .map_or_else(String::new, |(_, commit)| commit.chars().take(8).collect()),
            false => String::new(),
        }
    };
    chart
        .configure_mesh()
        .x_desc("check (commit), oldest first")
        .y_desc("ratio this build / compared with")
        .axis_desc_style((FONT, 17))
        .label_style((FONT, 14))
        .x_labels(checks.len().clamp(1, 30))
        .x_label_formatter(&label)
        .light_line_style(BLACK.mix(0.04))
        .y_label_formatter(&|y| format!("{y:.2}"))
        .draw()
        .map_err(|e| anyhow!("{e}"))?;
    chart
        .draw_series(LineSeries::new(
            [(-0.5, 1.0), (right, 1.0)],
            BLACK.mix(0.5).stroke_width(1),
        ))
        .map_err(|e| anyhow!("{e}"))?;
    Ok(chart)
}

/// One series in `colour`, labelled `what`: its entries each at its point (x, ratio),
/// joined, with their intervals, and marked by their verdicts.
fn draw_ratios(
    chart: &mut Ratios<'_, '_>,
    points: &[(&Entry, (f64, f64))],
    what: &str,
    colour: RGBColor,
) -> anyhow::Result<()> {
    chart
        .draw_series(LineSeries::new(
            points.iter().map(|&(_, at)| at),
            colour.stroke_width(2),
        ))
        .map_err(|e| anyhow!("{e}"))?
        .label(what)
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2)));
    chart
        .draw_series(points.iter().map(|&(e, (x, _))| {
            PathElement::new([(x, e.lower), (x, e.upper)], colour.stroke_width(1))
        }))
        .map_err(|e| anyhow!("{e}"))?;
    let judged = |verdict: &'static str| {
        points
            .iter()
            .filter(move |(e, _)| e.verdict == verdict)
            .map(|&(_, at)| at)
    };
    chart
        .draw_series(judged("unchanged").map(|p| Circle::new(p, 3, colour.filled())))
        .map_err(|e| anyhow!("{e}"))?;
    chart
        .draw_series(
            judged("regressed").map(|p| TriangleMarker::new(p, MARKER, REGRESSED.filled())),
        )
        .map_err(|e| anyhow!("{e}"))?;
    chart
        .draw_series(judged("improved").map(|p| {
            EmptyElement::at(p)
                + Polygon::new(
                    vec![(-MARKER, -MARKER / 2), (MARKER, -MARKER / 2), (0, MARKER)],
                    IMPROVED.filled(),
                )
        }))
        .map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

/// Size of the regression and improvement markers, and their colours.
const MARKER: i32 = 9;
const REGRESSED: RGBColor = RGBColor(0xd6, 0x27, 0x28);
const IMPROVED: RGBColor = RGBColor(0x2c, 0xa0, 0x2c);
