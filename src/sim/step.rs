//! One time step of the seed's method, composed from integration, boundary, broad phase
//! and contact resolution. Cannot fail, does no I/O.
//!
//! Determinism rule: contacts are resolved one after another in the canonical order of
//! their id pairs (`Contact::key`). Two contacts that share no disk commute exactly, so
//! any schedule that keeps this order within each chain of contacts sharing disks gives
//! the same bits; that is what lets parallel backends reproduce this serial reference.

use serde::{Deserialize, Serialize};

use super::counters::StepCounters;
use super::grid::{Contact, StripGrid, find_contacts_all_pairs};
use super::neighbours::{
    DISPLACEMENT_BLOCK, Displacements, PairList, Skin, mark_escapees, with_reorder_scratch,
};
use super::particles::{DiskFigures, DiskSlices, Particles, PerDiskSlice};
use super::pieces::InTurn;
use super::resolve::resolve_contacts;
use super::scene::{Boundary, Domain, Physics, Scene, wrap_periodic};
use super::schedule::ResolutionOrder;

/// Grid builds between re-storings of the disks in grid order, in scenes of fewer than
/// [`LARGE_SCENE_DISKS`] disks: their arrays stay in the caches, where a pair scan
/// reading disks stored out of grid order loses little.
const SMALL_SCENE_REORDER_INTERVAL: u32 = 16;

/// Grid builds between re-storings in larger scenes: as disks drift from the order they
/// were stored in, the lists' pairs read positions further apart in memory, and past the
/// caches each such read waits on memory. Re-storing every 4 builds instead of 16
/// measured 1.03–1.12× at 6·10⁵ and 10⁶ disks, 1.02–1.06× at 10⁷ (100 steps), 0.94–1.05×
/// at 10⁵; every 2 instead of 4, serial 1.00–1.04× at 6·10⁵ and 10⁶, 0.99–1.00× at 10⁷,
/// rayon 1.02–1.08× over 100 steps and more but 0.91–0.93× over 50 at 10⁶ and 0.05
/// (`docs/performance.md`).
const LARGE_SCENE_REORDER_INTERVAL: u32 = 2;

/// Scenes from this many disks on are re-stored every [`LARGE_SCENE_REORDER_INTERVAL`]
/// builds: about where positions and lists (some 35 bytes per disk) outgrow a server's
/// last-level cache (3·10⁵ disks already gained 1.06× on a 32 MB one).
const LARGE_SCENE_DISKS: usize = 1 << 18;

/// When a stepper re-stores the disks in grid order: at the first build (a sort from
/// scratch: a new scene is stored in placement order, which is random in space), then
/// every 16 builds, or every 2 in scenes too large for the caches. Storage order never
/// changes a result, so each backend could keep its own; they share this one.
#[derive(Clone, Copy, Debug)]
pub struct ReorderSchedule {
    interval: u32,
    builds_since: u32,
}

impl ReorderSchedule {
    /// The schedule for a scene of `n_disks` disks (all ranks' or threads' together).
    pub fn for_scene(n_disks: usize) -> ReorderSchedule {
        let interval = if n_disks >= LARGE_SCENE_DISKS {
            LARGE_SCENE_REORDER_INTERVAL
        } else {
            SMALL_SCENE_REORDER_INTERVAL
        };
        ReorderSchedule {
            interval,
            builds_since: interval - 1,
        }
    }

    /// Counts one grid build; true when it re-stores the disks.
    pub fn count_build(&mut self) -> bool {
        self.builds_since += 1;
        let due = self.builds_since >= self.interval;
        if due {
            self.builds_since = 0;
        }
        due
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Broadphase {
    /// Cell list, O(N) per step.
    #[default]
    Grid,
    /// Every pair, O(N²) per step: the seed report's algorithm, kept for comparison.
    AllPairs,
}

impl Broadphase {
    pub fn name(self) -> &'static str {
        match self {
            Broadphase::Grid => "grid",
            Broadphase::AllPairs => "allpairs",
        }
    }
}

/// Settings of the time-stepped method.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepParams {
    /// Time step, positive and finite.
    pub dt: f64,
    pub broadphase: Broadphase,
}

/// Advances a set of disks in time. Holds scratch memory only; the caller owns the disks.
#[derive(Clone, Debug)]
pub struct Stepper {
    domain: Domain,
    physics: Physics,
    params: StepParams,
    /// Strips tall enough for the neighbour list's skin.
    grid: StripGrid,
    skin: Skin,
    neighbours: PairList,
    /// Disks that moved half the skin since the list was built (this step's).
    pub(crate) escapees: Vec<u32>,
    /// When the disks are next stored in grid order.
    reorder: ReorderSchedule,
    contacts: Vec<Contact>,
    order: ResolutionOrder,
    counters: StepCounters,
}

impl Stepper {
    pub fn new(
        domain: Domain,
        physics: Physics,
        params: StepParams,
        particles: &Particles,
    ) -> Self {
        let (skin, grid) = Skin::with_grid(&domain, particles, params.dt);
        Stepper {
            domain,
            physics,
            params,
            grid,
            skin,
            neighbours: PairList::default(),
            escapees: Vec::new(),
            reorder: ReorderSchedule::for_scene(particles.len()),
            contacts: Vec::new(),
            order: ResolutionOrder::default(),
            counters: StepCounters::default(),
        }
    }

    /// A stepper for the disks of `scene`.
    pub fn for_scene(scene: &Scene, params: StepParams) -> Self {
        Stepper::new(scene.domain, scene.physics, params, &scene.particles)
    }

    pub fn counters(&self) -> StepCounters {
        self.counters
    }

    /// The pairs the last [`Stepper::find_contacts`] found, in resolution order.
    pub fn contacts(&self) -> &[Contact] {
        &self.contacts
    }

    /// Builds the neighbour list at the disks' present positions (it may re-store them),
    /// as the first step would: part of a run's set-up, so that the stepping loop's
    /// clock counts steps alike (molecular-dynamics codes such as LAMMPS build their
    /// lists in a set-up phase that their loop time leaves out). Changes no result:
    /// when lists are built never does (`sim::neighbours`).
    pub fn build_lists(&mut self, particles: &mut Particles) {
        if self.params.broadphase == Broadphase::Grid && !self.skin.is_built_for(particles) {
            self.rebuild_list(particles);
        }
    }

    /// One full step: move, apply the boundary, find overlaps, resolve them.
    pub fn step(&mut self, particles: &mut Particles) {
        self.advance(particles);
        self.find_contacts(particles);
        self.resolve_contacts(particles);
    }

    /// Moves every disk by one dt and applies the boundary ([`advance_disks`]).
    pub fn advance(&mut self, particles: &mut Particles) {
        let n_particles = particles.len();
        let walls = advance_disks(
            &self.domain,
            &self.physics,
            self.params.dt,
            particles.disk_slices_mut(),
            self.skin.tracking(n_particles),
        );
        self.counters.merge(&walls);
    }

    /// Finds every overlapping pair, in an order that resolves with the canonical bits
    /// ([`ResolutionOrder::arrange`]). May change the storage order of the disks (never
    /// their ids or values).
    pub fn find_contacts(&mut self, particles: &mut Particles) {
        self.contacts.clear();
        match self.params.broadphase {
            Broadphase::Grid => self.find_contacts_listed(particles),
            Broadphase::AllPairs => {
                find_contacts_all_pairs(particles, &self.domain, &mut self.contacts);
            }
        }
        // The result of resolution must not depend on how pairs were found: lone pairs
        // commute with every other, the rest go in canonical order. A pair of an escapee
        // may have been found twice (see `find_contacts_listed`): kept once.
        self.order.arrange(&particles.id, &mut self.contacts);
    }

    /// The overlapping pairs from the neighbour list, rebuilt when it is stale. Disks
    /// that escaped it (moved half the skin), while few, have their pairs found by
    /// queries of the grid instead of a rebuild.
    fn find_contacts_listed(&mut self, particles: &mut Particles) {
        let domain = &self.domain.clone();
        let largest_sq = self
            .skin
            .largest_displacement_sq(particles, domain, &InTurn);
        self.escapees.clear();
        if self.skin.is_exceeded(largest_sq) {
            if self.skin.may_reach(largest_sq) {
                let all = 0..particles.len();
                self.skin.escapees(all, &mut self.escapees);
            }
            if !self
                .skin
                .may_patch(self.escapees.len(), particles.len(), largest_sq)
            {
                self.escapees.clear();
                self.rebuild_list(particles);
            }
        }
        self.neighbours
            .find_contacts(particles, domain, &mut self.contacts);
        if !self.escapees.is_empty() {
            self.grid.find_contacts_of(
                &self.escapees,
                largest_sq.sqrt(),
                particles,
                domain,
                &mut self.contacts,
            );
        }
    }

    /// Re-sorts the grid (when the [`ReorderSchedule`] says so, the disks too) and
    /// rebuilds the neighbour list at the disks' positions.
    fn rebuild_list(&mut self, particles: &mut Particles) {
        self.grid.build(particles);
        if self.reorder.count_build() {
            // Storing disks in grid order keeps the next builds' reads sequential. It
            // works in the memory of the list, rebuilt below.
            let grid = &mut self.grid;
            let lists = std::slice::from_mut(&mut self.neighbours);
            with_reorder_scratch(lists, particles.len(), |scratch| {
                grid.store_in_grid_order(particles, scratch, &InTurn);
            });
        }
        let strips = self.grid.owned();
        self.neighbours
            .rebuild(&self.grid, strips, particles, &self.domain, &self.skin);
        self.skin.record(particles, &InTurn);
    }

    /// Resolves the found pairs ([`resolve_contacts`]).
    pub fn resolve_contacts(&mut self, particles: &mut Particles) {
        self.resolve_calling(particles, |_| {});
    }

    /// [`Stepper::resolve_contacts`], then calls `collided` with the key
    /// ([`Contact::key`]) of every pair that received an impulse of the first pass: the
    /// accuracy observer (`sim::observe::MissedCollisions`) compares them with the pairs
    /// that met.
    pub fn resolve_contacts_noting(
        &mut self,
        particles: &mut Particles,
        mut collided: impl FnMut(u64),
    ) {
        let mut impulsed = Vec::new();
        self.resolve_calling(particles, |contact| impulsed.push(*contact));
        for contact in &impulsed {
            collided(contact.key(&particles.id));
        }
    }

    /// [`resolve_contacts`] of the found pairs, calling `collided` as it does.
    fn resolve_calling(&mut self, particles: &mut Particles, collided: impl FnMut(&Contact)) {
        resolve_contacts(
            particles,
            &self.domain,
            &self.physics,
            self.params.dt,
            &self.contacts,
            &mut self.counters,
            collided,
        );
    }
}

/// The per-disk half of a step for any chunk of disks: move them by one dt (the
/// seed's equations 8–9, x += v·dt, without a field; velocity Verlet, equations 6–7,
/// with a constant one), then reflect those that touch a wall while moving outward, or
/// wrap periodic ones; with `displacements` (the neighbour lists' record of this chunk,
/// which starts at a block boundary), also how far each block's disks are from where
/// the lists were built. No disk's update reads another's, so chunks can go in any
/// order or in parallel. Returns what the walls saw: the reflections and the deepest
/// penetration (the other counters are zero).
///
/// One pass over the disks, a block of [`DISPLACEMENT_BLOCK`] at a time, so that each
/// disk is read once per step; the loops over a block vectorise (their length is not
/// fixed at compile time: fully unrolled, they would not).
pub fn advance_disks(
    domain: &Domain,
    physics: &Physics,
    dt: f64,
    disks: DiskSlices<'_>,
    displacements: Option<Displacements<'_>>,
) -> StepCounters {
    match domain.boundary {
        Boundary::Walls => advance_in::<false>(domain, physics, dt, disks, displacements),
        Boundary::Periodic => advance_in::<true>(domain, physics, dt, disks, displacements),
    }
}

fn advance_in<const PERIODIC: bool>(
    domain: &Domain,
    physics: &Physics,
    dt: f64,
    disks: DiskSlices<'_>,
    displacements: Option<Displacements<'_>>,
) -> StepCounters {
    const B: usize = DISPLACEMENT_BLOCK;
    let DiskSlices {
        x,
        y,
        vx,
        vy,
        radius,
    } = disks;
    let mut walls = StepCounters::default();
    let mut record = displacements.map(|record| {
        (
            record.x_built.chunks(B),
            record.y_built.chunks(B),
            record.escaped.iter_mut(),
            record.escape_sq,
        )
    });
    let blocks = x
        .chunks_mut(B)
        .zip(y.chunks_mut(B))
        .zip(vx.chunks_mut(B))
        .zip(vy.chunks_mut(B))
        .zip(radius.chunks(B));
    for ((((x, y), vx), vy), radius) in blocks {
        let record = record
            .as_mut()
            .and_then(|(x_built, y_built, counts, escape_sq)| {
                Some((x_built.next()?, y_built.next()?, counts.next()?, *escape_sq))
            });
        advance_block::<PERIODIC>(
            x, y, vx, vy, radius, domain, physics, dt, record, &mut walls,
        );
    }
    walls
}

/// Moves the disks of one block of [`DISPLACEMENT_BLOCK`] (fewer in a chunk's last),
/// applies the boundary, and with `record` (where they were at the lists' build, the
/// slot for the block's marks of escapees, and the squared distance at which a disk
/// escapes) marks the disks that escaped the lists.
/// Not inlined: as a function's arguments the slices are known not to alias, which
/// lets its loops vectorise.
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn advance_block<const PERIODIC: bool>(
    x: &mut [f64],
    y: &mut [f64],
    vx: &mut [f64],
    vy: &mut [f64],
    radius: PerDiskSlice<'_>,
    domain: &Domain,
    physics: &Physics,
    dt: f64,
    record: Option<(&[f32], &[f32], &mut u64, f64)>,
    walls: &mut StepCounters,
) {
    match physics.gravity {
        None => {
            drift(x, vx, dt);
            drift(y, vy, dt);
        }
        Some([gx, gy]) => {
            accelerate(x, vx, gx, dt);
            accelerate(y, vy, gy, dt);
        }
    }
    if PERIODIC {
        wrap_block(x, domain.width);
        wrap_block(y, domain.height);
    } else {
        match radius {
            PerDiskSlice::Shared { value, .. } => {
                reflect_at_walls(x, y, vx, vy, |_| value, domain, physics, walls);
            }
            PerDiskSlice::Each(radius) => {
                let radius = &radius[..x.len()];
                reflect_at_walls(x, y, vx, vy, |i| radius[i], domain, physics, walls);
            }
        }
    }
    if let Some((x0, y0, escapees, escape_sq)) = record {
        *escapees = mark_escapees::<PERIODIC>(x, y, x0, y0, domain, escape_sq);
    }
}

/// Maps the coordinates of one block back into `[0, length)` ([`wrap_periodic`]). Few
/// disks cross an edge in any step: a branch-free test of the whole block (it
/// vectorises) finds the blocks with one outside, and only those are wrapped disk by disk.
fn wrap_block(coordinates: &mut [f64], length: f64) {
    let outside = coordinates
        .iter()
        .fold(false, |outside, &c| outside | (c < 0.0) | (c >= length));
    if outside {
        for c in coordinates.iter_mut() {
            *c = wrap_periodic(*c, length);
        }
    }
}

fn drift(positions: &mut [f64], velocities: &[f64], dt: f64) {
    for (p, v) in positions.iter_mut().zip(velocities) {
        *p += v * dt;
    }
}

fn accelerate(positions: &mut [f64], velocities: &mut [f64], acceleration: f64, dt: f64) {
    let half_a_dt2 = 0.5 * acceleration * dt * dt;
    let a_dt = acceleration * dt;
    for (p, v) in positions.iter_mut().zip(velocities) {
        *p += *v * dt + half_a_dt2;
        *v += a_dt;
    }
}

/// Reflects the disks of one block that touch a wall and move towards it, counting
/// the reflections and the deepest penetration into `walls`. Few disks touch a wall in
/// any step: a branch-free test of the whole block (it vectorises) finds the blocks with
/// one near a wall, and only those are looked at disk by disk. The branch is almost
/// never taken, so it is well predicted. A disk not near a wall is not in it: its
/// penetration is negative and cannot be deepest.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn reflect_at_walls(
    x: &[f64],
    y: &[f64],
    vx: &mut [f64],
    vy: &mut [f64],
    radius: impl Fn(usize) -> f64,
    domain: &Domain,
    physics: &Physics,
    walls: &mut StepCounters,
) {
    let (width, height) = (domain.width, domain.height);
    let n = x.len();
    let (y, vx, vy) = (&y[..n], &mut vx[..n], &mut vy[..n]);
    // How many disks of the block are near a wall: an integer sum, which vectorises (a
    // NaN disk is near no wall).
    let near = (0..n).fold(0_u32, |near, i| {
        let (x, y, r) = (x[i], y[i], radius(i));
        let outside = (x - r < 0.0) | (x + r > width) | (y - r < 0.0) | (y + r > height);
        near + u32::from(outside)
    });
    if near == 0 {
        return;
    }
    let e = physics.wall_restitution;
    let mut reflect = |p: f64, v: &mut f64, r: f64, length: f64| {
        let outward = (p - r < 0.0 && *v < 0.0) || (p + r > length && *v > 0.0);
        if outward {
            *v *= -e;
        }
        walls.max_wall_penetration = walls
            .max_wall_penetration
            .max((r - p).max(p + r - length) / r);
        walls.wall_collisions += u64::from(outward);
    };
    for i in 0..n {
        reflect(x[i], &mut vx[i], radius(i), width);
        reflect(y[i], &mut vy[i], radius(i), height);
    }
}

/// The largest dt for which the fastest disk moves at most `fraction` of the smallest
/// radius per step. With a field, the fastest speed includes what a fall across the
/// whole box can add. A scene at rest gets the dt of unit speed.
pub fn auto_dt(figures: &DiskFigures, domain: &Domain, physics: &Physics, fraction: f64) -> f64 {
    let mut max_speed = figures.max_speed;
    if let Some([gx, gy]) = physics.gravity {
        let g = gx.hypot(gy);
        max_speed += (2.0 * g * domain.width.max(domain.height)).sqrt();
    }
    let max_speed = if max_speed > 0.0 { max_speed } else { 1.0 };
    fraction * figures.min_radius / max_speed
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The builds (counted from 1) at which the schedule for `n_disks` re-stores the
    /// disks, among the first `builds`.
    fn restoring_builds(n_disks: usize, builds: u32) -> Vec<u32> {
        let mut schedule = ReorderSchedule::for_scene(n_disks);
        (1..=builds).filter(|_| schedule.count_build()).collect()
    }

    /// The first build re-stores the disks (they are in placement order); then a small
    /// scene waits 16 builds between re-storings, a large one 2.
    #[test]
    fn disks_are_restored_at_the_first_build_then_more_often_in_large_scenes() {
        assert_eq!(restoring_builds(1000, 40), [1, 17, 33]);
        assert_eq!(restoring_builds(LARGE_SCENE_DISKS - 1, 40), [1, 17, 33]);
        assert_eq!(restoring_builds(LARGE_SCENE_DISKS, 8), [1, 3, 5, 7]);
    }
}
