//! Registration against known rigid transforms of the synthetic room.

use nalgebra::{Isometry3, Point3, Vector3};
use opengs_gicp::synthetic::{tum_camera, RoomScene, DEPTH_UNITS_PER_METRE};
use opengs_gicp::{
    register, sample_depth_grid, Cloud, Gaussian, GicpError, RegistrationConfig, Regularization,
    Solver, Target, DEFAULT_NEIGHBOURS,
};

/// Camera-frame points of the room seen from `pose` on a pixel grid.
fn view(pose: &Isometry3<f64>, stride: usize) -> Vec<Point3<f64>> {
    let cam = tum_camera();
    let depth = RoomScene::default().render_depth(&cam, pose, DEPTH_UNITS_PER_METRE);
    sample_depth_grid(&depth, DEPTH_UNITS_PER_METRE, &cam, stride, 10.0)
        .expect("consistent image")
        .points
}

fn offset(cm: f64, deg: f64) -> Isometry3<f64> {
    let axis = Vector3::new(0.3, -1.0, 0.5).normalize();
    let dir = Vector3::new(1.0, 0.5, -0.7).normalize();
    Isometry3::new(dir * cm / 100.0, axis * deg.to_radians())
}

fn errors(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    let d = a.inverse() * b;
    (d.rotation.angle().to_degrees(), d.translation.vector.norm())
}

/// A known transform of one scene cloud: source = T⁻¹ · target, so the answer is T.
fn recover(
    truth: Isometry3<f64>,
    initial: Isometry3<f64>,
    config: &RegistrationConfig,
) -> (f64, f64, usize) {
    let target_points = view(&Isometry3::identity(), 4);
    let source_points: Vec<_> = target_points.iter().map(|p| truth.inverse() * p).collect();
    let target = Target::from_points(
        target_points,
        DEFAULT_NEIGHBOURS,
        Regularization::NormalizedEllipse,
    )
    .expect("k ≥ 3");
    let source = Cloud::with_covariances(
        source_points,
        DEFAULT_NEIGHBOURS,
        Regularization::NormalizedEllipse,
    )
    .expect("k ≥ 3");
    let result = register(&source, &target, &initial, config).expect("registers");
    assert!(
        result.converged,
        "did not converge in {} iterations",
        result.iterations
    );
    let (rot, trans) = errors(&truth, &result.transform);
    eprintln!(
        "{:?}: {rot:.2e}°, {:.2e} mm, {} iterations",
        config.solver,
        trans * 1e3,
        result.iterations
    );
    (rot, trans, result.iterations)
}

#[test]
fn recovers_a_known_transform_exactly() {
    // Frame-to-frame motion (2 cm, 1°), started from the identity.
    let (rot, trans, _) = recover(
        offset(2.0, 1.0),
        Isometry3::identity(),
        &RegistrationConfig::tum(),
    );
    assert!(rot < 0.05, "rotation error {rot}°");
    assert!(trans < 1e-3, "translation error {trans} m");
}

#[test]
fn converges_from_10cm_5deg_gauss_newton_and_levenberg_marquardt() {
    // A 10 cm offset is beyond the 3 cm tracking radius, so widen it.
    for solver in [Solver::GaussNewton, Solver::LevenbergMarquardt] {
        let config = RegistrationConfig {
            solver,
            max_correspondence_distance: 0.3,
            ..RegistrationConfig::tum()
        };
        let (rot, trans, iterations) = recover(offset(10.0, 5.0), Isometry3::identity(), &config);
        assert!(
            rot < 0.05 && trans < 1e-3,
            "{solver:?}: {rot}°, {trans} m after {iterations} iterations"
        );
    }
}

#[test]
fn registers_two_different_views_of_the_room() {
    // Different viewpoints sample different surface points: no exact answer,
    // but the pose must be within a few mm / tenths of a degree.
    let first = Isometry3::identity();
    let second = offset(3.0, 1.5);
    let target = Target::from_points(
        view(&first, 2),
        DEFAULT_NEIGHBOURS,
        Regularization::NormalizedEllipse,
    )
    .expect("k ≥ 3");
    let source = Cloud::with_covariances(
        view(&second, 5),
        DEFAULT_NEIGHBOURS,
        Regularization::NormalizedEllipse,
    )
    .expect("k ≥ 3");
    let config = RegistrationConfig::tum();
    let result = register(&source, &target, &Isometry3::identity(), &config).expect("registers");
    let (rot, trans) = errors(&second, &result.transform);
    eprintln!(
        "two views: {rot:.3}°, {:.3} mm, overlap {:.3}",
        trans * 1e3,
        result.overlap
    );
    assert!(rot < 0.2 && trans < 5e-3, "{rot}°, {trans} m");
    assert!(result.overlap > 0.7, "overlap {}", result.overlap);
    assert!(result.inlier_rmse < 0.01, "rmse {}", result.inlier_rmse);
}

#[test]
fn points_on_a_line_are_degenerate_not_nan() {
    let line: Vec<_> = (0..200)
        .map(|i| Point3::new(i as f64 * 0.01, 0.0, 1.0))
        .collect();
    let target = Target::from_points(
        line.clone(),
        DEFAULT_NEIGHBOURS,
        Regularization::NormalizedEllipse,
    )
    .expect("k ≥ 3");
    let source =
        Cloud::with_covariances(line, DEFAULT_NEIGHBOURS, Regularization::NormalizedEllipse)
            .expect("k ≥ 3");
    for solver in [Solver::GaussNewton, Solver::LevenbergMarquardt] {
        let config = RegistrationConfig {
            solver,
            ..RegistrationConfig::tum()
        };
        let r = register(&source, &target, &Isometry3::identity(), &config);
        assert!(matches!(r, Err(GicpError::Degenerate(_))), "{r:?}");
    }
}

#[test]
fn empty_and_tiny_clouds_are_errors() {
    let target = Target::from_points(
        view(&Isometry3::identity(), 16),
        DEFAULT_NEIGHBOURS,
        Regularization::Plane,
    )
    .expect("k ≥ 3");
    let config = RegistrationConfig::tum();
    let empty = Cloud::default();
    assert_eq!(
        register(&empty, &target, &Isometry3::identity(), &config),
        Err(GicpError::EmptyCloud { what: "source" })
    );
    let two = Cloud::with_covariances(
        vec![Point3::origin(), Point3::new(1.0, 0.0, 0.0)],
        3,
        Regularization::Plane,
    )
    .expect("k ≥ 3");
    assert!(matches!(
        register(&two, &target, &Isometry3::identity(), &config),
        Err(GicpError::TooFewPoints { found: 2, .. })
    ));
    let empty_target = Target::new(Cloud::default());
    let source =
        Cloud::with_covariances(view(&Isometry3::identity(), 16), 10, Regularization::Plane)
            .expect("k ≥ 3");
    assert_eq!(
        register(&source, &empty_target, &Isometry3::identity(), &config),
        Err(GicpError::EmptyCloud { what: "target" })
    );
}

#[test]
fn far_apart_clouds_have_no_correspondences() {
    let pts = view(&Isometry3::identity(), 16);
    let target = Target::from_points(pts.clone(), 10, Regularization::Plane).expect("k ≥ 3");
    let source = Cloud::with_covariances(pts, 10, Regularization::Plane).expect("k ≥ 3");
    let r = register(
        &source,
        &target,
        &Isometry3::translation(100.0, 0.0, 0.0),
        &RegistrationConfig::tum(),
    );
    assert!(
        matches!(r, Err(GicpError::TooFewCorrespondences { found: 0, .. })),
        "{r:?}"
    );
}

#[test]
fn overlap_fraction_on_a_hand_built_case() {
    // Target: a 10×10 grid (1 cm spacing) at z = 0. Source: the same grid,
    // but the last 3 of its 10 rows lifted by 5 cm, beyond √1e-3 ≈ 3.2 cm.
    // At the identity 70 of 100 points overlap; the solver must not move
    // (a lifted point is also beyond the 2 cm correspondence radius).
    let grid = |lift_from_row: usize| -> Vec<Point3<f64>> {
        (0..100)
            .map(|i| {
                let (r, c) = (i / 10, i % 10);
                let z = if r >= lift_from_row { 0.05 } else { 0.0 };
                Point3::new(c as f64 * 0.01, r as f64 * 0.01, z)
            })
            .collect()
    };
    let flat: Vec<Point3<f64>> = grid(10);
    // Add two perpendicular walls below the grid (z < 0, far from the lifted
    // rows) so the pose is observable.
    let mut target_pts = flat.clone();
    target_pts.extend((0..100).map(|i| {
        Point3::new(
            -0.01,
            (i / 10) as f64 * 0.01,
            -((i % 10) as f64 * 0.01 + 0.01),
        )
    }));
    target_pts.extend((0..100).map(|i| {
        Point3::new(
            (i % 10) as f64 * 0.01,
            -0.01,
            -((i / 10) as f64 * 0.01 + 0.01),
        )
    }));
    let target = Target::from_points(target_pts, 10, Regularization::Plane).expect("k ≥ 3");
    let mut source_pts = grid(7);
    source_pts.extend((0..100).map(|i| {
        Point3::new(
            -0.01,
            (i / 10) as f64 * 0.01,
            -((i % 10) as f64 * 0.01 + 0.01),
        )
    }));
    source_pts.extend((0..100).map(|i| {
        Point3::new(
            (i % 10) as f64 * 0.01,
            -0.01,
            -((i / 10) as f64 * 0.01 + 0.01),
        )
    }));
    let source = Cloud::with_covariances(source_pts, 10, Regularization::Plane).expect("k ≥ 3");
    let r = register(
        &source,
        &target,
        &Isometry3::identity(),
        &RegistrationConfig::tum(),
    )
    .expect("registers");
    // 300 source points: 70 + 100 + 100 overlap, the 30 lifted ones do not.
    assert_eq!(r.inliers, 270);
    assert!(
        (r.overlap - 270.0 / 300.0).abs() < 1e-12,
        "overlap {}",
        r.overlap
    );
    assert!((r.fitness - 0.9).abs() < 1e-12);
}

#[test]
fn registers_against_a_target_built_from_gaussians() {
    // The mapper's Gaussians: one per target point, a flat disc oriented by
    // the point's plane covariance (rotation from its eigenvectors), scale
    // (1 cm, 1 cm, 1 mm).
    let points = view(&Isometry3::identity(), 4);
    let planes =
        opengs_gicp::estimate_covariances(&points, DEFAULT_NEIGHBOURS, Regularization::Plane)
            .expect("k ≥ 3");
    let gaussians: Vec<Gaussian> = points
        .iter()
        .zip(&planes)
        .map(|(p, c)| {
            let eig = nalgebra::SymmetricEigen::new(*c);
            // Order the axes so the smallest eigenvalue (the normal) is z.
            let mut order = [0, 1, 2];
            order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
            let mut axes = nalgebra::Matrix3::from_columns(&[
                eig.eigenvectors.column(order[0]).into_owned(),
                eig.eigenvectors.column(order[1]).into_owned(),
                eig.eigenvectors.column(order[2]).into_owned(),
            ]);
            if axes.determinant() < 0.0 {
                axes.set_column(2, &(-axes.column(2)));
            }
            let q = nalgebra::UnitQuaternion::from_matrix(&axes);
            Gaussian {
                mean: *p,
                rotation: [q.w, q.i, q.j, q.k],
                scale: Vector3::new(0.01, 0.01, 0.001),
            }
        })
        .collect();
    let target = Target::from_gaussians(&gaussians, Regularization::NormalizedEllipse)
        .expect("valid Gaussians");
    let truth = offset(2.0, 1.0);
    let source_points: Vec<_> = points.iter().map(|p| truth.inverse() * p).collect();
    let source = Cloud::with_covariances(
        source_points,
        DEFAULT_NEIGHBOURS,
        Regularization::NormalizedEllipse,
    )
    .expect("k ≥ 3");
    let result = register(
        &source,
        &target,
        &Isometry3::identity(),
        &RegistrationConfig::tum(),
    )
    .expect("registers");
    let (rot, trans) = errors(&truth, &result.transform);
    eprintln!("Gaussian target: {rot:.2e}°, {:.2e} mm", trans * 1e3);
    assert!(rot < 0.05 && trans < 1e-3, "{rot}°, {trans} m");
}

/// Points on an axis-aligned rectangle: `axis` is fixed at `at`, the two others run over
/// `a` and `b` (start, end) in steps of `step`, shifted by `shift` steps.
fn rectangle(
    axis: usize,
    at: f64,
    a: (f64, f64),
    b: (f64, f64),
    step: f64,
    shift: f64,
) -> Vec<Point3<f64>> {
    let (ia, ib) = ((axis + 1) % 3, (axis + 2) % 3);
    let mut points = Vec::new();
    let mut u = a.0 + shift * step;
    while u < a.1 {
        let mut v = b.0 + shift * step;
        while v < b.1 {
            let mut p = Point3::origin();
            p[axis] = at;
            p[ia] = u;
            p[ib] = v;
            points.push(p);
            v += step;
        }
        u += step;
    }
    points
}

#[test]
fn a_thin_boards_new_face_does_not_pull_the_registration() {
    // A room (back wall, floor, side wall) and a 2.5 cm board standing on the floor. The
    // model holds the board's face at x = 0 only; the frame, at the model's own pose, sees
    // its other face at x = 2.5 cm from close by (dense), and not the first one. With
    // correspondences up to 3 cm that face's points pair with the first face and pull
    // the camera along x against the side wall (1.1 cm here); 2 cm leaves them unpaired.
    let room = |step: f64, shift: f64| {
        let mut p = rectangle(2, 3.0, (-1.5, 1.5), (-1.0, 0.8), step, shift);
        p.extend(rectangle(1, 0.8, (1.0, 3.0), (-1.5, 1.5), step, shift));
        p.extend(rectangle(0, -1.5, (-1.0, 0.8), (1.0, 3.0), step, shift));
        p
    };
    let board = |x: f64, shift: f64| rectangle(0, x, (0.3, 0.8), (1.0, 1.6), 0.01, shift);
    let mut model = room(0.02, 0.0);
    model.extend(board(0.0, 0.0));
    let mut frame = room(0.02, 0.5);
    frame.extend(board(0.025, 0.5));
    let target =
        Target::from_points(model, DEFAULT_NEIGHBOURS, Regularization::Plane).expect("k ≥ 3");
    let source =
        Cloud::with_covariances(frame, DEFAULT_NEIGHBOURS, Regularization::Plane).expect("k ≥ 3");
    let slide = |max_correspondence_distance: f64| {
        let config = RegistrationConfig {
            max_correspondence_distance,
            ..RegistrationConfig::tum()
        };
        let r = register(&source, &target, &Isometry3::identity(), &config).expect("registers");
        r.transform.translation.vector.norm() * 100.0
    };
    let (tum, wide) = (
        slide(RegistrationConfig::tum().max_correspondence_distance),
        slide(0.03),
    );
    eprintln!("slide: {tum:.3} cm at the TUM setting, {wide:.3} cm at 3 cm");
    assert!(tum < 0.1, "slid {tum:.3} cm");
    assert!(wide > 1.0, "3 cm correspondences slid only {wide:.3} cm");
}
