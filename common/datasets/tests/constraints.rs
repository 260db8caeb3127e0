//! The synthetic views constrain point-to-plane tracking in all 6 DoF: the
//! point-to-plane Hessian Σ [p×n; n][p×n; n]ᵀ is well conditioned everywhere
//! along the default path (flat walls alone would leave it rank-deficient).

use nalgebra::{Matrix6, SymmetricEigen, Vector3, Vector6};
use opengs_datasets::{RgbdFrame, RgbdSource, SyntheticOptions, SyntheticSource};
use opengs_geometry::Intrinsics;

fn point(f: &RgbdFrame, k: &Intrinsics, u: u32, v: u32) -> Option<Vector3<f64>> {
    let z = f.depth_m(u, v)? as f64;
    Some(k.backproject(u as f64, v as f64, z).coords)
}

/// Eigenvalues (ascending) of the normalised point-to-plane Hessian, with
/// points centred on their mean so rotation and translation scale alike.
fn hessian_spectrum(f: &RgbdFrame, k: &Intrinsics) -> Vec<f64> {
    let mut samples = Vec::new();
    for v in (1..f.height - 1).step_by(4) {
        for u in (1..f.width - 1).step_by(4) {
            let (Some(p), Some(px), Some(py)) = (
                point(f, k, u, v),
                point(f, k, u + 1, v),
                point(f, k, u, v + 1),
            ) else {
                continue;
            };
            let (dx, dy) = (px - p, py - p);
            // Skip depth discontinuities: normals there are meaningless.
            if dx.norm() > 0.05 || dy.norm() > 0.05 {
                continue;
            }
            let n = dx.cross(&dy);
            if n.norm() < 1e-12 {
                continue;
            }
            samples.push((p, n.normalize()));
        }
    }
    let mean = samples.iter().map(|(p, _)| p).sum::<Vector3<f64>>() / samples.len() as f64;
    let mut h = Matrix6::zeros();
    for (p, n) in &samples {
        let q = p - mean;
        let j = Vector6::from_iterator(q.cross(n).iter().chain(n.iter()).copied());
        h += j * j.transpose();
    }
    h /= samples.len() as f64;
    let mut ev: Vec<f64> = SymmetricEigen::new(h).eigenvalues.iter().copied().collect();
    ev.sort_by(f64::total_cmp);
    ev
}

#[test]
fn every_view_constrains_all_six_dof() {
    let mut src = SyntheticSource::new(SyntheticOptions {
        frames: Some(600),
        ..SyntheticOptions::default()
    })
    .expect("source");
    let k = src.intrinsics();
    for i in (0..600).step_by(50) {
        let f = src.frame(i).expect("frame");
        let ev = hessian_spectrum(&f, &k);
        let (min, max) = (ev[0], ev[5]);
        eprintln!("frame {i}: eigenvalues {ev:.5?}");
        assert!(min / max > 0.03, "frame {i}: ill-conditioned {ev:?}");
    }
}
