//! Global registration: where a cloud lies in a model with no guess at all, as Open3D's
//! `registration_ransac_based_on_feature_matching` finds it. G-ICP converges from within
//! tens of centimetres and some 20°; a camera that comes back to mapped space from
//! somewhere else (fr2_desk's 12 s gap: 2–4.5 m + rad from every keyframe) needs this.
//!
//! 1. Both clouds thinned to `voxel`, normals from the covariances, [`fpfh`] features.
//! 2. Correspondences: for an even subset of `match_points` source points, the nearest
//!    target point in feature space, kept when the pair are each other's nearest (mutual).
//! 3. RANSAC: three correspondences at random; their triangle must have about the same
//!    sides in both clouds (`edge_similarity`) and the fit of the three must bring each
//!    within `inlier_distance`, else the sample is dropped; a fit that passes is scored
//!    by its fitness on an even subset of `score_points` source points: the share with
//!    a target point within `inlier_distance`.
//! 4. The best few hypotheses, each refitted to its inlier correspondences, their
//!    fitness over all source points.
//!
//! The answers are starting points, not results: the caller registers from them and
//! verifies.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Isometry3, Point3};
use opengs_geometry::rigid_fit;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::fpfh::{fpfh, oriented_normals, Fpfh, FPFH_LEN};
use crate::{Cloud, PointTree};

/// Settings of [`register_global`] (Open3D's tutorial values for a 5 cm voxel).
#[derive(Debug, Clone, PartialEq)]
pub struct GlobalConfig {
    /// Voxel both clouds are thinned to (m).
    pub voxel: f64,
    /// Neighbourhood of a feature (m), and at most this many neighbours in it.
    pub feature_radius: f64,
    pub max_neighbours: usize,
    /// A correspondence within this distance after the fit is an inlier (m).
    pub inlier_distance: f64,
    /// Shortest ÷ longest of a triangle side in the two clouds must reach this.
    pub edge_similarity: f64,
    /// RANSAC samples drawn, and at most this many that pass the cheap checks scored
    /// against the whole target.
    pub iterations: usize,
    pub max_validations: usize,
    /// Source points matched to the target (an even subset) …
    pub match_points: usize,
    /// … and those a hypothesis is scored on.
    pub score_points: usize,
    /// Hypotheses returned, best fitness first.
    pub answers: usize,
    pub seed: u64,
}

impl Default for GlobalConfig {
    fn default() -> Self {
        Self {
            voxel: 0.05,
            feature_radius: 0.25,
            max_neighbours: 100,
            inlier_distance: 0.075,
            edge_similarity: 0.9,
            iterations: 100_000,
            max_validations: 1_000,
            match_points: 2_500,
            score_points: 500,
            answers: 3,
            seed: 7,
        }
    }
}

/// A cloud thinned, with its features and the trees the matching needs.
pub struct FeatureCloud {
    points: Vec<Point3<f64>>,
    features: Vec<Fpfh>,
    tree: PointTree,
    /// `None` for an empty cloud (the tree cannot be built empty).
    feature_tree: Option<ImmutableKdTree<f32, FPFH_LEN>>,
}

impl FeatureCloud {
    /// Features of `cloud` (points with covariances); `viewpoint(p)` is where the sensor
    /// that saw `p` stood (normals face it).
    pub fn new(
        cloud: &Cloud,
        viewpoint: impl Fn(&Point3<f64>) -> Point3<f64> + Sync,
        config: &GlobalConfig,
    ) -> Self {
        let thin = cloud.voxel_subsample(config.voxel);
        let tree = PointTree::new(&thin.points);
        let normals = oriented_normals(&thin.points, &thin.covariances, viewpoint);
        let features = fpfh(
            &thin.points,
            &normals,
            &tree,
            config.feature_radius,
            config.max_neighbours,
        );
        let feature_tree =
            (!features.is_empty()).then(|| ImmutableKdTree::new_from_slice(&features));
        Self {
            points: thin.points,
            features,
            tree,
            feature_tree,
        }
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    fn nearest_feature(&self, f: &Fpfh) -> Option<usize> {
        let tree = self.feature_tree.as_ref()?;
        Some(tree.nearest_one::<SquaredEuclidean>(f).item as usize)
    }
}

/// One hypothesis: `p_target ≈ transform · p_source`.
#[derive(Debug, Clone, PartialEq)]
pub struct GlobalMatch {
    pub transform: Isometry3<f64>,
    /// Correspondences within the inlier distance, of `correspondences`.
    pub inliers: usize,
    pub correspondences: usize,
    /// Share of the thinned source points with a target point within the inlier distance.
    pub fitness: f64,
}

/// Mutual nearest neighbours in feature space, `(source index, target index)`, from an
/// even subset of at most `queries` source points (a search in 33 dimensions costs
/// about a millisecond per thousand target points; a few hundred right matches suffice).
fn correspondences(
    source: &FeatureCloud,
    target: &FeatureCloud,
    queries: usize,
) -> Vec<(usize, usize)> {
    let stride = source.len().div_ceil(queries.max(1)).max(1);
    let ids: Vec<usize> = (0..source.len()).step_by(stride).collect();
    ids.into_par_iter()
        .filter(|&i| source.features[i].iter().any(|v| *v != 0.0))
        .filter_map(|i| {
            let j = target.nearest_feature(&source.features[i])?;
            (source.nearest_feature(&target.features[j]) == Some(i)).then_some((i, j))
        })
        .collect()
}

/// Whether the triangle of three correspondences has about the same sides in both clouds.
fn similar_triangles(
    s: &[Point3<f64>; 3],
    t: &[Point3<f64>; 3],
    min_ratio: f64,
    min_side: f64,
) -> bool {
    [(0, 1), (1, 2), (2, 0)].iter().all(|&(a, b)| {
        let (ls, lt) = ((s[a] - s[b]).norm(), (t[a] - t[b]).norm());
        ls.min(lt) >= min_ratio * ls.max(lt) && ls.min(lt) >= min_side
    })
}

/// Hypotheses for where `source` lies in `target`, best fitness first (empty when fewer
/// than three correspondences, or no sample survives).
pub fn register_global(
    source: &FeatureCloud,
    target: &FeatureCloud,
    config: &GlobalConfig,
) -> Vec<GlobalMatch> {
    if source.is_empty() || target.is_empty() {
        return Vec::new();
    }
    let pairs = correspondences(source, target, config.match_points);
    if pairs.len() < 3 {
        return Vec::new();
    }
    let d2 = config.inlier_distance * config.inlier_distance;
    let inliers_of = |t: &Isometry3<f64>| -> Vec<(usize, usize)> {
        pairs
            .iter()
            .copied()
            .filter(|&(i, j)| (t * source.points[i] - target.points[j]).norm_squared() <= d2)
            .collect()
    };
    let on_target = |t: &Isometry3<f64>, points: &[Point3<f64>]| -> f64 {
        let hits = points
            .iter()
            .filter(|p| target.tree.nearest_within(&(t * *p), d2).is_some())
            .count();
        hits as f64 / points.len().max(1) as f64
    };
    // Hypotheses are ranked on an even subset of the frame, the answers on all of it.
    let stride = source.len().div_ceil(config.score_points.max(1)).max(1);
    let subset: Vec<Point3<f64>> = source.points.iter().step_by(stride).copied().collect();
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    // (fitness on the subset, transform), the best `answers` kept.
    let mut best: Vec<(f64, Isometry3<f64>)> = Vec::new();
    let mut validated = 0;
    for _ in 0..config.iterations {
        if validated >= config.max_validations {
            break;
        }
        let k = [
            rng.gen_range(0..pairs.len()),
            rng.gen_range(0..pairs.len()),
            rng.gen_range(0..pairs.len()),
        ];
        if k[0] == k[1] || k[1] == k[2] || k[0] == k[2] {
            continue;
        }
        let s = k.map(|k| source.points[pairs[k].0]);
        let t = k.map(|k| target.points[pairs[k].1]);
        // A degenerate (near-collinear or tiny) triangle fixes no rotation.
        if !similar_triangles(&s, &t, config.edge_similarity, 2.0 * config.voxel) {
            continue;
        }
        let Some(fit) = rigid_fit(&s, &t) else {
            continue;
        };
        if s.iter()
            .zip(&t)
            .any(|(a, b)| (fit * a - b).norm_squared() > d2)
        {
            continue;
        }
        // Scored by the frame's points on the model, not the correspondences: in a room most features
        // lie on planes and match at random, so a right pose has few correspondences
        // but puts most of the frame on the model.
        validated += 1;
        let n = on_target(&fit, &subset);
        let worst = best.last().map_or(0.0, |b| b.0);
        if best.len() < config.answers || n > worst {
            // Hypotheses that agree (within a voxel and 5°) are one.
            let same = best.iter().position(|(_, b)| {
                let d = b.inverse() * fit;
                d.translation.vector.norm() < config.voxel && d.rotation.angle() < 0.09
            });
            match same {
                Some(at) if best[at].0 >= n => continue,
                Some(at) => {
                    best.remove(at);
                }
                None => {}
            }
            best.push((n, fit));
            best.sort_by(|a, b| b.0.total_cmp(&a.0));
            best.truncate(config.answers);
        }
    }
    let mut answers: Vec<GlobalMatch> = best
        .into_iter()
        .map(|(_, t)| {
            let inl = inliers_of(&t);
            let (s, g): (Vec<_>, Vec<_>) = inl
                .iter()
                .map(|&(i, j)| (source.points[i], target.points[j]))
                .unzip();
            let t = rigid_fit(&s, &g).unwrap_or(t);
            GlobalMatch {
                transform: t,
                inliers: inliers_of(&t).len(),
                correspondences: pairs.len(),
                fitness: on_target(&t, &source.points),
            }
        })
        .collect();
    answers.sort_by(|a, b| b.fitness.total_cmp(&a.fitness));
    answers
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_clouds_give_no_hypothesis() {
        let config = GlobalConfig::default();
        let empty = FeatureCloud::new(&Cloud::default(), |p| *p, &config);
        assert!(empty.is_empty());
        assert!(register_global(&empty, &empty, &config).is_empty());
    }
}
