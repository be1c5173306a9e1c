//! Second derivatives in candle.
//!
//! Candle's backward pass detaches every gradient it produces (so gradients
//! carry no graph and cannot be differentiated again) unless the environment
//! variable `CANDLE_GRAD_DO_NOT_DETACH` is set to a non-empty value other than
//! `"0"`. Candle reads it once per thread, lazily, the first time a backward
//! pass runs on that thread. LGN and HGN differentiate a learned scalar and
//! then train on the derivative, so they need grad-of-grad: they call
//! [`ensure_second_order`] before every use, which sets the variable when it is
//! unset and then checks, on the calling thread, that a second derivative
//! really comes out (a thread that ran a backward pass before the variable was
//! set keeps the old behaviour for its lifetime, and that must be an error, not
//! silently zero gradients).

use crate::error::{bail, Result};
use candle_core::{Device, Tensor, Var};
use std::cell::Cell;

/// The variable candle reads.
pub const DO_NOT_DETACH: &str = "CANDLE_GRAD_DO_NOT_DETACH";

thread_local! {
    /// Whether the probe passed on this thread (candle's setting is per thread and fixed).
    static CHECKED: Cell<bool> = const { Cell::new(false) };
}

/// Sets `CANDLE_GRAD_DO_NOT_DETACH=1` if it is unset. An explicit value is left
/// alone (so `0` is respected, and [`ensure_second_order`] then reports it).
///
/// `set_var` is not synchronised with concurrent `getenv` calls on other
/// threads; it is done once, when the first LGN/HGN is built or used.
pub fn request_second_order() {
    if std::env::var_os(DO_NOT_DETACH).is_none() {
        std::env::set_var(DO_NOT_DETACH, "1");
    }
}

/// d²/dx² of x³ = exp(3 ln x) at x = 2 (exact: 6x = 12), computed by
/// differentiating candle's gradient; `None` when the second backward pass
/// yields no gradient at all.
///
/// x³ is written as a chain of ops on purpose: when candle detaches, the
/// gradient flowing *between* ops loses its graph, so only the last op's local
/// factor stays differentiable and the result is wrong (−6 here: d/dx of
/// 24/x with 24 frozen), not merely missing. A single `powf` would hide this.
pub fn probe_second_derivative() -> Result<Option<f64>> {
    let x = Var::from_tensor(&Tensor::new(&[2.0f64], &Device::Cpu)?)?;
    let y = (x.as_tensor().log()? * 3.0)?.exp()?.sum_all()?;
    let g = y.backward()?;
    let Some(dy) = g.get(x.as_tensor()) else {
        bail!("candle produced no first derivative of x³");
    };
    let g2 = dy.sum_all()?.backward()?;
    Ok(match g2.get(x.as_tensor()) {
        Some(t) => Some(t.flatten_all()?.to_vec1::<f64>()?[0]),
        None => None,
    })
}

/// Makes sure second derivatives work on the calling thread: requests them
/// (`request_second_order`) and proves it once per thread with
/// [`probe_second_derivative`] (d²x³/dx² = 6x = 12 at x = 2).
pub fn ensure_second_order() -> Result<()> {
    if CHECKED.with(std::cell::Cell::get) {
        return Ok(());
    }
    request_second_order();
    match probe_second_derivative()? {
        Some(v) if (v - 12.0).abs() < 1e-9 => {
            CHECKED.with(|c| c.set(true));
            Ok(())
        }
        got => bail!(
            "second derivatives are unavailable on this thread (probe gave {got:?}, expected 12): \
             candle detaches gradients unless {DO_NOT_DETACH}=1 is set before the thread's first \
             backward pass; start the program with {DO_NOT_DETACH}=1"
        ),
    }
}

/// Gradient of a scalar `root` with respect to each of `vars` (zeros when the
/// root does not depend on one). With second order enabled the gradients keep
/// their graph, so they can be differentiated again.
pub fn grads(root: &Tensor, vars: &[&Var]) -> Result<Vec<Tensor>> {
    let g = root.backward()?;
    vars.iter()
        .map(|v| {
            Ok(match g.get(v.as_tensor()) {
                Some(t) => t.clone(),
                None => v.as_tensor().zeros_like()?,
            })
        })
        .collect()
}

/// Per-sample Hessian blocks of `f` with respect to `x`: `g` is ∂f/∂x
/// `(B·n, d)` (with graph), samples independent; returns `(B, D, D)`, entry
/// `[b, j, i] = ∂g_j/∂x_i` for sample `b` (D = n·d). One backward pass per
/// coordinate: column j of every sample's Hessian at once.
pub fn hessian(g: &Tensor, x: &Var, b: usize) -> Result<Tensor> {
    let total = g.elem_count();
    let dd = total / b.max(1);
    let gb = g.reshape((b, dd))?;
    let mut rows = Vec::with_capacity(dd);
    for j in 0..dd {
        let root = gb.narrow(1, j, 1)?.sum_all()?;
        rows.push(grads(&root, &[x])?.remove(0).reshape((b, dd))?);
    }
    Ok(Tensor::stack(&rows, 1)?)
}
