//! The GICP factor of one correspondence `(p_s, Σ_s) ↔ (p_t, Σ_t)` at `T = (R, t)`:
//!
//! ```text
//! d = T p_s − p_t                 residual
//! Ω = (Σ_t + R Σ_s Rᵀ)⁻¹          information of the residual
//! e = dᵀ Ω d                      Mahalanobis error
//! J = ∂d/∂δ = [ −[T p_s]× | I ]   left perturbation (see `lie`)
//! H = Jᵀ Ω J,  b = Jᵀ Ω d         Gauss-Newton normal equations
//! ```

use crate::lie::skew;
use nalgebra::{Matrix3, Matrix6, Point3, Vector6};

/// Normal-equation contribution of one correspondence.
pub struct Linearized {
    pub h: Matrix6<f64>,
    pub b: Vector6<f64>,
    pub error: f64,
}

/// Inverse of a symmetric 3×3 matrix by its adjugate; `None` if singular.
#[inline]
fn symmetric_inverse(m: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let (a, b, c) = (m[(0, 0)], m[(0, 1)], m[(0, 2)]);
    let (d, e, f) = (m[(1, 1)], m[(1, 2)], m[(2, 2)]);
    let c00 = d * f - e * e;
    let c01 = c * e - b * f;
    let c02 = b * e - c * d;
    let det = a * c00 + b * c01 + c * c02;
    if !det.is_finite() || det.abs() <= f64::MIN_POSITIVE {
        return None;
    }
    let inv = 1.0 / det;
    let c11 = a * f - c * c;
    let c12 = b * c - a * e;
    let c22 = a * d - b * b;
    Some(Matrix3::new(c00, c01, c02, c01, c11, c12, c02, c12, c22) * inv)
}

/// Information matrix `Ω = (Σ_t + R Σ_s Rᵀ)⁻¹`; `None` if not invertible.
#[inline]
pub fn information(
    rotation: &Matrix3<f64>,
    source_cov: &Matrix3<f64>,
    target_cov: &Matrix3<f64>,
) -> Option<Matrix3<f64>> {
    let combined = target_cov + rotation * source_cov * rotation.transpose();
    symmetric_inverse(&combined)
}

/// Mahalanobis error `dᵀ Ω d` of one correspondence.
#[inline]
pub fn error(
    rotation: &Matrix3<f64>,
    transformed_source: &Point3<f64>,
    source_cov: &Matrix3<f64>,
    target: &Point3<f64>,
    target_cov: &Matrix3<f64>,
) -> f64 {
    let d = transformed_source - target;
    information(rotation, source_cov, target_cov).map_or(0.0, |omega| d.dot(&(omega * d)))
}

/// `H`, `b` and `e` of one correspondence, `transformed_source = T p_s`.
///
/// With `J = [ −[q]× | I ]`, `w = Ω d` and `M = [q]× Ω`, the blocks are
/// `H = [ −M [q]×  M ; Mᵀ  Ω ]` and `b = [ q × w ; w ]`.
#[inline]
pub fn linearize(
    rotation: &Matrix3<f64>,
    transformed_source: &Point3<f64>,
    source_cov: &Matrix3<f64>,
    target: &Point3<f64>,
    target_cov: &Matrix3<f64>,
) -> Option<Linearized> {
    let omega = information(rotation, source_cov, target_cov)?;
    let q = transformed_source.coords;
    let d = transformed_source - target;
    let w = omega * d;
    let q_cross = skew(&q);
    let m = q_cross * omega;
    let mut h = Matrix6::zeros();
    h.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-(m * q_cross)));
    h.fixed_view_mut::<3, 3>(0, 3).copy_from(&m);
    h.fixed_view_mut::<3, 3>(3, 0).copy_from(&m.transpose());
    h.fixed_view_mut::<3, 3>(3, 3).copy_from(&omega);
    let mut b = Vector6::zeros();
    b.fixed_rows_mut::<3>(0).copy_from(&q.cross(&w));
    b.fixed_rows_mut::<3>(3).copy_from(&w);
    Some(Linearized {
        h,
        b,
        error: d.dot(&w),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lie::left_update;
    use approx::assert_relative_eq;
    use nalgebra::{Isometry3, Vector3};

    #[test]
    fn gradient_matches_finite_difference_of_the_error() {
        // ∂e/∂δ = 2 Jᵀ Ω d = 2b, with Ω held fixed at the linearisation point.
        let t = Isometry3::new(Vector3::new(0.1, 0.0, 0.2), Vector3::new(0.05, -0.1, 0.2));
        let r = t.rotation.to_rotation_matrix().into_inner();
        let p_s = Point3::new(0.3, -0.4, 1.2);
        let p_t = Point3::new(0.45, -0.3, 1.5);
        let cs = Matrix3::from_diagonal(&Vector3::new(1.0, 2.0, 0.5));
        let ct = Matrix3::from_diagonal(&Vector3::new(0.7, 1.0, 1.5));
        let lin = linearize(&r, &(t * p_s), &cs, &p_t, &ct).expect("invertible");
        let omega = information(&r, &cs, &ct).expect("invertible");
        let e = |t: &Isometry3<f64>| {
            let d = t * p_s - p_t;
            d.dot(&(omega * d))
        };
        let h = 1e-7;
        for k in 0..6 {
            let mut d = Vector6::zeros();
            d[k] = h;
            let numeric = (e(&left_update(&t, &d)) - e(&t)) / h;
            assert_relative_eq!(numeric, 2.0 * lin.b[k], epsilon = 1e-5);
        }
        assert_relative_eq!(lin.error, e(&t), epsilon = 1e-12);
        // H = Jᵀ Ω J with the explicit Jacobian.
        let mut j = nalgebra::Matrix3x6::zeros();
        j.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(-skew(&(t * p_s).coords)));
        j.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&Matrix3::identity());
        assert_relative_eq!(lin.h, j.transpose() * omega * j, epsilon = 1e-9);
        assert_relative_eq!(
            omega,
            (ct + r * cs * r.transpose())
                .try_inverse()
                .expect("invertible"),
            epsilon = 1e-12
        );
    }
}
