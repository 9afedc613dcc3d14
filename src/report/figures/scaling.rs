//! The scaling figures of one setup: time, speedup, efficiency and steps per second
//! against workers, and for runs that drew every step the frames per second with
//! drawing beside their steps per second; one colour per backend in every figure,
//! backends at one worker count side by side, error bars from the repetitions, log axes
//! (efficiency, a fraction, on a linear one), titles that name the setup.

use std::path::{Path, PathBuf};

use anyhow::anyhow;
use plotters::coord::combinators::WithKeyPoints;
use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::report::analysis::{BackendScaling, Setup};
use crate::report::figures::{Analysed, Chart, FONT, Link, PALETTE, draw_legend, write};
use crate::report::units::significant;
use crate::run::backend_kind::BackendKind;
use crate::study::manifest::Scaling;
use crate::system::output::Canvas;

const SIZE: (u32, u32) = (900, 560);

/// What a figure plots against workers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Figure {
    /// Median seconds per run, min–max bars (the seed's Figure 6).
    Time,
    /// S(p), with the ideal S = p.
    Speedup,
    /// E(p), with the 75% line the findings use.
    Efficiency,
    /// Median steps per second, nothing drawn.
    Fps,
    /// Median frames per second with drawing (the seed's Figure 5), beside the same runs'
    /// steps per second without it (dashed); only for runs that drew every step.
    Drawing,
}

impl Figure {
    pub const ALL: [Figure; 5] = [
        Figure::Time,
        Figure::Speedup,
        Figure::Efficiency,
        Figure::Fps,
        Figure::Drawing,
    ];

    /// Whether `setup` has anything to show in this figure.
    pub fn shows(self, setup: &Setup) -> bool {
        self != Figure::Drawing || setup.drawn
    }

    pub fn file_stem(self) -> &'static str {
        match self {
            Figure::Time => "time",
            Figure::Speedup => "speedup",
            Figure::Efficiency => "efficiency",
            Figure::Fps => "steps-per-s",
            Figure::Drawing => "fps-drawing",
        }
    }

    fn title(self) -> &'static str {
        match self {
            Figure::Time => "Time per run",
            Figure::Speedup => "Speedup",
            Figure::Efficiency => "Parallel efficiency",
            Figure::Fps => "Steps per second",
            Figure::Drawing => "Frames per second with drawing",
        }
    }

    fn axis(self, scaling: Scaling) -> &'static str {
        match (self, scaling) {
            (Figure::Time, _) => "seconds per run (median, min–max)",
            (Figure::Speedup, Scaling::Strong) => "speedup S(p) = T(baseline) / T(p)",
            (Figure::Speedup, Scaling::Weak) => "scaled speedup p·E(p)",
            (Figure::Efficiency, Scaling::Strong) => "efficiency E(p) = S(p) / p",
            (Figure::Efficiency, Scaling::Weak) => "weak efficiency T(1, N₀) / T(p, p·N₀)",
            (Figure::Fps, _) => "steps per second (median)",
            (Figure::Drawing, _) => "per second (median): frames drawn, steps (dashed)",
        }
    }

    /// Where strong-scaling curves leave room: time rises and speedup stays below the
    /// ideal line on the right; efficiency and steps per second start high on the left.
    fn legend_position(self) -> SeriesLabelPosition {
        match self {
            Figure::Time | Figure::Speedup => SeriesLabelPosition::UpperLeft,
            Figure::Efficiency | Figure::Fps => SeriesLabelPosition::LowerLeft,
            // Frames with drawing below, steps without it above: the middle is free.
            Figure::Drawing => SeriesLabelPosition::MiddleRight,
        }
    }

    /// (low, median, high) of one point.
    fn values(self, point: &crate::report::analysis::Point) -> (f64, f64, f64) {
        match self {
            Figure::Time => (point.min_s, point.median_s, point.max_s),
            Figure::Speedup => (point.speedup, point.speedup, point.speedup),
            Figure::Efficiency => (point.efficiency, point.efficiency, point.efficiency),
            Figure::Fps => (point.fps, point.fps, point.fps),
            Figure::Drawing => {
                let fps = point.fps_with_drawing;
                (fps, fps, fps)
            }
        }
    }

    /// The values drawn dashed beside this figure's, from the same runs: the step rate
    /// without drawing beside the frame rate with it.
    fn beside(self, point: &crate::report::analysis::Point) -> Option<f64> {
        (self == Figure::Drawing).then_some(point.fps)
    }
}

/// One scaling figure of one setup, drawn as `<prefix>-<figure>.png`.
pub struct ScalingChart<'a> {
    pub figure: Figure,
    pub setup: &'a Setup,
    pub prefix: String,
}

impl<'a> Chart<'a> for ScalingChart<'a> {
    /// The figures of every setup that scales, as `setup-<n>-<figure>.png` (n counts the
    /// study's setups from 1), linked under the setup's tables.
    fn of(analysed: &Analysed<'a>) -> Vec<(Link, Self)> {
        analysed
            .setups
            .iter()
            .enumerate()
            // One backend at one worker count has no scaling to draw (e.g. accuracy studies).
            .filter(|(_, setup)| setup.scales())
            .flat_map(|(index, setup)| {
                charts(setup, format!("setup-{}", index + 1)).map(move |chart| {
                    let figure = chart.figure;
                    (Link::Setup { index, figure }, chart)
                })
            })
            .collect()
    }

    fn file_name(&self) -> String {
        format!("{}-{}.png", self.prefix, self.figure.file_stem())
    }

    fn size(&self) -> (u32, u32) {
        SIZE
    }

    fn draw(&self, canvas: &Canvas<'_>) -> anyhow::Result<()> {
        draw(self.figure, self.setup, canvas)
    }
}

/// The figures `setup` shows ([`Figure::shows`]), in [`Figure::ALL`]'s order, named
/// `<prefix>-<figure>.png`.
fn charts(setup: &Setup, prefix: String) -> impl Iterator<Item = ScalingChart<'_>> {
    Figure::ALL
        .into_iter()
        .filter(|figure| figure.shows(setup))
        .map(move |figure| ScalingChart {
            figure,
            setup,
            prefix: prefix.clone(),
        })
}

/// Draws every figure of `setup` into `dir` as `<prefix>-<figure>.png`, whether or not
/// it scales; returns the paths.
pub fn draw_setup(
    setup: &Setup,
    dir: &Path,
    prefix: &str,
) -> anyhow::Result<Vec<(Figure, PathBuf)>> {
    charts(setup, prefix.to_owned())
        .map(|chart| Ok((chart.figure, write(&chart, dir)?)))
        .collect()
}

/// One colour per backend, the same in every figure.
fn colour(backend: &BackendScaling) -> RGBColor {
    let base = match BackendKind::from_name(&backend.backend) {
        Some(BackendKind::Serial) => PALETTE[3],
        Some(BackendKind::Rayon) => PALETTE[0],
        Some(BackendKind::Mpi) => PALETTE[1],
        None => PALETTE[2],
    };
    // Each doubling of the nodes moves the colour halfway further toward the palette's
    // spare colour, and each doubling of the threads per rank lightens it, so that a
    // backend's curves stay apart and of one family (darker would run into serial's
    // near-black).
    let toward = PALETTE[2];
    let moved = 0.5f64.powi(backend.nodes.max(1).ilog2() as i32);
    let kept = 0.6f64.powi(backend.threads_per_rank.max(1).ilog2() as i32);
    let shade = |channel: u8, spare: u8| {
        let mixed = f64::from(spare) + (f64::from(channel) - f64::from(spare)) * moved;
        (255.0 - (255.0 - mixed) * kept).round() as u8
    };
    RGBColor(
        shade(base.0, toward.0),
        shade(base.1, toward.1),
        shade(base.2, toward.2),
    )
}

/// Ticks of a log axis over `low..high`: the first of these mantissas times the powers
/// of ten that gives at least [`MIN_TICKS`] ticks and at most [`MAX_LOG_TICKS`] (the
/// finest that does not exceed it, when none gives both), so that a range narrower than
/// a decade still gets several labels and a wide one is not crowded.
fn log_ticks(low: f64, high: f64) -> Vec<f64> {
    const MANTISSAS: [&[f64]; 4] = [
        &[1.0],
        &[1.0, 2.0, 5.0],
        &[1.0, 1.5, 2.0, 3.0, 5.0, 7.0],
        &[1.0, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0],
    ];
    let ticks_of = |mantissas: &[f64]| {
        let mut ticks = Vec::new();
        let mut decade = 10_f64.powf(low.log10().floor());
        while decade <= high {
            let in_range = mantissas.iter().map(|m| m * decade).filter(|t| (low..=high).contains(t));
            ticks.extend(in_range);
            decade *= 10.0;
        }
        ticks
    };
    let mut fitting = Vec::new();
    for mantissas in MANTISSAS {
        let ticks = ticks_of(mantissas);
        if ticks.len() > MAX_LOG_TICKS && !fitting.is_empty() {
            break;
        }
        fitting = ticks;
        if fitting.len() >= MIN_TICKS {
            break;
        }
    }
    fitting
}

const MIN_TICKS: usize = 4;
/// The narrowest log value axis, high over low: wide enough for [`MIN_TICKS`] labels.
const MIN_LOG_RATIO: f64 = 3.0;
const MAX_LOG_TICKS: usize = 12;

fn draw(figure: Figure, setup: &Setup, root: &Canvas<'_>) -> anyhow::Result<()> {
    let backends: Vec<&BackendScaling> = setup
        .backends
        .iter()
        .filter(|b| b.points.iter().any(|p| figure.values(p).1.is_finite()))
        .collect();
    let mut workers: Vec<u64> = backends
        .iter()
        .flat_map(|b| b.points.iter().map(|p| p.workers))
        .collect();
    workers.sort_unstable();
    workers.dedup();
    let max_workers = workers.last().copied().unwrap_or(1).max(2) as f64;
    let (y_low, y_high) = y_range(figure, &backends, max_workers);
    root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
    // Ticks at the measured worker counts: a log axis' own ticks skip most of them.
    let x_ticks: Vec<f64> = workers.iter().map(|&p| p as f64).collect();
    let x = (0.8_f64..max_workers * 1.25)
        .log_scale()
        .with_key_points(x_ticks);
    let plot = Plot {
        figure,
        setup,
        backends: &backends,
        max_workers,
    };
    match figure {
        // A fraction of the ideal, read against 100% and the 75% line: linear from 0.
        Figure::Efficiency => {
            let y: RangedCoordf64 = (y_low..y_high).into();
            plot.draw(root, x, y, &|y| format!("{:.0}%", 100.0 * y))
        }
        _ => {
            let y = (y_low..y_high)
                .log_scale()
                .with_key_points(log_ticks(y_low, y_high));
            plot.draw(root, x, y, &|y| significant(*y, 3))
        }
    }
}

/// The title of `figure` for `setup`: what it plots, then the setup's scene and every
/// value that tells it from the study's other setups (n, packing, steps, dt, settings).
fn caption(figure: Figure, setup: &Setup) -> String {
    let n = match setup.scaling {
        Scaling::Strong => format!("n = {}", setup.n),
        Scaling::Weak => format!("n = {} per worker", setup.n),
    };
    let mut words = vec![
        n,
        format!("packing {}", significant(setup.packing, 3)),
        format!("{} steps of dt {}", setup.steps, significant(setup.dt, 3)),
    ];
    words.extend(setup.settings.iter().cloned());
    format!("{}: {}, {}", figure.title(), setup.scene, words.join(", "))
}

/// One scaling figure's content, drawn on either kind of value axis.
struct Plot<'s> {
    figure: Figure,
    setup: &'s Setup,
    backends: &'s [&'s BackendScaling],
    max_workers: f64,
}

impl Plot<'_> {
    fn draw<Y>(
        &self,
        root: &Canvas<'_>,
        x: WithKeyPoints<LogCoord<f64>>,
        y: Y,
        y_label: &dyn Fn(&f64) -> String,
    ) -> anyhow::Result<()>
    where
        Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
    {
        let figure = self.figure;
        let mut chart = ChartBuilder::on(root)
            .caption(caption(figure, self.setup), (FONT, 20))
            .margin(16)
            .x_label_area_size(50)
            .y_label_area_size(80)
            .build_cartesian_2d(x, y)
            .map_err(|e| anyhow!("{e}"))?;
        chart
            .configure_mesh()
            .x_desc(
                "workers (threads, ranks or ranks × threads, log scale; curves side by side at \
                 each count)",
            )
            .y_desc(figure.axis(self.setup.scaling))
            .axis_desc_style((FONT, 18))
            .label_style((FONT, 15))
            .light_line_style(BLACK.mix(0.04))
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(y_label)
            .draw()
            .map_err(|e| anyhow!("{e}"))?;
        draw_reference(&mut chart, figure, self.max_workers)?;
        for (index, backend) in self.backends.iter().enumerate() {
            let shift = dodge(index, self.backends.len());
            draw_backend(&mut chart, figure, backend, shift)?;
        }
        draw_legend(&mut chart, figure.legend_position(), 15)
    }
}

/// The factor backend `index` of `count` multiplies its worker counts by, so that points
/// of several backends at one count stand side by side instead of on top of each other
/// (a fixed distance on the log axis).
fn dodge(index: usize, count: usize) -> f64 {
    DODGE.powf(index as f64 - (count.max(1) - 1) as f64 / 2.0)
}

/// The ratio between neighbouring backends' positions at one worker count.
const DODGE: f64 = 1.04;

/// The value axis of a figure over `backends`: every drawn value, with room above and
/// below (the ideal speedup up to `max_workers`, and 100% efficiency, always show).
fn y_range(figure: Figure, backends: &[&BackendScaling], max_workers: f64) -> (f64, f64) {
    let (mut low, mut high) = backends
        .iter()
        .flat_map(|b| b.points.iter())
        .flat_map(|p| {
            let (low, mid, high) = figure.values(p);
            [low, mid, high, figure.beside(p).unwrap_or(f64::NAN)]
        })
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, 0.0_f64), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !low.is_finite() {
        (low, high) = (0.1, 1.0);
    }
    match figure {
        // The ideal line reaches p.
        Figure::Speedup => high = high.max(max_workers),
        // A linear axis from 0 to a little above 100% (or the highest efficiency).
        Figure::Efficiency => return (0.0, high.max(1.0) * 1.1),
        _ => {}
    }
    let (low, high) = (low / 1.5, high * 1.5);
    // Wide enough for four tick labels (see `log_ticks`).
    let widen = (MIN_LOG_RATIO / (high / low)).max(1.0).sqrt();
    (low / widen, high * widen)
}

/// The reference line of a figure: the ideal speedup S = p, or 75% efficiency.
fn draw_reference<Y: Ranged<ValueType = f64>>(
    chart: &mut Chart2d<'_, '_, Y>,
    figure: Figure,
    max_workers: f64,
) -> anyhow::Result<()> {
    let (line, label) = match figure {
        Figure::Speedup => ([(1.0, 1.0), (max_workers, max_workers)], "ideal S = p"),
        Figure::Efficiency => ([(0.8, 0.75), (max_workers * 1.25, 0.75)], "75%"),
        _ => return Ok(()),
    };
    chart
        .draw_series(LineSeries::new(line, BLACK.mix(0.4).stroke_width(1)))
        .map_err(|e| anyhow!("{e}"))?
        .label(label)
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.mix(0.4)));
    Ok(())
}

/// One backend's series: its values with their ranges, and the values drawn beside
/// them (dashed), in the backend's colour, each at its worker count times `shift`.
fn draw_backend<Y: Ranged<ValueType = f64>>(
    chart: &mut Chart2d<'_, '_, Y>,
    figure: Figure,
    backend: &BackendScaling,
    shift: f64,
) -> anyhow::Result<()> {
    let colour = colour(backend);
    let points: Vec<(f64, (f64, f64, f64))> = backend
        .points
        .iter()
        .map(|p| (p.workers as f64 * shift, figure.values(p)))
        .filter(|(_, (_, mid, _))| mid.is_finite() && *mid > 0.0)
        .collect();
    chart
        .draw_series(LineSeries::new(
            points.iter().map(|&(x, (_, mid, _))| (x, mid)),
            colour.stroke_width(2),
        ))
        .map_err(|e| anyhow!("{e}"))?
        .label(match figure {
            Figure::Drawing => format!("{}: frames/s with drawing", backend.label()),
            _ => backend.label(),
        })
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2)));
    let beside: Vec<(f64, f64)> = backend
        .points
        .iter()
        .filter_map(|p| Some((p.workers as f64 * shift, figure.beside(p)?)))
        .filter(|(_, value)| value.is_finite() && *value > 0.0)
        .collect();
    if !beside.is_empty() {
        chart
            .draw_series(DashedLineSeries::new(
                beside.iter().copied(),
                8,
                6,
                colour.stroke_width(2),
            ))
            .map_err(|e| anyhow!("{e}"))?
            .label(format!("{}: steps/s without drawing", backend.label()))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 8, y)], colour.stroke_width(2)));
        chart
            .draw_series(
                beside
                    .iter()
                    .map(|&point| Circle::new(point, 4, colour.stroke_width(2))),
            )
            .map_err(|e| anyhow!("{e}"))?;
    }
    chart
        .draw_series(
            points.iter().map(|&(x, (lo, mid, hi))| {
                ErrorBar::new_vertical(x, lo, mid, hi, colour.filled(), 8)
            }),
        )
        .map_err(|e| anyhow!("{e}"))?;
    chart
        .draw_series(
            points
                .iter()
                .map(|&(x, (_, mid, _))| Circle::new((x, mid), 4, colour.filled())),
        )
        .map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

/// The chart of a scaling figure: log workers against a value axis `Y`.
type Chart2d<'a, 'b, Y> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<WithKeyPoints<LogCoord<f64>>, Y>>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_ticks_label_narrow_ranges_and_thin_out_wide_ones() {
        let narrow = log_ticks(4.0, 25.0);
        for (tick, expected) in narrow.iter().zip([5.0, 7.0, 10.0, 15.0, 20.0]) {
            assert!((tick - expected).abs() < 1e-9, "{narrow:?}");
        }
        assert_eq!(narrow.len(), 5, "{narrow:?}");
        let wide = log_ticks(0.0015, 300.0);
        assert_eq!(wide.len(), 5, "{wide:?}");
        // Every range a figure draws, at least a factor of 3 wide ([`MIN_LOG_RATIO`]),
        // has at least four labels, and none more than twelve.
        for low in [0.9, 1.3, 4.4, 9.5, 13.0, 17.0, 19_000.0, 21_000.0, 0.00045] {
            for widening in [3.0, 4.5, 10.0, 100.0, 5000.0, 1e5] {
                let ticks = log_ticks(low, low * widening);
                assert!((MIN_TICKS..=MAX_LOG_TICKS).contains(&ticks.len()), "{low}: {ticks:?}");
            }
        }
    }

    #[test]
    fn backends_at_one_worker_count_stand_apart_and_efficiency_is_linear_from_zero() {
        assert_eq!(dodge(0, 1), 1.0);
        assert!(dodge(0, 2) < 1.0 && dodge(1, 2) > 1.0);
        assert!((dodge(0, 3) * dodge(2, 3) - 1.0).abs() < 1e-12);
        let (low, high) = y_range(Figure::Efficiency, &[], 4.0);
        assert_eq!(low, 0.0);
        assert!((1.0..1.2).contains(&high), "{high}");
    }

    #[test]
    fn a_title_names_the_setup_and_what_tells_it_apart() {
        let setup = Setup {
            scene: "gas".into(),
            scaling: Scaling::Strong,
            n: 100_000,
            steps: 100,
            dt: 0.02264154330493038,
            packing: 0.4,
            broadphase: "grid".into(),
            drawn: false,
            settings: vec!["tc=0".into()],
            backends: Vec::new(),
            distinct_hashes: 1,
        };
        assert_eq!(
            caption(Figure::Speedup, &setup),
            "Speedup: gas, n = 100000, packing 0.4, 100 steps of dt 0.0226, tc=0"
        );
    }
}
