//! Threads kept for the engine's parallel loops: a training step's chunks
//! and a large graph's MLP rows ([`super::split`]). A step of a small graph
//! is tens of microseconds, so waking a sleeping pool every step cost more
//! than the second core gave (5-spring epochs on two threads ran about as
//! fast as on one, with a fifth of the time in the kernel): these helpers
//! spin briefly between jobs instead, and the calling thread works too.
//!
//! A job passes no allocation: a helper runs a closure on the caller's
//! stack, which the caller does not leave before every helper is done with it
//! (the scoped-join pattern, kept even when the caller's own share panics).
//! Between jobs a helper spins for [`SPIN`], then parks.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long a helper waits for the next job before parking: training steps
/// and a step's MLPs come fractions of a millisecond apart.
const SPIN: Duration = Duration::from_micros(200);

/// A helper's share of a join: a closure on the caller's stack.
#[derive(Clone, Copy)]
struct Job(*const (dyn Fn() + Sync));

/// What caller and helper share.
struct Shared {
    /// The job of the latest post; read by the helper after `posted` moves.
    job: Mutex<Option<Job>>,
    posted: AtomicU64,
    finished: AtomicU64,
    panicked: AtomicBool,
    exit: AtomicBool,
}

// SAFETY: `Job` points at a closure that is `Sync`; the caller keeps it alive
// and untouched until `finished` says the helper is done with it.
unsafe impl Send for Shared {}
// SAFETY: as for Send; the pointer itself is behind a mutex.
unsafe impl Sync for Shared {}

/// One kept thread.
pub(crate) struct Helper {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

impl Helper {
    /// Starts the thread.
    pub(crate) fn start() -> std::io::Result<Self> {
        let shared = Arc::new(Shared {
            job: Mutex::new(None),
            posted: AtomicU64::new(0),
            finished: AtomicU64::new(0),
            panicked: AtomicBool::new(false),
            exit: AtomicBool::new(false),
        });
        let theirs = shared.clone();
        let thread = std::thread::Builder::new()
            .name("mcgnode-helper".into())
            .spawn(move || serve(&theirs))?;
        Ok(Self {
            shared,
            thread: Some(thread),
        })
    }

    /// Hands `job` to the thread.
    fn post(&self, job: &(dyn Fn() + Sync)) {
        let sh = &self.shared;
        let job: *const (dyn Fn() + Sync + '_) = job;
        // Only the lifetime changes, which a pointer cast cannot do.
        #[allow(clippy::missing_transmute_annotations, clippy::transmute_ptr_to_ptr)]
        // SAFETY: only the lifetime is erased; every caller waits for the
        // post (`Waiter`) before the closure goes out of scope.
        let job = Job(unsafe { std::mem::transmute(job) });
        *sh.job.lock().unwrap_or_else(PoisonError::into_inner) = Some(job);
        // A panic of a join the caller unwound from is not this one's.
        sh.panicked.store(false, Ordering::Release);
        sh.posted.fetch_add(1, Ordering::Release);
        if let Some(t) = &self.thread {
            t.thread().unpark();
        }
    }

    /// Returns once the latest post is done (at once if there is none
    /// pending: only the caller posts, so `posted` stands still meanwhile).
    fn wait(&self) {
        let n = self.shared.posted.load(Ordering::Acquire);
        let mut spins = 0u32;
        while self.shared.finished.load(Ordering::Acquire) < n {
            spins += 1;
            if spins < 1 << 14 {
                std::hint::spin_loop();
            } else {
                // The helper was not scheduled: give it the core.
                std::thread::yield_now();
            }
        }
    }

    /// Runs `mine` here and `theirs` on the helper, and returns when both
    /// are done (a panic in `theirs` is raised here).
    pub(crate) fn join(&self, mine: impl FnOnce(), theirs: &(dyn Fn() + Sync)) {
        join_all(std::slice::from_ref(self), mine, theirs);
    }
}

/// Waits, on drop, for its helpers' latest posts: the closure they point at
/// stays alive until every helper is done, even if the caller's share
/// panics.
struct Waiter<'a>(&'a [Helper]);

impl Drop for Waiter<'_> {
    fn drop(&mut self) {
        self.0.iter().for_each(Helper::wait);
    }
}

/// Runs `mine` here and `theirs` on every helper at once; returns when all
/// are done, raising a helper's panic here.
fn join_all(helpers: &[Helper], mine: impl FnOnce(), theirs: &(dyn Fn() + Sync)) {
    let waiter = Waiter(helpers);
    for h in helpers {
        h.post(theirs);
    }
    mine();
    drop(waiter);
    let panicked = helpers
        .iter()
        .any(|h| h.shared.panicked.swap(false, Ordering::AcqRel));
    assert!(!panicked, "a helper thread's share of the work panicked");
}

/// A helper's loop: wait for a post, run its job, say it is done.
fn serve(sh: &Shared) {
    let mut seen = 0;
    loop {
        let t = Instant::now();
        let mut spins = 0u32;
        while sh.posted.load(Ordering::Acquire) == seen {
            if sh.exit.load(Ordering::Acquire) {
                return;
            }
            spins += 1;
            if spins % 64 != 0 || t.elapsed() < SPIN {
                std::hint::spin_loop();
            } else {
                // Woken by the next post or by `Drop` (both unpark).
                std::thread::park();
            }
        }
        seen = sh.posted.load(Ordering::Acquire);
        let job = *sh.job.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(Job(f)) = job {
            // SAFETY: the poster waits for `finished` before the closure
            // goes out of scope, and the closure is `Sync`.
            let run = AssertUnwindSafe(|| unsafe { (*f)() });
            if catch_unwind(run).is_err() {
                sh.panicked.store(true, Ordering::Release);
            }
        }
        sh.finished.store(seen, Ordering::Release);
    }
}

impl Drop for Helper {
    fn drop(&mut self) {
        self.shared.exit.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}

/// The threads of a training engine: the caller and `threads − 1` helpers.
pub(crate) struct Crew {
    helpers: Vec<Helper>,
}

impl Crew {
    /// A crew of `threads` threads (the caller counts as one), or none for
    /// one thread.
    pub(crate) fn new(threads: usize) -> std::io::Result<Option<Self>> {
        if threads <= 1 {
            return Ok(None);
        }
        let helpers = (1..threads)
            .map(|_| Helper::start())
            .collect::<std::io::Result<_>>()?;
        Ok(Some(Self { helpers }))
    }

    /// Threads, the caller's included.
    pub(crate) fn threads(&self) -> usize {
        self.helpers.len() + 1
    }

    /// `work(item, i)` for every `items[i]`, each index on one thread: the
    /// threads take the next index in turn, so a core slowed by a neighbour
    /// does less.
    pub(crate) fn for_each<C: Send>(&self, items: &mut [C], work: impl Fn(&mut C, usize) + Sync) {
        let slots = Slots {
            ptr: items.as_mut_ptr(),
            len: items.len(),
            _items: std::marker::PhantomData,
        };
        let next = AtomicUsize::new(0);
        let each = || loop {
            let i = next.fetch_add(1, Ordering::Relaxed);
            if i >= slots.len {
                break;
            }
            // SAFETY: `i` is claimed by this thread alone (the counter).
            work(unsafe { slots.get(i) }, i);
        };
        join_all(&self.helpers, each, &each);
    }
}

/// `&mut [C]` handed to several threads, each taking distinct indices.
struct Slots<'a, C> {
    ptr: *mut C,
    len: usize,
    _items: std::marker::PhantomData<&'a mut [C]>,
}

// SAFETY: the items are `Send` and each is reached by one thread only.
unsafe impl<C: Send> Sync for Slots<'_, C> {}

impl<C> Slots<'_, C> {
    /// # Safety
    /// `i < len`, and no other reference to item `i` is alive.
    #[allow(clippy::mut_from_ref)]
    unsafe fn get(&self, i: usize) -> &mut C {
        assert!(i < self.len, "an item out of its slice");
        // SAFETY: in bounds; exclusive by the caller's contract.
        unsafe { &mut *self.ptr.add(i) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every item is visited once per call, call after call, with one
    /// helper and with three (more threads than this machine may have).
    #[test]
    fn every_item_once() {
        for threads in [2, 4] {
            let crew = Crew::new(threads).unwrap().unwrap();
            assert_eq!(crew.threads(), threads);
            let mut items = vec![0u64; 37];
            for round in 1..=200u64 {
                crew.for_each(&mut items, |x, i| *x += i as u64 + 1);
                for (i, x) in items.iter().enumerate() {
                    assert_eq!(*x, round * (i as u64 + 1), "item {i}, call {round}");
                }
            }
            crew.for_each(&mut [] as &mut [u64], |_, _| unreachable!());
        }
        assert!(Crew::new(1).unwrap().is_none());
    }

    /// A panic on any thread reaches the caller, after every thread has
    /// stopped touching the caller's items; the crew works on afterwards.
    #[test]
    fn a_panic_reaches_the_caller() {
        let crew = Crew::new(2).unwrap().unwrap();
        let mut items = vec![0u32; 64];
        let r = std::panic::catch_unwind(AssertUnwindSafe(|| {
            crew.for_each(&mut items, |x, i| {
                assert!(i != 40, "item 40");
                *x = 1;
            });
        }));
        assert!(r.is_err());
        crew.for_each(&mut items, |x, _| *x = 2);
        assert!(items.iter().all(|&x| x == 2));
    }
}
