//! Tests of the dense kernels: the tiled and vector passes against plain
//! references, bit for bit.

use super::*;

/// The reverse pass as it was written before [`dots`], one output at a
/// time: the reference the blocked one is tested against, bit for bit.
#[allow(clippy::too_many_arguments)]
fn backward_one_at_a_time(
    l: &Linear,
    th: &[f64],
    g: &mut [f64],
    a: &[f64],
    c: &[f64],
    r: usize,
    gy: &[f64],
    mut gx: Option<(&mut [f64], &mut [f64])>,
) {
    let na = a.len() / r;
    for j in 0..l.out {
        g[l.b + j] += sum(&gy[j * r..(j + 1) * r]);
    }
    for i in 0..l.inp {
        let xi = if i < na {
            &a[i * r..(i + 1) * r]
        } else {
            &c[(i - na) * r..(i - na + 1) * r]
        };
        for j in 0..l.out {
            g[l.w + i * l.out + j] += dot(xi, &gy[j * r..(j + 1) * r]);
        }
        if let Some((ga, gc)) = gx.as_mut() {
            let gxi = if i < na {
                &mut ga[i * r..(i + 1) * r]
            } else {
                &mut gc[(i - na) * r..(i - na + 1) * r]
            };
            for j in 0..l.out {
                let wv = th[l.w + i * l.out + j];
                for (gv, yv) in gxi.iter_mut().zip(&gy[j * r..(j + 1) * r]) {
                    *gv = wv.mul_add(*yv, *gv);
                }
            }
        }
    }
}

type Backward<'f> = &'f dyn Fn(&Tape, &mut [f64], &mut [f64], &mut [f64]);

/// [`Mlp::forward_any`] with one count of outputs a pass.
type TiledForward = fn(&Mlp, &[f64], (&[f64], &[f64]), usize, bool, &mut Tape, &mut [f64]);

/// The blocked reverse pass of a layer (eight or four outputs per pass, the
/// rest of the input gradients in one pass, the weights of outputs past the
/// blocks four input rows a pass) gives the bits of the one-output-at-a-time
/// pass, for widths that are and are not multiples of four, with and
/// without input gradients, and input gradients written (`set`) give the
/// bits of input gradients added to zeros.
#[test]
fn blocked_backward_gives_the_same_bits() {
    let wave =
        |n: usize, k: f64| -> Vec<f64> { (0..n).map(|i| (k * i as f64 + 0.3).sin()).collect() };
    for (inp, out, r) in [
        (7usize, 16usize, 203usize),
        (48, 16, 97),
        (5, 5, 10),
        (5, 5, 37),
        (3, 9, 1),
        (9, 6, 37),
        (7, 13, 37),
        (6, 11, 37),
        (4, 1, 37),
    ] {
        let l = Linear {
            w: 0,
            b: inp * out,
            inp,
            out,
        };
        let th = wave(inp * out + out, 0.37);
        let na = inp / 2;
        let (a, c) = (wave(na * r, 0.11), wave((inp - na) * r, 0.23));
        let gy = wave(out * r, 0.19);
        let run = |blocked: bool, with_gx: bool| {
            let mut g = wave(th.len(), 0.05);
            let (mut ga, mut gc) = (wave(na * r, 0.07), wave((inp - na) * r, 0.13));
            let gx = with_gx.then_some((&mut ga[..], &mut gc[..]));
            if blocked {
                l.backward(&th, &mut g, &a, &c, r, &gy, gx, false);
            } else {
                backward_one_at_a_time(&l, &th, &mut g, &a, &c, r, &gy, gx);
            }
            (g, ga, gc)
        };
        // Written (`set`) over whatever the buffers held: the bits of
        // accumulating into zeros.
        let set = {
            let mut g = wave(th.len(), 0.05);
            let (mut ga, mut gc) = (vec![f64::NAN; na * r], vec![f64::NAN; (inp - na) * r]);
            l.backward(&th, &mut g, &a, &c, r, &gy, Some((&mut ga, &mut gc)), true);
            let (mut za, mut zc) = (vec![0.0; na * r], vec![0.0; (inp - na) * r]);
            l.backward(&th, &mut g, &a, &c, r, &gy, Some((&mut za, &mut zc)), false);
            let bits = |v: &[f64]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
            (bits(&ga) == bits(&za), bits(&gc) == bits(&zc))
        };
        assert_eq!(
            set,
            (true, true),
            "{inp}x{out}, {r} rows: set against added to zeros"
        );
        for with_gx in [true, false] {
            let (x, y) = (run(true, with_gx), run(false, with_gx));
            let bits = |v: &[f64]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&x.0), bits(&y.0), "{inp}x{out}, {r} rows");
            assert_eq!(bits(&x.1), bits(&y.1), "{inp}x{out}, {r} rows");
            assert_eq!(bits(&x.2), bits(&y.2), "{inp}x{out}, {r} rows");
        }
    }
}

/// The dispatched passes (AVX2 where the CPU has it) give the same bits
/// as the portable build of the same code: vectors only widen the loops.
#[test]
fn vector_build_gives_the_same_bits() {
    let (mlp, off) = mlp_of_sizes(&[7, 16, 16, 3]);
    let wave =
        |n: usize, k: f64| -> Vec<f64> { (0..n).map(|i| (k * i as f64 + 0.3).sin()).collect() };
    let th = wave(off, 0.37);
    let r = 203; // not a multiple of any vector width
    let (a, c) = (wave(4 * r, 0.11), wave(3 * r, 0.23));
    let gy = wave(3 * r, 0.19);
    let run = |fwd: &dyn Fn(&mut Tape, &mut [f64]), bwd: Backward| {
        let mut tape = mlp.tape(r);
        let mut y = vec![0.0; 3 * r];
        fwd(&mut tape, &mut y);
        let (mut g, mut ga, mut gc) = (vec![0.0; off], vec![0.0; 4 * r], vec![0.0; 3 * r]);
        bwd(&tape, &mut g, &mut ga, &mut gc);
        (y, g, ga, gc)
    };
    let w = mlp.width() * r;
    let dispatched = run(
        &|t, y| mlp.forward(&th, &a, &c, r, t, y),
        &|t, g, ga, gc| {
            let (mut s1, mut s2) = (vec![0.0; w], vec![0.0; w]);
            mlp.backward(&th, g, &a, &c, r, t, &gy, Some((ga, gc)), &mut s1, &mut s2)
        },
    );
    let portable = run(
        &|t, y| mlp.forward_any::<OUTS_WIDE>(&th, (&a, &c), (r, 0..r, false), t, Out::new(y, r)),
        &|t, g, ga, gc| {
            let (mut s1, mut s2) = (vec![0.0; w], vec![0.0; w]);
            mlp.backward_any(&th, g, &a, &c, r, t, &gy, Some((ga, gc)), &mut s1, &mut s2)
        },
    );
    assert!(dispatched.0.iter().any(|v| *v != 0.0));
    assert_eq!(dispatched, portable);
    // The tiled pass against the layer-by-layer one: the same outputs
    // and tapes, recording or not, at row counts below, at and around a
    // tile.
    let rows = [
        1,
        4,
        5,
        8,
        9,
        10,
        12,
        13,
        TILE - 1,
        TILE,
        TILE + 1,
        TILE + 5,
        203,
    ];
    for r in rows {
        let (a, c) = (wave(4 * r, 0.11), wave(3 * r, 0.23));
        let (mut want_tape, mut want) = (mlp.tape(r), vec![0.0; 3 * r]);
        mlp.layerwise(&th, &a, &c, r, &mut want_tape, &mut want);
        let (mut tape, mut y) = (mlp.tape(r), vec![0.0; 3 * r]);
        mlp.forward(&th, &a, &c, r, &mut tape, &mut y);
        assert_eq!(y, want, "{r} rows");
        assert_eq!(tape.hidden, want_tape.hidden, "{r} rows: tape");
        let mut yi = vec![0.0; 3 * r];
        mlp.forward(&th, &a, &c, r, &mut mlp.inference_tape(), &mut yi);
        assert_eq!(yi, want, "{r} rows, not recording");
        each_output_count_gives(&mlp, &th, (&a, &c), r, (&want, &want_tape));
    }
}

/// [`vector_build_gives_the_same_bits`] for each path's count of outputs a
/// pass (16 and 3 outputs: blocks and one-output tails), whatever this CPU
/// dispatches to, with the outputs activated too (squareplus block by block
/// in full tiles): the layer-by-layer outputs `want` and tape.
fn each_output_count_gives(
    mlp: &Mlp,
    th: &[f64],
    (a, c): (&[f64], &[f64]),
    r: usize,
    (want, want_tape): (&[f64], &Tape),
) {
    let by_outs: [(usize, TiledForward); 2] = [
        (OUTS_WIDE, |m, th, ac, r, act, t, y| {
            m.forward_any::<OUTS_WIDE>(th, ac, (r, 0..r, act), t, Out::new(y, r));
        }),
        (OUTS_AVX2, |m, th, ac, r, act, t, y| {
            m.forward_any::<OUTS_AVX2>(th, ac, (r, 0..r, act), t, Out::new(y, r));
        }),
    ];
    let mut want_act = want.to_vec();
    squareplus_in_place(&mut want_act);
    for (outs, fwd) in by_outs {
        for (act, want) in [(false, want), (true, &want_act[..])] {
            let (mut tape, mut y) = (mlp.tape(r), vec![0.0; want.len()]);
            fwd(mlp, th, (a, c), r, act, &mut tape, &mut y);
            assert_eq!(y, want, "{r} rows, {outs} outputs a pass, activated: {act}");
            assert_eq!(
                tape.hidden, want_tape.hidden,
                "{r} rows, {outs} outputs: tape"
            );
        }
    }
}

/// An empty parameter-gradient buffer skips the parameters and leaves the
/// input gradients bit for bit as they are with it (planning's reverse pass).
#[test]
fn input_gradients_without_parameter_gradients() {
    let wave =
        |n: usize, k: f64| -> Vec<f64> { (0..n).map(|i| (k * i as f64 + 0.3).sin()).collect() };
    let (inp, out, r) = (9usize, 6usize, 37usize);
    let l = Linear {
        w: 0,
        b: inp * out,
        inp,
        out,
    };
    let th = wave(inp * out + out, 0.37);
    let (a, c) = (wave(4 * r, 0.11), wave((inp - 4) * r, 0.23));
    let gy = wave(out * r, 0.19);
    let run = |with_params: bool| {
        let mut g = if with_params {
            vec![0.0; th.len()]
        } else {
            vec![]
        };
        let (mut ga, mut gc) = (vec![0.0; 4 * r], vec![0.0; (inp - 4) * r]);
        l.backward(&th, &mut g, &a, &c, r, &gy, Some((&mut ga, &mut gc)), false);
        (g, ga, gc)
    };
    let (full, skipped) = (run(true), run(false));
    assert!(full.0.iter().any(|x| *x != 0.0));
    assert!(skipped.0.is_empty());
    let bits = |v: &[f64]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&full.1), bits(&skipped.1));
    assert_eq!(bits(&full.2), bits(&skipped.2));
}

/// The engine's squareplus is within an ulp of the plain formula with
/// either root (the exact one, or an f32 root and two Newton steps) over the
/// whole range, huge and tiny inputs and non-finite ones included, and the
/// dispatched (vector) pass gives the same bits as the portable one.
#[test]
fn fast_squareplus_is_within_an_ulp() {
    for root in [Root::Exact, Root::ViaF32] {
        squareplus_within_an_ulp(root);
    }
    let mut xs: Vec<f64> = (-4000..=4000).map(|i| f64::from(i) * 0.01).collect();
    xs.extend([
        0.0,
        -0.0,
        1e15,
        -1e15,
        9.99e14,
        f64::MAX,
        f64::MIN,
        1e300,
        -1e-300,
    ]);
    let mut v = xs.clone();
    squareplus_in_place(&mut v);
    let portable: Vec<f64> = xs.iter().map(|&x| squareplus_fast(x)).collect();
    let bits = |v: &[f64]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&v), bits(&portable));
}

/// [`fast_squareplus_is_within_an_ulp`] for one root kind.
fn squareplus_within_an_ulp(root: Root) {
    let mut xs: Vec<f64> = (-4000..=4000).map(|i| f64::from(i) * 0.01).collect();
    for e in -300..=300 {
        let x = 10f64.powi(e) * 1.2345;
        xs.extend([x, -x]);
    }
    xs.extend([0.0, -0.0, 1e15, -1e15, 9.99e14, f64::MAX, f64::MIN]);
    let (mut worst, mut checked) = (0u64, 0);
    for &x in &xs {
        // The root itself, against the correctly rounded one.
        let y = x * x + 4.0;
        if y < 1e30 {
            let fast = match root {
                Root::Exact => y.sqrt(),
                Root::ViaF32 => sqrt_via_f32(y),
            };
            let exact = y.sqrt();
            worst = worst.max(fast.to_bits().abs_diff(exact.to_bits()));
            checked += 1;
        }
        let (fast, plain) = (squareplus_by(root, x), crate::gnode::mlp::squareplus_f64(x));
        if !plain.is_finite() {
            // x² overflowed: the plain formula says ∞ where the value is x
            // (x > 0) or about 1/|x| (x < 0); the engine's is right.
            let want = if x > 0.0 { x } else { 0.0 };
            assert!(
                (fast - want).abs() <= f64::EPSILON * want,
                "{x:e}: {fast:e}"
            );
            continue;
        }
        let tol = 2.0 * f64::EPSILON * plain.abs().max(f64::MIN_POSITIVE);
        // Large negative x: both cancel the same way; compare in absolute
        // terms against the root's size there.
        let scale = (x * x + 4.0).sqrt().min(f64::MAX);
        assert!(
            (fast - plain).abs() <= tol.max(2.0 * f64::EPSILON * scale),
            "squareplus({x:e}): {fast:e} against {plain:e}"
        );
    }
    assert!(checked > 8000);
    assert!(worst <= 1, "{root:?}: the root is {worst} ulps off");
    assert!(squareplus_by(root, f64::NAN).is_nan());
    assert_eq!(squareplus_by(root, f64::INFINITY), f64::INFINITY);
}

/// [`dots`] of 4 and of 8 vectors (AVX2 registers where the CPU has them)
/// gives the bits of as many portable [`dot`]s, at every length (the tail
/// included).
#[test]
fn dots_give_the_bits_of_dot() {
    for n in 0..41 {
        let v = |k: usize| -> Vec<f64> {
            (0..n)
                .map(|i| ((i * 7 + k * 13) as f64 * 0.37).sin() * 10f64.powi((i % 5) as i32 - 2))
                .collect()
        };
        let a = v(0);
        let b: Vec<Vec<f64>> = (1..9).map(v).collect();
        let four = dot4(&a, std::array::from_fn(|j| &b[j][..]));
        let eight: [f64; 8] = dots(&a, std::array::from_fn(|j| &b[j][..]));
        for (j, bj) in b.iter().enumerate() {
            let want = dot(&a, bj).to_bits();
            assert_eq!(
                eight[j].to_bits(),
                want,
                "8 vectors, length {n}, output {j}"
            );
            if j < 4 {
                assert_eq!(four[j].to_bits(), want, "4 vectors, length {n}, output {j}");
            }
        }
    }
}

/// `MCGNODE_ROOT` picks either root kind, and a value it does not know
/// leaves the CPU's choice.
#[test]
fn the_environment_picks_the_root() {
    assert_eq!(chosen_root(Root::ViaF32, None), Root::ViaF32);
    assert_eq!(chosen_root(Root::Exact, Some("")), Root::Exact);
    assert_eq!(chosen_root(Root::ViaF32, Some("exact")), Root::Exact);
    assert_eq!(chosen_root(Root::Exact, Some("f32")), Root::ViaF32);
    assert_eq!(chosen_root(Root::Exact, Some("fast")), Root::Exact);
}

/// `MCGNODE_SIMD` narrows the path, never widens it, and a value it does
/// not know leaves the widest path.
#[test]
fn the_environment_narrows_the_vector_path() {
    use Simd::{Avx2, Avx512, Portable};
    assert_eq!(chosen(Avx512, None), Avx512);
    assert_eq!(chosen(Avx512, Some("avx2")), Avx2);
    assert_eq!(chosen(Avx512, Some("portable")), Portable);
    assert_eq!(chosen(Avx2, Some("avx512")), Avx2);
    assert_eq!(chosen(Portable, Some("avx2")), Portable);
    assert_eq!(chosen(Avx2, Some("sse")), Avx2);
}
