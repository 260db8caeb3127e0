use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

/// A rigid transform. Stage messages and files carry camera-to-world poses.
pub type Pose = Isometry3<f64>;

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PoseParseError {
    #[error("expected {expected} numbers, found {found}")]
    WrongCount { expected: usize, found: usize },
    #[error("'{0}' is not a number")]
    NotANumber(String),
    #[error("quaternion has zero or non-finite norm")]
    BadQuaternion,
}

/// Parses `tx ty tz qx qy qz qw` (TUM order) into a pose.
pub fn parse_tum_pose(text: &str) -> Result<Pose, PoseParseError> {
    let vals: Vec<f64> = text
        .split_whitespace()
        .map(|t| {
            t.parse::<f64>()
                .map_err(|_| PoseParseError::NotANumber(t.to_string()))
        })
        .collect::<Result<_, _>>()?;
    if vals.len() != 7 {
        return Err(PoseParseError::WrongCount {
            expected: 7,
            found: vals.len(),
        });
    }
    pose_from_tum(&vals[..7].try_into().expect("length checked"))
}

/// Builds a pose from `[tx, ty, tz, qx, qy, qz, qw]`, normalising the quaternion.
pub fn pose_from_tum(v: &[f64; 7]) -> Result<Pose, PoseParseError> {
    let q = Quaternion::new(v[6], v[3], v[4], v[5]);
    let n = q.norm();
    if !n.is_finite() || n < 1e-12 || v[..3].iter().any(|x| !x.is_finite()) {
        return Err(PoseParseError::BadQuaternion);
    }
    Ok(Isometry3::from_parts(
        Translation3::new(v[0], v[1], v[2]),
        UnitQuaternion::from_quaternion(q),
    ))
}

/// Formats a pose as `tx ty tz qx qy qz qw` (TUM order), 9 decimals (round-trips to 1e-9).
pub fn format_tum_pose(p: &Pose) -> String {
    let t = p.translation.vector;
    let q = p.rotation.quaternion();
    format!(
        "{:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}",
        t.x, t.y, t.z, q.i, q.j, q.k, q.w
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn tum_round_trip() {
        let p = parse_tum_pose("1 2 3 0 0 0.7071068 0.7071068").expect("valid");
        assert_relative_eq!(p.translation.vector.y, 2.0);
        // 90° about z maps x to y.
        let x = p.rotation * nalgebra::Vector3::x();
        assert_relative_eq!(x.y, 1.0, epsilon = 1e-6);
        let q = parse_tum_pose(&format_tum_pose(&p)).expect("valid");
        assert_relative_eq!(p.to_homogeneous(), q.to_homogeneous(), epsilon = 1e-6);
    }

    #[test]
    fn bad_pose_text() {
        assert_eq!(
            parse_tum_pose("1 2 3"),
            Err(PoseParseError::WrongCount {
                expected: 7,
                found: 3
            })
        );
        assert!(matches!(
            parse_tum_pose("1 2 x 0 0 0 1"),
            Err(PoseParseError::NotANumber(_))
        ));
        assert_eq!(
            parse_tum_pose("1 2 3 0 0 0 0"),
            Err(PoseParseError::BadQuaternion)
        );
    }
}

/// A pose as `[tx, ty, tz, qx, qy, qz, qw]` (TUM order), as messages carry it.
pub fn pose_to_tum(p: &Pose) -> [f64; 7] {
    let t = p.translation.vector;
    let q = p.rotation.quaternion();
    [t.x, t.y, t.z, q.i, q.j, q.k, q.w]
}

#[cfg(test)]
mod array_tests {
    use super::*;

    #[test]
    fn array_round_trip() {
        let a = [0.5, -1.0, 2.0, 0.0, 0.0, 0.0, 1.0];
        let p = pose_from_tum(&a).expect("valid");
        assert_eq!(pose_to_tum(&p), a);
    }
}
