//! Observables of a state: energy (kinetic, and potential in a field), momentum, the
//! bitwise state hash, the exact count of collisions the time-stepped method misses,
//! a run's temperature, pressure and compressibility factor, and the series of
//! per-block sums they are averaged from (analysed in `stats::observables`).
//!
//! Every whole-system sum is exact ([`ExactSum`]) and the state hash adds one hash per
//! disk, so none depends on the order the disks are stored in or on how they were
//! divided among threads and ranks: a rank sums its own disks ([`StateSums`]) and the
//! ranks' sums merge into the serial run's bits.

use xxhash_rust::xxh3::xxh3_64;

use super::cells::{CellList, NONE};
use super::counters::StepCounters;
use super::event::contact_wait;
use super::exact_sum::{EXACT_SUM_WORDS, ExactSum};
use super::particles::{DiskFigures, Particles};
use super::scene::{Domain, Physics};

/// Whole-system quantities measured at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observables {
    /// Σ ½ m v².
    pub kinetic_energy: f64,
    /// Σ m v, as [px, py].
    pub momentum: [f64; 2],
}

/// The kinetic energy and momentum of `particles`.
pub fn observe(particles: &Particles) -> Observables {
    let mut sums = StateSums::default();
    for idx in 0..particles.len() {
        sums.add_motion(particles, idx);
    }
    sums.observables()
}

/// The potential energy of the disks in the constant field `gravity`, −Σ m g·x (zero
/// at the box's lower left corner); 0 without a field. With the kinetic energy it makes
/// the total that an elastic scene with gravity conserves.
pub fn potential_energy(particles: &Particles, gravity: Option<[f64; 2]>) -> f64 {
    let Some(gravity) = gravity else {
        return 0.0;
    };
    (0..particles.len())
        .map(|idx| potential_of(particles, idx, gravity))
        .collect::<ExactSum>()
        .value()
}

/// −m g·x of the disk stored at `idx`.
#[inline]
fn potential_of(particles: &Particles, idx: usize, [gx, gy]: [f64; 2]) -> f64 {
    -(particles.mass[idx] * (gx * particles.x[idx] + gy * particles.y[idx]))
}

/// ½ m v² of the disk stored at `idx`.
#[inline]
pub fn kinetic_of(particles: &Particles, idx: usize) -> f64 {
    let (vx, vy) = (particles.vx[idx], particles.vy[idx]);
    0.5 * particles.mass[idx] * (vx * vx + vy * vy)
}

/// The exact sums over some disks that whole-system figures come from, to be merged
/// with other disks' sums in any order: a rank's own disks, or all of them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StateSums {
    pub disks: u64,
    kinetic: ExactSum,
    momentum: [ExactSum; 2],
    /// −Σ m g·x in the field the sums were taken in (0 without one).
    potential: ExactSum,
    /// Σ (wrapping) of each disk's hash of its id and exact x, y, vx, vy.
    hash: u64,
    pub max_radius: f64,
}

/// Values of [`StateSums::to_words`].
pub const STATE_SUMS_WORDS: usize = 4 * EXACT_SUM_WORDS + 4;

impl StateSums {
    /// The sums over the disks stored at `disks`, with the potential energy in `gravity`.
    pub fn of(
        particles: &Particles,
        disks: std::ops::Range<usize>,
        gravity: Option<[f64; 2]>,
    ) -> StateSums {
        let mut sums = StateSums {
            disks: disks.len() as u64,
            ..StateSums::default()
        };
        for idx in disks {
            sums.add_motion(particles, idx);
            if let Some(gravity) = gravity {
                sums.potential.add(potential_of(particles, idx, gravity));
            }
            let (x, y) = (particles.x[idx], particles.y[idx]);
            let (vx, vy) = (particles.vx[idx], particles.vy[idx]);
            sums.hash = sums
                .hash
                .wrapping_add(disk_hash(particles.id[idx], [x, y, vx, vy]));
            sums.max_radius = sums.max_radius.max(particles.radius[idx]);
        }
        sums
    }

    /// The sums over every disk.
    pub fn all(particles: &Particles, gravity: Option<[f64; 2]>) -> StateSums {
        StateSums::of(particles, 0..particles.len(), gravity)
    }

    /// Adds the kinetic energy and momentum of the disk stored at `idx`.
    #[inline]
    fn add_motion(&mut self, particles: &Particles, idx: usize) {
        let (m, vx, vy) = (particles.mass[idx], particles.vx[idx], particles.vy[idx]);
        self.kinetic.add(kinetic_of(particles, idx));
        self.momentum[0].add(m * vx);
        self.momentum[1].add(m * vy);
    }

    /// Adds the sums of other disks.
    pub fn merge(&mut self, other: &StateSums) {
        self.disks += other.disks;
        self.kinetic.merge(&other.kinetic);
        self.momentum[0].merge(&other.momentum[0]);
        self.momentum[1].merge(&other.momentum[1]);
        self.potential.merge(&other.potential);
        self.hash = self.hash.wrapping_add(other.hash);
        self.max_radius = self.max_radius.max(other.max_radius);
    }

    pub fn observables(&self) -> Observables {
        Observables {
            kinetic_energy: self.kinetic.value(),
            momentum: [self.momentum[0].value(), self.momentum[1].value()],
        }
    }

    pub fn potential_energy(&self) -> f64 {
        self.potential.value()
    }

    /// The state hash: equal hashes mean bitwise-identical states.
    pub fn state_hash(&self) -> String {
        format!("{:016x}", self.hash)
    }

    /// The sums as [`STATE_SUMS_WORDS`] exact `f64`s, to send between ranks.
    pub fn to_words(&self) -> Vec<f64> {
        let mut words = Vec::with_capacity(STATE_SUMS_WORDS);
        for sum in [
            &self.kinetic,
            &self.momentum[0],
            &self.momentum[1],
            &self.potential,
        ] {
            words.extend(sum.to_words());
        }
        // Counts below 2⁵³ and the hash in halves of 32 bits: exact as f64.
        words.extend([
            self.disks as f64,
            (self.hash >> 32) as f64,
            (self.hash & 0xffff_ffff) as f64,
            self.max_radius,
        ]);
        words
    }

    pub fn from_words(words: &[f64]) -> StateSums {
        let sum = |k: usize| ExactSum::from_words(&words[k * EXACT_SUM_WORDS..]);
        let rest = &words[4 * EXACT_SUM_WORDS..];
        StateSums {
            kinetic: sum(0),
            momentum: [sum(1), sum(2)],
            potential: sum(3),
            disks: rest[0] as u64,
            hash: ((rest[1] as u64) << 32) | rest[2] as u64,
            max_radius: rest[3],
        }
    }
}

/// What set-up reads of the initial disks, as exact sums and extremes that merge in any
/// order, so that ranks holding parts of a scene read the whole scene's figures to the
/// bit: the [`StateSums`] but the hash, the area covered and Σ v² (for the packing and
/// the rms speed), and the extremes that size strips, skins and a dt rule.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneSums {
    pub state: StateSums,
    area: ExactSum,
    speed_square: ExactSum,
    min_radius: f64,
    max_speed: f64,
}

impl Default for SceneSums {
    fn default() -> SceneSums {
        SceneSums {
            state: StateSums::default(),
            area: ExactSum::default(),
            speed_square: ExactSum::default(),
            min_radius: f64::INFINITY,
            max_speed: 0.0,
        }
    }
}

impl SceneSums {
    /// The sums over every disk of `particles`, with the potential energy in `gravity`.
    pub fn of(particles: &Particles, gravity: Option<[f64; 2]>) -> SceneSums {
        let mut sums = SceneSums::default();
        sums.state.disks = particles.len() as u64;
        let mut fastest_square = 0.0_f64;
        for idx in 0..particles.len() {
            let state = &mut sums.state;
            state.add_motion(particles, idx);
            if let Some(gravity) = gravity {
                state.potential.add(potential_of(particles, idx, gravity));
            }
            let (vx, vy) = (particles.vx[idx], particles.vy[idx]);
            let speed_square = vx * vx + vy * vy;
            fastest_square = fastest_square.max(speed_square);
            sums.speed_square.add(speed_square);
        }
        sums.max_speed = fastest_square.sqrt();
        match particles.radius.shared() {
            // Equal disks: n equal areas, as an exact product (its value and its error).
            Some(r) => {
                let (n, each) = (particles.len() as f64, std::f64::consts::PI * r * r);
                let product = n * each;
                sums.area.add(product);
                sums.area.add(n.mul_add(each, -product));
                if !particles.is_empty() {
                    sums.state.max_radius = r;
                    sums.min_radius = r;
                }
            }
            None => {
                for r in particles.radius.iter().copied() {
                    sums.area.add(std::f64::consts::PI * r * r);
                    sums.state.max_radius = sums.state.max_radius.max(r);
                    sums.min_radius = sums.min_radius.min(r);
                }
            }
        }
        sums
    }

    /// Adds the sums of other disks.
    pub fn merge(&mut self, other: &SceneSums) {
        self.state.merge(&other.state);
        self.area.merge(&other.area);
        self.speed_square.merge(&other.speed_square);
        self.min_radius = self.min_radius.min(other.min_radius);
        self.max_speed = self.max_speed.max(other.max_speed);
    }

    /// The sums as exact `f64`s, to send between ranks.
    pub fn to_words(&self) -> Vec<f64> {
        let mut words = self.state.to_words();
        words.extend(self.area.to_words());
        words.extend(self.speed_square.to_words());
        words.extend([self.min_radius, self.max_speed]);
        words
    }

    pub fn from_words(words: &[f64]) -> SceneSums {
        let rest = &words[STATE_SUMS_WORDS..];
        let extremes = &rest[2 * EXACT_SUM_WORDS..];
        SceneSums {
            state: StateSums::from_words(words),
            area: ExactSum::from_words(rest),
            speed_square: ExactSum::from_words(&rest[EXACT_SUM_WORDS..]),
            min_radius: extremes[0],
            max_speed: extremes[1],
        }
    }

    /// √⟨v²⟩ over the disks, 0 for none.
    pub fn rms_speed(&self) -> f64 {
        (self.speed_square.value() / self.state.disks.max(1) as f64).sqrt()
    }

    pub fn figures(&self) -> DiskFigures {
        DiskFigures {
            n_disks: self.state.disks as usize,
            disk_area: self.area.value(),
            max_radius: self.state.max_radius,
            min_radius: self.min_radius,
            max_speed: self.max_speed,
        }
    }
}

/// xxh3-64 of a disk's id and the exact bits of its x, y, vx, vy (little-endian).
fn disk_hash(id: u32, state: [f64; 4]) -> u64 {
    let mut bytes = [0u8; 36];
    bytes[..4].copy_from_slice(&id.to_le_bytes());
    for (k, value) in state.iter().enumerate() {
        bytes[4 + 8 * k..12 + 8 * k].copy_from_slice(&value.to_le_bytes());
    }
    xxh3_64(&bytes)
}

/// Σ ½ m v², alone (cheaper than [`observe`]).
pub fn kinetic_energy(particles: &Particles) -> f64 {
    (0..particles.len())
        .map(|idx| kinetic_of(particles, idx))
        .collect::<ExactSum>()
        .value()
}

/// The temperature of a state in 2D (k_B = 1): kinetic energy per disk.
pub fn temperature(particles: &Particles) -> f64 {
    kinetic_energy(particles) / particles.len().max(1) as f64
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
    ends_interval(step, steps, SERIES_BLOCKS).then_some(step as f64 * dt)
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
        self.close_block_with(time, counters, || kinetic_energy(particles));
    }

    /// Whether each block's end reads the kinetic energy.
    pub fn reads_energy(&self) -> bool {
        self.reads_energy
    }

    /// Closes the block that ends at `time` with the running `counters`; `kinetic_energy`
    /// gives the state's, called only if [`Self::reads_energy`].
    pub fn close_block_with(
        &mut self,
        time: f64,
        counters: &StepCounters,
        kinetic_energy: impl FnOnce() -> f64,
    ) {
        let kinetic_energy = match self.reads_energy {
            true => kinetic_energy(),
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

/// The state hash of every disk (see [`StateSums::state_hash`]): equal hashes mean
/// bitwise-identical states, whatever order the disks are stored in.
pub fn state_hash(particles: &Particles) -> String {
    StateSums::all(particles, None).state_hash()
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::scene::GasSpec;

    fn figures(sums: &StateSums) -> ([u64; 4], String) {
        let o = sums.observables();
        let bits = [
            o.kinetic_energy,
            o.momentum[0],
            o.momentum[1],
            sums.potential_energy(),
        ];
        (bits.map(f64::to_bits), sums.state_hash())
    }

    /// The figures of a state do not depend on the order its disks are stored in, nor on
    /// how they were divided (as among ranks, each summing its own and sending the sums).
    #[test]
    fn figures_and_hash_are_the_same_in_any_storage_order_and_any_division() {
        let mut particles = GasSpec::unit(500, 0.3).build().unwrap().particles;
        let gravity = Some([0.0, -0.1]);
        let whole = StateSums::all(&particles, gravity);
        let reversed: Vec<u32> = (0..particles.len() as u32).rev().collect();
        particles.reorder(&reversed);
        assert_eq!(
            figures(&StateSums::all(&particles, gravity)),
            figures(&whole)
        );
        for cut in [0, 1, 250, 499] {
            let mut divided = StateSums::of(&particles, cut..particles.len(), gravity);
            let sent = StateSums::of(&particles, 0..cut, gravity).to_words();
            assert_eq!(sent.len(), STATE_SUMS_WORDS);
            divided.merge(&StateSums::from_words(&sent));
            assert_eq!(figures(&divided), figures(&whole), "cut at {cut}");
            assert_eq!(divided.disks, 500);
        }
    }

    #[test]
    fn the_hash_tells_apart_states_one_bit_apart() {
        let mut particles = GasSpec::unit(100, 0.3).build().unwrap().particles;
        let before = state_hash(&particles);
        particles.vx[37] = f64::from_bits(particles.vx[37].to_bits() ^ 1);
        assert_ne!(state_hash(&particles), before);
        // The same numbers on swapped disks are another state.
        particles.vx[37] = f64::from_bits(particles.vx[37].to_bits() ^ 1);
        particles.vx.swap(3, 4);
        assert_ne!(state_hash(&particles), before);
    }
}
