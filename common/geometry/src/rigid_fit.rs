//! The rigid motion that best maps one point list onto another (Umeyama 1991, no scale).
//!
//! With centred points, `C = 1/n Σ d_i s_iᵀ = U D Vᵀ`, `R = U S Vᵀ` where
//! `S = diag(1, 1, det(U)·det(V))` keeps R a rotation (no reflection), and
//! `t = μ_dst − R μ_src`.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// The rigid `T` minimising `Σ |dst_i − T src_i|²`; `None` when the lists differ in length,
/// hold fewer than 3 pairs, or the fit is not finite.
pub fn rigid_fit(src: &[Point3<f64>], dst: &[Point3<f64>]) -> Option<Isometry3<f64>> {
    if src.len() != dst.len() || src.len() < 3 {
        return None;
    }
    let n = src.len() as f64;
    let mu_src = src.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let mu_dst = dst.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let cross = src.iter().zip(dst).fold(Matrix3::zeros(), |c, (s, d)| {
        c + (d.coords - mu_dst) * (s.coords - mu_src).transpose()
    }) / n;
    let svd = cross.svd(true, true);
    let (u, v_t) = svd.u.zip(svd.v_t)?;
    // Singular values are unordered in nalgebra: flip the column of the smallest.
    let smallest = svd.singular_values.imin();
    let mut s = Vector3::repeat(1.0);
    if u.determinant() * v_t.determinant() < 0.0 {
        s[smallest] = -1.0;
    }
    let r = u * Matrix3::from_diagonal(&s) * v_t;
    if !r.iter().all(|x| x.is_finite()) {
        return None;
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let t = mu_dst - rotation * mu_src;
    t.iter()
        .all(|x| x.is_finite())
        .then(|| Isometry3::from_parts(Translation3::from(t), rotation))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_known_motion_and_refuses_too_few_pairs() {
        let truth = Isometry3::new(Vector3::new(0.3, -1.2, 2.0), Vector3::new(0.1, -0.7, 0.4));
        let src = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 2.0, 0.0),
            Point3::new(0.5, 0.5, 3.0),
        ];
        let dst: Vec<_> = src.iter().map(|p| truth * p).collect();
        let fit = rigid_fit(&src, &dst).expect("four points in general position");
        let err = truth.inverse() * fit;
        assert!(err.translation.vector.norm() < 1e-12);
        assert!(err.rotation.angle() < 1e-12);
        assert_eq!(rigid_fit(&src[..2], &dst[..2]), None);
        assert_eq!(rigid_fit(&src, &dst[..3]), None);
    }
}
