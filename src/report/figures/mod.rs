//! The report's figures (PNG, plotters), one file per figure behind one interface,
//! [`Chart`]: the scaling figures of each setup (`scaling`: time, speedup, efficiency and
//! steps per second against workers), the accuracy study's (`pareto`, `stability`,
//! `cooling`), the check history's (`history`) and the scaling prediction's
//! (`prediction`). Which figures a report gets is decided
//! here, not by its caller: [`draw`] asks each figure type of the list which of the
//! analysed data it applies to, draws those, and says what it drew for report.md to link.
//! Shared here too: the embedded font (DejaVu Sans, so no system font is needed), the
//! palette, the legend and the titled canvas. What the figures show is computed by the
//! analysis (`report::analysis`, `report::accuracy`); report.md is `report::markdown`'s.
//!
//! A new figure is a file with a type that implements [`Chart`], and one line in the
//! `figures!` list below.

use std::path::{Path, PathBuf};
use std::sync::Once;

use anyhow::anyhow;
use plotters::coord::CoordTranslate;
use plotters::prelude::*;

use crate::report::accuracy::{CoolingCurve, PackingGroup};
use crate::report::analysis::Setup;
use crate::report::prediction::Prediction;
use crate::study::history::Entry;
use crate::system::output::{Canvas, write_png};

/// Declares the figure modules of the list and `every_chart`, which asks each of their
/// types in turn (the list's order) which figures apply.
macro_rules! figures {
    ($($module:ident::$chart:ident),+ $(,)?) => {
        $(pub mod $module;)+

        /// Every figure that `analysed` gets, with where report.md links it.
        fn every_chart<'a>(analysed: &Analysed<'a>) -> Vec<(Link, Box<dyn Chart<'a> + 'a>)> {
            let mut charts: Vec<(Link, Box<dyn Chart<'a> + 'a>)> = Vec::new();
            $(
                for (link, chart) in $module::$chart::of(analysed) {
                    charts.push((link, Box::new(chart)));
                }
            )+
            charts
        }
    };
}

// Every figure type, one line each: its file (module) and the type in it that implements
// `Chart`. A report's figures are drawn in this order.
figures! {
    scaling::ScalingChart,
    pareto::Pareto,
    stability::Stability,
    cooling::Cooling,
    history::History,
    prediction::PredictionChart,
}

/// What figures are drawn from: a study's analysed records, or a check history.
#[derive(Clone, Copy, Default)]
pub struct Analysed<'a> {
    /// The study's setups ([`crate::report::analysis::analyse`]), in the manifest's order.
    pub setups: &'a [Setup],
    /// An accuracy study's packing groups ([`crate::report::accuracy::analyse`]); `None`
    /// for any other study.
    pub accuracy: Option<&'a [PackingGroup]>,
    /// The e < 1 runs' cooling curves ([`crate::report::accuracy::cooling`]); empty for
    /// elastic studies.
    pub cooling: &'a [CoolingCurve],
    /// A check history's entries, oldest check first; `None` for a study.
    pub history: Option<&'a [Entry]>,
    /// The study's scaling prediction ([`crate::report::prediction::predict`]), if it has
    /// MPI runs to predict from.
    pub prediction: Option<&'a Prediction>,
}

/// Where report.md links a figure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Link {
    /// Under the tables of the setup at `index` (in [`Analysed::setups`]), as its `figure`.
    Setup {
        index: usize,
        figure: scaling::Figure,
    },
    /// In the accuracy section's list of figures.
    Accuracy,
    /// By its file name, in a section of its own (the cooling curves, the check history).
    OwnSection,
}

/// One figure of a report: a PNG beside report.md.
pub trait Chart<'a> {
    /// The figures of this type that `analysed` gets, in the order report.md shows them,
    /// each with where report.md links it; none when the type does not apply.
    fn of(analysed: &Analysed<'a>) -> Vec<(Link, Self)>
    where
        Self: Sized;
    /// Its file name in the report folder.
    fn file_name(&self) -> String;
    /// Its size in pixels (width, height).
    fn size(&self) -> (u32, u32);
    /// Draws it on a blank canvas of [`Chart::size`].
    fn draw(&self, canvas: &Canvas<'_>) -> anyhow::Result<()>;
}

/// What [`draw`] drew, in the order drawn: each figure's file name (relative to the
/// report) and where report.md links it.
#[derive(Clone, Debug, Default)]
pub struct Drawn(pub Vec<(Link, String)>);

impl Drawn {
    /// The figures of each of the first `n_setups` setups, in the order drawn (the
    /// shape of [`crate::report::markdown::Pictures::figures`]).
    pub fn by_setup(&self, n_setups: usize) -> Vec<Vec<(scaling::Figure, String)>> {
        (0..n_setups)
            .map(|setup| {
                self.0
                    .iter()
                    .filter_map(|(link, name)| match *link {
                        Link::Setup { index, figure } if index == setup => {
                            Some((figure, name.clone()))
                        }
                        _ => None,
                    })
                    .collect()
            })
            .collect()
    }

    /// The figures of the accuracy section's list, in the order drawn.
    pub fn accuracy(&self) -> Vec<String> {
        self.0
            .iter()
            .filter(|(link, _)| *link == Link::Accuracy)
            .map(|(_, name)| name.clone())
            .collect()
    }
}

/// Draws every figure that `analysed` gets into `dir` (each atomically), in the list's
/// order; returns what it drew.
pub fn draw(analysed: &Analysed<'_>, dir: &Path) -> anyhow::Result<Drawn> {
    every_chart(analysed)
        .into_iter()
        .map(|(link, chart)| {
            write(chart.as_ref(), dir)?;
            Ok((link, chart.file_name()))
        })
        .collect::<anyhow::Result<_>>()
        .map(Drawn)
}

/// Draws `chart` into `dir` (atomically); returns its path.
pub fn write(chart: &dyn Chart<'_>, dir: &Path) -> anyhow::Result<PathBuf> {
    register_font();
    let path = dir.join(chart.file_name());
    write_png(&path, chart.size(), |canvas| chart.draw(canvas))?;
    Ok(path)
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
