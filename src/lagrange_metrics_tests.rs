//! Unit tests of `lagrange_metrics` against computations made another way:
//! closed forms for MSE and E_kin, the primal entropic problem for Sinkhorn.

use super::*;

/// A trajectory of `frames + 1` frames of `n` particles in 2-D from `f`.
fn traj(frames: usize, n: usize, f: impl Fn(usize, usize, usize) -> f64) -> Vec<Vec<f64>> {
    (0..=frames)
        .map(|k| (0..n * 2).map(|c| f(k, c / 2, c % 2)).collect())
        .collect()
}

fn view(t: &[Vec<f64>]) -> Frames<'_> {
    Frames {
        q: t.iter().map(Vec::as_slice).collect(),
    }
}

fn close(a: f64, b: f64, rel: f64) {
    assert!((a - b).abs() <= rel * b.abs().max(1e-300), "{a} vs {b}");
}

#[test]
fn mse_is_the_mean_over_frames_of_the_squared_offset() {
    // Predicted frame k is the truth shifted by k·c in x only: its MSE is
    // (k c)² / 2 (one of two dimensions), so MSE_K = c²/2 · mean(k²).
    let c = 0.01;
    let truth = traj(25, 7, |k, i, a| (i + a) as f64 + 0.1 * k as f64);
    let pred = traj(25, 7, |k, i, a| {
        (i + a) as f64 + 0.1 * k as f64 + if a == 0 { c * k as f64 } else { 0.0 }
    });
    let m = trajectory_metrics(&view(&truth), &view(&pred), 2, 0.1, 1.0).unwrap();
    let want = |kk: usize| c * c / 2.0 * (1..=kk).map(|k| (k * k) as f64).sum::<f64>() / kk as f64;
    close(m.mse5.unwrap(), want(5), 1e-12);
    close(m.mse10.unwrap(), want(10), 1e-12);
    close(m.mse20.unwrap(), want(20), 1e-12);
    assert_eq!(m.frames, HORIZON);
}

#[test]
fn short_rollouts_leave_the_longer_horizons_out() {
    let truth = traj(7, 3, |k, i, a| (i * 2 + a) as f64 + k as f64);
    let m = trajectory_metrics(&view(&truth), &view(&truth), 2, 1.0, 1.0).unwrap();
    assert_eq!(
        (m.mse5, m.mse10, m.mse20, m.frames),
        (Some(0.0), None, None, 7)
    );
    assert!(m.sinkhorn.abs() < 1e-12, "{}", m.sinkhorn);
    let one = traj(0, 3, |_, i, a| (i + a) as f64);
    assert_eq!(
        trajectory_metrics(&view(&one), &view(&one), 2, 1.0, 1.0),
        Err(LagrangeError::NoFrames)
    );
}

#[test]
fn kinetic_energy_of_uniform_motion_against_standing_still() {
    // Every particle moves by u per frame interval h: E_kin = dx² N |u/h|²
    // per frame pair; a prediction that stands still has E_kin 0.
    let (n, u, h, dx) = (9, (0.03, -0.04), 0.5, 0.2);
    let truth = traj(20, n, |k, i, a| {
        i as f64 + k as f64 * if a == 0 { u.0 } else { u.1 }
    });
    let still = traj(20, n, |_, i, _| i as f64);
    let e = dx * dx * n as f64 * (u.0 * u.0 + u.1 * u.1) / (h * h);
    let m = trajectory_metrics(&view(&truth), &view(&still), 2, h, dx).unwrap();
    close(m.e_kin_mse.unwrap(), e * e, 1e-12);
}

#[test]
fn sinkhorn_of_single_points_is_their_squared_distance() {
    let s = sinkhorn_divergence(&[0.0, 0.0], &[0.3, 0.4], 2).unwrap();
    close(s, 0.25, 1e-12);
}

/// The primal entropic cost of two points against two, uniform weights:
/// min over P = [[p, ½−p], [½−p, p]] of ⟨P, C⟩ + ε KL(P | ab^T), found by
/// golden-section search on p (the problem is convex in p).
fn primal_2x2(c: [[f64; 2]; 2], eps: f64) -> f64 {
    let obj = |p: f64| {
        let q = 0.5 - p;
        let kl = |x: f64| x * (x / 0.25).ln();
        p * (c[0][0] + c[1][1]) + q * (c[0][1] + c[1][0]) + eps * (2.0 * kl(p) + 2.0 * kl(q))
    };
    let (mut lo, mut hi) = (1e-300, 0.5 - 1e-16);
    let r = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..200 {
        let (a, b) = (hi - r * (hi - lo), lo + r * (hi - lo));
        if obj(a) < obj(b) {
            hi = b;
        } else {
            lo = a;
        }
    }
    obj(0.5 * (lo + hi))
}

#[test]
fn sinkhorn_of_two_points_matches_the_primal_problem() {
    let x = [0.0, 0.0, 1.0, 0.2];
    let y = [0.1, -0.3, 0.7, 0.9];
    let d2 = |p: &[f64], q: &[f64], i: usize, j: usize| {
        (p[2 * i] - q[2 * j]).powi(2) + (p[2 * i + 1] - q[2 * j + 1]).powi(2)
    };
    let c = |p: &[f64], q: &[f64]| {
        [
            [d2(p, q, 0, 0), d2(p, q, 0, 1)],
            [d2(p, q, 1, 0), d2(p, q, 1, 1)],
        ]
    };
    let cxy = c(&x, &y);
    let eps = 0.05 * (cxy[0][0] + cxy[0][1] + cxy[1][0] + cxy[1][1]) / 4.0;
    let want =
        primal_2x2(cxy, eps) - 0.5 * (primal_2x2(c(&x, &x), eps) + primal_2x2(c(&y, &y), eps));
    close(sinkhorn_divergence(&x, &y, 2).unwrap(), want, 1e-8);
}

#[test]
fn sinkhorn_is_symmetric_positive_and_zero_on_equal_clouds() {
    let x: Vec<f64> = (0..40)
        .map(|k| (f64::from(k * 37 % 11) * 0.13).sin())
        .collect();
    let y: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(k, v)| v + 0.05 * (k as f64).cos())
        .collect();
    let (a, b) = (
        sinkhorn_divergence(&x, &y, 2).unwrap(),
        sinkhorn_divergence(&y, &x, 2).unwrap(),
    );
    assert!(a > 0.0, "{a}");
    close(a, b, 1e-7); // each converged to a marginal error of 1e-8
    assert!(sinkhorn_divergence(&x, &x, 2).unwrap().abs() < 1e-12);
}

#[test]
fn averages_are_plain_means_and_drop_missing_horizons() {
    let m = |mse5: f64, mse20: Option<f64>| LagrangeMetrics {
        mse5: Some(mse5),
        mse10: Some(mse5),
        mse20,
        sinkhorn: mse5,
        e_kin_mse: Some(2.0 * mse5),
        frames: if mse20.is_some() { 20 } else { 12 },
    };
    let a = average(&[m(1.0, Some(1.0)), m(3.0, None)]).unwrap();
    assert_eq!(
        (a.mse5, a.mse20, a.sinkhorn, a.e_kin_mse, a.frames),
        (Some(2.0), None, 2.0, Some(4.0), 12)
    );
    assert!(average(&[]).is_none());
}

#[test]
fn bad_input_is_refused_with_what_is_wrong() {
    let t = traj(3, 2, |k, i, a| (k + i + a) as f64);
    let mut p = t.clone();
    p[2][1] = f64::NAN;
    let e = trajectory_metrics(&view(&t), &view(&p), 2, 1.0, 1.0).unwrap_err();
    assert!(e.to_string().contains("position"), "{e}");
    let e = trajectory_metrics(&view(&t), &view(&t[..2]), 2, 1.0, 1.0).unwrap_err();
    assert!(e.to_string().contains("predicted frames"), "{e}");
    let e = trajectory_metrics(&view(&t), &view(&t), 2, 1.0, 0.0).unwrap_err();
    assert!(e.to_string().contains("dx"), "{e}");
}
