//! Chains of contacts that cross a slab's edge, resolved by the ranks that hold them:
//! each rank sends its shared contacts to its peers, and resolves, in canonical order,
//! every chain of its own disks that its own and its peers' contacts close.
//!
//! A chain is closed at a rank when every rank that may have found one of its contacts
//! sent its contacts there. Another rank finds a contact of a disk only when it sees the
//! disk: as a ghost (the owner exported it to the rank below) or as a reported escapee
//! (the owner reported it to its peers). So a disk's possible finders are its owner, the
//! rank it was exported to if it was, and, if it was reported, the owners of the strips
//! its query may read (every rank works them out alike from the disk's record); a chain
//! whose disks' finders are all this rank or its peers holds every contact of the
//! serial run's chain, and resolving it in canonical order gives the serial bits. A
//! chain that reaches further (a pile across several slabs) is open: the ranks then fall
//! back to gathering every shared contact on every rank.

use std::collections::HashMap;
use std::ops::Range;

use crate::sim::grid::{Contact, order_canonically};
use crate::sim::particles::PACKED_LEN;
use crate::sim::resolve::resolve_contacts;
use crate::sim::{Domain, Particles, Physics, StepCounters};

/// Values per disk of a shared contact sent to the peers: the packed disk
/// ([`Particles::pack`]), its owner rank, and how other ranks saw it ([`Seen`] bits).
pub const SHARED_DISK_LEN: usize = PACKED_LEN + 2;

/// How ranks other than its owner saw a disk this step.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Seen {
    /// In the owner's first strip at the last build: the rank below holds it as a ghost.
    pub exported: bool,
    /// Reported as an escapee to the owner's peers.
    pub reported: bool,
}

impl Seen {
    fn bits(self) -> f64 {
        f64::from(u8::from(self.exported) | u8::from(self.reported) << 1)
    }

    fn of_bits(bits: f64) -> Seen {
        let bits = bits as u8;
        Seen {
            exported: bits & 1 != 0,
            reported: bits & 2 != 0,
        }
    }

    fn merge(self, other: Seen) -> Seen {
        Seen {
            exported: self.exported || other.exported,
            reported: self.reported || other.reported,
        }
    }
}

/// Appends disk `idx` of `particles` to a shared-contact buffer.
pub fn pack_shared_disk(
    particles: &Particles,
    idx: usize,
    owner: usize,
    seen: Seen,
    out: &mut Vec<f64>,
) {
    particles.pack(idx, out);
    out.push(owner as f64);
    out.push(seen.bits());
}

/// Which ranks may see whose disks: this rank's peers, and the rank every rank's
/// first strip goes to as ghosts, from the slabs every rank knows.
#[derive(Debug)]
pub struct Neighbourhood {
    me: usize,
    peers: Vec<usize>,
    export_to: Vec<Option<usize>>,
}

impl Neighbourhood {
    /// `slabs[r]`: the strips of rank r; `owner[s]`: the rank of strip s; `peers`: this
    /// rank's peers (mutual, in rank order, never `me`).
    pub fn new(
        slabs: &[Range<usize>],
        owner: &[usize],
        periodic: bool,
        me: usize,
        peers: Vec<usize>,
    ) -> Neighbourhood {
        let export_to = (slabs.iter().enumerate())
            .map(|(rank, slab)| {
                let below = match slab.start {
                    0 if periodic => owner.len() - 1,
                    0 => return None,
                    start => start - 1,
                };
                Some(owner[below]).filter(|&owner| owner != rank)
            })
            .collect();
        Neighbourhood {
            me,
            peers,
            export_to,
        }
    }

    /// This rank.
    pub fn rank(&self) -> usize {
        self.me
    }

    /// This rank's peers.
    pub fn peers(&self) -> &[usize] {
        &self.peers
    }

    /// The rank this rank's first strip goes to as ghosts.
    pub fn export_to(&self) -> Option<usize> {
        self.export_to[self.me]
    }

    /// True when this rank or a peer.
    pub fn is_near(&self, rank: usize) -> bool {
        rank == self.me || self.peers().binary_search(&rank).is_ok()
    }

    /// True when every rank that may have found a contact of a disk of `owner`, seen as
    /// `seen`, is this rank or one of its peers; `query_is_near` says it of the ranks
    /// whose strips the disk's query read, if it was reported.
    fn closes(&self, owner: usize, seen: Seen, query_is_near: impl FnOnce() -> bool) -> bool {
        self.is_near(owner)
            && (!seen.exported || self.export_to[owner].is_none_or(|to| self.is_near(to)))
            && (!seen.reported || query_is_near())
    }
}

/// The shared contacts of this rank and its peers, as one set of disks (each once, by
/// id) and the pairs between them.
struct Gathered {
    disks: Particles,
    owner: Vec<usize>,
    seen: Vec<Seen>,
    contacts: Vec<Contact>,
}

impl Gathered {
    fn of(buffers: &[&[f64]]) -> Gathered {
        let mut gathered = Gathered {
            disks: Particles::default(),
            owner: Vec::new(),
            seen: Vec::new(),
            contacts: Vec::new(),
        };
        let mut slot_of: HashMap<u32, usize> = HashMap::new();
        for buffer in buffers {
            for pair in buffer.chunks_exact(2 * SHARED_DISK_LEN) {
                let (a, b) = pair.split_at(SHARED_DISK_LEN);
                let [slot_a, slot_b] = [a, b].map(|record| {
                    let (packed, about) = record.split_at(PACKED_LEN);
                    let seen = Seen::of_bits(about[1]);
                    let slot = *slot_of.entry(packed[0] as u32).or_insert_with(|| {
                        gathered.disks.unpack_append(packed);
                        gathered.owner.push(about[0] as usize);
                        gathered.seen.push(Seen::default());
                        gathered.disks.len() - 1
                    });
                    gathered.seen[slot] = gathered.seen[slot].merge(seen);
                    slot
                });
                gathered.contacts.push(Contact::new(slot_a, slot_b));
            }
        }
        gathered
    }

    /// The chain of every disk, as the smallest slot in it.
    fn chains(&self) -> Vec<usize> {
        let mut parent: Vec<usize> = (0..self.disks.len()).collect();
        fn root(parent: &mut [usize], mut slot: usize) -> usize {
            while parent[slot] != slot {
                parent[slot] = parent[parent[slot]];
                slot = parent[slot];
            }
            slot
        }
        for contact in &self.contacts {
            let (a, b) = (
                root(&mut parent, contact.a as usize),
                root(&mut parent, contact.b as usize),
            );
            parent[a.max(b)] = a.min(b);
        }
        (0..parent.len())
            .map(|slot| root(&mut parent, slot))
            .collect()
    }
}

/// The outcome of a rank's closed shared chains, to apply once every rank's chains are
/// known to be closed.
#[derive(Debug, Default)]
pub struct Resolution {
    /// The new position and velocity (x, y, vx, vy) of own disks, by storage index.
    pub updates: Vec<(usize, [f64; 4])>,
    /// What the chains this rank counts did.
    pub counters: StepCounters,
}

impl Resolution {
    pub fn apply(&self, particles: &mut Particles) {
        for &(idx, [x, y, vx, vy]) in &self.updates {
            particles.x[idx] = x;
            particles.y[idx] = y;
            particles.vx[idx] = vx;
            particles.vy[idx] = vy;
        }
    }
}

/// The disks and rule of one rank's resolution of its shared chains.
pub struct SharedChains<'a, Q> {
    pub hood: &'a Neighbourhood,
    /// Whether the query of a reported escapee at height y of radius r read only strips
    /// of this rank and its peers, called with (y, r).
    pub query_is_near: Q,
    pub domain: &'a Domain,
    pub physics: &'a Physics,
    pub dt: f64,
}

impl<Q: Fn(f64, f64) -> bool> SharedChains<'_, Q> {
    /// Resolves, in canonical order, every chain that holds an own disk in the shared
    /// contacts of `buffers` (this rank's and its peers', of [`pack_shared_disk`]
    /// records in pairs), when all of them are closed; `None` when one is open. The
    /// own disks are found at `own_slot[id]`. A chain is counted by the rank owning its
    /// smallest id only, so that the ranks' sum counts it once.
    pub fn resolve_closed_chains(
        &self,
        buffers: &[&[f64]],
        own_slot: &HashMap<u32, usize>,
    ) -> Option<Resolution> {
        let me = self.hood.me;
        let mut gathered = Gathered::of(buffers);
        let chain = gathered.chains();
        let n_slots = gathered.disks.len();
        let (mut has_own, mut closed) = (vec![false; n_slots], vec![true; n_slots]);
        let mut counted_by = vec![(u32::MAX, 0); n_slots];
        for (slot, &root) in chain.iter().enumerate() {
            let (owner, id) = (gathered.owner[slot], gathered.disks.id[slot]);
            has_own[root] |= owner == me;
            let disks = &gathered.disks;
            let query_is_near = || (self.query_is_near)(disks.y[slot], disks.radius[slot]);
            closed[root] &= self.hood.closes(owner, gathered.seen[slot], query_is_near);
            counted_by[root] = counted_by[root].min((id, owner));
        }
        if (0..n_slots).any(|root| has_own[root] && !closed[root]) {
            return None;
        }
        let (mut counted, mut uncounted): (Vec<Contact>, Vec<Contact>) = (gathered.contacts)
            .iter()
            .filter(|contact| has_own[chain[contact.a as usize]])
            .partition(|contact| counted_by[chain[contact.a as usize]].1 == me);
        let mut resolution = Resolution::default();
        self.resolve_in_order(&mut gathered.disks, &mut counted, &mut resolution.counters);
        self.resolve_in_order(
            &mut gathered.disks,
            &mut uncounted,
            &mut StepCounters::default(),
        );
        resolution.updates = own_updates(&gathered.disks, own_slot);
        Some(resolution)
    }

    /// Resolves every chain of `buffers` (all ranks' shared contacts, the same on every
    /// rank) in canonical order, counting them all: what the ranks do together when a
    /// chain reaches past the peers.
    pub fn resolve_all_chains(
        &self,
        buffers: &[&[f64]],
        own_slot: &HashMap<u32, usize>,
    ) -> Resolution {
        let mut gathered = Gathered::of(buffers);
        let mut resolution = Resolution::default();
        let contacts = &mut gathered.contacts;
        self.resolve_in_order(&mut gathered.disks, contacts, &mut resolution.counters);
        resolution.updates = own_updates(&gathered.disks, own_slot);
        resolution
    }

    /// Resolves `contacts` (whole chains) among `disks` in canonical order, a pair found
    /// twice once.
    fn resolve_in_order(
        &self,
        disks: &mut Particles,
        contacts: &mut Vec<Contact>,
        counters: &mut StepCounters,
    ) {
        order_canonically(contacts, &disks.id, &mut Vec::new());
        resolve_contacts(
            disks,
            self.domain,
            self.physics,
            self.dt,
            contacts,
            counters,
            |_| {},
        );
    }
}

/// The new states of the own disks among `disks`, found at `own_slot[id]`.
fn own_updates(disks: &Particles, own_slot: &HashMap<u32, usize>) -> Vec<(usize, [f64; 4])> {
    (disks.id.iter().enumerate())
        .filter_map(|(slot, id)| {
            let state = [disks.x[slot], disks.y[slot], disks.vx[slot], disks.vy[slot]];
            own_slot.get(id).map(|&idx| (idx, state))
        })
        .collect()
}
