//! [`Workers`]: a thread pool for the solver's short parallel regions.
//!
//! Handing borrowed items to threads that outlive the call needs `unsafe` (as in
//! `std::thread::scope` or rayon): this module is the only place in the crate that allows it.
//! Each use says why it is sound; the tests below run it under load, nested and panicking.
#![allow(unsafe_code)]

use core::sync::atomic::Ordering::SeqCst;
use core::sync::atomic::{AtomicBool, AtomicPtr, AtomicU64, AtomicUsize};
use core::time::Duration;
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::Instant;

use super::Parallel;

/// A small pool of worker threads that wait for work by spinning briefly, for the short
/// parallel regions of a step (about one per substep, tens of microseconds each), where a
/// general-purpose task pool spends as long waking its threads as the work takes.
///
/// [`Workers::for_each_mut`] publishes the items with one *seat* for a helper per item beyond
/// the first (at most one per helper); the calling thread and the helpers that take a seat
/// claim items one at a time until none are left, so the call never waits for a worker that
/// has not started (a worker the system does not schedule costs nothing but its share of the
/// speed-up). The call returns once every claimed item is done. A call of `k` items wakes at
/// most `k − 1` sleeping helpers, and a helper that never worked, or not for [`Workers::SPIN`],
/// sleeps until a call wakes it: on a 16-core machine a cloth of two parts keeps two threads
/// busy, not sixteen spinning on the same counters (work grows the threads a step uses, not
/// the core count), and an idle pool costs no CPU. A helper that worked spins until
/// [`Workers::SPIN`] after its last item, through calls with no seat for it: a substep's
/// seams (eight items on sixteen threads) do not send half the helpers to sleep, to be woken
/// again by the next substep's parts. A call made while another runs (from inside it, or
/// from another thread) runs serially on its own thread.
///
/// The solver itself never starts threads: create one `Workers` (the Bevy plugin keeps one
/// as a resource) and pass it where a [`Parallel`] is asked for.
pub struct Workers {
    shared: Arc<Shared>,
    handles: Vec<std::thread::JoinHandle<()>>,
}

/// One published call: items are claimed by index.
struct Job<'a> {
    next: AtomicUsize,
    done: AtomicUsize,
    len: usize,
    run: &'a (dyn Fn(usize) + Sync),
    /// Helpers that may still join: one per item beyond the first, at most one per helper.
    seats: AtomicUsize,
    /// An item panicked (the panic is raised again on the calling thread).
    panicked: AtomicBool,
}

struct Shared {
    /// The published call, or null.
    job: AtomicPtr<Job<'static>>,
    /// Incremented by each call, so workers see new work.
    epoch: AtomicU64,
    /// Workers between loading `job` and finishing with it.
    busy: AtomicUsize,
    /// Workers asleep (or about to be) on `wake`.
    sleepers: AtomicUsize,
    /// How many times a worker has woken from `wake` (for tests and diagnostics).
    wakes: AtomicUsize,
    /// Set while a call runs (a nested call runs serially).
    active: AtomicBool,
    /// How long a helper spins after its last item ([`Workers::SPIN`]).
    spin: Duration,
    stop: AtomicBool,
    lock: Mutex<()>,
    wake: Condvar,
}

impl Workers {
    /// How long a worker spins for new work before it sleeps.
    pub const SPIN: Duration = Duration::from_micros(200);

    /// A pool of `helpers` threads besides the calling one: `available_parallelism − 1` keeps
    /// one thread per core. With 0 every call runs on the calling thread. Helpers the system
    /// refuses to start are left out (the pool still works, with fewer threads).
    #[must_use]
    pub fn new(helpers: usize) -> Self {
        Self::with_spin(helpers, Self::SPIN)
    }

    /// [`Workers::new`] with helpers that spin for `spin` after their last item (tests).
    fn with_spin(helpers: usize, spin: Duration) -> Self {
        let shared = Arc::new(Shared {
            job: AtomicPtr::new(core::ptr::null_mut()),
            epoch: AtomicU64::new(0),
            busy: AtomicUsize::new(0),
            sleepers: AtomicUsize::new(0),
            wakes: AtomicUsize::new(0),
            active: AtomicBool::new(false),
            spin,
            stop: AtomicBool::new(false),
            lock: Mutex::new(()),
            wake: Condvar::new(),
        });
        let handles = (0..helpers)
            .filter_map(|k| {
                let shared = Arc::clone(&shared);
                std::thread::Builder::new()
                    .name(format!("cloth worker {k}"))
                    .spawn(move || worker(&shared))
                    .ok()
            })
            .collect();
        Self { shared, handles }
    }

    /// One helper per core besides the calling thread.
    #[must_use]
    pub fn per_core() -> Self {
        Self::new(
            std::thread::available_parallelism()
                .map_or(1, std::num::NonZeroUsize::get)
                .saturating_sub(1),
        )
    }
}

impl core::fmt::Debug for Workers {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Workers")
            .field("helpers", &self.handles.len())
            .finish()
    }
}

impl Drop for Workers {
    fn drop(&mut self) {
        self.shared.stop.store(true, SeqCst);
        {
            let _guard = self
                .shared
                .lock
                .lock()
                .unwrap_or_else(PoisonError::into_inner);
            self.shared.wake.notify_all();
        }
        for h in self.handles.drain(..) {
            let _ = h.join();
        }
    }
}

/// Claims and runs items of `job` until none are left.
fn drain(job: &Job<'_>) {
    loop {
        let i = job.next.fetch_add(1, SeqCst);
        if i >= job.len {
            return;
        }
        let run = std::panic::AssertUnwindSafe(|| (job.run)(i));
        if std::panic::catch_unwind(run).is_err() {
            job.panicked.store(true, SeqCst);
        }
        job.done.fetch_add(1, SeqCst);
    }
}

impl Job<'_> {
    /// Takes a seat at this call, if one is left.
    fn take_seat(&self) -> bool {
        self.seats
            .fetch_update(SeqCst, SeqCst, |s| s.checked_sub(1))
            .is_ok()
    }
}

fn worker(shared: &Shared) {
    let mut seen = 0u64;
    // When this helper last finished an item (`None`: never, or before it last slept): it
    // spins for a new call until `spin` after that, through calls that had no seat for it;
    // one that was not needed sleeps at once.
    let mut worked: Option<Instant> = None;
    loop {
        // Wait for a new call: spin, then sleep.
        let mut spins = 0u32;
        loop {
            if shared.stop.load(SeqCst) {
                return;
            }
            if shared.epoch.load(SeqCst) != seen {
                break;
            }
            spins += 1;
            if spins.is_multiple_of(64) && worked.is_none_or(|t| t.elapsed() >= shared.spin) {
                worked = None;
                let guard = shared.lock.lock().unwrap_or_else(PoisonError::into_inner);
                shared.sleepers.fetch_add(1, SeqCst);
                let guard = shared
                    .wake
                    .wait_while(guard, |()| {
                        shared.epoch.load(SeqCst) == seen && !shared.stop.load(SeqCst)
                    })
                    .unwrap_or_else(PoisonError::into_inner);
                shared.sleepers.fetch_sub(1, SeqCst);
                shared.wakes.fetch_add(1, SeqCst);
                drop(guard);
                break;
            }
            core::hint::spin_loop();
        }
        seen = shared.epoch.load(SeqCst);
        shared.busy.fetch_add(1, SeqCst);
        let job = shared.job.load(SeqCst);
        if !job.is_null() {
            // SAFETY: the caller keeps the job alive until `busy` is back to zero after it
            // withdrew the pointer, and this thread counted itself in `busy` before loading it.
            let job = unsafe { &*job };
            if job.take_seat() {
                drain(job);
                worked = Some(Instant::now());
            }
        }
        shared.busy.fetch_sub(1, SeqCst);
    }
}

/// A pointer that may cross threads: each item is handed to exactly one thread.
struct Items<T>(*mut T);
// SAFETY: items are `Send` and every index is claimed by one thread only.
unsafe impl<T: Send> Sync for Items<T> {}

impl Parallel for Workers {
    fn for_each_mut<T: Send, F: Fn(&mut T) + Sync>(&self, items: &mut [T], f: F) {
        let s = &*self.shared;
        if items.len() < 2 || self.handles.is_empty() || s.active.swap(true, SeqCst) {
            items.iter_mut().for_each(f);
            return;
        }
        let base = Items(items.as_mut_ptr());
        let base = &base;
        let run = move |i: usize| {
            // SAFETY: `i < len` and each index is claimed once (`Job::next`).
            f(unsafe { &mut *base.0.add(i) });
        };
        let seats = (items.len() - 1).min(self.handles.len());
        let job = Job {
            next: AtomicUsize::new(0),
            done: AtomicUsize::new(0),
            len: items.len(),
            run: &run,
            seats: AtomicUsize::new(seats),
            panicked: AtomicBool::new(false),
        };
        // SAFETY (lifetime erased): withdrawn below, and waited for, before `job` goes.
        let ptr = core::ptr::from_ref(&job).cast_mut().cast::<Job<'static>>();
        s.job.store(ptr, SeqCst);
        s.epoch.fetch_add(1, SeqCst);
        // Wake only the seats the helpers still awake (spinning after their last call) cannot
        // fill; one woken for nothing sleeps again at once. A helper that counted itself
        // asleep after this load sees the new epoch before it waits, so none is missed.
        let sleeping = s.sleepers.load(SeqCst);
        let awake = self.handles.len().saturating_sub(sleeping);
        let wake = seats.saturating_sub(awake).min(sleeping);
        if wake > 0 {
            let _guard = s.lock.lock().unwrap_or_else(PoisonError::into_inner);
            for _ in 0..wake {
                s.wake.notify_one();
            }
        }
        drain(&job);
        // Every item is claimed: wait for those still running elsewhere.
        wait_until(|| job.done.load(SeqCst) == job.len);
        s.job.store(core::ptr::null_mut(), SeqCst);
        wait_until(|| s.busy.load(SeqCst) == 0);
        s.active.store(false, SeqCst);
        assert!(!job.panicked.load(SeqCst), "a cloth work item panicked");
    }

    fn threads(&self) -> usize {
        self.handles.len() + 1
    }
}

/// Spins until `ready`, yielding the core now and then.
fn wait_until(ready: impl Fn() -> bool) {
    let mut spins = 0u32;
    while !ready() {
        spins += 1;
        if spins.is_multiple_of(256) {
            std::thread::yield_now();
        } else {
            core::hint::spin_loop();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::parallel::Serial;

    #[test]
    fn every_item_runs_once_call_after_call() {
        let workers = Workers::new(3);
        assert_eq!(workers.threads(), 4);
        for round in 0..2000usize {
            let mut items: Vec<usize> = (0..1 + round % 17).collect();
            workers.for_each_mut(&mut items, |x| *x = *x * 2 + 1);
            for (i, x) in items.iter().enumerate() {
                assert_eq!(*x, i * 2 + 1, "round {round}");
            }
            if round % 500 == 0 {
                // Long enough for the workers to fall asleep: the next call wakes them.
                std::thread::sleep(Workers::SPIN * 3);
            }
        }
    }

    #[test]
    fn work_is_shared_between_threads() {
        let workers = Workers::new(1);
        let mut seen = std::collections::HashSet::new();
        for _ in 0..200 {
            let mut items: Vec<Option<std::thread::ThreadId>> = vec![None; 8];
            workers.for_each_mut(&mut items, |t| {
                std::thread::sleep(Duration::from_micros(200));
                *t = Some(std::thread::current().id());
            });
            seen.extend(items.into_iter().flatten());
            if seen.len() > 1 {
                break;
            }
        }
        assert_eq!(seen.len(), 2, "the helper never took an item");
    }

    #[test]
    fn a_call_of_few_items_leaves_the_other_helpers_asleep() {
        let workers = Workers::new(7);
        let asleep = || workers.shared.sleepers.load(SeqCst);
        let start = Instant::now();
        while asleep() < 7 {
            assert!(
                start.elapsed() < Duration::from_secs(10),
                "helpers never slept"
            );
            std::thread::sleep(Workers::SPIN);
        }
        // A cloth of two parts, called after every helper has gone to sleep: one seat a
        // call, so one helper woken a call (before seats, every call woke all seven to spin
        // on the same counters: 479 wake-ups when tried here).
        let rounds = 100;
        let before = workers.shared.wakes.load(SeqCst);
        for round in 0..rounds {
            std::thread::sleep(Workers::SPIN * 2);
            let mut items = vec![0u32; 2];
            workers.for_each_mut(&mut items, |x| *x += 1);
            assert_eq!(items, [1, 1], "round {round}");
        }
        let woken = workers.shared.wakes.load(SeqCst) - before;
        // Slack for spurious wake-ups; 7 a call would be 700.
        assert!(
            woken <= 2 * rounds,
            "{woken} wake-ups for {rounds} calls of two items"
        );
        // Many items still reach every helper.
        let mut seen = std::collections::HashSet::new();
        for _ in 0..200 {
            let mut items: Vec<Option<std::thread::ThreadId>> = vec![None; 64];
            workers.for_each_mut(&mut items, |t| {
                std::thread::sleep(Duration::from_micros(100));
                *t = Some(std::thread::current().id());
            });
            seen.extend(items.into_iter().flatten());
            if seen.len() == 8 {
                break;
            }
        }
        assert!(seen.len() > 2, "only {} threads took items", seen.len());
    }

    #[test]
    fn helpers_that_worked_stay_awake_through_calls_with_no_seat_for_them() {
        // A spin longer than the test: a helper that worked never sleeps in it.
        let workers = Workers::with_spin(3, Duration::from_secs(60));
        let asleep = || workers.shared.sleepers.load(SeqCst);
        let settle = || std::thread::sleep(Duration::from_millis(20));
        // Calls of many slow items until every helper has taken one (and so spins).
        let start = Instant::now();
        loop {
            let mut items = vec![0u8; 16];
            workers.for_each_mut(&mut items, |x| {
                std::thread::sleep(Duration::from_micros(500));
                *x = 1;
            });
            settle();
            if asleep() == 0 {
                break;
            }
            assert!(
                start.elapsed() < Duration::from_secs(20),
                "a helper never took an item"
            );
        }
        // Calls of two items (a substep's seams on a big machine) seat one helper: the others
        // are not needed, but worked a moment ago and the next call may need them.
        for round in 0..50 {
            let mut items = vec![0u8; 2];
            workers.for_each_mut(&mut items, |x| *x += 1);
            assert_eq!(items, [1, 1], "round {round}");
        }
        settle();
        assert_eq!(
            asleep(),
            0,
            "helpers slept after calls that had no seat for them"
        );
    }

    #[test]
    fn nested_calls_run_on_the_calling_thread() {
        let workers = Workers::new(2);
        let mut outer: Vec<Vec<u32>> = (0..6).map(|k| vec![k; 5]).collect();
        workers.for_each_mut(&mut outer, |inner| {
            workers.for_each_mut(inner, |x| *x += 10);
        });
        for (k, inner) in outer.iter().enumerate() {
            assert!(inner.iter().all(|&x| x == k as u32 + 10));
        }
    }

    #[test]
    fn a_panicking_item_panics_the_caller_and_the_pool_goes_on() {
        let workers = Workers::new(2);
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            let mut items = vec![0u32; 8];
            workers.for_each_mut(&mut items, |x| {
                *x += 1;
                assert!(*x > 5, "boom");
            });
        }));
        assert!(result.is_err());
        let mut items = vec![1u32; 8];
        workers.for_each_mut(&mut items, |x| *x += 1);
        assert_eq!(items, vec![2; 8]);
    }

    #[test]
    fn the_same_cloth_steps_bit_for_bit_as_on_one_thread() {
        use crate::solver::{
            Grid, MassDistribution, Pin, Simulation, SolverParams, TopologyOptions,
        };
        let grid = Grid::new(48, 48, 1.0, 1.0);
        let t = grid.topology(TopologyOptions::default()).unwrap();
        let m = t.masses(1.0, MassDistribution::Uniform);
        let make = || {
            let mut s = Simulation::new(t.clone(), &m, SolverParams::default()).unwrap();
            s.set_part_count(4);
            s.state_mut()
                .set_pins([0, 47].map(|v| Pin {
                    vertex: v,
                    target: grid.positions()[v as usize],
                }))
                .unwrap();
            s
        };
        let (mut a, mut b) = (make(), make());
        let workers = Workers::new(3);
        for _ in 0..20 {
            a.step(1.0 / 60.0, &Serial);
            b.step(1.0 / 60.0, &workers);
        }
        assert!(a.state().positions.iter().all(|p| p.is_finite()));
        assert_eq!(a.state().positions, b.state().positions);
    }

    #[test]
    fn dropping_the_pool_stops_its_threads() {
        let workers = Workers::new(2);
        let mut items = vec![0u8; 4];
        workers.for_each_mut(&mut items, |x| *x = 1);
        drop(workers); // joins: a thread that never stopped would hang this test
        assert_eq!(items, vec![1; 4]);
    }
}
