//! Global registration against a known pose of the synthetic room: a view 1.16 m from every
//! view the model was built from, where G-ICP from the nearest of them does not arrive.

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use opengs_gicp::synthetic::{tum_camera, RoomScene, DEPTH_UNITS_PER_METRE};
use opengs_gicp::{
    register, register_global, sample_depth_grid, Cloud, FeatureCloud, GlobalConfig,
    RegistrationConfig, Regularization, Target, DEFAULT_NEIGHBOURS,
};

fn yaw(degrees: f64) -> UnitQuaternion<f64> {
    // The room's y points down: a turn about y pans the camera.
    UnitQuaternion::from_axis_angle(&Vector3::y_axis(), degrees.to_radians())
}

/// The room seen from `pose`, in the camera frame.
fn view(pose: &Isometry3<f64>) -> Cloud {
    let cam = tum_camera();
    let depth = RoomScene::default().render_depth(&cam, pose, DEPTH_UNITS_PER_METRE);
    let samples =
        sample_depth_grid(&depth, DEPTH_UNITS_PER_METRE, &cam, 4, 10.0).expect("consistent image");
    Cloud::from_depth_samples(&samples, DEFAULT_NEIGHBOURS, Regularization::Plane)
        .expect("enough samples")
}

#[test]
fn a_view_far_from_every_model_view_registers_from_a_global_hypothesis() {
    // The model: three views from the room's centre, panned −40°, 0° and 40°.
    let mut model = Cloud::default();
    for angle in [-40.0, 0.0, 40.0] {
        let pose = Isometry3::from_parts(Vector3::zeros().into(), yaw(angle));
        let world = view(&pose).transformed(&pose);
        model.points.extend(world.points);
        model.covariances.extend(world.covariances);
    }
    let config = GlobalConfig::default();
    let target = FeatureCloud::new(&model, |_| Point3::origin(), &config);
    // The frame: from 0.5 m right, 0.3 m up and 1 m forward, panned −50° and rolled 23°,
    // looking at the table block and the spheres.
    let truth = Isometry3::from_parts(
        Vector3::new(0.5, -0.3, 1.0).into(),
        yaw(-50.0) * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.4),
    );
    let frame = view(&truth);
    let source = FeatureCloud::new(&frame, |_| Point3::origin(), &config);
    let found = register_global(&source, &target, &config);
    assert!(!found.is_empty());
    // Hypotheses are starting points: G-ICP from each, the best fitness kept.
    let target_cloud = Target::new(model.voxel_subsample(0.01));
    let registration = RegistrationConfig::default();
    let mut best: Option<(f64, Isometry3<f64>, Isometry3<f64>)> = None;
    for h in &found {
        let r = register(&frame, &target_cloud, &h.transform, &registration).expect("registers");
        if best.as_ref().is_none_or(|b| r.fitness > b.0) {
            best = Some((r.fitness, h.transform, r.transform));
        }
    }
    let (fitness, start, end) = best.expect("a registration");
    let (from, to) = (truth.inverse() * start, truth.inverse() * end);
    eprintln!(
        "{} hypotheses; the one that registered best started {:.1} cm {:.2}° off, ended {:.2} mm {:.3}° off at fitness {fitness:.2}",
        found.len(),
        from.translation.vector.norm() * 100.0,
        from.rotation.angle().to_degrees(),
        to.translation.vector.norm() * 1e3,
        to.rotation.angle().to_degrees(),
    );
    // G-ICP from the nearest model view ends elsewhere.
    let nearest = Isometry3::from_parts(Vector3::zeros().into(), yaw(-40.0));
    let alone = register(&frame, &target_cloud, &nearest, &registration).expect("registers");
    let off = truth.inverse() * alone.transform;
    assert!(off.translation.vector.norm() > 0.1, "{off}");
    assert!(from.translation.vector.norm() < 0.2 && from.rotation.angle() < 5f64.to_radians());
    assert!(to.translation.vector.norm() < 0.002 && to.rotation.angle() < 0.2f64.to_radians());
}
