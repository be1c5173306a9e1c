//! One graph's MLP rows on two cores: inference on a large graph (the node's
//! 1,000-particle contact states) hands the second half of each edge MLP's
//! rows to a helper thread kept for the workspace ([`super::crew`]).
//! Training and batched rollouts already fill the cores with states, so
//! they never split.

use std::ops::Range;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, PoisonError};

use super::crew::Helper;
use super::dense::{squareplus_in_place, Mlp, Out, Tape};

/// Rows below which an MLP is not split: the hand-over costs about a
/// microsecond, a 16-wide edge MLP about 60 ns a row.
pub const SPLIT_ROWS: usize = 1024;

/// Rows a thread takes at a time (a multiple of the 16-row tile).
const BLOCK: usize = 1024;

/// Whether the machine has a second core for the helper.
fn second_core() -> bool {
    super::cores::all_cores() > 1
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
    /// The helper's scratch for [`Split::blocks`].
    scratch: Scratch,
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
        let split = !tape.records() && self.ready(r);
        let (true, Some(helper)) = (split, &self.helper) else {
            mlp.forward(th, a, c, r, tape, y);
            if activate {
                squareplus_in_place(y);
            }
            return;
        };
        self.tape.fit(mlp);
        let out = Out::new(y, r);
        let work = |rows: Range<usize>, tape: &mut Tape| {
            // SAFETY: each block of rows is taken by one thread only.
            unsafe { mlp.forward_part(th, (a, c), r, rows, tape, out, activate) };
        };
        share(helper, r, BLOCK, (tape, &mut self.tape), &work);
    }

    /// Whether `r` rows go to both threads: splitting is on and there are
    /// enough, the helper started on first need (if it cannot start,
    /// splitting turns off).
    fn ready(&mut self, r: usize) -> bool {
        let wanted = |s: &Self| s.enabled && r >= SPLIT_ROWS;
        if wanted(self) && self.helper.is_none() {
            self.helper = Helper::start().ok();
            self.enabled = self.helper.is_some();
        }
        wanted(self)
    }

    /// `work(rows, scratch)` over the rows `0..r` in blocks of `block` (a
    /// multiple of the 16-row tile), in order on this thread, or on both
    /// threads when there are enough; `mine` is this thread's scratch, the
    /// helper's is kept here. `work` must write each block's rows alone.
    pub(crate) fn blocks(
        &mut self,
        r: usize,
        block: usize,
        mine: &mut Scratch,
        work: &(dyn Fn(Range<usize>, &mut Scratch) + Sync),
    ) {
        match (self.ready(r), &self.helper) {
            (true, Some(helper)) => share(helper, r, block, (mine, &mut self.scratch), work),
            _ => (0..r)
                .step_by(block.max(1))
                .for_each(|lo| work(lo..r.min(lo + block), mine)),
        }
    }
}

/// One thread's buffers for [`Split::blocks`]: an MLP tile's scratch and a
/// block's intermediate rows.
#[derive(Clone, Debug, Default)]
pub(crate) struct Scratch {
    pub(crate) tape: Tape,
    pub(crate) rows: [Vec<f64>; 3],
}

/// Both threads take blocks of `block` rows of `0..r` in turn until none
/// is left, so that a slower core (a busy neighbour) does less; this thread
/// works with `mine`, the helper with `spare`. Blocks start on tile
/// boundaries: the tiles are those of the whole pass.
fn share<S: Send>(
    helper: &Helper,
    r: usize,
    block: usize,
    (mine, spare): (&mut S, &mut S),
    work: &(dyn Fn(Range<usize>, &mut S) + Sync),
) {
    let next = AtomicUsize::new(0);
    let run = |s: &mut S| loop {
        let lo = next.fetch_add(1, Ordering::Relaxed) * block;
        if lo >= r {
            break;
        }
        work(lo..r.min(lo + block), s);
    };
    // Only the helper takes the spare (an uncontended lock).
    let spare = Mutex::new(spare);
    let theirs = || run(&mut spare.lock().unwrap_or_else(PoisonError::into_inner));
    helper.join(|| run(mine), &theirs);
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
