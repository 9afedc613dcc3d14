//! The box, its boundary, the contact physics, and seeded initial conditions.
//!
//! Everything here is pure: a [`GasSpec`] and its seed always give the same disks
//! (placed by `sim::place`).
//! Parsing scene files lives in `crate::run::scene_file`; this module only builds state.

use serde::{Deserialize, Serialize};

use super::particles::Particles;

/// Random sequential addition of equal disks jams near this area fraction in 2D.
pub const RSA_JAMMING_PACKING: f64 = 0.547;

/// The largest area fraction random placement is asked for. It adds disks band by band
/// (`sim::place`), and a band filled after its neighbours starts with their edge disks
/// in place, so it jams sooner than the whole box would: near 0.52 at 10⁶ disks.
pub const RANDOM_MAX_PACKING: f64 = 0.51;

/// Consecutive failed random tries for one disk before placement gives up.
pub(super) const MAX_TRIES_PER_DISK: u32 = 20_000;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Boundary {
    /// Hard walls at x = 0, x = width, y = 0, y = height.
    Walls,
    /// The box wraps around in both directions; pairs interact through the minimum image.
    Periodic,
}

impl Boundary {
    pub fn name(self) -> &'static str {
        match self {
            Boundary::Walls => "walls",
            Boundary::Periodic => "periodic",
        }
    }
}

/// The simulation box `[0, width] × [0, height]` and what happens at its edges.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Domain {
    pub width: f64,
    pub height: f64,
    pub boundary: Boundary,
}

impl Domain {
    /// Vector from disk a to disk b; the minimum image in a periodic box.
    ///
    /// Swapping a and b negates the result exactly, so a pair's distance has the
    /// same bits whichever way round it is found.
    #[inline(always)]
    pub fn separation(&self, xa: f64, ya: f64, xb: f64, yb: f64) -> (f64, f64) {
        match self.boundary {
            Boundary::Walls => self.separation_in::<false>(xa, ya, xb, yb),
            Boundary::Periodic => self.separation_in::<true>(xa, ya, xb, yb),
        }
    }

    /// [`Domain::separation`] with the boundary fixed at compile time, for hot loops.
    /// Both give the same bits: they are the same arithmetic.
    #[inline(always)]
    pub fn separation_in<const PERIODIC: bool>(
        &self,
        xa: f64,
        ya: f64,
        xb: f64,
        yb: f64,
    ) -> (f64, f64) {
        let dx = xb - xa;
        let dy = yb - ya;
        if PERIODIC {
            (
                minimum_image(dx, self.width),
                minimum_image(dy, self.height),
            )
        } else {
            (dx, dy)
        }
    }

    pub fn area(&self) -> f64 {
        self.width * self.height
    }
}

/// `d` as its shortest periodic image along a side of `length`: in f64 for positions,
/// and in f32 for the strip grid's rounded entries ([`crate::sim::grid`]).
#[inline(always)]
pub fn minimum_image<T>(d: T, length: T) -> T
where
    T: Copy
        + PartialOrd
        + From<f32>
        + std::ops::Add<Output = T>
        + std::ops::Sub<Output = T>
        + std::ops::Mul<Output = T>
        + std::ops::Neg<Output = T>,
{
    let half = T::from(0.5) * length;
    if d > half {
        d - length
    } else if d < -half {
        d + length
    } else {
        d
    }
}

/// Maps a coordinate back into `[0, length)` after a periodic disk crossed an edge.
#[inline(always)]
pub fn wrap_periodic(coordinate: f64, length: f64) -> f64 {
    let wrapped = if coordinate >= length {
        coordinate - length
    } else if coordinate < 0.0 {
        coordinate + length
    } else {
        return coordinate;
    };
    // One box length covers any sane step; rem_euclid covers a disk that crossed more.
    let wrapped = if (0.0..=length).contains(&wrapped) {
        wrapped
    } else {
        coordinate.rem_euclid(length)
    };
    // -1e-20 + length rounds to length itself: that point belongs at 0.
    if wrapped < length { wrapped } else { 0.0 }
}

/// Contact laws and external field of a scene: the one struct a physical scene field is
/// declared in. The scene file fills it (`run::scene_file`), and it travels whole down
/// to the kernels (`sim::collision`, the wall rules), so a new field reaches them
/// without changing a signature.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Physics {
    /// Pair restitution e in [0, 1].
    pub restitution: f64,
    /// Wall restitution in [0, 1]: the fraction of normal speed a wall gives back.
    pub wall_restitution: f64,
    /// Constant acceleration, `None` when the scene has no field (then a step is a pure drift).
    pub gravity: Option<[f64; 2]>,
}

/// What a scene file that says nothing of physics gets: elastic pairs and walls, no field.
impl Default for Physics {
    fn default() -> Physics {
        Physics {
            restitution: 1.0,
            wall_restitution: 1.0,
            gravity: None,
        }
    }
}

impl Physics {
    /// Restitution `e` for pairs and walls alike, no field.
    pub fn with_restitution(e: f64) -> Physics {
        Physics {
            restitution: e,
            wall_restitution: e,
            ..Physics::default()
        }
    }

    /// Elastic pairs and walls, no field.
    pub fn elastic() -> Physics {
        Physics::default()
    }

    /// Pairs and walls give back all their normal speed: the kinetic energy is conserved.
    pub fn is_elastic(&self) -> bool {
        self.restitution == 1.0 && self.wall_restitution == 1.0
    }
}

/// A complete initial condition: box, physics and disks.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub domain: Domain,
    pub physics: Physics,
    pub particles: Particles,
}

impl Scene {
    /// Area fraction covered by disks.
    pub fn packing(&self) -> f64 {
        self.particles.disk_area() / self.domain.area()
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RadiusDistribution {
    Fixed(f64),
    /// Uniform in `[min, max]`.
    Uniform {
        min: f64,
        max: f64,
    },
}

impl RadiusDistribution {
    pub fn max(&self) -> f64 {
        match *self {
            RadiusDistribution::Fixed(r) => r,
            RadiusDistribution::Uniform { max, .. } => max,
        }
    }

    /// Mean disk area π⟨r²⟩.
    pub fn mean_area(&self) -> f64 {
        let mean_r2 = match *self {
            RadiusDistribution::Fixed(r) => r * r,
            RadiusDistribution::Uniform { min, max } => (min * min + min * max + max * max) / 3.0,
        };
        std::f64::consts::PI * mean_r2
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MassRule {
    Fixed(f64),
    /// Mass equals the disk's area π r² (unit areal density).
    Area,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Placement {
    /// Random sequential addition: uniform random non-overlapping positions.
    Random,
    /// A square lattice filling the box, for packings random addition cannot reach.
    Lattice,
}

impl Placement {
    pub fn name(self) -> &'static str {
        match self {
            Placement::Random => "random",
            Placement::Lattice => "lattice",
        }
    }

    /// The largest area fraction this placement reaches: random addition in bands jams
    /// ([`RANDOM_MAX_PACKING`]), a square lattice holds at most π/4.
    pub fn max_packing(self) -> f64 {
        match self {
            Placement::Random => RANDOM_MAX_PACKING,
            Placement::Lattice => std::f64::consts::FRAC_PI_4,
        }
    }
}

/// How big the box is: by area fraction (square box) or by explicit size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Extent {
    Packing(f64),
    Size { width: f64, height: f64 },
}

/// A seeded random gas.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GasSpec {
    pub n_particles: usize,
    pub extent: Extent,
    pub radius: RadiusDistribution,
    pub mass: MassRule,
    /// Root-mean-square speed of the initial velocities.
    pub speed_rms: f64,
    pub placement: Placement,
    pub boundary: Boundary,
    pub physics: Physics,
    pub seed: u64,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlacementError {
    #[error(
        "packing {packing} is above {RANDOM_MAX_PACKING}, past which random addition jams; \
         use placement = \"lattice\" or a lower packing"
    )]
    BeyondJamming { packing: f64 },
    #[error(
        "random placement jammed at disk {placed} of {n_particles} (packing {packing:.3}) after \
         {MAX_TRIES_PER_DISK} tries; lower the packing or use placement = \"lattice\""
    )]
    Jammed {
        placed: usize,
        n_particles: usize,
        packing: f64,
    },
    #[error(
        "a {columns}×{rows} lattice of disks of radius {max_radius} does not fit in a {width}×{height} box; \
         lower n or the packing, or enlarge the box"
    )]
    LatticeTooDense {
        columns: usize,
        rows: usize,
        max_radius: f64,
        width: f64,
        height: f64,
    },
    #[error(
        "a periodic box must be at least 3 contact diameters ({min_side}) across, got {width}×{height}; \
         enlarge the box or use boundary = \"walls\""
    )]
    PeriodicBoxTooSmall {
        min_side: f64,
        width: f64,
        height: f64,
    },
}

impl GasSpec {
    /// The reference gas of benches and tests: `n_particles` disks of radius 1 and mass
    /// 1 at area fraction `packing`, v_rms = 1, random placement, elastic walls, seed 0.
    /// Change any field with struct-update syntax.
    pub fn unit(n_particles: usize, packing: f64) -> GasSpec {
        GasSpec {
            n_particles,
            extent: Extent::Packing(packing),
            radius: RadiusDistribution::Fixed(1.0),
            mass: MassRule::Fixed(1.0),
            speed_rms: 1.0,
            placement: Placement::Random,
            boundary: Boundary::Walls,
            physics: Physics::elastic(),
            seed: 0,
        }
    }

    /// Draws radii, positions and velocities from the seed, in one process: the same
    /// disks that ranks build band by band (`sim::place`).
    pub fn build(&self) -> Result<Scene, PlacementError> {
        let (domain, particles) = self.build_whole()?;
        Ok(Scene {
            domain,
            physics: self.physics,
            particles,
        })
    }
}

/// Periodic boxes need three cells of one contact diameter each way: the cell list
/// and the minimum image both assume a disk never meets two images of another.
pub fn check_periodic_box(domain: &Domain, max_radius: f64) -> Result<(), PlacementError> {
    let min_side = 3.0 * 2.0 * max_radius;
    if domain.boundary == Boundary::Periodic
        && (domain.width < min_side || domain.height < min_side)
    {
        return Err(PlacementError::PeriodicBoxTooSmall {
            min_side,
            width: domain.width,
            height: domain.height,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use xxhash_rust::xxh3::Xxh3;

    use super::*;

    /// Hex xxh3-64 of every array of the built disks (ids, positions, velocities, radii,
    /// masses) in storage order, and of the box: equal hashes mean the same scene bit for bit.
    fn scene_hash(gas: &GasSpec) -> String {
        let scene = gas.build().expect("the gas places");
        let particles = &scene.particles;
        let mut hasher = Xxh3::new();
        for &id in &particles.id {
            hasher.update(&id.to_le_bytes());
        }
        let p = particles;
        let motion = [&p.x, &p.y, &p.vx, &p.vy].map(|values| values.iter());
        let properties = [&p.radius, &p.mass].map(|values| values.iter());
        for value in motion
            .into_iter()
            .flatten()
            .chain(properties.into_iter().flatten())
        {
            hasher.update(&value.to_le_bytes());
        }
        for value in [scene.domain.width, scene.domain.height] {
            hasher.update(&value.to_le_bytes());
        }
        format!("{:016x}", hasher.digest())
    }

    /// The placed scene is part of every recorded run (its `state_hash`, the CI baseline,
    /// the shipped results): building it faster must not change a bit. These hashes were
    /// recorded with the placement in bands (`sim::place`).
    #[test]
    fn placement_gives_the_recorded_scenes_bit_for_bit() {
        let uniform = RadiusDistribution::Uniform { min: 0.5, max: 1.5 };
        let cases = [
            (
                "walls, fixed r, packing 0.05",
                GasSpec::unit(1000, 0.05),
                "c9a3354c42781c11",
            ),
            (
                "walls, fixed r, packing 0.3",
                GasSpec::unit(20_000, 0.3),
                "68f8364636de6699",
            ),
            (
                "periodic, fixed r, packing 0.3",
                GasSpec {
                    boundary: Boundary::Periodic,
                    seed: 7,
                    ..GasSpec::unit(10_000, 0.3)
                },
                "00ca4132bff95f3c",
            ),
            (
                "walls, fixed r, packing 0.5 (near jamming)",
                GasSpec {
                    seed: 3,
                    ..GasSpec::unit(2000, 0.5)
                },
                "7546720ed999064a",
            ),
            (
                "walls, lattice, packing 0.5",
                GasSpec {
                    placement: Placement::Lattice,
                    ..GasSpec::unit(10_000, 0.5)
                },
                "1e92b08453a2a0d0",
            ),
            (
                "walls, uniform r, mass by area, packing 0.3",
                GasSpec {
                    radius: uniform,
                    mass: MassRule::Area,
                    seed: 11,
                    ..GasSpec::unit(5000, 0.3)
                },
                "6da083186345af75",
            ),
            (
                "periodic, uniform r, packing 0.05",
                GasSpec {
                    radius: uniform,
                    boundary: Boundary::Periodic,
                    seed: 5,
                    ..GasSpec::unit(5000, 0.05)
                },
                "2c761050b04eefc7",
            ),
            (
                "periodic, fewer cells than the 3x3 block",
                GasSpec {
                    boundary: Boundary::Periodic,
                    ..GasSpec::unit(5, 0.05)
                },
                "a554ac486d699f38",
            ),
            (
                "walls, a wide explicit box",
                GasSpec {
                    extent: Extent::Size {
                        width: 400.0,
                        height: 9.0,
                    },
                    speed_rms: 2.5,
                    ..GasSpec::unit(300, 0.0)
                },
                "4f41b7a873c7ab94",
            ),
        ];
        let mut failures = Vec::new();
        for (name, gas, recorded) in cases {
            let hash = scene_hash(&gas);
            if hash != recorded {
                failures.push(format!("{name}: built {hash}, recorded {recorded}"));
            }
        }
        assert!(failures.is_empty(), "{}", failures.join("\n"));
    }

    #[test]
    fn periodic_wrap_lands_in_the_box_from_either_side_and_any_distance() {
        assert_eq!(wrap_periodic(3.5, 10.0), 3.5);
        assert_eq!(wrap_periodic(10.0, 10.0), 0.0);
        assert_eq!(wrap_periodic(12.5, 10.0), 2.5);
        assert_eq!(wrap_periodic(-2.5, 10.0), 7.5);
        assert_eq!(wrap_periodic(-1e-20, 10.0), 0.0);
        assert_eq!(wrap_periodic(35.0, 10.0), 5.0);
        assert_eq!(wrap_periodic(-25.0, 10.0), 5.0);
    }
}
