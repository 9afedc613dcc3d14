//! The status line: one line of text in the rows below the drawing, in the embedded
//! DejaVu Sans rasterised once per character by ab_glyph.

use ab_glyph::{Font, FontRef, PxScale, ScaleFont, point};

use crate::draw::raster::Frame;
use crate::report::figures::FONT_BYTES;

/// Rows below the drawing that hold the status line.
pub const STATUS_ROWS: usize = 20;
/// Height of the text, in pixels.
const TEXT_PX: f32 = 14.0;
const PAPER: u32 = 0x00F0_F0F0;
const INK: [u32; 3] = [0x20, 0x20, 0x20];

/// One printable ASCII character as coverage (0–255) over its pixel box.
#[derive(Clone, Debug)]
struct Glyph {
    advance: f32,
    left: i32,
    top: i32,
    width: usize,
    coverage: Vec<u8>,
}

/// The characters ' ' to '~', ready to blend into a frame.
#[derive(Clone, Debug)]
pub struct StatusFont {
    glyphs: Vec<Glyph>,
    ascent: f32,
}

impl Default for StatusFont {
    fn default() -> StatusFont {
        // The embedded font is valid; failing here would be a build defect.
        let font = FontRef::try_from_slice(FONT_BYTES)
            .unwrap_or_else(|_| panic!("the embedded DejaVu Sans is a valid font"));
        let scale = PxScale::from(TEXT_PX);
        let scaled = font.as_scaled(scale);
        let glyphs = (' '..='~')
            .map(|c| {
                let id = font.glyph_id(c);
                let mut glyph = Glyph {
                    advance: scaled.h_advance(id),
                    left: 0,
                    top: 0,
                    width: 0,
                    coverage: Vec::new(),
                };
                if let Some(outline) =
                    font.outline_glyph(id.with_scale_and_position(scale, point(0.0, 0.0)))
                {
                    let bounds = outline.px_bounds();
                    glyph.left = bounds.min.x as i32;
                    glyph.top = bounds.min.y as i32;
                    glyph.width = bounds.width() as usize;
                    glyph.coverage = vec![0; glyph.width * bounds.height() as usize];
                    outline.draw(|x, y, c| {
                        glyph.coverage[y as usize * glyph.width + x as usize] =
                            (c.clamp(0.0, 1.0) * 255.0) as u8;
                    });
                }
                glyph
            })
            .collect();
        StatusFont {
            glyphs,
            ascent: scaled.ascent(),
        }
    }
}

impl StatusFont {
    /// Clears the frame's status rows and writes `text` on them (characters outside
    /// printable ASCII show as '?'; what does not fit is cut off).
    pub fn write(&self, frame: &mut Frame, text: &str) {
        let width = frame.width;
        let first = width * frame.height;
        let rows = &mut frame.pixels[first..];
        rows.fill(PAPER);
        let n_rows = frame.status_rows as i32;
        let baseline = (n_rows as f32 - TEXT_PX) / 2.0 + self.ascent;
        let mut pen = 4.0_f32;
        for c in text.chars() {
            let c = if (' '..='~').contains(&c) { c } else { '?' };
            let glyph = &self.glyphs[c as usize - ' ' as usize];
            let left = pen.round() as i32 + glyph.left;
            let top = baseline.round() as i32 + glyph.top;
            for (idx, &coverage) in glyph.coverage.iter().enumerate() {
                let col = left + (idx % glyph.width) as i32;
                let row = top + (idx / glyph.width) as i32;
                if coverage == 0 || col < 0 || col >= width as i32 || row < 0 || row >= n_rows {
                    continue;
                }
                let pixel = &mut rows[row as usize * width + col as usize];
                let alpha = u32::from(coverage);
                let mix = |ink: u32, shift: u32| {
                    let paper = (*pixel >> shift) & 0xFF;
                    ((ink * alpha + paper * (255 - alpha)) / 255) << shift
                };
                *pixel = mix(INK[0], 16) | mix(INK[1], 8) | mix(INK[2], 0);
            }
            pen += glyph.advance;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::draw::raster::{View, draw};
    use crate::sim::snapshot::Snapshot;

    #[test]
    fn the_status_line_writes_ink_in_the_status_rows_only() {
        let mut frame = Frame::with_status_rows(STATUS_ROWS);
        let view = View::whole_box(120, 30, 10.0, 10.0);
        draw(&Snapshot::default(), &view, &mut frame);
        let scene: Vec<u32> = frame.scene_pixels().to_vec();
        let font = StatusFont::default();
        font.write(&mut frame, "");
        let blank = frame.pixels.clone();
        assert!(blank[120 * 30..].iter().all(|&p| p == PAPER));
        font.write(&mut frame, "fps 60");
        assert_eq!(frame.scene_pixels(), scene.as_slice());
        let inked = frame.pixels[120 * 30..]
            .iter()
            .filter(|&&p| p != PAPER)
            .count();
        assert!(inked > 30, "{inked} pixels of ink");
        // Writing again gives the same pixels: the rows are cleared first.
        let once = frame.pixels.clone();
        font.write(&mut frame, "fps 60");
        assert_eq!(frame.pixels, once);
    }
}
