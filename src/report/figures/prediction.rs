//! The predicted scaling: weak and strong efficiency against ranks up to 10⁴, each a
//! band (shaded) around its middle (line), the measured configurations (filled marks)
//! and the model's values for them as they ran (crosses), the assumptions as caption.

use anyhow::anyhow;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::report::figures::{Analysed, Chart, FONT, Link, PALETTE, draw_legend};
use crate::report::prediction::{MAX_RANKS, Predicted, Prediction, Scaling, assumptions};
use crate::system::output::Canvas;

/// The file report.md links.
pub const FILE_NAME: &str = "prediction.png";

const SIZE: (u32, u32) = (1000, 760);
/// Pixels under the plot for the caption.
const CAPTION_HEIGHT: u32 = 190;
/// Characters of a caption line at most (continuations are indented).
const CAPTION_CHARS: usize = 140;

pub struct PredictionChart<'a> {
    prediction: &'a Prediction,
}

impl<'a> Chart<'a> for PredictionChart<'a> {
    fn of(analysed: &Analysed<'a>) -> Vec<(Link, Self)> {
        analysed
            .prediction
            .map(|prediction| (Link::OwnSection, PredictionChart { prediction }))
            .into_iter()
            .collect()
    }

    fn file_name(&self) -> String {
        FILE_NAME.to_owned()
    }

    fn size(&self) -> (u32, u32) {
        SIZE
    }

    fn draw(&self, canvas: &Canvas<'_>) -> anyhow::Result<()> {
        canvas.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
        let (plot, caption) = canvas.split_vertically(SIZE.1 - CAPTION_HEIGHT);
        let top = self
            .prediction
            .weak
            .iter()
            .chain(&self.prediction.strong)
            .map(|p| p.high)
            .chain(self.prediction.measured.iter().map(|e| e.measured.max(e.modelled)))
            .fold(1.0_f64, f64::max)
            .min(2.0)
            * 1.05;
        let mut chart = ChartBuilder::on(&plot)
            .caption(
                "Predicted efficiency (a model: bands) and measured (marks)",
                (FONT, 22),
            )
            .margin(16)
            .x_label_area_size(50)
            .y_label_area_size(70)
            .build_cartesian_2d((1.0..MAX_RANKS as f64 * 1.2).log_scale(), 0.0..top)
            .map_err(|e| anyhow!("{e}"))?;
        chart
            .configure_mesh()
            .x_desc("ranks P")
            .y_desc("parallel efficiency")
            .axis_desc_style((FONT, 17))
            .label_style((FONT, 14))
            .light_line_style(BLACK.mix(0.04))
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| format!("{:.0}%", 100.0 * y))
            .draw()
            .map_err(|e| anyhow!("{e}"))?;
        for (scaling, curve, colour, name) in [
            (Scaling::Weak, &self.prediction.weak, PALETTE[0], "weak"),
            (Scaling::Strong, &self.prediction.strong, PALETTE[1], "strong"),
        ] {
            draw_band(&mut chart, curve, colour, name)?;
            let points: Vec<_> = self
                .prediction
                .measured
                .iter()
                .filter(|e| e.scaling == scaling)
                .collect();
            chart
                .draw_series(
                    points
                        .iter()
                        .map(|e| Circle::new((e.ranks as f64, e.measured), 6, colour.filled())),
                )
                .map_err(|e| anyhow!("{e}"))?
                .label(format!("{name}: measured here"))
                .legend(move |(x, y)| Circle::new((x + 10, y), 6, colour.filled()));
            chart
                .draw_series(points.iter().map(|e| {
                    Cross::new((e.ranks as f64, e.modelled), 7, colour.stroke_width(2))
                }))
                .map_err(|e| anyhow!("{e}"))?
                .label(format!("{name}: model, as the runs ran here"))
                .legend(move |(x, y)| Cross::new((x + 10, y), 6, colour.stroke_width(2)));
        }
        draw_legend(&mut chart, SeriesLabelPosition::UpperRight, 13)?;
        let style = TextStyle::from((FONT, 13)).color(&BLACK);
        let lines = std::iter::once("Assumptions:".to_owned()).chain(
            assumptions(self.prediction)
                .into_iter()
                .flat_map(|a| wrapped(&format!("– {a}"), CAPTION_CHARS)),
        );
        for (i, line) in lines.enumerate() {
            caption
                .draw_text(&line, &style, (20, 4 + 17 * i as i32))
                .map_err(|e| anyhow!("{e}"))?;
        }
        Ok(())
    }
}

/// `text` cut at spaces into lines of at most `width` characters (a longer word stays
/// whole); lines after the first are indented.
fn wrapped(text: &str, width: usize) -> Vec<String> {
    let mut lines = vec![String::new()];
    for word in text.split(' ') {
        let line = lines.last_mut().expect("lines start with one");
        if !line.trim().is_empty() && line.chars().count() + 1 + word.chars().count() > width {
            lines.push(format!("   {word}"));
        } else {
            if !line.is_empty() {
                line.push(' ');
            }
            line.push_str(word);
        }
    }
    lines
}

type Plot<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<LogCoord<f64>, RangedCoordf64>>;

/// A curve's band shaded between its low and high ends, its middle as a line.
fn draw_band(
    chart: &mut Plot<'_, '_>,
    curve: &[Predicted],
    colour: RGBColor,
    name: &str,
) -> anyhow::Result<()> {
    let outline: Vec<(f64, f64)> = curve
        .iter()
        .map(|p| (p.ranks as f64, p.high))
        .chain(curve.iter().rev().map(|p| (p.ranks as f64, p.low)))
        .collect();
    chart
        .draw_series([Polygon::new(outline, colour.mix(0.18).filled())])
        .map_err(|e| anyhow!("{e}"))?;
    chart
        .draw_series(LineSeries::new(
            curve.iter().map(|p| (p.ranks as f64, p.mid)),
            colour.stroke_width(2),
        ))
        .map_err(|e| anyhow!("{e}"))?
        .label(format!("{name}: predicted, band and middle"))
        .legend(move |(x, y)| {
            Rectangle::new([(x, y - 5), (x + 20, y + 5)], colour.mix(0.4).filled())
        });
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::wrapped;

    #[test]
    fn caption_lines_break_at_spaces_and_continuations_are_indented() {
        assert_eq!(wrapped("a bb ccc", 4), ["a bb", "   ccc"]);
        assert_eq!(wrapped("longword x", 4), ["longword", "   x"]);
    }
}
