//! Fast Point Feature Histograms (Rusu, Blodow and Beetz, ICRA 2009), computed as PCL and
//! Open3D do: a description of the surface shape around a point that does not depend on
//! where the camera stood, so a frame can be matched to a model with no pose guess.
//!
//! For a point pair `(p₁, n₁)`, `(p₂, n₂)` with `d = p₂ − p₁` (the pair ordered so that
//! `p₁`'s normal makes the smaller angle with the line between them):
//!
//! ```text
//! u = n₁,  v = (d × u) / |d × u|,  w = u × v       the Darboux frame at p₁
//! f₁ = atan2(w·n₂, u·n₂)    f₂ = v·n₂    f₃ = u·d / |d|
//! ```
//!
//! SPFH(p): the three features of `p` with each neighbour within `radius`, binned 11 ways
//! each (33 bins), each histogram scaled to sum 100. FPFH(p) = SPFH(p) + the neighbours'
//! SPFHs weighted by 1 / squared distance, each histogram of that sum rescaled to 100.
//! Normals must face the side the surface was seen from (see [`oriented_normals`]).

use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};
use rayon::prelude::*;

use crate::PointTree;

/// Bins per feature, and in all.
const BINS: usize = 11;
pub const FPFH_LEN: usize = 3 * BINS;

/// One point's histogram.
pub type Fpfh = [f32; FPFH_LEN];

/// Unit normals from the points' covariances (the direction of least spread), each turned
/// to face `viewpoint(p)`, where the sensor that saw `p` stood.
pub fn oriented_normals(
    points: &[Point3<f64>],
    covariances: &[Matrix3<f64>],
    viewpoint: impl Fn(&Point3<f64>) -> Point3<f64> + Sync,
) -> Vec<Vector3<f64>> {
    points
        .par_iter()
        .zip(covariances)
        .map(|(p, c)| {
            let n = least_spread_direction(c);
            if n.dot(&(viewpoint(p) - p)) < 0.0 {
                -n
            } else {
                n
            }
        })
        .collect()
}

/// The unit eigenvector of `c`'s smallest eigenvalue λ, as the largest cross product of
/// two rows of `c − λI` (both rows are orthogonal to it). nalgebra's eigenvectors can be
/// wrong where two eigenvalues coincide (a flat disc `I − nnᵀ` gave one lying in the disc).
pub fn least_spread_direction(c: &Matrix3<f64>) -> Vector3<f64> {
    let eig = SymmetricEigen::new(*c);
    let m = c - Matrix3::identity() * eig.eigenvalues.min();
    let (r0, r1, r2) = (
        m.row(0).transpose(),
        m.row(1).transpose(),
        m.row(2).transpose(),
    );
    let best = [r0.cross(&r1), r0.cross(&r2), r1.cross(&r2)]
        .into_iter()
        .max_by(|a, b| a.norm_squared().total_cmp(&b.norm_squared()))
        .unwrap_or_else(Vector3::zeros);
    match best.try_normalize(1e-12) {
        Some(n) => n,
        // Two smallest eigenvalues alike (a line): any direction across it will do.
        None => eig.eigenvectors.column(eig.eigenvalues.imin()).into_owned(),
    }
}

/// `(f₁, f₂, f₃)` of a pair, `None` for coincident points or a normal along the line.
fn pair_features(
    p1: &Point3<f64>,
    n1: &Vector3<f64>,
    p2: &Point3<f64>,
    n2: &Vector3<f64>,
) -> Option<[f64; 3]> {
    let mut d = p2 - p1;
    let len = d.norm();
    if len == 0.0 {
        return None;
    }
    let (a1, a2) = (n1.dot(&d) / len, n2.dot(&d) / len);
    // The same point is p₁ whichever way round the pair comes.
    let (u, n2, f3) = if a1.abs().acos() > a2.abs().acos() {
        d = -d;
        (n2, n1, -a2)
    } else {
        (n1, n2, a1)
    };
    let v = d.cross(u);
    let v_len = v.norm();
    if v_len == 0.0 {
        return None;
    }
    let v = v / v_len;
    let w = u.cross(&v);
    Some([w.dot(n2).atan2(u.dot(n2)), v.dot(n2), f3])
}

fn bin(value: f64, low: f64, high: f64) -> usize {
    let b = (BINS as f64 * (value - low) / (high - low)).floor();
    b.clamp(0.0, (BINS - 1) as f64) as usize
}

/// FPFH of every point over its neighbours within `radius` (at most `max_neighbours`,
/// nearest first); a point without neighbours gets an all-zero histogram.
pub fn fpfh(
    points: &[Point3<f64>],
    normals: &[Vector3<f64>],
    tree: &PointTree,
    radius: f64,
    max_neighbours: usize,
) -> Vec<Fpfh> {
    let r2 = radius * radius;
    let neighbours: Vec<Vec<(usize, f64)>> = points
        .par_iter()
        .map(|p| {
            tree.knn(p, max_neighbours + 1)
                .into_iter()
                // The point itself (and copies of it, up to rounding) is no neighbour.
                .filter(|&(_, d2)| d2 <= r2 && d2 > 1e-12)
                .collect()
        })
        .collect();
    let spfh: Vec<Fpfh> = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let mut h = [0f32; FPFH_LEN];
            let near = &neighbours[i];
            if near.is_empty() {
                return h;
            }
            let step = 100.0 / near.len() as f32;
            for &(j, _) in near {
                if let Some([f1, f2, f3]) = pair_features(p, &normals[i], &points[j], &normals[j]) {
                    let pi = std::f64::consts::PI;
                    h[bin(f1, -pi, pi)] += step;
                    h[BINS + bin(f2, -1.0, 1.0)] += step;
                    h[2 * BINS + bin(f3, -1.0, 1.0)] += step;
                }
            }
            h
        })
        .collect();
    neighbours
        .par_iter()
        .enumerate()
        .map(|(i, near)| {
            let mut h = [0f32; FPFH_LEN];
            let mut sums = [0f32; 3];
            for &(j, d2) in near {
                let weight = 1.0 / d2 as f32;
                for (b, v) in spfh[j].iter().enumerate() {
                    let add = v * weight;
                    h[b] += add;
                    sums[b / BINS] += add;
                }
            }
            for (b, v) in h.iter_mut().enumerate() {
                let s = sums[b / BINS];
                if s > 0.0 {
                    *v *= 100.0 / s;
                }
                *v += spfh[i][b];
            }
            h
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, UnitQuaternion};

    #[test]
    fn the_normal_of_a_flat_disc_whatever_its_tilt() {
        // The case nalgebra's eigenvectors got wrong: point 50 of the sphere below.
        for n in [
            Vector3::new(
                9.150446530217571e-18,
                0.14943813247359922,
                0.9887710779360422,
            ),
            Vector3::z(),
            Vector3::new(1.0, -2.0, 0.5).normalize(),
        ] {
            let c = Matrix3::identity() - n * n.transpose();
            let found = least_spread_direction(&c);
            assert!((found.dot(&n).abs() - 1.0).abs() < 1e-9, "{n:?}: {found:?}");
        }
    }

    #[test]
    fn pair_features_of_a_hand_worked_pair_and_its_reverse() {
        // p₂ one metre along x, n₁ = z, n₂ tilted 45° from z towards x.
        let (p1, n1) = (Point3::origin(), Vector3::z());
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let (p2, n2) = (Point3::new(1.0, 0.0, 0.0), Vector3::new(s, 0.0, s));
        // |n₁·d| = 0 (90°) > |n₂·d| = 0.71 (45°): the pair is taken from p₂. u = n₂,
        // d = (−1, 0, 0), v = d × u = (0, 0.71, 0)/0.71 = y, w = u × v = (−0.71, 0, 0.71).
        // f₁ = atan2(w·n₁, u·n₁) = atan2(0.71, 0.71) = 45°, f₂ = v·n₁ = 0, f₃ = −n₂·(1,0,0) = −0.71.
        let f = pair_features(&p1, &n1, &p2, &n2).expect("a proper pair");
        assert!((f[0] - std::f64::consts::FRAC_PI_4).abs() < 1e-12, "{f:?}");
        assert!(f[1].abs() < 1e-12);
        assert!((f[2] + s).abs() < 1e-12);
        assert_eq!(pair_features(&p2, &n2, &p1, &n1), Some(f));
        assert_eq!(pair_features(&p1, &n1, &p1, &n2), None);
    }

    /// Points on a unit sphere's upper half and a plane beside it, each with its surface
    /// normal.
    fn shape() -> Vec<(Point3<f64>, Vector3<f64>)> {
        let mut points = Vec::new();
        for i in 1..21 {
            for j in 0..40 {
                let (t, p) = (i as f64 * 0.075, j as f64 * std::f64::consts::TAU / 40.0);
                let q = Point3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos());
                points.push((q, q.coords));
            }
        }
        for x in 0..20 {
            for y in 0..20 {
                let q = Point3::new(1.5 + x as f64 * 0.1, y as f64 * 0.1 - 1.0, 0.0);
                points.push((q, Vector3::z()));
            }
        }
        points
    }

    /// Features of `shape` moved by `t`, seen from `t · eye`; covariances are flat discs
    /// across the true normals (no neighbour search whose ties could differ).
    fn features(t: &Isometry3<f64>, eye: Point3<f64>) -> Vec<Fpfh> {
        let (points, covariances): (Vec<_>, Vec<_>) = shape()
            .into_iter()
            .map(|(p, n)| {
                let n = t.rotation * n;
                (t * p, Matrix3::identity() - n * n.transpose())
            })
            .unzip();
        let normals = oriented_normals(&points, &covariances, |_| t * eye);
        fpfh(&points, &normals, &PointTree::new(&points), 0.43, 1000)
    }

    #[test]
    fn histograms_do_not_change_with_the_pose_and_tell_sphere_from_plane() {
        // High above: every normal faces up (a flipped neighbour would put f₁ at ±π, a bin
        // edge).
        let eye = Point3::new(0.5, 0.0, 50.0);
        let a = features(&Isometry3::identity(), eye);
        let t = Isometry3::from_parts(
            Vector3::new(2.0, -1.0, 0.5).into(),
            UnitQuaternion::from_euler_angles(0.4, -1.1, 2.0),
        );
        let b = features(&t, eye);
        // A pair within rounding of a bin edge may fall either side: compare whole
        // histograms (600 in all), not bins.
        for (x, y) in a.iter().zip(&b) {
            let moved: f32 = x.iter().zip(y).map(|(u, v)| (u - v).abs()).sum();
            assert!(moved < 0.5, "{moved}: {x:?} vs {y:?}");
        }
        // Each of the three histograms sums to 200 (its SPFH part and its neighbours' part).
        let h = &a[100];
        for k in 0..3 {
            let s: f32 = h[k * BINS..(k + 1) * BINS].iter().sum();
            assert!((s - 200.0).abs() < 1e-3, "{s}");
        }
        // On the plane all normals agree: f₂ = f₃ = 0 and f₁ = 0, one bin each.
        let plane = &a[800 + 10 * 20 + 10];
        assert!(
            (plane[bin(0.0, -1.0, 1.0) + BINS] - 200.0).abs() < 1e-3,
            "{plane:?}"
        );
        let distance = |x: &Fpfh, y: &Fpfh| {
            x.iter()
                .zip(y)
                .map(|(u, v)| (u - v).powi(2))
                .sum::<f32>()
                .sqrt()
        };
        // Two sphere points are nearer each other than either is to a plane point.
        let (s1, s2) = (&a[10 * 40 + 5], &a[10 * 40 + 25]);
        assert!(
            distance(s1, s2) * 3.0 < distance(s1, plane),
            "{} {}",
            distance(s1, s2),
            distance(s1, plane)
        );
    }
}
