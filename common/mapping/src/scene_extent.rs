//! Scene extent, which scales the position learning rate and the size pruning of the
//! final optimisation and `opengs refine`. 3DGS takes 1.1 × the largest distance of a
//! camera centre from their mean: right for cameras around an object, wrong for a SLAM
//! camera inside a room, whose path can span 1 m while the walls it maps stand 4 m away
//! (pruned as "too large", they opened holes). So the extent is also at least the radius
//! that holds 95 % of the map seen from the cameras' centre.

use opengs_geometry::Pose;

/// Share of the map's means the extent must hold (the rest: floaters, far outliers).
const MAP_SHARE: f64 = 0.95;

/// The larger of 1.1 × the radius of the camera centres of `poses` (camera-to-world) and
/// the radius around their mean that holds 95 % of `means`; at least `floor`.
pub fn scene_extent(poses: impl IntoIterator<Item = Pose>, means: &[[f32; 3]], floor: f32) -> f32 {
    let centres: Vec<[f64; 3]> = poses
        .into_iter()
        .map(|p| {
            let t = p.translation.vector;
            [t.x, t.y, t.z]
        })
        .collect();
    if centres.is_empty() {
        return floor;
    }
    let n = centres.len() as f64;
    let mean: [f64; 3] = std::array::from_fn(|i| centres.iter().map(|c| c[i]).sum::<f64>() / n);
    let distance = |c: [f64; 3]| (0..3).map(|i| (c[i] - mean[i]).powi(2)).sum::<f64>().sqrt();
    let cameras = 1.1 * centres.iter().map(|c| distance(*c)).fold(0.0f64, f64::max);
    let mut seen: Vec<f64> = means
        .iter()
        .map(|m| distance(m.map(f64::from)))
        .filter(|d| d.is_finite())
        .collect();
    let map = if seen.is_empty() {
        0.0
    } else {
        let k = ((MAP_SHARE * seen.len() as f64).ceil() as usize).clamp(1, seen.len()) - 1;
        *seen.select_nth_unstable_by(k, f64::total_cmp).1
    };
    (cameras.max(map) as f32).max(floor)
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_geometry::nalgebra::{Translation3, UnitQuaternion};

    fn at(x: f64) -> Pose {
        Pose::from_parts(Translation3::new(x, 0.0, 0.0), UnitQuaternion::identity())
    }

    #[test]
    fn radius_of_centres_with_floor() {
        let e = scene_extent([at(-2.0), at(2.0), at(0.0)], &[], 0.5);
        assert!((e - 2.2).abs() < 1e-6, "{e}");
        assert_eq!(scene_extent([at(1.0)], &[], 0.5), 0.5);
        assert_eq!(scene_extent([], &[[9.0, 0.0, 0.0]], 0.5), 0.5);
    }

    #[test]
    fn a_room_larger_than_the_camera_path_sets_the_extent() {
        // Cameras within ±0.5 m (1.1 × 0.5 = 0.55 m); 100 wall points 4 m away, of which
        // 5 are floaters at 40 m: 95 % of the map lies within 4 m.
        let mut means = vec![[0.0f32, 4.0, 0.0]; 95];
        means.extend([[40.0f32, 0.0, 0.0]; 5]);
        means.push([f32::NAN, 0.0, 0.0]);
        let e = scene_extent([at(-0.5), at(0.5)], &means, 1.0);
        assert!((e - 4.0).abs() < 1e-6, "{e}");
        // With one more floater the 95th percentile is one.
        means.extend([[40.0f32, 0.0, 0.0]; 1]);
        let e = scene_extent([at(-0.5), at(0.5)], &means, 1.0);
        assert!((e - 40.0).abs() < 1e-4, "{e}");
    }
}
