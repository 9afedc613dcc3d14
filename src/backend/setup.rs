//! A distributed run's set-up: each rank places only its bands of a seeded gas
//! (`sim::place`), the ranks merge the exact sums set-up reads, and every disk goes to
//! the rank whose slab holds it. No rank holds more than its share of the disks, plus
//! the edges of the bands beside its own.
//!
//! A scene of listed disks, or a run whose method or dt is chosen by pilots on the whole
//! scene, is built whole on every rank instead, and each rank keeps a share of it.

use std::collections::BTreeMap;
use std::ops::Range;

use crate::backend::BackendError;
use crate::backend::comm::Communicator;
use crate::run::spec::{PreparedRun, RunSpec, SceneSource};
use crate::sim::exact_sum::{EXACT_SUM_WORDS, ExactSum};
use crate::sim::grid::StripLayout;
use crate::sim::neighbours::Skin;
use crate::sim::observe::SceneSums;
use crate::sim::particles::{PACKED_LEN, SPARE_SHARE};
use crate::sim::place::{Edges, GasPlan};
use crate::sim::scene::{GasSpec, PlacementError};
use crate::sim::{Particles, Scene};

/// A rank's start: the prepared run (its scene holding no disks), this rank's disks,
/// all in its slab, the sums over the whole scene's initial disks, the strips and the
/// slabs, and the most disks the rank held on the way.
pub struct RankStart {
    pub prepared: PreparedRun,
    pub own: Particles,
    pub whole: SceneSums,
    pub skin: Skin,
    pub layout: StripLayout,
    pub slabs: Vec<Range<usize>>,
    pub most_held: usize,
}

/// Builds the initial disks on the ranks together (all ranks call this together).
pub fn start<C: Communicator>(comm: &C, spec: &RunSpec) -> Result<RankStart, BackendError> {
    let (prepared, placed, whole) = match &spec.scene {
        SceneSource::Gas(gas) if spec.may_prepare_in_parts() => {
            let (scene, placed) = place_own(comm, gas)?;
            let whole = merged_sums(comm, &placed, scene.physics.gravity);
            let scene = Scene {
                particles: Particles::default(),
                ..scene
            };
            (spec.prepare_from(scene, &whole)?, placed, whole)
        }
        _ => {
            let mut prepared = spec.prepare()?;
            let all = prepared.take_particles();
            let share = share_of(&all, comm.rank(), comm.size());
            drop(all);
            let whole = merged_sums(comm, &share, prepared.scene.physics.gravity);
            (prepared, share, whole)
        }
    };
    let scene = &prepared.scene;
    let figures = whole.figures();
    let skin = Skin::for_figures(&scene.domain, &figures, prepared.params.dt);
    let layout = StripLayout::for_figures(&scene.domain, &figures, skin.width());
    let per_strip = strip_counts(comm, &layout, &placed);
    let n_strips = layout.n_strips;
    if n_strips < comm.size() {
        return Err(BackendError::Mpi(format!(
            "the box is {n_strips} strips (one contact diameter each) tall, fewer than the \
             {} ranks asked for; use at most {n_strips} ranks or a taller box",
            comm.size()
        )));
    }
    let slabs = cut_slabs(&per_strip, comm.size());
    let most_placed = placed.len();
    let own = to_slabs(comm, placed, &layout, &slabs);
    let most_held = most_placed.max(own.len());
    Ok(RankStart {
        prepared,
        own,
        whole,
        skin,
        layout,
        slabs,
        most_held,
    })
}

/// The disks stored from `rank`·N/P to (`rank` + 1)·N/P: a rank's share of a scene
/// every rank built whole.
fn share_of(all: &Particles, rank: usize, n_ranks: usize) -> Particles {
    let n = all.len();
    let mut packed = Vec::new();
    for idx in n * rank / n_ranks..n * (rank + 1) / n_ranks {
        all.pack(idx, &mut packed);
    }
    let mut share = Particles::default();
    share.unpack_append(&packed);
    share
}

/// This rank's bands of `gas`, placed with the other ranks': the box (no disks) and the
/// disks placed here, their velocities normalised over the whole gas.
fn place_own<C: Communicator>(comm: &C, gas: &GasSpec) -> Result<(Scene, Particles), BackendError> {
    let (me, n_ranks) = (comm.rank(), comm.size());
    let blocks = gas.radius_blocks();
    let area = gas.area_of_blocks(blocks * me / n_ranks..blocks * (me + 1) / n_ranks);
    let area = merged(comm, vec![area])[0].value();
    let plan = gas.plan(area)?;
    let owner = |band: usize| band_owner(&plan, band, n_ranks);
    let bands = (0..plan.n_bands()).filter(|&band| owner(band) == me);
    let bands = match (bands.clone().min(), bands.max()) {
        (Some(first), Some(last)) => first..last + 1,
        _ => 0..0,
    };
    let placed = plan.place(bands.clone(), &mut |edges| {
        swap_edges(comm, &plan, &bands, &owner, edges)
    });
    // A band that jammed jams the run on every rank, with the first failure's words.
    let failure = match &placed {
        Err(PlacementError::Jammed {
            placed, packing, ..
        }) => vec![1.0, *placed as f64, *packing],
        _ => vec![0.0, 0.0, 0.0],
    };
    let failures = comm.all_gather(&failure);
    if let Some(first) = failures.iter().find(|failure| failure[0] > 0.0) {
        return Err(PlacementError::Jammed {
            placed: first[1] as usize,
            n_particles: gas.n_particles,
            packing: first[2],
        }
        .into());
    }
    let mut particles = plan.particles(placed?);
    plan.set_velocities(&mut particles, &mut |local| merged(comm, local));
    let scene = Scene {
        domain: plan.domain,
        physics: gas.physics,
        particles: Particles::default(),
    };
    Ok((scene, particles))
}

/// The rank that places `band`: the one whose share of the disks holds the band's
/// middle disk, so that the ranks' bands run in order and hold about N/P disks each
/// (ranks may place none when there are fewer bands than ranks).
fn band_owner(plan: &GasPlan, band: usize, n_ranks: usize) -> usize {
    let n = plan.n_particles().max(1) as u128;
    let middle = 2 * plan.first_index(band) as u128 + plan.count(band) as u128;
    ((middle * n_ranks as u128 / (2 * n)) as usize).min(n_ranks - 1)
}

/// Sends the edges of this rank's first and last band to the ranks placing the bands
/// beside them and returns theirs (nothing when this rank places no band).
fn swap_edges<C: Communicator>(
    comm: &C,
    plan: &GasPlan,
    bands: &Range<usize>,
    owner: &dyn Fn(usize) -> usize,
    edges: Edges,
) -> Edges {
    if bands.is_empty() {
        return Edges::new();
    }
    let me = comm.rank();
    // A band's bottom edge (side 0) is for the band below, its top edge for the one above.
    let mut outgoing: BTreeMap<usize, Vec<f64>> = BTreeMap::new();
    for (band, side, disks) in edges {
        let Some(beside) = plan.neighbours(band)[side] else {
            continue;
        };
        if bands.contains(&beside) {
            continue;
        }
        let message = outgoing.entry(owner(beside)).or_default();
        message.extend([band as f64, side as f64, disks.len() as f64]);
        message.extend(disks.iter().flatten());
    }
    let mut from: Vec<usize> = [
        plan.neighbours(bands.start)[0],
        plan.neighbours(bands.end - 1)[1],
    ]
    .into_iter()
    .flatten()
    .filter(|beside| !bands.contains(beside))
    .map(owner)
    .filter(|&rank| rank != me)
    .collect();
    from.sort_unstable();
    from.dedup();
    let sends: Vec<(usize, &[f64])> = (outgoing.iter())
        .filter(|(rank, _)| **rank != me)
        .map(|(&rank, message)| (rank, message.as_slice()))
        .collect();
    let mut received = Edges::new();
    for message in comm.send_receive(&sends, &from) {
        let mut rest = message.as_slice();
        while let [band, side, n, tail @ ..] = rest {
            let n = *n as usize;
            let disks = tail[..3 * n]
                .chunks_exact(3)
                .map(|disk| [disk[0], disk[1], disk[2]])
                .collect();
            received.push((*band as usize, *side as usize, disks));
            rest = &tail[3 * n..];
        }
    }
    received
}

/// The merge, on every rank, of every rank's `local` sums (all ranks pass as many).
fn merged<C: Communicator>(comm: &C, local: Vec<ExactSum>) -> Vec<ExactSum> {
    let words: Vec<f64> = local.iter().flat_map(ExactSum::to_words).collect();
    let mut sums = vec![ExactSum::default(); local.len()];
    for theirs in comm.all_gather(&words) {
        for (k, sum) in sums.iter_mut().enumerate() {
            sum.merge(&ExactSum::from_words(&theirs[k * EXACT_SUM_WORDS..]));
        }
    }
    sums
}

/// The [`SceneSums`] of every rank's disks, merged, on every rank.
fn merged_sums<C: Communicator>(comm: &C, own: &Particles, gravity: Option<[f64; 2]>) -> SceneSums {
    let mut whole = SceneSums::default();
    for theirs in comm.all_gather(&SceneSums::of(own, gravity).to_words()) {
        whole.merge(&SceneSums::from_words(&theirs));
    }
    whole
}

/// The disks in each strip, over all ranks: each rank sends the counts of the strips
/// its disks lie in, from the lowest to the highest (a run of strips, as its disks lie
/// in a run of bands).
fn strip_counts<C: Communicator>(comm: &C, layout: &StripLayout, own: &Particles) -> Vec<usize> {
    let strips: Vec<usize> = own.y.iter().map(|&y| layout.strip_of(y)).collect();
    let mut mine = Vec::new();
    if let (Some(&low), Some(&high)) = (strips.iter().min(), strips.iter().max()) {
        mine = vec![0.0; high - low + 2];
        mine[0] = low as f64;
        for strip in strips {
            mine[strip - low + 1] += 1.0;
        }
    }
    let mut per_strip = vec![0; layout.n_strips];
    for theirs in comm.all_gather(&mine) {
        if let [low, counts @ ..] = theirs.as_slice() {
            for (k, &count) in counts.iter().enumerate() {
                per_strip[*low as usize + k] += count as usize;
            }
        }
    }
    per_strip
}

/// Cuts strips holding `per_strip` disks each into `n_ranks` slabs of whole strips (at
/// least one each, so `n_ranks` ≤ the strips), each slab ending where the disks before
/// it first reach their share of the total.
pub(crate) fn cut_slabs(per_strip: &[usize], n_ranks: usize) -> Vec<Range<usize>> {
    let n_strips = per_strip.len();
    let total: usize = per_strip.iter().sum();
    let mut slabs = Vec::with_capacity(n_ranks);
    let (mut start, mut count) = (0, 0);
    for rank in 0..n_ranks - 1 {
        let share = total * (rank + 1) / n_ranks;
        // Leave at least one strip for each rank still to come.
        let last_end = n_strips - (n_ranks - rank - 1);
        let mut end = start + 1;
        count += per_strip[start];
        while end < last_end && count < share {
            count += per_strip[end];
            end += 1;
        }
        slabs.push(start..end);
        start = end;
    }
    slabs.push(start..n_strips);
    slabs
}

/// Sends every disk to the rank whose slab holds it and returns this rank's. Only the
/// disks that leave are copied: most stay, as a rank's bands lie about where its slab is.
fn to_slabs<C: Communicator>(
    comm: &C,
    mut placed: Particles,
    layout: &StripLayout,
    slabs: &[Range<usize>],
) -> Particles {
    let (me, owner) = (comm.rank(), owners(slabs, layout.n_strips));
    let mut outgoing = vec![Vec::new(); comm.size()];
    let mut leaving = Vec::new();
    for idx in 0..placed.len() {
        let to = owner[layout.strip_of(placed.y[idx])];
        if to != me {
            placed.pack(idx, &mut outgoing[to]);
            leaving.push(idx);
        }
    }
    // Highest first, so that the disk moved into a freed slot never is one leaving.
    for &idx in leaving.iter().rev() {
        placed.swap_remove(idx);
    }
    let arrived = comm.exchange(&outgoing);
    drop(outgoing);
    let incoming: usize = arrived.iter().map(|packed| packed.len() / PACKED_LEN).sum();
    let n_own = placed.len() + incoming;
    placed.reserve_exact(incoming + n_own / SPARE_SHARE);
    for packed in &arrived {
        placed.unpack_append(packed);
    }
    placed
}

/// The rank that owns each of `n_strips` strips cut into `slabs`.
pub(crate) fn owners(slabs: &[Range<usize>], n_strips: usize) -> Vec<usize> {
    let mut owner = vec![0; n_strips];
    for (rank, strips) in slabs.iter().enumerate() {
        owner[strips.clone()].fill(rank);
    }
    owner
}
