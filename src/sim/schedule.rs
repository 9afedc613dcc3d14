//! Which contacts a band of workers may resolve on its own: chains of contacts that
//! share disks, found with a union–find over the contacts of one step.
//!
//! The serial reference resolves every contact in canonical order ([`Contact::key`]).
//! Contacts that share no disk commute exactly, so a band may resolve a chain in
//! canonical order on its own whenever it found every contact of that chain; the other
//! chains (those that cross between bands) are resolved afterwards, in canonical
//! order, by one worker. Either way each chain sees its contacts in the serial order,
//! so the result has the serial bits.

use super::grid::Contact;

/// Marks a chain whose contacts were found by more than one band.
const SHARED: u32 = u32::MAX;
/// Marks a disk not yet seen in this step's contacts.
const UNSEEN: u32 = u32::MAX - 1;

/// Scratch memory for splitting contacts by chain: per storage index, the union–find
/// parent and the band that found the chain (valid for disks in this step's contacts).
#[derive(Clone, Debug, Default)]
pub struct ContactSchedule {
    parent: Vec<u32>,
    finder: Vec<u32>,
}

impl ContactSchedule {
    /// Keeps in `found[band]` (each list in canonical order) the contacts of the chains
    /// found entirely by that band, in the same order, and moves every other contact to
    /// `crossing`, in canonical order. `n_particles` bounds the storage indices.
    pub fn split(
        &mut self,
        n_particles: usize,
        found: &mut [Vec<Contact>],
        crossing: &mut Vec<Contact>,
    ) {
        if found.len() < 2 {
            crossing.clear();
            return;
        }
        self.split_pinned(n_particles, found, crossing, |_| false);
    }

    /// [`ContactSchedule::split`], where every chain with a `pinned` disk (by storage
    /// index) also moves to `crossing`: a rank pins the disks other ranks also see.
    pub fn split_pinned(
        &mut self,
        n_particles: usize,
        found: &mut [Vec<Contact>],
        crossing: &mut Vec<Contact>,
        pinned: impl Fn(u32) -> bool,
    ) {
        crossing.clear();
        self.parent.resize(n_particles, 0);
        self.finder.resize(n_particles, UNSEEN);
        // Only the disks in contacts are touched: O(contacts), not O(disks).
        for contact in found.iter().flatten() {
            for disk in [contact.a, contact.b] {
                self.parent[disk as usize] = disk;
                self.finder[disk as usize] = if pinned(disk) { SHARED } else { UNSEEN };
            }
        }
        for (band, contacts) in found.iter().enumerate() {
            for contact in contacts {
                let root_a = self.root_halving(contact.a);
                let root_b = self.root_halving(contact.b);
                let finder = merge_finders(
                    merge_finders(self.finder[root_a as usize], self.finder[root_b as usize]),
                    band as u32,
                );
                self.parent[root_b as usize] = root_a;
                self.finder[root_a as usize] = finder;
            }
        }
        for (band, contacts) in found.iter_mut().enumerate() {
            contacts.retain(|contact| {
                let own = self.finder[self.root(contact.a) as usize] == band as u32;
                if !own {
                    crossing.push(*contact);
                }
                own
            });
        }
        crossing.sort_unstable_by_key(|contact| contact.key);
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

fn merge_finders(a: u32, b: u32) -> u32 {
    match (a, b) {
        (UNSEEN, other) | (other, UNSEEN) => other,
        (a, b) if a == b => a,
        _ => SHARED,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn contact(a: u32, b: u32) -> Contact {
        Contact {
            key: (u64::from(a.min(b)) << 32) | u64::from(a.max(b)),
            a,
            b,
        }
    }

    #[test]
    fn chains_within_one_band_stay_and_chains_across_bands_move_in_canonical_order() {
        // Band 0: 0–1, 1–2 (a chain of its own) and 5–6; band 1: 3–4 (its own) and 6–7,
        // which joins 5–6 into a chain found by both bands.
        let mut found = vec![
            vec![contact(0, 1), contact(1, 2), contact(5, 6)],
            vec![contact(3, 4), contact(6, 7)],
        ];
        let mut crossing = Vec::new();
        ContactSchedule::default().split(8, &mut found, &mut crossing);
        assert_eq!(found[0], vec![contact(0, 1), contact(1, 2)]);
        assert_eq!(found[1], vec![contact(3, 4)]);
        assert_eq!(crossing, vec![contact(5, 6), contact(6, 7)]);
    }

    #[test]
    fn chains_with_a_pinned_disk_move_and_the_rest_stay() {
        let mut found = vec![vec![contact(0, 1), contact(2, 3), contact(3, 4)]];
        let mut crossing = Vec::new();
        ContactSchedule::default().split_pinned(5, &mut found, &mut crossing, |d| d == 4);
        assert_eq!(found[0], vec![contact(0, 1)]);
        assert_eq!(crossing, vec![contact(2, 3), contact(3, 4)]);
    }

    #[test]
    fn a_long_chain_touching_another_band_at_its_far_end_moves_whole() {
        let mut found = vec![
            (0..10).map(|i| contact(i, i + 1)).collect::<Vec<_>>(),
            vec![contact(20, 10)],
        ];
        let mut crossing = Vec::new();
        ContactSchedule::default().split(21, &mut found, &mut crossing);
        assert!(found.iter().all(Vec::is_empty));
        assert_eq!(crossing.len(), 11);
        assert!(crossing.is_sorted_by_key(|c| c.key));
    }
}
