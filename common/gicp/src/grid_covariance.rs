//! Covariances of depth-grid samples from the k nearest neighbours among
//! the samples of a 5×5 window of the sampling grid.
//!
//! Why: a kd-tree kNN per point costs ~1 µs, the window ~0.1 µs, and for a
//! depth image the 10 nearest 3D neighbours of a sample lie in its 5×5
//! grid window except at rare occlusion boundaries.

use crate::covariance::{covariance_of_offsets, regularize, Regularization};
use crate::{DepthSamples, GicpError};
use nalgebra::Matrix3;
use rayon::prelude::*;

/// Half-width of the grid window (2 → 5×5 cells, 24 candidates for k = 10).
const WINDOW_RADIUS: isize = 2;

/// One regularised covariance per sample, from its `k` nearest neighbours
/// (itself included) within its 5×5 grid window.
pub fn estimate_covariances_on_grid(
    samples: &DepthSamples,
    k: usize,
    regularization: Regularization,
) -> Result<Vec<Matrix3<f64>>, GicpError> {
    let max_k = ((2 * WINDOW_RADIUS + 1) * (2 * WINDOW_RADIUS + 1)) as usize;
    if !(3..=max_k).contains(&k) {
        return Err(GicpError::Invalid(format!(
            "grid covariances need 3 ≤ k ≤ {max_k}, k = {k}"
        )));
    }
    let (cols, rows) = samples.grid_size;
    let stride = samples.stride.max(1);
    if samples.points.len() != samples.pixels.len() {
        return Err(GicpError::LengthMismatch("sample points and pixels"));
    }
    // Which sample sits in each grid cell (u32::MAX: none).
    let mut cell_sample = vec![u32::MAX; cols * rows];
    for (i, &(u, v)) in samples.pixels.iter().enumerate() {
        let (c, r) = (u as usize / stride, v as usize / stride);
        if c >= cols || r >= rows {
            return Err(GicpError::Invalid(format!(
                "pixel ({u}, {v}) is outside the {cols}×{rows} grid"
            )));
        }
        cell_sample[r * cols + c] = i as u32;
    }
    let points = &samples.points;
    Ok(samples
        .pixels
        .par_iter()
        .zip(points.par_iter())
        .with_min_len(256)
        .map(|(&(u, v), p)| {
            let (c, r) = (
                (u as usize / stride) as isize,
                (v as usize / stride) as isize,
            );
            let mut candidates: [(f64, u32); 25] = [(f64::INFINITY, u32::MAX); 25];
            let mut n = 0;
            for dr in -WINDOW_RADIUS..=WINDOW_RADIUS {
                for dc in -WINDOW_RADIUS..=WINDOW_RADIUS {
                    let (cc, rr) = (c + dc, r + dr);
                    if cc < 0 || rr < 0 || cc >= cols as isize || rr >= rows as isize {
                        continue;
                    }
                    let j = cell_sample[rr as usize * cols + cc as usize];
                    if j != u32::MAX {
                        candidates[n] = ((points[j as usize] - p).norm_squared(), j);
                        n += 1;
                    }
                }
            }
            let nearest = &mut candidates[..n];
            let kk = k.min(n);
            if kk < n {
                nearest.select_nth_unstable_by(kk - 1, |a, b| a.0.total_cmp(&b.0));
            }
            let cov =
                covariance_of_offsets(nearest[..kk].iter().map(|&(_, j)| points[j as usize] - p));
            regularize(&cov, regularization)
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::covariance::estimate_covariances;
    use crate::sample_depth_grid;
    use crate::synthetic::{tum_camera, RoomScene, DEPTH_UNITS_PER_METRE};
    use nalgebra::Isometry3;

    #[test]
    fn grid_window_matches_kd_tree_knn_almost_everywhere() {
        // On the room's flat surfaces many neighbours tie in distance, so the
        // two searches may pick different (equally near) points; the surface
        // normal, i.e. the plane-regularised covariance, must still agree.
        let cam = tum_camera();
        let depth =
            RoomScene::default().render_depth(&cam, &Isometry3::identity(), DEPTH_UNITS_PER_METRE);
        let samples =
            sample_depth_grid(&depth, DEPTH_UNITS_PER_METRE, &cam, 5, 10.0).expect("valid");
        let grid =
            estimate_covariances_on_grid(&samples, 10, Regularization::Plane).expect("valid k");
        let tree =
            estimate_covariances(&samples.points, 10, Regularization::Plane).expect("valid k");
        let same = grid
            .iter()
            .zip(&tree)
            .filter(|(a, b)| (*a - *b).abs().max() < 1e-2)
            .count();
        let fraction = same as f64 / grid.len() as f64;
        assert!(fraction > 0.95, "only {fraction} of covariances agree");
        assert!(estimate_covariances_on_grid(&samples, 26, Regularization::Plane).is_err());
    }
}
