//! Renderer tests with hand-worked numbers, plus fast-vs-reference on a random scene.

use opengs_geometry::{Intrinsics, Pose};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::map::{Gaussian, GaussianMap};
use crate::output::{RenderOutput, RenderRequest};
use crate::reference::render_reference;
use crate::render::render;
use crate::{stored_weight, Camera};

fn camera(near: f32) -> Camera {
    // Principal point on pixel (32, 24); identity pose: camera at origin looking down +z.
    Camera::from_pose(
        Intrinsics::new(100.0, 100.0, 32.0, 24.0, 64, 48),
        &Pose::identity(),
        near,
    )
}

fn blob(z: f32, sigma: f32, opacity: f32, color: [f32; 3], label: u32) -> Gaussian {
    Gaussian::from_values(
        [0.0, 0.0, z],
        [1.0, 0.0, 0.0, 0.0],
        [sigma; 3],
        opacity,
        color,
        label,
    )
}

fn map_of(gs: &[Gaussian]) -> GaussianMap {
    let mut m = GaussianMap::new();
    for g in gs {
        m.push(*g);
    }
    m
}

/// Labels only, then the semantic request with top-K `k`.
fn label_requests(k: usize) -> [RenderRequest; 2] {
    let only_labels = RenderRequest {
        labels: true,
        ..RenderRequest::default()
    };
    [only_labels, RenderRequest::semantic(k)]
}

/// `req` rendered on this CPU's SIMD kernels, then on the portable ones: (portable, output).
fn render_on_both_kernels(
    map: &GaussianMap,
    cam: &Camera,
    req: &RenderRequest,
) -> [(bool, RenderOutput); 2] {
    [false, true].map(|portable| {
        crate::cpu::cap_level(portable.then_some(crate::cpu::SimdLevel::Portable));
        let o = render(map, cam, req).output;
        crate::cpu::cap_level(None);
        (portable, o)
    })
}

/// Pixel (x, y)'s top-K heaviest first, as (ids, weights).
fn heaviest_first(tk: &crate::TopK, x: u32, y: u32) -> (Vec<u32>, Vec<f32>) {
    tk.pixel_sorted(x, y).into_iter().unzip()
}

/// Pixel (x, y)'s top-K as a set: by id.
fn top_k_by_id(tk: &crate::TopK, x: u32, y: u32) -> Vec<(u32, f32)> {
    let mut v: Vec<(u32, f32)> = tk.pixel(x, y).collect();
    v.sort_by_key(|e| e.0);
    v
}

/// A reference list as the top-K stores it (weights as f16), by id.
fn stored_by_id(list: &[(u32, f32)]) -> Vec<(u32, f32)> {
    let mut v: Vec<(u32, f32)> = list.iter().map(|&(id, w)| (id, stored_weight(w))).collect();
    v.sort_by_key(|e| e.0);
    v
}

fn close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol
}

/// A top-K weight (stored as f16: within a relative 2^-11) against its f32 value.
fn close_weight(stored: f32, want: f32) -> bool {
    (stored - want).abs() <= want.abs() * 2f32.powi(-11) + 1e-7
}

#[test]
fn single_gaussian_head_on_matches_hand_values() {
    let map = map_of(&[blob(2.0, 0.02, 0.8, [0.2, 0.4, 0.6], 7)]);
    let r = render(&map, &camera(0.05), &RenderRequest::semantic(50));
    // Σ' = (fx/z)²σ² + 0.3 = 50²·0.02² + 0.3 = 1.3; λmax = 1.3 + sqrt(0.1) → radius ceil(3·1.2713) = 4.
    assert_eq!(r.projected.radii[0], 4);
    assert!(close(r.projected.conics[0][0], 1.0 / 1.3, 1e-6));
    assert_eq!(r.projected.means2d[0], [32.0, 24.0]);
    let o = &r.output;
    let c = o.index(32, 24);
    // Centre: α = 0.8, T = 1.
    for (got, want) in o.color[c].iter().zip([0.16, 0.32, 0.48]) {
        assert!(close(*got, want, 1e-6), "{got} vs {want}");
    }
    assert!(close(o.depth[c], 1.6, 1e-6));
    assert!(close(o.silhouette[c], 0.8, 1e-6));
    assert!(close(o.final_transmittance[c], 0.2, 1e-6));
    // One pixel right: α = 0.8·exp(−0.5/1.3) = 0.544570.
    let n = o.index(33, 24);
    assert!(
        close(o.silhouette[n], 0.544_570, 1e-5),
        "{}",
        o.silhouette[n]
    );
    let labels = o.labels.as_ref().expect("asked for");
    assert_eq!(labels[c], 7);
    assert_eq!(labels[o.index(0, 0)], 0);
    let tk = o.top_k.as_ref().expect("asked for");
    let (ids, ws) = heaviest_first(tk, 32, 24);
    assert_eq!(ids, &[0]);
    assert!(close_weight(ws[0], 0.8));
    assert_eq!(tk.pixel(0, 0).count(), 0);
    let vis = o.visible_per_label.as_ref().expect("asked for");
    assert_eq!(vis.get(&7), Some(&1));
    assert_eq!(vis.len(), 1);
}

#[test]
fn voted_label_flips_with_front_opacity() {
    // Centre pixel: w_front = o, w_back = 0.9·(1 − o): the front wins iff o > 0.9/1.9 ≈ 0.474.
    for (o_front, want) in [(0.4f32, 2u32), (0.6, 1)] {
        let map = map_of(&[
            blob(2.0, 0.02, o_front, [1.0, 0.0, 0.0], 1),
            blob(3.0, 0.02, 0.9, [0.0, 1.0, 0.0], 2),
        ]);
        let r = render(&map, &camera(0.05), &RenderRequest::semantic(50));
        let o = &r.output;
        assert_eq!(o.labels.as_ref().expect("asked")[o.index(32, 24)], want);
        let (ids, ws) = heaviest_first(o.top_k.as_ref().expect("asked"), 32, 24);
        let (w_front, w_back) = (o_front, 0.9 * (1.0 - o_front));
        let expect: Vec<(u32, f32)> = if w_back > w_front {
            vec![(1, w_back), (0, w_front)]
        } else {
            vec![(0, w_front), (1, w_back)]
        };
        assert_eq!(ids, &[expect[0].0, expect[1].0]);
        assert!(close_weight(ws[0], expect[0].1) && close_weight(ws[1], expect[1].1));
    }
}

#[test]
fn label_zero_never_beats_a_real_label() {
    // Front background Gaussian has the larger weight (0.9 vs 0.09) but label 0 never wins.
    let map = map_of(&[
        blob(2.0, 0.02, 0.9, [1.0; 3], 0),
        blob(3.0, 0.02, 0.9, [1.0; 3], 5),
    ]);
    let r = render(&map, &camera(0.05), &RenderRequest::semantic(50));
    assert_eq!(
        r.output.labels.as_ref().expect("asked")[r.output.index(32, 24)],
        5
    );
}

#[test]
fn voting_goes_per_pixel_when_a_tile_meets_a_second_label() {
    // Front to back: a small label-3 Gaussian centred on pixel (34, 24), a label-0 one and a
    // wide label-4 one on (32, 24). (34, 24): w3 = 0.5 beats w4 < 0.5·0.9. (32, 24):
    // w3 = 0.5·e^(−2/1.3) = 0.1073 loses to w4 = 0.9·(1 − 0.1073)·0.5 = 0.4017.
    let mut front = blob(2.0, 0.02, 0.5, [1.0, 0.0, 0.0], 3);
    front.mean[0] = 2.0 * 2.0 / 100.0;
    let map = map_of(&[
        front,
        blob(2.5, 0.02, 0.5, [0.0; 3], 0),
        blob(3.0, 0.1, 0.9, [0.0, 1.0, 0.0], 4),
    ]);
    let cam = camera(0.05);
    let slow = render_reference(&map, &cam, 50);
    for req in label_requests(50) {
        for (portable, o) in render_on_both_kernels(&map, &cam, &req) {
            let labels = o.labels.as_ref().expect("asked");
            assert_eq!(labels[o.index(34, 24)], 3);
            assert_eq!(labels[o.index(32, 24)], 4);
            assert_eq!(labels[o.index(38, 24)], 4);
            assert_eq!(labels, &slow.labels, "portable {portable}");
        }
    }
}

#[test]
fn top_k_orders_by_weight_and_truncates() {
    // Front to back opacities; weights w = αT: 0.1, 0.45, 0.09, 0.216, 0.0432, 0.00504.
    let ops = [0.1f32, 0.5, 0.2, 0.6, 0.3, 0.05];
    let gs: Vec<Gaussian> = ops
        .iter()
        .enumerate()
        .map(|(i, &o)| blob(2.0 + 0.1 * i as f32, 0.02, o, [0.5; 3], i as u32 + 1))
        .collect();
    let map = map_of(&gs);
    let r = render(&map, &camera(0.05), &RenderRequest::semantic(3));
    let (ids, ws) = heaviest_first(r.output.top_k.as_ref().expect("asked"), 32, 24);
    assert_eq!(ids, &[1, 3, 0]);
    for (got, want) in ws.iter().zip([0.45f32, 0.216, 0.1]) {
        assert!(close_weight(*got, want), "{got} vs {want}");
    }
    let r = render(&map, &camera(0.05), &RenderRequest::semantic(50));
    let (ids, _) = heaviest_first(r.output.top_k.as_ref().expect("asked"), 32, 24);
    assert_eq!(ids, &[1, 3, 0, 2, 4, 5]);
}

#[test]
fn near_plane_culls() {
    let map = map_of(&[
        blob(0.04, 0.001, 0.9, [1.0; 3], 3),
        blob(-1.0, 0.02, 0.9, [1.0; 3], 4),
    ]);
    let r = render(&map, &camera(0.05), &RenderRequest::semantic(50));
    assert!(r.output.silhouette.iter().all(|&s| s == 0.0));
    assert!(r
        .output
        .visible_per_label
        .as_ref()
        .expect("asked")
        .is_empty());
    assert!(r.bins.ids.is_empty());
    // Same Gaussian with the near plane moved closer is rendered.
    let r = render(&map, &camera(0.03), &RenderRequest::semantic(50));
    assert!(r.output.silhouette[r.output.index(32, 24)] > 0.89);
}

#[test]
fn transmittance_saturation_stops_compositing() {
    // α = 0.95 each: T = 0.05, 0.0025, 1.25e-4; the 4th would leave 6.25e-6 < 1e-4 → stop.
    let colors = [
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [1.0, 1.0, 1.0],
        [1.0, 1.0, 1.0],
    ];
    let gs: Vec<Gaussian> = colors
        .iter()
        .enumerate()
        .map(|(i, &c)| {
            blob(
                2.0 + 0.1 * i as f32,
                0.02,
                0.95,
                c,
                if i < 3 { 1 } else { 9 },
            )
        })
        .collect();
    let map = map_of(&gs);
    let r = render(&map, &camera(0.05), &RenderRequest::semantic(50));
    let o = &r.output;
    let c = o.index(32, 24);
    assert_eq!(o.n_contrib[c], 3);
    assert!(close(o.final_transmittance[c], 1.25e-4, 1e-8));
    assert!(close(o.silhouette[c], 1.0 - 1.25e-4, 1e-6));
    for (got, want) in o.color[c].iter().zip([0.95, 0.0475, 0.002375]) {
        assert!(close(*got, want, 1e-6), "{got} vs {want}");
    }
    let ids: Vec<u32> = o
        .top_k
        .as_ref()
        .expect("asked")
        .pixel(32, 24)
        .map(|e| e.0)
        .collect();
    assert_eq!(ids, [0, 1, 2]);
    assert_eq!(o.labels.as_ref().expect("asked")[c], 1);
}

fn random_scene(n: usize, seed: u64) -> GaussianMap {
    random_scene_with_labels(n, seed, 6)
}

/// Random scene whose labels are drawn from 0..labels.
fn random_scene_with_labels(n: usize, seed: u64, labels: u32) -> GaussianMap {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut m = GaussianMap::new();
    for _ in 0..n {
        let z: f32 = rng.gen_range(-0.5..4.0);
        let q: [f32; 4] = std::array::from_fn(|_| rng.gen_range(-1.0..1.0));
        let scale: [f32; 3] =
            std::array::from_fn(|_| rng.gen_range(0.005f32.ln()..0.3f32.ln()).exp());
        m.push(Gaussian::from_values(
            [rng.gen_range(-1.5..1.5), rng.gen_range(-1.2..1.2), z],
            q,
            scale,
            rng.gen_range(0.002..0.999),
            std::array::from_fn(|_| rng.gen_range(-0.1..1.1)),
            rng.gen_range(0..labels),
        ));
    }
    m
}

#[test]
fn fast_matches_reference_on_random_scene() {
    // 72×52: partial tiles on both axes; K = 8 so truncation happens.
    let k = Intrinsics::new(60.0, 62.0, 35.5, 25.0, 72, 52);
    let pose = crate::scene::look_at([0.1, -0.2, -0.3], [0.0, 0.0, 2.0]);
    for seed in 0..3 {
        let map = random_scene(600, seed);
        let cam = Camera::from_pose(k, &pose, 0.1);
        let fast = render(&map, &cam, &RenderRequest::semantic(8)).output;
        let slow = render_reference(&map, &cam, 8);
        let mut max_diff = 0.0f32;
        for p in 0..fast.color.len() {
            for c in 0..3 {
                max_diff = max_diff.max((fast.color[p][c] - slow.color[p][c]).abs());
            }
            max_diff = max_diff.max((fast.depth[p] - slow.depth[p]).abs());
            max_diff = max_diff.max((fast.silhouette[p] - slow.silhouette[p]).abs());
        }
        assert!(max_diff <= 1e-4, "seed {seed}: max diff {max_diff}");
        assert_eq!(
            fast.labels.as_ref().expect("asked"),
            &slow.labels,
            "seed {seed}"
        );
        let tk = fast.top_k.as_ref().expect("asked");
        let mut truncated = 0;
        for y in 0..k.height {
            for x in 0..k.width {
                let want = &slow.top_k[(y * k.width + x) as usize];
                let got = top_k_by_id(tk, x, y);
                assert_eq!(got, stored_by_id(want), "seed {seed} pixel ({x}, {y})");
                truncated += (got.len() == 8) as usize;
            }
        }
        assert!(truncated > 0, "test should exercise truncation");
        assert_eq!(
            fast.visible_per_label.as_ref().expect("asked"),
            &slow.visible_per_label
        );
        // On-demand top-K replays give the same lists.
        let again = render(&map, &cam, &RenderRequest::color_depth());
        for (x, y) in [(0, 0), (35, 25), (71, 51), (10, 40), (60, 3)] {
            assert_eq!(
                stored_by_id(&again.top_k_at(x, y, 8)),
                top_k_by_id(tk, x, y),
                "seed {seed} pixel ({x}, {y})"
            );
        }
        // The cheap request renders the same images bit for bit.
        let plain = render(&map, &cam, &RenderRequest::color_depth()).output;
        assert_eq!(plain.color, fast.color);
        assert_eq!(plain.depth, fast.depth);
        assert!(plain.labels.is_none() && plain.top_k.is_none());
    }
}

#[test]
fn random_scene_exercises_the_renderer() {
    // Guards the comparison above against passing on an empty image.
    let k = Intrinsics::new(60.0, 62.0, 35.5, 25.0, 72, 52);
    let pose = crate::scene::look_at([0.1, -0.2, -0.3], [0.0, 0.0, 2.0]);
    let map = random_scene(600, 0);
    let out = render(
        &map,
        &Camera::from_pose(k, &pose, 0.1),
        &RenderRequest::semantic(8),
    )
    .output;
    let covered = out.silhouette.iter().filter(|&&s| s > 0.5).count();
    assert!(covered > out.silhouette.len() / 2, "covered {covered}");
    let labels = out.labels.expect("asked");
    let distinct: std::collections::BTreeSet<u32> = labels.iter().copied().collect();
    assert!(distinct.len() >= 4, "{distinct:?}");
    assert!(out.n_contrib.iter().any(|&n| n > 8));
}

#[test]
fn top_k_comes_front_to_back() {
    let ops = [0.1f32, 0.5, 0.2, 0.6, 0.3, 0.05];
    let gs: Vec<Gaussian> = ops
        .iter()
        .enumerate()
        .map(|(i, &o)| blob(2.0 + 0.1 * i as f32, 0.02, o, [0.5; 3], i as u32 + 1))
        .collect();
    let r = render(&map_of(&gs), &camera(0.05), &RenderRequest::semantic(3));
    let (ids, ws): (Vec<u32>, Vec<f32>) = r
        .output
        .top_k
        .as_ref()
        .expect("asked")
        .pixel(32, 24)
        .unzip();
    assert_eq!(ids, &[0, 1, 3]);
    assert!(close_weight(ws[1], 0.45));
}

#[test]
fn top_k_of_a_long_list_matches_the_formula() {
    // 40 stacked Gaussians (longer than the branch-free ranking path), opacities cycling.
    let ops: Vec<f32> = (0..40)
        .map(|i| 0.02 + 0.03 * ((i * 7) % 11) as f32)
        .collect();
    let gs: Vec<Gaussian> = ops
        .iter()
        .enumerate()
        .map(|(i, &o)| blob(2.0 + 0.01 * i as f32, 0.02, o, [0.5; 3], 1))
        .collect();
    let map = map_of(&gs);
    // Centre pixel: w_i = α_i·Π_{j<i}(1 − α_j), with α = the stored opacity.
    let mut t = 1.0f32;
    let mut want: Vec<(u32, f32)> = Vec::new();
    for i in 0..40 {
        let a = map.opacity(i);
        want.push((i as u32, a * t));
        t *= 1.0 - a;
    }
    want.sort_by(|a, b| b.1.total_cmp(&a.1));
    for k in [10usize, 50] {
        let r = render(&map, &camera(0.05), &RenderRequest::semantic(k));
        let (ids, ws) = heaviest_first(r.output.top_k.as_ref().expect("asked"), 32, 24);
        assert_eq!(ids.len(), k.min(40));
        for (j, (&id, &w)) in ids.iter().zip(&ws).enumerate() {
            assert_eq!(id, want[j].0, "k={k} position {j}");
            assert!(close_weight(w, want[j].1));
        }
    }
}

#[test]
fn portable_kernels_match_simd_kernels() {
    // The SIMD builds (AVX2 / AVX-512) must be bit-identical to the portable one.
    let k = Intrinsics::new(60.0, 62.0, 35.5, 25.0, 72, 52);
    let pose = crate::scene::look_at([0.1, -0.2, -0.3], [0.0, 0.0, 2.0]);
    let map = random_scene(600, 5);
    let cam = Camera::from_pose(k, &pose, 0.1);
    let only_labels = RenderRequest {
        labels: true,
        ..RenderRequest::default()
    };
    for req in [
        RenderRequest::semantic(8),
        RenderRequest::color_depth(),
        only_labels,
    ] {
        let simd = render(&map, &cam, &req).output;
        crate::cpu::cap_level(Some(crate::cpu::SimdLevel::Portable));
        let portable = render(&map, &cam, &req).output;
        crate::cpu::cap_level(None);
        assert_eq!(simd.color, portable.color);
        assert_eq!(simd.depth, portable.depth);
        assert_eq!(simd.final_transmittance, portable.final_transmittance);
        assert_eq!(simd.n_contrib, portable.n_contrib);
        assert_eq!(simd.labels, portable.labels);
        let (a, b) = (simd.top_k.as_ref(), portable.top_k.as_ref());
        assert_eq!(a.map(|t| t.entries()), b.map(|t| t.entries()));
        if let (Some(a), Some(b)) = (a, b) {
            for y in 0..k.height {
                for x in 0..k.width {
                    assert!(a.pixel(x, y).eq(b.pixel(x, y)));
                }
            }
        }
    }
}

#[test]
fn top_k_lists_are_front_to_back_on_random_scene() {
    // The entries (checked against the reference's heaviest-first lists elsewhere) come in
    // depth order.
    let k = Intrinsics::new(60.0, 62.0, 35.5, 25.0, 72, 52);
    let pose = crate::scene::look_at([0.1, -0.2, -0.3], [0.0, 0.0, 2.0]);
    let map = random_scene(600, 1);
    let cam = Camera::from_pose(k, &pose, 0.1);
    let plain = render(&map, &cam, &RenderRequest::color_depth());
    let mut truncated = 0;
    for top_k in [4usize, 8, 50] {
        let tk = render(&map, &cam, &RenderRequest::semantic(top_k))
            .output
            .top_k
            .expect("asked");
        for y in 0..k.height {
            for x in 0..k.width {
                let got: Vec<(u32, f32)> = tk.pixel(x, y).collect();
                let order: Vec<u32> = plain
                    .pixel_contributions(x, y)
                    .iter()
                    .map(|c| c.0)
                    .collect();
                let pos = |id: u32| order.iter().position(|&o| o == id);
                assert!(
                    got.windows(2).all(|p| pos(p[0].0) < pos(p[1].0)),
                    "({x}, {y})"
                );
                assert_eq!(got.len(), order.len().min(top_k), "k={top_k} ({x}, {y})");
                assert_eq!(tk.count[(y * k.width + x) as usize] as usize, got.len());
                truncated += (order.len() > top_k) as usize;
            }
        }
    }
    assert!(truncated > 0);
}

#[test]
fn crowded_rows_match_the_reference() {
    // 30 faint Gaussians stacked on each pixel centre of a 16×16 block: every pixel there
    // has several dozen contributions (more than K = 50) from a thousand Gaussians per row.
    let cam = camera(0.05);
    let mut gs = Vec::new();
    for layer in 0..30 {
        let z = 2.0 + 0.01 * layer as f32;
        for py in 16..32 {
            for px in 16..32 {
                let (x, y) = (
                    z * (px as f32 - 32.0) / 100.0,
                    z * (py as f32 - 24.0) / 100.0,
                );
                let mut g = blob(z, 0.01, 0.05, [0.2, 0.5, 0.8], 1 + (px + layer) as u32 % 3);
                g.mean = [x, y, z];
                gs.push(g);
            }
        }
    }
    let map = map_of(&gs);
    let fast = render(&map, &cam, &RenderRequest::semantic(50)).output;
    let slow = render_reference(&map, &cam, 50);
    assert_eq!(fast.labels.as_ref().expect("asked"), &slow.labels);
    let tk = fast.top_k.as_ref().expect("asked");
    let mut truncated = 0;
    for y in 0..48 {
        for x in 0..64 {
            let got = top_k_by_id(tk, x, y);
            let want = stored_by_id(&slow.top_k[(y * 64 + x) as usize]);
            assert_eq!(got, want, "pixel ({x}, {y})");
            truncated += (got.len() == 50) as usize;
        }
    }
    assert!(truncated > 0, "the block's pixels should be truncated to K");
    // The portable kernels build the same lists.
    crate::cpu::cap_level(Some(crate::cpu::SimdLevel::Portable));
    let portable = render(&map, &cam, &RenderRequest::semantic(50)).output;
    crate::cpu::cap_level(None);
    let tp = portable.top_k.as_ref().expect("asked");
    for y in 0..48 {
        for x in 0..64 {
            assert!(tk.pixel(x, y).eq(tp.pixel(x, y)), "pixel ({x}, {y})");
        }
    }
}

#[test]
fn rows_meeting_many_labels_are_voted_exactly() {
    // Labels from 40 values: many tile rows meet more labels than a row tracks, so their
    // pixels are voted from their lists (semantic requests) or a replay (labels only).
    let k = Intrinsics::new(60.0, 62.0, 35.5, 25.0, 72, 52);
    let pose = crate::scene::look_at([0.1, -0.2, -0.3], [0.0, 0.0, 2.0]);
    let map = random_scene_with_labels(900, 11, 40);
    let cam = Camera::from_pose(k, &pose, 0.1);
    let slow = render_reference(&map, &cam, 8);
    // How many tile rows meet more real labels than tracked.
    let rendered = render(&map, &cam, &RenderRequest::color_depth());
    let mut crowded = 0;
    for y in 0..k.height {
        for tx in 0..k.width.div_ceil(16) {
            let mut met = std::collections::BTreeSet::new();
            for x in tx * 16..(tx * 16 + 16).min(k.width) {
                for (id, _) in rendered.pixel_contributions(x, y) {
                    met.insert(map.labels[id as usize]);
                }
            }
            met.remove(&0);
            crowded += (met.len() > crate::row_votes::ROW_LABELS) as usize;
        }
    }
    assert!(crowded > 0, "the scene should crowd some rows with labels");
    for req in label_requests(8) {
        for (portable, o) in render_on_both_kernels(&map, &cam, &req) {
            assert_eq!(
                o.labels.as_ref().expect("asked"),
                &slow.labels,
                "{req:?} portable {portable} ({crowded} crowded rows)"
            );
        }
    }
}

/// `count` faint, wide Gaussians stacked on pixel (40, 24), rendered with top-K (K = 50,
/// heaviest first) and labels, against the reference. Opacity grows with depth, so the
/// heaviest are at the back; α from 0.005 (above 1/255) to 0.009 keeps T above e^-7.7 (above
/// the cut-off) through 1100 of them.
fn stack_matches_reference(count: usize) {
    let gs: Vec<Gaussian> = (0..count)
        .map(|i| {
            let z = 2.0 + 0.001 * i as f32;
            let opacity = 0.005 + 0.004 * i as f32 / count as f32;
            let mut g = blob(z, 0.05, opacity, [0.3, 0.6, 0.9], 1 + i as u32 % 5);
            g.mean = [z * 8.0 / 100.0, 0.0, z];
            g
        })
        .collect();
    let map = map_of(&gs);
    let cam = camera(0.05);
    let slow = render_reference(&map, &cam, 50);
    let seen = render(&map, &cam, &RenderRequest::color_depth());
    assert_eq!(
        seen.pixel_contributions(40, 24).len(),
        count,
        "all should reach the centre"
    );
    for (portable, o) in render_on_both_kernels(&map, &cam, &RenderRequest::semantic(50)) {
        assert_eq!(o.labels.as_ref().expect("asked"), &slow.labels);
        let tk = o.top_k.as_ref().expect("asked");
        for y in 0..48 {
            for x in 0..64 {
                let want = &slow.top_k[(y * 64 + x) as usize];
                assert_eq!(
                    top_k_by_id(tk, x, y),
                    stored_by_id(want),
                    "portable {portable} pixel ({x}, {y})"
                );
            }
        }
    }
}

#[test]
fn tiles_of_one_label_vote_it_without_sums_and_switch_exactly() {
    // A front layer of label 5 above row 40; behind it, label 9 on the right half (heavier
    // than the front where both are: it switches those tiles to summing mid-list, from the
    // silhouette so far), label 0 on the bottom rows, and one label-0 blob in front at the
    // top left (its tile sums from the first Gaussian). Tiles elsewhere stay uniform; the
    // bottom rows took only label 0 and vote 0.
    let mut gs = Vec::new();
    let mut layer = |z: f32, opacity: f32, label: u32, keep: &dyn Fn(f32, f32) -> bool| {
        for py in (2..48).step_by(4) {
            for px in (2..64).step_by(4) {
                let (px, py) = (px as f32, py as f32);
                if keep(px, py) {
                    let mut g = blob(z, 0.03, opacity, [0.4, 0.5, 0.6], label);
                    g.mean = [z * (px - 32.0) / 100.0, z * (py - 24.0) / 100.0, z];
                    gs.push(g);
                }
            }
        }
    };
    layer(1.5, 0.5, 0, &|px, py| px < 12.0 && py < 12.0);
    layer(2.0, 0.3, 5, &|_, py| py < 40.0);
    layer(2.5, 0.9, 9, &|px, _| px >= 32.0);
    layer(3.0, 0.9, 0, &|_, py| py >= 32.0);
    let map = map_of(&gs);
    let cam = camera(0.05);
    let slow = render_reference(&map, &cam, 50);
    let labels: std::collections::BTreeSet<u32> = slow.labels.iter().copied().collect();
    assert_eq!(labels, [0, 5, 9].into(), "the scene should vote 0, 5 and 9");
    for req in label_requests(50) {
        for (portable, o) in render_on_both_kernels(&map, &cam, &req) {
            assert_eq!(
                o.labels.as_ref().expect("asked"),
                &slow.labels,
                "{req:?} {portable}"
            );
        }
    }
}

#[test]
fn lists_longer_than_keep_heaviest_takes_match_the_reference() {
    // The centre pixels take 1100 contributions (their row's log grows past its first
    // allocation): the K heaviest are chosen by a sort of keys instead.
    stack_matches_reference(1100);
}

#[test]
fn long_lists_keep_their_heaviest() {
    // Lists of 60 and 100, the heaviest at the back: the K kept are chosen from 64 and 128
    // lanes (in registers on AVX-512).
    stack_matches_reference(60);
    stack_matches_reference(100);
}
