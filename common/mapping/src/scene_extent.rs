//! Scene extent from camera positions (3DGS: 1.1 × the largest distance of a camera centre
//! from their mean), which scales the position learning rate and the size pruning.

use opengs_geometry::Pose;

/// 1.1 × the radius of the camera centres of `poses` (camera-to-world), at least `floor`.
pub fn scene_extent(poses: impl IntoIterator<Item = Pose>, floor: f32) -> f32 {
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
    let radius = centres
        .iter()
        .map(|c| (0..3).map(|i| (c[i] - mean[i]).powi(2)).sum::<f64>().sqrt())
        .fold(0.0f64, f64::max);
    ((1.1 * radius) as f32).max(floor)
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_geometry::nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn radius_of_centres_with_floor() {
        let at =
            |x: f64| Pose::from_parts(Translation3::new(x, 0.0, 0.0), UnitQuaternion::identity());
        let e = scene_extent([at(-2.0), at(2.0), at(0.0)], 0.5);
        assert!((e - 2.2).abs() < 1e-6, "{e}");
        assert_eq!(scene_extent([at(1.0)], 0.5), 0.5);
        assert_eq!(scene_extent([], 0.5), 0.5);
    }
}
