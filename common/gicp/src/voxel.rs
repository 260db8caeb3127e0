use nalgebra::{Point3, Vector3};
use std::collections::HashMap;

/// Replaces the points of each cubic voxel of side `voxel_size` by their
/// centroid. Output order follows each voxel's first point (deterministic).
pub fn voxel_downsample(points: &[Point3<f64>], voxel_size: f64) -> Vec<Point3<f64>> {
    if voxel_size.is_nan() || voxel_size <= 0.0 {
        return points.to_vec();
    }
    let inv = 1.0 / voxel_size;
    let mut slot_of_voxel: HashMap<[i64; 3], usize> = HashMap::with_capacity(points.len());
    let mut sums: Vec<(Vector3<f64>, u32)> = Vec::new();
    for p in points {
        let key = [
            (p.x * inv).floor() as i64,
            (p.y * inv).floor() as i64,
            (p.z * inv).floor() as i64,
        ];
        let slot = *slot_of_voxel.entry(key).or_insert_with(|| {
            sums.push((Vector3::zeros(), 0));
            sums.len() - 1
        });
        sums[slot].0 += p.coords;
        sums[slot].1 += 1;
    }
    sums.into_iter()
        .map(|(sum, n)| Point3::from(sum / n as f64))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn centroid_per_voxel() {
        let pts = [
            Point3::new(0.1, 0.1, 0.1),
            Point3::new(0.3, 0.1, 0.1),
            Point3::new(1.5, 0.0, 0.0),
            Point3::new(-0.1, 0.0, 0.0),
        ];
        let out = voxel_downsample(&pts, 1.0);
        assert_eq!(out.len(), 3);
        assert_relative_eq!(out[0], Point3::new(0.2, 0.1, 0.1));
        assert_relative_eq!(out[1], Point3::new(1.5, 0.0, 0.0));
        assert_relative_eq!(out[2], Point3::new(-0.1, 0.0, 0.0));
    }
}
