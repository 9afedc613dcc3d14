//! Pictures of a scene: the disks drawn to scale in their box, coloured by speed — a
//! PNG of one state (the seed's Figure 4) or an animated GIF of a run.

use std::path::Path;

use anyhow::anyhow;
use plotters::coord::Shift;
use plotters::drawing::DrawingAreaErrorKind;
use plotters::prelude::*;
use plotters_backend::DrawingErrorKind;
use plotters_bitmap::BitMapBackendError;

use crate::sim::engine::Engine;
use crate::sim::{Boundary, Particles, Scene};
use crate::spec::PreparedRun;
use crate::view::raster::speed_rgb;

/// Pixels along the longer side of the box.
const LONG_SIDE_PX: f64 = 800.0;
/// Pixels of margin around the box.
const MARGIN_PX: f64 = 10.0;

/// Where a box of `width` × `height` lands on the picture, and the picture's size.
#[derive(Clone, Copy, Debug)]
struct Frame {
    scale: f64,
    height: f64,
    size: (u32, u32),
}

impl Frame {
    fn of(scene: &Scene) -> Frame {
        let (w, h) = (scene.domain.width, scene.domain.height);
        let scale = LONG_SIDE_PX / w.max(h);
        let size = (
            (w * scale + 2.0 * MARGIN_PX).ceil() as u32,
            (h * scale + 2.0 * MARGIN_PX).ceil() as u32,
        );
        Frame {
            scale,
            height: h,
            size,
        }
    }

    /// Pixel of a point of the box (y up in the box, down on the picture).
    fn pixel(&self, x: f64, y: f64) -> (i32, i32) {
        (
            (MARGIN_PX + x * self.scale).round() as i32,
            (MARGIN_PX + (self.height - y) * self.scale).round() as i32,
        )
    }
}

/// Blue (at rest) through red (at `fast` and above), the live view's colours.
fn speed_colour(speed: f64, fast: f64) -> RGBColor {
    let [r, g, b] = speed_rgb(speed / fast);
    RGBColor(r, g, b)
}

fn draw_state(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    scene: &Scene,
    particles: &Particles,
    fast: f64,
) -> anyhow::Result<()> {
    let frame = Frame::of(scene);
    area.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
    let corner = frame.pixel(0.0, scene.domain.height);
    let far = frame.pixel(scene.domain.width, 0.0);
    let edge = match scene.domain.boundary {
        Boundary::Walls => BLACK.stroke_width(2),
        Boundary::Periodic => BLACK.mix(0.3).stroke_width(1),
    };
    area.draw(&Rectangle::new([corner, far], edge))
        .map_err(|e| anyhow!("{e}"))?;
    for idx in 0..particles.len() {
        let speed = particles.vx[idx].hypot(particles.vy[idx]);
        let centre = frame.pixel(particles.x[idx], particles.y[idx]);
        let radius = (particles.radius[idx] * frame.scale).max(1.0);
        area.draw(&Circle::new(
            centre,
            radius,
            speed_colour(speed, fast).filled(),
        ))
        .map_err(|e| anyhow!("{e}"))?;
    }
    Ok(())
}

/// Twice the rms speed: the colour scale's red end (1 for a gas at rest).
pub fn fast_speed(particles: &Particles) -> f64 {
    let fast = 2.0 * particles.rms_speed();
    if fast > 0.0 { fast } else { 1.0 }
}

/// Writes a PNG of the disks after all the run's steps.
pub fn png_after_run(prepared: &PreparedRun, path: &Path) -> anyhow::Result<()> {
    let scene = &prepared.scene;
    let fast = fast_speed(&scene.particles);
    let mut particles = scene.particles.clone();
    let mut engine = Engine::new(scene, prepared.method, prepared.params, prepared.event);
    for _ in 0..prepared.steps {
        engine.step(&mut particles);
    }
    let area = BitMapBackend::new(path, Frame::of(scene).size).into_drawing_area();
    draw_state(&area, scene, &particles, fast)?;
    area.present().map_err(|e| picture_error(path, e))
}

/// Why a picture could not be written to `path`, in words (plotters' own text of its
/// bitmap errors is a debug dump).
pub fn picture_error(path: &Path, err: DrawingAreaErrorKind<BitMapBackendError>) -> anyhow::Error {
    let reason = match &err {
        DrawingAreaErrorKind::BackendError(DrawingErrorKind::DrawingError(backend)) => {
            match backend {
                BitMapBackendError::IOError(io) => crate::output::io_reason(io),
                // An image error's text is its I/O error's, when it is one.
                BitMapBackendError::ImageError(image) => {
                    crate::output::without_os_code(image.to_string())
                }
                BitMapBackendError::GifEncodingError(gif) => gif.to_string(),
                BitMapBackendError::InvalidBuffer => "the picture buffer is invalid".to_owned(),
            }
        }
        other => other.to_string(),
    };
    anyhow!("cannot write {}: {reason}", path.display())
}

/// Writes an animated GIF of the run: `frames` pictures from the start to the last step.
pub fn gif_of_run(prepared: &PreparedRun, path: &Path, frames: u32) -> anyhow::Result<()> {
    let scene = &prepared.scene;
    let fast = fast_speed(&scene.particles);
    let area = BitMapBackend::gif(path, Frame::of(scene).size, 60)
        .map_err(|e| {
            picture_error(
                path,
                DrawingAreaErrorKind::BackendError(DrawingErrorKind::DrawingError(e)),
            )
        })?
        .into_drawing_area();
    let mut particles = scene.particles.clone();
    let mut engine = Engine::new(scene, prepared.method, prepared.params, prepared.event);
    let mut done = 0;
    for frame in 0..frames {
        // Frame k shows the state after round(k·steps/(frames − 1)) steps.
        let target = (u64::from(frame) * prepared.steps).div_ceil(u64::from(frames - 1).max(1));
        while done < target.min(prepared.steps) {
            engine.step(&mut particles);
            done += 1;
        }
        draw_state(&area, scene, &particles, fast)?;
        area.present().map_err(|e| picture_error(path, e))?;
    }
    Ok(())
}
