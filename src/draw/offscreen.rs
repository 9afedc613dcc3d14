//! Drawing every step offscreen (`draw = true`): the state after each step is copied into
//! a snapshot and drawn whole by the live view's rasterizer, into a frame no window shows.
//! Both parts are timed here, apart from the stepping loop, so that a run can report the
//! frames per second the seed's OpenGL window measured (simulation and drawing) beside
//! its step rate without drawing.

use crate::draw::raster::{Frame, View, draw, fast_speed};
use crate::sim::snapshot::Snapshot;
use crate::sim::{Domain, Particles};
use crate::system::machine::timed;

/// Pixels of an offscreen frame: `collide view`'s default drawing.
pub const DRAW_SIZE: (usize, usize) = (800, 800);

/// The snapshot and frame of a drawn run, reused from step to step, and the seconds spent.
#[derive(Debug)]
pub struct Offscreen {
    snapshot: Snapshot,
    frame: Frame,
    view: View,
    /// The speed drawn red: twice the initial rms speed, as in the live view.
    fast: f64,
    /// Seconds filling snapshots and drawing them, summed over the steps.
    pub seconds: f64,
}

impl Offscreen {
    /// Draws the whole of `domain` at [`DRAW_SIZE`], coloured against the speeds of the
    /// `initial` disks.
    pub fn new(domain: &Domain, initial: &Particles) -> Offscreen {
        let (width, height) = DRAW_SIZE;
        Offscreen {
            snapshot: Snapshot::default(),
            frame: Frame::with_status_rows(0),
            view: View::whole_box(width, height, domain.width, domain.height),
            fast: fast_speed(initial),
            seconds: 0.0,
        }
    }

    /// An [`Offscreen`] when the run asks to draw, else `None`.
    pub fn when(draw: bool, domain: &Domain, initial: &Particles) -> Option<Offscreen> {
        draw.then(|| Offscreen::new(domain, initial))
    }

    /// Fills the snapshot from `particles` and draws it (on the calling thread).
    pub fn draw(&mut self, particles: &Particles) {
        let Offscreen {
            snapshot,
            frame,
            view,
            fast,
            seconds,
        } = self;
        timed(seconds, || {
            snapshot.fill_from(particles, *fast);
            draw(snapshot, view, frame);
            // The frame is never read: keep the optimiser from dropping the drawing.
            std::hint::black_box(&frame.pixels);
        });
    }

    /// The pixels of the last frame (row by row from the top, 0RGB).
    pub fn pixels(&self) -> &[u32] {
        self.frame.scene_pixels()
    }
}

/// Draws after a step when `offscreen` is set: what the backends' stepping loops call.
pub fn draw_step(offscreen: &mut Option<Offscreen>, particles: &Particles) {
    if let Some(offscreen) = offscreen {
        offscreen.draw(particles);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::draw::raster::BACKGROUND;
    use crate::sim::{Boundary, Disk};

    #[test]
    fn each_draw_fills_the_frame_with_the_disks_and_counts_its_seconds() {
        let domain = Domain {
            width: 10.0,
            height: 10.0,
            boundary: Boundary::Walls,
        };
        let disk = |x| Disk {
            x,
            y: 5.0,
            vx: 1.0,
            vy: 0.0,
            radius: 1.0,
            mass: 1.0,
        };
        let particles = Particles::from_disks(&[disk(3.0), disk(7.0)]);
        let mut offscreen = Offscreen::new(&domain, &particles);
        offscreen.draw(&particles);
        let pixels = offscreen.pixels();
        assert_eq!(pixels.len(), DRAW_SIZE.0 * DRAW_SIZE.1);
        // Two disks of a tenth of the box across: about 2·π·(78 px)² coloured pixels.
        let coloured = pixels.iter().filter(|&&p| p != BACKGROUND).count();
        assert!((30_000..45_000).contains(&coloured), "{coloured}");
        assert!(offscreen.seconds > 0.0);
    }
}
