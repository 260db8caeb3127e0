//! Backward-pass tests: analytic gradients (f32 backward) against central finite differences
//! of an independent f64 forward, and an end-to-end optimisation run.

use opengs_geometry::{Intrinsics, Pose};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::adam::{Adam, AdamConfig};
use crate::backward::Backward;
use crate::blend::{MAX_ALPHA, MIN_ALPHA, MIN_TRANSMITTANCE};
use crate::grads::MapGrads;
use crate::map::{color_to_sh_dc, Gaussian, GaussianMap, SH_C0};
use crate::output::RenderRequest;
use crate::project::radius_tile_rect;
use crate::render::render;
use crate::scene::look_at;
use crate::target::TargetFrame;
use crate::tiles::{TileGrid, TILE_SIZE};
use crate::train::{train_step, TrainConfig, TrainWorkspace};
use crate::Camera;

/// Parameters per Gaussian: mean 3, quaternion 4, log-scale 3, opacity logit 1, SH DC 3.
const P: usize = 14;
const KINDS: [(&str, std::ops::Range<usize>); 5] = [
    ("mean", 0..3),
    ("rotation", 3..7),
    ("log_scale", 7..10),
    ("opacity", 10..11),
    ("color", 11..14),
];

fn flatten(map: &GaussianMap) -> Vec<f64> {
    let mut v = Vec::with_capacity(map.len() * P);
    for i in 0..map.len() {
        let g = map.get(i);
        v.extend(g.mean.iter().map(|&x| x as f64));
        v.extend(g.rotation.iter().map(|&x| x as f64));
        v.extend(g.log_scale.iter().map(|&x| x as f64));
        v.push(g.opacity_logit as f64);
        v.extend(g.sh_dc.iter().map(|&x| x as f64));
    }
    v
}

fn flatten_grads(g: &MapGrads) -> Vec<f64> {
    let mut v = Vec::with_capacity(g.len() * P);
    for i in 0..g.len() {
        v.extend(g.means[i].iter().map(|&x| x as f64));
        v.extend(g.rotations[i].iter().map(|&x| x as f64));
        v.extend(g.log_scales[i].iter().map(|&x| x as f64));
        v.push(g.opacity_logits[i] as f64);
        v.extend(g.sh_dc[i].iter().map(|&x| x as f64));
    }
    v
}

/// Screen-space data of one Gaussian in f64 (reference 3DGS maths, written independently).
struct Proj64 {
    mean2d: [f64; 2],
    depth: f64,
    conic: [f64; 3],
    opacity: f64,
    color: [f64; 3],
    tiles: crate::tiles::TileRect,
}

fn project64(cam: &Camera, x: &[f64], grid: &TileGrid) -> Option<Proj64> {
    let k = &cam.intrinsics;
    let w: [[f64; 3]; 3] = cam.rotation.map(|r| r.map(|v| v as f64));
    let t = cam.translation.map(|v| v as f64);
    let p: [f64; 3] =
        std::array::from_fn(|i| w[i][0] * x[0] + w[i][1] * x[1] + w[i][2] * x[2] + t[i]);
    let z = p[2];
    if z <= cam.near as f64 {
        return None;
    }
    let lim_x = 1.3 * k.width as f64 / (2.0 * k.fx);
    let lim_y = 1.3 * k.height as f64 / (2.0 * k.fy);
    let tx = (p[0] / z).clamp(-lim_x, lim_x) * z;
    let ty = (p[1] / z).clamp(-lim_y, lim_y) * z;
    let j = [
        [k.fx / z, 0.0, -k.fx * tx / (z * z)],
        [0.0, k.fy / z, -k.fy * ty / (z * z)],
    ];
    let n = (x[3] * x[3] + x[4] * x[4] + x[5] * x[5] + x[6] * x[6]).sqrt();
    let (r, qx, qy, qz) = (x[3] / n, x[4] / n, x[5] / n, x[6] / n);
    let rot = [
        [
            1.0 - 2.0 * (qy * qy + qz * qz),
            2.0 * (qx * qy - r * qz),
            2.0 * (qx * qz + r * qy),
        ],
        [
            2.0 * (qx * qy + r * qz),
            1.0 - 2.0 * (qx * qx + qz * qz),
            2.0 * (qy * qz - r * qx),
        ],
        [
            2.0 * (qx * qz - r * qy),
            2.0 * (qy * qz + r * qx),
            1.0 - 2.0 * (qx * qx + qy * qy),
        ],
    ];
    let s = [x[7].exp(), x[8].exp(), x[9].exp()];
    let sigma: [[f64; 3]; 3] = std::array::from_fn(|a| {
        std::array::from_fn(|b| (0..3).map(|c| rot[a][c] * s[c] * s[c] * rot[b][c]).sum())
    });
    let jw: [[f64; 3]; 2] =
        std::array::from_fn(|a| std::array::from_fn(|b| (0..3).map(|c| j[a][c] * w[c][b]).sum()));
    let cov = |a: usize, b: usize| -> f64 {
        (0..3)
            .map(|c| {
                (0..3)
                    .map(|d| jw[a][c] * sigma[c][d] * jw[b][d])
                    .sum::<f64>()
            })
            .sum()
    };
    let (a, b, c) = (cov(0, 0) + 0.3, cov(0, 1), cov(1, 1) + 0.3);
    let det = a * c - b * b;
    let mid = 0.5 * (a + c);
    let lambda = mid + (mid * mid - det).max(0.1).sqrt();
    let radius = (3.0 * lambda.sqrt()).ceil() as u32;
    let mean2d = [k.fx * p[0] / z + k.cx, k.fy * p[1] / z + k.cy];
    Some(Proj64 {
        mean2d,
        depth: z,
        conic: [c / det, -b / det, a / det],
        opacity: 1.0 / (1.0 + (-x[10]).exp()),
        color: std::array::from_fn(|i| (0.5 + SH_C0 as f64 * x[11 + i]).max(0.0)),
        tiles: radius_tile_rect([mean2d[0] as f32, mean2d[1] as f32], radius, grid),
    })
}

/// f64 render: per-pixel colour and depth, plus each pixel's contributing Gaussians and the
/// smallest distance of any threshold test to its boundary (how safe finite differences are).
struct Render64 {
    color: Vec<[f64; 3]>,
    depth: Vec<f64>,
    contribs: Vec<Vec<u32>>,
    margin: f64,
    /// Pixels where compositing stopped early, and α values clamped at 0.99.
    stops: usize,
    clamps: usize,
}

fn render64(cam: &Camera, params: &[f64]) -> Render64 {
    let grid = TileGrid::new(cam.width(), cam.height());
    let mut gs: Vec<(usize, Proj64)> = params
        .chunks(P)
        .enumerate()
        .filter_map(|(i, x)| project64(cam, x, &grid).map(|g| (i, g)))
        .collect();
    gs.sort_by(|a, b| a.1.depth.total_cmp(&b.1.depth).then(a.0.cmp(&b.0)));
    let n = (grid.width * grid.height) as usize;
    let mut out = Render64 {
        color: vec![[0.0; 3]; n],
        depth: vec![0.0; n],
        contribs: vec![Vec::new(); n],
        margin: f64::INFINITY,
        stops: 0,
        clamps: 0,
    };
    for y in 0..grid.height {
        for x in 0..grid.width {
            let p = (y * grid.width + x) as usize;
            let mut t = 1.0f64;
            for (id, g) in &gs {
                if !g.tiles.contains(x / TILE_SIZE, y / TILE_SIZE) {
                    continue;
                }
                let (dx, dy) = (g.mean2d[0] - x as f64, g.mean2d[1] - y as f64);
                let power =
                    -0.5 * (g.conic[0] * dx * dx + g.conic[2] * dy * dy) - g.conic[1] * dx * dy;
                let raw = g.opacity * power.exp();
                out.margin = out
                    .margin
                    .min((raw - MIN_ALPHA as f64).abs())
                    .min((raw - MAX_ALPHA as f64).abs());
                let alpha = raw.min(MAX_ALPHA as f64);
                if power > 0.0 || alpha < MIN_ALPHA as f64 {
                    continue;
                }
                out.clamps += (raw > MAX_ALPHA as f64) as usize;
                let test_t = t * (1.0 - alpha);
                out.margin = out.margin.min((test_t - MIN_TRANSMITTANCE as f64).abs());
                if test_t < MIN_TRANSMITTANCE as f64 {
                    out.stops += 1;
                    break;
                }
                for c in 0..3 {
                    out.color[p][c] += g.color[c] * alpha * t;
                }
                out.depth[p] += g.depth * alpha * t;
                out.contribs[p].push(*id as u32);
                t = test_t;
            }
        }
    }
    out
}

/// Random scene of `n` Gaussians in front of a tilted camera over a 24×20 image.
fn random_scene(seed: u64, n: usize) -> (GaussianMap, Camera) {
    scene_with(seed, n, 0.6, 0.3..0.95)
}

/// Random scene with means within ±`spread` m (x) and opacities drawn from `opacity`.
fn scene_with(
    seed: u64,
    n: usize,
    spread: f32,
    opacity: std::ops::Range<f32>,
) -> (GaussianMap, Camera) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let k = Intrinsics::new(30.0, 28.0, 11.7, 9.6, 24, 20);
    let pose: Pose = look_at([0.2, -0.1, -0.3], [0.0, 0.0, 3.0]);
    let cam = Camera::from_pose(k, &pose, 0.05);
    let mut map = GaussianMap::new();
    for _ in 0..n {
        let q: [f32; 4] = std::array::from_fn(|_| rng.gen_range(-1.0..1.0));
        map.push(Gaussian {
            mean: [
                rng.gen_range(-spread..spread),
                rng.gen_range(-0.8 * spread..0.8 * spread),
                rng.gen_range(2.0..4.0),
            ],
            rotation: q,
            log_scale: std::array::from_fn(|_| rng.gen_range(0.05f32..0.35).ln()),
            opacity_logit: crate::map::logit(rng.gen_range(opacity.clone())),
            sh_dc: std::array::from_fn(|_| color_to_sh_dc(rng.gen_range(-0.2..1.0))),
            label: 1,
        });
    }
    (map, cam)
}

/// Fixed random weights: L = Σ wc·C + wd·D, so dL/dC = wc and dL/dD = wd.
fn weights(seed: u64, n: usize) -> (Vec<[f32; 3]>, Vec<f32>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x9e37);
    let wc = (0..n)
        .map(|_| std::array::from_fn(|_| rng.gen_range(-1.0..1.0)))
        .collect();
    let wd = (0..n).map(|_| rng.gen_range(-1.0..1.0)).collect();
    (wc, wd)
}

fn loss64(r: &Render64, wc: &[[f32; 3]], wd: &[f32]) -> f64 {
    let mut l = 0.0;
    for (p, (w, c)) in wc.iter().zip(&r.color).enumerate() {
        l += (0..3).map(|k| w[k] as f64 * c[k]).sum::<f64>();
        l += wd[p] as f64 * r.depth[p];
    }
    l
}

/// Per parameter kind: (‖analytic − fd‖ / ‖fd‖, worst element error relative to the kind's
/// largest |fd|, parameters skipped because a step crossed a threshold).
fn gradient_errors(
    seed: u64,
    n: usize,
    map: &GaussianMap,
    cam: &Camera,
) -> Vec<(&'static str, f64, f64, usize)> {
    let (w, h) = (cam.width() as usize, cam.height() as usize);
    let (wc, wd) = weights(seed, w * h);
    let rendered = render(map, cam, &RenderRequest::color_depth());
    let mut grads = MapGrads::default();
    Backward::new().run(map, cam, &rendered, &wc, &wd, &mut grads);
    let analytic = flatten_grads(&grads);
    let params = flatten(map);
    let base = render64(cam, &params);
    // The f32 renderer and the f64 one must agree on every contribution.
    for y in 0..h as u32 {
        for x in 0..w as u32 {
            let f32_ids: Vec<u32> = rendered
                .pixel_contributions(x, y)
                .iter()
                .map(|c| c.0)
                .collect();
            assert_eq!(
                f32_ids,
                base.contribs[y as usize * w + x as usize],
                "scene {seed}: pixel ({x}, {y})"
            );
        }
    }
    let eps = 1e-6;
    let mut fd = vec![0.0; params.len()];
    let mut skipped = vec![false; params.len()];
    for j in 0..params.len() {
        let mut pp = params.clone();
        pp[j] += eps;
        let rp = render64(cam, &pp);
        pp[j] -= 2.0 * eps;
        let rm = render64(cam, &pp);
        skipped[j] = rp.contribs != base.contribs || rm.contribs != base.contribs;
        fd[j] = (loss64(&rp, &wc, &wd) - loss64(&rm, &wc, &wd)) / (2.0 * eps);
    }
    KINDS
        .iter()
        .map(|(name, range)| {
            let idx: Vec<usize> = (0..n)
                .flat_map(|g| range.clone().map(move |k| g * P + k))
                .filter(|&j| !skipped[j])
                .collect();
            let diff: f64 = idx
                .iter()
                .map(|&j| (analytic[j] - fd[j]).powi(2))
                .sum::<f64>()
                .sqrt();
            let norm: f64 = idx.iter().map(|&j| fd[j].powi(2)).sum::<f64>().sqrt();
            let scale = idx.iter().map(|&j| fd[j].abs()).fold(0.0, f64::max);
            let worst = idx
                .iter()
                .map(|&j| (analytic[j] - fd[j]).abs() / scale.max(1e-12))
                .fold(0.0, f64::max);
            let n_skipped = range.len() * n - idx.len();
            (*name, diff / norm.max(1e-12), worst, n_skipped)
        })
        .collect()
}

fn assert_gradients(seed: u64, n: usize, map: &GaussianMap, cam: &Camera) {
    let base = render64(cam, &flatten(map));
    assert!(
        base.margin > MARGIN,
        "scene {seed} sits on a threshold (margin {})",
        base.margin
    );
    for (name, rel, worst, skipped) in gradient_errors(seed, n, map, cam) {
        eprintln!("scene {seed} {name:>9}: rel {rel:.2e} worst elem {worst:.2e} skipped {skipped}");
        assert!(rel < 1e-2, "scene {seed} {name}: relative error {rel}");
        assert!(
            worst < 2e-2,
            "scene {seed} {name}: worst element error {worst}"
        );
        assert!(
            skipped == 0,
            "scene {seed} {name}: {skipped} parameters crossed a threshold"
        );
    }
}

/// Smallest distance of any threshold test (α cut-offs, T stop) from its boundary: far above
/// the finite-difference step's effect (~1e-6) and f32 rounding (~1e-7).
const MARGIN: f64 = 1e-5;

/// Seeds whose scenes keep every threshold test ≥ MARGIN away from its boundary.
fn smooth_seeds(n: usize, count: usize) -> Vec<u64> {
    (0..200u64)
        .filter(|&s| {
            let (map, cam) = random_scene(s, n);
            render64(&cam, &flatten(&map)).margin > MARGIN
        })
        .take(count)
        .collect()
}

#[test]
fn gradients_match_finite_differences_on_random_scenes() {
    // Every kernel level this CPU has: the portable backward is tested on any machine.
    for level in crate::cpu::SimdLevel::available() {
        crate::cpu::cap_level(Some(level));
        for n in [3, 6, 10] {
            let seeds = smooth_seeds(n, 2);
            assert!(!seeds.is_empty());
            for s in seeds {
                let (map, cam) = random_scene(s, n);
                assert_gradients(s, n, &map, &cam);
            }
        }
        crate::cpu::cap_level(None);
    }
}

#[test]
fn every_kernel_level_gives_the_same_gradients() {
    let k = Intrinsics::new(131.25, 131.25, 79.5, 59.5, 160, 120);
    let cam = Camera::from_pose(k, &crate::scene::indoor_poses(1)[0], 0.05);
    let map = crate::scene::indoor_scene(20_000, 3);
    let (wc, wd) = weights(7, 160 * 120);
    let grads_at = |level| {
        crate::cpu::cap_level(Some(level));
        let rendered = render(&map, &cam, &RenderRequest::color_depth());
        let mut g = MapGrads::default();
        Backward::new().run(&map, &cam, &rendered, &wc, &wd, &mut g);
        crate::cpu::cap_level(None);
        flatten_grads(&g)
    };
    let portable = grads_at(crate::cpu::SimdLevel::Portable);
    let norm: f64 = portable.iter().map(|a| a * a).sum::<f64>().sqrt();
    assert!(norm > 0.0);
    for level in crate::cpu::SimdLevel::available() {
        let other = grads_at(level);
        let diff: f64 = portable
            .iter()
            .zip(&other)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(
            diff / norm < 1e-5,
            "{level:?}: relative difference {}",
            diff / norm
        );
    }
}

#[test]
fn gradients_through_early_stop_and_alpha_clamp() {
    // Nearly opaque, overlapping Gaussians: α hits 0.99 and T drops below 1e-4.
    let (mut tested_stop, mut tested_clamp) = (false, false);
    for s in 0..300u64 {
        let (map, cam) = scene_with(s, 8, 0.15, 0.97..0.9999);
        let base = render64(&cam, &flatten(&map));
        let wanted = (base.stops > 0 && !tested_stop) || (base.clamps > 0 && !tested_clamp);
        if base.margin > MARGIN && wanted {
            assert_gradients(s, 8, &map, &cam);
            tested_stop |= base.stops > 0;
            tested_clamp |= base.clamps > 0;
        }
        if tested_stop && tested_clamp {
            return;
        }
    }
    panic!("no smooth scene with early stops ({tested_stop}) and clamps ({tested_clamp})");
}

#[test]
fn gradients_through_the_fov_clamp() {
    // A wide Gaussian centred outside 1.3·tan(fov/2) but reaching into the image.
    let (mut map, cam) = random_scene(5, 2);
    let world_of = |p: [f32; 3]| {
        // Inverse of the camera transform: R^T (p - t).
        let r = &cam.rotation;
        let d = [
            p[0] - cam.translation[0],
            p[1] - cam.translation[1],
            p[2] - cam.translation[2],
        ];
        std::array::from_fn(|i| r[0][i] * d[0] + r[1][i] * d[1] + r[2][i] * d[2])
    };
    let mut found = false;
    for k in 0..40 {
        let x = 1.7 + 0.01 * k as f32; // x/z = 0.57 … 0.7 > lim 0.52
        map.means[1] = world_of([x, 0.1, 3.0]);
        map.log_scales[1] = [0.6f32.ln(), 0.3f32.ln(), 0.2f32.ln()];
        map.opacity_logits[1] = 2.0;
        let base = render64(&cam, &flatten(&map));
        if base.margin > MARGIN && base.contribs.iter().any(|c| c.contains(&1)) {
            assert_gradients(1000 + k, 2, &map, &cam);
            found = true;
            break;
        }
    }
    assert!(found, "no clamped test configuration found");
}

/// Optimisation: a perturbed copy of a known scene is pulled back towards its render.
#[test]
fn adam_steps_recover_a_perturbed_scene() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let k = Intrinsics::new(60.0, 60.0, 31.5, 23.5, 64, 48);
    let cam = Camera::from_pose(k, &Pose::identity(), 0.05);
    let mut truth = GaussianMap::new();
    for _ in 0..150 {
        truth.push(Gaussian::from_values(
            [
                rng.gen_range(-1.4..1.4),
                rng.gen_range(-1.0..1.0),
                rng.gen_range(2.5..3.0),
            ],
            std::array::from_fn(|_| rng.gen_range(-1.0..1.0)),
            [rng.gen_range(0.05..0.15), rng.gen_range(0.05..0.15), 0.02],
            rng.gen_range(0.5..0.9),
            [rng.gen(), rng.gen(), rng.gen()],
            1,
        ));
    }
    let r = render(&truth, &cam, &RenderRequest::color_depth());
    let target = TargetFrame::from_rgb_f32(64, 48, &r.output.color, &r.output.depth);
    let mut map = truth.clone();
    for i in 0..map.len() {
        for c in 0..3 {
            map.means[i][c] += rng.gen_range(-0.03..0.03);
            map.sh_dc[i][c] += color_to_sh_dc(0.5 + rng.gen_range(-0.2..0.2));
        }
        map.opacity_logits[i] += rng.gen_range(-1.0..1.0);
    }
    let config = AdamConfig {
        lr_mean: 1e-3,
        lr_sh_dc: 1e-2,
        ..AdamConfig::gs_defaults(1.0)
    };
    let mut adam = Adam::new(config, map.len());
    let mut ws = TrainWorkspace::new();
    let cfg = TrainConfig::default();
    let first = train_step(&mut map, &mut adam, &cam, &target, &cfg, &mut ws).loss;
    let mut last = first;
    for _ in 0..300 {
        last = train_step(&mut map, &mut adam, &cam, &target, &cfg, &mut ws).loss;
    }
    eprintln!(
        "PSNR {:.2} → {:.2} dB, loss {:.4} → {:.4}",
        first.psnr, last.psnr, first.total, last.total
    );
    assert!(
        last.psnr >= first.psnr + 8.0,
        "PSNR {} → {}",
        first.psnr,
        last.psnr
    );
}

/// The per-thread buffers sum to the same gradients whatever the thread count.
#[test]
fn gradients_do_not_depend_on_thread_count() {
    let k = Intrinsics::new(131.25, 131.25, 79.5, 59.5, 160, 120);
    let cam = Camera::from_pose(k, &crate::scene::indoor_poses(1)[0], 0.05);
    let map = crate::scene::indoor_scene(20_000, 3);
    let (wc, wd) = weights(7, 160 * 120);
    let grads_with = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool");
        pool.install(|| {
            let rendered = render(&map, &cam, &RenderRequest::color_depth());
            let mut g = MapGrads::default();
            Backward::new().run(&map, &cam, &rendered, &wc, &wd, &mut g);
            flatten_grads(&g)
        })
    };
    let (one, three) = (grads_with(1), grads_with(3));
    let diff: f64 = one
        .iter()
        .zip(&three)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt();
    let norm: f64 = one.iter().map(|a| a * a).sum::<f64>().sqrt();
    assert!(norm > 0.0);
    assert!(diff / norm < 1e-5, "relative difference {}", diff / norm);
}

/// One `Backward` reused across steps (buffers drained to zero, not cleared) gives what a
/// fresh one gives, when the map and the thread count change between steps too.
#[test]
fn a_reused_backward_gives_what_a_fresh_one_gives() {
    let k = Intrinsics::new(131.25, 131.25, 79.5, 59.5, 160, 120);
    let cam = Camera::from_pose(k, &crate::scene::indoor_poses(1)[0], 0.05);
    let (wc, wd) = weights(7, 160 * 120);
    let mut reused = Backward::new();
    for (seed, n, threads) in [
        (3, 20_000, 2),
        (4, 20_000, 2),
        (5, 12_000, 2),
        (6, 12_000, 3),
    ] {
        let map = crate::scene::indoor_scene(n, seed);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool");
        let (fresh, again) = pool.install(|| {
            let rendered = render(&map, &cam, &RenderRequest::color_depth());
            let (mut a, mut b) = (MapGrads::default(), MapGrads::default());
            Backward::new().run(&map, &cam, &rendered, &wc, &wd, &mut a);
            reused.run(&map, &cam, &rendered, &wc, &wd, &mut b);
            (flatten_grads(&a), flatten_grads(&b))
        });
        // Tiles go to threads in whatever order: sums agree to rounding, not bit for bit.
        let norm: f64 = fresh.iter().map(|a| a * a).sum::<f64>().sqrt();
        let diff: f64 = fresh
            .iter()
            .zip(&again)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(norm > 0.0);
        assert!(
            diff / norm < 1e-5,
            "seed {seed}, {n} Gaussians, {threads} threads: relative difference {}",
            diff / norm
        );
    }
}

/// Chunks dropped before all their gradients were taken still leave zeros behind.
#[test]
fn an_untaken_chunk_is_zeroed_when_dropped() {
    let k = Intrinsics::new(131.25, 131.25, 79.5, 59.5, 160, 120);
    let cam = Camera::from_pose(k, &crate::scene::indoor_poses(1)[0], 0.05);
    let map = crate::scene::indoor_scene(5_000, 3);
    let (wc, wd) = weights(7, 160 * 120);
    let rendered = render(&map, &cam, &RenderRequest::color_depth());
    let mut raster = crate::RasterBackward::new();
    let run = |raster: &mut crate::RasterBackward| {
        raster.run(
            &rendered.projected,
            &rendered.bins,
            &rendered.output,
            &wc,
            &wd,
        )
    };
    run(&mut raster);
    let mut first: Vec<Option<crate::ScreenGrad>> = Vec::new();
    for mut chunk in raster.drain_chunks(1000) {
        for _ in 0..1000 {
            first.push(chunk.take_next());
        }
    }
    first.truncate(map.len());
    assert!(first.iter().any(Option::is_some));
    // Run again, take only the first 10 of each chunk, drop the rest …
    run(&mut raster);
    for mut chunk in raster.drain_chunks(1000) {
        for _ in 0..10 {
            chunk.take_next();
        }
    }
    // … and a third run must not see the second one's leftovers added in.
    run(&mut raster);
    let mut third = Vec::new();
    for mut chunk in raster.drain_chunks(1000) {
        for _ in 0..1000 {
            third.push(chunk.take_next());
        }
    }
    third.truncate(map.len());
    assert_eq!(first.len(), third.len());
    // Leftovers added in would be of the gradients' own size; rounding is far below it.
    for (a, b) in first.iter().zip(&third) {
        let (a, b) = (a.unwrap_or_default(), b.unwrap_or_default());
        let scale = a.opacity.abs().max(1e-3);
        assert!(
            (a.opacity - b.opacity).abs() <= 1e-4 * scale,
            "{a:?} vs {b:?}"
        );
        assert!((a.mean2d[0] - b.mean2d[0]).abs() <= 1e-4 * a.mean2d[0].abs().max(1e-3));
    }
}
