//! Broad phase: which disks overlap, found by sorted strips (or all pairs, for comparison).
//!
//! Both searches report the same set of overlapping pairs, tested with the same
//! arithmetic ([`Domain::separation_in`]), so the two broad phases give bit-identical
//! runs. The order in which pairs are found is not canonical; the stepper sorts them.

use super::particles::Particles;
use super::scene::{Boundary, Domain};

/// An overlapping pair. `a` is the storage index of the disk with the lower id.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Contact {
    /// `(lower id << 32) | higher id`: sorting by key gives the canonical pair order.
    pub key: u64,
    pub a: u32,
    pub b: u32,
}

impl Contact {
    /// The contact between the disks stored at `i` and `j`, oriented by id.
    #[inline(always)]
    pub fn new(particles: &Particles, i: usize, j: usize) -> Contact {
        let (id_i, id_j) = (particles.id[i], particles.id[j]);
        let (lo, hi, a, b) = if id_i < id_j {
            (id_i, id_j, i, j)
        } else {
            (id_j, id_i, j, i)
        };
        Contact {
            key: (u64::from(lo) << 32) | u64::from(hi),
            a: a as u32,
            b: b as u32,
        }
    }
}

/// One disk in the sorted view: what the pair scan reads, 32 bytes, in (strip, x) order.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Entry {
    x: f64,
    y: f64,
    radius: f64,
    /// Storage index of the disk.
    idx: u32,
    strip: u32,
}

impl Entry {
    #[inline(always)]
    fn before(&self, other: &Entry) -> bool {
        self.strip < other.strip || (self.strip == other.strip && self.x < other.x)
    }
}

/// The grid broad phase: the box cut into horizontal strips one contact diameter tall,
/// disks sorted by x within each strip (a sweep-and-prune per strip).
///
/// Each disk is tested against the disks after it in its own strip while their x
/// distance is below one diameter, and against the disks of the strip above within one
/// diameter in x: about 3·ρ·d² candidates per disk. The sorted order persists between
/// steps, so re-sorting is an insertion sort over the few disks that moved past a
/// neighbour or into another strip: O(N) per step. Scratch memory only.
#[derive(Clone, Debug)]
pub struct StripGrid {
    n_strips: usize,
    inv_strip_height: f64,
    width: f64,
    /// Largest contact distance, widened by a relative 1e-9 so that the window never
    /// rejects a pair the exact test (done with the shared arithmetic) would accept.
    reach: f64,
    /// `strip_start[s]..strip_start[s + 1]` are the slots of strip `s` in `entries`.
    strip_start: Vec<u32>,
    entries: Vec<Entry>,
}

impl StripGrid {
    /// A grid for disks no larger than `max_radius` in `domain`.
    ///
    /// A periodic domain must be at least three contact diameters across
    /// (`scene::check_periodic_box`), so no pair is found through two images.
    pub fn new(domain: &Domain, max_radius: f64, n_particles: usize) -> StripGrid {
        let contact = 2.0 * max_radius;
        // Strips at least one contact diameter tall, and (in sparse boxes) no more strips
        // than disks; never fewer than three in a periodic box, which is that tall.
        let n_strips = ((domain.height / contact).floor() as usize).clamp(1, n_particles.max(3));
        StripGrid {
            n_strips,
            inv_strip_height: n_strips as f64 / domain.height,
            width: domain.width,
            reach: contact * (1.0 + 1e-9),
            strip_start: vec![0; n_strips + 1],
            entries: Vec::new(),
        }
    }

    /// Storage indices in sorted order (strip, then x), as of the last build.
    pub fn sorted_indices(&self) -> Vec<u32> {
        self.entries.iter().map(|entry| entry.idx).collect()
    }

    /// Tells the grid that the caller stored the disks in [`StripGrid::sorted_indices`]
    /// order, so slot and storage index now coincide.
    pub fn storage_now_sorted(&mut self) {
        for (slot, entry) in self.entries.iter_mut().enumerate() {
            entry.idx = slot as u32;
        }
    }

    /// Re-sorts the disks by strip and x. Disks outside a walled box go to the nearest
    /// edge strip, which still holds every disk they can touch.
    pub fn build(&mut self, particles: &Particles) {
        let max_strip = self.n_strips - 1;
        let strip_of = |y: f64| ((y * self.inv_strip_height) as usize).min(max_strip) as u32;
        // The first build (or one for a different set of disks) sorts from scratch; later
        // ones start from the previous order.
        let from_scratch = self.entries.len() != particles.len();
        if from_scratch {
            self.entries = (0..particles.len())
                .map(|idx| Entry {
                    x: particles.x[idx],
                    y: particles.y[idx],
                    radius: particles.radius[idx],
                    idx: idx as u32,
                    strip: 0,
                })
                .collect();
        }
        self.strip_start.fill(0);
        for entry in &mut self.entries {
            let idx = entry.idx as usize;
            entry.x = particles.x[idx];
            entry.y = particles.y[idx];
            // `as usize` saturates: negative coordinates (and NaN) land in strip 0.
            entry.strip = strip_of(entry.y);
            self.strip_start[entry.strip as usize + 1] += 1;
        }
        for strip in 0..self.n_strips {
            self.strip_start[strip + 1] += self.strip_start[strip];
        }
        if from_scratch {
            self.entries
                .sort_unstable_by(|a, b| a.strip.cmp(&b.strip).then(a.x.total_cmp(&b.x)));
        } else {
            insertion_sort(&mut self.entries);
        }
    }

    /// Appends every overlapping pair to `contacts` (in no particular order).
    /// Call [`StripGrid::build`] first with the same particles.
    pub fn find_contacts(
        &self,
        particles: &Particles,
        domain: &Domain,
        contacts: &mut Vec<Contact>,
    ) {
        match domain.boundary {
            Boundary::Walls => self.scan::<false>(particles, domain, contacts),
            Boundary::Periodic => self.scan::<true>(particles, domain, contacts),
        }
    }

    fn scan<const PERIODIC: bool>(
        &self,
        particles: &Particles,
        domain: &Domain,
        contacts: &mut Vec<Contact>,
    ) {
        let entries = &self.entries[..];
        let (reach, width) = (self.reach, self.width);
        let test = |a: &Entry, b: &Entry, contacts: &mut Vec<Contact>| {
            let (dx, dy) = domain.separation_in::<PERIODIC>(a.x, a.y, b.x, b.y);
            let contact = a.radius + b.radius;
            if dx * dx + dy * dy < contact * contact {
                contacts.push(Contact::new(particles, a.idx as usize, b.idx as usize));
            }
        };
        for strip in 0..self.n_strips {
            let own = self.strip_start[strip] as usize..self.strip_start[strip + 1] as usize;
            let north_strip = if strip + 1 < self.n_strips {
                Some(strip + 1)
            } else if PERIODIC {
                Some(0)
            } else {
                None
            };
            let north = north_strip.map_or(0..0, |s| {
                self.strip_start[s] as usize..self.strip_start[s + 1] as usize
            });
            let own_entries = &entries[own.clone()];
            let north_entries = &entries[north];
            // First north disk not left of the current window; the window only moves right.
            let mut north_first = 0;
            for (pos, a) in own_entries.iter().enumerate() {
                // Own strip: the disks to the right within reach.
                for b in own_entries[pos + 1..]
                    .iter()
                    .take_while(|b| b.x - a.x < reach)
                {
                    test(a, b, contacts);
                }
                // North strip: the disks within reach on either side.
                while north_first < north_entries.len()
                    && north_entries[north_first].x <= a.x - reach
                {
                    north_first += 1;
                }
                for b in north_entries[north_first..]
                    .iter()
                    .take_while(|b| b.x < a.x + reach)
                {
                    test(a, b, contacts);
                }
                if PERIODIC {
                    // The same windows seen through the periodic image in x.
                    if a.x + reach > width {
                        for b in own_entries[..pos]
                            .iter()
                            .take_while(|b| b.x + width - a.x < reach)
                        {
                            test(a, b, contacts);
                        }
                        for b in north_entries
                            .iter()
                            .take_while(|b| b.x + width < a.x + reach)
                        {
                            test(a, b, contacts);
                        }
                    }
                    if a.x - reach < 0.0 {
                        for b in north_entries
                            .iter()
                            .rev()
                            .take_while(|b| b.x - width > a.x - reach)
                        {
                            test(a, b, contacts);
                        }
                    }
                }
            }
        }
    }
}

/// Sorts nearly sorted entries in O(n + inversions).
fn insertion_sort(entries: &mut [Entry]) {
    for i in 1..entries.len() {
        if !entries[i].before(&entries[i - 1]) {
            continue;
        }
        let moving = entries[i];
        let mut j = i;
        while j > 0 && moving.before(&entries[j - 1]) {
            entries[j] = entries[j - 1];
            j -= 1;
        }
        entries[j] = moving;
    }
}

/// The seed report's O(N²) search: every pair tested once. Kept to check the grid.
pub fn find_contacts_all_pairs(
    particles: &Particles,
    domain: &Domain,
    contacts: &mut Vec<Contact>,
) {
    match domain.boundary {
        Boundary::Walls => all_pairs::<false>(particles, domain, contacts),
        Boundary::Periodic => all_pairs::<true>(particles, domain, contacts),
    }
}

fn all_pairs<const PERIODIC: bool>(
    particles: &Particles,
    domain: &Domain,
    contacts: &mut Vec<Contact>,
) {
    let (x, y, radius) = (&particles.x, &particles.y, &particles.radius);
    for i in 0..particles.len() {
        for j in i + 1..particles.len() {
            let (dx, dy) = domain.separation_in::<PERIODIC>(x[i], y[i], x[j], y[j]);
            let contact = radius[i] + radius[j];
            if dx * dx + dy * dy < contact * contact {
                contacts.push(Contact::new(particles, i, j));
            }
        }
    }
}
