//! The event-driven reference: disks fly in straight lines between collisions, and the
//! exact time of every pair collision, wall bounce and cell crossing is computed and
//! processed in time order, so no collision is missed (Rapaport's method; Lubachevsky's
//! delayed states). Pure: no I/O, no threads, and it cannot fail mid-run.
//!
//! - **Delayed states.** Each disk stores its position at its own last event time; only
//!   the disks of an event are brought to the event's time. [`EventSim::advance_to`]
//!   brings every disk to the requested time and writes the state out.
//! - **Cells** at least one contact diameter across (wider in sparse boxes: about one
//!   disk per two cells); a disk's cell changes exactly at its crossing events, so a pair
//!   can only touch while in neighbouring cells. Pair predictions look at the 3 × 3
//!   neighbourhood, with each neighbour's periodic image shift, and test each candidate
//!   without branching on the outcome.
//! - **Queue.** One pending event per disk, its earliest, kept in a calendar queue
//!   ([`EventCalendar`]: O(1) update and minimum). A pair event records the partner's collision counter
//!   at prediction time; if the partner's velocity changed since, the event is stale and
//!   the disk is predicted afresh when it comes up (lazy invalidation). A crossing does
//!   not change a trajectory, so it keeps the best pair event found so far and only looks
//!   at the cells that entered the neighbourhood.
//! - **Memory order.** What a pair test reads of a disk fills one cache line ([`Flight`]),
//!   the rest of its state another ([`Agenda`]). Every few events per disk the disks are
//!   re-stored cell by cell, so a neighbourhood's disks lie close together in memory; the
//!   caller's storage order is kept in `origin` and never changes.
//! - **Contact physics** is the time-stepped method's impulse law
//!   ([`exchange_along`]) along the line of centres at contact.
//! - **Inelastic collapse** (e < 1): the TC model of Luding and McNamara — a collision is
//!   elastic when either disk collided less than `tc` ago; [`EventSim::collapse_guard_fired`]
//!   counts how often. Without the guard a collapse is detected
//!   ([`super::collapse::CollapseDetector`], judged once per window of collisions): the
//!   simulation then stops at [`EventSim::collapse_time`] and processes no more events.
//!
//! Gravity (parabolic flights) is not modelled: input validation refuses it with this
//! method. Disks must start without overlaps (scene construction guarantees it).

use super::calendar::EventCalendar;
use super::cells::{CellGrid, NONE, Neighbour};
use super::collapse::CollapseDetector;
use super::collision::{PairSide, exchange_along};
use super::counters::{StepCounters, virial_term};
use super::particles::Particles;
use super::scene::{Boundary, Domain, Physics};

/// Cells hold about this many disks in sparse boxes (bigger cells: fewer crossings, more
/// candidates). 0.5 did best of 0.25–3 in cycles estimated by cachegrind (instructions,
/// cache misses and mispredicted branches) at N = 10⁴ and 10⁵, packings 0.05 and 0.3;
/// at 0.3 the cells are then one contact diameter wide, their minimum.
const DISKS_PER_CELL: f64 = 0.5;

/// Events between re-storings of the disks in cell order, per disk.
const EVENTS_PER_DISK_BETWEEN_REORDERS: u64 = 8;

/// Settings of the event-driven method.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EventParams {
    /// TC model time: a collision within `tc` of either disk's previous one is elastic.
    /// 0 turns the guard off; irrelevant when e = 1.
    pub tc: f64,
}

/// What a disk's next event is.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    /// Nothing ahead (a disk at rest in a box of disks at rest).
    Nothing,
    /// Collision with `partner`, valid while the partner's counter still equals `count`.
    Pair { partner: u32, count: u32 },
    /// Entering the neighbouring cell along x (`axis` 0) or y (1), forward or backward.
    Cross { axis: u8, forward: bool },
    /// Bouncing off the wall along `axis`.
    Wall { axis: u8 },
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Scheduled {
    time: f64,
    kind: Kind,
}

const NOTHING: Scheduled = Scheduled {
    time: f64::INFINITY,
    kind: Kind::Nothing,
};

/// The earliest pair collision found so far in a search: its time and partner.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Nearest {
    time: f64,
    /// [`NONE`] when none was found.
    partner: u32,
}

const NO_PARTNER: Nearest = Nearest {
    time: f64::INFINITY,
    partner: NONE,
};

impl Scheduled {
    #[inline(always)]
    fn earlier(self, other: Scheduled) -> Scheduled {
        if other.time < self.time { other } else { self }
    }
}

/// One disk's flight: its position at its local time `t`, its velocity, and where it is:
/// everything a pair prediction reads of a neighbour, in one cache line.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(align(64))]
struct Flight {
    x: f64,
    y: f64,
    vx: f64,
    vy: f64,
    t: f64,
    radius: f64,
    /// How many times the velocity changed (invalidates partners' predictions).
    count: u32,
    /// Column and row of its cell.
    home: [u32; 2],
    /// The next disk of its cell's member list ([`NONE`] at the end).
    next_in_cell: u32,
}

/// The rest of a disk's state, read only when it has an event: one more cache line.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(align(64))]
struct Agenda {
    mass: f64,
    /// Time of the disk's last pair collision (TC model).
    last_collision: f64,
    /// The pending event (the one in the queue).
    next: Scheduled,
    /// The earliest pair event found since the velocity last changed.
    best_pair: Scheduled,
}

impl Flight {
    #[inline(always)]
    fn position_at(&self, time: f64) -> (f64, f64) {
        let dt = time - self.t;
        (self.x + self.vx * dt, self.y + self.vy * dt)
    }
}

/// The event-driven simulation of one scene. It owns the flights; the caller's
/// [`Particles`] receive the state, in their own storage order, at every
/// [`EventSim::advance_to`].
#[derive(Clone, Debug)]
pub struct EventSim {
    domain: Domain,
    physics: Physics,
    params: EventParams,
    /// The time of the last processed event (or of the last `advance_to`).
    time: f64,
    grid: CellGrid,
    /// Per cell: its first disk ([`NONE`]: empty); the rest follow `next_in_cell`.
    heads: Vec<u32>,
    flights: Vec<Flight>,
    agendas: Vec<Agenda>,
    /// Per disk: its storage index in the caller's [`Particles`].
    origin: Vec<u32>,
    /// Events processed since the disks were last re-stored in cell order.
    events_since_reorder: u64,
    queue: EventCalendar,
    counters: StepCounters,
    cell_crossings: u64,
    collapse_guard_fired: u64,
    collapse: CollapseDetector,
}

impl EventSim {
    /// Starts at time 0 from `particles` (no overlaps; positions inside the box).
    pub fn new(
        domain: Domain,
        physics: Physics,
        params: EventParams,
        particles: &Particles,
    ) -> EventSim {
        let n = particles.len();
        let density = n as f64 / domain.area();
        let min_side = (2.0 * particles.max_radius()).max((DISKS_PER_CELL / density).sqrt());
        // A periodic box needs 3 cells each way (3 contact diameters fit: scene checks).
        let min_side = match domain.boundary {
            Boundary::Periodic => min_side
                .min(domain.width / 3.0)
                .min(domain.height / 3.0)
                .max(2.0 * particles.max_radius()),
            Boundary::Walls => min_side,
        };
        let grid = CellGrid::new(&domain, min_side, n);
        let flights: Vec<Flight> = (0..n)
            .map(|idx| {
                let (col, row) = grid.cell_of(particles.x[idx], particles.y[idx]);
                Flight {
                    x: particles.x[idx],
                    y: particles.y[idx],
                    vx: particles.vx[idx],
                    vy: particles.vy[idx],
                    t: 0.0,
                    radius: particles.radius[idx],
                    count: 0,
                    home: [col as u32, row as u32],
                    next_in_cell: NONE,
                }
            })
            .collect();
        let agendas = (0..n)
            .map(|idx| Agenda {
                mass: particles.mass[idx],
                last_collision: f64::NEG_INFINITY,
                next: NOTHING,
                best_pair: NOTHING,
            })
            .collect();
        let mut sim = EventSim {
            domain,
            physics,
            params,
            time: 0.0,
            heads: vec![NONE; grid.len()],
            grid,
            flights,
            agendas,
            origin: (0..n as u32).collect(),
            events_since_reorder: 0,
            queue: EventCalendar::new(n),
            counters: StepCounters::default(),
            cell_crossings: 0,
            collapse_guard_fired: 0,
            collapse: CollapseDetector::new(
                n,
                physics.restitution < 1.0 || physics.wall_restitution < 1.0,
            ),
        };
        for disk in 0..n {
            let [col, row] = sim.flights[disk].home;
            sim.insert(disk as u32, sim.grid.index(col as usize, row as usize));
        }
        sim.reorder();
        for disk in 0..n as u32 {
            sim.predict(disk);
        }
        sim.refile_queue();
        sim
    }

    /// Re-stores the disks cell by cell (row by row), remapping every index that names a
    /// disk. Physics is untouched: only where each disk's data lives changes.
    fn reorder(&mut self) {
        let n = self.flights.len();
        let mut order = Vec::with_capacity(n); // new slot → old slot
        for &first in &self.heads {
            let mut disk = first;
            while disk != NONE {
                order.push(disk);
                disk = self.flights[disk as usize].next_in_cell;
            }
        }
        let mut new_slot = vec![0u32; n];
        for (new, &old) in order.iter().enumerate() {
            new_slot[old as usize] = new as u32;
        }
        let remap = |event: Scheduled| match event.kind {
            Kind::Pair { partner, count } => Scheduled {
                time: event.time,
                kind: Kind::Pair {
                    partner: new_slot[partner as usize],
                    count,
                },
            },
            _ => event,
        };
        permute(&mut self.flights, &order, |f| f);
        permute(&mut self.origin, &order, |o| o);
        permute(&mut self.agendas, &order, |agenda| Agenda {
            next: remap(agenda.next),
            best_pair: remap(agenda.best_pair),
            ..agenda
        });
        self.heads.fill(NONE);
        // Inserting backwards leaves each cell's list in ascending slot order.
        for disk in (0..n).rev() {
            let [col, row] = self.flights[disk].home;
            let cell = self.grid.index(col as usize, row as usize);
            self.insert(disk as u32, cell);
        }
        self.refile_queue();
        self.events_since_reorder = 0;
    }

    /// Files every disk's pending event afresh, in blocks sized for the current rate.
    fn refile_queue(&mut self) {
        let times = self.agendas.iter().map(|agenda| agenda.next.time);
        self.queue.refile(self.time, times);
    }

    /// Adds `disk` at the head of `cell`'s member list.
    #[inline]
    fn insert(&mut self, disk: u32, cell: usize) {
        self.flights[disk as usize].next_in_cell = self.heads[cell];
        self.heads[cell] = disk;
    }

    /// Takes `disk` out of `cell`'s member list, where it must be (lists hold a disk or
    /// two, so walking to its predecessor is cheaper than keeping back links).
    #[inline]
    fn remove(&mut self, disk: u32, cell: usize) {
        let next = self.flights[disk as usize].next_in_cell;
        if self.heads[cell] == disk {
            self.heads[cell] = next;
            return;
        }
        let mut before = self.heads[cell];
        while self.flights[before as usize].next_in_cell != disk {
            before = self.flights[before as usize].next_in_cell;
        }
        self.flights[before as usize].next_in_cell = next;
    }

    /// Time reached so far.
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Pair and wall collisions, overlaps at contact (rounding only) and the virial.
    pub fn counters(&self) -> StepCounters {
        self.counters
    }

    /// Cell crossings processed (bookkeeping events, not physics).
    pub fn cell_crossings(&self) -> u64 {
        self.cell_crossings
    }

    /// Collisions the TC model made elastic.
    pub fn collapse_guard_fired(&self) -> u64 {
        self.collapse_guard_fired
    }

    /// The time at which inelastic collapse was detected; no event is processed after it.
    pub fn collapse_time(&self) -> Option<f64> {
        self.collapse.collapse_time()
    }

    /// Processes every event up to time `t_end` (not before the current time), brings all
    /// disks to `t_end` (to the collapse time if collapse was detected) and writes their
    /// positions and velocities to `particles` (the set this simulation started from, in
    /// the same storage order).
    pub fn advance_to(&mut self, particles: &mut Particles, t_end: f64) {
        self.run(t_end, u64::MAX);
        if self.collapse_time().is_none() {
            self.time = self.time.max(t_end);
        }
        self.write_state(particles);
    }

    /// Processes events until `collisions` more pair or wall collisions have happened
    /// (for benches: no time limit, no state written; call [`EventSim::advance_to`] with
    /// [`EventSim::time`] to write it).
    pub fn advance_collisions(&mut self, collisions: u64) {
        self.run(f64::INFINITY, collisions);
    }

    fn run(&mut self, t_end: f64, max_collisions: u64) {
        if self.collapse_time().is_some() {
            return;
        }
        let stop = (self.counters.pair_collisions + self.counters.wall_collisions)
            .saturating_add(max_collisions);
        // One comparison per event serves both limits: the caller's and the collapse
        // detector's window.
        let mut limit = stop.min(self.collapse.window_end());
        loop {
            let (time, disk) = self.queue.earliest();
            let collisions = self.counters.pair_collisions + self.counters.wall_collisions;
            if collisions >= limit {
                if collisions >= stop || self.collapse.judge(collisions, self.time) {
                    return;
                }
                limit = stop.min(self.collapse.window_end());
            }
            if time > t_end || disk == NONE {
                return;
            }
            self.time = time;
            self.events_since_reorder += 1;
            if self.events_since_reorder
                > EVENTS_PER_DISK_BETWEEN_REORDERS * self.flights.len() as u64
            {
                self.reorder();
                continue;
            }
            let event = self.agendas[disk as usize].next;
            match event.kind {
                Kind::Nothing => return,
                Kind::Pair { partner, count } => {
                    if self.flights[partner as usize].count == count {
                        self.collide(disk, partner);
                    } else {
                        // The partner changed course since: predict this disk afresh.
                        self.predict(disk);
                    }
                }
                Kind::Cross { axis, forward } => self.cross(disk, axis, forward),
                Kind::Wall { axis } => self.bounce(disk, axis),
            }
        }
    }

    /// Brings every disk to the current time and writes the state to `particles`.
    fn write_state(&mut self, particles: &mut Particles) {
        let time = self.time;
        for (flight, &idx) in self.flights.iter_mut().zip(&self.origin) {
            let idx = idx as usize;
            let (x, y) = flight.position_at(time);
            (flight.x, flight.y, flight.t) = (x, y, time);
            particles.x[idx] = x;
            particles.y[idx] = y;
            particles.vx[idx] = flight.vx;
            particles.vy[idx] = flight.vy;
        }
    }

    /// Brings one disk to the current time.
    #[inline(always)]
    fn bring_to_now(&mut self, disk: u32) {
        let flight = &mut self.flights[disk as usize];
        let (x, y) = flight.position_at(self.time);
        (flight.x, flight.y, flight.t) = (x, y, self.time);
    }

    /// A pair collision of `a` and `b` at the current time.
    fn collide(&mut self, a: u32, b: u32) {
        self.bring_to_now(a);
        self.bring_to_now(b);
        let (fa, fb) = (self.flights[a as usize], self.flights[b as usize]);
        let (dx, dy) = self.domain.separation(fa.x, fa.y, fb.x, fb.y);
        let distance = dx.hypot(dy);
        let contact = fa.radius + fb.radius;
        let now = self.time;
        let (ga, gb) = (self.agendas[a as usize], self.agendas[b as usize]);
        let guarded =
            now - ga.last_collision < self.params.tc || now - gb.last_collision < self.params.tc;
        let law = if guarded {
            self.collapse_guard_fired += u64::from(self.physics.restitution < 1.0);
            Physics {
                restitution: 1.0,
                ..self.physics
            }
        } else {
            self.physics
        };
        let side = |f: &Flight, g: &Agenda| PairSide {
            mass: g.mass,
            vx: f.vx,
            vy: f.vy,
        };
        let ([[vax, vay], [vbx, vby]], impulse) = exchange_along(
            &law,
            dx / distance,
            dy / distance,
            side(&fa, &ga),
            side(&fb, &gb),
        );
        for (disk, vx, vy) in [(a, vax, vay), (b, vbx, vby)] {
            let flight = &mut self.flights[disk as usize];
            (flight.vx, flight.vy) = (vx, vy);
            flight.count = flight.count.wrapping_add(1);
            self.agendas[disk as usize].last_collision = now;
        }
        let overlap = ((contact - distance) / contact).max(0.0);
        let counters = &mut self.counters;
        counters.pair_collisions += 1;
        counters.max_overlap = counters.max_overlap.max(overlap);
        counters.overlap_sum += overlap;
        counters.virial += virial_term(distance * impulse);
        self.predict(a);
        self.predict(b);
    }

    /// A wall bounce along `axis` at the current time.
    fn bounce(&mut self, disk: u32, axis: u8) {
        self.bring_to_now(disk);
        let flight = &mut self.flights[disk as usize];
        let e = self.physics.wall_restitution;
        if axis == 0 {
            flight.vx *= -e;
        } else {
            flight.vy *= -e;
        }
        flight.count = flight.count.wrapping_add(1);
        self.counters.wall_collisions += 1;
        self.predict(disk);
    }

    /// A cell crossing along `axis` at the current time: the trajectory is unchanged, so
    /// the best pair event found so far stays valid (if its partner did not change
    /// course) and only the cells that entered the neighbourhood are searched.
    fn cross(&mut self, disk: u32, axis: u8, forward: bool) {
        self.bring_to_now(disk);
        self.cell_crossings += 1;
        let i = disk as usize;
        let [col, row] = self.flights[i].home;
        let (old_col, old_row) = (col as usize, row as usize);
        let step: i64 = if forward { 1 } else { -1 };
        let (d_col, d_row) = if axis == 0 { (step, 0) } else { (0, step) };
        let target = self
            .grid
            .offset(old_col, old_row, d_col, d_row)
            .expect("crossings are only scheduled towards existing cells");
        // Across a periodic edge the stored position moves to the new cell's image.
        let flight = &mut self.flights[i];
        flight.x -= target.shift_x;
        flight.y -= target.shift_y;
        self.remove(disk, self.grid.index(old_col, old_row));
        self.insert(disk, target.cell);
        let (new_col, new_row) = (
            target.cell % self.grid.n_cols,
            target.cell / self.grid.n_cols,
        );
        self.flights[i].home = [new_col as u32, new_row as u32];
        let best = self.agendas[i].best_pair;
        let still_valid = match best.kind {
            Kind::Pair { partner, count } => self.flights[partner as usize].count == count,
            _ => true,
        };
        if !still_valid {
            self.predict(disk);
            return;
        }
        let mut nearest = match best.kind {
            Kind::Pair { partner, .. } => Nearest {
                time: best.time,
                partner,
            },
            _ => NO_PARTNER,
        };
        for offset in -1..=1 {
            let (c, r) = if axis == 0 {
                (step, offset)
            } else {
                (offset, step)
            };
            if let Some(neighbour) = self.grid.offset(new_col, new_row, c, r) {
                nearest = self.nearest_in(disk, neighbour, nearest);
            }
        }
        self.schedule(disk, nearest);
    }

    /// Predicts a disk's next event from scratch (it must be at the current time or be
    /// brought there here).
    fn predict(&mut self, disk: u32) {
        self.bring_to_now(disk);
        let [col, row] = self.flights[disk as usize].home;
        let (col, row) = (col as usize, row as usize);
        let (n_cols, n_rows) = (self.grid.n_cols, self.grid.n_rows);
        let mut nearest = NO_PARTNER;
        if col >= 1 && col + 1 < n_cols && row >= 1 && row + 1 < n_rows {
            // Away from the edges: no wrapping, no shifts.
            let centre = row * n_cols + col;
            for cell in [
                centre - n_cols - 1,
                centre - n_cols,
                centre - n_cols + 1,
                centre - 1,
                centre,
                centre + 1,
                centre + n_cols - 1,
                centre + n_cols,
                centre + n_cols + 1,
            ] {
                let neighbour = Neighbour {
                    cell,
                    shift_x: 0.0,
                    shift_y: 0.0,
                };
                nearest = self.nearest_in(disk, neighbour, nearest);
            }
        } else {
            for neighbour in self.grid.neighbourhood(col, row) {
                nearest = self.nearest_in(disk, neighbour, nearest);
            }
        }
        self.schedule(disk, nearest);
    }

    /// Records the nearest collision as the disk's best pair event and schedules the
    /// earliest of it, its next cell crossing and its next wall bounce.
    fn schedule(&mut self, disk: u32, nearest: Nearest) {
        let i = disk as usize;
        let best_pair = if nearest.partner == NONE {
            NOTHING
        } else {
            Scheduled {
                time: nearest.time,
                kind: Kind::Pair {
                    partner: nearest.partner,
                    count: self.flights[nearest.partner as usize].count,
                },
            }
        };
        self.agendas[i].best_pair = best_pair;
        let next = best_pair
            .earlier(self.crossing(disk, 0))
            .earlier(self.crossing(disk, 1));
        self.agendas[i].next = next;
        self.queue.set(disk, next.time);
    }

    /// The earlier of `nearest` and the earliest collision of `disk` (at the current
    /// time) with a disk of `neighbour`; ties keep the earlier find. Written without
    /// branches on the outcome of each test, which no predictor can guess.
    #[inline(always)]
    fn nearest_in(&self, disk: u32, neighbour: Neighbour, nearest: Nearest) -> Nearest {
        let now = self.time;
        let a = &self.flights[disk as usize];
        let mut nearest = nearest;
        let mut other = self.heads[neighbour.cell];
        while other != NONE {
            let b = &self.flights[other as usize];
            let (bx, by) = b.position_at(now);
            let dx = bx + neighbour.shift_x - a.x;
            let dy = by + neighbour.shift_y - a.y;
            let wait = contact_wait(dx, dy, b.vx - a.vx, b.vy - a.vy, a.radius + b.radius);
            let time = now + wait;
            let earlier = (time < nearest.time) & (other != disk);
            nearest.time = select(earlier, time, nearest.time);
            // A mask rather than `if`, which compiles to a branch here.
            let take = 0u32.wrapping_sub(u32::from(earlier));
            nearest.partner = (other & take) | (nearest.partner & !take);
            other = b.next_in_cell;
        }
        nearest
    }

    /// The disk's next cell crossing or wall bounce along `axis`.
    #[inline]
    fn crossing(&self, disk: u32, axis: u8) -> Scheduled {
        let i = disk as usize;
        let f = &self.flights[i];
        let (position, velocity, cell, cell_side, n_cells, length) = if axis == 0 {
            let (w, n) = (self.grid.cell_width, self.grid.n_cols);
            (f.x, f.vx, f.home[0] as usize, w, n, self.domain.width)
        } else {
            let (h, n) = (self.grid.cell_height, self.grid.n_rows);
            (f.y, f.vy, f.home[1] as usize, h, n, self.domain.height)
        };
        if velocity == 0.0 {
            return NOTHING;
        }
        let forward = velocity > 0.0;
        let at_edge = if forward {
            cell + 1 == n_cells
        } else {
            cell == 0
        };
        let (target, kind) = if at_edge && self.domain.boundary == Boundary::Walls {
            let contact_at = if forward { length - f.radius } else { f.radius };
            (contact_at, Kind::Wall { axis })
        } else {
            let boundary = if forward {
                if cell + 1 == n_cells {
                    length
                } else {
                    (cell + 1) as f64 * cell_side
                }
            } else {
                cell as f64 * cell_side
            };
            (boundary, Kind::Cross { axis, forward })
        };
        Scheduled {
            time: f.t + ((target - position) / velocity).max(0.0),
            kind,
        }
    }
}

/// Replaces `values` by `map(values[old])` for each `old` of `order`.
fn permute<T: Copy>(values: &mut Vec<T>, order: &[u32], map: impl Fn(T) -> T) {
    *values = order.iter().map(|&old| map(values[old as usize])).collect();
}

/// Relative distance (of the squared contact distance) within which a pair counts as touching.
const TOUCHING: f64 = 1e-10;

/// Time until two disks at separation `(dx, dy)` (from a to b) with relative velocity
/// `(dvx, dvy)` (b's minus a's) come within `contact`; infinite if they never do.
/// Overlapping approaching pairs (rounding) collide at once; separating ones never.
#[inline(always)]
pub fn contact_wait(dx: f64, dy: f64, dvx: f64, dvy: f64, contact: f64) -> f64 {
    let b = dx * dvx + dy * dvy;
    let v2 = dvx * dvx + dvy * dvy;
    let distance_sq = dx * dx + dy * dy;
    let contact_sq = contact * contact;
    let c = distance_sq - contact_sq;
    // Every outcome is computed and one selected, without a branch: which one applies
    // is what no predictor can guess (and a disk tested against itself is "touching").
    // Touching to rounding: a collision now if the pair really approaches; none if its
    // normal approach is rounding-sized (below 1e-9 of the relative speed), as for a
    // pair that e = 0 left at zero normal speed, which must not collide with zero
    // impulse again and again.
    let touching = c < TOUCHING * contact_sq;
    let touch_now = (b < 0.0) & (b * b > 1e-18 * v2 * distance_sq);
    // Otherwise, approaching with paths that come within contact: the smaller root
    // c / (−b + √disc), written to avoid cancellation (NaN when there is none).
    let discriminant = b * b - v2 * c;
    let root = (c / (-b + discriminant.sqrt())).max(0.0);
    let meets = (b < 0.0) & (discriminant >= 0.0);
    let wait = select(meets, root, f64::INFINITY);
    let touch_wait = select(touch_now, 0.0, f64::INFINITY);
    select(touching, touch_wait, wait)
}

/// `if condition { if_true } else { if_false }` with bit masks: the compiler turns an
/// `if` between two computed values into a branch when one looks expensive, and in the
/// pair test no predictor can guess it.
#[inline(always)]
fn select(condition: bool, if_true: f64, if_false: f64) -> f64 {
    let mask = 0u64.wrapping_sub(u64::from(condition));
    f64::from_bits((if_true.to_bits() & mask) | (if_false.to_bits() & !mask))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::particles::Disk;

    fn two_disks(
        xa: f64,
        vxa: f64,
        xb: f64,
        vxb: f64,
        boundary: Boundary,
    ) -> (EventSim, Particles) {
        let disk = |x, vx| Disk {
            x,
            y: 50.0,
            vx,
            vy: 0.0,
            radius: 1.0,
            mass: 1.0,
        };
        let particles = Particles::from_disks(&[disk(xa, vxa), disk(xb, vxb)]);
        let domain = Domain {
            width: 100.0,
            height: 100.0,
            boundary,
        };
        let sim = EventSim::new(
            domain,
            Physics::elastic(),
            EventParams { tc: 0.0 },
            &particles,
        );
        (sim, particles)
    }

    #[test]
    fn contact_wait_is_the_exact_root() {
        // Gap 18 closed at relative speed 2.
        assert_eq!(contact_wait(20.0, 0.0, -2.0, 0.0, 2.0), 9.0);
        assert_eq!(contact_wait(20.0, 0.0, 2.0, 0.0, 2.0), f64::INFINITY);
        // Passing by at an offset of 3 > 2: never.
        assert_eq!(contact_wait(20.0, 3.0, -2.0, 0.0, 2.0), f64::INFINITY);
        // Overlapping and approaching (rounding): at once.
        assert_eq!(contact_wait(1.9, 0.0, -1.0, 0.0, 2.0), 0.0);
        // Touching and sliding with a rounding-sized normal approach: never.
        assert_eq!(contact_wait(2.0, 0.0, -1e-17, 1.0, 2.0), f64::INFINITY);
    }

    #[test]
    fn head_on_pair_meets_at_the_exact_time_and_exchanges_velocities() {
        let (mut sim, mut particles) = two_disks(40.0, 1.0, 60.0, -1.0, Boundary::Walls);
        sim.advance_to(&mut particles, 8.999);
        assert_eq!(sim.counters().pair_collisions, 0);
        sim.advance_to(&mut particles, 10.0);
        assert_eq!(sim.counters().pair_collisions, 1);
        assert_eq!((particles.vx[0], particles.vx[1]), (-1.0, 1.0));
        assert!((particles.x[0] - 48.0).abs() < 1e-12, "{}", particles.x[0]);
        assert!((particles.x[1] - 52.0).abs() < 1e-12, "{}", particles.x[1]);
    }

    #[test]
    fn periodic_pair_meets_across_the_edge() {
        // 2 → wraps left, 97 → moving right: centres 5 apart through the edge, gap 3.
        let (mut sim, mut particles) = two_disks(2.0, -0.5, 97.0, 0.5, Boundary::Periodic);
        sim.advance_to(&mut particles, 2.9);
        assert_eq!(sim.counters().pair_collisions, 0);
        sim.advance_to(&mut particles, 3.1);
        assert_eq!(sim.counters().pair_collisions, 1);
        assert_eq!((particles.vx[0], particles.vx[1]), (0.5, -0.5));
    }
}
