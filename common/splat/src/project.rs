//! EWA projection of 3D Gaussians to screen space (docs/METHOD.md §2, reference 3DGS `preprocess`).

use rayon::prelude::*;

use crate::blend::MIN_ALPHA;
use crate::camera::Camera;
use crate::map::{covariance3d, sh_dc_to_color, sigmoid, GaussianMap};
use crate::tiles::{TileGrid, TileRect, TILE_SIZE};

/// Screen-space data of one Gaussian, exactly as the 3DGS forward computes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProjectedGaussian {
    /// Projected centre in pixels (OpenCV: pixel (u, v) centred at (u, v)).
    pub mean2d: [f32; 2],
    /// Camera-frame z.
    pub depth: f32,
    /// Inverse 2D covariance (a, b, c) = [[a, b], [b, c]].
    pub conic: [f32; 3],
    /// 2D covariance (incl. +0.3 dilation) as (xx, xy, yy).
    pub cov2d: [f32; 3],
    /// ceil(3·sqrt(λmax)).
    pub radius: u32,
    pub opacity: f32,
    /// RGB clamped at ≥ 0.
    pub color: [f32; 3],
}

/// Projects one Gaussian; `None` when culled by the near plane or a degenerate 2D covariance.
#[inline]
pub fn project_gaussian(
    cam: &Camera,
    mean: [f32; 3],
    rotation: [f32; 4],
    log_scale: [f32; 3],
    opacity_logit: f32,
    sh_dc: [f32; 3],
) -> Option<ProjectedGaussian> {
    let k = &cam.intrinsics;
    let (fx, fy, cx, cy) = (k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32);
    let p = cam.to_camera(mean);
    let tz = p[2];
    if tz <= cam.near {
        return None;
    }
    // EWA Jacobian with x/z, y/z clamped to 1.3·tan(fov/2) (3DGS computeCov2D).
    let lim_x = 1.3 * (k.width as f32 / (2.0 * fx));
    let lim_y = 1.3 * (k.height as f32 / (2.0 * fy));
    let tx = (p[0] / tz).clamp(-lim_x, lim_x) * tz;
    let ty = (p[1] / tz).clamp(-lim_y, lim_y) * tz;
    let j = [
        [fx / tz, 0.0, -(fx * tx) / (tz * tz)],
        [0.0, fy / tz, -(fy * ty) / (tz * tz)],
    ];
    let w = &cam.rotation;
    // T = J·W (2×3)
    let t: [[f32; 3]; 2] = std::array::from_fn(|r| {
        std::array::from_fn(|c| j[r][0] * w[0][c] + j[r][1] * w[1][c] + j[r][2] * w[2][c])
    });
    let s = covariance3d(rotation, log_scale);
    // T·Σ (2×3), then (T·Σ)·Tᵀ (2×2)
    let ts: [[f32; 3]; 2] = std::array::from_fn(|r| {
        std::array::from_fn(|c| t[r][0] * s[0][c] + t[r][1] * s[1][c] + t[r][2] * s[2][c])
    });
    let cov = |r: usize, c: usize| ts[r][0] * t[c][0] + ts[r][1] * t[c][1] + ts[r][2] * t[c][2];
    let a = cov(0, 0) + 0.3;
    let b = cov(0, 1);
    let c = cov(1, 1) + 0.3;
    let det = a * c - b * b;
    if det == 0.0 {
        return None;
    }
    let det_inv = 1.0 / det;
    let conic = [c * det_inv, -b * det_inv, a * det_inv];
    let mid = 0.5 * (a + c);
    let lambda1 = mid + (mid * mid - det).max(0.1).sqrt();
    let radius = (3.0 * lambda1.sqrt()).ceil() as u32;
    let mean2d = [fx * p[0] / tz + cx, fy * p[1] / tz + cy];
    Some(ProjectedGaussian {
        mean2d,
        depth: tz,
        conic,
        cov2d: [a, b, c],
        radius,
        opacity: sigmoid(opacity_logit),
        color: sh_dc.map(|f| sh_dc_to_color(f).max(0.0)),
    })
}

/// Tiles touched by a radius around `mean2d`, exactly as 3DGS `getRect` (truncating division).
pub fn radius_tile_rect(mean2d: [f32; 2], radius: u32, grid: &TileGrid) -> TileRect {
    let r = radius as f32;
    let t = TILE_SIZE as f32;
    let clamp = |v: f32, hi: u32| (v as i32).max(0).min(hi as i32) as u32;
    TileRect {
        x0: clamp((mean2d[0] - r) / t, grid.tiles_x),
        y0: clamp((mean2d[1] - r) / t, grid.tiles_y),
        x1: clamp((mean2d[0] + r + t - 1.0) / t, grid.tiles_x),
        y1: clamp((mean2d[1] + r + t - 1.0) / t, grid.tiles_y),
    }
}

/// Region where a Gaussian can reach α ≥ 1/255: q = dᵀ·conic·d ≤ `q_max`, inside ±(`half_w`, `half_h`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AlphaEllipse {
    /// Threshold on q with a safety margin for f32 rounding (conservative).
    pub q_max: f32,
    pub half_w: f32,
    pub half_h: f32,
}

impl AlphaEllipse {
    /// `None` when the Gaussian can never reach α ≥ 1/255.
    pub fn of(g: &ProjectedGaussian) -> Option<Self> {
        if g.opacity < MIN_ALPHA {
            return None;
        }
        // o·e^(−q/2) ≥ 1/255  ⇔  q ≤ 2·ln(255·o)
        let q = 2.0 * (g.opacity / MIN_ALPHA).ln().max(0.0);
        let [sxx, _, syy] = g.cov2d;
        let [a, b, c] = g.conic;
        let (w0, h0) = ((q * sxx).sqrt() * 1.01 + 1.0, (q * syy).sqrt() * 1.01 + 1.0);
        // f32 rounding of q at a pixel is a few ulp of its largest term inside the box.
        let term_bound = a * w0 * w0 + 2.0 * b.abs() * w0 * h0 + c * h0 * h0;
        let q_max = q * 1.001 + 1e-3 + 1e-5 * term_bound;
        Some(Self {
            q_max,
            half_w: (q_max * sxx).sqrt() + 0.01,
            half_h: (q_max * syy).sqrt() + 0.01,
        })
    }
}

/// Projected Gaussians, one entry per map Gaussian (culled ones have an empty `tile_rects` entry).
/// Kept as plain arrays so a backward pass can reuse them.
#[derive(Debug, Clone, Default)]
pub struct Projected {
    pub means2d: Vec<[f32; 2]>,
    pub depths: Vec<f32>,
    pub conics: Vec<[f32; 3]>,
    pub radii: Vec<u32>,
    pub opacities: Vec<f32>,
    pub colors: Vec<[f32; 3]>,
    pub ellipses: Vec<AlphaEllipse>,
    /// Tiles binned: the 3DGS radius rectangle ∩ the α-ellipse box (empty = culled).
    pub tile_rects: Vec<TileRect>,
}

impl Projected {
    pub fn len(&self) -> usize {
        self.means2d.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means2d.is_empty()
    }
}

/// Cheap exact pre-cull: true when the Gaussian surely projects to no tile or can never
/// reach α ≥ 1/255, judged from an upper bound of its 3DGS radius (skips the covariance).
#[inline]
fn surely_culled(
    cam: &Camera,
    grid: &TileGrid,
    mean: [f32; 3],
    log_scale: [f32; 3],
    opacity_logit: f32,
) -> bool {
    // sigmoid(x) < 1/255 ⇔ x < −ln 254 ≈ −5.537; the margin keeps f32 rounding on the safe side.
    if opacity_logit < -5.6 {
        return true;
    }
    let p = cam.to_camera(mean);
    let z = p[2];
    if z <= cam.near {
        return true;
    }
    let k = &cam.intrinsics;
    let (fx, fy) = (k.fx as f32, k.fy as f32);
    let lim_x = 1.3 * (k.width as f32 / (2.0 * fx));
    let lim_y = 1.3 * (k.height as f32 / (2.0 * fy));
    let (rx, ry) = (
        (p[0] / z).clamp(-lim_x, lim_x),
        (p[1] / z).clamp(-lim_y, lim_y),
    );
    // λmax(Σ') ≤ tr(Σ') + √0.1 ≤ ‖J‖²_F·s²max + 0.6 + √0.1
    let j2 = (fx / z) * (fx / z) * (1.0 + rx * rx) + (fy / z) * (fy / z) * (1.0 + ry * ry);
    let s_max = log_scale[0].max(log_scale[1]).max(log_scale[2]);
    // exp_approx (≈1 ulp, inlined) instead of a libm call: the 1.01 margin below covers it.
    let lambda = j2 * crate::blend::exp_approx(2.0 * s_max) + 0.92;
    let r_bound = (3.0 * lambda.sqrt() * 1.01 + 2.0).ceil() as u32;
    let mean2d = [fx * p[0] / z + k.cx as f32, fy * p[1] / z + k.cy as f32];
    radius_tile_rect(mean2d, r_bound, grid).is_empty()
}

/// Projects every Gaussian of the map (rayon-parallel).
pub fn project(map: &GaussianMap, cam: &Camera, grid: &TileGrid) -> Projected {
    let mut out = Projected::default();
    project_into(map, cam, grid, &mut out);
    out
}

/// [`project`] into existing arrays, reusing their allocations.
pub fn project_into(map: &GaussianMap, cam: &Camera, grid: &TileGrid, out: &mut Projected) {
    let n = map.len();
    out.means2d.resize(n, [0.0; 2]);
    out.depths.resize(n, 0.0);
    out.conics.resize(n, [0.0; 3]);
    out.radii.resize(n, 0);
    out.opacities.resize(n, 0.0);
    out.colors.resize(n, [0.0; 3]);
    out.ellipses.resize(n, AlphaEllipse::default());
    out.tile_rects.resize(n, TileRect::EMPTY);
    const CHUNK: usize = 4096;
    let chunks: Vec<_> = out
        .means2d
        .chunks_mut(CHUNK)
        .zip(out.depths.chunks_mut(CHUNK))
        .zip(out.conics.chunks_mut(CHUNK))
        .zip(out.radii.chunks_mut(CHUNK))
        .zip(out.opacities.chunks_mut(CHUNK))
        .zip(out.colors.chunks_mut(CHUNK))
        .zip(out.ellipses.chunks_mut(CHUNK))
        .zip(out.tile_rects.chunks_mut(CHUNK))
        .enumerate()
        .collect();
    chunks.into_par_iter().for_each(
        |(c, (((((((means2d, depths), conics), radii), opacities), colors), ellipses), rects))| {
            for j in 0..means2d.len() {
                let i = c * CHUNK + j;
                let (g, e, rect) = project_one(map, cam, grid, i);
                means2d[j] = g.mean2d;
                depths[j] = g.depth;
                conics[j] = g.conic;
                radii[j] = g.radius;
                opacities[j] = g.opacity;
                colors[j] = g.color;
                ellipses[j] = e;
                rects[j] = rect;
            }
        },
    );
}

/// Projection of Gaussian `i` with its α-ellipse and binned tiles (empty when culled).
#[inline]
fn project_one(
    map: &GaussianMap,
    cam: &Camera,
    grid: &TileGrid,
    i: usize,
) -> (ProjectedGaussian, AlphaEllipse, TileRect) {
    let culled = (
        ProjectedGaussian::culled(),
        AlphaEllipse::default(),
        TileRect::EMPTY,
    );
    if surely_culled(
        cam,
        grid,
        map.means[i],
        map.log_scales[i],
        map.opacity_logits[i],
    ) {
        return culled;
    }
    let Some(g) = project_gaussian(
        cam,
        map.means[i],
        map.rotations[i],
        map.log_scales[i],
        map.opacity_logits[i],
        map.sh_dc[i],
    ) else {
        return culled;
    };
    let rect = radius_tile_rect(g.mean2d, g.radius, grid);
    let Some(e) = AlphaEllipse::of(&g) else {
        return (g, AlphaEllipse::default(), TileRect::EMPTY);
    };
    let tight = rect.intersect(&grid.tiles_of_box(g.mean2d, e.half_w, e.half_h));
    (g, e, tight)
}

impl ProjectedGaussian {
    fn culled() -> Self {
        Self {
            mean2d: [0.0; 2],
            depth: 0.0,
            conic: [0.0; 3],
            cov2d: [0.0; 3],
            radius: 0,
            opacity: 0.0,
            color: [0.0; 3],
        }
    }
}
