//! The accuracy study's figures (PNG, plotters, the fonts and palette of `figures`):
//! speed against error (missed fraction, pressure and collision-rate errors) with the
//! Pareto front, and the stability map of v_rms·dt/r ×
//! packing coloured by missed-collision fraction with the failure boundary; and for
//! e < 1 the cooling curves against Haff's law.

use std::path::{Path, PathBuf};

use anyhow::anyhow;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::accuracy::{
    AccuracyPoint, Breakdown, CoolingCurve, FAILURE_MISSED_FRACTION, PackingGroup, method_label,
    pareto_front,
};
use crate::figures::{FONT, PALETTE, draw_legend, register_font};
use crate::output::{Canvas, write_png};

/// File names of the two figures.
pub const PARETO_FILE: &str = "accuracy-pareto.png";
pub const STABILITY_FILE: &str = "accuracy-stability.png";
const PARETO_SIZE: (u32, u32) = (2000, 600);
const STABILITY_SIZE: (u32, u32) = (1100, 560);
/// Which error a panel plots.
type ErrorOf = fn(&AccuracyPoint) -> f64;
/// Errors of exactly 0 are drawn at this floor of the log axis.
const ERROR_FLOOR: f64 = 1e-5;

/// Draws both figures into `dir`; returns their paths (pareto, stability).
pub fn draw(groups: &[PackingGroup], dir: &Path) -> anyhow::Result<(PathBuf, PathBuf)> {
    register_font();
    let pareto = dir.join(PARETO_FILE);
    write_png(&pareto, PARETO_SIZE, |canvas| draw_pareto(groups, canvas))?;
    let stability = dir.join(STABILITY_FILE);
    write_png(&stability, STABILITY_SIZE, |canvas| {
        draw_stability(groups, canvas)
    })?;
    Ok((pareto, stability))
}

/// An error as plotted: its magnitude, 0 raised to the floor.
fn plotted(error: f64) -> f64 {
    error.abs().max(ERROR_FLOOR)
}

/// `root` filled white with `title` across its top; the area below.
fn titled_canvas<'a>(
    root: &Canvas<'a>,
    title: &str,
    title_size: u32,
) -> anyhow::Result<Canvas<'a>> {
    root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
    root.titled(title, (FONT, title_size))
        .map_err(|e| anyhow!("{e}"))
}

fn draw_pareto(groups: &[PackingGroup], canvas: &Canvas<'_>) -> anyhow::Result<()> {
    let root = titled_canvas(
        canvas,
        "Speed against accuracy: step method (points, large dt on the left) and event reference (dashed)",
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
    let speeds: Vec<f64> = groups
        .iter()
        .flat_map(|g| g.steps.iter().chain(&g.reference))
        .map(|p| p.sim_time_per_s)
        .filter(|s| s.is_finite() && *s > 0.0)
        .collect();
    let (s_low, s_high) = speeds
        .iter()
        .fold((f64::INFINITY, 0.0_f64), |(lo, hi), &s| {
            (lo.min(s), hi.max(s))
        });
    let (s_low, s_high) = if s_low.is_finite() {
        (s_low / 2.0, s_high * 2.0)
    } else {
        (0.1, 10.0)
    };
    for (panel_index, (panel, (name, error))) in panels.iter().zip(errors).enumerate() {
        let mut chart = ChartBuilder::on(panel)
            .margin(16)
            .x_label_area_size(50)
            .y_label_area_size(80)
            .build_cartesian_2d(
                (ERROR_FLOOR / 2.0..2.0_f64).log_scale(),
                (s_low..s_high).log_scale(),
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
        for (index, group) in groups.iter().enumerate() {
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
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2))
                });
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
                let speed = reference.sim_time_per_s;
                chart
                    .draw_series(DashedLineSeries::new(
                        [(ERROR_FLOOR / 2.0, speed), (2.0, speed)],
                        8,
                        5,
                        colour.stroke_width(1),
                    ))
                    .map_err(|e| anyhow!("{e}"))?
                    .label(format!("event, packing {:.2} (error 0)", group.packing))
                    .legend(move |(x, y)| TriangleMarker::new((x + 10, y), 6, colour.filled()));
                chart
                    .draw_series([TriangleMarker::new(
                        (ERROR_FLOOR, speed),
                        7,
                        colour.filled(),
                    )])
                    .map_err(|e| anyhow!("{e}"))?;
            }
            let front = pareto_front(&candidates);
            let rings = candidates
                .iter()
                .zip(&front)
                .filter(|(_, on)| **on)
                .map(|(&(speed, e), _)| Circle::new((plotted(e), speed), 9, BLACK.stroke_width(2)));
            let drawn = chart.draw_series(rings).map_err(|e| anyhow!("{e}"))?;
            if index == 0 {
                drawn
                    .label("Pareto front (per packing)")
                    .legend(|(x, y)| Circle::new((x + 10, y), 6, BLACK.stroke_width(2)));
            }
        }
        // One legend, on the left panel, whose lower right stays clear of the data
        // (accurate steps are slow, fast steps inaccurate).
        if panel_index == 0 {
            draw_legend(&mut chart, SeriesLabelPosition::LowerRight, 14)?;
        }
    }
    Ok(())
}

/// The stability map's colour scale: missed-collision fraction, log, floor to 1.
fn draw_colour_scale(area: &Canvas<'_>) -> anyhow::Result<()> {
    let mut chart = ChartBuilder::on(area)
        .margin_top(16)
        .margin_bottom(66)
        .margin_right(16)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..1.0_f64, (ERROR_FLOOR..1.0_f64).log_scale())
        .map_err(|e| anyhow!("{e}"))?;
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc("missed fraction")
        .axis_desc_style((FONT, 15))
        .label_style((FONT, 14))
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .draw()
        .map_err(|e| anyhow!("{e}"))?;
    const SLICES: i32 = 100;
    let at = |k: i32| ERROR_FLOOR.powf(1.0 - f64::from(k) / f64::from(SLICES));
    chart
        .draw_series((0..SLICES).map(|k| {
            let (low, high) = (at(k), at(k + 1));
            Rectangle::new(
                [(0.0, low), (1.0, high)],
                missed_colour((low * high).sqrt()).filled(),
            )
        }))
        .map_err(|e| anyhow!("{e}"))?;
    chart
        .draw_series([PathElement::new(
            [
                (0.0, FAILURE_MISSED_FRACTION),
                (1.0, FAILURE_MISSED_FRACTION),
            ],
            BLACK.stroke_width(3),
        )])
        .map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

/// Green (nothing missed) through yellow to red (everything missed), by log fraction.
fn missed_colour(fraction: f64) -> RGBColor {
    if !fraction.is_finite() {
        return RGBColor(0xdd, 0xdd, 0xdd);
    }
    let t = ((fraction.max(ERROR_FLOOR).log10() - ERROR_FLOOR.log10()) / -ERROR_FLOOR.log10())
        .clamp(0.0, 1.0);
    let mix = |a: u8, b: u8, s: f64| (a as f64 + (b as f64 - a as f64) * s).round() as u8;
    let (green, yellow, red) = ((0x4c, 0xaf, 0x50), (0xff, 0xe0, 0x66), (0xe5, 0x39, 0x35));
    let (from, to, s): ((u8, u8, u8), (u8, u8, u8), f64) = if t < 0.5 {
        (green, yellow, 2.0 * t)
    } else {
        (yellow, red, 2.0 * t - 1.0)
    };
    RGBColor(
        mix(from.0, to.0, s),
        mix(from.1, to.1, s),
        mix(from.2, to.2, s),
    )
}

fn draw_stability(groups: &[PackingGroup], canvas: &Canvas<'_>) -> anyhow::Result<()> {
    // Columns: the distinct v_rms·dt/r of the step runs, ascending; rows: the packings.
    let mut columns: Vec<f64> = groups
        .iter()
        .flat_map(|g| g.steps.iter().map(|p| p.step_over_radius))
        .filter(|x| x.is_finite())
        .collect();
    columns.sort_by(f64::total_cmp);
    columns.dedup_by(|a, b| (*a / *b - 1.0).abs() < 0.02);
    let column_of = |x: f64| columns.iter().position(|c| (x / c - 1.0).abs() < 0.02);
    let (nx, ny) = (columns.len().max(1), groups.len().max(1));
    let root = titled_canvas(
        canvas,
        &format!(
            "Stability map of the step method: missed-collision fraction (m) and max overlap (ov); black line: m = {FAILURE_MISSED_FRACTION:e}"
        ),
        19,
    )?;
    let (map_area, scale_area) = root.split_horizontally(STABILITY_SIZE.0 - 130);
    draw_colour_scale(&scale_area)?;
    let mut chart = ChartBuilder::on(&map_area)
        .margin(16)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d(
            // An integer range is inclusive once segmented: 0..n − 1 gives n cells.
            (0..nx - 1).into_segmented(),
            (0..ny - 1).into_segmented(),
        )
        .map_err(|e| anyhow!("{e}"))?;
    let index = |value: &SegmentValue<usize>| match value {
        SegmentValue::CenterOf(i) => Some(*i),
        _ => None,
    };
    let column_label = |x: &SegmentValue<usize>| {
        index(x)
            .and_then(|i| columns.get(i))
            .map_or_else(String::new, |c| format!("{c:.3}"))
    };
    let row_label = |y: &SegmentValue<usize>| {
        index(y)
            .and_then(|j| groups.get(j))
            .map_or_else(String::new, |g| format!("{:.2}", g.packing))
    };
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("v_rms·dt/r (how many radii the rms disk moves per step)")
        .y_desc("packing")
        .axis_desc_style((FONT, 17))
        .label_style((FONT, 15))
        .x_label_formatter(&column_label)
        .y_label_formatter(&row_label)
        .draw()
        .map_err(|e| anyhow!("{e}"))?;
    // cells[j][i]: the point at row j (packing), column i.
    let mut cells: Vec<Vec<Option<&AccuracyPoint>>> = vec![vec![None; nx]; ny];
    for (j, group) in groups.iter().enumerate() {
        for point in &group.steps {
            if let Some(i) = column_of(point.step_over_radius) {
                cells[j][i] = Some(point);
            }
        }
    }
    for (j, row) in cells.iter().enumerate() {
        for (i, cell) in row.iter().enumerate() {
            let Some(point) = cell else { continue };
            use SegmentValue::{CenterOf, Exact};
            chart
                .draw_series([Rectangle::new(
                    [(Exact(i), Exact(j)), (Exact(i + 1), Exact(j + 1))],
                    missed_colour(point.missed_fraction).filled(),
                )])
                .map_err(|e| anyhow!("{e}"))?;
            let style =
                TextStyle::from((FONT, 15).into_font()).pos(Pos::new(HPos::Center, VPos::Center));
            let label = EmptyElement::at((CenterOf(i), CenterOf(j)))
                + Text::new(
                    if point.missed_fraction == 0.0 {
                        "m 0".to_owned()
                    } else {
                        format!("m {:.1e}", point.missed_fraction)
                    },
                    (0, -10),
                    style.clone(),
                )
                + Text::new(format!("ov {:.3}", point.max_overlap), (0, 10), style);
            chart.draw_series([label]).map_err(|e| anyhow!("{e}"))?;
        }
    }
    // The failure boundary: every cell edge between a failed and a passing cell.
    let failed = |(j, i): (usize, usize)| cells[j][i].map(AccuracyPoint::failed);
    let differ = |a, b| matches!((failed(a), failed(b)), (Some(x), Some(y)) if x != y);
    use SegmentValue::Exact;
    let mut edges: Vec<[(SegmentValue<usize>, SegmentValue<usize>); 2]> = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            if i + 1 < nx && differ((j, i), (j, i + 1)) {
                edges.push([(Exact(i + 1), Exact(j)), (Exact(i + 1), Exact(j + 1))]);
            }
            if j + 1 < ny && differ((j, i), (j + 1, i)) {
                edges.push([(Exact(i), Exact(j + 1)), (Exact(i + 1), Exact(j + 1))]);
            }
        }
    }
    chart
        .draw_series(
            edges
                .into_iter()
                .map(|edge| PathElement::new(edge, BLACK.stroke_width(4))),
        )
        .map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

/// File name of the e < 1 cooling figure.
pub const COOLING_FILE: &str = "accuracy-cooling.png";
const COOLING_SIZE: (u32, u32) = (1400, 620);

/// Draws T/T₀ against t/t₀ of every cooling curve (one panel per packing, one line per
/// method, TC time and dt, dashed where it broke down, a cross where the event method
/// collapsed) with Haff's law 1/(1 + t/t₀)² in black; returns its path.
pub fn draw_cooling(curves: &[CoolingCurve], dir: &Path) -> anyhow::Result<PathBuf> {
    register_font();
    let path = dir.join(COOLING_FILE);
    write_png(&path, COOLING_SIZE, |canvas| plot_cooling(curves, canvas))?;
    Ok(path)
}

fn plot_cooling(curves: &[CoolingCurve], canvas: &Canvas<'_>) -> anyhow::Result<()> {
    let root = titled_canvas(
        canvas,
        "Cooling (e < 1): T/T₀ against t/t₀, Haff's law in black, broken-down runs dashed, collapse ×",
        22,
    )?;
    // One panel per packing (curves arrive ordered by packing).
    let mut packings: Vec<f64> = curves.iter().map(|c| c.packing).collect();
    packings.dedup_by(|a, b| format!("{a:.4}") == format!("{b:.4}"));
    let panels = root.split_evenly((1, packings.len().max(1)));
    for (panel, &packing) in panels.iter().zip(&packings) {
        let group: Vec<&CoolingCurve> = curves
            .iter()
            .filter(|c| format!("{:.4}", c.packing) == format!("{packing:.4}"))
            .collect();
        plot_cooling_panel(panel, packing, &group)?;
    }
    Ok(())
}

/// Curve colours: the palette's first three (its fourth is near Haff's black), then
/// orange, purple and brown (a packing has up to six runs).
const COOLING_COLOURS: [RGBColor; 6] = [
    PALETTE[0],
    PALETTE[1],
    PALETTE[2],
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x94, 0x67, 0xbd),
    RGBColor(0x8c, 0x56, 0x4b),
];

fn plot_cooling_panel(
    panel: &Canvas<'_>,
    packing: f64,
    curves: &[&CoolingCurve],
) -> anyhow::Result<()> {
    let scaled = |curve: &CoolingCurve| -> Vec<(f64, f64)> {
        let t_zero = curve.points[0][1];
        curve
            .points
            .iter()
            .map(|&[t, temperature]| (t / curve.haff_t0, temperature / t_zero))
            .filter(|&(x, y)| x.is_finite() && y.is_finite() && y > 0.0)
            .collect()
    };
    let x_high = curves
        .iter()
        .flat_map(|c| scaled(c).into_iter().map(|(x, _)| x))
        .fold(0.0_f64, f64::max)
        .max(0.1);
    let mut chart = ChartBuilder::on(panel)
        .caption(format!("packing {packing:.2}"), (FONT, 18))
        .margin(16)
        .x_label_area_size(50)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..x_high * 1.02, 0.0..1.05_f64)
        .map_err(|e| anyhow!("{e}"))?;
    chart
        .configure_mesh()
        .x_desc("t / t₀ (Haff's t₀ fitted to the event run)")
        .y_desc("T / T₀")
        .axis_desc_style((FONT, 17))
        .label_style((FONT, 14))
        .light_line_style(BLACK.mix(0.04))
        .y_label_formatter(&|y| format!("{y:.2}"))
        .draw()
        .map_err(|e| anyhow!("{e}"))?;
    let haff: Vec<(f64, f64)> = (0..=100)
        .map(|i| {
            let x = x_high * i as f64 / 100.0;
            (x, 1.0 / (1.0 + x).powi(2))
        })
        .collect();
    chart
        .draw_series(LineSeries::new(haff, BLACK.stroke_width(3)))
        .map_err(|e| anyhow!("{e}"))?
        .label("Haff's law 1/(1 + t/t₀)²")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.stroke_width(3)));
    let mut collapse_legend = false;
    for (index, curve) in curves.iter().enumerate() {
        let colour = COOLING_COLOURS[index % COOLING_COLOURS.len()];
        let points = scaled(curve);
        let step = if curve.method == "event" {
            "exact".to_owned()
        } else {
            format!("v_rms·dt/r = {:.3}", curve.step_over_radius)
        };
        let t_end = points.last().map_or(0.0, |p| p.0);
        // The unguarded event run says whether and when it collapsed.
        let outcome = match curve.breakdown() {
            Some(Breakdown::Collapse { time }) => {
                format!(": collapsed at t/t₀ = {:.3}", time / curve.haff_t0)
            }
            _ if curve.tc == 0.0 => format!(": no collapse by t/t₀ = {t_end:.3}"),
            _ => String::new(),
        };
        let label = format!(
            "{} ({step}){outcome}, max |T/T_Haff − 1| = {:.1}%",
            method_label(&curve.method, curve.tc),
            100.0 * curve.haff_deviation
        );
        let style = colour.stroke_width(2);
        let legend = move |(x, y): (i32, i32)| PathElement::new([(x, y), (x + 20, y)], style);
        if curve.broke_down() {
            chart
                .draw_series(DashedLineSeries::new(points.clone(), 8, 5, style))
                .map_err(|e| anyhow!("{e}"))?
                .label(label)
                .legend(legend);
        } else {
            chart
                .draw_series(LineSeries::new(points.clone(), style))
                .map_err(|e| anyhow!("{e}"))?
                .label(label)
                .legend(legend);
        }
        chart
            .draw_series(points.iter().map(|&p| Circle::new(p, 3, colour.filled())))
            .map_err(|e| anyhow!("{e}"))?;
        // The curve ends at the collapse (its last point): a cross marks it.
        if let (Some(Breakdown::Collapse { .. }), Some(&end)) = (curve.breakdown(), points.last()) {
            let drawn = chart
                .draw_series([Cross::new(end, 10, colour.stroke_width(4))])
                .map_err(|e| anyhow!("{e}"))?;
            if !collapse_legend {
                collapse_legend = true;
                drawn
                    .label("inelastic collapse: the event method stops")
                    .legend(|(x, y)| Cross::new((x + 10, y), 7, BLACK.stroke_width(3)));
            }
        }
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperRight, 13)?;
    Ok(())
}
