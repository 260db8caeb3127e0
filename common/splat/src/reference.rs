//! Slow, obviously-correct twins of the fast kernels, for tests: the renderer (every pixel
//! walks every Gaussian in depth order, restricted only to the Gaussian's 3DGS tile
//! rectangle, as the spec says) and the mapping loss (plane by plane).

use std::collections::BTreeMap;

use crate::blend::{alpha_of, gaussian_power, MIN_ALPHA, MIN_TRANSMITTANCE};
use crate::camera::Camera;
use crate::fused_loss::sign;
use crate::loss::{LossValue, LossWeights};
use crate::map::GaussianMap;
use crate::project::{project_gaussian, radius_tile_rect, ProjectedGaussian};
use crate::ssim::{ssim_plane, SsimScratch};
use crate::target::TargetFrame;
use crate::tiles::{TileGrid, TILE_SIZE};

pub struct RefOutput {
    pub color: Vec<[f32; 3]>,
    pub depth: Vec<f32>,
    pub silhouette: Vec<f32>,
    pub labels: Vec<u32>,
    /// Per pixel: (Gaussian id, weight), sorted by weight desc, ties front first, ≤ K.
    pub top_k: Vec<Vec<(u32, f32)>>,
    pub visible_per_label: BTreeMap<u32, u32>,
}

pub fn render_reference(map: &GaussianMap, cam: &Camera, k: usize) -> RefOutput {
    let grid = TileGrid::new(cam.width(), cam.height());
    let mut gs: Vec<(usize, ProjectedGaussian)> = (0..map.len())
        .filter_map(|i| {
            project_gaussian(
                cam,
                map.means[i],
                map.rotations[i],
                map.log_scales[i],
                map.opacity_logits[i],
                map.sh_dc[i],
            )
            .map(|g| (i, g))
        })
        .collect();
    gs.sort_by(|a, b| a.1.depth.total_cmp(&b.1.depth).then(a.0.cmp(&b.0)));
    let rects: Vec<_> = gs
        .iter()
        .map(|(_, g)| radius_tile_rect(g.mean2d, g.radius, &grid))
        .collect();
    let n = (grid.width * grid.height) as usize;
    let mut out = RefOutput {
        color: vec![[0.0; 3]; n],
        depth: vec![0.0; n],
        silhouette: vec![0.0; n],
        labels: vec![0; n],
        top_k: vec![Vec::new(); n],
        visible_per_label: BTreeMap::new(),
    };
    let mut visible = vec![false; map.len()];
    for y in 0..grid.height {
        for x in 0..grid.width {
            let p = (y * grid.width + x) as usize;
            let mut t = 1.0f32;
            let mut sums: Vec<(u32, f32)> = Vec::new();
            let mut contribs: Vec<(u32, f32)> = Vec::new();
            for ((id, g), rect) in gs.iter().zip(&rects) {
                if !rect.contains(x / TILE_SIZE, y / TILE_SIZE) {
                    continue;
                }
                let power = gaussian_power(g.conic, g.mean2d[0] - x as f32, g.mean2d[1] - y as f32);
                if power > 0.0 {
                    continue;
                }
                let alpha = alpha_of(g.opacity, power);
                if alpha < MIN_ALPHA {
                    continue;
                }
                let test_t = t * (1.0 - alpha);
                if test_t < MIN_TRANSMITTANCE {
                    break;
                }
                let w = alpha * t;
                for c in 0..3 {
                    out.color[p][c] += g.color[c] * w;
                }
                out.depth[p] += g.depth * w;
                out.silhouette[p] += w;
                t = test_t;
                visible[*id] = true;
                contribs.push((*id as u32, w));
                let label = map.labels[*id];
                if label != 0 {
                    match sums.iter_mut().find(|(l, _)| *l == label) {
                        Some(e) => e.1 += w,
                        None => sums.push((label, w)),
                    }
                }
            }
            // Largest sum wins, ties to the smaller label.
            out.labels[p] = sums
                .iter()
                .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
                .map_or(0, |e| e.0);
            contribs.sort_by(|a, b| b.1.total_cmp(&a.1)); // stable: front first on ties
            contribs.truncate(k);
            out.top_k[p] = contribs;
        }
    }
    for (i, v) in visible.iter().enumerate() {
        if *v {
            *out.visible_per_label.entry(map.labels[i]).or_insert(0) += 1;
        }
    }
    out
}

/// The mapping loss as it was before the fused kernel ([`crate::Loss::eval`]'s twin): plane
/// by plane, the L1 sign and sums, then [`ssim_plane`] per channel (seven full-size blurred
/// planes), then the depth term. Same value and gradients to rounding.
pub fn loss_reference(
    color: &[[f32; 3]],
    depth: &[f32],
    target: &TargetFrame,
    w: &LossWeights,
    dl_dcolor: &mut Vec<[f32; 3]>,
    dl_ddepth: &mut Vec<f32>,
) -> LossValue {
    let n = target.pixels();
    assert!(
        color.len() == n && depth.len() == n,
        "render and target sizes differ"
    );
    dl_dcolor.clear();
    dl_dcolor.resize(n, [0.0; 3]);
    dl_ddepth.clear();
    dl_ddepth.resize(n, 0.0);
    let (wd, hd) = (target.width as usize, target.height as usize);
    let inv_n3 = 1.0 / (3 * n) as f32;
    let mut scratch = SsimScratch::default();
    let mut render_plane = vec![0.0f32; n];
    let mut grad_plane = vec![0.0f32; n];

    let (mut l1, mut sq_err, mut ssim_sum) = (0.0f64, 0.0f64, 0.0f64);
    for c in 0..3 {
        let tp = &target.rgb[c];
        for i in 0..n {
            let (x, y) = (color[i][c], tp[i]);
            render_plane[i] = x;
            grad_plane[i] = w.l1 * inv_n3 * sign(x - y);
            l1 += (x - y).abs() as f64;
            let e = x.clamp(0.0, 1.0) - y;
            sq_err += (e * e) as f64;
        }
        ssim_sum += ssim_plane(
            &render_plane,
            tp,
            wd,
            hd,
            -w.ssim * inv_n3,
            Some(&mut grad_plane),
            &mut scratch,
        );
        for (g, &v) in dl_dcolor.iter_mut().zip(&grad_plane) {
            g[c] = v;
        }
    }

    if w.colour_needs_depth {
        crate::loss::hold_colour_without_depth(dl_dcolor, &target.depth);
    }
    let valid = target.depth.iter().filter(|&&d| d > 0.0).count();
    let mut depth_l1 = 0.0f64;
    if valid > 0 {
        let k = w.depth / valid as f32;
        for ((g, &d), &t) in dl_ddepth.iter_mut().zip(depth).zip(&target.depth) {
            if t > 0.0 {
                *g = k * sign(d - t);
                depth_l1 += (d - t).abs() as f64;
            }
        }
        depth_l1 /= valid as f64;
    }
    let l1 = (l1 / (3 * n) as f64) as f32;
    let ssim = (ssim_sum / (3 * n) as f64) as f32;
    let mse = sq_err / (3 * n) as f64;
    LossValue {
        total: w.l1 * l1 + w.ssim * (1.0 - ssim) + w.depth * depth_l1 as f32,
        l1,
        ssim,
        depth_l1: depth_l1 as f32,
        psnr: (-10.0 * mse.max(1e-20).log10()) as f32,
    }
}
