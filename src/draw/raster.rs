//! The software rasterizer: a [`Snapshot`] and [`View`] settings to a frame of 0RGB
//! `u32` pixels. Pure: no window, no files, no clock.
//!
//! Two ways to draw, chosen per frame from the size of the largest disk on screen:
//! true circles (every pixel whose centre lies inside a disk) when a disk covers a pixel
//! or more, and below that a splat: each pixel gets the mean speed colour of the disks
//! whose centres fall in it, blended into the background by the share of the pixel the
//! disks cover (their count times the mean disk area, at most all of it). The splat is
//! what keeps 10⁶ disks and more readable and fast when the whole box is shown.

use crate::sim::Particles;
use crate::sim::snapshot::{SPEED_LEVELS, Snapshot};

/// Pixels of margin around the whole box at zoom 1.
pub const MARGIN_PX: f64 = 10.0;
/// Below this radius on screen (pixels) disks are splatted instead of drawn as circles.
pub const SPLAT_BELOW_PX: f64 = 1.0;
pub const BACKGROUND: u32 = 0x00FF_FFFF;
/// The box's outline.
pub const OUTLINE: u32 = 0x0040_4040;

/// What part of the box is shown, on how many pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// Pixels of the drawing, at least 1 each way.
    pub width: usize,
    pub height: usize,
    /// The box's size (simulation units).
    pub box_width: f64,
    pub box_height: f64,
    /// 1 shows the whole box; 2 shows half its width, twice as large.
    pub zoom: f64,
    /// The point of the box at the centre of the drawing.
    pub centre: [f64; 2],
}

impl View {
    /// The whole box of `box_width` × `box_height` on `width` × `height` pixels.
    pub fn whole_box(width: usize, height: usize, box_width: f64, box_height: f64) -> View {
        View {
            width,
            height,
            box_width,
            box_height,
            zoom: 1.0,
            centre: [0.5 * box_width, 0.5 * box_height],
        }
    }

    /// Pixels per unit of length.
    pub fn scale(&self) -> f64 {
        let fit_x = (self.width as f64 - 2.0 * MARGIN_PX).max(1.0) / self.box_width;
        let fit_y = (self.height as f64 - 2.0 * MARGIN_PX).max(1.0) / self.box_height;
        fit_x.min(fit_y) * self.zoom
    }

    /// Where a point of the box lands, in pixels from the top-left corner (y up in the
    /// box, down on the screen); pixel (i, j) covers [i, i + 1) × [j, j + 1).
    pub fn to_pixel(&self, x: f64, y: f64) -> [f64; 2] {
        let scale = self.scale();
        [
            0.5 * self.width as f64 + (x - self.centre[0]) * scale,
            0.5 * self.height as f64 - (y - self.centre[1]) * scale,
        ]
    }

    /// Zooms by `factor` about the centre of the drawing.
    pub fn zoom_by(&mut self, factor: f64) {
        self.zoom = (self.zoom * factor).clamp(0.25, 4096.0);
    }

    /// Moves the shown part by a fraction of the drawing's width and height.
    pub fn pan_by(&mut self, right: f64, up: f64) {
        let scale = self.scale();
        self.centre[0] += right * self.width as f64 / scale;
        self.centre[1] += up * self.height as f64 / scale;
    }
}

/// Blue (at rest) through red (at the colour scale's fast end), as RGB: `t` in [0, 1].
pub fn speed_rgb(t: f64) -> [u8; 3] {
    let t = t.clamp(0.0, 1.0);
    [
        (40.0 + 200.0 * t) as u8,
        (90.0 + 40.0 * (1.0 - (2.0 * t - 1.0).abs())) as u8,
        (220.0 - 180.0 * t) as u8,
    ]
}

/// The colour of every speed level of a snapshot.
fn palette() -> Vec<u32> {
    (0..=SPEED_LEVELS)
        .map(|level| {
            let [r, g, b] = speed_rgb(f64::from(level) / f64::from(SPEED_LEVELS));
            u32::from_be_bytes([0, r, g, b])
        })
        .collect()
}

/// A drawing: `width` × `height` pixels of the box, then `status_rows` rows below it
/// that [`draw`] leaves to the caller; with the splat's scratch memory, kept between
/// frames.
#[derive(Clone, Debug, Default)]
pub struct Frame {
    pub width: usize,
    /// Rows of the box's drawing (the status rows come after them).
    pub height: usize,
    pub status_rows: usize,
    /// Row by row from the top, 0RGB.
    pub pixels: Vec<u32>,
    palette: Vec<u32>,
    /// The splat's per-pixel disk count and speed sum: zero between frames, set back
    /// to zero pixel by pixel after each splat.
    count: Vec<u32>,
    speed_sum: Vec<u32>,
    /// The pixels the last splat gave a disk, in the order it reached them.
    touched: Vec<u32>,
}

impl Frame {
    /// An empty frame whose drawings will have `status_rows` rows below the box.
    pub fn with_status_rows(status_rows: usize) -> Frame {
        Frame {
            status_rows,
            palette: palette(),
            ..Frame::default()
        }
    }

    /// The pixels of the box's drawing (the rows above the status rows).
    pub fn scene_pixels(&self) -> &[u32] {
        &self.pixels[..self.width * self.height]
    }
}

/// How a frame drew the disks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Drawn {
    Circles,
    Splat,
}

impl Drawn {
    pub fn name(self) -> &'static str {
        match self {
            Drawn::Circles => "circles",
            Drawn::Splat => "splat",
        }
    }
}

/// Draws `snapshot` as `view` shows it into `frame` (resized to the view, the status
/// rows untouched unless the size changed), and says how.
pub fn draw(snapshot: &Snapshot, view: &View, frame: &mut Frame) -> Drawn {
    let (width, height) = (view.width, view.height);
    if frame.palette.is_empty() {
        frame.palette = palette();
    }
    let total = width * (height + frame.status_rows);
    if frame.width != width || frame.height != height || frame.pixels.len() != total {
        frame.width = width;
        frame.height = height;
        frame.pixels.clear();
        frame.pixels.resize(total, BACKGROUND);
    }
    frame.pixels[..width * height].fill(BACKGROUND);
    let scale = view.scale();
    let drawn = if f64::from(snapshot.max_radius) * scale < SPLAT_BELOW_PX {
        splat(snapshot, view, frame);
        Drawn::Splat
    } else {
        circles(snapshot, view, frame);
        Drawn::Circles
    };
    outline(view, frame);
    drawn
}

/// Float pixel coordinates are x·scale + offset: the view's transform in f32.
struct Transform {
    scale: f32,
    offset: [f32; 2],
}

impl Transform {
    fn of(view: &View) -> Transform {
        let [x0, y0] = view.to_pixel(0.0, 0.0);
        Transform {
            scale: view.scale() as f32,
            offset: [x0 as f32, y0 as f32],
        }
    }
}

fn splat(snapshot: &Snapshot, view: &View, frame: &mut Frame) {
    let (width, height) = (view.width, view.height);
    let n_pixels = width * height;
    if frame.count.len() != n_pixels {
        frame.count.clear();
        frame.count.resize(n_pixels, 0);
        frame.speed_sum.clear();
        frame.speed_sum.resize(n_pixels, 0);
    }
    // Only the pixels a disk lands on are blended and cleared again: for 10⁵ disks at
    // most 10⁵ of the 640,000 pixels of an 800 × 800 frame, not all of them.
    frame.touched.clear();
    let Transform { scale, offset } = Transform::of(view);
    let (w, h) = (width as f32, height as f32);
    for ((&x, &y), &speed) in snapshot.x.iter().zip(&snapshot.y).zip(&snapshot.speed) {
        let px = offset[0] + x * scale;
        let py = offset[1] - y * scale;
        if px >= 0.0 && py >= 0.0 && px < w && py < h {
            let pixel_idx = py as usize * width + px as usize;
            if frame.count[pixel_idx] == 0 {
                frame.touched.push(pixel_idx as u32);
            }
            frame.count[pixel_idx] += 1;
            frame.speed_sum[pixel_idx] += u32::from(speed);
        }
    }
    // The share of a pixel one disk covers, in 1/256ths (the blend's unit).
    let n_disks = snapshot.len().max(1) as f64;
    let disk_px = snapshot.disk_area / n_disks * view.scale() * view.scale();
    let coverage_per_disk = (256.0 * disk_px).max(1.0) as u32;
    let [br, bg, bb] = rgb(BACKGROUND);
    for &pixel_idx in &frame.touched {
        let pixel_idx = pixel_idx as usize;
        let count = std::mem::take(&mut frame.count[pixel_idx]);
        let speed_sum = std::mem::take(&mut frame.speed_sum[pixel_idx]);
        let colour = frame.palette[(speed_sum / count) as usize];
        let alpha = count.saturating_mul(coverage_per_disk).min(256);
        let [r, g, b] = rgb(colour);
        let mix = |fore: u32, back: u32| (fore * alpha + back * (256 - alpha)) >> 8;
        frame.pixels[pixel_idx] = (mix(r, br) << 16) | (mix(g, bg) << 8) | mix(b, bb);
    }
}

fn rgb(colour: u32) -> [u32; 3] {
    [(colour >> 16) & 0xFF, (colour >> 8) & 0xFF, colour & 0xFF]
}

fn circles(snapshot: &Snapshot, view: &View, frame: &mut Frame) {
    let width = view.width;
    let Transform { scale, offset } = Transform::of(view);
    let (w, h) = (view.width as f32, view.height as f32);
    for idx in 0..snapshot.len() {
        let cx = offset[0] + snapshot.x[idx] * scale;
        let cy = offset[1] - snapshot.y[idx] * scale;
        let r = snapshot.radius[idx] * scale;
        if cx + r < 0.0 || cy + r < 0.0 || cx - r >= w || cy - r >= h {
            continue;
        }
        let colour = frame.palette[usize::from(snapshot.speed[idx])];
        // Rows whose pixel centres (j + ½) lie within r of the centre.
        let first_row = (cy - r - 0.5).ceil().max(0.0) as usize;
        let last_row = (cy + r - 0.5).floor().min(h - 1.0);
        let mut drawn = false;
        if last_row >= 0.0 {
            for row in first_row..=last_row as usize {
                let dy = row as f32 + 0.5 - cy;
                let half_squared = r * r - dy * dy;
                if half_squared < 0.0 {
                    continue;
                }
                let half = half_squared.sqrt();
                let first_col = (cx - half - 0.5).ceil().max(0.0) as usize;
                let last_col = (cx + half - 0.5).floor().min(w - 1.0);
                if last_col < first_col as f32 {
                    continue;
                }
                frame.pixels[row * width + first_col..=row * width + last_col as usize]
                    .fill(colour);
                drawn = true;
            }
        }
        // A disk smaller than a pixel still shows as the pixel of its centre.
        if !drawn && cx >= 0.0 && cy >= 0.0 && cx < w && cy < h {
            frame.pixels[cy as usize * width + cx as usize] = colour;
        }
    }
}

/// The box's edges, one pixel wide, where they are on screen.
fn outline(view: &View, frame: &mut Frame) {
    let [left, top] = view.to_pixel(0.0, view.box_height);
    let [right, bottom] = view.to_pixel(view.box_width, 0.0);
    let (w, h) = (view.width as f64, view.height as f64);
    let clamp_col = |x: f64| x.floor().clamp(0.0, w - 1.0) as usize;
    let clamp_row = |y: f64| y.floor().clamp(0.0, h - 1.0) as usize;
    let (col_range, row_range) = (
        clamp_col(left)..=clamp_col(right),
        clamp_row(top)..=clamp_row(bottom),
    );
    for (edge_row, visible) in [
        (top, top >= 0.0 && top < h),
        (bottom, bottom >= 0.0 && bottom < h),
    ] {
        if visible {
            let row = edge_row.floor() as usize;
            frame.pixels[row * view.width + col_range.start()..=row * view.width + col_range.end()]
                .fill(OUTLINE);
        }
    }
    for (edge_col, visible) in [
        (left, left >= 0.0 && left < w),
        (right, right >= 0.0 && right < w),
    ] {
        if visible {
            let col = edge_col.floor() as usize;
            for row in row_range.clone() {
                frame.pixels[row * view.width + col] = OUTLINE;
            }
        }
    }
}

/// Twice the rms speed: the colour scale's red end (1 for a gas at rest).
pub fn fast_speed(particles: &Particles) -> f64 {
    let fast = 2.0 * particles.rms_speed();
    if fast > 0.0 { fast } else { 1.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{Disk, Particles};

    /// A 20 × 20 box on 40 × 40 pixels: one pixel per unit, the box from pixel 10 to 30.
    fn view() -> View {
        View::whole_box(40, 40, 20.0, 20.0)
    }

    /// Disks at rest or moving along x at `vx` (the colour scale's fast end is 1).
    fn snapshot(disks: &[(f64, f64, f64, f64)]) -> Snapshot {
        let disks: Vec<Disk> = disks
            .iter()
            .map(|&(x, y, radius, vx)| Disk {
                x,
                y,
                vx,
                vy: 0.0,
                radius,
                mass: 1.0,
            })
            .collect();
        let mut snapshot = Snapshot::default();
        snapshot.fill_from(&Particles::from_disks(&disks), 1.0);
        snapshot
    }

    fn drawn(snapshot: &Snapshot, view: &View) -> Frame {
        let mut frame = Frame::with_status_rows(0);
        draw(snapshot, view, &mut frame);
        frame
    }

    /// Pixels (col, row) of the box's inside that are not background.
    fn coloured(frame: &Frame) -> Vec<(usize, usize)> {
        let mut found = Vec::new();
        for row in 11..30 {
            for col in 11..30 {
                if frame.pixels[row * frame.width + col] != BACKGROUND {
                    found.push((col, row));
                }
            }
        }
        found
    }

    #[test]
    fn a_disk_covers_the_pixels_whose_centres_it_contains() {
        // Centre at pixel (20, 20), radius 2: rows 18..=21, two or four pixels each.
        let frame = drawn(&snapshot(&[(10.0, 10.0, 2.0, 0.0)]), &view());
        let mut expected = vec![(19, 18), (20, 18), (19, 21), (20, 21)];
        expected.extend((18..22).flat_map(|col| [(col, 19), (col, 20)]));
        expected.sort_by_key(|&(col, row)| (row, col));
        assert_eq!(coloured(&frame), expected);
        let [r, g, b] = speed_rgb(0.0);
        assert_eq!(frame.pixels[19 * 40 + 20], u32::from_be_bytes([0, r, g, b]));
    }

    #[test]
    fn the_box_outline_is_drawn_at_its_edges() {
        let frame = drawn(&snapshot(&[]), &view());
        for k in 10..=30 {
            for (col, row) in [(k, 10), (k, 30), (10, k), (30, k)] {
                assert_eq!(frame.pixels[row * 40 + col], OUTLINE, "({col}, {row})");
            }
        }
        assert_eq!(frame.pixels[9 * 40 + 9], BACKGROUND);
        assert_eq!(frame.pixels[20 * 40 + 20], BACKGROUND);
    }

    #[test]
    fn colour_goes_from_blue_at_rest_to_red_at_the_fast_end() {
        let frame = drawn(
            &snapshot(&[(5.0, 10.0, 1.5, 0.0), (15.0, 10.0, 1.5, 3.0)]),
            &view(),
        );
        let slow = frame.pixels[19 * 40 + 15];
        let fast = frame.pixels[19 * 40 + 25];
        assert_eq!(rgb(slow), [40, 90, 220]);
        assert_eq!(rgb(fast), [240, 90, 40]);
    }

    #[test]
    fn small_disks_are_splatted_with_their_mean_speed_and_covered_share() {
        // Two disks of radius 0.9 px in one pixel cover it fully: the colour of their
        // mean speed level, (0 + 254) / 2 = 127.
        let full = drawn(
            &snapshot(&[(10.2, 10.2, 0.9, 0.0), (10.7, 10.7, 0.9, 254.0 / 255.0)]),
            &view(),
        );
        assert_eq!(coloured(&full), [(20, 19)]);
        let [r, g, b] = speed_rgb(127.0 / 255.0);
        assert_eq!(rgb(full.pixels[19 * 40 + 20]), [r, g, b].map(u32::from));
        // One disk of radius 0.2 covers π·0.04 of its pixel, 32/256: blue blended
        // into white by that share.
        let faint = drawn(&snapshot(&[(10.5, 10.5, 0.2, 0.0)]), &view());
        assert_eq!(faint.pixels[19 * 40 + 20], 0x00E4_EAFA);
    }

    #[test]
    fn zooming_in_turns_a_splat_into_circles_about_the_centre() {
        let mut zoomed = view();
        zoomed.zoom_by(4.0);
        // Radius 0.9 is 3.6 px at zoom 4; the disk at the box's centre stays there, on
        // rows of 8, 6, 6 and 2 pixels each side of its centre (the box's edges are off
        // screen).
        let frame = drawn(&snapshot(&[(10.0, 10.0, 0.9, 0.0)]), &zoomed);
        let n_coloured = frame.pixels.iter().filter(|&&p| p != BACKGROUND).count();
        assert_eq!(n_coloured, 44);
        assert_ne!(frame.pixels[20 * 40 + 20], BACKGROUND);
        // Panning right by a quarter of the drawing moves the disk 10 px to the left.
        zoomed.pan_by(0.25, 0.0);
        let moved = drawn(&snapshot(&[(10.0, 10.0, 0.9, 0.0)]), &zoomed);
        assert_eq!(moved.pixels[20 * 40 + 20], BACKGROUND);
        assert_eq!(moved.pixels[20 * 40 + 10], frame.pixels[20 * 40 + 20]);
    }

    #[test]
    fn disks_off_screen_are_skipped_and_the_status_rows_kept() {
        let mut frame = Frame::with_status_rows(3);
        let far = snapshot(&[
            (-50.0, 5.0, 2.0, 0.0),
            (70.0, 90.0, 0.5, 0.0),
            (10.0, -40.0, 0.1, 0.0),
        ]);
        draw(&far, &view(), &mut frame);
        assert_eq!(frame.pixels.len(), 40 * 43);
        frame.pixels[40 * 41] = 7;
        draw(&far, &view(), &mut frame);
        assert_eq!(frame.pixels[40 * 41], 7, "the status rows are the caller's");
        assert!(coloured(&frame).is_empty());
    }

    /// The splat clears its scratch as it goes: a frame drawn after another is the frame
    /// drawn fresh.
    #[test]
    fn a_splat_leaves_nothing_behind_for_the_next_frame() {
        let first = snapshot(&[(10.2, 10.2, 0.4, 0.0), (3.5, 17.5, 0.4, 0.5)]);
        let second = snapshot(&[(10.4, 10.6, 0.4, 1.0), (12.5, 4.5, 0.4, 0.2)]);
        let mut frame = Frame::with_status_rows(0);
        assert_eq!(draw(&first, &view(), &mut frame), Drawn::Splat);
        draw(&second, &view(), &mut frame);
        assert_eq!(frame.pixels, drawn(&second, &view()).pixels);
    }
}
