//! Camera-frame points and surface normals from depth by finite differences.

use opengs_geometry::Intrinsics;

/// Back-projected point and unit normal per coarse pixel; a zero normal
/// means "unknown" (missing depth or no continuous neighbour).
#[derive(Debug, Clone, Default)]
pub struct SurfaceGeometry {
    pub points: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
}

impl SurfaceGeometry {
    /// `k` must be the camera at the coarse resolution; `max_jump` is the
    /// relative depth step beyond which two neighbours are not differentiated.
    pub fn from_depth(
        depth_m: &[f32],
        width: usize,
        height: usize,
        k: &Intrinsics,
        max_jump: f32,
    ) -> Self {
        let (fx, fy, cx, cy) = (k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32);
        let points: Vec<[f32; 3]> = depth_m
            .iter()
            .enumerate()
            .map(|(i, &z)| {
                let (u, v) = ((i % width) as f32, (i / width) as f32);
                [(u - cx) * z / fx, (v - cy) * z / fy, z]
            })
            .collect();
        let continuous = |a: usize, b: usize| {
            let (za, zb) = (depth_m[a], depth_m[b]);
            za > 0.0 && zb > 0.0 && (za - zb).abs() <= max_jump * za.min(zb)
        };
        // Central difference where both sides continue the surface, else the
        // continuous side only: normals never straddle a depth edge.
        let tangent = |i: usize, prev: Option<usize>, next: Option<usize>| -> Option<[f32; 3]> {
            let p = prev.filter(|&j| continuous(i, j));
            let n = next.filter(|&j| continuous(i, j));
            let (a, b) = match (p, n) {
                (Some(p), Some(n)) => (p, n),
                (Some(p), None) => (p, i),
                (None, Some(n)) => (i, n),
                (None, None) => return None,
            };
            Some(sub(points[b], points[a]))
        };
        let mut normals = vec![[0.0f32; 3]; points.len()];
        for y in 0..height {
            for x in 0..width {
                let i = y * width + x;
                if depth_m[i] <= 0.0 {
                    continue;
                }
                let left = (x > 0).then(|| i - 1);
                let right = (x + 1 < width).then(|| i + 1);
                let up = (y > 0).then(|| i - width);
                let down = (y + 1 < height).then(|| i + width);
                let (Some(tu), Some(tv)) = (tangent(i, left, right), tangent(i, up, down)) else {
                    continue;
                };
                let mut n = cross(tu, tv);
                let len = dot(n, n).sqrt();
                if len <= f32::MIN_POSITIVE {
                    continue;
                }
                // Face the camera (the viewing ray is +p from the origin).
                let sign = if dot(n, points[i]) > 0.0 { -1.0 } else { 1.0 };
                n = n.map(|c| c * sign / len);
                normals[i] = n;
            }
        }
        Self { points, normals }
    }
}

pub fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub fn is_known(n: [f32; 3]) -> bool {
    n != [0.0; 3]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fronto_parallel_plane_faces_camera() {
        let k = Intrinsics::new(100.0, 100.0, 4.5, 4.5, 10, 10);
        let depth = vec![2.0f32; 100];
        let g = SurfaceGeometry::from_depth(&depth, 10, 10, &k, 0.05);
        for n in &g.normals {
            assert!((n[2] + 1.0).abs() < 1e-5, "{n:?}");
        }
    }

    #[test]
    fn tilted_plane_and_missing_depth() {
        // Plane z = 2 + 0.5 x (camera frame): normal ∝ (0.5, 0, -1).
        let k = Intrinsics::new(100.0, 100.0, 4.5, 4.5, 10, 10);
        let mut depth = vec![0.0f32; 100];
        for (i, d) in depth.iter_mut().enumerate() {
            let u = (i % 10) as f32;
            // Solve z = 2 + 0.5 * (u - cx) * z / fx for z.
            *d = 2.0 / (1.0 - 0.5 * (u - 4.5) / 100.0);
        }
        depth[55] = 0.0;
        let g = SurfaceGeometry::from_depth(&depth, 10, 10, &k, 0.05);
        let expected = [0.5f32 / 1.25f32.sqrt(), 0.0, -1.0 / 1.25f32.sqrt()];
        let n = g.normals[33];
        assert!(dot(n, expected) > 0.9999, "{n:?}");
        assert!(!is_known(g.normals[55]));
        assert!(
            is_known(g.normals[54]),
            "one-sided difference next to a hole"
        );
    }
}
