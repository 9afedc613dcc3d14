//! The accuracy study's speed against error: missed fraction, pressure and
//! collision-rate errors, one panel each, with the Pareto front.

use anyhow::anyhow;
use plotters::prelude::*;

use crate::report::accuracy::{AccuracyPoint, PackingGroup, pareto_front};
use crate::report::figures::{
    Analysed, Chart, ERROR_FLOOR, FONT, Link, PALETTE, draw_legend, titled_canvas,
};
use crate::system::output::Canvas;

/// File name of the figure.
pub const PARETO_FILE: &str = "accuracy-pareto.png";

/// Which error a panel plots.
type ErrorOf = fn(&AccuracyPoint) -> f64;

/// The figure of an accuracy study's packing groups.
pub struct Pareto<'a>(pub &'a [PackingGroup]);

impl<'a> Chart<'a> for Pareto<'a> {
    /// One figure for an accuracy study, listed in its accuracy section.
    fn of(analysed: &Analysed<'a>) -> Vec<(Link, Self)> {
        analysed
            .accuracy
            .map(|groups| (Link::Accuracy, Pareto(groups)))
            .into_iter()
            .collect()
    }

    fn file_name(&self) -> String {
        PARETO_FILE.to_owned()
    }

    fn size(&self) -> (u32, u32) {
        (2000, 600)
    }

    fn draw(&self, canvas: &Canvas<'_>) -> anyhow::Result<()> {
        draw_pareto(self.0, canvas)
    }
}

/// An error as plotted: its magnitude, 0 raised to the floor; NaN (no reference to
/// measure it against) stays NaN and is not drawn.
fn plotted(error: f64) -> f64 {
    match error.is_nan() {
        true => f64::NAN,
        false => error.abs().max(ERROR_FLOOR),
    }
}

/// The error axis' right end; its left end is half the floor.
const ERROR_HIGH: f64 = 2.0;

/// A panel: log error against log speed.
type Panel<'a, 'b> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<LogCoord<f64>, LogCoord<f64>>>;

fn draw_pareto(groups: &[PackingGroup], canvas: &Canvas<'_>) -> anyhow::Result<()> {
    let root = titled_canvas(
        canvas,
        "Speed against accuracy: step method (points, larger dt further right) and event reference (dashed)",
        22,
    )?;
    let panels = root.split_evenly((1, 3));
    let errors: [(&str, ErrorOf); 3] = [
        ("missed-collision fraction", |p| p.missed_fraction),
        ("|Z error| against the event reference", |p| p.z_error),
        ("|collision-rate error| against the event reference", |p| {
            p.rate_error
        }),
    ];
    let speeds = speed_range(groups);
    for (panel_index, (panel, (name, error))) in panels.iter().zip(errors).enumerate() {
        let mut chart = panel_axes(panel, name, speeds)?;
        for (index, group) in groups.iter().enumerate() {
            draw_group(&mut chart, group, index, error)?;
        }
        // One legend, on the left panel, whose lower right stays clear of the data
        // (accurate steps are slow, fast steps inaccurate).
        if panel_index == 0 {
            draw_legend(&mut chart, SeriesLabelPosition::LowerRight, 14)?;
        }
    }
    Ok(())
}

/// The speed axis of every panel: every run's simulated time per wall second, with a
/// factor of 2 of room either side.
fn speed_range(groups: &[PackingGroup]) -> (f64, f64) {
    let (low, high) = groups
        .iter()
        .flat_map(|g| g.steps.iter().chain(&g.reference))
        .map(|p| p.sim_time_per_s)
        .filter(|s| s.is_finite() && *s > 0.0)
        .fold((f64::INFINITY, 0.0_f64), |(lo, hi), s| {
            (lo.min(s), hi.max(s))
        });
    if low.is_finite() {
        (low / 2.0, high * 2.0)
    } else {
        (0.1, 10.0)
    }
}

/// A panel's axes and mesh: the error `name` against the speeds `(low, high)`.
fn panel_axes<'a, 'b>(
    panel: &'a Canvas<'b>,
    name: &str,
    (low, high): (f64, f64),
) -> anyhow::Result<Panel<'a, 'b>> {
    let mut chart = ChartBuilder::on(panel)
        .margin(16)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d(
            (ERROR_FLOOR / 2.0..ERROR_HIGH).log_scale(),
            (low..high).log_scale(),
        )
        .map_err(|e| anyhow!("{e}"))?;
    chart
        .configure_mesh()
        .x_desc(format!("{name} (log; 0 drawn at {ERROR_FLOOR:e})"))
        .y_desc("simulated time per wall second")
        .axis_desc_style((FONT, 17))
        .label_style((FONT, 14))
        .light_line_style(BLACK.mix(0.04))
        .x_label_formatter(&|x| format!("{x:.0e}"))
        .y_label_formatter(&|y| format!("{y:.0}"))
        .draw()
        .map_err(|e| anyhow!("{e}"))?;
    Ok(chart)
}

/// One packing's series in a panel (the group at `index`, in the palette's colour of
/// that index): its steps, its event reference and their Pareto front.
fn draw_group(
    chart: &mut Panel<'_, '_>,
    group: &PackingGroup,
    index: usize,
    error: ErrorOf,
) -> anyhow::Result<()> {
    let colour = PALETTE[index % PALETTE.len()];
    let points: Vec<(f64, f64)> = group
        .steps
        .iter()
        .map(|p| (plotted(error(p)), p.sim_time_per_s))
        .filter(|(e, s)| e.is_finite() && s.is_finite())
        .collect();
    chart
        .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))
        .map_err(|e| anyhow!("{e}"))?
        .label(format!("step, packing {:.2}", group.packing))
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2)));
    chart
        .draw_series(points.iter().map(|&p| Circle::new(p, 4, colour.filled())))
        .map_err(|e| anyhow!("{e}"))?;
    // The front among this packing's methods: speed up, error down.
    let mut candidates: Vec<(f64, f64)> = group
        .steps
        .iter()
        .map(|p| (p.sim_time_per_s, error(p).abs()))
        .collect();
    if let Some(reference) = &group.reference {
        candidates.push((reference.sim_time_per_s, 0.0));
        draw_reference(chart, reference.sim_time_per_s, group.packing, colour)?;
    }
    draw_front(chart, &candidates, index == 0)
}

/// The event reference of a packing: its speed across the panel (dashed), and a
/// triangle at error 0 (drawn at the floor).
fn draw_reference(
    chart: &mut Panel<'_, '_>,
    speed: f64,
    packing: f64,
    colour: RGBColor,
) -> anyhow::Result<()> {
    chart
        .draw_series(DashedLineSeries::new(
            [(ERROR_FLOOR / 2.0, speed), (ERROR_HIGH, speed)],
            8,
            5,
            colour.stroke_width(1),
        ))
        .map_err(|e| anyhow!("{e}"))?
        .label(format!("event, packing {packing:.2} (error 0)"))
        .legend(move |(x, y)| TriangleMarker::new((x + 10, y), 6, colour.filled()));
    chart
        .draw_series([TriangleMarker::new(
            (ERROR_FLOOR, speed),
            7,
            colour.filled(),
        )])
        .map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

/// Rings around the Pareto front of `candidates` (speed, error); labelled in the legend
/// when `labelled` (once per panel).
fn draw_front(
    chart: &mut Panel<'_, '_>,
    candidates: &[(f64, f64)],
    labelled: bool,
) -> anyhow::Result<()> {
    let front = pareto_front(candidates);
    let rings = candidates
        .iter()
        .zip(&front)
        .filter(|(_, on)| **on)
        .map(|(&(speed, e), _)| Circle::new((plotted(e), speed), 9, BLACK.stroke_width(2)));
    let drawn = chart.draw_series(rings).map_err(|e| anyhow!("{e}"))?;
    if labelled {
        drawn
            .label("Pareto front (per packing)")
            .legend(|(x, y)| Circle::new((x + 10, y), 6, BLACK.stroke_width(2)));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_error_without_a_reference_is_not_drawn_as_no_error() {
        assert!(plotted(f64::NAN).is_nan());
        assert_eq!(plotted(0.0), ERROR_FLOOR);
        assert_eq!(plotted(-0.25), 0.25);
    }
}
