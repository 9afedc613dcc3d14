//! A team of a rayon pool's threads that stays awake for a whole run: the rayon
//! backend's stages are split over it, phase after phase, without any thread going to
//! sleep between them.
//!
//! Why not rayon's own parallel iterators: a rayon worker that finds no work for some
//! 30 µs goes to sleep, and waking a sleeping vCPU took 33–68 µs on the virtual machines
//! this was measured on. A step of the rayon backend is three or four parallel phases,
//! up to a dozen at a list rebuild, with serial pieces between them; every phase started
//! with a sleeping worker, or ended
//! with one thread waiting, asleep, for the other's last piece: at 10⁵ disks the second
//! thread did little at all. A team member waits as Intel's OpenMP threads do by
//! default: it polls for the next phase, yielding its core between polls, and parks
//! only after [`IDLE_BEFORE_PARKING`] without work (`KMP_BLOCKTIME`, also 200 ms
//! there).
//!
//! The thread that leads the team takes a phase's pieces too, and a phase ends when
//! its pieces are done: a member that has not come by the time every piece is handed
//! out (descheduled by the host, or one of more threads than cores) is not waited for.
//!
//! Each thread first takes the pieces of its own share, a contiguous run of them (the
//! leader the first, member k the (k+1)-th), then helps with what is left of the
//! others'. The backend cuts every phase the same way, in storage order (chunks of the
//! disks, bands of strips, whose disks are stored in band order), so a thread works on
//! the same disks phase after phase and step after step, which keeps them in its own
//! core's caches. When the first free thread took the next piece, a thread often moved
//! disks the other had just written, and on the 2-vCPU virtual machines measured,
//! during spells that came and went within minutes, the move of 10⁶ disks took 113–135
//! ms over 100 steps instead of 78–85, while two MPI ranks, each with its own disks,
//! were not slowed (the likeliest reason, not measured directly: the host then ran the
//! two vCPUs on cores that share no cache). Shares keep the move at 81–89 ms in those
//! spells (`docs/performance.md`). Results never depend on which thread ran a piece:
//! every piece writes only its own output, and reductions run afterwards, in piece
//! order, on the leader.

use std::any::Any;
use std::cell::UnsafeCell;
use std::panic::{AssertUnwindSafe, catch_unwind, resume_unwind};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::thread::Thread;
use std::time::{Duration, Instant};

use crate::sim::pieces::Pieces;

/// How long a member polls for the next phase before it parks: through the serial
/// pieces of a step and the loop between steps (drawing a step offscreen included);
/// not so long that a team left idle keeps a core busy for more than a moment.
const IDLE_BEFORE_PARKING: Duration = Duration::from_millis(200);

/// The threads of the current rayon pool, as a team led by the calling thread; see
/// [`with_team`].
pub struct Team<'a> {
    shared: &'a Shared,
}

/// Runs `work` on this thread, a worker of a rayon pool (inside `ThreadPool::install`),
/// with every other worker of the pool joined to a [`Team`] that `work` can split
/// phases over. The other workers are held until `work` returns (or panics); one that
/// is busy elsewhere meanwhile only leaves more of each phase to the others.
pub fn with_team<R>(work: impl FnOnce(&Team<'_>) -> R) -> R {
    let shared = Shared::new(rayon::current_num_threads());
    rayon::in_place_scope(|scope| lead(scope, &shared, work))
}

/// Runs `work` on this thread, which need not be a worker of any pool, leading a
/// [`Team`] of itself and every worker of `members`, as [`with_team`] does. An MPI rank
/// steps this way: its communication stays on the thread that started MPI.
pub fn with_team_beside<R>(members: &rayon::ThreadPool, work: impl FnOnce(&Team<'_>) -> R) -> R {
    let shared = Shared::new(members.current_num_threads() + 1);
    members.in_place_scope(|scope| lead(scope, &shared, work))
}

/// Spawns a member into `scope` for every thread of `shared` but the leader (thread
/// 0, this one), and runs `work` with the team.
fn lead<'s, R>(
    scope: &rayon::Scope<'s>,
    shared: &'s Shared,
    work: impl FnOnce(&Team<'_>) -> R,
) -> R {
    for member in 1..shared.cursors.len() {
        scope.spawn(move |_| shared.serve(member));
    }
    let team = Team { shared };
    // Dismissed however `work` ends: the scope waits for every member to leave.
    let _dismiss = Dismiss(shared);
    work(&team)
}

impl Team<'_> {
    /// The threads of the team other than the leader (one cursor each).
    fn n_members(&self) -> usize {
        self.shared.cursors.len() - 1
    }

    /// Calls `task(index)` for every index in `0..n_items` over the team. A member
    /// that has not joined by the time the leader has handed out every index is not
    /// waited for: a phase costs the leader no more than its items when the other
    /// threads are slow to come (descheduled, or more threads than cores).
    fn run(&self, n_items: usize, task: &(dyn Fn(usize) + Sync)) {
        let shared = self.shared;
        if self.n_members() == 0 || n_items <= 1 {
            (0..n_items).for_each(task);
            return;
        }
        // SAFETY: a member calls `task` only inside the phase opened below, and this
        // function returns only after closing it and seeing no member inside: the
        // erased lifetime is never outlived.
        let task: *const (dyn Fn(usize) + Sync + 'static) =
            unsafe { std::mem::transmute::<*const (dyn Fn(usize) + Sync + '_), _>(task) };
        // SAFETY: the last phase is closed with no member inside, and a member reads
        // the phase only once inside an open one.
        unsafe { *shared.phase.get() = Phase { task, n_items } };
        shared.open_phase();
        shared.take_items(0);
        shared.close_phase();
        let panic = shared.panic.lock().map(|mut held| held.take());
        if let Ok(Some(payload)) = panic {
            resume_unwind(payload);
        }
    }
}

/// Pieces of work spread over the team: the backend's own phases and the core's passes
/// in pieces.
impl Pieces for Team<'_> {
    fn workers(&self) -> usize {
        self.n_members() + 1
    }

    /// Calls `task` once with each of `items`, spread over the team (each thread its
    /// own share of them first, then any left); returns when every call has returned.
    /// A panic in a call is raised again here, after the others have returned.
    fn for_each<T: Send>(&self, items: &mut [T], task: impl Fn(&mut T) + Sync) {
        let items = ItemsPtr(items.as_mut_ptr(), items.len());
        let items = &items;
        // SAFETY: `run` calls the closure with each index below the length once, so
        // every `&mut` points to a different item, alive until `run` returns.
        self.run(items.1, &|index| task(unsafe { &mut *items.0.add(index) }));
    }
}

/// A slice's items (start and length), handed to the threads one each
/// ([`Team::for_each`]).
struct ItemsPtr<T>(*mut T, usize);

// SAFETY: the items are `Send`, and each is reached from one thread only.
unsafe impl<T: Send> Sync for ItemsPtr<T> {}

/// The phase the members work on: a task and its number of items.
#[derive(Clone, Copy)]
struct Phase {
    task: *const (dyn Fn(usize) + Sync + 'static),
    n_items: usize,
}

/// The next unclaimed item of one thread's share, alone in its cache line(s): every
/// thread claims from it once it has run out of its own share.
#[derive(Default)]
#[repr(align(128))]
struct Cursor(AtomicUsize);

/// What the leader and the members share.
struct Shared {
    /// Odd while a phase is open, even while none is: the leader adds one to open a
    /// phase and one to close it.
    generation: AtomicU64,
    /// Written by the leader only while no phase is open and no member is inside one.
    phase: UnsafeCell<Phase>,
    /// Per thread of the team (the leader first), the next item of its share; set by
    /// the leader before it opens a phase.
    cursors: Vec<Cursor>,
    /// Members inside the open phase (or checking whether they may enter it).
    inside: AtomicUsize,
    dismissed: AtomicBool,
    /// The first panic of a phase's tasks, raised again by the leader.
    panic: Mutex<Option<Box<dyn Any + Send>>>,
    /// Members parked, and every member's thread, to unpark.
    n_parked: AtomicUsize,
    members: Mutex<Vec<Thread>>,
}

// SAFETY: `phase` is written by the leader only while no member reads it (see
// `Team::run`), and its task is `Sync`.
unsafe impl Sync for Shared {}

impl Shared {
    /// The state of a team of `n_threads` threads, the leader included.
    fn new(n_threads: usize) -> Self {
        let idle: &'static (dyn Fn(usize) + Sync) = &|_| {};
        Shared {
            generation: AtomicU64::new(0),
            phase: UnsafeCell::new(Phase {
                task: idle,
                n_items: 0,
            }),
            cursors: (0..n_threads).map(|_| Cursor::default()).collect(),
            inside: AtomicUsize::new(0),
            dismissed: AtomicBool::new(false),
            panic: Mutex::new(None),
            n_parked: AtomicUsize::new(0),
            members: Mutex::new(Vec::new()),
        }
    }

    /// A member's life: wait for a phase it has not worked in, enter it if it is still
    /// open, take its items, leave; until dismissed.
    fn serve(&self, thread: usize) {
        if let Ok(mut members) = self.members.lock() {
            members.push(std::thread::current());
        }
        let mut seen = 0;
        while let Some(generation) = self.wait_for_phase(seen) {
            seen = generation;
            // Sequentially consistent with `close_phase`: either the leader sees this
            // member inside and waits for it, or this sees the phase closed.
            self.inside.fetch_add(1, Ordering::SeqCst);
            if self.generation.load(Ordering::SeqCst) == generation {
                self.take_items(thread);
            }
            self.inside.fetch_sub(1, Ordering::Release);
        }
    }

    /// Runs items of the open phase until none is left: those of the share of thread
    /// `thread` first, then what is left of the next threads' shares.
    fn take_items(&self, thread: usize) {
        // SAFETY: read inside an open phase (see `serve` and `Team::run`), which the
        // leader does not close and return from while this thread is inside.
        let phase = unsafe { *self.phase.get() };
        let task = unsafe { &*phase.task };
        let n_threads = self.cursors.len();
        for offset in 0..n_threads {
            let share = (thread + offset) % n_threads;
            let end = self.share_start(share + 1, phase.n_items);
            loop {
                let index = self.cursors[share].0.fetch_add(1, Ordering::Relaxed);
                if index >= end {
                    break;
                }
                if let Err(payload) = catch_unwind(AssertUnwindSafe(|| task(index)))
                    && let Ok(mut held) = self.panic.lock()
                {
                    held.get_or_insert(payload);
                }
            }
        }
    }

    /// Opens the phase written in `phase`, every share unclaimed, and wakes parked
    /// members.
    fn open_phase(&self) {
        // SAFETY: written by the leader before the phase opens (`Team::run`).
        let phase = unsafe { *self.phase.get() };
        for (thread, cursor) in self.cursors.iter().enumerate() {
            cursor
                .0
                .store(self.share_start(thread, phase.n_items), Ordering::Relaxed);
        }
        // Sequentially consistent with the members' parking: either a member sees the
        // new generation, or this sees it parked and unparks it.
        self.generation.fetch_add(1, Ordering::SeqCst);
        if self.n_parked.load(Ordering::SeqCst) > 0 {
            self.unpark_all();
        }
    }

    /// The first of `n_items` items in the share of thread `thread` (the leader's is 0);
    /// a share ends where the next thread's starts, the last at `n_items`.
    fn share_start(&self, thread: usize, n_items: usize) -> usize {
        thread * n_items / self.cursors.len()
    }

    /// Closes the open phase, whose items are all handed out, and returns once no
    /// member is inside it (their items are then done, their writes seen).
    fn close_phase(&self) {
        self.generation.fetch_add(1, Ordering::SeqCst);
        while self.inside.load(Ordering::SeqCst) != 0 {
            std::thread::yield_now();
        }
    }

    fn unpark_all(&self) {
        if let Ok(members) = self.members.lock() {
            members.iter().for_each(Thread::unpark);
        }
    }

    /// Polls until a phase other than `seen` is open, and returns its generation, or
    /// `None` once dismissed; parks after [`IDLE_BEFORE_PARKING`].
    fn wait_for_phase(&self, seen: u64) -> Option<u64> {
        let idle_since = Instant::now();
        let mut polls: u32 = 0;
        loop {
            if let Some(next) = self.next_phase(seen) {
                return next;
            }
            // The clock is read every 64 polls: a poll stays two loads and a yield.
            polls = polls.wrapping_add(1);
            if !polls.is_multiple_of(64) || idle_since.elapsed() < IDLE_BEFORE_PARKING {
                // Yielding, not spinning: the core goes to whatever else is runnable,
                // and under valgrind (which runs one thread at a time) to the leader.
                std::thread::yield_now();
                continue;
            }
            self.n_parked.fetch_add(1, Ordering::SeqCst);
            if self.next_phase(seen).is_none() {
                // An unpark before this park makes it return at once.
                std::thread::park();
            }
            self.n_parked.fetch_sub(1, Ordering::SeqCst);
        }
    }

    /// `Some(None)` once dismissed, `Some(Some(generation))` while a phase other than
    /// `seen` is open, `None` otherwise.
    fn next_phase(&self, seen: u64) -> Option<Option<u64>> {
        if self.dismissed.load(Ordering::SeqCst) {
            return Some(None);
        }
        let generation = self.generation.load(Ordering::SeqCst);
        (generation % 2 == 1 && generation != seen).then_some(Some(generation))
    }
}

/// Dismisses the members when dropped.
struct Dismiss<'a>(&'a Shared);

impl Drop for Dismiss<'_> {
    fn drop(&mut self) {
        self.0.dismissed.store(true, Ordering::SeqCst);
        self.0.unpark_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pool(threads: usize) -> rayon::ThreadPool {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a pool")
    }

    #[test]
    fn every_item_is_given_to_exactly_one_call_in_every_phase() {
        for threads in [1, 2, 3] {
            let mut counts = vec![0_u32; 1000];
            pool(threads).install(|| {
                with_team(|team| {
                    assert_eq!(team.n_members() + 1, threads);
                    for _ in 0..50 {
                        team.for_each(&mut counts, |count| *count += 1);
                    }
                })
            });
            assert!(counts.iter().all(|&count| count == 50), "{threads} threads");
        }
    }

    /// Two items that each wait for the other to start can only finish on two threads.
    #[test]
    fn a_member_takes_items_of_a_phase_beside_the_leader() {
        let started = AtomicUsize::new(0);
        let threads = pool(2).install(|| {
            with_team(|team| {
                team.map(0..2, |_| {
                    started.fetch_add(1, Ordering::SeqCst);
                    let give_up = Instant::now() + Duration::from_secs(30);
                    while started.load(Ordering::SeqCst) < 2 && Instant::now() < give_up {
                        std::thread::yield_now();
                    }
                    std::thread::current().id()
                })
            })
        });
        assert_eq!(started.load(Ordering::SeqCst), 2);
        assert_ne!(threads[0], threads[1], "the two items ran on two threads");
    }

    /// Each thread starts on its own share: of four items, the leader runs the first
    /// two and the member the last two. Every item waits until the item that starts
    /// the other thread's share (for items 0 and 2), or every item (for 1 and 3), has
    /// started, so neither thread can run out of work and take from the other's share.
    #[test]
    fn each_thread_runs_its_own_share_of_a_phase() {
        let started = AtomicUsize::new(0);
        let (leader, threads) = pool(2).install(|| {
            let leader = std::thread::current().id();
            let threads = with_team(|team| {
                team.map(0..4, |item| {
                    started.fetch_add(1, Ordering::SeqCst);
                    let wait_for = if item % 2 == 0 { 2 } else { 4 };
                    let give_up = Instant::now() + Duration::from_secs(30);
                    while started.load(Ordering::SeqCst) < wait_for && Instant::now() < give_up {
                        std::thread::yield_now();
                    }
                    std::thread::current().id()
                })
            });
            (leader, threads)
        });
        assert_eq!(started.load(Ordering::SeqCst), 4);
        assert_eq!(threads[..2], [leader, leader], "the leader's share");
        assert_eq!(threads[2], threads[3], "the member's share");
        assert_ne!(threads[2], leader, "the member's share");
    }

    #[test]
    fn a_map_returns_its_outputs_in_the_order_of_its_items() {
        let squares = pool(2).install(|| with_team(|team| team.map(0..300_u64, |i| i * i)));
        assert_eq!(squares, (0..300_u64).map(|i| i * i).collect::<Vec<_>>());
    }

    #[test]
    fn a_panic_in_a_task_reaches_the_leader_and_the_pool_stays_usable() {
        let pool = pool(2);
        let outcome = catch_unwind(AssertUnwindSafe(|| {
            pool.install(|| {
                with_team(|team| {
                    team.for_each(&mut [0, 1, 2, 3, 4, 5, 6, 7], |item| {
                        assert_ne!(*item, 5, "item 5 panics");
                    });
                })
            })
        }));
        assert!(outcome.is_err(), "the panic was raised again");
        let sum: u64 = pool.install(|| with_team(|team| team.map(1..=4_u64, |i| i).iter().sum()));
        assert_eq!(sum, 10);
    }

    #[test]
    fn members_idle_for_long_park_and_wake_for_the_next_phase() {
        pool(3).install(|| {
            with_team(|team| {
                let parked_all = || team.shared.n_parked.load(Ordering::SeqCst) == 2;
                let give_up = Instant::now() + IDLE_BEFORE_PARKING * 20;
                while !parked_all() && Instant::now() < give_up {
                    std::thread::sleep(IDLE_BEFORE_PARKING / 4);
                }
                assert!(parked_all(), "both members parked");
                let doubled = team.map(0..64_u32, |i| 2 * i);
                assert_eq!(doubled, (0..64_u32).map(|i| 2 * i).collect::<Vec<_>>());
            })
        });
    }
}
