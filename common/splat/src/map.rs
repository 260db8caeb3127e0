//! The Gaussian map as a struct of arrays (docs/METHOD.md §1).

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

/// SH band-0 constant: colour = 0.5 + SH_C0 · f_dc.
pub const SH_C0: f32 = 0.282_094_8;

/// Converts an RGB colour channel to the SH DC coefficient stored in the map and in PLY.
pub fn color_to_sh_dc(c: f32) -> f32 {
    (c - 0.5) / SH_C0
}

/// Converts an SH DC coefficient to its (unclamped) colour channel.
pub fn sh_dc_to_color(f: f32) -> f32 {
    0.5 + SH_C0 * f
}

/// Logistic function: stored opacity logit → opacity.
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Inverse of [`sigmoid`], for building Gaussians from an opacity.
pub fn logit(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

/// One Gaussian, as pushed into or read from a [`GaussianMap`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gaussian {
    pub mean: [f32; 3],
    /// Unit quaternion (w, x, y, z).
    pub rotation: [f32; 4],
    pub log_scale: [f32; 3],
    pub opacity_logit: f32,
    /// SH degree-0 coefficients; colour = 0.5 + SH_C0 · sh_dc.
    pub sh_dc: [f32; 3],
    pub label: u32,
}

impl Gaussian {
    /// Builds a Gaussian from render-space values (colour in [0, 1], opacity in (0, 1), scales in metres).
    pub fn from_values(
        mean: [f32; 3],
        rotation: [f32; 4],
        scale: [f32; 3],
        opacity: f32,
        color: [f32; 3],
        label: u32,
    ) -> Self {
        Self {
            mean,
            rotation: normalize_quat(rotation),
            log_scale: scale.map(f32::ln),
            opacity_logit: logit(opacity),
            sh_dc: color.map(color_to_sh_dc),
            label,
        }
    }

    pub fn color(&self) -> [f32; 3] {
        self.sh_dc.map(sh_dc_to_color)
    }

    pub fn opacity(&self) -> f32 {
        sigmoid(self.opacity_logit)
    }

    pub fn scale(&self) -> [f32; 3] {
        self.log_scale.map(f32::exp)
    }
}

/// Normalises a (w, x, y, z) quaternion; a zero quaternion becomes the identity.
pub fn normalize_quat(q: [f32; 4]) -> [f32; 4] {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    if n > 0.0 && n.is_finite() {
        q.map(|v| v / n)
    } else {
        [1.0, 0.0, 0.0, 0.0]
    }
}

/// Rotation matrix of a (w, x, y, z) quaternion, normalised first (as 3DGS does).
pub fn quat_to_matrix(q: [f32; 4]) -> [[f32; 3]; 3] {
    let [r, x, y, z] = normalize_quat(q);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - r * z),
            2.0 * (x * z + r * y),
        ],
        [
            2.0 * (x * y + r * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - r * x),
        ],
        [
            2.0 * (x * z - r * y),
            2.0 * (y * z + r * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// World-space covariance R S Sᵀ Rᵀ (row-major), from rotation and log-scale, in f32 as the renderer uses it.
pub fn covariance3d(rotation: [f32; 4], log_scale: [f32; 3]) -> [[f32; 3]; 3] {
    let r = quat_to_matrix(rotation);
    let s = log_scale.map(f32::exp);
    // M = R·S, Σ = M·Mᵀ
    let m: [[f32; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| r[i][j] * s[j]));
    std::array::from_fn(|i| {
        std::array::from_fn(|j| m[i][0] * m[j][0] + m[i][1] * m[j][1] + m[i][2] * m[j][2])
    })
}

/// Gaussians stored column-wise: 60 bytes each (see [`GaussianMap::bytes_per_gaussian`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GaussianMap {
    pub means: Vec<[f32; 3]>,
    /// Unit quaternions (w, x, y, z).
    pub rotations: Vec<[f32; 4]>,
    pub log_scales: Vec<[f32; 3]>,
    pub opacity_logits: Vec<f32>,
    /// SH degree-0 coefficients (colour = 0.5 + SH_C0 · sh_dc); kept as f_dc so PLY round trips are exact.
    pub sh_dc: Vec<[f32; 3]>,
    pub labels: Vec<u32>,
}

impl GaussianMap {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn with_capacity(n: usize) -> Self {
        Self {
            means: Vec::with_capacity(n),
            rotations: Vec::with_capacity(n),
            log_scales: Vec::with_capacity(n),
            opacity_logits: Vec::with_capacity(n),
            sh_dc: Vec::with_capacity(n),
            labels: Vec::with_capacity(n),
        }
    }

    /// Memory per Gaussian in the map's arrays.
    pub const fn bytes_per_gaussian() -> usize {
        std::mem::size_of::<[f32; 3]>() * 3
            + std::mem::size_of::<[f32; 4]>()
            + std::mem::size_of::<f32>()
            + std::mem::size_of::<u32>()
    }

    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    pub fn push(&mut self, g: Gaussian) {
        self.means.push(g.mean);
        self.rotations.push(g.rotation);
        self.log_scales.push(g.log_scale);
        self.opacity_logits.push(g.opacity_logit);
        self.sh_dc.push(g.sh_dc);
        self.labels.push(g.label);
    }

    /// Appends all Gaussians of `other`.
    pub fn extend_from(&mut self, other: &GaussianMap) {
        self.means.extend_from_slice(&other.means);
        self.rotations.extend_from_slice(&other.rotations);
        self.log_scales.extend_from_slice(&other.log_scales);
        self.opacity_logits.extend_from_slice(&other.opacity_logits);
        self.sh_dc.extend_from_slice(&other.sh_dc);
        self.labels.extend_from_slice(&other.labels);
    }

    pub fn get(&self, i: usize) -> Gaussian {
        Gaussian {
            mean: self.means[i],
            rotation: self.rotations[i],
            log_scale: self.log_scales[i],
            opacity_logit: self.opacity_logits[i],
            sh_dc: self.sh_dc[i],
            label: self.labels[i],
        }
    }

    pub fn color(&self, i: usize) -> [f32; 3] {
        self.sh_dc[i].map(sh_dc_to_color)
    }

    pub fn opacity(&self, i: usize) -> f32 {
        sigmoid(self.opacity_logits[i])
    }

    pub fn scale(&self, i: usize) -> [f32; 3] {
        self.log_scales[i].map(f32::exp)
    }

    /// Covariance of Gaussian `i`: R S Sᵀ Rᵀ.
    pub fn covariance(&self, i: usize) -> Matrix3<f32> {
        let c = covariance3d(self.rotations[i], self.log_scales[i]);
        Matrix3::from_fn(|r, k| c[r][k])
    }

    /// Rotation of Gaussian `i` as a nalgebra unit quaternion.
    pub fn rotation(&self, i: usize) -> UnitQuaternion<f32> {
        let [w, x, y, z] = self.rotations[i];
        UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z))
    }

    pub fn mean(&self, i: usize) -> Vector3<f32> {
        Vector3::from(self.means[i])
    }

    /// Removes every Gaussian whose `remove` flag is set, keeping order.
    /// Returns the old→new index map (`None` for removed Gaussians).
    pub fn remove_where(&mut self, remove: &[bool]) -> Vec<Option<u32>> {
        assert_eq!(
            remove.len(),
            self.len(),
            "mask length must equal map length"
        );
        let mut old_to_new = Vec::with_capacity(self.len());
        let mut next = 0u32;
        for &r in remove {
            if r {
                old_to_new.push(None);
            } else {
                old_to_new.push(Some(next));
                next += 1;
            }
        }
        retain_by_mask(&mut self.means, remove);
        retain_by_mask(&mut self.rotations, remove);
        retain_by_mask(&mut self.log_scales, remove);
        retain_by_mask(&mut self.opacity_logits, remove);
        retain_by_mask(&mut self.sh_dc, remove);
        retain_by_mask(&mut self.labels, remove);
        old_to_new
    }

    /// Indices of the Gaussians carrying `label`.
    pub fn indices_with_label(&self, label: u32) -> Vec<u32> {
        (0..self.len() as u32)
            .filter(|&i| self.labels[i as usize] == label)
            .collect()
    }

    /// A new map with the Gaussians carrying `label` (e.g. to extract an object).
    pub fn select_label(&self, label: u32) -> GaussianMap {
        self.select(&self.indices_with_label(label))
    }

    /// A new map with the Gaussians at `indices`, in that order.
    pub fn select(&self, indices: &[u32]) -> GaussianMap {
        let mut out = GaussianMap::with_capacity(indices.len());
        for &i in indices {
            out.push(self.get(i as usize));
        }
        out
    }

    /// Number of Gaussians per label (index = label), for completeness (§5.2).
    pub fn count_per_label(&self) -> std::collections::BTreeMap<u32, u32> {
        let mut counts = std::collections::BTreeMap::new();
        for &l in &self.labels {
            *counts.entry(l).or_insert(0) += 1;
        }
        counts
    }
}

fn retain_by_mask<T>(v: &mut Vec<T>, remove: &[bool]) {
    let mut i = 0;
    v.retain(|_| {
        let keep = !remove[i];
        i += 1;
        keep
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn g(label: u32, x: f32) -> Gaussian {
        Gaussian::from_values(
            [x, 0.0, 1.0],
            [1.0, 0.0, 0.0, 0.0],
            [0.01; 3],
            0.5,
            [0.2, 0.4, 0.6],
            label,
        )
    }

    #[test]
    fn at_most_64_bytes_per_gaussian() {
        assert_eq!(GaussianMap::bytes_per_gaussian(), 60);
    }

    #[test]
    fn remove_and_select() {
        let mut m = GaussianMap::new();
        for i in 0..5 {
            m.push(g(i % 2, i as f32));
        }
        let map = m.remove_where(&[false, true, false, true, true]);
        assert_eq!(map, vec![Some(0), None, Some(1), None, None]);
        assert_eq!(m.len(), 2);
        assert_eq!(m.means[1][0], 2.0);
        assert_eq!(m.select_label(0).len(), 2);
        assert_eq!(m.indices_with_label(1), Vec::<u32>::new());
    }

    #[test]
    fn covariance_of_rotated_scaled_gaussian() {
        // 90° about z swaps the x and y variances.
        let s = std::f32::consts::FRAC_1_SQRT_2;
        let mut m = GaussianMap::new();
        m.push(Gaussian::from_values(
            [0.0; 3],
            [s, 0.0, 0.0, s],
            [0.1, 0.2, 0.3],
            0.5,
            [0.5; 3],
            1,
        ));
        let c = m.covariance(0);
        assert!((c[(0, 0)] - 0.04).abs() < 1e-6);
        assert!((c[(1, 1)] - 0.01).abs() < 1e-6);
        assert!((c[(2, 2)] - 0.09).abs() < 1e-6);
        assert!(c[(0, 1)].abs() < 1e-6);
        let col = m.color(0);
        assert!((col[0] - 0.5).abs() < 1e-6);
        assert!((m.opacity(0) - 0.5).abs() < 1e-6);
    }
}
