//! Where an object is and how big it is, from its Gaussians' means weighted by opacity:
//!
//! ```text
//! w_i = σ(opacity_i); Gaussians with w_i < 1/255 are left out    they never reach a pixel's α threshold
//! c   = per-axis weighted median of the means x_i              a centre stray Gaussians cannot drag
//! r_i = ‖x_i − c‖,  m = wmedian(r),  s = 1.4826 · wmedian(|r − m|)
//! kept: r_i ≤ max(m + 3 s, 2 m)                                strays trimmed; 2 m keeps the ends of long or even objects
//! μ = Σ w x / Σ w,   Σ = Σ w (x − μ)(x − μ)ᵀ / Σ w              over the kept
//! AABB = per-axis min / max of the kept means
//! OBB  = eigenvectors a_k of Σ (largest variance first, right-handed); along each, min / max of a_kᵀ x
//! V    = Π_k (e_k + d),  e_k the OBB's edge lengths,  d = 2 · wmedian(geometric-mean scale)
//! ```
//!
//! The means lie inside the splats, so V grows the box by one typical Gaussian: a flat object
//! (a picture, a wall) has the thickness of its Gaussians rather than none.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use opengs_splat::{GaussianMap, MIN_ALPHA};
use serde::Serialize;

/// Gaussians further from the robust centre than `median + TRIM_SIGMAS · σ` are strays.
const TRIM_SIGMAS: f64 = 3.0;
/// MAD → standard deviation for normally spread distances.
const MAD_TO_SIGMA: f64 = 1.4826;

/// Axis-aligned box (world frame, metres).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Aabb {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

/// Oriented box: centre, unit axes (rows, right-handed, longest first) and half edge lengths.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct OrientedBox {
    pub center: [f64; 3],
    pub axes: [[f64; 3]; 3],
    pub half_extents: [f64; 3],
}

impl OrientedBox {
    /// The eight corners (for drawing or checks).
    pub fn corners(&self) -> [[f64; 3]; 8] {
        std::array::from_fn(|k| {
            let sign = |bit: usize| if k >> bit & 1 == 1 { 1.0 } else { -1.0 };
            std::array::from_fn(|i| {
                self.center[i]
                    + (0..3)
                        .map(|a| sign(a) * self.half_extents[a] * self.axes[a][i])
                        .sum::<f64>()
            })
        })
    }
}

/// Position and size of one object.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Extent {
    /// Opacity-weighted mean of the kept Gaussians' means.
    pub centroid: [f64; 3],
    pub aabb: Aabb,
    pub obb: OrientedBox,
    /// Volume of the oriented box grown by one typical Gaussian diameter (m³).
    pub volume: f64,
    /// Gaussians the boxes were built from.
    pub kept: usize,
    /// Gaussians left out: strays far from the rest, and ones too transparent to show.
    pub trimmed: usize,
}

/// One Gaussian as the extent sees it.
#[derive(Debug, Clone, Copy)]
struct Point {
    x: Vector3<f64>,
    w: f64,
}

/// Extent of the Gaussians `indices` of `map`; `None` when none of them is opaque enough to show.
pub fn extent_of(map: &GaussianMap, indices: &[u32]) -> Option<Extent> {
    let visible: Vec<(Point, f64)> = indices
        .iter()
        .map(|&i| i as usize)
        .filter(|&i| map.opacity(i) >= MIN_ALPHA)
        .map(|i| {
            let p = Point {
                x: Vector3::from(map.means[i].map(f64::from)),
                w: f64::from(map.opacity(i)),
            };
            let mean_log_scale = map.log_scales[i].iter().map(|&s| f64::from(s)).sum::<f64>() / 3.0;
            (p, mean_log_scale.exp())
        })
        .collect();
    if visible.is_empty() {
        return None;
    }
    let points: Vec<Point> = visible.iter().map(|(p, _)| *p).collect();
    let kept = trim_strays(&points);
    let gaussian_diameter = 2.0 * weighted_median(visible.iter().map(|(p, s)| (*s, p.w)).collect());
    let (centroid, covariance) = weighted_moments(&kept);
    let obb = oriented_box(&kept, &covariance);
    let volume = obb
        .half_extents
        .iter()
        .map(|h| 2.0 * h + gaussian_diameter)
        .product();
    Some(Extent {
        centroid: centroid.into(),
        aabb: axis_aligned_box(&kept),
        obb,
        volume,
        kept: kept.len(),
        trimmed: indices.len() - kept.len(),
    })
}

/// The points within `max(m + 3σ, 2m)` of the per-axis weighted median (module doc).
fn trim_strays(points: &[Point]) -> Vec<Point> {
    let centre: Vector3<f64> = Vector3::from_fn(|axis, _| {
        weighted_median(points.iter().map(|p| (p.x[axis], p.w)).collect())
    });
    let distance: Vec<f64> = points.iter().map(|p| (p.x - centre).norm()).collect();
    let median = weighted_median(
        distance
            .iter()
            .zip(points)
            .map(|(&r, p)| (r, p.w))
            .collect(),
    );
    let mad = weighted_median(
        distance
            .iter()
            .zip(points)
            .map(|(&r, p)| ((r - median).abs(), p.w))
            .collect(),
    );
    let limit = (median + TRIM_SIGMAS * MAD_TO_SIGMA * mad).max(2.0 * median);
    points
        .iter()
        .zip(&distance)
        .filter(|(_, &r)| r <= limit)
        .map(|(p, _)| *p)
        .collect()
}

/// Weighted mean and covariance.
fn weighted_moments(points: &[Point]) -> (Vector3<f64>, Matrix3<f64>) {
    let total: f64 = points.iter().map(|p| p.w).sum();
    let mean = points.iter().map(|p| p.x * p.w).sum::<Vector3<f64>>() / total;
    let covariance = points
        .iter()
        .map(|p| {
            let d = p.x - mean;
            d * d.transpose() * p.w
        })
        .sum::<Matrix3<f64>>()
        / total;
    (mean, covariance)
}

fn axis_aligned_box(points: &[Point]) -> Aabb {
    let mut min = [f64::INFINITY; 3];
    let mut max = [f64::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            min[k] = min[k].min(p.x[k]);
            max[k] = max[k].max(p.x[k]);
        }
    }
    Aabb { min, max }
}

/// Box along the covariance's eigenvectors, tight around the points.
fn oriented_box(points: &[Point], covariance: &Matrix3<f64>) -> OrientedBox {
    let eigen = SymmetricEigen::new(*covariance);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
    // Largest component positive: the same object gives the same axes whatever the solver's signs.
    let canonical = |v: Vector3<f64>| {
        let k = v.iamax();
        if v[k] < 0.0 {
            -v
        } else {
            v
        }
    };
    let a0 = canonical(eigen.eigenvectors.column(order[0]).into_owned());
    let a1 = canonical(eigen.eigenvectors.column(order[1]).into_owned());
    let axes = [a0, a1, a0.cross(&a1)];
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            let t = axes[k].dot(&p.x);
            lo[k] = lo[k].min(t);
            hi[k] = hi[k].max(t);
        }
    }
    let center = (0..3)
        .map(|k| axes[k] * (0.5 * (lo[k] + hi[k])))
        .sum::<Vector3<f64>>();
    OrientedBox {
        center: center.into(),
        axes: axes.map(Into::into),
        half_extents: std::array::from_fn(|k| 0.5 * (hi[k] - lo[k])),
    }
}

/// The value at which the sorted (value, weight) pairs reach half their total weight.
fn weighted_median(mut pairs: Vec<(f64, f64)>) -> f64 {
    pairs.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let half = 0.5 * pairs.iter().map(|p| p.1).sum::<f64>();
    let mut acc = 0.0;
    for &(value, weight) in &pairs {
        acc += weight;
        if acc >= half {
            return value;
        }
    }
    pairs.last().map_or(0.0, |p| p.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weighted_median_follows_the_weights() {
        assert_eq!(
            weighted_median(vec![(1.0, 1.0), (2.0, 1.0), (3.0, 1.0)]),
            2.0
        );
        assert_eq!(
            weighted_median(vec![(1.0, 1.0), (2.0, 1.0), (9.0, 5.0)]),
            9.0
        );
        assert_eq!(weighted_median(vec![(5.0, 1.0)]), 5.0);
    }
}
