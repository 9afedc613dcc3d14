//! Broad phase: which disks overlap, found by sorted strips (or all pairs, for comparison).
//!
//! Both searches report the same set of overlapping pairs, tested with the same
//! arithmetic ([`Domain::separation_in`]), so the two broad phases give bit-identical
//! runs. The order in which pairs are found is not canonical; the stepper sorts them.

use std::ops::{Range, RangeInclusive};

use super::particles::{DiskFigures, Particles, ReorderScratch};
use super::pieces::Pieces;
use super::scene::{Boundary, Domain, minimum_image};

/// An overlapping pair: the storage indices of its two disks, in either order. Every
/// law applied to a pair gives the same bits with its disks swapped
/// ([`crate::sim::collision`]), so a pair needs no orientation, and its ids are read
/// only where the canonical order is needed ([`Contact::key`]): not for the lone pairs
/// that most of a step's are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Contact {
    pub a: u32,
    pub b: u32,
}

impl Contact {
    /// The contact between the disks stored at `i` and `j`.
    #[inline(always)]
    pub fn new(i: usize, j: usize) -> Contact {
        Contact {
            a: i as u32,
            b: j as u32,
        }
    }

    /// `(lower id << 32) | higher id`, by the disks' ids `ids` (one per storage index):
    /// sorting by key gives the canonical pair order.
    #[inline(always)]
    pub fn key(&self, ids: &[u32]) -> u64 {
        let (id_a, id_b) = (ids[self.a as usize], ids[self.b as usize]);
        (u64::from(id_a.min(id_b)) << 32) | u64::from(id_a.max(id_b))
    }
}

/// Puts `contacts` in canonical order ([`Contact::key`], by the disks' ids `ids`), a pair
/// found twice kept once. `keyed` is scratch memory (each key is read once, not at every
/// comparison).
pub fn order_canonically(
    contacts: &mut Vec<Contact>,
    ids: &[u32],
    keyed: &mut Vec<(u64, Contact)>,
) {
    keyed.clear();
    keyed.extend(contacts.iter().map(|contact| (contact.key(ids), *contact)));
    keyed.sort_unstable_by_key(|&(key, _)| key);
    keyed.dedup_by_key(|&mut (key, _)| key);
    contacts.clear();
    contacts.extend(keyed.iter().map(|&(_, contact)| contact));
}

/// One disk in the sorted view: what the pair scan reads, 12 bytes, kept in x order
/// inside its strip (which strip is where it is kept). The position is rounded to f32, which halves the memory of the
/// grid and of its scans; every test on it is widened by the rounding
/// ([`rounding_slack`]), so it finds a superset of the pairs, and the pairs that count
/// are decided by the disks' own f64 positions.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Entry {
    x: f32,
    y: f32,
    /// Storage index of the disk.
    idx: u32,
}

impl Entry {
    /// Storage index of the disk.
    pub fn idx(&self) -> u32 {
        self.idx
    }

    /// The disk's x (rounded to f32) at the last refresh.
    pub fn x(&self) -> f32 {
        self.x
    }
}

const _: () = assert!(std::mem::size_of::<Entry>() == 12, "entries of 12 bytes");

/// A disk on its way into a strip: its entry, and the global index of the strip.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mover {
    pub entry: Entry,
    strip: u32,
}

impl Mover {
    /// Global index of the strip the disk goes to.
    pub fn strip(&self) -> usize {
        self.strip as usize
    }

    /// Storage index of the disk.
    pub fn idx(&self) -> u32 {
        self.entry.idx
    }
}

/// How the box is cut into strips: shared, read-only, by every band and rank.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StripLayout {
    /// Strips across the whole box.
    pub n_strips: usize,
    inv_strip_height: f64,
    width: f64,
    /// Largest contact distance, widened by a relative 1e-9 so that the window never
    /// rejects a pair the exact test (done with the shared arithmetic) would accept.
    reach: f64,
    /// The radius of every disk, when all are equal (the scan then skips reading radii).
    equal_radius: Option<f64>,
    max_radius: f64,
}

impl StripLayout {
    /// Strips at least one contact diameter (`2 · max_radius`) tall over the whole box,
    /// for `particles` (all the scene's disks).
    ///
    /// In sparse boxes there are no more strips than disks; a periodic box must be at
    /// least three contact diameters tall (`scene::check_periodic_box`), so it has at
    /// least three strips and no pair is found through two images.
    pub fn new(domain: &Domain, particles: &Particles) -> StripLayout {
        StripLayout::with_skin(domain, particles, 0.0)
    }

    /// Strips at least `2 · max_radius + skin` tall, for pairs closer than their radii
    /// plus `skin` (a neighbour list's candidates). A skin of 0 is [`StripLayout::new`].
    pub fn with_skin(domain: &Domain, particles: &Particles, skin: f64) -> StripLayout {
        StripLayout::for_figures(domain, &particles.figures(), skin)
    }

    /// [`StripLayout::with_skin`] for a scene of these figures.
    pub fn for_figures(domain: &Domain, figures: &DiskFigures, skin: f64) -> StripLayout {
        let max_radius = figures.max_radius;
        let contact = 2.0 * max_radius + skin;
        let n_particles = figures.n_disks;
        let n_strips = ((domain.height / contact).floor() as usize).clamp(1, n_particles.max(3));
        StripLayout {
            n_strips,
            inv_strip_height: n_strips as f64 / domain.height,
            width: domain.width,
            reach: contact * (1.0 + 1e-9),
            equal_radius: (figures.min_radius == max_radius).then_some(max_radius),
            max_radius,
        }
    }

    /// True when every disk has the same radius.
    pub fn has_equal_radii(&self) -> bool {
        self.equal_radius.is_some()
    }

    /// The height of the box.
    pub fn height(&self) -> f64 {
        self.n_strips as f64 / self.inv_strip_height
    }

    /// The strip a disk at height `y` belongs to. Disks outside a walled box go to the
    /// nearest edge strip, which still holds every disk they can touch; `as usize`
    /// saturates, so negative heights (and NaN) land in strip 0.
    #[inline(always)]
    pub fn strip_of(&self, y: f64) -> usize {
        ((y * self.inv_strip_height) as usize).min(self.n_strips - 1)
    }
}

/// The grid broad phase: the box cut into horizontal strips one contact diameter tall,
/// disks sorted by x within each strip (a sweep-and-prune per strip).
///
/// Each disk is tested against the disks after it in its own strip while their x
/// distance is below one diameter, and against the disks of the strip above within one
/// diameter in x: about 3·ρ·d² candidates per disk. The sorted order persists between
/// steps: a refresh re-sorts each strip by insertion (the disks barely moved) and
/// merges in the few that changed strip, so a build is O(N). Scratch memory only.
///
/// A grid can hold a window of the strips (a rank's subdomain): it owns the strips
/// `first..first + n_owned`, finds the pairs whose scanning disk lies in them, and may
/// hold one more, read-only ghost strip above them: copies of the next strip's disks.
/// Every strip is its own vector, so bands of strips can be refreshed and scanned by
/// different threads.
#[derive(Clone, Debug)]
pub struct StripGrid {
    layout: StripLayout,
    /// Global index of `strips[0]`.
    first: usize,
    n_owned: usize,
    /// `strips[..n_owned]` are owned; `strips[n_owned]`, if present, is the ghost strip.
    strips: Vec<Vec<Entry>>,
    /// All strips of a periodic box: the strip above the last one is the first.
    north_wraps: bool,
    movers: Vec<Mover>,
}

impl StripGrid {
    /// A grid over the whole box, built for `particles` where they are.
    pub fn new(domain: &Domain, particles: &Particles) -> StripGrid {
        StripGrid::with_skin(domain, particles, 0.0)
    }

    /// A grid over the whole box whose strips also find pairs within `skin` of touching,
    /// built for `particles` where they are. That first build sorts from scratch (a
    /// placed scene is stored in random spatial order): part of a run's set-up, as for
    /// the ranks of the distributed backend; the builds of later steps re-sort by
    /// insertion.
    pub fn with_skin(domain: &Domain, particles: &Particles, skin: f64) -> StripGrid {
        StripGrid::whole(
            domain,
            StripLayout::with_skin(domain, particles, skin),
            particles,
        )
    }

    /// [`StripGrid::with_skin`] with its strips laid out already.
    pub fn whole(domain: &Domain, layout: StripLayout, particles: &Particles) -> StripGrid {
        let mut grid = StripGrid::window(domain, layout, 0..layout.n_strips);
        grid.build(particles);
        grid
    }

    /// A grid owning the strips `owned` (global indices, not empty) of `layout`, with a
    /// ghost strip when the strip above the last owned one exists and is not owned.
    pub fn window(domain: &Domain, layout: StripLayout, owned: Range<usize>) -> StripGrid {
        debug_assert!(!owned.is_empty() && owned.end <= layout.n_strips);
        let whole = owned.start == 0 && owned.end == layout.n_strips;
        let periodic = domain.boundary == Boundary::Periodic;
        let has_ghost = !whole && (owned.end < layout.n_strips || periodic);
        StripGrid {
            layout,
            first: owned.start,
            n_owned: owned.len(),
            strips: vec![Vec::new(); owned.len() + usize::from(has_ghost)],
            north_wraps: whole && periodic,
            movers: Vec::new(),
        }
    }

    pub fn layout(&self) -> &StripLayout {
        &self.layout
    }

    /// Owned strips, as global indices.
    pub fn owned(&self) -> Range<usize> {
        self.first..self.first + self.n_owned
    }

    /// Where the strip with global index `strip` is held: its index in `strips`, if the
    /// grid holds it (owned, or the ghost strip).
    fn local_strip(&self, strip: usize) -> Option<usize> {
        let owned = strip.wrapping_sub(self.first);
        if owned < self.n_owned {
            Some(owned)
        } else {
            (self.ghost_strip() == Some(strip)).then_some(self.n_owned)
        }
    }

    /// Whether a query ([`StripGrid::find_contacts_of`]) around a disk of radius
    /// `radius` at height `y`, when disks moved up to `moved`, may read strips this grid
    /// does not own.
    pub fn query_leaves_owned(&self, y: f64, radius: f64, moved: f64, domain: &Domain) -> bool {
        let owned = self.owned();
        (self.strips_queried(y, radius, moved, domain)).any(|strip| !owned.contains(&strip))
    }

    /// The strips (global indices) a query ([`StripGrid::find_contacts_of`]) around a
    /// disk of radius `radius` at height `y` may read, when disks moved up to `moved`.
    pub fn strips_queried(
        &self,
        y: f64,
        radius: f64,
        moved: f64,
        domain: &Domain,
    ) -> impl Iterator<Item = usize> {
        let reach = self.query_reach(radius, moved);
        let strips = match domain.boundary {
            Boundary::Walls => self.query_strips::<false>(y, reach),
            Boundary::Periodic => self.query_strips::<true>(y, reach),
        };
        let n_strips = self.layout.n_strips as i64;
        strips.map(move |strip| strip.rem_euclid(n_strips) as usize)
    }

    /// The strips a query reaching `reach` around height `y` reads, as unwrapped global
    /// indices: in a periodic box every strip once, even when the window wraps all the
    /// way round; at walls the edge strips hold the disks beyond them.
    fn query_strips<const PERIODIC: bool>(&self, y: f64, reach: f64) -> RangeInclusive<i64> {
        let n_strips = self.layout.n_strips as i64;
        let inv_height = self.layout.inv_strip_height;
        let lowest = ((y - reach) * inv_height).floor() as i64;
        let highest = ((y + reach) * inv_height).floor() as i64;
        if PERIODIC {
            lowest..=highest.min(lowest + n_strips - 1)
        } else {
            lowest.clamp(0, n_strips - 1)..=highest.clamp(0, n_strips - 1)
        }
    }

    /// How far from a disk of radius `radius` a query looks, when disks moved up to
    /// `moved` since the build: widened by a relative 1e-9, as the layout's reach.
    fn query_reach(&self, radius: f64, moved: f64) -> f64 {
        (radius + self.layout.max_radius + moved) * (1.0 + 1e-9)
    }

    /// Global index of the ghost strip, if this grid has one.
    pub fn ghost_strip(&self) -> Option<usize> {
        (self.strips.len() > self.n_owned)
            .then(|| (self.first + self.n_owned) % self.layout.n_strips)
    }

    /// Disks in the owned strips.
    pub fn len(&self) -> usize {
        self.strips[..self.n_owned].iter().map(Vec::len).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Re-stores `particles` (the disks of the owned strips, as of the last build) in
    /// grid order (strip, then x), working in `scratch`, and points the entries to their
    /// new slots, in one piece or many (`pieces`). Results do not change: pair order and
    /// sums go by id, not storage.
    pub fn store_in_grid_order(
        &mut self,
        particles: &mut Particles,
        scratch: ReorderScratch<'_>,
        pieces: &impl Pieces,
    ) {
        assert_eq!(scratch.order.len(), self.len(), "an order of every disk");
        // Whole strips per piece, each at least as many entries as a piece of the cut.
        let per_piece = pieces.piece_len(self.len(), 1, 1);
        let owned = &mut self.strips[..self.n_owned];
        // A disk that changed strips since it was stored moved by about a strip's length.
        let reach = owned.iter().map(Vec::len).max().unwrap_or(0) * 9 / 8;
        let (mut strips, mut order, mut first) = (owned, &mut scratch.order[..], 0);
        let mut cut = Vec::new();
        while !strips.is_empty() {
            let (mut n_strips, mut n_entries) = (0, 0);
            while n_strips < strips.len() && n_entries < per_piece {
                n_entries += strips[n_strips].len();
                n_strips += 1;
            }
            let (piece_strips, after) = std::mem::take(&mut strips).split_at_mut(n_strips);
            let (piece_order, order_after) = std::mem::take(&mut order).split_at_mut(n_entries);
            cut.push((first, piece_strips, piece_order));
            (strips, order, first) = (after, order_after, first + n_entries);
        }
        // One pass: each entry's disk goes to the next slot, which the entry then names.
        pieces.for_each(&mut cut, |(first, strips, order)| {
            let entries = strips.iter_mut().flatten();
            for ((slot, order), entry) in (*first..).zip(order.iter_mut()).zip(entries) {
                *order = entry.idx;
                entry.idx = slot as u32;
            }
        });
        particles.store_in_order(scratch, reach, pieces);
    }

    /// The owned entries of the strip with global index `strip`, in x order.
    pub fn strip_entries(&self, strip: usize) -> &[Entry] {
        &self.strips[strip - self.first]
    }

    /// Sorts the disks stored at `indices` (all in owned strips) into the grid from
    /// scratch, dropping whatever it held. Each strip gets room for the disks counted
    /// in it and a little more ([`with_room`]): filled by pushing, a strip's room doubled
    /// whenever it ran out, and a strip of 1,100–2,000 disks ended with room for 2,048
    /// (the grid of 10⁶ disks took 19.9 bytes per disk for 12 of entries).
    pub fn fill(&mut self, particles: &Particles, indices: Range<usize>) {
        let mut counts = vec![0_usize; self.strips.len()];
        for idx in indices.clone() {
            counts[self.layout.strip_of(particles.y[idx]) - self.first] += 1;
        }
        for (strip, count) in self.strips.iter_mut().zip(counts) {
            *strip = Vec::with_capacity(with_room(count));
        }
        for idx in indices {
            let mover = self.mover(particles, idx);
            self.strips[mover.strip() - self.first].push(mover.entry);
        }
        // Disks stored in row order arrive as a few runs already sorted by x (the rows
        // that meet the strip): a merging sort finds the runs and merges them in a few
        // linear passes.
        for strip in &mut self.strips[..self.n_owned] {
            strip.sort_by(|a, b| a.x.total_cmp(&b.x));
        }
    }

    /// The entry of the disk stored at `idx`, for the strip its height gives.
    pub fn mover(&self, particles: &Particles, idx: usize) -> Mover {
        let y = particles.y[idx];
        Mover {
            entry: Entry {
                x: particles.x[idx] as f32,
                y: y as f32,
                idx: idx as u32,
            },
            strip: self.layout.strip_of(y) as u32,
        }
    }

    /// Replaces the ghost strip with the disks stored at `indices`, given in x order
    /// (they are the next strip's disks, in the order their owner keeps them).
    pub fn set_ghosts(&mut self, particles: &Particles, indices: Range<usize>) {
        assert!(self.ghost_strip().is_some(), "a grid with a ghost strip");
        let ghosts = self.strips.last_mut().expect("a ghost strip");
        ghosts.clear();
        ghosts.extend(indices.map(|idx| Entry {
            x: particles.x[idx] as f32,
            y: particles.y[idx] as f32,
            idx: idx as u32,
        }));
    }

    /// Points the entry of the disk stored at `from` (at height `y`) to storage index `to`,
    /// after the caller moved the disk there.
    pub fn relabel(&mut self, y: f64, from: u32, to: u32) {
        let strip = &mut self.strips[self.layout.strip_of(y) - self.first];
        let entry = strip
            .iter_mut()
            .find(|entry| entry.idx == from)
            .expect("every owned disk has an entry in the strip of its height");
        entry.idx = to;
    }

    /// Re-sorts the disks of the whole grid by strip and x after they moved. The first
    /// build (or one for a different set of disks) sorts from scratch.
    pub fn build(&mut self, particles: &Particles) {
        if self.len() != particles.len() {
            self.fill(particles, 0..particles.len());
            return;
        }
        let mut movers = std::mem::take(&mut self.movers);
        movers.clear();
        let owned = self.owned();
        let layout = self.layout;
        let strips = &mut self.strips[..self.n_owned];
        refresh_band(&layout, strips, owned.start, particles, &mut movers);
        receive_band(strips, owned.start, &[&movers]);
        self.movers = movers;
    }

    /// The owned strips, for bands of threads: split them, [`refresh_band`] each, then
    /// [`receive_band`] each with every band's movers.
    pub fn owned_strips_mut(&mut self) -> &mut [Vec<Entry>] {
        &mut self.strips[..self.n_owned]
    }

    /// Balanced bands of owned strips (global indices, in order, none empty) for up to
    /// `n_bands` workers: cut where the running disk count passes each equal share.
    pub fn bands(&self, n_bands: usize) -> Vec<Range<usize>> {
        let total = self.len().max(1);
        let mut bands = Vec::with_capacity(n_bands);
        let mut start = 0;
        let mut count = 0;
        for (local, strip) in self.strips[..self.n_owned].iter().enumerate() {
            count += strip.len();
            let share = total * (bands.len() + 1) / n_bands;
            let is_last = local + 1 == self.n_owned;
            if is_last || (count >= share && bands.len() + 1 < n_bands) {
                bands.push(self.first + start..self.first + local + 1);
                start = local + 1;
            }
        }
        bands
    }

    /// Appends every overlapping pair found by the owned strips (in no particular order).
    /// Call [`StripGrid::build`] first with the same particles.
    pub fn find_contacts(
        &self,
        particles: &Particles,
        domain: &Domain,
        contacts: &mut Vec<Contact>,
    ) {
        self.find_contacts_in(self.owned(), particles, domain, contacts);
    }

    /// Appends the overlapping pairs whose scanning disk lies in `strips` (owned, global
    /// indices): each pair is found by exactly one strip.
    pub fn find_contacts_in(
        &self,
        strips: Range<usize>,
        particles: &Particles,
        domain: &Domain,
        contacts: &mut Vec<Contact>,
    ) {
        let mut sink = ContactSink { contacts };
        self.scan_in(strips, particles, domain, 0.0, &mut sink);
    }

    /// Appends, as `[storage index, storage index]`, the pairs whose scanning disk lies
    /// in `strips` (owned, global indices) and whose centres are closer than their radii
    /// plus `skin`: the candidates of a neighbour list. The layout's strips must be at
    /// least `2 · max_radius + skin` tall ([`StripLayout::with_skin`]). With equal radii
    /// the list may hold a few pairs up to the rounding of the f32 entries further apart
    /// ([`rounding_slack`]): a superset, which the list's exact test filters.
    pub fn find_pairs_in(
        &self,
        strips: Range<usize>,
        particles: &Particles,
        domain: &Domain,
        skin: f64,
        pairs: &mut Vec<[u32; 2]>,
    ) {
        debug_assert!(self.layout.reach >= skin);
        self.scan_in(strips, particles, domain, skin, &mut PairSink { pairs });
    }

    /// Appends every pair of a disk stored at one of `movers` and another disk of the
    /// grid that overlap now, when no disk is further than `moved` from its position at
    /// the last build (which the grid holds): a query around each mover of the strips
    /// (those the grid holds: owned and ghost) and x windows within
    /// `r_mover + max_radius + moved` of it. A mover need not be in the grid. A pair
    /// may be appended twice (by both its disks, or by this and a neighbour list): the
    /// caller sorts and removes repeats. The overlap test is the scan's arithmetic.
    pub fn find_contacts_of(
        &self,
        movers: &[u32],
        moved: f64,
        particles: &Particles,
        domain: &Domain,
        contacts: &mut Vec<Contact>,
    ) {
        match domain.boundary {
            Boundary::Walls => self.query::<false>(movers, moved, particles, domain, contacts),
            Boundary::Periodic => self.query::<true>(movers, moved, particles, domain, contacts),
        }
    }

    fn query<const PERIODIC: bool>(
        &self,
        movers: &[u32],
        moved: f64,
        particles: &Particles,
        domain: &Domain,
        contacts: &mut Vec<Contact>,
    ) {
        let (x, y, radius) = (&particles.x, &particles.y, &particles.radius);
        let n_strips = self.layout.n_strips as i64;
        let width = self.layout.width;
        for &mover in movers {
            let a = mover as usize;
            let (xa, ya) = (x[a], y[a]);
            let reach = self.query_reach(radius[a], moved);
            // x windows of build positions: one, or two where a periodic window wraps.
            let whole = (f64::NEG_INFINITY, f64::INFINITY);
            let windows = match (PERIODIC, reach < 0.5 * width) {
                (false, _) => [(xa - reach, xa + reach), (0.0, 0.0)],
                (true, false) => [whole, (0.0, 0.0)],
                (true, true) if xa - reach < 0.0 => {
                    [(xa - reach, xa + reach), (xa - reach + width, width)]
                }
                (true, true) if xa + reach > width => {
                    [(xa - reach, xa + reach), (0.0, xa + reach - width)]
                }
                (true, true) => [(xa - reach, xa + reach), (0.0, 0.0)],
            };
            // The entries' x is rounded to f32: widen the windows by the rounding of any x
            // inside them (at most |xa| + reach, or the box's width when periodic).
            let slack = rounding_slack(xa.abs().max(width) + reach);
            for strip in self.query_strips::<PERIODIC>(ya, reach) {
                let Some(local) = self.local_strip(strip.rem_euclid(n_strips) as usize) else {
                    continue;
                };
                let entries = &self.strips[local][..];
                // A window with `from == to` holds nothing.
                for &(from, to) in windows.iter().filter(|(from, to)| from < to) {
                    let (from, to) = (from - slack, to + slack);
                    let first = first_at_or_right_of(entries, from, width);
                    for b in entries[first..].iter().take_while(|b| f64::from(b.x) < to) {
                        let j = b.idx as usize;
                        if j == a {
                            continue;
                        }
                        let (dx, dy) = domain.separation_in::<PERIODIC>(xa, ya, x[j], y[j]);
                        let contact = radius[a] + radius[j];
                        if dx * dx + dy * dy < contact * contact {
                            contacts.push(Contact::new(a, j));
                        }
                    }
                }
            }
        }
    }

    fn scan_in(
        &self,
        strips: Range<usize>,
        particles: &Particles,
        domain: &Domain,
        skin: f64,
        sink: &mut impl Sink,
    ) {
        let local = strips.start - self.first..strips.end - self.first;
        match (domain.boundary, self.layout.equal_radius.is_some()) {
            (Boundary::Walls, true) => {
                self.scan::<false, true, _>(local, particles, domain, skin, sink)
            }
            (Boundary::Walls, false) => {
                self.scan::<false, false, _>(local, particles, domain, skin, sink)
            }
            (Boundary::Periodic, true) => {
                self.scan::<true, true, _>(local, particles, domain, skin, sink)
            }
            (Boundary::Periodic, false) => {
                self.scan::<true, false, _>(local, particles, domain, skin, sink)
            }
        }
    }

    /// A bound on |x| and |y| of the f32 entries of the local strips `local` and of the
    /// strip each scans above it, and on the box's sides: what bounds the rounding of
    /// their positions and of the periodic images. A strip is sorted by x, so its ends
    /// bound its |x|; a strip's disks are within the box's height, except in the edge
    /// strips, which hold the disks outside a walled box and are read whole.
    fn largest_coordinate(&self, local: &Range<usize>) -> f64 {
        let above = (local.end < self.strips.len()).then_some(local.end);
        let wrapped = (self.north_wraps && local.end == self.strips.len()).then_some(0);
        let last_strip = self.layout.n_strips - 1;
        let mut largest = self.layout.width.max(self.layout.height());
        for strip in local.clone().chain(above).chain(wrapped) {
            let entries = &self.strips[strip];
            let ends = entries.first().into_iter().chain(entries.last());
            for entry in ends {
                largest = largest.max(f64::from(entry.x.abs()));
            }
            let global = if strip < self.n_owned {
                self.first + strip
            } else {
                self.ghost_strip().unwrap_or(0)
            };
            if global == 0 || global == last_strip {
                for entry in entries {
                    largest = largest.max(f64::from(entry.y.abs()));
                }
            }
        }
        largest
    }

    /// Offers `sink` every pair whose scanning disk lies in the local strips `local`
    /// (each pair once), with whether their centres are closer than their radii plus
    /// `skin`. Windows in x: a disk's own strip from the next disk on, and the strip
    /// above, both within `reach` of it.
    ///
    /// The windows and a first test read the f32 entries, widened by their rounding
    /// ([`rounding_slack`]) to the largest contact distance plus `skin`; a pair that
    /// passes is then decided by the disks' f64 positions and radii with the shared
    /// arithmetic, unless the sink takes a superset (a neighbour list of equal disks).
    ///
    /// Most windows hold a few disks: the first [`OWN_WINDOW`] and [`NORTH_WINDOW`]
    /// candidates are tested whatever their count (a candidate outside the window
    /// fails the window test, not a loop exit: no mispredicted branch per disk), and a
    /// loop continues only the rare window that reaches further.
    fn scan<const PERIODIC: bool, const EQUAL_RADII: bool, S: Sink>(
        &self,
        local: Range<usize>,
        particles: &Particles,
        domain: &Domain,
        skin: f64,
        sink: &mut S,
    ) {
        let slack = rounding_slack(self.largest_coordinate(&local) + self.layout.reach);
        let reach = rounded_up(self.layout.reach + slack);
        let width = self.layout.width as f32;
        let near_limit = 2.0 * self.layout.max_radius + skin + slack;
        let equal_radius = self.layout.equal_radius.unwrap_or(0.0);
        let test = PairTest::<PERIODIC, EQUAL_RADII> {
            // In f32, as the entries: the slack covers the few roundings of this test too.
            near_sq: rounded_up(near_limit * near_limit),
            width,
            height: domain.height as f32,
            particles,
            domain,
            equal_limit: equal_radius + equal_radius + skin,
            skin,
            superset: !S::EXACT && EQUAL_RADII,
        };
        let imaged = |a: &Entry, b: &Entry| test.decide(test.near(a, b), a, b);
        let plain = |a: &Entry, b: &Entry| test.decide(test.near_plain(a, b), a, b);
        // Inside a disk's own window, and its north window unless the strip is the box's
        // last (whose north is the first, a box height away), the minimum image leaves
        // every difference as it is when the box is at least 5 strips tall (|dy| is at
        // most two strips, under half the height) and the reach is at most half its
        // width (|dx| is under the reach): the same test, bit for bit, without the image.
        // A candidate offered outside its window fails on the window either way.
        let plain_inside = !PERIODIC || (self.layout.n_strips >= 5 && reach <= 0.5 * width);
        let no_entries: &[Entry] = &[];
        for strip in local {
            let own_entries = &self.strips[strip][..];
            let north_entries = if strip + 1 < self.strips.len() {
                &self.strips[strip + 1][..]
            } else if self.north_wraps {
                &self.strips[0][..]
            } else {
                no_entries
            };
            let north_is_first = self.first + strip + 1 == self.layout.n_strips;
            // First north disk not left of the current window; the window only moves right.
            let mut north_first = 0;
            for (pos, a) in own_entries.iter().enumerate() {
                // Own strip: the disks to the right within reach.
                let right = |b: &Entry| b.x - a.x < reach;
                let own = &own_entries[pos + 1..];
                if plain_inside {
                    offer_window::<OWN_WINDOW>(own, a, right, &plain, sink);
                } else {
                    offer_window::<OWN_WINDOW>(own, a, right, &imaged, sink);
                }
                // North strip: the disks within reach on either side.
                north_first = first_in_window(north_entries, north_first, a.x - reach);
                let left = |b: &Entry| b.x < a.x + reach;
                let north = &north_entries[north_first..];
                if plain_inside && !north_is_first {
                    offer_window::<NORTH_WINDOW>(north, a, left, &plain, sink);
                } else {
                    offer_window::<NORTH_WINDOW>(north, a, left, &imaged, sink);
                }
                if PERIODIC {
                    offer_periodic_images(
                        own_entries,
                        pos,
                        north_entries,
                        reach,
                        width,
                        &imaged,
                        sink,
                    );
                }
            }
        }
    }
}

/// Offers `sink` the pairs of `own_entries[pos]` with the disks its own and north
/// windows reach through the box's periodic image in x: the disks at the strip's other
/// end, when the window crosses the box's right or left side.
#[inline(always)]
fn offer_periodic_images(
    own_entries: &[Entry],
    pos: usize,
    north_entries: &[Entry],
    reach: f32,
    width: f32,
    imaged: &impl Fn(&Entry, &Entry) -> bool,
    sink: &mut impl Sink,
) {
    let a = &own_entries[pos];
    if a.x + reach > width {
        for b in own_entries[..pos]
            .iter()
            .take_while(|b| b.x + width - a.x < reach)
        {
            sink.make_room(1);
            // SAFETY: room was made just above.
            unsafe { sink.offer(imaged(a, b), a, b) };
        }
        for b in north_entries
            .iter()
            .take_while(|b| b.x + width < a.x + reach)
        {
            sink.make_room(1);
            // SAFETY: room was made just above.
            unsafe { sink.offer(imaged(a, b), a, b) };
        }
    }
    if a.x - reach < 0.0 {
        for b in north_entries
            .iter()
            .rev()
            .take_while(|b| b.x - width > a.x - reach)
        {
            sink.make_room(1);
            // SAFETY: room was made just above.
            unsafe { sink.offer(imaged(a, b), a, b) };
        }
    }
}

/// The tests a scanned pair goes through: first on the f32 entries, widened by their
/// rounding to the largest contact distance plus the skin; then, unless the sink takes
/// a superset, on the disks' f64 positions and radii with the shared arithmetic.
struct PairTest<'a, const PERIODIC: bool, const EQUAL_RADII: bool> {
    /// The square of the widened limit, in f32 as the entries.
    near_sq: f32,
    width: f32,
    height: f32,
    particles: &'a Particles,
    domain: &'a Domain,
    /// With equal radii the exact limit is one number: `r + r + skin`.
    equal_limit: f64,
    skin: f64,
    /// The f32 test alone decides (a neighbour list of equal disks).
    superset: bool,
}

impl<const PERIODIC: bool, const EQUAL_RADII: bool> PairTest<'_, PERIODIC, EQUAL_RADII> {
    #[inline(always)]
    fn close(&self, dx: f32, dy: f32) -> bool {
        dx * dx + dy * dy < self.near_sq
    }

    /// The f32 test, through the minimum image in a periodic box.
    #[inline(always)]
    fn near(&self, a: &Entry, b: &Entry) -> bool {
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        match PERIODIC {
            true => self.close(
                minimum_image(dx, self.width),
                minimum_image(dy, self.height),
            ),
            false => self.close(dx, dy),
        }
    }

    /// The f32 test where the minimum image cannot change the differences.
    #[inline(always)]
    fn near_plain(&self, a: &Entry, b: &Entry) -> bool {
        self.close(b.x - a.x, b.y - a.y)
    }

    /// The f64 test. With a skin of 0, `r_a + r_b + skin` is the contact distance itself:
    /// adding 0.0 to a positive number is exact.
    #[inline(always)]
    fn exact(&self, a: &Entry, b: &Entry) -> bool {
        let (i, j) = (a.idx as usize, b.idx as usize);
        let (x, y) = (&self.particles.x, &self.particles.y);
        let (dx, dy) = self
            .domain
            .separation_in::<PERIODIC>(x[i], y[i], x[j], y[j]);
        let limit = if EQUAL_RADII {
            self.equal_limit
        } else {
            let radius = &self.particles.radius;
            radius[i] + radius[j] + self.skin
        };
        dx * dx + dy * dy < limit * limit
    }

    /// Whether the pair passes, given the f32 test's answer.
    #[inline(always)]
    fn decide(&self, nearby: bool, a: &Entry, b: &Entry) -> bool {
        if self.superset {
            nearby
        } else {
            nearby && self.exact(a, b)
        }
    }
}

/// Entries a window's left end passes tested at once ([`first_in_window`]).
const WINDOW_STEP: usize = 4;

/// The first of `entries` (sorted by x) from `from` on whose x is above `left_end`, for
/// a window that only moves right. The scan's next disk moves the window's left end by
/// about one entry: [`WINDOW_STEP`] entries are tested at once, without a branch per
/// entry (a loop exit after a varying count is mispredicted), and a loop continues only
/// when all of them are passed.
#[inline(always)]
fn first_in_window(entries: &[Entry], from: usize, left_end: f32) -> usize {
    let mut first = from;
    if let Some(next) = entries.get(first..first + WINDOW_STEP) {
        // Sorted: the entries passed come first, so their count is the step.
        let passed: usize = next.iter().map(|b| usize::from(b.x <= left_end)).sum();
        first += passed;
        if passed < WINDOW_STEP {
            return first;
        }
    }
    while first < entries.len() && entries[first].x <= left_end {
        first += 1;
    }
    first
}

/// Candidates of a disk's own strip tested without a loop exit ([`StripGrid::scan`]).
const OWN_WINDOW: usize = 2;
/// Candidates of the strip above tested without a loop exit ([`StripGrid::scan`]).
const NORTH_WINDOW: usize = 4;

/// Offers `sink` the pairs of `a` with the disks of one window of its scan: the
/// `candidates` from the window's start on, in x order, while `inside` (the window ends
/// where `inside` first fails). The first `K` are offered whatever their count, those
/// outside failing the test rather than a loop exit; a loop continues only when the
/// `K`-th is still inside. Room for the first `K` is made at once, not one by one.
#[inline(always)]
fn offer_window<const K: usize>(
    candidates: &[Entry],
    a: &Entry,
    inside: impl Fn(&Entry) -> bool,
    within: &impl Fn(&Entry, &Entry) -> bool,
    sink: &mut impl Sink,
) {
    let rest = match candidates.split_first_chunk::<K>() {
        Some((window, rest)) => {
            sink.make_room(K);
            for b in window {
                // SAFETY: room was made for these `K` just above.
                unsafe { sink.offer(inside(b) & within(a, b), a, b) };
            }
            if inside(&window[K - 1]) { rest } else { &[] }
        }
        None => candidates,
    };
    for b in rest.iter().take_while(|b| inside(b)) {
        sink.make_room(1);
        // SAFETY: room was made just above.
        unsafe { sink.offer(within(a, b), a, b) };
    }
}

/// Where the scan's candidate pairs go: `offer` is called for every candidate, with
/// whether it passed the test.
trait Sink {
    /// Whether the pairs must be decided exactly (by the disks' f64 positions), or a
    /// superset will do (the f32 entries' widened test alone).
    const EXACT: bool;
    /// Makes room for `n` more offers.
    fn make_room(&mut self, _n: usize) {}
    /// Takes one candidate pair.
    ///
    /// # Safety
    /// Room was made for this offer ([`Sink::make_room`]) and not used by another.
    unsafe fn offer(&mut self, accepted: bool, a: &Entry, b: &Entry);
}

/// The index of the first entry of a strip (sorted by x) whose x is not below `from`:
/// `entries.partition_point(|b| f64::from(b.x) < from)`, searched in a window around
/// where a strip of evenly spread disks across a box `width` wide would hold it, the
/// window doubling until it brackets the answer. A query's binary search over a whole
/// strip of a large box misses the caches at most of its dozen probes; this one reads a
/// few lines near the guess.
fn first_at_or_right_of(entries: &[Entry], from: f64, width: f64) -> usize {
    let below = |idx: usize| f64::from(entries[idx].x) < from;
    let len = entries.len();
    // A saturating cast: a NaN or negative guess is 0, a huge one `len`.
    let guess = ((from / width * len as f64) as usize).min(len);
    let mut reach = 1;
    loop {
        let (lo, hi) = (guess.saturating_sub(reach), (guess + reach).min(len));
        // The answer is in lo..=hi when the entry before lo is below and the one at hi
        // is not.
        if (lo == 0 || below(lo - 1)) && (hi == len || !below(hi)) {
            return lo + entries[lo..hi].partition_point(|b| f64::from(b.x) < from);
        }
        reach *= 2;
    }
}

/// How far a test on f32 entries must be widened to never reject a pair the f64
/// positions would accept, when every coordinate involved, and every sum of them, is
/// at most `largest` in magnitude: rounding to f32 moves a coordinate by at most
/// `largest · 2⁻²⁴`, and the few f32 operations of a test add as much again a few
/// times; `2⁻²⁰` (16 units) covers them with room to spare.
fn rounding_slack(largest: f64) -> f64 {
    largest * f64::from(f32::EPSILON) * 8.0
}

/// `value` as an f32 no smaller than it.
fn rounded_up(value: f64) -> f32 {
    let rounded = value as f32;
    if f64::from(rounded) < value {
        rounded.next_up()
    } else {
        rounded
    }
}

/// Overlapping pairs as [`Contact`]s. Few candidates overlap: the branch is predictable.
struct ContactSink<'a> {
    contacts: &'a mut Vec<Contact>,
}

impl Sink for ContactSink<'_> {
    const EXACT: bool = true;
    #[inline(always)]
    unsafe fn offer(&mut self, accepted: bool, a: &Entry, b: &Entry) {
        if accepted {
            let contact = Contact::new(a.idx as usize, b.idx as usize);
            self.contacts.push(contact);
        }
    }
}

/// Candidate pairs of a neighbour list, as storage indices. A good share of candidates
/// pass: every candidate is written, and the length grows only by those that passed,
/// so there is no branch to mispredict.
struct PairSink<'a> {
    pairs: &'a mut Vec<[u32; 2]>,
}

impl Sink for PairSink<'_> {
    const EXACT: bool = false;
    #[inline(always)]
    fn make_room(&mut self, n: usize) {
        if self.pairs.capacity() - self.pairs.len() < n {
            self.pairs.reserve(n.max(1024));
        }
    }

    #[inline(always)]
    unsafe fn offer(&mut self, accepted: bool, a: &Entry, b: &Entry) {
        let len = self.pairs.len();
        debug_assert!(len < self.pairs.capacity(), "room made for every offer");
        // SAFETY: the caller made room for this element at `len`; the length grows over
        // it only when it was written.
        unsafe {
            self.pairs.as_mut_ptr().add(len).write([a.idx, b.idx]);
            self.pairs.set_len(len + usize::from(accepted));
        }
    }
}

/// First phase of a build, for one band of strips (`band[0]` is the strip with global
/// index `first`): reads the disks' new positions, moves the disks that changed strip
/// out to `movers` (then sorted by strip and x), and re-sorts the rest of each strip.
pub fn refresh_band(
    layout: &StripLayout,
    band: &mut [Vec<Entry>],
    first: usize,
    particles: &Particles,
    movers: &mut Vec<Mover>,
) {
    let (x, y) = (&particles.x[..], &particles.y[..]);
    for (offset, strip) in band.iter_mut().enumerate() {
        let here = (first + offset) as u32;
        let mut kept = 0;
        for read in 0..strip.len() {
            let mut entry = strip[read];
            let idx = entry.idx as usize;
            entry.x = x[idx] as f32;
            entry.y = y[idx] as f32;
            // The strip goes by the f64 height, as everywhere.
            let strip_now = layout.strip_of(y[idx]) as u32;
            if strip_now == here {
                strip[kept] = entry;
                kept += 1;
            } else {
                movers.push(Mover {
                    entry,
                    strip: strip_now,
                });
            }
        }
        strip.truncate(kept);
        insertion_sort(strip);
    }
    sort_movers(movers);
}

/// Sorts movers by strip, then x: the order [`receive_band`] takes.
pub fn sort_movers(movers: &mut [Mover]) {
    movers.sort_unstable_by(|a, b| a.strip.cmp(&b.strip).then(a.entry.x.total_cmp(&b.entry.x)));
}

/// Second phase of a build, for one band of strips (`band[0]` has global index
/// `first`): merges in the movers of every band (each list sorted by strip and x) that
/// now belong to this band's strips.
pub fn receive_band(band: &mut [Vec<Entry>], first: usize, movers: &[&[Mover]]) {
    let end = first + band.len();
    for list in movers {
        let from = list.partition_point(|m| m.strip() < first);
        let to = list.partition_point(|m| m.strip() < end);
        for group in list[from..to].chunk_by(|a, b| a.strip == b.strip) {
            merge_sorted(&mut band[group[0].strip() - first], group);
        }
    }
}

/// A strip's spare room: one entry for every this many it holds. Strips change by a
/// few disks per build (one of the grid of 10⁶ disks at packing 0.3 holds about 1,200).
const STRIP_SPARE_SHARE: usize = 32;

/// The room for a strip of `len` disks: them and [`STRIP_SPARE_SHARE`]'s spare.
fn with_room(len: usize) -> usize {
    len + len / STRIP_SPARE_SHARE + 1
}

/// Merges `incoming` (sorted by x) into `strip` (sorted by x), from the back.
fn merge_sorted(strip: &mut Vec<Entry>, incoming: &[Mover]) {
    let mut read = strip.len();
    let len = read + incoming.len();
    if len > strip.capacity() {
        strip.reserve_exact(with_room(len) - read);
    }
    strip.resize(len, Entry::default());
    let mut write = strip.len();
    for new in incoming.iter().rev().map(|mover| &mover.entry) {
        while read > 0 && new.x < strip[read - 1].x {
            read -= 1;
            write -= 1;
            strip[write] = strip[read];
        }
        write -= 1;
        strip[write] = *new;
    }
}

/// Sorts the nearly sorted entries of one strip by x in O(n + inversions).
fn insertion_sort(entries: &mut [Entry]) {
    for i in 1..entries.len() {
        if entries[i].x >= entries[i - 1].x {
            continue;
        }
        let moving = entries[i];
        let mut j = i;
        while j > 0 && moving.x < entries[j - 1].x {
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
    find_contacts_all_pairs_from(0..particles.len(), particles, domain, contacts);
}

/// The pairs of [`find_contacts_all_pairs`] whose first disk (in storage order) is in
/// `rows`: disjoint row ranges split the search among workers.
pub fn find_contacts_all_pairs_from(
    rows: Range<usize>,
    particles: &Particles,
    domain: &Domain,
    contacts: &mut Vec<Contact>,
) {
    match domain.boundary {
        Boundary::Walls => all_pairs::<false>(rows, particles, domain, contacts),
        Boundary::Periodic => all_pairs::<true>(rows, particles, domain, contacts),
    }
}

fn all_pairs<const PERIODIC: bool>(
    rows: Range<usize>,
    particles: &Particles,
    domain: &Domain,
    contacts: &mut Vec<Contact>,
) {
    let (x, y, radius) = (&particles.x, &particles.y, &particles.radius);
    for i in rows {
        for j in i + 1..particles.len() {
            let (dx, dy) = domain.separation_in::<PERIODIC>(x[i], y[i], x[j], y[j]);
            let contact = radius[i] + radius[j];
            if dx * dx + dy * dy < contact * contact {
                contacts.push(Contact::new(i, j));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::particles::Disk;

    /// Numbers uniform in [0, 1) from a linear congruential generator started at `state`:
    /// the tests' own, the same on every platform and crate version.
    fn uniform_from(mut state: u64) -> impl FnMut() -> f64 {
        move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1_u64 << 53) as f64
        }
    }

    /// 300 disks in a corner far from the origin of a box 2²⁵ wide, where f32 positions
    /// are 4 apart: centres 0.001–3 apart, radii equal or not. The f32 entries alone
    /// would misjudge most of these pairs.
    fn far_cluster(equal_radii: bool) -> Particles {
        let mut uniform = uniform_from(0x9e37_79b9_7f4a_7c15);
        let disks: Vec<Disk> = (0..300)
            .map(|_| Disk {
                x: 33_554_000.0 + 30.0 * uniform(),
                y: 1.0 + 30.0 * uniform(),
                vx: 0.0,
                vy: 0.0,
                radius: if equal_radii { 1.0 } else { 0.5 + uniform() },
                mass: 1.0,
            })
            .collect();
        Particles::from_disks(&disks)
    }

    /// The search from a guess finds what a binary search over the whole strip finds,
    /// wherever the guess lands: strips empty, short, crowded at one end, with equal
    /// x's, and bounds outside the box or infinite.
    #[test]
    fn the_search_from_a_guess_finds_the_first_entry_a_binary_search_finds() {
        let strip = |xs: &[f32]| -> Vec<Entry> {
            xs.iter()
                .enumerate()
                .map(|(idx, &x)| Entry {
                    x,
                    y: 0.0,
                    idx: idx as u32,
                })
                .collect()
        };
        let even: Vec<f32> = (0..1000).map(|k| k as f32 * 0.1).collect();
        let crowded: Vec<f32> = (0..1000).map(|k| 90.0 + k as f32 * 0.01).collect();
        let equal = [5.0_f32; 64];
        let strips = [
            strip(&[]),
            strip(&[50.0]),
            strip(&even),
            strip(&crowded),
            strip(&equal),
        ];
        let bounds = [
            f64::NEG_INFINITY,
            -3.0,
            0.0,
            0.05,
            5.0,
            5.0 + 1e-9,
            49.95,
            90.5,
            99.89,
            100.0,
            250.0,
            f64::INFINITY,
        ];
        for entries in &strips {
            for from in bounds {
                assert_eq!(
                    first_at_or_right_of(entries, from, 100.0),
                    entries.partition_point(|b| f64::from(b.x) < from),
                    "{} entries, from {from}",
                    entries.len()
                );
            }
        }
    }

    fn sorted(mut pairs: Vec<[u32; 2]>) -> Vec<[u32; 2]> {
        for pair in &mut pairs {
            pair.sort_unstable();
        }
        pairs.sort_unstable();
        pairs
    }

    /// A re-storing in pieces (whole strips each, run last first) stores the disks and
    /// names their new slots as one in one piece does: from placement order (gathered
    /// whole), and, the disks moved a little, from near grid order (in place).
    #[test]
    fn a_restoring_in_pieces_stores_the_disks_as_in_one() {
        use crate::sim::particles::ReorderScratch;
        use crate::sim::pieces::{Backwards, InTurn};
        use crate::sim::scene::{GasSpec, MassRule, RadiusDistribution};
        let scene = GasSpec {
            radius: RadiusDistribution::Uniform { min: 0.5, max: 1.5 },
            mass: MassRule::Area,
            seed: 9,
            ..GasSpec::unit(3000, 0.3)
        }
        .build()
        .expect("places");
        let n = scene.particles.len();
        // The grid's entries and the disks after a re-storing in `pieces`.
        fn stored(
            grid: &StripGrid,
            particles: &Particles,
            pieces: &impl Pieces,
        ) -> (StripGrid, Particles) {
            let (mut grid, mut particles) = (grid.clone(), particles.clone());
            let n = particles.len();
            let (mut order, mut spare) = (vec![0; n], vec![0.0; n]);
            let scratch = ReorderScratch {
                order: &mut order,
                spare: &mut spare,
            };
            grid.store_in_grid_order(&mut particles, scratch, pieces);
            (grid, particles)
        }
        let entries = |grid: &StripGrid| -> Vec<Vec<Entry>> {
            grid.owned()
                .map(|strip| grid.strip_entries(strip).to_vec())
                .collect()
        };
        let mut grid = StripGrid::new(&scene.domain, &scene.particles);
        let mut particles = scene.particles.clone();
        grid.build(&particles);
        for round in ["from placement order", "from near grid order"] {
            let (whole_grid, whole) = stored(&grid, &particles, &InTurn);
            assert_ne!(whole.id, particles.id, "{round}: re-stored");
            for workers in [2, 3, 7] {
                let (cut_grid, cut) = stored(&grid, &particles, &Backwards(workers));
                assert_eq!(cut, whole, "{round}, {workers} pieces: the disks");
                assert_eq!(
                    entries(&cut_grid),
                    entries(&whole_grid),
                    "{round}: the slots"
                );
            }
            (grid, particles) = (whole_grid, whole);
            let Domain { width, height, .. } = scene.domain;
            for k in 0..n {
                let turn = f64::from(particles.id[k]);
                particles.x[k] = (particles.x[k] + 0.4 * turn.cos()).clamp(1.5, width - 1.5);
                particles.y[k] = (particles.y[k] + 0.4 * turn.sin()).clamp(1.5, height - 1.5);
            }
            grid.build(&particles);
        }
    }

    /// The exact search finds exactly the pairs of the all-pairs test, and a neighbour
    /// list holds at least every pair within its skin, however coarse f32 is where the
    /// disks are: the f32 entries only narrow the search.
    #[test]
    fn searches_on_f32_entries_miss_no_pair_far_from_the_origin() {
        for boundary in [Boundary::Walls, Boundary::Periodic] {
            let domain = Domain {
                width: 33_554_432.0,
                height: 32.0,
                boundary,
            };
            for equal_radii in [true, false] {
                let particles = far_cluster(equal_radii);
                let case = format!("{boundary:?}, equal radii {equal_radii}");
                let (contacts, _) = assert_searches_miss_no_pair(&domain, &particles, 0.5, &case);
                assert!(contacts > 100, "the cluster is dense: {contacts} pairs");
            }
        }
    }

    /// In periodic boxes from 3 to 8 strips tall, and from narrower than two reaches to
    /// wide, the exact search finds exactly the all-pairs contacts and a neighbour list
    /// holds every pair within its skin, through the edges too: the scan leaves out the
    /// minimum image only where it changes nothing (at least 5 strips, a reach of at
    /// most half the width, not across the last strip).
    #[test]
    fn periodic_boxes_of_few_strips_miss_no_pair_across_their_edges() {
        let mut uniform = uniform_from(0x2545_f491_4f6c_dd1d);
        let skin = 1.0;
        // Strips 2·r + skin = 3 tall.
        for n_strips in 3..=8 {
            for width in [5.0, 9.0, 40.0] {
                let domain = Domain {
                    width,
                    height: 3.0 * n_strips as f64 + 0.5,
                    boundary: Boundary::Periodic,
                };
                let n = (domain.area() * 0.25) as usize;
                let disks: Vec<Disk> = (0..n)
                    .map(|_| Disk {
                        x: domain.width * uniform(),
                        y: domain.height * uniform(),
                        vx: 0.0,
                        vy: 0.0,
                        radius: 1.0,
                        mass: 1.0,
                    })
                    .collect();
                let particles = Particles::from_disks(&disks);
                let case = format!("{n_strips} strips, width {width}");
                let layout = StripLayout::with_skin(&domain, &particles, skin);
                assert_eq!(layout.n_strips, n_strips, "{case}");
                let (_, near) = assert_searches_miss_no_pair(&domain, &particles, skin, &case);
                assert!(near > n / 2, "{case}: {near} pairs within the skin");
            }
        }
    }

    /// Asserts that the exact search finds exactly the all-pairs contacts of `particles`
    /// and that a neighbour list with `skin` holds every pair within the skin of
    /// touching; returns how many contacts and how many pairs within the skin there are.
    fn assert_searches_miss_no_pair(
        domain: &Domain,
        particles: &Particles,
        skin: f64,
        case: &str,
    ) -> (usize, usize) {
        let grid = StripGrid::new(domain, particles);
        let (mut found, mut all) = (Vec::new(), Vec::new());
        grid.find_contacts(particles, domain, &mut found);
        find_contacts_all_pairs(particles, domain, &mut all);
        let keys = |contacts: &[Contact]| {
            let mut keys: Vec<u64> = contacts.iter().map(|c| c.key(&particles.id)).collect();
            keys.sort_unstable();
            keys
        };
        assert_eq!(keys(&found), keys(&all), "{case}");

        let listing = StripGrid::with_skin(domain, particles, skin);
        let mut listed = Vec::new();
        listing.find_pairs_in(listing.owned(), particles, domain, skin, &mut listed);
        let listed = sorted(listed);
        let (x, y, r) = (&particles.x, &particles.y, &particles.radius);
        let mut near = 0;
        for i in 0..particles.len() {
            for j in i + 1..particles.len() {
                let (dx, dy) = domain.separation(x[i], y[i], x[j], y[j]);
                let limit = r[i] + r[j] + skin;
                if dx * dx + dy * dy < limit * limit {
                    let pair = [i as u32, j as u32];
                    assert!(
                        listed.binary_search(&pair).is_ok(),
                        "{pair:?} listed, {case}"
                    );
                    near += 1;
                }
            }
        }
        (all.len(), near)
    }
}
