//! Labels for the mapper's trackable Gaussians. The map target (mapper → tracker) carries
//! their means, rotations and scales but no labels, and the viewer publishes nothing, so it
//! labels them itself from what the pipeline does send: the consensus' consistent label map
//! of each keyframe, seen from that keyframe's pose with its depth. A Gaussian takes the label
//! of the newest labelled keyframe that sees it: it projects inside the image, in front of
//! the camera, and its depth agrees with the keyframe's measured depth there (so occluded
//! Gaussians are not painted with the occluder's label). Gaussians no labelled keyframe sees
//! stay unlabelled.

use std::collections::VecDeque;

use crate::labels::UNLABELLED;

/// Keyframes kept for their geometry until their consensus arrives.
const KEPT_KEYFRAMES: usize = 16;
/// Labelled keyframes a Gaussian is looked up in, newest first.
const KEPT_VIEWS: usize = 8;
/// Depth agreement: a Gaussian within this many metres of the measured surface...
const DEPTH_TOLERANCE_M: f64 = 0.05;
/// ... plus this fraction of the depth counts as on it.
const DEPTH_TOLERANCE_REL: f64 = 0.02;
/// Closer than this to a camera counts as behind it.
const NEAR_M: f64 = 0.05;

/// A camera-to-world pose: translation, then the unit quaternion x, y, z, w (TUM order).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub translation: [f64; 3],
    pub rotation_xyzw: [f64; 4],
}

impl Pose {
    /// From `tx ty tz qx qy qz qw`, the quaternion normalised; `None` if it is not finite
    /// or has no length.
    pub fn from_tum(p: &[f64; 7]) -> Option<Self> {
        let [tx, ty, tz, qx, qy, qz, qw] = *p;
        let n = (qx * qx + qy * qy + qz * qz + qw * qw).sqrt();
        if !(p.iter().all(|v| v.is_finite()) && n.is_finite() && n > 1e-12) {
            return None;
        }
        Some(Self {
            translation: [tx, ty, tz],
            rotation_xyzw: [qx / n, qy / n, qz / n, qw / n],
        })
    }

    /// The rotation matrix (camera axes in world coordinates, column by column).
    fn matrix(&self) -> [[f64; 3]; 3] {
        let [x, y, z, w] = self.rotation_xyzw;
        [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - z * w),
                2.0 * (x * z + y * w),
            ],
            [
                2.0 * (x * y + z * w),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - x * w),
            ],
            [
                2.0 * (x * z - y * w),
                2.0 * (y * z + x * w),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ]
    }

    /// A world point in this camera's frame.
    pub fn world_to_camera(&self, p: [f64; 3]) -> [f64; 3] {
        let r = self.matrix();
        let d = [
            p[0] - self.translation[0],
            p[1] - self.translation[1],
            p[2] - self.translation[2],
        ];
        // Rᵀ · d
        [0, 1, 2].map(|c| r[0][c] * d[0] + r[1][c] * d[1] + r[2][c] * d[2])
    }

    /// As logged: f32 translation and quaternion.
    pub fn to_f32(self) -> ([f32; 3], [f32; 4]) {
        (
            self.translation.map(|v| v as f32),
            self.rotation_xyzw.map(|v| v as f32),
        )
    }
}

/// Where a keyframe was and what it measured.
#[derive(Debug, Clone)]
pub struct KeyframeGeometry {
    pub seq: u64,
    pub pose: Pose,
    /// fx, fy, cx, cy.
    pub intrinsics: [f64; 4],
    pub width: u32,
    pub height: u32,
    pub depth: Vec<u16>,
    pub units_per_metre: f32,
}

/// A keyframe with its consistent label map.
#[derive(Debug, Clone)]
struct View {
    geometry: KeyframeGeometry,
    labels: Vec<u32>,
}

impl View {
    /// The label at `p`'s pixel if this view sees `p` on its measured surface.
    fn label(&self, p: [f64; 3]) -> Option<u32> {
        let g = &self.geometry;
        let [x, y, z] = g.pose.world_to_camera(p);
        // NaN fails this too.
        if z.is_nan() || z <= NEAR_M {
            return None;
        }
        let [fx, fy, cx, cy] = g.intrinsics;
        let u = (fx * x / z + cx).round();
        let v = (fy * y / z + cy).round();
        if !(u >= 0.0 && v >= 0.0 && u < g.width as f64 && v < g.height as f64) {
            return None;
        }
        let i = v as usize * g.width as usize + u as usize;
        let raw = *g.depth.get(i)?;
        if raw == 0 {
            return None;
        }
        let d = raw as f64 / g.units_per_metre as f64;
        if (z - d).abs() > DEPTH_TOLERANCE_M + DEPTH_TOLERANCE_REL * d {
            return None;
        }
        self.labels.get(i).copied()
    }
}

/// Recent keyframes and the labelled ones among them.
#[derive(Debug, Default)]
pub struct LabelledViews {
    keyframes: VecDeque<KeyframeGeometry>,
    views: VecDeque<View>,
}

impl LabelledViews {
    /// Keeps a keyframe's geometry for its consensus to come.
    pub fn keyframe(&mut self, k: KeyframeGeometry) {
        let valid = k.units_per_metre.is_finite()
            && k.units_per_metre > 0.0
            && k.intrinsics.iter().all(|v| v.is_finite())
            && k.depth.len() == k.width as usize * k.height as usize;
        if !valid {
            return;
        }
        self.keyframes.retain(|old| old.seq != k.seq);
        self.keyframes.push_back(k);
        while self.keyframes.len() > KEPT_KEYFRAMES {
            self.keyframes.pop_front();
        }
    }

    /// Keyframe `seq`'s consistent label map arrived; false when its keyframe is unknown here
    /// or of another size (then it labels nothing).
    pub fn consensus(&mut self, seq: u64, width: u32, height: u32, labels: &[u32]) -> bool {
        let Some(geometry) = self.keyframes.iter().find(|k| k.seq == seq).cloned() else {
            return false;
        };
        if (geometry.width, geometry.height) != (width, height)
            || labels.len() != geometry.depth.len()
        {
            return false;
        }
        self.views.retain(|v| v.geometry.seq != seq);
        self.views.push_back(View {
            geometry,
            labels: labels.to_vec(),
        });
        while self.views.len() > KEPT_VIEWS {
            self.views.pop_front();
        }
        true
    }

    pub fn views(&self) -> usize {
        self.views.len()
    }

    /// The label of a world point: from the newest labelled view that sees it with a label.
    pub fn label(&self, p: [f32; 3]) -> u32 {
        let p = p.map(f64::from);
        self.views
            .iter()
            .rev()
            .filter_map(|v| v.label(p))
            .find(|&l| l != UNLABELLED)
            .unwrap_or(UNLABELLED)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const W: u32 = 64;
    const H: u32 = 48;
    const K: [f64; 4] = [50.0, 50.0, 31.5, 23.5];

    fn identity() -> Pose {
        Pose::from_tum(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]).expect("valid")
    }

    /// A keyframe looking at a wall `wall_m` ahead, left half label 3, right half label 8.
    fn wall(seq: u64, pose: Pose, wall_m: f64) -> (KeyframeGeometry, Vec<u32>) {
        let n = (W * H) as usize;
        let depth = vec![(wall_m * 1000.0) as u16; n];
        let labels = (0..n)
            .map(|i| {
                if (i % W as usize) < (W / 2) as usize {
                    3
                } else {
                    8
                }
            })
            .collect();
        let k = KeyframeGeometry {
            seq,
            pose,
            intrinsics: K,
            width: W,
            height: H,
            depth,
            units_per_metre: 1000.0,
        };
        (k, labels)
    }

    #[test]
    fn poses_are_checked_and_normalised() {
        assert!(Pose::from_tum(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]).is_none());
        assert!(Pose::from_tum(&[f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]).is_none());
        let p = Pose::from_tum(&[1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 2.0]).expect("valid");
        assert_eq!(p.rotation_xyzw, [0.0, 0.0, 0.0, 1.0]);
        assert_eq!(p.world_to_camera([1.0, 2.0, 4.0]), [0.0, 0.0, 1.0]);
        // 90° about y: the camera's z axis is the world's x axis.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let turned = Pose::from_tum(&[0.0, 0.0, 0.0, 0.0, h, 0.0, h]).expect("valid");
        let c = turned.world_to_camera([2.0, 0.0, 0.0]);
        assert!(
            (c[0]).abs() < 1e-12 && (c[1]).abs() < 1e-12 && (c[2] - 2.0).abs() < 1e-12,
            "{c:?}"
        );
    }

    #[test]
    fn gaussians_on_the_seen_surface_take_its_label() {
        let mut views = LabelledViews::default();
        let (k, labels) = wall(10, identity(), 2.0);
        // No consensus yet: nothing is labelled.
        views.keyframe(k);
        assert_eq!(views.label([-0.3, 0.0, 2.0]), UNLABELLED);
        assert!(!views.consensus(11, W, H, &labels), "unknown keyframe");
        assert!(!views.consensus(10, W + 1, H, &labels), "other size");
        assert!(views.consensus(10, W, H, &labels));
        assert_eq!(views.label([-0.3, 0.0, 2.0]), 3, "left half, on the wall");
        assert_eq!(
            views.label([0.3, 0.1, 2.02]),
            8,
            "right half, within the tolerance"
        );
        assert_eq!(
            views.label([0.3, 0.0, 1.5]),
            UNLABELLED,
            "in front of the wall"
        );
        assert_eq!(
            views.label([0.3, 0.0, 2.5]),
            UNLABELLED,
            "behind it: occluded"
        );
        assert_eq!(
            views.label([5.0, 0.0, 2.0]),
            UNLABELLED,
            "outside the image"
        );
        assert_eq!(
            views.label([0.0, 0.0, -2.0]),
            UNLABELLED,
            "behind the camera"
        );
        assert_eq!(views.label([f32::NAN, 0.0, 2.0]), UNLABELLED);
    }

    #[test]
    fn the_newest_view_that_sees_a_gaussian_wins() {
        let mut views = LabelledViews::default();
        let (k1, l1) = wall(1, identity(), 2.0);
        views.keyframe(k1);
        assert!(views.consensus(1, W, H, &l1));
        // A later keyframe from 1 m further back sees the same wall with other labels.
        let back = Pose::from_tum(&[0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0]).expect("valid");
        let (k2, mut l2) = wall(2, back, 3.0);
        l2.iter_mut().for_each(|l| *l = 42);
        views.keyframe(k2);
        assert!(views.consensus(2, W, H, &l2));
        assert_eq!(views.label([-0.3, 0.0, 2.0]), 42);
        // A newer view whose measured surface lies elsewhere does not take the point over.
        let (k3, mut l3) = wall(3, back, 1.0);
        l3.iter_mut().for_each(|l| *l = 77);
        views.keyframe(k3);
        assert!(views.consensus(3, W, H, &l3));
        assert_eq!(views.label([-0.3, 0.0, 2.0]), 42);
        // Background in the newest view falls back to an older label.
        let (k4, mut l4) = wall(4, back, 3.0);
        l4.iter_mut().for_each(|l| *l = UNLABELLED);
        views.keyframe(k4);
        assert!(views.consensus(4, W, H, &l4));
        assert_eq!(views.label([-0.3, 0.0, 2.0]), 42);
    }

    #[test]
    fn only_recent_keyframes_and_views_are_kept() {
        let mut views = LabelledViews::default();
        for seq in 0..40 {
            let (k, l) = wall(seq, identity(), 2.0);
            views.keyframe(k);
            if seq % 2 == 0 {
                views.consensus(seq, W, H, &l);
            }
        }
        assert!(views.keyframes.len() <= KEPT_KEYFRAMES);
        assert_eq!(views.views(), KEPT_VIEWS);
        // A keyframe with a depth image of the wrong size is not kept.
        let (mut bad, l) = wall(100, identity(), 2.0);
        bad.depth.pop();
        views.keyframe(bad);
        assert!(!views.consensus(100, W, H, &l));
    }
}
