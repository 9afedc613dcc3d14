//! The check history's figure: each check's ratio (this build over what it was compared
//! with) and its interval, one series per configuration and instruction count, over the
//! checks in the order they ran, labelled by commit; a regression is marked by a red
//! triangle up, an improvement by a green triangle down.

use anyhow::anyhow;
use plotters::prelude::*;

use crate::report::figures::{Chart, FONT, PALETTE, draw_legend, titled_canvas};
use crate::study::history::Entry;
use crate::system::output::Canvas;

/// The figure of a check history's entries (oldest check first).
pub struct History<'a>(pub &'a [Entry]);

impl Chart for History<'_> {
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

fn plot_history(entries: &[Entry], canvas: &Canvas<'_>) -> anyhow::Result<()> {
    let root = titled_canvas(
        canvas,
        "collide check over commits: ratio to what each check compared with (95% interval); \
         ▲ regressed, ▼ improved",
        20,
    )?;
    let checks = checks(entries);
    let index = |entry: &Entry| {
        checks
            .iter()
            .position(|&(when, commit)| when == entry.checked_utc && commit == entry.commit)
            .unwrap_or(0) as f64
    };
    let finite = entries
        .iter()
        .filter(|e| e.lower.is_finite() && e.upper.is_finite());
    let low = finite.clone().map(|e| e.lower).fold(0.9_f64, f64::min);
    let high = finite.map(|e| e.upper).fold(1.1_f64, f64::max);
    let mut chart = ChartBuilder::on(&root)
        .margin(16)
        .x_label_area_size(60)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5..checks.len() as f64 - 0.5, low * 0.98..high * 1.02)
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
            [(-0.5, 1.0), (checks.len() as f64 - 0.5, 1.0)],
            BLACK.mix(0.5).stroke_width(1),
        ))
        .map_err(|e| anyhow!("{e}"))?;
    let mut series: Vec<(&str, &str)> = Vec::new();
    for entry in entries {
        if !series.iter().any(|(key, _)| *key == entry.key) {
            series.push((&entry.key, &entry.what));
        }
    }
    for (number, (key, what)) in series.iter().enumerate() {
        let colour = PALETTE[number % PALETTE.len()];
        // Series side by side within a check, so their intervals do not hide each other.
        let offset = 0.3 * (number as f64 / series.len().max(1) as f64 - 0.5);
        let points: Vec<&Entry> = entries.iter().filter(|e| e.key == *key).collect();
        chart
            .draw_series(LineSeries::new(
                points.iter().map(|e| (index(e) + offset, e.ratio)),
                colour.stroke_width(2),
            ))
            .map_err(|e| anyhow!("{e}"))?
            .label(*what)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2)));
        chart
            .draw_series(points.iter().map(|e| {
                let x = index(e) + offset;
                PathElement::new([(x, e.lower), (x, e.upper)], colour.stroke_width(1))
            }))
            .map_err(|e| anyhow!("{e}"))?;
        let at = |e: &Entry| (index(e) + offset, e.ratio);
        let judged = |verdict: &'static str| {
            let at = &at;
            points
                .iter()
                .filter(move |e| e.verdict == verdict)
                .map(move |e| at(e))
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
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperLeft, 14)
}

/// Size of the regression and improvement markers, and their colours.
const MARKER: i32 = 9;
const REGRESSED: RGBColor = RGBColor(0xd6, 0x27, 0x28);
const IMPROVED: RGBColor = RGBColor(0x2c, 0xa0, 0x2c);
