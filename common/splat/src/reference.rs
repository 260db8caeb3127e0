//! Slow, obviously-correct renderer for tests: every pixel walks every Gaussian in depth
//! order, restricted only to the Gaussian's 3DGS tile rectangle (as the spec says).

use std::collections::BTreeMap;

use crate::blend::{alpha_of, gaussian_power, MIN_ALPHA, MIN_TRANSMITTANCE};
use crate::camera::Camera;
use crate::map::GaussianMap;
use crate::project::{project_gaussian, radius_tile_rect, ProjectedGaussian};
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
