use nalgebra::{Matrix3, Point3, Rotation3, SymmetricEigen, UnitQuaternion};
use opengs_geometry::{Intrinsics, Pose};
use opengs_gicp::{
    estimate_covariances_on_grid, sample_depth_grid, NeighbourGrid, PointTree, Regularization,
    DEFAULT_NEIGHBOURS,
};
use opengs_splat::{render, Camera, Gaussian, GaussianMap, RenderRequest};

/// A keyframe as the tracker sent it: its points, and its images.
pub struct DensifyInput<'a> {
    /// World-frame points.
    pub points: &'a [[f32; 3]],
    /// World-frame covariances, upper triangle `xx xy xz yy yz zz` (normalised: shape only).
    pub covariances: &'a [[f32; 6]],
    /// Camera-to-world pose of the keyframe (to colour points from its image).
    pub pose: Pose,
    pub intrinsics: Intrinsics,
    /// RGB8 of the keyframe, row-major.
    pub rgb: &'a [u8],
    /// Raw depth of the keyframe, row-major (0 = missing), and its units per metre.
    pub depth: &'a [u16],
    pub depth_scale: f32,
}

/// Where the map leaves a keyframe open (SplaTAM's densification): rendered at the
/// keyframe, a pixel with valid depth is a hole when it accumulates α below
/// `max_silhouette`, or when the map's surface there lies behind the observed one by more
/// than `max(min_depth_error, median_factor × the median depth error)` over the covered
/// samples (SplaTAM's rule: something new in front; the median keeps the blend of
/// foreground and background at object edges from counting).
#[derive(Debug, Clone, PartialEq)]
pub struct HoleFilling {
    /// Depth samples are taken every this many pixels (the tracker's stride).
    pub stride: usize,
    pub max_silhouette: f32,
    pub min_depth_error: f32,
    pub median_factor: f32,
    /// Depth beyond this (m) is not mapped.
    pub max_depth: f64,
}

impl Default for HoleFilling {
    fn default() -> Self {
        Self {
            stride: 5,
            max_silhouette: 0.5,
            min_depth_error: 0.05,
            median_factor: 50.0,
            max_depth: 10.0,
        }
    }
}

/// Neighbours whose mean distance sets a point's size (the local sample spacing).
const SPACING_NEIGHBOURS: usize = 4;
/// Flattest axis relative to the others, so surfaces stay surfaces.
const MIN_AXIS: f64 = 0.1;

/// New Gaussians for the keyframe points that have no map Gaussian within
/// `overlap_distance` (docs/METHOD.md §8): mean = point, shape = the point's covariance,
/// largest axis = `scale` × local sample spacing, colour from the keyframe image.
pub fn gaussians_from_points(
    input: &DensifyInput,
    map_means: &[[f32; 3]],
    overlap_distance: f32,
    opacity: f32,
    scale: f32,
) -> Vec<Gaussian> {
    let d2 = (overlap_distance as f64).powi(2);
    // Only map means that can be within the distance of a point go in the grid, which is
    // built per keyframe: over the whole map it cost more than the rest of densification
    // (scene 5's loop with noise: 30 → 16–22 ms a keyframe; the box holds about half the map).
    // The slack keeps f32 rounding at the box's edge from dropping a mean.
    let (lo, hi) = finite_bounds(input.points, overlap_distance * 1.001);
    let existing: Vec<Point3<f64>> = map_means
        .iter()
        .filter(|m| (0..3).all(|j| m[j] >= lo[j] && m[j] <= hi[j]))
        .map(|m| Point3::new(m[0] as f64, m[1] as f64, m[2] as f64))
        .collect();
    let grid =
        (!existing.is_empty()).then(|| NeighbourGrid::new(&existing, overlap_distance as f64));
    let points: Vec<Point3<f64>> = input
        .points
        .iter()
        .map(|p| Point3::new(p[0] as f64, p[1] as f64, p[2] as f64))
        .collect();
    let tree = PointTree::new(&points);
    let world_to_camera = input.pose.inverse();
    let k = &input.intrinsics;
    let mut out = Vec::new();
    for (i, p) in points.iter().enumerate() {
        if !p.coords.iter().all(|v| v.is_finite()) {
            continue;
        }
        if grid
            .as_ref()
            .is_some_and(|g| g.nearest_within(p, d2).is_some())
        {
            continue;
        }
        let Some(uv) = k.project(&(world_to_camera * p)) else {
            continue;
        };
        let (u, v) = (uv.x.round(), uv.y.round());
        if u < 0.0 || v < 0.0 || u >= k.width as f64 || v >= k.height as f64 {
            continue;
        }
        let px = (v as usize * k.width as usize + u as usize) * 3;
        let Some(c) = input.rgb.get(px..px + 3) else {
            continue;
        };
        let color = [
            c[0] as f32 / 255.0,
            c[1] as f32 / 255.0,
            c[2] as f32 / 255.0,
        ];
        let neighbours = tree.knn(p, SPACING_NEIGHBOURS + 1);
        let spacing = neighbours
            .iter()
            .skip(1)
            .map(|(_, d)| d.sqrt())
            .sum::<f64>()
            / SPACING_NEIGHBOURS as f64;
        let spacing = if spacing.is_finite() && spacing > 0.0 {
            spacing
        } else {
            0.01
        };
        let (rotation, axes) = shape(&input.covariances[i], spacing * scale as f64);
        out.push(Gaussian::from_values(
            [p.x as f32, p.y as f32, p.z as f32],
            rotation,
            axes,
            opacity,
            color,
            0,
        ));
    }
    out
}

/// New Gaussians for the depth samples of a keyframe that `map`, rendered at `camera` (the
/// keyframe's camera at any resolution), leaves open ([`HoleFilling`]): mean = the sample,
/// shape = its grid covariance, largest axis = `scale` × the pixel footprint of the stride.
pub fn gaussians_for_holes(
    input: &DensifyInput,
    map: &GaussianMap,
    camera: &Camera,
    holes: &HoleFilling,
    opacity: f32,
    scale: f32,
) -> Vec<Gaussian> {
    let k = &input.intrinsics;
    let Ok(samples) = sample_depth_grid(
        input.depth,
        input.depth_scale as f64,
        k,
        holes.stride,
        holes.max_depth,
    ) else {
        return Vec::new();
    };
    if samples.points.is_empty() {
        return Vec::new();
    }
    let Ok(covariances) = estimate_covariances_on_grid(
        &samples,
        DEFAULT_NEIGHBOURS,
        Regularization::NormalizedEllipse,
    ) else {
        return Vec::new();
    };
    let out = render(map, camera, &RenderRequest::color_depth()).output;
    let (rw, rh) = (camera.width() as usize, camera.height() as usize);
    let (sx, sy) = (rw as f64 / k.width as f64, rh as f64 / k.height as f64);
    let rotation = input.pose.rotation.to_rotation_matrix().into_inner();
    let render_index = |&(u, v): &(u32, u32)| {
        let ru = ((u as f64 * sx) as usize).min(rw - 1);
        let rv = ((v as f64 * sy) as usize).min(rh - 1);
        rv * rw + ru
    };
    // Rendered minus observed depth where the map covers the sample.
    let errors: Vec<Option<f32>> = samples
        .points
        .iter()
        .zip(&samples.pixels)
        .map(|(p, px)| {
            let i = render_index(px);
            let alpha = out.silhouette[i];
            (alpha >= holes.max_silhouette).then(|| out.depth[i] / alpha - p.z as f32)
        })
        .collect();
    let mut magnitudes: Vec<f32> = errors.iter().flatten().map(|e| e.abs()).collect();
    let median = if magnitudes.is_empty() {
        0.0
    } else {
        let mid = magnitudes.len() / 2;
        *magnitudes.select_nth_unstable_by(mid, f32::total_cmp).1
    };
    let too_far = holes.min_depth_error.max(holes.median_factor * median);
    let mut new = Vec::new();
    for (((p, &(u, v)), cov), error) in samples
        .points
        .iter()
        .zip(&samples.pixels)
        .zip(&covariances)
        .zip(&errors)
    {
        let open = match error {
            None => true,
            Some(e) => *e > too_far,
        };
        if !open {
            continue;
        }
        let px = (v as usize * k.width as usize + u as usize) * 3;
        let Some(c) = input.rgb.get(px..px + 3) else {
            continue;
        };
        let world = input.pose * p;
        let c_world = rotation * cov * rotation.transpose();
        let spacing = holes.stride as f64 * p.z / k.fx;
        let (rot, axes) = shape(
            &[
                c_world[(0, 0)] as f32,
                c_world[(0, 1)] as f32,
                c_world[(0, 2)] as f32,
                c_world[(1, 1)] as f32,
                c_world[(1, 2)] as f32,
                c_world[(2, 2)] as f32,
            ],
            spacing * scale as f64,
        );
        new.push(Gaussian::from_values(
            [world.x as f32, world.y as f32, world.z as f32],
            rot,
            axes,
            opacity,
            [0, 1, 2].map(|j| c[j] as f32 / 255.0),
            0,
        ));
    }
    new
}

/// The box around the finite `points`, grown by `margin` on every side (empty when none is).
fn finite_bounds(points: &[[f32; 3]], margin: f32) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in points.iter().filter(|p| p.iter().all(|v| v.is_finite())) {
        for j in 0..3 {
            lo[j] = lo[j].min(p[j]);
            hi[j] = hi[j].max(p[j]);
        }
    }
    (lo.map(|v| v - margin), hi.map(|v| v + margin))
}

/// Rotation (w, x, y, z) and scales (m) of a Gaussian with the covariance's shape and `spacing` size.
fn shape(cov: &[f32; 6], spacing: f64) -> ([f32; 4], [f32; 3]) {
    let c = cov.map(|v| v as f64);
    let m = Matrix3::new(c[0], c[1], c[2], c[1], c[3], c[4], c[2], c[4], c[5]);
    if !m.iter().all(|v| v.is_finite()) {
        let s = spacing as f32;
        return ([1.0, 0.0, 0.0, 0.0], [s, s, s]);
    }
    let eig = SymmetricEigen::new(m);
    let largest = eig.eigenvalues.max().max(1e-12);
    let mut axes = eig.eigenvectors;
    if axes.determinant() < 0.0 {
        axes.column_mut(2).neg_mut();
    }
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(axes));
    // Relative axis lengths from the covariance, the largest one spacing long.
    let scale = eig
        .eigenvalues
        .map(|l| (spacing * (l.max(0.0) / largest).sqrt().max(MIN_AXIS)) as f32);
    (
        [q.w as f32, q.i as f32, q.j as f32, q.k as f32],
        [scale[0], scale[1], scale[2]],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_covariance_gives_a_flat_disk_of_the_spacing() {
        // A plane z = const: large xx, yy; tiny zz.
        let (q, s) = shape(&[1.0, 0.0, 0.0, 1.0, 0.0, 1e-3], 0.01);
        let mut sorted = s;
        sorted.sort_by(f32::total_cmp);
        assert!((sorted[2] - 0.01).abs() < 1e-6 && (sorted[1] - 0.01).abs() < 1e-6);
        assert!((sorted[0] - 0.001).abs() < 1e-6, "{s:?}");
        // The flat axis is z.
        let rot = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            q[0] as f64,
            q[1] as f64,
            q[2] as f64,
            q[3] as f64,
        ));
        let flat = s
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .map(|(i, _)| i)
            .unwrap_or(0);
        let axis = rot * nalgebra::Vector3::ith(flat, 1.0);
        assert!(axis.z.abs() > 0.999, "{axis:?}");
    }

    #[test]
    fn points_near_the_map_are_skipped_and_colours_come_from_the_image() {
        let k = Intrinsics::new(10.0, 10.0, 1.5, 1.5, 4, 4);
        let rgb: Vec<u8> = (0..16).flat_map(|i| [i as u8 * 10, 0, 255]).collect();
        // Pixel (u, v) = (2, 1) at depth 1 m, camera at the origin looking down +z.
        let p = k.backproject(2.0, 1.0, 1.0);
        let q = k.backproject(1.0, 2.0, 1.0);
        let points = [[p.x as f32, p.y as f32, 1.0], [q.x as f32, q.y as f32, 1.0]];
        let covs = [[1.0, 0.0, 0.0, 1.0, 0.0, 1e-3]; 2];
        let input = DensifyInput {
            points: &points,
            covariances: &covs,
            pose: Pose::identity(),
            intrinsics: k,
            rgb: &rgb,
            depth: &[],
            depth_scale: 1000.0,
        };
        let all = gaussians_from_points(&input, &[], 0.02, 0.1, 1.0);
        assert_eq!(all.len(), 2);
        assert!(
            (all[0].color()[0] - 60.0 / 255.0).abs() < 1e-5,
            "pixel 6 has red 60"
        );
        assert!((all[0].opacity() - 0.1).abs() < 1e-6);
        // The first point already has a Gaussian 1 cm away (outside the points' box, inside
        // the distance): only the second is new.
        let near = [[points[0][0] + 0.01, points[0][1], 1.0]];
        assert!(near[0][0] > points.iter().map(|p| p[0]).fold(f32::MIN, f32::max));
        let new = gaussians_from_points(&input, &near, 0.02, 0.1, 1.0);
        assert_eq!(new.len(), 1);
        assert!((new[0].mean[1] - points[1][1]).abs() < 1e-6);
    }

    /// A 40×30 camera 2 m in front of a wall (depth 2 m everywhere), grey.
    fn wall(k: &Intrinsics) -> (Vec<u16>, Vec<u8>) {
        let n = (k.width * k.height) as usize;
        (vec![2000u16; n], vec![128u8; 3 * n])
    }

    #[test]
    fn holes_are_where_the_render_is_empty_or_behind_the_observed_surface() {
        let k = Intrinsics::new(40.0, 40.0, 19.5, 14.5, 40, 30);
        let (depth, rgb) = wall(&k);
        let input = DensifyInput {
            points: &[],
            covariances: &[],
            pose: Pose::identity(),
            intrinsics: k,
            rgb: &rgb,
            depth: &depth,
            depth_scale: 1000.0,
        };
        let camera = Camera::from_pose(k, &Pose::identity(), 0.05);
        let holes = HoleFilling::default();
        // An empty map: every 5th pixel of the 40×30 frame is a hole (8 × 6 samples).
        let all = gaussians_for_holes(&input, &GaussianMap::new(), &camera, &holes, 0.9, 0.7);
        assert_eq!(all.len(), 48);
        assert!(all.iter().all(|g| (g.mean[2] - 2.0).abs() < 1e-6));
        // Those Gaussians close the wall: nothing left open.
        let mut map = GaussianMap::new();
        all.iter().for_each(|g| map.push(*g));
        assert!(gaussians_for_holes(&input, &map, &camera, &holes, 0.9, 0.7).is_empty());
        // The left three sample columns (x < −0.4 m) mapped 1 m too far (3 m): the frame
        // sees a surface 1 m in front of the map's there, far beyond 50 × the median error
        // (0 on the rest): those 18 samples open (the column beside the right part blends
        // with it and may not), the others not.
        let mut far = GaussianMap::new();
        for g in &all {
            let mut moved = *g;
            if g.mean[0] < -0.4 {
                moved.mean = [g.mean[0] * 1.5, g.mean[1] * 1.5, 3.0];
                moved.log_scale = g.log_scale.map(|l| l + 1.5f32.ln());
            }
            far.push(moved);
        }
        let in_front = gaussians_for_holes(&input, &far, &camera, &holes, 0.9, 0.7);
        assert!((15..=18).contains(&in_front.len()), "{}", in_front.len());
        assert!(in_front.iter().all(|g| g.mean[0] < -0.4));
        // Only the right half mapped (u ≥ 20): the left half's samples (u < 20: 4 of 8
        // columns, 24 samples) open, and at most the column at its edge.
        let mut half = GaussianMap::new();
        all.iter()
            .filter(|g| g.mean[0] > 0.0)
            .for_each(|g| half.push(*g));
        let left = gaussians_for_holes(&input, &half, &camera, &holes, 0.9, 0.7);
        assert!(
            left.iter().all(|g| g.mean[0] < 0.05),
            "{:?}",
            left.iter().map(|g| g.mean[0]).collect::<Vec<_>>()
        );
        assert!((24..=30).contains(&left.len()), "{}", left.len());
    }
}
