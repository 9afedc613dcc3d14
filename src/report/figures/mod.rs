//! The report's figures (PNG, plotters), one file per figure behind one interface,
//! [`Chart`]: the scaling figures of each setup (`scaling`: time, speedup, efficiency and
//! steps per second against workers), the accuracy study's (`pareto`, `stability`,
//! `cooling`) and the check history's (`history`). Shared here: the embedded font (DejaVu Sans, so no system font is
//! needed), the palette, the legend and the titled canvas.
//!
//! A new figure is a file with a type that implements [`Chart`], and one line in the
//! list that draws it ([`accuracy_charts`] for the accuracy study's).

pub mod cooling;
pub mod history;
pub mod pareto;
pub mod scaling;
pub mod stability;

use std::path::{Path, PathBuf};
use std::sync::Once;

use anyhow::anyhow;
use plotters::coord::CoordTranslate;
use plotters::prelude::*;

use crate::report::accuracy::PackingGroup;
use crate::system::output::{Canvas, write_png};

/// One figure of a report: a PNG beside report.md.
pub trait Chart {
    /// Its file name in the report folder.
    fn file_name(&self) -> String;
    /// Its size in pixels (width, height).
    fn size(&self) -> (u32, u32);
    /// Draws it on a blank canvas of [`Chart::size`].
    fn draw(&self, canvas: &Canvas<'_>) -> anyhow::Result<()>;
}

/// Draws `chart` into `dir` (atomically); returns its path.
pub fn write(chart: &dyn Chart, dir: &Path) -> anyhow::Result<PathBuf> {
    register_font();
    let path = dir.join(chart.file_name());
    write_png(&path, chart.size(), |canvas| chart.draw(canvas))?;
    Ok(path)
}

/// The accuracy study's figures of speed against accuracy, in the order the report
/// shows them.
pub fn accuracy_charts(groups: &[PackingGroup]) -> Vec<Box<dyn Chart + '_>> {
    vec![
        Box::new(pareto::Pareto(groups)),
        Box::new(stability::Stability(groups)),
    ]
}

pub(crate) const FONT: &str = "sans-serif";

/// The palette of series: backends, or the accuracy study's packings by index.
pub(crate) const PALETTE: [RGBColor; 4] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xd6, 0x27, 0x28),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0x33, 0x33, 0x33),
];

/// DejaVu Sans (assets/DejaVuSans-LICENSE.txt), embedded once for figures and the live view.
pub(crate) const FONT_BYTES: &[u8] = include_bytes!("../../../assets/DejaVuSans.ttf");

pub(crate) fn register_font() {
    static FONT_ONCE: Once = Once::new();
    FONT_ONCE.call_once(|| {
        // The embedded font is valid; failing here would be a build defect.
        plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES)
            .unwrap_or_else(|_| panic!("the embedded DejaVu Sans is a valid font"));
    });
}

/// Errors of exactly 0 are drawn at this floor of the accuracy figures' log axes.
const ERROR_FLOOR: f64 = 1e-5;

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

/// The series labels of every figure: framed, on a translucent white, at `position`.
pub(crate) fn draw_legend<'a, DB, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
    font_size: u32,
) -> anyhow::Result<()>
where
    DB: DrawingBackend + 'a,
    CT: CoordTranslate,
{
    chart
        .configure_series_labels()
        .position(position)
        .label_font((FONT, font_size))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(|e| anyhow!("{e}"))
}
