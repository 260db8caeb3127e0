//! Backward of the EWA projection (reference 3DGS `preprocess` / `computeCov2D` backward):
//! screen-space gradients → mean, quaternion, log-scale, opacity logit and SH DC.
//!
//! Forward recap: p = W·m + t, u = fx·p.x/p.z + cx, Σ' = J·W·Σ·Wᵀ·Jᵀ + 0.3·I with
//! J = [[fx/z, 0, −fx·tx/z²], [0, fy/z, −fy·ty/z²]] (tx, ty = clamped p.x, p.y),
//! conic = Σ'⁻¹, Σ = R·S·Sᵀ·Rᵀ, S = exp(log_scale), R from the normalised quaternion.

use crate::camera::Camera;
use crate::map::{normalize_quat, quat_to_matrix, SH_C0};
use crate::raster_backward::ScreenGrad;

type M3 = [[f32; 3]; 3];

/// Parameter gradients of one Gaussian.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GaussianGrad {
    pub mean: [f32; 3],
    pub rotation: [f32; 4],
    pub log_scale: [f32; 3],
    pub opacity_logit: f32,
    pub sh_dc: [f32; 3],
}

/// Chains `g` back through the projection of one Gaussian (which must not have been culled).
pub fn project_backward(
    cam: &Camera,
    mean: [f32; 3],
    rotation: [f32; 4],
    log_scale: [f32; 3],
    opacity_logit: f32,
    sh_dc: [f32; 3],
    g: &ScreenGrad,
) -> GaussianGrad {
    let k = &cam.intrinsics;
    let (fx, fy) = (k.fx as f32, k.fy as f32);
    let w = &cam.rotation;
    let p = cam.to_camera(mean);
    let z = p[2];
    let lim_x = 1.3 * (k.width as f32 / (2.0 * fx));
    let lim_y = 1.3 * (k.height as f32 / (2.0 * fy));
    let (rx, ry) = (p[0] / z, p[1] / z);
    let (tx, ty) = (rx.clamp(-lim_x, lim_x) * z, ry.clamp(-lim_y, lim_y) * z);
    let j = [
        [fx / z, 0.0, -(fx * tx) / (z * z)],
        [0.0, fy / z, -(fy * ty) / (z * z)],
    ];
    let t: [[f32; 3]; 2] = std::array::from_fn(|r| {
        std::array::from_fn(|c| j[r][0] * w[0][c] + j[r][1] * w[1][c] + j[r][2] * w[2][c])
    });
    let rot = quat_to_matrix(rotation);
    let s = log_scale.map(f32::exp);
    let m: M3 = std::array::from_fn(|i| std::array::from_fn(|jj| rot[i][jj] * s[jj]));
    let sigma: M3 = std::array::from_fn(|i| {
        std::array::from_fn(|jj| m[i][0] * m[jj][0] + m[i][1] * m[jj][1] + m[i][2] * m[jj][2])
    });
    let ts: [[f32; 3]; 2] = std::array::from_fn(|r| {
        std::array::from_fn(|c| (0..3).map(|kk| t[r][kk] * sigma[kk][c]).sum())
    });
    let cov = |r: usize, c: usize| ts[r][0] * t[c][0] + ts[r][1] * t[c][1] + ts[r][2] * t[c][2];
    let (a, b, c) = (cov(0, 0) + 0.3, cov(0, 1), cov(1, 1) + 0.3);
    let det_inv = 1.0 / (a * c - b * b);
    let q = [[c * det_inv, -b * det_inv], [-b * det_inv, a * det_inv]];

    // Conic → Σ': with symmetric-matrix gradients, dL/dΣ' = −Q·(dL/dQ)·Q.
    let gq = [
        [g.conic[0], 0.5 * g.conic[1]],
        [0.5 * g.conic[1], g.conic[2]],
    ];
    let qg: [[f32; 2]; 2] = std::array::from_fn(|r| {
        std::array::from_fn(|cc| q[r][0] * gq[0][cc] + q[r][1] * gq[1][cc])
    });
    let g2: [[f32; 2]; 2] = std::array::from_fn(|r| {
        std::array::from_fn(|cc| -(qg[r][0] * q[0][cc] + qg[r][1] * q[1][cc]))
    });

    // Σ' = T·Σ·Tᵀ: dL/dΣ = Tᵀ·G2·T and dL/dT = 2·G2·T·Σ.
    let g2t: [[f32; 3]; 2] = std::array::from_fn(|r| {
        std::array::from_fn(|cc| g2[r][0] * t[0][cc] + g2[r][1] * t[1][cc])
    });
    let g_sigma: M3 = std::array::from_fn(|i| {
        std::array::from_fn(|jj| t[0][i] * g2t[0][jj] + t[1][i] * g2t[1][jj])
    });
    let g_t: [[f32; 3]; 2] = std::array::from_fn(|r| {
        std::array::from_fn(|cc| 2.0 * (0..3).map(|kk| g2t[r][kk] * sigma[kk][cc]).sum::<f32>())
    });
    // T = J·W: dL/dJ = dL/dT·Wᵀ.
    let g_j: [[f32; 3]; 2] = std::array::from_fn(|r| {
        std::array::from_fn(|kk| (0..3).map(|cc| g_t[r][cc] * w[kk][cc]).sum())
    });

    // J, centre and depth → camera-frame point.
    let (z2, z3) = (z * z, z * z * z);
    let mut gp = [0.0f32; 3];
    gp[2] += -fx / z2 * g_j[0][0] - fy / z2 * g_j[1][1]
        + 2.0 * fx * tx / z3 * g_j[0][2]
        + 2.0 * fy * ty / z3 * g_j[1][2];
    let (g_tx, g_ty) = (-fx / z2 * g_j[0][2], -fy / z2 * g_j[1][2]);
    // Unclamped: tx = p.x; clamped: tx = ±lim·z.
    if rx < -lim_x || rx > lim_x {
        gp[2] += g_tx * rx.clamp(-lim_x, lim_x);
    } else {
        gp[0] += g_tx;
    }
    if ry < -lim_y || ry > lim_y {
        gp[2] += g_ty * ry.clamp(-lim_y, lim_y);
    } else {
        gp[1] += g_ty;
    }
    gp[0] += fx / z * g.mean2d[0];
    gp[1] += fy / z * g.mean2d[1];
    gp[2] -= (fx * p[0] * g.mean2d[0] + fy * p[1] * g.mean2d[1]) / z2;
    gp[2] += g.depth;
    let g_mean = std::array::from_fn(|cc| w[0][cc] * gp[0] + w[1][cc] * gp[1] + w[2][cc] * gp[2]);

    // Σ = M·Mᵀ with M = R·S: dL/dM = 2·dL/dΣ·M.
    let g_m: M3 = std::array::from_fn(|i| {
        std::array::from_fn(|jj| 2.0 * (0..3).map(|kk| g_sigma[i][kk] * m[kk][jj]).sum::<f32>())
    });
    let g_log_scale = std::array::from_fn(|jj| {
        let g_s: f32 = (0..3).map(|i| g_m[i][jj] * rot[i][jj]).sum();
        g_s * s[jj]
    });
    let g_rot: M3 = std::array::from_fn(|i| std::array::from_fn(|jj| g_m[i][jj] * s[jj]));

    let opacity = 1.0 / (1.0 + (-opacity_logit).exp());
    GaussianGrad {
        mean: g_mean,
        rotation: quat_backward(rotation, &g_rot),
        log_scale: g_log_scale,
        opacity_logit: g.opacity * opacity * (1.0 - opacity),
        // The renderer clamps colour at 0, which kills the gradient there.
        sh_dc: std::array::from_fn(|cc| {
            if 0.5 + SH_C0 * sh_dc[cc] > 0.0 {
                SH_C0 * g.color[cc]
            } else {
                0.0
            }
        }),
    }
}

/// dL/dq for the stored quaternion q, given dL/dR of R(q/|q|).
fn quat_backward(q: [f32; 4], g: &M3) -> [f32; 4] {
    let [r, x, y, z] = normalize_quat(q);
    let gn = [
        2.0 * (-z * g[0][1] + y * g[0][2] + z * g[1][0] - x * g[1][2] - y * g[2][0] + x * g[2][1]),
        2.0 * (y * g[0][1] + z * g[0][2] + y * g[1][0] - 2.0 * x * g[1][1] - r * g[1][2]
            + z * g[2][0]
            + r * g[2][1]
            - 2.0 * x * g[2][2]),
        2.0 * (-2.0 * y * g[0][0] + x * g[0][1] + r * g[0][2] + x * g[1][0] + z * g[1][2]
            - r * g[2][0]
            + z * g[2][1]
            - 2.0 * y * g[2][2]),
        2.0 * (-2.0 * z * g[0][0] - r * g[0][1] + x * g[0][2] + r * g[1][0] - 2.0 * z * g[1][1]
            + y * g[1][2]
            + x * g[2][0]
            + y * g[2][1]),
    ];
    // Through q̂ = q/|q|: dL/dq = (gn − q̂·(q̂·gn)) / |q|.
    let norm = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    if !(norm > 0.0 && norm.is_finite()) {
        return [0.0; 4];
    }
    let qn = [r, x, y, z];
    let dot: f32 = (0..4).map(|i| qn[i] * gn[i]).sum();
    std::array::from_fn(|i| (gn[i] - qn[i] * dot) / norm)
}
