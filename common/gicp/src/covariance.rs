use crate::{GicpError, PointTree};
use nalgebra::{Matrix3, Point3, SymmetricEigen, UnitQuaternion, Vector3};
use rayon::prelude::*;

/// docs/METHOD.md §7: covariances from the 10 nearest neighbours.
pub const DEFAULT_NEIGHBOURS: usize = 10;

/// Smallest allowed (normalised) eigenvalue: keeps every covariance invertible.
const EPSILON: f64 = 1e-3;

/// How a raw neighbourhood covariance is turned into a well-conditioned one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Regularization {
    /// GS-ICP / fast_gicp: eigenvalues divided by the middle one, clamped
    /// at ≥ 1e-3. Keeps the ellipse's shape, removes its scale (docs/METHOD.md §7).
    #[default]
    NormalizedEllipse,
    /// small_gicp: eigenvalues replaced by (1, 1, 1e-3), i.e. a thin disc
    /// whose normal is the direction of least spread.
    Plane,
    /// The raw covariance, untouched (e.g. Gaussians' own R S² Rᵀ).
    None,
}

/// Applies a regularisation to a symmetric positive semi-definite matrix.
///
/// Fast path: both regularisations only need the eigenvalues and the
/// eigenvector `n` of the smallest one, since
/// `U diag(max(λᵢ/m, ε)) Uᵀ = C/m + (ε − λ_min/m) n nᵀ` when only λ_min is
/// clamped, and the plane is `I − (1 − ε) n nᵀ`. Near-repeated smallest
/// eigenvalues (where `n` is ill-defined) take the full decomposition.
pub fn regularize(cov: &Matrix3<f64>, regularization: Regularization) -> Matrix3<f64> {
    if regularization == Regularization::None {
        return *cov;
    }
    let Some((lambda, normal)) = eigen_with_smallest_vector(cov) else {
        return regularize_by_eigendecomposition(cov, regularization);
    };
    let [_, middle, smallest] = lambda;
    match regularization {
        Regularization::NormalizedEllipse => {
            if middle < EPSILON * lambda[0] {
                // Needle: two clamped values, take the full decomposition.
                return regularize_by_eigendecomposition(cov, regularization);
            }
            let scaled_smallest = smallest / middle;
            let mut out = cov / middle;
            if scaled_smallest < EPSILON {
                out += normal * normal.transpose() * (EPSILON - scaled_smallest);
            }
            out
        }
        Regularization::Plane => {
            Matrix3::identity() - normal * normal.transpose() * (1.0 - EPSILON)
        }
        Regularization::None => *cov,
    }
}

/// Eigenvalues (largest first, closed form) and the unit eigenvector of the
/// smallest; `None` when the smallest is (nearly) repeated or all are zero.
fn eigen_with_smallest_vector(a: &Matrix3<f64>) -> Option<([f64; 3], Vector3<f64>)> {
    let off = a[(0, 1)].powi(2) + a[(0, 2)].powi(2) + a[(1, 2)].powi(2);
    let q = a.trace() / 3.0;
    let p2 =
        (a[(0, 0)] - q).powi(2) + (a[(1, 1)] - q).powi(2) + (a[(2, 2)] - q).powi(2) + 2.0 * off;
    let p = (p2 / 6.0).sqrt();
    if !p.is_finite() || p <= 0.0 {
        return None;
    }
    // Trigonometric solution of the characteristic cubic (Smith, 1961).
    let b = (a - Matrix3::identity() * q) / p;
    let r = (b.determinant() / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let largest = q + 2.0 * p * phi.cos();
    let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
    let middle = 3.0 * q - largest - smallest;
    if middle - smallest <= 1e-6 * largest.abs().max(f64::MIN_POSITIVE) {
        return None;
    }
    // The eigenvector spans the null space of A − λI: the largest cross
    // product of two of its rows.
    let m = a - Matrix3::identity() * smallest;
    let (r0, r1, r2) = (
        m.row(0).transpose(),
        m.row(1).transpose(),
        m.row(2).transpose(),
    );
    let candidates = [r0.cross(&r1), r0.cross(&r2), r1.cross(&r2)];
    let best = candidates
        .iter()
        .max_by(|x, y| x.norm_squared().total_cmp(&y.norm_squared()))?;
    let norm = best.norm();
    if !norm.is_finite() || norm <= 0.0 {
        return None;
    }
    Some(([largest, middle.max(0.0), smallest.max(0.0)], best / norm))
}

/// Reference implementation by a full symmetric eigendecomposition.
pub fn regularize_by_eigendecomposition(
    cov: &Matrix3<f64>,
    regularization: Regularization,
) -> Matrix3<f64> {
    if regularization == Regularization::None {
        return *cov;
    }
    let eig = SymmetricEigen::new(*cov);
    let u = eig.eigenvectors;
    let lambda = eig.eigenvalues.map(|l| l.max(0.0));
    let values = match regularization {
        Regularization::NormalizedEllipse => {
            let largest = lambda.max();
            if largest <= 0.0 {
                // A single point has no shape: an isotropic unit ball.
                return Matrix3::identity();
            }
            let mut sorted = [lambda.x, lambda.y, lambda.z];
            sorted.sort_by(f64::total_cmp);
            // A needle-shaped (collinear) neighbourhood has no middle
            // spread; normalising by ε·largest keeps it a finite needle.
            let middle = sorted[1].max(EPSILON * largest);
            lambda.map(|l| (l / middle).max(EPSILON))
        }
        Regularization::Plane => {
            let normal = lambda.imin();
            Vector3::from_fn(|i, _| if i == normal { EPSILON } else { 1.0 })
        }
        Regularization::None => unreachable!("handled above"),
    };
    u * Matrix3::from_diagonal(&values) * u.transpose()
}

/// Sample covariance `1/n Σ (p − μ)(p − μ)ᵀ` of some points.
pub fn sample_covariance<'a>(points: impl Iterator<Item = &'a Point3<f64>>) -> Matrix3<f64> {
    covariance_of_offsets(points.map(|p| p.coords))
}

/// Sample covariance of vectors (offsets from a nearby point keep the
/// one-pass formula accurate far from the origin).
pub fn covariance_of_offsets(offsets: impl Iterator<Item = Vector3<f64>>) -> Matrix3<f64> {
    let mut n = 0.0;
    let mut sum = Vector3::zeros();
    let mut sum_outer = Matrix3::zeros();
    for v in offsets {
        n += 1.0;
        sum += v;
        sum_outer += v * v.transpose();
    }
    if n == 0.0 {
        return Matrix3::zeros();
    }
    let mean = sum / n;
    sum_outer / n - mean * mean.transpose()
}

/// One regularised covariance per point, from its `k` nearest neighbours
/// (the point itself included), computed in parallel.
pub fn estimate_covariances(
    points: &[Point3<f64>],
    k: usize,
    regularization: Regularization,
) -> Result<Vec<Matrix3<f64>>, GicpError> {
    if k < 3 {
        return Err(GicpError::Invalid(format!(
            "covariance needs at least 3 neighbours, k = {k}"
        )));
    }
    let tree = PointTree::new(points);
    Ok(points
        .par_iter()
        .with_min_len(256)
        .map(|p| {
            let neighbours = tree.knn(p, k);
            let cov = covariance_of_offsets(neighbours.iter().map(|&(i, _)| points[i] - p));
            regularize(&cov, regularization)
        })
        .collect())
}

/// Covariance of a Gaussian with unit rotation `q` and per-axis `scale`: `R S² Rᵀ`.
pub fn covariance_from_gaussian(q: &UnitQuaternion<f64>, scale: &Vector3<f64>) -> Matrix3<f64> {
    let r = q.to_rotation_matrix().into_inner();
    let s2 = Matrix3::from_diagonal(&scale.component_mul(scale));
    r * s2 * r.transpose()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::Quaternion;
    use std::f64::consts::PI;

    /// 8 points on the ellipse x²/4 + y² = 1 at θ = kπ/4:
    /// mean 0, E[x²] = 4·½ = 2, E[y²] = ½, E[xy] = 0.
    fn ellipse_points() -> Vec<Point3<f64>> {
        (0..8)
            .map(|k| {
                let t = k as f64 * PI / 4.0;
                Point3::new(2.0 * t.cos(), t.sin(), 0.0)
            })
            .collect()
    }

    #[test]
    fn sample_covariance_of_the_ellipse_by_hand() {
        let c = sample_covariance(ellipse_points().iter());
        assert_relative_eq!(
            c,
            Matrix3::from_diagonal(&Vector3::new(2.0, 0.5, 0.0)),
            epsilon = 1e-12
        );
    }

    #[test]
    fn normalized_ellipse_divides_by_middle_and_clamps() {
        // Singular values (2, ½, 0) / ½ = (4, 1, 0) → clamp → (4, 1, 1e-3).
        let covs = estimate_covariances(&ellipse_points(), 8, Regularization::NormalizedEllipse)
            .expect("valid k");
        for c in covs {
            assert_relative_eq!(
                c,
                Matrix3::from_diagonal(&Vector3::new(4.0, 1.0, 1e-3)),
                epsilon = 1e-9
            );
        }
    }

    #[test]
    fn plane_regularisation_on_the_ellipse_is_diag_1_1_eps() {
        let covs =
            estimate_covariances(&ellipse_points(), 8, Regularization::Plane).expect("valid k");
        for c in covs {
            assert_relative_eq!(
                c,
                Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 1e-3)),
                epsilon = 1e-9
            );
        }
    }

    #[test]
    fn plane_regularisation_of_a_tilted_plane_is_i_minus_nnt() {
        // Grid on the plane z = x, normal n = (1, 0, −1)/√2:
        // expected  Σ = I − (1 − ε) n nᵀ.
        let pts: Vec<_> = (0..5)
            .flat_map(|i| {
                (0..5).map(move |j| Point3::new(i as f64 * 0.1, j as f64 * 0.1, i as f64 * 0.1))
            })
            .collect();
        let n = Vector3::new(1.0, 0.0, -1.0).normalize();
        let expected = Matrix3::identity() - (1.0 - 1e-3) * n * n.transpose();
        let c = regularize(&sample_covariance(pts.iter()), Regularization::Plane);
        assert_relative_eq!(c, expected, epsilon = 1e-9);
    }

    #[test]
    fn normalized_ellipse_of_rotated_matrix_by_hand() {
        // Σ = R diag(9, 3, 0.001) Rᵀ, R = 90° about z. Middle value 3:
        // (3, 1, 3.3e-4 → 1e-3), rotated back: diag(1, 3, 1e-3).
        let r = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), PI / 2.0);
        let m = r.to_rotation_matrix().into_inner();
        let raw = m * Matrix3::from_diagonal(&Vector3::new(9.0, 3.0, 0.001)) * m.transpose();
        let c = regularize(&raw, Regularization::NormalizedEllipse);
        assert_relative_eq!(
            c,
            Matrix3::from_diagonal(&Vector3::new(1.0, 3.0, 1e-3)),
            epsilon = 1e-9
        );
    }

    #[test]
    fn collinear_and_single_point_neighbourhoods_stay_finite() {
        let line: Vec<_> = (0..10).map(|i| Point3::new(i as f64, 0.0, 0.0)).collect();
        let c = regularize(
            &sample_covariance(line.iter()),
            Regularization::NormalizedEllipse,
        );
        assert!(c.iter().all(|v| v.is_finite()));
        assert!(c.determinant() > 0.0);
        let single = regularize(&Matrix3::zeros(), Regularization::NormalizedEllipse);
        assert_eq!(single, Matrix3::identity());
    }

    #[test]
    fn closed_form_path_matches_the_full_eigendecomposition() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..2000 {
            // Random SPD matrices with spreads from needles to blobs.
            let axes = Matrix3::from_fn(|_, _| rng.gen_range(-1.0..1.0));
            let spread = Vector3::new(
                rng.gen_range(0.0..2.0),
                rng.gen_range(0.0..1.0),
                rng.gen_range(0.0..0.01),
            );
            let c = axes * Matrix3::from_diagonal(&spread) * axes.transpose();
            for reg in [Regularization::NormalizedEllipse, Regularization::Plane] {
                let fast = regularize(&c, reg);
                let reference = regularize_by_eigendecomposition(&c, reg);
                assert!(
                    (fast - reference).abs().max() < 1e-6 * reference.abs().max().max(1.0),
                    "{reg:?} {c}"
                );
            }
        }
    }

    #[test]
    fn gaussian_covariance_is_r_s2_rt() {
        // 90° about z swaps the x and y scales: diag(4, 1, 0.25) → diag(1, 4, 0.25).
        let q = UnitQuaternion::from_quaternion(Quaternion::new(
            (PI / 4.0).cos(),
            0.0,
            0.0,
            (PI / 4.0).sin(),
        ));
        let c = covariance_from_gaussian(&q, &Vector3::new(2.0, 1.0, 0.5));
        assert_relative_eq!(
            c,
            Matrix3::from_diagonal(&Vector3::new(1.0, 4.0, 0.25)),
            epsilon = 1e-12
        );
    }
}
