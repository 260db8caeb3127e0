//! Rigid motion of the selected Gaussians (move, rotate), about a pivot c:
//!
//! ```text
//! mean      x' = R (x − c) + c + t
//! rotation  q' = q_R ⊗ q        the Gaussian's own axes turn with the object; of ±q' the one
//!                               nearer q, so a full turn gives q back
//! scale     unchanged           a rigid motion keeps sizes
//! opacity   unchanged
//! colour    SH band 0 looks the same from every direction: unchanged. Bands ≥ 1 would have
//!           to be turned by R too; GaussianMap holds band 0 only, and `apply` names every
//!           field of the map, so a field added for higher bands stops this compiling until
//!           it is handled here. Files with higher bands are refused (see `sh_guard`).
//! ```
//!
//! Sums are done in f64 and stored as the map's f32. A pure translation leaves rotations bit-exact.

use nalgebra::{Quaternion, Unit, UnitQuaternion, Vector3};
use opengs_splat::GaussianMap;

use crate::error::{ObjectError, Result};
use crate::selection::Selection;

/// x ↦ R (x − pivot) + pivot + translation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidMotion {
    pub rotation: UnitQuaternion<f64>,
    pub pivot: Vector3<f64>,
    pub translation: Vector3<f64>,
}

impl RigidMotion {
    /// A move by `t` (metres, world frame).
    pub fn translation(t: [f64; 3]) -> Result<Self> {
        finite("translation", &t)?;
        Ok(Self {
            rotation: UnitQuaternion::identity(),
            pivot: Vector3::zeros(),
            translation: Vector3::from(t),
        })
    }

    /// A turn by `degrees` (right-hand rule) about the line through `pivot` along `axis`.
    pub fn rotation_about(axis: [f64; 3], degrees: f64, pivot: [f64; 3]) -> Result<Self> {
        finite("rotation angle", &[degrees])?;
        finite("rotation centre", &pivot)?;
        let axis_vector = Vector3::from(axis);
        let norm = axis_vector.norm();
        if !(norm.is_finite() && norm > 0.0) {
            return Err(ObjectError::BadAxis(axis));
        }
        let unit = Unit::new_unchecked(axis_vector / norm);
        Ok(Self {
            rotation: UnitQuaternion::from_axis_angle(&unit, degrees.to_radians()),
            pivot: Vector3::from(pivot),
            translation: Vector3::zeros(),
        })
    }

    /// Where the motion takes point `x`.
    pub fn apply_point(&self, x: Vector3<f64>) -> Vector3<f64> {
        self.rotation * (x - self.pivot) + self.pivot + self.translation
    }

    fn turns(&self) -> bool {
        self.rotation.angle() != 0.0
    }
}

/// Moves the Gaussians of `selection` by `motion`; returns how many moved.
pub fn apply(map: &mut GaussianMap, selection: &Selection, motion: &RigidMotion) -> usize {
    // Every field named: one added later (e.g. SH bands ≥ 1) must be handled here.
    let GaussianMap {
        means,
        rotations,
        log_scales: _,
        opacity_logits: _,
        sh_dc: _,
        labels,
    } = map;
    let mut moved = 0;
    for ((mean, rotation), label) in means
        .iter_mut()
        .zip(rotations.iter_mut())
        .zip(labels.iter())
    {
        if !selection.contains(*label) {
            continue;
        }
        let x = motion.apply_point(Vector3::from(mean.map(f64::from)));
        *mean = [x.x as f32, x.y as f32, x.z as f32];
        if motion.turns() {
            *rotation = compose(&motion.rotation, *rotation);
        }
        moved += 1;
    }
    moved
}

/// q_R ⊗ q for a stored (w, x, y, z) quaternion, with the sign nearer q.
fn compose(turn: &UnitQuaternion<f64>, q: [f32; 4]) -> [f32; 4] {
    let [w, x, y, z] = q.map(f64::from);
    let before = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
    let after = (turn * before).into_inner();
    let sign = if after.dot(before.as_ref()) < 0.0 {
        -1.0
    } else {
        1.0
    };
    [after.w, after.i, after.j, after.k].map(|v| (sign * v) as f32)
}

fn finite(what: &'static str, values: &[f64]) -> Result<()> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(ObjectError::NotFinite {
            what,
            value: values.to_vec(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quarter_turn_about_z_through_a_pivot() {
        let m = RigidMotion::rotation_about([0.0, 0.0, 2.0], 90.0, [1.0, 0.0, 0.0]).expect("valid");
        let p = m.apply_point(Vector3::new(2.0, 0.0, 5.0));
        assert!((p - Vector3::new(1.0, 1.0, 5.0)).norm() < 1e-12, "{p}");
        // The identity quaternion becomes the turn itself: (cos 45°, 0, 0, sin 45°).
        let q = compose(&m.rotation, [1.0, 0.0, 0.0, 0.0]);
        let h = std::f32::consts::FRAC_1_SQRT_2;
        assert!((q[0] - h).abs() < 1e-7 && (q[3] - h).abs() < 1e-7, "{q:?}");
    }

    #[test]
    fn refuses_a_zero_axis_and_non_finite_values() {
        assert!(matches!(
            RigidMotion::rotation_about([0.0; 3], 10.0, [0.0; 3]),
            Err(ObjectError::BadAxis(_))
        ));
        let err = RigidMotion::translation([0.0, f64::NAN, 0.0]).expect_err("NaN");
        assert!(err.to_string().contains("translation"), "{err}");
    }
}
