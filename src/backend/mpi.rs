//! MPI through rsmpi (feature `mpi`): the [`Communicator`] of the distributed backend,
//! one rank's run when collide was started by `mpirun`, and the ping-pong of `collide
//! calibrate --network` (its fit is `cluster::network`'s).

use std::num::NonZeroUsize;

use mpi::Count;
use mpi::collective::SystemOperation;
use mpi::datatype::{Partition, PartitionMut};
use mpi::request::WaitGuard;
use mpi::topology::SimpleCommunicator;
use mpi::traits::{Communicator as _, CommunicatorCollectives, Destination, Source};

use crate::backend::comm::{COUNT_BYTES, Communicator};
use crate::backend::distributed::{self, FinalState};
use crate::backend::{BackendError, RunOutcome};
use crate::cluster::network::{Measured, SIZES, Sample};
use crate::run::spec::RunSpec;

/// True when this process is a rank started by an MPI launcher (OpenMPI, MPICH, PMIx).
pub fn launched_by_mpi() -> bool {
    ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK"]
        .iter()
        .any(|name| std::env::var_os(name).is_some())
}

/// Runs `spec` as one rank of the MPI world, stepping on `threads` threads. `ranks`,
/// when given, must be the world size. Returns the outcome on rank 0 (with the whole
/// final state if `final_state` asks for it) and `None` on the others.
pub fn run_rank(
    spec: &RunSpec,
    ranks: Option<usize>,
    final_state: FinalState,
    threads: Option<NonZeroUsize>,
) -> Result<Option<RunOutcome>, BackendError> {
    // A rank's threads step its slab; only this thread, the one that starts MPI, calls
    // it (`distributed::run`). The level MPI grants is what any OpenMPI or MPICH build
    // gives at least, and asking for it is what the standard requires of such a rank.
    let (universe, granted) = mpi::initialize_with_threading(mpi::Threading::Funneled)
        .ok_or_else(|| BackendError::Mpi("MPI was already initialised in this process".into()))?;
    let comm = MpiComm {
        world: universe.world(),
    };
    let threads = match (threads, granted) {
        (Some(threads), mpi::Threading::Single) if threads.get() > 1 => {
            return Err(BackendError::Mpi(format!(
                "this MPI library allows one thread per process (MPI_THREAD_SINGLE), and \
                 --threads asks for {threads}; drop --threads or use an MPI built with \
                 thread support"
            )));
        }
        (Some(threads), _) => threads,
        (None, mpi::Threading::Single) => NonZeroUsize::MIN,
        (None, _) => share_of_cpus(&comm),
    };
    // Where the rank may run goes to the launching process.
    eprintln!(
        "{}",
        crate::cluster::placement::rank_line(comm.rank(), threads.get())
    );
    if let Some(asked) = ranks
        && asked != comm.size()
    {
        return Err(BackendError::Mpi(format!(
            "--ranks {asked} but mpirun started {} ranks; drop --ranks or make them agree",
            comm.size()
        )));
    }
    distributed::run(&comm, spec, final_state, threads)
}

/// The threads of a rank told no count: the CPUs its mask allows (what the launcher
/// bound it to: one core, `PE=T` cores, a socket, or the whole node), but no more than
/// its even share of the node's CPUs among the ranks on the node, so that ranks that
/// share a mask (a socket, or no binding) do not take the same CPUs; at least one.
fn share_of_cpus(comm: &MpiComm) -> NonZeroUsize {
    let on_node = comm.world.split_shared(comm.world.rank()).size().max(1) as usize;
    let mask = std::thread::available_parallelism().map_or(1, NonZeroUsize::get);
    let share = crate::system::machine::machine_cores() / on_node;
    NonZeroUsize::new(mask.min(share)).unwrap_or(NonZeroUsize::MIN)
}

/// Timed blocks of each size; a size's time is their median (robust to the other
/// jobs of a shared machine).
const BLOCKS: usize = 5;

/// Round trips of `bytes` in one timed block: about 2²⁴ bytes each way, 4 to 400.
fn trips(bytes: usize) -> usize {
    ((1 << 24) / bytes / BLOCKS).clamp(4, 400)
}

/// As one of exactly 2 ranks: a ping-pong of each of [`SIZES`] and a small all-reduce
/// (3 values, as the distributed step's), each timed in [`BLOCKS`] blocks after a
/// warm-up. Returns what was measured on rank 0, `None` on rank 1.
pub fn measure_network() -> Result<Option<Measured>, BackendError> {
    let universe = mpi::initialize()
        .ok_or_else(|| BackendError::Mpi("MPI was already initialised in this process".into()))?;
    let world = universe.world();
    if world.size() != 2 {
        return Err(BackendError::Mpi(format!(
            "the network's ping-pong runs on 2 ranks, and the launcher started {}",
            world.size()
        )));
    }
    let rank = world.rank();
    let other = world.process_at_rank(1 - rank);
    // The median of the blocks' seconds per call of `round`, after one block of warm-up.
    let time = |calls: usize, round: &mut dyn FnMut()| {
        let mut blocks: Vec<f64> = (0..=BLOCKS)
            .map(|_| {
                world.barrier();
                let start = std::time::Instant::now();
                (0..calls).for_each(|_| round());
                start.elapsed().as_secs_f64() / calls as f64
            })
            .skip(1)
            .collect();
        crate::stats::median(&mut blocks)
    };
    let samples = SIZES
        .iter()
        .map(|&bytes| {
            let mut buffer = vec![0u8; bytes];
            let round_trip = time(trips(bytes), &mut || {
                if rank == 0 {
                    other.send(&buffer[..]);
                    other.receive_into(&mut buffer[..]);
                } else {
                    other.receive_into(&mut buffer[..]);
                    other.send(&buffer[..]);
                }
            });
            Sample {
                bytes: bytes as f64,
                seconds: round_trip / 2.0,
            }
        })
        .collect();
    let values = [1.0_f64; 3];
    let mut largest = [0.0_f64; 3];
    let allreduce_s = time(400, &mut || {
        world.all_reduce_into(&values[..], &mut largest[..], SystemOperation::max());
    });
    Ok((rank == 0).then_some(Measured {
        samples,
        allreduce_s,
    }))
}

// The counts round of an exchange or all-gather sends these, as the trait's docs count.
const _: () = assert!(size_of::<Count>() as u64 == COUNT_BYTES);

struct MpiComm {
    world: SimpleCommunicator,
}

/// Offsets of consecutive blocks of the given sizes.
fn displacements(counts: &[Count]) -> Vec<Count> {
    counts
        .iter()
        .scan(0, |offset, &count| {
            let start = *offset;
            *offset += count;
            Some(start)
        })
        .collect()
}

/// Cuts `buffer` into consecutive blocks of the given sizes.
fn split_blocks(buffer: &[f64], counts: &[Count]) -> Vec<Vec<f64>> {
    let mut rest = buffer;
    counts
        .iter()
        .map(|&count| {
            let (block, tail) = rest.split_at(count as usize);
            rest = tail;
            block.to_vec()
        })
        .collect()
}

fn count_of(buffer: &[f64]) -> Count {
    Count::try_from(buffer.len()).expect("an MPI message below 2^31 values")
}

impl Communicator for MpiComm {
    fn rank(&self) -> usize {
        self.world.rank() as usize
    }

    fn size(&self) -> usize {
        self.world.size() as usize
    }

    fn barrier(&self) {
        self.world.barrier();
    }

    fn max_all(&self, values: &[f64]) -> Vec<f64> {
        let mut largest = vec![0.0; values.len()];
        self.world
            .all_reduce_into(values, &mut largest[..], SystemOperation::max());
        largest
    }

    fn send_receive(&self, sends: &[(usize, &[f64])], from: &[usize]) -> Vec<Vec<f64>> {
        let process = |rank: usize| self.world.process_at_rank(rank as i32);
        mpi::request::scope(|scope| {
            // Every send is posted before any receive waits, so ranks that send to each
            // other never wait on each other; the guards wait for the sends at the end.
            let _sending: Vec<WaitGuard<'_, [f64], _>> = sends
                .iter()
                .map(|&(to, buffer)| WaitGuard::from(process(to).immediate_send(scope, buffer)))
                .collect();
            from.iter()
                .map(|&sender| process(sender).receive_vec::<f64>().0)
                .collect()
        })
    }

    fn exchange(&self, outgoing: &[Vec<f64>]) -> Vec<Vec<f64>> {
        let send_counts: Vec<Count> = outgoing.iter().map(|buffer| count_of(buffer)).collect();
        let mut recv_counts = vec![0; self.size()];
        self.world
            .all_to_all_into(&send_counts[..], &mut recv_counts[..]);
        let send = outgoing.concat();
        let mut recv = vec![0.0; recv_counts.iter().map(|&c| c as usize).sum()];
        {
            let send_displs = displacements(&send_counts);
            let recv_displs = displacements(&recv_counts);
            let partition = Partition::new(&send[..], &send_counts[..], &send_displs[..]);
            let mut received = PartitionMut::new(&mut recv[..], &recv_counts[..], &recv_displs[..]);
            self.world
                .all_to_all_varcount_into(&partition, &mut received);
        }
        split_blocks(&recv, &recv_counts)
    }

    fn all_gather(&self, data: &[f64]) -> Vec<Vec<f64>> {
        let mut counts = vec![0; self.size()];
        self.world.all_gather_into(&count_of(data), &mut counts[..]);
        let mut recv = vec![0.0; counts.iter().map(|&c| c as usize).sum()];
        {
            let displs = displacements(&counts);
            let mut received = PartitionMut::new(&mut recv[..], &counts[..], &displs[..]);
            self.world.all_gather_varcount_into(data, &mut received);
        }
        split_blocks(&recv, &counts)
    }
}
