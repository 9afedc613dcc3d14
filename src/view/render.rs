//! Pictures of a scene: the disks drawn to scale in their box, coloured by speed, with
//! the key of the colours below — a PNG of one state (the seed's Figure 4) or an
//! animated GIF of a run.

use std::path::Path;

use anyhow::anyhow;
use plotters::prelude::*;

use crate::system::output::{Canvas, write_gif, write_png};

use crate::draw::raster::{fast_speed, speed_rgb};
use crate::report::figures::{FONT, register_font};
use crate::report::units::significant;
use crate::run::spec::PreparedRun;
use crate::sim::engine::Engine;
use crate::sim::{Boundary, Particles, Scene};

/// Pixels along the longer side of the box.
const LONG_SIDE_PX: f64 = 800.0;
/// Pixels of margin around the box.
const MARGIN_PX: f64 = 10.0;
/// Pixels below the box's margin for the colour key.
const KEY_PX: f64 = 40.0;
/// Width and height of the key's colour bar, in pixels.
const KEY_BAR_PX: (i32, i32) = (240, 12);
/// Hundredths of a second between the frames of a GIF.
const FRAME_DELAY_CS: u16 = 6;

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
            (h * scale + 2.0 * MARGIN_PX + KEY_PX).ceil() as u32,
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

/// The key below the box: the colour bar from rest to `fast`, its ends and middle
/// labelled, and what it measures in which units.
fn draw_key(area: &Canvas<'_>, frame: &Frame, fast: f64) -> anyhow::Result<()> {
    register_font();
    let (width, height) = KEY_BAR_PX;
    let left = MARGIN_PX as i32;
    let top = (frame.size.1 as f64 - KEY_PX) as i32;
    for column in 0..width {
        let speed = fast * f64::from(column) / f64::from(width - 1);
        let bar = [(left + column, top), (left + column + 1, top + height)];
        area.draw(&Rectangle::new(bar, speed_colour(speed, fast).filled()))
            .map_err(|e| anyhow!("{e}"))?;
    }
    let style = (FONT, 13).into_font().color(&BLACK);
    let labels = [(0.0, 0), (0.5, width / 2 - 10), (1.0, width - 24)];
    for (fraction, at) in labels {
        let label = significant(fraction * fast, 3);
        area.draw(&Text::new(
            label,
            (left + at, top + height + 2),
            style.clone(),
        ))
        .map_err(|e| anyhow!("{e}"))?;
    }
    let what = format!(
        "speed, in the scene's lengths per unit of time: blue at rest, red from {} (twice the rms speed) up",
        significant(fast, 3)
    );
    area.draw(&Text::new(what, (left + width + 12, top), style))
        .map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

/// Blue (at rest) through red (at `fast` and above), the live view's colours.
fn speed_colour(speed: f64, fast: f64) -> RGBColor {
    let [r, g, b] = speed_rgb(speed / fast);
    RGBColor(r, g, b)
}

fn draw_state(
    area: &Canvas<'_>,
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
    draw_key(area, &frame, fast)
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
    write_png(path, Frame::of(scene).size, |area| {
        draw_state(area, scene, &particles, fast)
    })
}

/// Writes an animated GIF of the run: `frames` pictures from the start to the last step.
pub fn gif_of_run(prepared: &PreparedRun, path: &Path, frames: u32) -> anyhow::Result<()> {
    let scene = &prepared.scene;
    let fast = fast_speed(&scene.particles);
    let mut particles = scene.particles.clone();
    let mut engine = Engine::new(scene, prepared.method, prepared.params, prepared.event);
    let mut done = 0;
    write_gif(
        path,
        Frame::of(scene).size,
        frames,
        FRAME_DELAY_CS,
        |frame, area| {
            // Frame k shows the state after round(k·steps/(frames − 1)) steps.
            let target = (u64::from(frame) * prepared.steps).div_ceil(u64::from(frames - 1).max(1));
            while done < target.min(prepared.steps) {
                engine.step(&mut particles);
                done += 1;
            }
            draw_state(area, scene, &particles, fast)
        },
    )
}
