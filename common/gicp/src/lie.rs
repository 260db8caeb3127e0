//! The SE(3) perturbation used by the solver.
//!
//! An update `δ = (ω, v)` (rotation vector first, then translation) acts on
//! the left: `T ← [exp(ω) | v] · T`, so a transformed point `q = T p` moves
//! to `exp(ω) q + v ≈ q − [q]× ω + v`, giving `∂q/∂δ = [ −[q]× | I ]`.

use nalgebra::{
    Isometry3, Matrix3, Matrix4, Rotation3, Translation3, UnitQuaternion, Vector3, Vector6,
};

/// `[v]×`, the matrix with `[v]× w = v × w`.
#[inline]
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// `[exp(ω) | v] · T`.
pub fn left_update(t: &Isometry3<f64>, delta: &Vector6<f64>) -> Isometry3<f64> {
    let omega = Vector3::new(delta[0], delta[1], delta[2]);
    let v = Vector3::new(delta[3], delta[4], delta[5]);
    let step = Isometry3::from_parts(
        Translation3::from(v),
        UnitQuaternion::from_scaled_axis(omega),
    );
    step * t
}

/// A 4×4 homogeneous matrix as a rigid transform; `None` unless its
/// rotation block is orthonormal with determinant +1 (to 1e-6) and its
/// last row is `0 0 0 1`.
pub fn isometry_from_matrix(m: &Matrix4<f64>) -> Option<Isometry3<f64>> {
    let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let orthonormal = (r.transpose() * r - Matrix3::identity()).abs().max() < 1e-6;
    let last_row_ok = (m.fixed_view::<1, 4>(3, 0) - nalgebra::RowVector4::new(0.0, 0.0, 0.0, 1.0))
        .abs()
        .max()
        < 1e-9;
    if !orthonormal
        || !last_row_ok
        || (r.determinant() - 1.0).abs() > 1e-6
        || !m.iter().all(|v| v.is_finite())
    {
        return None;
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let t = Vector3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
    Some(Isometry3::from_parts(Translation3::from(t), rotation))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::Point3;

    #[test]
    fn matrix_round_trip_and_rejection() {
        let t = Isometry3::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(0.3, -0.1, 0.2));
        let back = isometry_from_matrix(&t.to_homogeneous()).expect("rigid");
        assert_relative_eq!(back.to_homogeneous(), t.to_homogeneous(), epsilon = 1e-12);
        assert!(isometry_from_matrix(&(Matrix4::identity() * 2.0)).is_none());
        let mut reflection = Matrix4::identity();
        reflection[(0, 0)] = -1.0;
        assert!(isometry_from_matrix(&reflection).is_none());
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let t = Isometry3::new(Vector3::new(0.3, -0.2, 1.0), Vector3::new(0.1, 0.2, -0.3));
        let p = Point3::new(0.5, 1.5, -2.0);
        let q = t * p;
        let h = 1e-7;
        for k in 0..6 {
            let mut d = Vector6::zeros();
            d[k] = h;
            let numeric = (left_update(&t, &d) * p - q) / h;
            let analytic = if k < 3 {
                -skew(&q.coords) * Vector3::ith(k, 1.0)
            } else {
                Vector3::ith(k - 3, 1.0)
            };
            assert_relative_eq!(numeric, analytic, epsilon = 1e-5);
        }
    }
}
