//! Mapping-loss tests: the fused kernel against its plane-by-plane reference twin on random
//! images (every SIMD level, several band splits), and its gradient against central finite
//! differences of an independent f64 loss (direct 11×11 window, no separable blur).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::cpu::{cap_level, SimdLevel};
use crate::loss::{Loss, LossValue, LossWeights};
use crate::reference::loss_reference;
use crate::ssim::{SSIM_C1, SSIM_C2};
use crate::target::TargetFrame;

/// Fast vs reference: loss terms to this relative error, each gradient entry to this
/// fraction of the largest |reference gradient| of its kind (colour, depth).
const VALUE_TOL: f64 = 1e-5;
const GRAD_TOL: f64 = 1e-5;

struct Case {
    target: TargetFrame,
    color: Vec<[f32; 3]>,
    depth: Vec<f32>,
}

/// A random target (every 5th depth invalid, a few exact ties with the render) and a render
/// that is the target plus noise of amplitude `noise` (1: unrelated images), colour a bit
/// outside [0, 1] in places as a render can be.
fn case(seed: u64, w: u32, h: u32, noise: f32) -> Case {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = (w * h) as usize;
    let rgb: Vec<[f32; 3]> = (0..n)
        .map(|_| std::array::from_fn(|_| rng.gen_range(0.0..1.0)))
        .collect();
    let tdepth: Vec<f32> = (0..n)
        .map(|i| {
            if i % 5 == 0 {
                0.0
            } else {
                rng.gen_range(0.5..4.0)
            }
        })
        .collect();
    let color = rgb
        .iter()
        .enumerate()
        .map(|(i, p)| {
            if i % 97 == 3 {
                *p // exact tie: L1 subgradient 0
            } else {
                p.map(|v| v + noise * rng.gen_range(-1.0..1.1f32))
            }
        })
        .collect();
    let depth = tdepth
        .iter()
        .map(|&d| (d + noise * rng.gen_range(-1.0..1.0f32)).max(0.0))
        .collect();
    Case {
        target: TargetFrame::from_rgb_f32(w, h, &rgb, &tdepth),
        color,
        depth,
    }
}

fn rel(a: f32, b: f32) -> f64 {
    (a as f64 - b as f64).abs() / (b as f64).abs().max(1e-6)
}

fn assert_close(fast: &LossValue, slow: &LossValue, what: &str) {
    for (name, a, b) in [
        ("total", fast.total, slow.total),
        ("l1", fast.l1, slow.l1),
        ("ssim", fast.ssim, slow.ssim),
        ("depth_l1", fast.depth_l1, slow.depth_l1),
        ("psnr", fast.psnr, slow.psnr),
    ] {
        assert!(
            rel(a, b) < VALUE_TOL,
            "{what}: {name} fast {a} reference {b}"
        );
    }
}

/// Largest |a − b| over the largest |b|.
fn worst<const K: usize>(a: &[[f32; K]], b: &[[f32; K]]) -> f64 {
    let scale = b
        .iter()
        .flatten()
        .fold(0.0f64, |m, &v| m.max(v.abs() as f64));
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .fold(0.0f64, |m, (&x, &y)| m.max((x as f64 - y as f64).abs()))
        / scale.max(1e-30)
}

fn eval_fast(c: &Case, loss: &mut Loss) -> (LossValue, Vec<[f32; 3]>, Vec<f32>) {
    eval_with(c, loss, &LossWeights::default())
}

fn eval_with(c: &Case, loss: &mut Loss, w: &LossWeights) -> (LossValue, Vec<[f32; 3]>, Vec<f32>) {
    let (mut gc, mut gd) = (Vec::new(), Vec::new());
    let v = loss.eval(&c.color, &c.depth, &c.target, w, &mut gc, &mut gd);
    (v, gc, gd)
}

/// The loss's exact gradient everywhere (colour held nowhere).
fn exact() -> LossWeights {
    LossWeights {
        colour_needs_depth: false,
        ..LossWeights::default()
    }
}

#[test]
fn colour_without_target_depth_is_held_and_the_rest_is_unchanged() {
    let c = case(7, 67, 41, 0.3);
    let (held, gc_held, gd_held) = eval_fast(&c, &mut Loss::new());
    let (free, gc_free, gd_free) = eval_with(&c, &mut Loss::new(), &exact());
    assert_eq!(held, free, "the value is the whole image's either way");
    assert_eq!(gd_held, gd_free);
    let mut held_pixels = 0;
    for (p, (h, f)) in gc_held.iter().zip(&gc_free).enumerate() {
        if c.target.depth[p] > 0.0 {
            assert_eq!(h, f, "pixel {p} has depth: its gradient is the loss's");
        } else {
            assert_eq!(*h, [0.0; 3], "pixel {p} has no depth: its colour is held");
            held_pixels += usize::from(f.iter().any(|&g| g != 0.0));
        }
    }
    // Every 5th pixel lacks depth; nearly all of them had a colour gradient to hold.
    assert!(held_pixels > 67 * 41 / 5 - 20, "{held_pixels} held");
}

#[test]
fn fused_loss_matches_reference_on_random_images() {
    // Sizes: narrower and lower than the window, odd, several bands, the bench's half size.
    let sizes = [(5, 3), (13, 7), (24, 20), (67, 41), (101, 131), (320, 240)];
    let mut loss = Loss::new();
    for level in SimdLevel::available() {
        cap_level(Some(level));
        for (k, &(w, h)) in sizes.iter().enumerate() {
            for (noise, weights) in [(1.0, LossWeights::default()), (0.02, exact())] {
                let c = case(10 + k as u64, w, h, noise);
                let (v, gc, gd) = eval_with(&c, &mut loss, &weights);
                let (mut rc, mut rd) = (Vec::new(), Vec::new());
                let r = loss_reference(&c.color, &c.depth, &c.target, &weights, &mut rc, &mut rd);
                let what = format!(
                    "{level:?} {w}x{h} noise {noise} colour held {}",
                    weights.colour_needs_depth
                );
                assert_close(&v, &r, &what);
                let gdw: Vec<[f32; 1]> = gd.iter().map(|&v| [v]).collect();
                let rdw: Vec<[f32; 1]> = rd.iter().map(|&v| [v]).collect();
                let (ec, ed) = (worst(&gc, &rc), worst(&gdw, &rdw));
                assert!(ec < GRAD_TOL, "{what}: colour gradient off by {ec}");
                assert!(ed < GRAD_TOL, "{what}: depth gradient off by {ed}");
                for (i, (a, b)) in gd.iter().zip(&rd).enumerate() {
                    assert_eq!(*a == 0.0, *b == 0.0, "{what}: depth mask at {i}");
                }
            }
        }
        cap_level(None);
    }
}

#[test]
fn band_split_changes_no_gradient() {
    // Each pixel's arithmetic is the same whichever band computes it: bit-identical
    // gradients on 1, 2 and 5 threads (5 bands of 48 rows, 4 of 64, ... at 240 rows).
    let c = case(4, 96, 240, 0.1);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| eval_fast(&c, &mut Loss::new()))
    };
    let (v1, gc1, gd1) = run(1);
    for threads in [2, 5] {
        let (v, gc, gd) = run(threads);
        assert!(gc == gc1 && gd == gd1, "{threads} threads");
        assert_close(&v, &v1, &format!("{threads} threads"));
    }
}

#[test]
fn reused_buffers_give_the_same_result_after_a_size_change() {
    let mut loss = Loss::new();
    let big = case(5, 64, 60, 0.3);
    let small = case(6, 30, 20, 0.3);
    let first = eval_fast(&small, &mut loss);
    eval_fast(&big, &mut loss);
    let again = eval_fast(&small, &mut loss);
    assert_eq!(first.1, again.1);
    assert_eq!(first.2, again.2);
    assert_eq!(first.0, again.0);
}

/// The loss in f64, written independently: the 2D window as the outer product of the 1D
/// Gaussian (σ = 1.5, radius 5), summed directly over the zero-padded image.
fn loss64(w: usize, h: usize, x: &[[f64; 3]], d: &[f64], t: &TargetFrame) -> f64 {
    let g1: Vec<f64> = (0..11)
        .map(|i| (-((i as f64 - 5.0).powi(2)) / (2.0 * 1.5 * 1.5)).exp())
        .collect();
    let s: f64 = g1.iter().sum();
    let g1: Vec<f64> = g1.iter().map(|v| v / s).collect();
    let n = w * h;
    let (c1, c2) = (SSIM_C1 as f64, SSIM_C2 as f64);
    let (mut l1, mut ssim) = (0.0, 0.0);
    for c in 0..3 {
        let y = |p: usize| t.rgb[c][p] as f64;
        l1 += x
            .iter()
            .zip(&t.rgb[c])
            .map(|(a, &b)| (a[c] - b as f64).abs())
            .sum::<f64>();
        for py in 0..h as isize {
            for px in 0..w as isize {
                let mut m = [0.0f64; 5];
                for dy in -5..=5isize {
                    for dx in -5..=5isize {
                        let (qx, qy) = (px + dx, py + dy);
                        if qx < 0 || qy < 0 || qx >= w as isize || qy >= h as isize {
                            continue;
                        }
                        let q = qy as usize * w + qx as usize;
                        let k = g1[(dx + 5) as usize] * g1[(dy + 5) as usize];
                        let (a, b) = (x[q][c], y(q));
                        m[0] += k * a;
                        m[1] += k * b;
                        m[2] += k * a * a;
                        m[3] += k * b * b;
                        m[4] += k * a * b;
                    }
                }
                let (ux, uy) = (m[0], m[1]);
                let (sxx, syy, sxy) = (m[2] - ux * ux, m[3] - uy * uy, m[4] - ux * uy);
                ssim += (2.0 * ux * uy + c1) * (2.0 * sxy + c2)
                    / ((ux * ux + uy * uy + c1) * (sxx + syy + c2));
            }
        }
    }
    let valid: Vec<usize> = (0..n).filter(|&p| t.depth[p] > 0.0).collect();
    let depth_l1 = valid
        .iter()
        .map(|&p| (d[p] - t.depth[p] as f64).abs())
        .sum::<f64>()
        / valid.len() as f64;
    let wts = LossWeights::default();
    let n3 = (3 * n) as f64;
    wts.l1 as f64 * l1 / n3 + wts.ssim as f64 * (1.0 - ssim / n3) + wts.depth as f64 * depth_l1
}

#[test]
fn fused_loss_gradient_matches_f64_finite_differences() {
    for level in SimdLevel::available() {
        cap_level(Some(level));
        for (seed, noise) in [(21, 1.0), (22, 0.05)] {
            fd_check(seed, noise, level);
        }
        cap_level(None);
    }
}

fn fd_check(seed: u64, noise: f32, level: SimdLevel) {
    let (w, h) = (23usize, 19usize);
    let c = case(seed, w as u32, h as u32, noise);
    let (_, gc, gd) = eval_with(&c, &mut Loss::new(), &exact());
    let x: Vec<[f64; 3]> = c.color.iter().map(|p| p.map(|v| v as f64)).collect();
    let d: Vec<f64> = c.depth.iter().map(|&v| v as f64).collect();
    let eps = 1e-6;
    let (mut fd, mut an) = (Vec::new(), Vec::new());
    for p in (0..w * h).step_by(4) {
        for ch in 0..3 {
            // Away from the L1 kink (ties are checked against the reference elsewhere).
            if (x[p][ch] - c.target.rgb[ch][p] as f64).abs() < 1e-4 {
                continue;
            }
            let mut xp = x.clone();
            xp[p][ch] += eps;
            let fp = loss64(w, h, &xp, &d, &c.target);
            xp[p][ch] -= 2.0 * eps;
            let fm = loss64(w, h, &xp, &d, &c.target);
            fd.push(("colour", p, (fp - fm) / (2.0 * eps)));
            an.push(gc[p][ch] as f64);
        }
        if (d[p] - c.target.depth[p] as f64).abs() > 1e-4 {
            let mut dp = d.clone();
            dp[p] += eps;
            let fp = loss64(w, h, &x, &dp, &c.target);
            dp[p] -= 2.0 * eps;
            let fm = loss64(w, h, &x, &dp, &c.target);
            fd.push(("depth", p, (fp - fm) / (2.0 * eps)));
            an.push(gd[p] as f64);
        }
    }
    assert!(fd.len() > 300, "{} checked", fd.len());
    let scale = fd.iter().fold(0.0f64, |m, f| m.max(f.2.abs()));
    for ((kind, p, f), a) in fd.iter().zip(&an) {
        let err = (a - f).abs() / scale;
        assert!(
            err < 1e-4,
            "{level:?} seed {seed}: {kind} at pixel {p}: analytic {a}, finite difference {f} (error {err} of the largest)"
        );
    }
}
