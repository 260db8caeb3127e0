//! Tracking the synthetic room along a real hand-held TUM trajectory.

use std::path::PathBuf;

use opengs_datasets::{open_dataset, DatasetSpec, DepthNoise};
use opengs_eval::ate_of_positions;
use opengs_geometry::nalgebra::Point3;
use opengs_tracking::{FrameTracker, TrackStatus, TrackerConfig};

fn fr1_xyz() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/tum_trajectories/freiburg1_xyz-groundtruth.txt")
}

/// Tracks `frames` frames; returns ATE RMSE (m) and the statuses.
fn track(frames: usize, noise: bool) -> (f64, Vec<TrackStatus>) {
    let mut spec: DatasetSpec = "synthetic".parse().expect("spec");
    spec.synthetic.trajectory = Some(fr1_xyz());
    spec.synthetic.frames = Some(frames);
    spec.synthetic.noise = noise.then(DepthNoise::default);
    let mut source = open_dataset(&spec).expect("dataset");
    let k = source.intrinsics();
    let mut tracker = FrameTracker::new(TrackerConfig::tum());
    let (mut est, mut gt, mut statuses) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..frames {
        let f = source.frame(i).expect("frame");
        let out = tracker.track(&f.depth, f.depth_scale as f64, &k);
        est.push(Point3::from(out.pose.translation.vector));
        gt.push(Point3::from(
            f.gt_pose
                .expect("synthetic has ground truth")
                .translation
                .vector,
        ));
        statuses.push(out.status);
    }
    let rmse = ate_of_positions(&est, &gt).expect("ate").rmse;
    eprintln!(
        "{frames} frames, noise {noise}: ATE RMSE {:.3} cm",
        rmse * 100.0
    );
    (rmse, statuses)
}

#[test]
fn noise_free_room_tracks_under_one_centimetre() {
    let (rmse, statuses) = track(90, false);
    assert_eq!(statuses[0], TrackStatus::Initial);
    let failures = statuses
        .iter()
        .filter(|s| !matches!(s, TrackStatus::Tracked | TrackStatus::Initial))
        .count();
    assert!(failures <= 2, "{failures} frames failed: {statuses:?}");
    assert!(rmse < 0.01, "ATE RMSE {:.2} cm", rmse * 100.0);
}

#[test]
fn kinect_noise_tracks_under_three_centimetres() {
    let (rmse, _) = track(90, true);
    assert!(rmse < 0.03, "ATE RMSE {:.2} cm", rmse * 100.0);
}

#[test]
fn frames_without_depth_fall_back_to_constant_velocity() {
    let mut spec: DatasetSpec = "synthetic".parse().expect("spec");
    spec.synthetic.frames = Some(5);
    let mut source = open_dataset(&spec).expect("dataset");
    let k = source.intrinsics();
    let mut tracker = FrameTracker::new(TrackerConfig::tum());
    let f0 = source.frame(0).expect("frame");
    let f1 = source.frame(1).expect("frame");
    let first = tracker.track(&f0.depth, f0.depth_scale as f64, &k);
    let second = tracker.track(&f1.depth, f1.depth_scale as f64, &k);
    assert_eq!(second.status, TrackStatus::Tracked);
    let empty = vec![0u16; f0.depth.len()];
    let blind = tracker.track(&empty, f0.depth_scale as f64, &k);
    assert_eq!(blind.status, TrackStatus::NoDepth);
    // The guess repeats the last motion: pose₂ = pose₁ · (pose₀⁻¹ · pose₁).
    let expected = second.pose * (first.pose.inverse() * second.pose);
    assert!((blind.pose.translation.vector - expected.translation.vector).norm() < 1e-9);
    assert!(blind.pose.translation.vector.iter().all(|v| v.is_finite()));
    // Wrong-size depth is a failure, not a panic.
    let bad = tracker.track(&empty[..10], f0.depth_scale as f64, &k);
    assert_ne!(bad.status, TrackStatus::Tracked);
}
