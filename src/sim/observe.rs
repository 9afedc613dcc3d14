//! Observables of a state: energy (kinetic, and potential in a field), momentum, the
//! bitwise state hash, the exact count of collisions the time-stepped method misses,
//! a run's temperature, pressure and compressibility factor, and the series of
//! per-block sums they are averaged from (analysed in `stats::observables`).
//!
//! Sums run in id order so that they do not depend on storage order or on how
//! disks were divided among workers.

use xxhash_rust::xxh3::Xxh3;

use super::cells::{CellList, NONE};
use super::counters::StepCounters;
use super::event::contact_wait;
use super::particles::Particles;
use super::scene::{Domain, Physics};

/// Whole-system quantities measured at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observables {
    /// Σ ½ m v².
    pub kinetic_energy: f64,
    /// Σ m v, as [px, py].
    pub momentum: [f64; 2],
}

pub fn observe(particles: &Particles) -> Observables {
    let mut kinetic_energy = 0.0;
    let mut momentum = [0.0, 0.0];
    // Fixed order (by id): floating-point sums are not associative.
    particles.for_each_in_id_order(|idx| {
        let (m, vx, vy) = (particles.mass[idx], particles.vx[idx], particles.vy[idx]);
        kinetic_energy += 0.5 * m * (vx * vx + vy * vy);
        momentum[0] += m * vx;
        momentum[1] += m * vy;
    });
    Observables {
        kinetic_energy,
        momentum,
    }
}

/// The potential energy of the disks in the constant field `gravity`, −Σ m g·x (zero
/// at the box's lower left corner), summed in id order; 0 without a field. With the
/// kinetic energy it makes the total that an elastic scene with gravity conserves.
pub fn potential_energy(particles: &Particles, gravity: Option<[f64; 2]>) -> f64 {
    let Some([gx, gy]) = gravity else {
        return 0.0;
    };
    let mut energy = 0.0;
    // Fixed order (by id): floating-point sums are not associative.
    particles.for_each_in_id_order(|idx| {
        energy -= particles.mass[idx] * (gx * particles.x[idx] + gy * particles.y[idx]);
    });
    energy
}

/// The temperature of a state in 2D (k_B = 1): kinetic energy per disk.
pub fn temperature(particles: &Particles) -> f64 {
    observe(particles).kinetic_energy / particles.len().max(1) as f64
}

/// A run's thermodynamics in 2D (k_B = 1): the mean temperature T̄ (kinetic energy per
/// disk), the pressure from the collision virial and the compressibility factor Z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Thermodynamics {
    pub temperature: f64,
    /// P = (n·T̄ + Σ d·J / (2·t)) / A: in a walled box the bulk estimate over the whole
    /// box area (wall forces are not in the virial).
    pub pressure: f64,
    /// Z = P·A / (n·T̄); `None` for a state at rest.
    pub compressibility_z: Option<f64>,
}

/// What a run of `n` disks in a box of `area` that lasted `duration` (simulated time)
/// says of its thermodynamics. T̄ is the time average of the sampled `curve` of [t, T]
/// (trapezoids) where there is one, else the mean of the initial and final kinetic
/// energies per disk; `virial` is Σ d·J over the collisions.
pub fn thermodynamics(
    n: usize,
    area: f64,
    duration: f64,
    virial: f64,
    curve: Option<&[[f64; 2]]>,
    kinetic_energies: [f64; 2],
) -> Thermodynamics {
    let n_f = n.max(1) as f64;
    let temperature = match curve {
        Some(curve) if curve.len() > 1 => {
            let area: f64 = curve
                .windows(2)
                .map(|w| 0.5 * (w[0][1] + w[1][1]) * (w[1][0] - w[0][0]))
                .sum();
            area / (curve[curve.len() - 1][0] - curve[0][0])
        }
        _ => 0.5 * (kinetic_energies[0] + kinetic_energies[1]) / n_f,
    };
    let pressure = (n_f * temperature + virial / (2.0 * duration)) / area;
    Thermodynamics {
        temperature,
        pressure,
        compressibility_z: (temperature > 0.0).then(|| pressure * area / (n_f * temperature)),
    }
}

/// Blocks a run's observables are recorded in (fewer when the run has fewer steps).
/// 128 leaves MSER-5 25 batches (a cut to within 4% of the run) and blocking 7 levels
/// with at least 4 blocks, and lets a run whose blocks are nearly independent after the
/// cut reach the 50 independent points below which the error bar is flagged (64 would
/// not, once half is cut); a few hundred numbers per run.
pub const SERIES_BLOCKS: u64 = 128;

/// Whether step `step` (1-based) of `steps` ends one of `samples` evenly spread
/// intervals (the last one ends at `step = steps`).
pub fn ends_interval(step: u64, steps: u64, samples: u64) -> bool {
    let samples = samples.min(steps);
    // Step k is an end when ⌊k·samples/steps⌋ moves on: `samples` of them, the last at
    // k = steps.
    step * samples / steps != (step - 1) * samples / steps
}

/// When step `step` (1-based) of `steps` steps of `dt` ends a block of the series: the
/// time it ends at, or `None` inside a block. Every backend closes its blocks here.
pub fn block_end(step: u64, steps: u64, dt: f64) -> Option<f64> {
    ends_interval(step, steps, SERIES_BLOCKS).then(|| step as f64 * dt)
}

/// What happened in one block of a run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Block {
    /// Simulated time at the block's end.
    pub end: f64,
    /// The block's simulated duration.
    pub duration: f64,
    pub pair_collisions: u64,
    pub wall_collisions: u64,
    /// Σ d·J over the block's impulses.
    pub virial: f64,
    /// ∫ kinetic energy dt over the block (trapezoid between its ends).
    pub kinetic_integral: f64,
}

/// Records a run's [`Block`]s from the running counters: a block's sums are the
/// differences of the totals at its ends. The virial total is a sum of terms on a fixed
/// grid (`StepCounters::record`), so it, and each block's share, has the same bits
/// whatever order the workers added them in.
#[derive(Clone, Debug)]
pub struct SeriesRecorder {
    blocks: Vec<Block>,
    start: f64,
    counters: StepCounters,
    kinetic_energy: f64,
    /// Whether the kinetic energy changes (losses or a field): otherwise it is read once.
    reads_energy: bool,
}

impl SeriesRecorder {
    /// Starts at time 0 with the initial kinetic energy; `physics` says whether the
    /// energy must be read at each block's end.
    pub fn new(kinetic_energy: f64, physics: &Physics) -> SeriesRecorder {
        SeriesRecorder {
            blocks: Vec::with_capacity(SERIES_BLOCKS as usize),
            start: 0.0,
            counters: StepCounters::default(),
            kinetic_energy,
            reads_energy: !physics.is_elastic() || physics.gravity.is_some(),
        }
    }

    /// Closes the block that ends at `time` with the running `counters` and state.
    pub fn close_block(&mut self, time: f64, counters: &StepCounters, particles: &Particles) {
        let kinetic_energy = match self.reads_energy {
            true => observe(particles).kinetic_energy,
            false => self.kinetic_energy,
        };
        let duration = time - self.start;
        self.blocks.push(Block {
            end: time,
            duration,
            pair_collisions: counters.pair_collisions - self.counters.pair_collisions,
            wall_collisions: counters.wall_collisions - self.counters.wall_collisions,
            virial: counters.virial - self.counters.virial,
            kinetic_integral: 0.5 * (self.kinetic_energy + kinetic_energy) * duration,
        });
        (self.start, self.counters, self.kinetic_energy) = (time, *counters, kinetic_energy);
    }

    pub fn blocks(self) -> Vec<Block> {
        self.blocks
    }
}

/// Hex xxh3-64 of the exact bits of x, y, vx, vy of every disk in id order
/// (little-endian). Equal hashes mean bitwise-identical states.
pub fn state_hash(particles: &Particles) -> String {
    let mut hasher = Xxh3::new();
    particles.for_each_in_id_order(|idx| {
        for value in [
            particles.x[idx],
            particles.y[idx],
            particles.vx[idx],
            particles.vy[idx],
        ] {
            hasher.update(&value.to_le_bytes());
        }
    });
    format!("{:016x}", hasher.digest())
}

/// Counts the collisions the time-stepped method misses, exactly: a pair not touching at
/// the start of a step whose straight relative path (the disks move as `x += v·dt`;
/// a common field cancels in the relative motion) comes within contact during the step,
/// and which the step's contact resolution then gives no impulse. That is tunnelling
/// (the disks pass through each other within one step), grazing (they touch and part
/// within one step) and order effects (an earlier impulse of the same step turned the
/// pair away before its turn).
///
/// Use: [`MissedCollisions::before_step`] on the state before a step (before the disks
/// move), then the step, resolving contacts with `Stepper::resolve_contacts_noting`
/// into [`MissedCollisions::resolved`], then [`MissedCollisions::after_step`]. Exact while
/// a disk moves less than half the box in a step. Costs about one broad phase per step,
/// so the timed runs leave it off unless asked (`observe = "accuracy"`).
#[derive(Clone, Debug, Default)]
pub struct MissedCollisions {
    /// Keys (lower id << 32 | higher id) of the pairs that met during this step.
    met: Vec<u64>,
    /// Keys of the pairs the step gave an impulse.
    resolved: Vec<u64>,
    /// Missed collisions so far.
    pub missed: u64,
}

impl MissedCollisions {
    /// Finds the pairs whose paths over the coming step of `dt` bring them into contact.
    pub fn before_step(&mut self, particles: &Particles, domain: &Domain, dt: f64) {
        self.met.clear();
        self.resolved.clear();
        let reach = 2.0 * particles.max_radius() + 2.0 * particles.max_speed() * dt;
        let mut cells = CellList::new(domain, reach, particles.len());
        let mut home = Vec::with_capacity(particles.len());
        for idx in 0..particles.len() {
            let (col, row) = cells.grid.cell_of(particles.x[idx], particles.y[idx]);
            cells.insert(idx as u32, cells.grid.index(col, row));
            home.push((col, row));
        }
        for (i, &(col, row)) in home.iter().enumerate() {
            for neighbour in cells.grid.neighbourhood(col, row) {
                let mut j = cells.first_in_cell(neighbour.cell);
                while j != NONE {
                    let j_idx = j as usize;
                    j = cells.next_in_cell(j);
                    // Each pair once per image: from its lower storage index.
                    if j_idx <= i {
                        continue;
                    }
                    let dx = particles.x[j_idx] + neighbour.shift_x - particles.x[i];
                    let dy = particles.y[j_idx] + neighbour.shift_y - particles.y[i];
                    let dvx = particles.vx[j_idx] - particles.vx[i];
                    let dvy = particles.vy[j_idx] - particles.vy[i];
                    let contact = particles.radius[i] + particles.radius[j_idx];
                    if dx * dx + dy * dy < contact * contact {
                        continue; // touching already: not a new meeting
                    }
                    if contact_wait(dx, dy, dvx, dvy, contact) <= dt {
                        let (a, b) = (particles.id[i], particles.id[j_idx]);
                        self.met
                            .push((u64::from(a.min(b)) << 32) | u64::from(a.max(b)));
                    }
                }
            }
        }
    }

    /// Notes that the step gave the pair `key` an impulse.
    pub fn resolved(&mut self, key: u64) {
        self.resolved.push(key);
    }

    /// Counts the pairs that met in the step without an impulse.
    pub fn after_step(&mut self) {
        self.met.sort_unstable();
        self.met.dedup();
        self.resolved.sort_unstable();
        self.missed += self
            .met
            .iter()
            .filter(|key| self.resolved.binary_search(key).is_err())
            .count() as u64;
    }
}
