//! The e < 1 cooling figure: T/T₀ against t/t₀ of every cooling curve (one panel per
//! packing, one line per method, TC time and dt, dashed where it broke down, a cross
//! where the event method collapsed) with Haff's law 1/(1 + t/t₀)² in black.

use anyhow::anyhow;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::report::accuracy::{Breakdown, CoolingCurve, method_label};
use crate::report::figures::{Analysed, Chart, FONT, Link, PALETTE, draw_legend, titled_canvas};
use crate::system::output::Canvas;

/// The figure of an accuracy study's cooling curves.
pub struct Cooling<'a>(pub &'a [CoolingCurve]);

impl<'a> Chart<'a> for Cooling<'a> {
    /// One figure when the study has cooling curves, linked in the cooling section.
    fn of(analysed: &Analysed<'a>) -> Vec<(Link, Self)> {
        match analysed.cooling {
            [] => Vec::new(),
            curves => vec![(Link::OwnSection, Cooling(curves))],
        }
    }

    fn file_name(&self) -> String {
        COOLING_FILE.to_owned()
    }

    fn size(&self) -> (u32, u32) {
        COOLING_SIZE
    }

    fn draw(&self, canvas: &Canvas<'_>) -> anyhow::Result<()> {
        plot_cooling(self.0, canvas)
    }
}

/// File name of the e < 1 cooling figure.
pub const COOLING_FILE: &str = "accuracy-cooling.png";
const COOLING_SIZE: (u32, u32) = (1400, 620);

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

/// A panel: t/t₀ against T/T₀, both linear.
type Panel<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The points of `curve` as drawn: (t/t₀, T/T₀), the finite ones with T > 0.
fn scaled(curve: &CoolingCurve) -> Vec<(f64, f64)> {
    let t_zero = curve.points[0][1];
    curve
        .points
        .iter()
        .map(|&[t, temperature]| (t / curve.haff_t0, temperature / t_zero))
        .filter(|&(x, y)| x.is_finite() && y.is_finite() && y > 0.0)
        .collect()
}

fn plot_cooling_panel(
    panel: &Canvas<'_>,
    packing: f64,
    curves: &[&CoolingCurve],
) -> anyhow::Result<()> {
    let x_high = curves
        .iter()
        .flat_map(|c| scaled(c).into_iter().map(|(x, _)| x))
        .fold(0.0_f64, f64::max)
        .max(0.1);
    let mut chart = panel_axes(panel, packing, x_high)?;
    draw_haff(&mut chart, x_high)?;
    let mut collapse_legend = false;
    for (index, curve) in curves.iter().enumerate() {
        let colour = COOLING_COLOURS[index % COOLING_COLOURS.len()];
        let collapsed = draw_curve(&mut chart, curve, colour)?;
        // The curve ends at the collapse (its last point): a cross marks it, once in the
        // legend.
        if let Some(end) = collapsed {
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

/// A panel's axes and mesh: t/t₀ up to `x_high`, T/T₀ up to 1.05.
fn panel_axes<'a, 'b>(
    panel: &'a Canvas<'b>,
    packing: f64,
    x_high: f64,
) -> anyhow::Result<Panel<'a, 'b>> {
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
    Ok(chart)
}

/// Haff's law 1/(1 + t/t₀)² up to `x_high`, in black.
fn draw_haff(chart: &mut Panel<'_, '_>, x_high: f64) -> anyhow::Result<()> {
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
    Ok(())
}

/// One run's curve in `colour`, dashed when it broke down, its points marked; returns
/// its last point when the run ended in a collapse.
fn draw_curve(
    chart: &mut Panel<'_, '_>,
    curve: &CoolingCurve,
    colour: RGBColor,
) -> anyhow::Result<Option<(f64, f64)>> {
    let points = scaled(curve);
    let label = curve_label(curve, &points);
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
    let collapsed = matches!(curve.breakdown(), Some(Breakdown::Collapse { .. }));
    Ok(points.last().copied().filter(|_| collapsed))
}

/// A run's legend entry: its method and step, whether and when the unguarded event run
/// collapsed, and its largest deviation from Haff's law.
fn curve_label(curve: &CoolingCurve, points: &[(f64, f64)]) -> String {
    let step = if curve.method == "event" {
        "exact".to_owned()
    } else {
        format!("v_rms·dt/r = {:.3}", curve.step_over_radius)
    };
    let t_end = points.last().map_or(0.0, |p| p.0);
    let outcome = match curve.breakdown() {
        Some(Breakdown::Collapse { time }) => {
            format!(": collapsed at t/t₀ = {:.3}", time / curve.haff_t0)
        }
        _ if curve.tc == 0.0 => format!(": no collapse by t/t₀ = {t_end:.3}"),
        _ => String::new(),
    };
    format!(
        "{} ({step}){outcome}, max |T/T_Haff − 1| = {:.1}%",
        method_label(&curve.method, curve.tc),
        100.0 * curve.haff_deviation
    )
}
