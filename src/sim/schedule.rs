//! Which contacts a worker may resolve on its own: chains of contacts that share disks,
//! found with a union–find over the contacts of one step.
//!
//! The serial reference resolves every contact in canonical order ([`Contact::key`]).
//! Contacts that share no disk commute exactly, so a worker may resolve a chain in
//! canonical order on its own whenever no other worker holds a contact of that chain.
//! A worker pins the disks other workers may also touch (a band's or rank's edge
//! strips); chains with a pinned disk are handed over and resolved afterwards, in
//! canonical order, in one place. Either way each chain sees its contacts in the serial
//! order, so the result has the serial bits.
//!
//! The same rule lets one worker order its own contacts for speed
//! ([`ResolutionOrder`]): a pair that shares no disk with any other is a chain of its
//! own and may go anywhere, so it goes in the order found, next to the disks it reads.

use super::grid::{Contact, order_canonically};
use super::particles::SPARE_SHARE;

/// Scratch memory for splitting contacts by chain, per storage index: the union–find
/// parent, and whether the disk's chain holds a pinned disk (valid for disks in this
/// step's chained contacts only), and the scratch of the resolution order.
#[derive(Clone, Debug, Default)]
pub struct ContactSchedule {
    parent: Vec<u32>,
    pinned: Vec<bool>,
    order: ResolutionOrder,
}

/// Scratch memory for putting one worker's contacts in an order that resolves to the
/// serial bits: which disks the contacts hold, the contacts that share a disk, and
/// those with their keys.
#[derive(Clone, Debug, Default)]
pub struct ResolutionOrder {
    holdings: Holdings,
    chained: Vec<Contact>,
    keyed: Vec<(u64, Contact)>,
}

/// Which disks, by storage index, one or several of a step's contacts hold: two bits a
/// disk, side by side in a word (a count per disk took a byte, 10 MB at 10⁷ disks).
/// Empty between calls.
#[derive(Clone, Debug, Default)]
struct Holdings {
    words: Vec<u64>,
}

impl Holdings {
    /// Disks per word.
    const PER_WORD: u32 = 32;

    /// Room for the storage indices below `n_particles`.
    fn cover(&mut self, n_particles: usize) {
        self.words
            .resize(n_particles.div_ceil(Self::PER_WORD as usize), 0);
    }

    /// The word of `disk` and its "held" bit (the bit above it is "held again").
    fn word_and_bit(disk: u32) -> (usize, u64) {
        let slot = disk % Self::PER_WORD;
        ((disk / Self::PER_WORD) as usize, 1 << (2 * slot))
    }

    /// Counts one more contact holding `disk`.
    fn add(&mut self, disk: u32) {
        let (word, held) = Self::word_and_bit(disk);
        let bits = &mut self.words[word];
        *bits |= held | ((*bits & held) << 1);
    }

    /// True when more than one contact holds `disk`.
    fn is_shared(&self, disk: u32) -> bool {
        let (word, held) = Self::word_and_bit(disk);
        self.words[word] & (held << 1) != 0
    }

    /// Forgets `disk`.
    fn remove(&mut self, disk: u32) {
        let (word, held) = Self::word_and_bit(disk);
        self.words[word] &= !(held | (held << 1));
    }

    #[cfg(test)]
    fn is_empty(&self) -> bool {
        self.words.iter().all(|&word| word == 0)
    }
}

/// A set of disks by storage index, one bit each: the disks of a worker's edge strip at
/// the last build, which [`ContactSchedule::split`] pins. Marked once per build, it is
/// read for every disk in a contact: a bit in a small array, not the disk's position at
/// the build in a large one.
#[derive(Clone, Debug, Default)]
pub struct DiskSet {
    words: Vec<u64>,
}

impl DiskSet {
    /// Empties the set, for storage indices below `n_particles`.
    pub fn clear(&mut self, n_particles: usize) {
        self.words.clear();
        self.words.resize(n_particles.div_ceil(64), 0);
    }

    pub fn insert(&mut self, disk: u32) {
        self.words[disk as usize / 64] |= 1 << (disk % 64);
    }

    pub fn contains(&self, disk: u32) -> bool {
        self.words[disk as usize / 64] & (1 << (disk % 64)) != 0
    }
}

impl ResolutionOrder {
    /// Orders `contacts` (whole chains, as found, possibly with a pair twice) for
    /// resolution with the canonical bits: first the pairs that share no disk with
    /// another, in the order found, then the others in canonical order ([`Contact::key`])
    /// with repeats removed. The lists find pairs in storage order, so the first part
    /// reads nearby memory; canonical order alone reads disks in random places. `ids`
    /// holds the disks' ids by storage index; only the chained pairs' are read.
    pub fn arrange(&mut self, ids: &[u32], contacts: &mut Vec<Contact>) {
        let mut chained = self.set_apart_chained(ids.len(), contacts);
        self.append_in_canonical_order(ids, contacts, &mut chained);
        self.chained = chained;
    }

    /// Moves the pairs that share a disk with another out of `contacts` (which keeps the
    /// lone pairs, in order) into the returned scratch vector, in order. Leaves the
    /// holdings empty.
    fn set_apart_chained(
        &mut self,
        n_particles: usize,
        contacts: &mut Vec<Contact>,
    ) -> Vec<Contact> {
        let holdings = &mut self.holdings;
        holdings.cover(n_particles);
        for contact in contacts.iter() {
            holdings.add(contact.a);
            holdings.add(contact.b);
        }
        let mut chained = std::mem::take(&mut self.chained);
        chained.clear();
        contacts.retain(|contact| {
            let alone = !holdings.is_shared(contact.a) && !holdings.is_shared(contact.b);
            if !alone {
                chained.push(*contact);
            }
            alone
        });
        for contact in contacts.iter().chain(&chained) {
            holdings.remove(contact.a);
            holdings.remove(contact.b);
        }
        chained
    }

    /// Appends `chained` to `contacts` in canonical order, a pair found twice once.
    fn append_in_canonical_order(
        &mut self,
        ids: &[u32],
        contacts: &mut Vec<Contact>,
        chained: &mut Vec<Contact>,
    ) {
        order_canonically(chained, ids, &mut self.keyed);
        contacts.extend_from_slice(chained);
    }
}

impl ContactSchedule {
    /// Keeps in `contacts` the chains with no `pinned` disk (by storage index), in
    /// resolution order ([`ResolutionOrder::arrange`], by the ids `ids`), and appends the
    /// others to `handed_over`.
    ///
    /// A lone pair (no disk shared with another pair) is a chain of its own, decided by
    /// its two disks; only the pairs that share disks, a small part of a step's, go
    /// through the union–find.
    pub fn split(
        &mut self,
        ids: &[u32],
        contacts: &mut Vec<Contact>,
        handed_over: &mut Vec<Contact>,
        pinned: impl Fn(u32) -> bool,
    ) {
        let n_particles = ids.len();
        let mut chained = self.order.set_apart_chained(n_particles, contacts);
        contacts.retain(|contact| {
            let keep = !pinned(contact.a) && !pinned(contact.b);
            if !keep {
                handed_over.push(*contact);
            }
            keep
        });
        self.split_chained(n_particles, &mut chained, handed_over, &pinned);
        self.order
            .append_in_canonical_order(ids, contacts, &mut chained);
        self.order.chained = chained;
    }

    /// Keeps in `chained` those of the chains with no `pinned` disk, in the same order,
    /// and appends the others to `handed_over`, in the same order: a union–find over the
    /// disks of these contacts only.
    fn split_chained(
        &mut self,
        n_particles: usize,
        chained: &mut Vec<Contact>,
        handed_over: &mut Vec<Contact>,
        pinned: impl Fn(u32) -> bool,
    ) {
        if self.parent.len() < n_particles {
            // Fresh zeroed memory, never written as a whole: a page is mapped when a
            // chained disk's entry on it is first written. A resize wrote every entry,
            // 5 bytes a disk for each worker (a rayon band's covers all the disks), in
            // the first step: rayon on 2 threads at 10⁷ disks peaked at 875,116 kB instead
            // of 834,792 (20 steps). With a spare share, as a rank's count grows.
            let len = n_particles + n_particles / SPARE_SHARE;
            self.parent = vec![0; len];
            self.pinned = vec![false; len];
        }
        for contact in chained.iter() {
            for disk in [contact.a, contact.b] {
                self.parent[disk as usize] = disk;
                self.pinned[disk as usize] = pinned(disk);
            }
        }
        for contact in chained.iter() {
            let root_a = self.root_halving(contact.a);
            let root_b = self.root_halving(contact.b);
            self.parent[root_b as usize] = root_a;
            self.pinned[root_a as usize] |= self.pinned[root_b as usize];
        }
        chained.retain(|contact| {
            let keep = !self.pinned[self.root(contact.a) as usize];
            if !keep {
                handed_over.push(*contact);
            }
            keep
        });
    }

    /// The representative of a disk's chain, halving the path on the way up.
    fn root_halving(&mut self, mut disk: u32) -> u32 {
        while self.parent[disk as usize] != disk {
            let grandparent = self.parent[self.parent[disk as usize] as usize];
            self.parent[disk as usize] = grandparent;
            disk = grandparent;
        }
        disk
    }

    /// The representative of a disk's chain.
    fn root(&self, mut disk: u32) -> u32 {
        while self.parent[disk as usize] != disk {
            disk = self.parent[disk as usize];
        }
        disk
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn contact(a: u32, b: u32) -> Contact {
        Contact { a, b }
    }

    /// Ids equal to the storage indices below `n`.
    fn ids(n: u32) -> Vec<u32> {
        (0..n).collect()
    }

    #[test]
    fn a_disk_set_holds_what_was_inserted_until_cleared() {
        let mut set = DiskSet::default();
        set.clear(130);
        for disk in [0, 63, 64, 129] {
            set.insert(disk);
        }
        let held: Vec<u32> = (0..130).filter(|&disk| set.contains(disk)).collect();
        assert_eq!(held, vec![0, 63, 64, 129]);
        set.clear(130);
        assert!((0..130).all(|disk| !set.contains(disk)));
    }

    #[test]
    fn chains_with_a_pinned_disk_are_handed_over_whole_and_the_rest_stay() {
        // 0–1 is a chain of its own; 2–3, 3–4 and 5–4 form one chain, pinned through 5.
        let mut contacts = vec![contact(0, 1), contact(2, 3), contact(3, 4), contact(5, 4)];
        let mut handed_over = Vec::new();
        ContactSchedule::default().split(&ids(6), &mut contacts, &mut handed_over, |d| d == 5);
        assert_eq!(contacts, vec![contact(0, 1)]);
        assert_eq!(
            handed_over,
            vec![contact(2, 3), contact(3, 4), contact(5, 4)]
        );
    }

    /// Against a reference that labels every chain by a flood over all contacts: the
    /// kept pairs are those of the chains without a pinned disk, in resolution order
    /// (as `arrange` orders them), and every other pair is handed over, once.
    #[test]
    fn a_split_keeps_the_unpinned_chains_in_resolution_order_and_hands_over_the_rest() {
        let mut schedule = ContactSchedule::default();
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = |bound: u32| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % u64::from(bound)) as u32
        };
        for round in 0..200 {
            let n = 6 + next(60);
            let id_of = ids(n);
            let mut contacts: Vec<Contact> = (0..next(40))
                .map(|_| (next(n), next(n)))
                .filter(|(a, b)| a != b)
                .map(|(a, b)| contact(a, b))
                .collect();
            contacts.dedup_by_key(|c| c.key(&id_of));
            let pinned: Vec<bool> = (0..n).map(|_| next(8) == 0).collect();
            // Reference: chain labels by repeated relaxation to the smallest disk.
            let mut label: Vec<u32> = (0..n).collect();
            loop {
                let mut changed = false;
                for c in &contacts {
                    let low = label[c.a as usize].min(label[c.b as usize]);
                    for disk in [c.a, c.b] {
                        changed |= label[disk as usize] != low;
                        label[disk as usize] = low;
                    }
                }
                if !changed {
                    break;
                }
            }
            let chain_pinned = |c: &Contact| {
                (0..n).any(|d| pinned[d as usize] && label[d as usize] == label[c.a as usize])
            };
            let mut expected_kept: Vec<Contact> = contacts
                .iter()
                .copied()
                .filter(|c| !chain_pinned(c))
                .collect();
            ResolutionOrder::default().arrange(&id_of, &mut expected_kept);
            let mut expected_handed: Vec<u64> = contacts
                .iter()
                .filter(|c| chain_pinned(c))
                .map(|c| c.key(&id_of))
                .collect();
            expected_handed.sort_unstable();

            let mut kept = contacts.clone();
            let mut handed_over = Vec::new();
            schedule.split(&id_of, &mut kept, &mut handed_over, |d| pinned[d as usize]);
            let mut handed: Vec<u64> = handed_over.iter().map(|c| c.key(&id_of)).collect();
            handed.sort_unstable();
            assert_eq!(kept, expected_kept, "round {round}");
            assert_eq!(handed, expected_handed, "round {round}");
        }
    }

    #[test]
    fn a_long_chain_pinned_at_its_far_end_is_handed_over_whole() {
        let mut contacts: Vec<Contact> = (0..10).map(|i| contact(i, i + 1)).collect();
        let mut handed_over = Vec::new();
        ContactSchedule::default().split(&ids(11), &mut contacts, &mut handed_over, |d| d == 10);
        assert!(contacts.is_empty());
        assert_eq!(handed_over.len(), 10);
    }

    /// Pairs alone keep the order found; pairs sharing a disk follow in canonical order,
    /// a repeat removed; the scratch is clean for the next step.
    #[test]
    fn lone_pairs_come_first_as_found_and_chains_follow_in_canonical_order() {
        let mut order = ResolutionOrder::default();
        let mut contacts = vec![
            contact(9, 8),
            contact(4, 3),
            contact(7, 6),
            contact(2, 3),
            contact(0, 1),
            contact(7, 6),
        ];
        order.arrange(&ids(10), &mut contacts);
        assert_eq!(
            contacts,
            vec![
                contact(9, 8),
                contact(0, 1),
                contact(2, 3),
                contact(4, 3),
                contact(7, 6)
            ]
        );
        assert!(order.holdings.is_empty());
        let mut next = vec![contact(3, 5), contact(1, 0)];
        order.arrange(&ids(10), &mut next);
        assert_eq!(next, vec![contact(3, 5), contact(1, 0)]);
    }

    /// Disks at the ends of the holdings' words (31, 32, 63, 64) and once, twice or
    /// three times held: only the pairs whose disks no other pair holds stay first.
    #[test]
    fn holdings_tell_shared_disks_apart_across_their_words() {
        let mut order = ResolutionOrder::default();
        let mut contacts = vec![
            contact(31, 32),
            contact(63, 64),
            contact(64, 95),
            contact(64, 30),
            contact(96, 127),
        ];
        order.arrange(&ids(128), &mut contacts);
        assert_eq!(
            contacts,
            vec![
                contact(31, 32),
                contact(96, 127),
                contact(64, 30),
                contact(63, 64),
                contact(64, 95)
            ]
        );
        assert!(order.holdings.is_empty());
    }

    #[test]
    fn scratch_from_an_earlier_step_does_not_leak_into_the_next() {
        let mut schedule = ContactSchedule::default();
        let mut handed_over = Vec::new();
        let mut first = vec![contact(0, 1)];
        schedule.split(&ids(3), &mut first, &mut handed_over, |d| d == 1);
        assert_eq!(handed_over.len(), 1);
        let mut second = vec![contact(1, 2)];
        handed_over.clear();
        schedule.split(&ids(3), &mut second, &mut handed_over, |_| false);
        assert_eq!(second, vec![contact(1, 2)]);
        assert!(handed_over.is_empty());
    }
}
