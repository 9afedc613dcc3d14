//! The e < 1 cooling figure: T/T₀ against t/t₀ of every cooling curve (one panel per
//! packing, one line per method, TC time and dt, dashed where it broke down, a cross
//! where the event method collapsed) with Haff's law 1/(1 + t/t₀)² in black.

use anyhow::anyhow;
use plotters::prelude::*;

use crate::report::accuracy::{Breakdown, CoolingCurve, method_label};
use crate::report::figures::{Chart, FONT, PALETTE, draw_legend, titled_canvas};
use crate::system::output::Canvas;

/// The figure of an accuracy study's cooling curves.
pub struct Cooling<'a>(pub &'a [CoolingCurve]);

impl Chart for Cooling<'_> {
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
