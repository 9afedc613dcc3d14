//! The accuracy study's stability map: v_rms·dt/r × packing, coloured by the
//! missed-collision fraction, with the failure boundary.

use anyhow::anyhow;
use plotters::coord::ranged1d::SegmentedCoord;
use plotters::coord::types::RangedCoordusize;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::report::accuracy::{AccuracyPoint, FAILURE_MISSED_FRACTION, PackingGroup};
use crate::report::figures::{Analysed, Chart, ERROR_FLOOR, FONT, Link, titled_canvas};
use crate::system::output::Canvas;

/// File name of the figure.
pub const STABILITY_FILE: &str = "accuracy-stability.png";
const STABILITY_SIZE: (u32, u32) = (1100, 560);

/// The figure of an accuracy study's packing groups.
pub struct Stability<'a>(pub &'a [PackingGroup]);

impl<'a> Chart<'a> for Stability<'a> {
    /// One figure for an accuracy study, listed in its accuracy section.
    fn of(analysed: &Analysed<'a>) -> Vec<(Link, Self)> {
        analysed
            .accuracy
            .map(|groups| (Link::Accuracy, Stability(groups)))
            .into_iter()
            .collect()
    }

    fn file_name(&self) -> String {
        STABILITY_FILE.to_owned()
    }

    fn size(&self) -> (u32, u32) {
        STABILITY_SIZE
    }

    fn draw(&self, canvas: &Canvas<'_>) -> anyhow::Result<()> {
        draw_stability(self.0, canvas)
    }
}

/// The map: one segment per column (v_rms·dt/r) across, one per row (packing) up.
type Map<'a, 'b> = ChartContext<
    'a,
    BitMapBackend<'b>,
    Cartesian2d<SegmentedCoord<RangedCoordusize>, SegmentedCoord<RangedCoordusize>>,
>;

/// A cell's corner or edge in the map's coordinates.
type Corner = (SegmentValue<usize>, SegmentValue<usize>);

/// `cells[j][i]`: the step run at row j (packing), column i, if one was run there.
type Cells<'g> = Vec<Vec<Option<&'g AccuracyPoint>>>;

/// Step sizes within this relative distance share a column.
const SAME_COLUMN: f64 = 0.02;

fn draw_stability(groups: &[PackingGroup], canvas: &Canvas<'_>) -> anyhow::Result<()> {
    let columns = columns(groups);
    let root = titled_canvas(
        canvas,
        &format!(
            "Stability map of the step method: missed-collision fraction (m) and max overlap (ov); black line: m = {FAILURE_MISSED_FRACTION:e}"
        ),
        19,
    )?;
    let (map_area, scale_area) = root.split_horizontally(STABILITY_SIZE.0 - 130);
    draw_colour_scale(&scale_area)?;
    let mut chart = map_axes(&map_area, &columns, groups)?;
    let cells = cells(groups, &columns);
    for (j, row) in cells.iter().enumerate() {
        for (i, cell) in row.iter().enumerate() {
            if let Some(point) = cell {
                draw_cell(&mut chart, (i, j), point)?;
            }
        }
    }
    chart
        .draw_series(
            failure_edges(&cells)
                .into_iter()
                .map(|edge| PathElement::new(edge, BLACK.stroke_width(4))),
        )
        .map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

/// The map's columns: the distinct v_rms·dt/r of the step runs, ascending.
fn columns(groups: &[PackingGroup]) -> Vec<f64> {
    let mut columns: Vec<f64> = groups
        .iter()
        .flat_map(|g| g.steps.iter().map(|p| p.step_over_radius))
        .filter(|x| x.is_finite())
        .collect();
    columns.sort_by(f64::total_cmp);
    columns.dedup_by(|a, b| (*a / *b - 1.0).abs() < SAME_COLUMN);
    columns
}

/// The step runs of `groups` (the rows) placed in `columns`.
fn cells<'g>(groups: &'g [PackingGroup], columns: &[f64]) -> Cells<'g> {
    let column_of = |x: f64| {
        columns
            .iter()
            .position(|c| (x / c - 1.0).abs() < SAME_COLUMN)
    };
    let mut cells: Cells<'g> = vec![vec![None; columns.len().max(1)]; groups.len().max(1)];
    for (j, group) in groups.iter().enumerate() {
        for point in &group.steps {
            if let Some(i) = column_of(point.step_over_radius) {
                cells[j][i] = Some(point);
            }
        }
    }
    cells
}

/// The map's axes, labelled by the columns' step sizes and the rows' packings.
fn map_axes<'a, 'b>(
    area: &'a Canvas<'b>,
    columns: &[f64],
    groups: &[PackingGroup],
) -> anyhow::Result<Map<'a, 'b>> {
    // At least two of each: a segmented axis of one value has no length to draw on (the
    // second row or column then stays blank and unlabelled).
    let (nx, ny) = (columns.len().max(2), groups.len().max(2));
    let mut chart = ChartBuilder::on(area)
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
    Ok(chart)
}

/// The cell at column i, row j: coloured by its missed fraction, labelled with it and
/// the maximum overlap.
fn draw_cell(
    chart: &mut Map<'_, '_>,
    (i, j): (usize, usize),
    point: &AccuracyPoint,
) -> anyhow::Result<()> {
    use SegmentValue::{CenterOf, Exact};
    chart
        .draw_series([Rectangle::new(
            [(Exact(i), Exact(j)), (Exact(i + 1), Exact(j + 1))],
            missed_colour(point.missed_fraction).filled(),
        )])
        .map_err(|e| anyhow!("{e}"))?;
    let style = TextStyle::from((FONT, 15).into_font()).pos(Pos::new(HPos::Center, VPos::Center));
    let missed = if point.missed_fraction == 0.0 {
        "m 0".to_owned()
    } else {
        format!("m {:.1e}", point.missed_fraction)
    };
    let label = EmptyElement::at((CenterOf(i), CenterOf(j)))
        + Text::new(missed, (0, -10), style.clone())
        + Text::new(format!("ov {:.3}", point.max_overlap), (0, 10), style);
    chart.draw_series([label]).map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

/// The failure boundary: every cell edge between a failed and a passing cell.
fn failure_edges(cells: &Cells<'_>) -> Vec<[Corner; 2]> {
    use SegmentValue::Exact;
    let failed = |(j, i): (usize, usize)| cells[j][i].map(AccuracyPoint::failed);
    let differ = |a, b| matches!((failed(a), failed(b)), (Some(x), Some(y)) if x != y);
    let (ny, nx) = (cells.len(), cells.first().map_or(0, Vec::len));
    let mut edges = Vec::new();
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
    edges
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
