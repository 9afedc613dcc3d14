//! A read-only picture of the state for drawing: f32 positions and radii and a one-byte
//! speed per disk, filled on request from [`Particles`]. Nothing here changes the state.

use super::particles::Particles;

/// Speeds are stored as 0..=[`SPEED_LEVELS`]: 0 at rest, the top level at the colour
/// scale's fast end and above.
pub const SPEED_LEVELS: u8 = u8::MAX;

/// The disks as a viewer needs them, in the state's storage order (drawing does not
/// depend on it: disks do not overlap).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Snapshot {
    pub x: Vec<f32>,
    pub y: Vec<f32>,
    pub radius: Vec<f32>,
    /// Speed of each disk in levels of `fast / SPEED_LEVELS`, saturating at `fast`.
    pub speed: Vec<u8>,
    /// The largest radius (0 for no disks).
    pub max_radius: f32,
    /// Σ π r², the area the disks cover.
    pub disk_area: f64,
    /// Σ ½ m v², summed in storage order: for display only (the last bits may differ
    /// from `observe`, which sums in id order).
    pub kinetic_energy: f64,
}

impl Snapshot {
    /// Refills this snapshot from `particles` (reusing its memory); `fast` is the speed
    /// drawn at the top of the colour scale (positive).
    pub fn fill_from(&mut self, particles: &Particles, fast: f64) {
        let n_particles = particles.len();
        self.x.clear();
        self.x.extend(particles.x.iter().map(|&x| x as f32));
        self.y.clear();
        self.y.extend(particles.y.iter().map(|&y| y as f32));
        self.radius.clear();
        self.radius
            .extend(particles.radius.iter().map(|&r| r as f32));
        self.max_radius = self.radius.iter().copied().fold(0.0, f32::max);
        self.disk_area = std::f64::consts::PI * particles.radius.iter().map(|r| r * r).sum::<f64>();
        self.speed.clear();
        self.speed.reserve(n_particles);
        let levels_per_speed = f64::from(SPEED_LEVELS) / fast;
        let mut kinetic_energy = 0.0;
        for idx in 0..n_particles {
            let (vx, vy) = (particles.vx[idx], particles.vy[idx]);
            let speed_squared = vx * vx + vy * vy;
            kinetic_energy += 0.5 * particles.mass[idx] * speed_squared;
            let level = (speed_squared.sqrt() * levels_per_speed).min(f64::from(SPEED_LEVELS));
            self.speed.push(level as u8);
        }
        self.kinetic_energy = kinetic_energy;
    }

    pub fn len(&self) -> usize {
        self.x.len()
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::Disk;

    #[test]
    fn a_snapshot_holds_positions_radii_and_speed_levels() {
        let disk = |x, vx, radius| Disk {
            x,
            y: 2.0,
            vx,
            vy: 0.0,
            radius,
            mass: 2.0,
        };
        let particles = Particles::from_disks(&[
            disk(1.0, 0.0, 0.5),
            disk(3.0, 1.0, 1.5),
            disk(5.0, -9.0, 1.0),
        ]);
        let mut snapshot = Snapshot::default();
        snapshot.fill_from(&particles, 2.0);
        assert_eq!(snapshot.x, [1.0, 3.0, 5.0]);
        assert_eq!(snapshot.y, [2.0; 3]);
        assert_eq!(snapshot.radius, [0.5, 1.5, 1.0]);
        // Half the fast speed is level 127; beyond it saturates.
        assert_eq!(snapshot.speed, [0, 127, SPEED_LEVELS]);
        assert_eq!(snapshot.max_radius, 1.5);
        assert_eq!(snapshot.disk_area, std::f64::consts::PI * 3.5);
        assert_eq!(snapshot.kinetic_energy, 1.0 + 81.0);
        // Refilling reuses the buffers and forgets the old disks.
        snapshot.fill_from(&Particles::from_disks(&[disk(7.0, 0.0, 0.25)]), 2.0);
        assert_eq!(snapshot.len(), 1);
        assert_eq!(snapshot.max_radius, 0.25);
    }
}
