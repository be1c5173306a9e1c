//! One graph's MLP rows on two cores: inference on a large graph (the node's
//! 1,000-particle contact states) hands the second half of each edge MLP's
//! rows to a helper thread kept for the workspace. Training and batched
//! rollouts already fill the cores with states, so they never split.
//!
//! A job passes no allocation: the helper runs a closure on the caller's
//! stack, which the caller does not leave before the helper is done (the
//! scoped-join pattern). Between jobs the helper spins briefly (a step's
//! MLPs come fractions of a millisecond apart), then parks.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::dense::{squareplus_in_place, Mlp, Out, Tape};

/// Rows below which an MLP is not split: the hand-over costs about a
/// microsecond, a 16-wide edge MLP about 60 ns a row.
pub const SPLIT_ROWS: usize = 1024;

/// Rows a thread takes at a time (a multiple of the 16-row tile).
const BLOCK: usize = 1024;

/// How long the helper waits for the next job before parking.
const SPIN: Duration = Duration::from_micros(200);

/// The helper's half of a join: a closure on the caller's stack.
#[derive(Clone, Copy)]
struct Job(*mut (dyn FnMut() + Send));

/// What caller and helper share.
struct Shared {
    /// The job of the latest post; read by the helper after `posted` moves.
    job: Mutex<Option<Job>>,
    posted: AtomicU64,
    finished: AtomicU64,
    panicked: AtomicBool,
    exit: AtomicBool,
}

// SAFETY: `Job` points at a closure that is `Send`; the caller keeps it alive
// and untouched until `finished` says the helper is done with it.
unsafe impl Send for Shared {}
// SAFETY: as for Send; the pointer itself is behind a mutex.
unsafe impl Sync for Shared {}

/// A second thread for one workspace's row halves.
pub(crate) struct Helper {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

impl Helper {
    /// Starts the thread; `None` if the system refuses one (then nothing
    /// is split).
    fn start() -> Option<Self> {
        let shared = Arc::new(Shared {
            job: Mutex::new(None),
            posted: AtomicU64::new(0),
            finished: AtomicU64::new(0),
            panicked: AtomicBool::new(false),
            exit: AtomicBool::new(false),
        });
        let theirs = shared.clone();
        let thread = std::thread::Builder::new()
            .name("mcgnode-rows".into())
            .spawn(move || serve(&theirs))
            .ok()?;
        Some(Self {
            shared,
            thread: Some(thread),
        })
    }

    /// Runs `mine` here and `theirs` on the helper, and returns when both
    /// are done (a panic in `theirs` is raised here).
    fn join(&self, mine: impl FnOnce(), theirs: &mut (dyn FnMut() + Send)) {
        let sh = &self.shared;
        // SAFETY (of the helper's use): `theirs` outlives this call, which
        // waits below until the helper has finished with it.
        let job: *mut (dyn FnMut() + Send + '_) = theirs;
        // Only the lifetime changes, which a pointer cast cannot do.
        #[allow(clippy::missing_transmute_annotations, clippy::transmute_ptr_to_ptr)]
        // SAFETY: only the lifetime is erased (see above).
        let job = Job(unsafe { std::mem::transmute(job) });
        *sh.job
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(job);
        let n = sh.posted.fetch_add(1, Ordering::Release) + 1;
        if let Some(t) = &self.thread {
            t.thread().unpark();
        }
        mine();
        let mut spins = 0u32;
        while sh.finished.load(Ordering::Acquire) < n {
            spins += 1;
            if spins < 1 << 14 {
                std::hint::spin_loop();
            } else {
                // The helper was not scheduled: give it the core.
                std::thread::yield_now();
            }
        }
        assert!(
            !sh.panicked.load(Ordering::Acquire),
            "the helper thread's half of an MLP panicked"
        );
    }
}

/// The helper's loop: wait for a post, run its job, say it is done.
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
        let job = *sh
            .job
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(Job(f)) = job {
            // SAFETY: the poster waits for `finished` before the closure
            // goes out of scope, and nobody else calls it meanwhile.
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

/// Whether the machine has a second core for the helper.
fn second_core() -> bool {
    std::thread::available_parallelism().is_ok_and(|n| n.get() > 1)
}

/// A chunk's means of splitting: off unless enabled, the helper started on
/// the first large MLP. A clone is off: batched rollouts clone a workspace
/// per core, which are busy already.
#[derive(Default)]
pub(crate) struct Split {
    enabled: bool,
    helper: Option<Helper>,
    /// The helper's tile scratch (sized by `Tape::fit`).
    tape: Tape,
}

impl Clone for Split {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl std::fmt::Debug for Split {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Split")
            .field("enabled", &self.enabled)
            .field("started", &self.helper.is_some())
            .finish_non_exhaustive()
    }
}

impl Split {
    /// Splits large MLPs from now on (when the machine has a second core).
    pub(crate) fn enable(&mut self) {
        self.enabled = second_core();
    }

    /// `y = mlp([a; c])` over `r` rows without recording, then squareplus
    /// on `y` when `activate` is set: the second half of the rows on the
    /// helper when there are enough, the same bits either way.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn forward(
        &mut self,
        mlp: &Mlp,
        th: &[f64],
        (a, c): (&[f64], &[f64]),
        r: usize,
        tape: &mut Tape,
        y: &mut [f64],
        activate: bool,
    ) {
        if !self.enabled || r < SPLIT_ROWS || tape.records() {
            mlp.forward(th, a, c, r, tape, y);
            if activate {
                squareplus_in_place(y);
            }
            return;
        }
        if self.helper.is_none() {
            self.helper = Helper::start();
        }
        let Some(helper) = &self.helper else {
            self.enabled = false;
            return self.forward(mlp, th, (a, c), r, tape, y, activate);
        };
        self.tape.fit(mlp);
        // Both threads take blocks of rows in turn until none is left, so
        // that a slower core (a busy neighbour) does less. Blocks start on
        // tile boundaries: the tiles are those of the whole pass.
        let next = AtomicUsize::new(0);
        let out = Out::new(y, r);
        let work = |tape: &mut Tape| loop {
            let lo = next.fetch_add(1, Ordering::Relaxed) * BLOCK;
            if lo >= r {
                break;
            }
            // SAFETY: each block of rows is taken by one thread only.
            unsafe { mlp.forward_part(th, (a, c), r, lo..r.min(lo + BLOCK), tape, out, activate) };
        };
        let spare = &mut self.tape;
        let mut theirs = || work(spare);
        let mine = || work(tape);
        helper.join(mine, &mut theirs);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::dense::mlp_of_sizes;

    /// An MLP of these sizes and smooth parameter values.
    fn mlp(sizes: &[usize]) -> (Mlp, Vec<f64>) {
        let (m, len) = mlp_of_sizes(sizes);
        (m, (0..len).map(|i| (0.37 * i as f64 + 0.3).sin()).collect())
    }

    /// Split or not, with the activation or without, the same bits as the
    /// one-thread pass followed by squareplus, join after join (row counts
    /// that are and are not multiples of a tile or block).
    #[test]
    fn split_rows_give_the_same_bits() {
        let (m, th) = mlp(&[3, 16, 16, 5]);
        let mut split = Split::default();
        split.enable();
        let mut tape = m.inference_tape();
        for r in [SPLIT_ROWS - 1, SPLIT_ROWS, 3001, 6144] {
            let a: Vec<f64> = (0..2 * r).map(|i| (0.11 * i as f64).cos()).collect();
            let c: Vec<f64> = (0..r).map(|i| (0.23 * i as f64).sin()).collect();
            for activate in [false, true] {
                let mut want = vec![0.0; 5 * r];
                m.forward(&th, &a, &c, r, &mut tape, &mut want);
                if activate {
                    squareplus_in_place(&mut want);
                }
                for _ in 0..50 {
                    let mut got = vec![f64::NAN; 5 * r];
                    split.forward(&m, &th, (&a, &c), r, &mut tape, &mut got, activate);
                    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&got), bits(&want), "{r} rows, activate {activate}");
                }
            }
        }
        assert_eq!(split.helper.is_some(), second_core());
        // A clone does not split (one per core would oversubscribe them).
        assert!(!split.clone().enabled);
    }
}
