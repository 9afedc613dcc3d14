//! The box, its boundary, the contact physics, and seeded initial conditions.
//!
//! Everything here is pure: a [`GasSpec`] and its seed always give the same disks.
//! Parsing scene files lives in `crate::scene_file`; this module only builds state.

use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::{Deserialize, Serialize};

use super::particles::{Disk, Particles};

/// Random sequential addition of equal disks jams near this area fraction in 2D.
pub const RSA_JAMMING_PACKING: f64 = 0.547;

/// Consecutive failed random tries for one disk before placement gives up.
const MAX_TRIES_PER_DISK: u32 = 20_000;

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

#[inline(always)]
fn minimum_image(d: f64, length: f64) -> f64 {
    if d > 0.5 * length {
        d - length
    } else if d < -0.5 * length {
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

/// Contact laws and external field of a scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Physics {
    /// Pair restitution e in [0, 1].
    pub restitution: f64,
    /// Wall restitution in [0, 1]: the fraction of normal speed a wall gives back.
    pub wall_restitution: f64,
    /// Constant acceleration, `None` when the scene has no field (then a step is a pure drift).
    pub gravity: Option<[f64; 2]>,
}

impl Physics {
    /// Restitution `e` for pairs and walls alike, no field.
    pub fn with_restitution(e: f64) -> Physics {
        Physics {
            restitution: e,
            wall_restitution: e,
            gravity: None,
        }
    }

    /// Elastic pairs and walls, no field.
    pub fn elastic() -> Physics {
        Physics::with_restitution(1.0)
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
        let disk_area: f64 = self
            .particles
            .radius
            .iter()
            .map(|r| std::f64::consts::PI * r * r)
            .sum();
        disk_area / self.domain.area()
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
        "packing {packing} is above {RSA_JAMMING_PACKING}, where random sequential addition jams; \
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

    /// Draws radii, positions and velocities from the seed.
    pub fn build(&self) -> Result<Scene, PlacementError> {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(self.seed);
        let radii: Vec<f64> = (0..self.n_particles)
            .map(|_| match self.radius {
                RadiusDistribution::Fixed(r) => r,
                RadiusDistribution::Uniform { min, max } => rng.random_range(min..=max),
            })
            .collect();
        let disk_area: f64 = radii.iter().map(|r| std::f64::consts::PI * r * r).sum();
        let (width, height) = match self.extent {
            Extent::Packing(packing) => {
                let side = (disk_area / packing).sqrt();
                (side, side)
            }
            Extent::Size { width, height } => (width, height),
        };
        let domain = Domain {
            width,
            height,
            boundary: self.boundary,
        };
        let max_radius = radii.iter().copied().fold(0.0, f64::max);
        check_periodic_box(&domain, max_radius)?;
        let positions = match self.placement {
            Placement::Random => {
                let packing = disk_area / domain.area();
                if packing > RSA_JAMMING_PACKING {
                    return Err(PlacementError::BeyondJamming { packing });
                }
                place_random(&domain, &radii, &mut rng)?
            }
            Placement::Lattice => place_lattice(&domain, self.n_particles, max_radius)?,
        };
        let masses: Vec<f64> = radii
            .iter()
            .map(|&r| match self.mass {
                MassRule::Fixed(m) => m,
                MassRule::Area => std::f64::consts::PI * r * r,
            })
            .collect();
        let velocities = maxwellian_velocities(&masses, self.speed_rms, &mut rng);
        let mut disks: Vec<Disk> = (0..self.n_particles)
            .map(|i| Disk {
                x: positions[i].0,
                y: positions[i].1,
                vx: velocities[i].0,
                vy: velocities[i].1,
                radius: radii[i],
                mass: masses[i],
            })
            .collect();
        // Ids in row order (rows one contact diameter tall, then x): canonical pair order
        // goes by id, so numbering neighbours close together keeps every pass over the
        // contacts close in memory. Placement order is random in space.
        let row_height = 2.0 * max_radius;
        disks.sort_by(|a, b| {
            let (row_a, row_b) = ((a.y / row_height).floor(), (b.y / row_height).floor());
            row_a.total_cmp(&row_b).then(a.x.total_cmp(&b.x))
        });
        Ok(Scene {
            domain,
            physics: self.physics,
            particles: Particles::from_disks(&disks),
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

/// Random sequential addition with a linked-cell occupancy grid (O(1) per try).
fn place_random(
    domain: &Domain,
    radii: &[f64],
    rng: &mut Xoshiro256PlusPlus,
) -> Result<Vec<(f64, f64)>, PlacementError> {
    const NONE: u32 = u32::MAX;
    let max_radius = radii.iter().copied().fold(0.0, f64::max);
    // At least one contact diameter; wider in sparse boxes, so the grid never has more
    // cells than disks.
    let cell = (2.0 * max_radius).max((domain.area() / radii.len() as f64).sqrt());
    let n_cols = ((domain.width / cell).floor() as usize).max(1);
    let n_rows = ((domain.height / cell).floor() as usize).max(1);
    let (cell_w, cell_h) = (domain.width / n_cols as f64, domain.height / n_rows as f64);
    let mut head = vec![NONE; n_cols * n_rows];
    let mut next = vec![NONE; radii.len()];
    let mut positions: Vec<(f64, f64)> = Vec::with_capacity(radii.len());
    let periodic = domain.boundary == Boundary::Periodic;
    let cell_of = |x: f64, y: f64| {
        (
            ((x / cell_w) as usize).min(n_cols - 1),
            ((y / cell_h) as usize).min(n_rows - 1),
        )
    };
    for (idx, &r) in radii.iter().enumerate() {
        let (lo_x, hi_x, lo_y, hi_y) = if periodic {
            (0.0, domain.width, 0.0, domain.height)
        } else {
            (r, domain.width - r, r, domain.height - r)
        };
        let mut tries = 0;
        let (x, y) = loop {
            if tries == MAX_TRIES_PER_DISK || lo_x > hi_x || lo_y > hi_y {
                let placed_area: f64 = radii[..idx]
                    .iter()
                    .map(|r| std::f64::consts::PI * r * r)
                    .sum();
                return Err(PlacementError::Jammed {
                    placed: idx,
                    n_particles: radii.len(),
                    packing: placed_area / domain.area(),
                });
            }
            tries += 1;
            let x = uniform_in(rng, lo_x, hi_x);
            let y = uniform_in(rng, lo_y, hi_y);
            let (cx, cy) = cell_of(x, y);
            let mut free = true;
            'cells: for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let Some(neighbour) = neighbour_cell(cx, cy, dx, dy, n_cols, n_rows, periodic)
                    else {
                        continue;
                    };
                    let mut other = head[neighbour];
                    while other != NONE {
                        let (ox, oy) = positions[other as usize];
                        let (sx, sy) = domain.separation(x, y, ox, oy);
                        let contact = r + radii[other as usize];
                        if sx * sx + sy * sy < contact * contact {
                            free = false;
                            break 'cells;
                        }
                        other = next[other as usize];
                    }
                }
            }
            if free {
                break (x, y);
            }
        };
        let (cx, cy) = cell_of(x, y);
        let cell_idx = cy * n_cols + cx;
        next[idx] = head[cell_idx];
        head[cell_idx] = idx as u32;
        positions.push((x, y));
    }
    Ok(positions)
}

/// Uniform in `[low, high)`, or `low` when the interval is a single point.
fn uniform_in(rng: &mut Xoshiro256PlusPlus, low: f64, high: f64) -> f64 {
    if high > low {
        rng.random_range(low..high)
    } else {
        low
    }
}

/// The neighbour of cell (cx, cy) at offset (dx, dy), wrapped when periodic.
/// Small grids may map several offsets to one cell; placement only reads, so that is harmless.
fn neighbour_cell(
    cx: usize,
    cy: usize,
    dx: i64,
    dy: i64,
    n_cols: usize,
    n_rows: usize,
    periodic: bool,
) -> Option<usize> {
    let (mut nx, mut ny) = (cx as i64 + dx, cy as i64 + dy);
    let (cols, rows) = (n_cols as i64, n_rows as i64);
    if periodic {
        nx = nx.rem_euclid(cols);
        ny = ny.rem_euclid(rows);
    } else if nx < 0 || ny < 0 || nx >= cols || ny >= rows {
        return None;
    }
    Some(ny as usize * n_cols + nx as usize)
}

/// Disk centres on a square lattice as close to the box's aspect as possible.
fn place_lattice(
    domain: &Domain,
    n_particles: usize,
    max_radius: f64,
) -> Result<Vec<(f64, f64)>, PlacementError> {
    let aspect = domain.width / domain.height;
    let columns = ((n_particles as f64 * aspect).sqrt().ceil() as usize).max(1);
    let rows = n_particles.div_ceil(columns).max(1);
    let spacing = (domain.width / columns as f64).min(domain.height / rows as f64);
    // The lattice sits centred in the box, so a spacing of one diameter also keeps the
    // outer disks half a spacing (at least one radius) clear of walls and periodic images.
    if spacing < 2.0 * max_radius {
        return Err(PlacementError::LatticeTooDense {
            columns,
            rows,
            max_radius,
            width: domain.width,
            height: domain.height,
        });
    }
    let x0 = 0.5 * (domain.width - spacing * (columns as f64 - 1.0));
    let y0 = 0.5 * (domain.height - spacing * (rows as f64 - 1.0));
    Ok((0..n_particles)
        .map(|i| {
            let (col, row) = (i % columns, i / columns);
            (x0 + spacing * col as f64, y0 + spacing * row as f64)
        })
        .collect())
}

/// Maxwellian velocities at equipartition, with the centre-of-mass drift removed and the
/// rms speed scaled to exactly `speed_rms`.
fn maxwellian_velocities(
    masses: &[f64],
    speed_rms: f64,
    rng: &mut Xoshiro256PlusPlus,
) -> Vec<(f64, f64)> {
    let mean_mass = masses.iter().sum::<f64>() / masses.len() as f64;
    let mut velocities: Vec<(f64, f64)> = masses
        .iter()
        .map(|&m| {
            let scale = (mean_mass / m).sqrt();
            let gx: f64 = rng.sample(StandardNormal);
            let gy: f64 = rng.sample(StandardNormal);
            (gx * scale, gy * scale)
        })
        .collect();
    let total_mass: f64 = masses.iter().sum();
    let (px, py) = masses
        .iter()
        .zip(&velocities)
        .fold((0.0, 0.0), |(px, py), (m, v)| (px + m * v.0, py + m * v.1));
    let (drift_x, drift_y) = (px / total_mass, py / total_mass);
    for v in &mut velocities {
        v.0 -= drift_x;
        v.1 -= drift_y;
    }
    let mean_square = velocities
        .iter()
        .map(|v| v.0 * v.0 + v.1 * v.1)
        .sum::<f64>()
        / velocities.len() as f64;
    let scale = if mean_square > 0.0 {
        speed_rms / mean_square.sqrt()
    } else {
        0.0
    };
    for v in &mut velocities {
        v.0 *= scale;
        v.1 *= scale;
    }
    velocities
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
        for values in [&p.x, &p.y, &p.vx, &p.vy, &p.radius, &p.mass] {
            for value in values {
                hasher.update(&value.to_le_bytes());
            }
        }
        for value in [scene.domain.width, scene.domain.height] {
            hasher.update(&value.to_le_bytes());
        }
        format!("{:016x}", hasher.digest())
    }

    /// The placed scene is part of every recorded run (its `state_hash`, the CI baseline,
    /// the shipped results): building it faster must not change a bit. These hashes were
    /// recorded with the first, straightforward placement.
    #[test]
    fn placement_gives_the_recorded_scenes_bit_for_bit() {
        let uniform = RadiusDistribution::Uniform { min: 0.5, max: 1.5 };
        let cases = [
            (
                "walls, fixed r, packing 0.05",
                GasSpec::unit(1000, 0.05),
                "07c04ced0ba38b3c",
            ),
            (
                "walls, fixed r, packing 0.3",
                GasSpec::unit(20_000, 0.3),
                "c2bcea67c4a69616",
            ),
            (
                "periodic, fixed r, packing 0.3",
                GasSpec {
                    boundary: Boundary::Periodic,
                    seed: 7,
                    ..GasSpec::unit(10_000, 0.3)
                },
                "c1fd7ae01e149fad",
            ),
            (
                "walls, fixed r, packing 0.5 (near jamming)",
                GasSpec {
                    seed: 3,
                    ..GasSpec::unit(2000, 0.5)
                },
                "6fc5038adae5a01b",
            ),
            (
                "walls, lattice, packing 0.5",
                GasSpec {
                    placement: Placement::Lattice,
                    ..GasSpec::unit(10_000, 0.5)
                },
                "533d686477129f0a",
            ),
            (
                "walls, uniform r, mass by area, packing 0.3",
                GasSpec {
                    radius: uniform,
                    mass: MassRule::Area,
                    seed: 11,
                    ..GasSpec::unit(5000, 0.3)
                },
                "91ec5649f3dead32",
            ),
            (
                "periodic, uniform r, packing 0.05",
                GasSpec {
                    radius: uniform,
                    boundary: Boundary::Periodic,
                    seed: 5,
                    ..GasSpec::unit(5000, 0.05)
                },
                "9b472947163f9089",
            ),
            (
                "periodic, fewer cells than the 3x3 block",
                GasSpec {
                    boundary: Boundary::Periodic,
                    ..GasSpec::unit(5, 0.05)
                },
                "d956c3dda4592449",
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
                "05dff41a6f878bfc",
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
