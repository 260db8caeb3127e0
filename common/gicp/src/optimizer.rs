use crate::cloud::check_registrable;
use crate::factor;
use crate::lie::left_update;
use crate::{Cloud, GicpError, RegistrationConfig, Solver, Target};
use nalgebra::{Isometry3, Matrix3, Matrix6, Matrix6x3, SymmetricEigen, UnitQuaternion, Vector6};
use rayon::prelude::*;

/// Outcome of one registration. Statistics come from the final
/// correspondences (those of the last linearisation).
#[derive(Debug, Clone, PartialEq)]
pub struct Registration {
    /// Source → target transform (`p_t ≈ T p_s`).
    pub transform: Isometry3<f64>,
    pub iterations: usize,
    /// Whether the last update was below both epsilons.
    pub converged: bool,
    /// Source points with a target point within the max correspondence distance.
    pub inliers: usize,
    /// `inliers / source points` (Open3D's "fitness").
    pub fitness: f64,
    /// Root mean square Euclidean distance of the inlier correspondences (m).
    pub inlier_rmse: f64,
    /// Fraction of source points whose nearest target point is within
    /// `overlapped_th` squared distance (docs/METHOD.md §7 keyframe rule).
    pub overlap: f64,
    /// Final summed Mahalanobis error `Σ dᵀ Ω d`.
    pub error: f64,
    /// Smallest ÷ largest eigenvalue of `H` at the last linearisation: near 0 when some
    /// motion (sliding along a wall, turning about a pole) is barely constrained.
    pub conditioning: f64,
    /// `H = Σ Jᵀ Ω J` at the last linearisation (rotation rows first, then translation, in
    /// the target frame: left updates): its weak directions are where a registration slides.
    pub hessian: Matrix6<f64>,
}

/// Source points handled by one parallel task.
const CHUNK: usize = 256;
/// Marks a source point without a correspondence.
const NO_MATCH: u32 = u32::MAX;

/// Sums over all correspondences of one linearisation.
#[derive(Clone)]
struct Normal {
    h: Matrix6<f64>,
    b: Vector6<f64>,
    error: f64,
    inliers: usize,
    inlier_sq_dist: f64,
    overlapping: usize,
}

impl Normal {
    fn zero() -> Self {
        Self {
            h: Matrix6::zeros(),
            b: Vector6::zeros(),
            error: 0.0,
            inliers: 0,
            inlier_sq_dist: 0.0,
            overlapping: 0,
        }
    }

    fn add(mut self, other: Self) -> Self {
        self.h += other.h;
        self.b += other.b;
        self.error += other.error;
        self.inliers += other.inliers;
        self.inlier_sq_dist += other.inlier_sq_dist;
        self.overlapping += other.overlapping;
        self
    }
}

/// Registers `source` to `target` starting from `initial` (source → target).
/// Runs on the current rayon pool: use `pool.install` to bound threads.
/// Plain Gauss-Newton steps: Anderson acceleration (AA-ICP: memory 5 with a safeguard,
/// memory 2 and 3 without) took 645–779 fine iterations against 691 (the worst frame 16–26
/// against 12) on 100 noisy frames of scene 2 along fr2_desk: correspondences flipping under
/// noise make the map from one step to the next rough.
pub fn register(
    source: &Cloud,
    target: &Target,
    initial: &Isometry3<f64>,
    config: &RegistrationConfig,
) -> Result<Registration, GicpError> {
    check_registrable("source", &source.points)?;
    target.check_registrable()?;
    if source.points.len() != source.covariances.len() {
        return Err(GicpError::LengthMismatch("source points and covariances"));
    }
    if !initial.to_homogeneous().iter().all(|v| v.is_finite()) {
        return Err(GicpError::Invalid("initial transform is not finite".into()));
    }
    let mut transform = *initial;
    let mut matches = vec![NO_MATCH; source.len()];
    let mut lambda = config.lm_initial_lambda;
    let mut iterations = 0;
    let mut converged = false;
    let mut last = linearize(source, target, &transform, config, &mut matches)?;
    while iterations < config.max_iterations {
        iterations += 1;
        check_rank(&last.h, config)?;
        let delta = match config.solver {
            Solver::GaussNewton if config.rotation_only => {
                let (next, delta) = rotation_step(&transform, &last.h, &last.b)?;
                transform = next;
                delta
            }
            Solver::GaussNewton => {
                let delta = solve(&last.h, &last.b)?;
                transform = left_update(&transform, &delta);
                delta
            }
            Solver::LevenbergMarquardt => {
                match lm_step(
                    source,
                    target,
                    &transform,
                    &last,
                    &matches,
                    &mut lambda,
                    config,
                )? {
                    Some(step) => {
                        transform = step.transform;
                        step.delta
                    }
                    // No damping lowers the error: we sit at a minimum.
                    None => {
                        converged = true;
                        break;
                    }
                }
            }
        };
        let small = delta.fixed_rows::<3>(0).norm() < config.rotation_epsilon
            && delta.fixed_rows::<3>(3).norm() < config.translation_epsilon;
        if small {
            converged = true;
            break;
        }
        let travel = initial.inverse() * transform;
        if travel.translation.vector.norm() > config.leash_metres
            || travel.rotation.angle() > config.leash_radians
        {
            // Off the leash: the statistics stay those of the last linearisation.
            break;
        }
        last = linearize(source, target, &transform, config, &mut matches)?;
    }
    if !transform.to_homogeneous().iter().all(|v| v.is_finite()) {
        return Err(GicpError::Degenerate("the solution is not finite".into()));
    }
    let n = source.len() as f64;
    let conditioning = eigenvalue_ratio(&last.h);
    Ok(Registration {
        transform,
        iterations,
        converged,
        inliers: last.inliers,
        fitness: last.inliers as f64 / n,
        inlier_rmse: (last.inlier_sq_dist / last.inliers.max(1) as f64).sqrt(),
        overlap: last.overlapping as f64 / n,
        error: last.error,
        conditioning,
        hessian: last.h,
    })
}

/// Correspondence search + factor linearisation at `transform`, in parallel
/// chunks, reduced into one set of normal equations.
fn linearize(
    source: &Cloud,
    target: &Target,
    transform: &Isometry3<f64>,
    config: &RegistrationConfig,
    matches: &mut [u32],
) -> Result<Normal, GicpError> {
    let rotation = transform.rotation.to_rotation_matrix().into_inner();
    let max_sq = config.max_correspondence_distance.powi(2);
    // Only neighbours within the inlier or overlap distance matter.
    let search_sq = max_sq.max(config.overlapped_th);
    // The grid answers searches up to its radius; the kd-tree anything farther.
    let tree = (search_sq > target.search_radius().powi(2)).then(|| target.tree());
    let grid = target.grid();
    let (t_points, t_covs) = (target.points(), target.covariances());
    let normal = matches
        .par_chunks_mut(CHUNK)
        .zip(
            source
                .points
                .par_chunks(CHUNK)
                .zip(source.covariances.par_chunks(CHUNK)),
        )
        .map(|(matches, (points, covs))| {
            let mut sum = Normal::zero();
            for ((m, p), c) in matches.iter_mut().zip(points).zip(covs) {
                *m = NO_MATCH;
                let q = transform * p;
                let nearest = match tree {
                    Some(tree) => tree.nearest_within(&q, search_sq),
                    None => grid.nearest_within(&q, search_sq),
                };
                let Some((j, sq_dist)) = nearest else {
                    continue;
                };
                if sq_dist <= config.overlapped_th {
                    sum.overlapping += 1;
                }
                if sq_dist > max_sq {
                    continue;
                }
                let Some(f) = factor::linearize(&rotation, &q, c, &t_points[j], &t_covs[j]) else {
                    continue;
                };
                *m = j as u32;
                sum.h += f.h;
                sum.b += f.b;
                sum.error += f.error;
                sum.inliers += 1;
                sum.inlier_sq_dist += sq_dist;
            }
            sum
        })
        .reduce(Normal::zero, Normal::add);
    if normal.inliers < config.min_correspondences {
        return Err(GicpError::TooFewCorrespondences {
            found: normal.inliers,
            needed: config.min_correspondences,
        });
    }
    Ok(normal)
}

/// Error `Σ dᵀ Ω d` at `transform` with correspondences held fixed.
fn fixed_correspondence_error(
    source: &Cloud,
    target: &Target,
    transform: &Isometry3<f64>,
    matches: &[u32],
) -> f64 {
    let rotation = transform.rotation.to_rotation_matrix().into_inner();
    let (t_points, t_covs) = (target.points(), target.covariances());
    matches
        .par_chunks(CHUNK)
        .zip(
            source
                .points
                .par_chunks(CHUNK)
                .zip(source.covariances.par_chunks(CHUNK)),
        )
        .map(|(matches, (points, covs))| {
            let mut e = 0.0;
            for ((&m, p), c) in matches.iter().zip(points).zip(covs) {
                if m != NO_MATCH {
                    let j = m as usize;
                    e += factor::error(&rotation, &(transform * p), c, &t_points[j], &t_covs[j]);
                }
            }
            e
        })
        .sum()
}

/// An accepted update and the transform it leads to.
struct Step {
    delta: Vector6<f64>,
    transform: Isometry3<f64>,
}

/// One Levenberg-Marquardt iteration: raise λ until a step lowers the error.
fn lm_step(
    source: &Cloud,
    target: &Target,
    transform: &Isometry3<f64>,
    at: &Normal,
    matches: &[u32],
    lambda: &mut f64,
    config: &RegistrationConfig,
) -> Result<Option<Step>, GicpError> {
    for _ in 0..config.lm_max_inner_iterations {
        let damped = at.h + Matrix6::identity() * *lambda;
        let (candidate, delta) = match config.rotation_only {
            true => rotation_step(transform, &damped, &at.b)?,
            false => {
                let delta = solve(&damped, &at.b)?;
                (left_update(transform, &delta), delta)
            }
        };
        if fixed_correspondence_error(source, target, &candidate, matches) <= at.error {
            *lambda /= config.lm_lambda_factor;
            return Ok(Some(Step {
                delta,
                transform: candidate,
            }));
        }
        *lambda *= config.lm_lambda_factor;
    }
    Ok(None)
}

/// Smallest ÷ largest eigenvalue of a symmetric `H` (0 when not positive).
fn eigenvalue_ratio(h: &Matrix6<f64>) -> f64 {
    let eigenvalues = SymmetricEigen::new(*h).eigenvalues;
    let (min, max) = (eigenvalues.min(), eigenvalues.max());
    if max.is_finite() && max > 0.0 && min > 0.0 {
        min / max
    } else {
        0.0
    }
}

/// Rank check of `H`: a null direction means the pose is not observable.
fn check_rank(h: &Matrix6<f64>, config: &RegistrationConfig) -> Result<(), GicpError> {
    let eigenvalues = SymmetricEigen::new(*h).eigenvalues;
    let (min, max) = (eigenvalues.min(), eigenvalues.max());
    if max.is_nan() || max <= 0.0 || min < config.degeneracy_ratio * max {
        return Err(GicpError::Degenerate(format!(
            "H is rank-deficient (eigenvalues from {min:.3e} to {max:.3e})"
        )));
    }
    Ok(())
}

/// A Gauss-Newton step that turns the source about its origin `t` (the camera centre)
/// and keeps `t`. To first order a left update `(ω, v)` keeps `t` when `v = t × ω`,
/// so `δ = G ω` with `G = [I; [t]×]`, and `ω` solves `(Gᵀ H G) ω = −Gᵀ b`.
/// Returns the new transform and `(ω, 0)` (for the convergence test: `t` does not move).
fn rotation_step(
    transform: &Isometry3<f64>,
    h: &Matrix6<f64>,
    b: &Vector6<f64>,
) -> Result<(Isometry3<f64>, Vector6<f64>), GicpError> {
    let t = transform.translation.vector;
    let mut g = Matrix6x3::zeros();
    g.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&Matrix3::identity());
    g.fixed_view_mut::<3, 3>(3, 0).copy_from(&t.cross_matrix());
    let a = g.transpose() * h * g;
    let omega = a
        .cholesky()
        .map(|c| -c.solve(&(g.transpose() * b)))
        .filter(|w| w.iter().all(|v| v.is_finite()))
        .ok_or_else(|| GicpError::Degenerate("the rotation block of H is singular".into()))?;
    let turned = Isometry3::from_parts(
        transform.translation,
        UnitQuaternion::from_scaled_axis(omega) * transform.rotation,
    );
    Ok((
        turned,
        Vector6::new(omega.x, omega.y, omega.z, 0.0, 0.0, 0.0),
    ))
}

/// `δ = −H⁻¹ b` by Cholesky (H is symmetric positive definite here).
fn solve(h: &Matrix6<f64>, b: &Vector6<f64>) -> Result<Vector6<f64>, GicpError> {
    let delta = h
        .cholesky()
        .map(|c| -c.solve(b))
        .ok_or_else(|| GicpError::Degenerate("H is not positive definite".into()))?;
    if delta.iter().all(|v| v.is_finite()) {
        Ok(delta)
    } else {
        Err(GicpError::Degenerate("the update is not finite".into()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector6;

    #[test]
    fn rank_deficient_h_is_degenerate() {
        // Nothing constrains the rotation about z: H's third row/column is zero.
        let h = Matrix6::from_diagonal(&Vector6::new(1.0, 2.0, 0.0, 3.0, 4.0, 5.0));
        assert!(matches!(
            check_rank(&h, &RegistrationConfig::tum()),
            Err(GicpError::Degenerate(_))
        ));
        let full = Matrix6::from_diagonal(&Vector6::new(1.0, 2.0, 1e-3, 3.0, 4.0, 5.0));
        assert!(check_rank(&full, &RegistrationConfig::tum()).is_ok());
        assert!(solve(&h, &Vector6::repeat(1.0)).is_err());
    }
}
