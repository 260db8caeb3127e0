//! Tracking on a room it was not tuned on (scene 3 of the suite): a 10 cm / 5° jump
//! between frames is recovered, a 6° shake about the camera centre is tracked without
//! the wide search, a frame from elsewhere is lost and grows nothing, and tracking
//! relocalises when the camera comes back after ten lost frames, inline and on the
//! pipeline's relocalisation thread, and when it turns up far from every pose it was
//! tracked at (global registration); a camera lost before ten frames after its start
//! verified starts again where it is.

use opengs_datasets::synthetic::noise::quantize_depth;
use opengs_datasets::synthetic::path::look_at;
use opengs_datasets::synthetic::raycast::render;
use opengs_datasets::synthetic::scene::Scene;
use opengs_datasets::synthetic::scene_suite::room_with_loop;
use opengs_geometry::nalgebra::{Isometry3, Point3, Vector3};
use opengs_geometry::{Intrinsics, Pose};
use opengs_gicp::CoarseToFine;
use opengs_tracking::{DepthFrame, FrameTracker, TrackOutcome, TrackStatus, TrackerConfig};

const FPS: f64 = 30.0;
const DEPTH_SCALE: f32 = 5000.0;

struct Room {
    scene: Scene,
    path: Vec<Pose>,
    k: Intrinsics,
}

fn room() -> Room {
    let r = room_with_loop(3);
    Room {
        path: r.path.poses(200, FPS, 3),
        scene: r.scene,
        k: Intrinsics::new(525.0, 525.0, 319.5, 239.5, 640, 480),
    }
}

impl Room {
    fn depth_at(&self, pose: &Pose) -> Vec<u16> {
        quantize_depth(&render(&self.scene, &self.k, pose).depth, DEPTH_SCALE)
    }

    /// Tracks the frame seen from `pose` at time `t`.
    fn track(&self, tracker: &mut FrameTracker, pose: &Pose, t: f64) -> TrackOutcome {
        let depth = self.depth_at(pose);
        tracker.track(&DepthFrame {
            depth: &depth,
            depth_scale: DEPTH_SCALE as f64,
            intrinsics: &self.k,
            timestamp: t,
        })
    }
}

/// Position error (m) of `out` against `truth`, with the tracker started at the truth.
fn error(out: &TrackOutcome, truth: &Pose) -> f64 {
    (out.pose.translation.vector - truth.translation.vector).norm()
}

/// A tracker started at the path's first pose, run over its first `n` frames; and the
/// last pose it verified.
fn tracked(room: &Room, n: usize) -> (FrameTracker, Pose) {
    tracked_by(FrameTracker::new(TrackerConfig::tum()), room, n)
}

fn tracked_by(mut tracker: FrameTracker, room: &Room, n: usize) -> (FrameTracker, Pose) {
    tracker.set_first_pose(room.path[0]);
    let mut last = room.path[0];
    for (i, pose) in room.path[..n].iter().enumerate() {
        let out = room.track(&mut tracker, pose, i as f64 / FPS);
        assert!(out.status.has_pose(), "frame {i}: {:?}", out.failure);
        assert!(
            error(&out, pose) < 0.005,
            "frame {i}: {:.2} cm",
            error(&out, pose) * 100.0
        );
        last = out.pose;
    }
    (tracker, last)
}

#[test]
fn a_ten_centimetre_five_degree_jump_between_frames_is_recovered() {
    let room = room();
    let n = 15;
    for (axis, direction) in [
        (Vector3::y(), Vector3::new(1.0, 0.0, 0.3)),
        (Vector3::x(), Vector3::new(-0.3, 0.2, 1.0)),
    ] {
        let (mut tracker, _) = tracked(&room, n);
        // The next frame, 10 cm and 5° away from where the path would be.
        let jump = Isometry3::new(direction.normalize() * 0.10, axis * 5f64.to_radians());
        let truth = room.path[n] * jump;
        let out = room.track(&mut tracker, &truth, n as f64 / FPS);
        assert_eq!(out.status, TrackStatus::Tracked, "{:?}", out.failure);
        assert!(
            error(&out, &truth) < 0.005,
            "{:.2} cm off",
            error(&out, &truth) * 100.0
        );
        assert!(out.wide_search.is_some(), "a jump takes the wide search");
    }
}

#[test]
fn a_frame_from_elsewhere_is_lost_adds_no_keyframe_and_the_next_is_tracked() {
    let room = room();
    let n = 20;
    let (mut tracker, last) = tracked(&room, n);
    let model = tracker.model_size();
    // The camera turned 150° and moved 1.2 m within one frame: whatever registration
    // returns, it must not be trusted.
    let elsewhere = room.path[n] * Isometry3::new(Vector3::new(0.8, 0.0, -0.9), Vector3::y() * 2.6);
    let lost = room.track(&mut tracker, &elsewhere, n as f64 / FPS);
    assert_eq!(lost.status, TrackStatus::Lost, "{:?}", lost.failure);
    assert!(lost.keyframe.is_none());
    assert!(lost.failure.is_some());
    // Reported at the last verified pose, not guessed.
    assert_eq!(lost.pose, last);
    assert_eq!(
        tracker.model_size(),
        model,
        "a lost frame adds nothing to the model"
    );
    assert!(tracker.is_lost());
    // Back on the path: relocalised from the last verified pose.
    let back = room.track(&mut tracker, &room.path[n + 1], (n + 5) as f64 / FPS);
    assert_eq!(back.status, TrackStatus::Relocalised, "{:?}", back.failure);
    assert!(error(&back, &room.path[n + 1]) < 0.005);
}

/// Ten frames looking straight at the ceiling from elsewhere after `n` tracked ones: each
/// lost, none guessed, no keyframe, reported at the last verified pose `last`. The time
/// of the last.
fn ten_frames_away(room: &Room, tracker: &mut FrameTracker, n: usize, last: &Pose) -> f64 {
    let away = room.path[n] * Isometry3::new(Vector3::new(0.0, -0.5, 0.0), Vector3::x() * 1.4);
    let mut t = n as f64 / FPS;
    for _ in 0..10 {
        t += 1.0 / FPS;
        let out = room.track(tracker, &away, t);
        assert_eq!(out.status, TrackStatus::Lost, "{:?}", out.failure);
        assert!(out.keyframe.is_none());
        assert_eq!(
            &out.pose, last,
            "a lost frame is reported at the last verified pose"
        );
    }
    t
}

/// The camera back on the path 12 frames further, `pace` between frames: the frame
/// (counted from there) that relocalised and its outcome; every frame before it lost.
fn back_on_the_path(
    room: &Room,
    tracker: &mut FrameTracker,
    n: usize,
    mut t: f64,
    frames: usize,
    pace: std::time::Duration,
) -> (usize, TrackOutcome) {
    for (k, truth) in room.path[n + 12..n + 12 + frames].iter().enumerate() {
        t += 1.0 / FPS;
        std::thread::sleep(pace);
        let out = room.track(tracker, truth, t);
        if out.status == TrackStatus::Relocalised {
            let err = error(&out, truth);
            assert!(err < 0.005, "{:.2} cm off after {k} frames", err * 100.0);
            return (k, out);
        }
        assert_eq!(
            out.status,
            TrackStatus::Lost,
            "frame {k}: {:?}",
            out.failure
        );
    }
    panic!("not relocalised within {frames} frames");
}

#[test]
fn tracking_relocalises_after_ten_lost_frames() {
    let room = room();
    let n = 30;
    let (mut tracker, last) = tracked(&room, n);
    let t = ten_frames_away(&room, &mut tracker, n, &last);
    // Within a few frames (one guess every 0.15 s) a guess verifies on the frame itself.
    let (_, out) = back_on_the_path(&room, &mut tracker, n, t, 12, Default::default());
    assert!(out.wide_search.is_none());
    let how = out.relocalised.as_deref().unwrap_or_default();
    assert!(how.starts_with("a guess "), "{how}");
    assert!(!tracker.is_lost());
}

#[test]
fn the_threaded_tracker_relocalises_from_a_guess_tried_off_the_tracking_path() {
    let room = room();
    let n = 30;
    let threaded = FrameTracker::threaded(TrackerConfig::tum()).expect("threads");
    let (mut tracker, last) = tracked_by(threaded, &room, n);
    let t = ten_frames_away(&room, &mut tracker, n, &last);
    // Frames at the camera's pace, so the thread's answers can arrive.
    let pace = std::time::Duration::from_millis(33);
    let (_, out) = back_on_the_path(&room, &mut tracker, n, t, 60, pace);
    // The guess verified on an earlier frame and was tracked on over the lost frames since
    // (until the view left the map), so this one is tracked from the last of them as from
    // the frame before: no wide search.
    assert_eq!(out.wide_search, None);
    let how = out.relocalised.as_deref().unwrap_or_default();
    assert!(how.starts_with("a guess "), "{how}");
    assert!(how.contains("; tracked on over "), "{how}");
    assert!(how.contains(" s before this frame, "), "{how}");
    assert!(!tracker.is_lost());
}

#[test]
fn a_shake_of_the_camera_is_tracked_without_the_wide_search() {
    let room = room();
    let n = 15;
    // A hand-held camera's prediction is good in position and off in rotation: the frame
    // turned 6° about its own centre from where the path goes.
    let shake = Isometry3::rotation(Vector3::new(1.0, 0.2, 0.0).normalize() * 6f64.to_radians());
    let truth = room.path[n] * shake;
    let shaken = |turned| {
        let mut tracker = FrameTracker::new(TrackerConfig {
            turned,
            ..TrackerConfig::tum()
        });
        tracker.set_first_pose(room.path[0]);
        for (i, pose) in room.path[..n].iter().enumerate() {
            room.track(&mut tracker, pose, i as f64 / FPS);
        }
        room.track(&mut tracker, &truth, n as f64 / FPS)
    };
    let out = shaken(TrackerConfig::tum().turned);
    assert_eq!(out.status, TrackStatus::Tracked, "{:?}", out.failure);
    assert!(
        error(&out, &truth) < 0.005,
        "{:.2} cm off",
        error(&out, &truth) * 100.0
    );
    assert_eq!(out.wide_search, None);
    // Without the turn the fine registration alone fails here and the wide search runs.
    let alone = shaken(CoarseToFine::fine_only());
    assert!(alone.wide_search.is_some(), "{:?}", alone.status);
}

/// The frame after the first, with four dropped between them: no velocity is known yet
/// (as after a restart or a relocalisation), so the prediction is the first pose and the
/// camera moved 7–8 cm from it. A fine answer that verified after sliding there is not
/// taken as it is: from the path's start it stopped 4.8 cm off (fitness and residual
/// passed) until the coarse-to-fine search from the prediction ran again.
#[test]
fn the_second_frame_after_dropped_ones_is_found_without_a_velocity() {
    let room = room();
    for start in [0usize, 40] {
        let mut tracker = FrameTracker::new(TrackerConfig::tum());
        tracker.set_first_pose(room.path[start]);
        room.track(&mut tracker, &room.path[start], start as f64 / FPS);
        let truth = room.path[start + 5];
        let out = room.track(&mut tracker, &truth, (start + 5) as f64 / FPS);
        assert_eq!(out.status, TrackStatus::Tracked, "{:?}", out.failure);
        assert!(
            error(&out, &truth) < 0.001,
            "from frame {start}: {:.2} cm off",
            error(&out, &truth) * 100.0
        );
    }
}

/// The camera 1.2 m and 150° away from the path's frame `n`.
fn far_from(room: &Room, n: usize) -> Pose {
    room.path[n] * Isometry3::new(Vector3::new(0.8, 0.0, -0.9), Vector3::y() * 2.6)
}

#[test]
fn a_camera_lost_before_its_start_stands_starts_again_where_it_is() {
    let room = room();
    let mut tracker = FrameTracker::new(TrackerConfig::tum());
    tracker.set_first_pose(room.path[0]);
    for (i, pose) in room.path[..7].iter().enumerate() {
        let out = room.track(&mut tracker, pose, i as f64 / FPS);
        assert!(out.status.has_pose(), "frame {i}: {:?}", out.failure);
    }
    // Six frames tracked: too few views for a camera to come back to.
    assert!(!tracker.start_stands());
    // The next frame is from halfway round the loop: tracking starts again there, at the
    // pose a start is given (here the truth, as the pipeline gives it with --gt-first-pose).
    let there = room.path[100];
    tracker.set_first_pose(there);
    let t0 = 7.0 / FPS;
    let again = room.track(&mut tracker, &there, t0);
    assert_eq!(again.status, TrackStatus::Initial, "{:?}", again.failure);
    let given_up = again.started_again.as_ref().expect("started again");
    assert_eq!(given_up.given_up, 0);
    assert!(given_up.why.contains("tracking lost"), "{}", given_up.why);
    assert_eq!(again.pose, there);
    assert!(again.keyframe.is_some(), "a new start is a keyframe");
    // Frames from there on are tracked against the new start alone, and after ten of them
    // the start stands.
    for k in 1..=12 {
        let truth = room.path[100 + k];
        let out = room.track(&mut tracker, &truth, t0 + k as f64 / FPS);
        assert_eq!(
            out.status,
            TrackStatus::Tracked,
            "frame {k}: {:?}",
            out.failure
        );
        assert!(out.started_again.is_none());
        assert!(
            error(&out, &truth) < 0.005,
            "frame {k}: {:.2} cm",
            error(&out, &truth) * 100.0
        );
        assert_eq!(tracker.start_stands(), k >= 10, "frame {k}");
    }
    // Once the start stands, a frame that fails is lost, not a new start.
    let lost = room.track(&mut tracker, &far_from(&room, 112), t0 + 13.0 / FPS);
    assert_eq!(lost.status, TrackStatus::Lost, "{:?}", lost.failure);
    assert!(lost.started_again.is_none() && lost.keyframe.is_none());
}

#[test]
fn a_kept_start_is_never_given_up() {
    let room = room();
    let mut tracker = FrameTracker::new(TrackerConfig::tum());
    tracker.set_first_pose(room.path[0]);
    room.track(&mut tracker, &room.path[0], 0.0);
    tracker.keep_start();
    let out = room.track(&mut tracker, &far_from(&room, 0), 1.0 / FPS);
    assert_eq!(out.status, TrackStatus::Lost, "{:?}", out.failure);
    assert!(out.started_again.is_none() && out.keyframe.is_none());
    assert_eq!(out.pose, room.path[0]);
}

/// Whole metres plus radians between two poses (a 10° turn weighs like 17 cm).
fn apart(a: &Pose, b: &Pose) -> f64 {
    let d = a.inverse() * b;
    d.translation.vector.norm() + d.rotation.angle()
}

/// Scene 3's loop for 3 s, then the camera, as after fr2_desk's 12 s gap, somewhere else:
/// from the middle of the arc 0.8 m towards the desk, 0.3 m up and rolled 0.5 rad, drifting
/// 3 mm a frame. Lost frames until the tracker relocalised and its position error then
/// (`None`: not within 30 frames, all lost); and the distance from the teleported camera
/// to the nearest tracked pose.
fn teleport(config: TrackerConfig) -> (Option<(usize, f64, String)>, f64) {
    let r = room_with_loop(3);
    let room = Room {
        path: Vec::new(),
        scene: r.scene,
        k: Intrinsics::new(525.0, 525.0, 319.5, 239.5, 640, 480),
    };
    let before: Vec<f64> = (0..90).map(|i| i as f64 / FPS).collect();
    let mapped = r.path.poses_at(&before, 3);
    let mid = Point3::from(mapped[45].translation.vector);
    let towards = (r.path.target - mid).normalize();
    let teleported: Vec<(Pose, f64)> = (0..30)
        .map(|i| {
            let eye = mid + towards * 0.8 + Vector3::z() * 0.3 + Vector3::x() * 0.003 * i as f64;
            (look_at(&eye, &r.path.target, 0.5), 10.0 + i as f64 / FPS)
        })
        .collect();
    let nearest = mapped
        .iter()
        .map(|m| apart(m, &teleported[0].0))
        .fold(f64::INFINITY, f64::min);
    let mut tracker = FrameTracker::new(config);
    tracker.set_first_pose(mapped[0]);
    for (i, pose) in mapped.iter().enumerate() {
        let out = room.track(&mut tracker, pose, before[i]);
        assert!(out.status.has_pose(), "frame {i}: {:?}", out.failure);
    }
    for (k, (truth, t)) in teleported.iter().enumerate() {
        let out = room.track(&mut tracker, truth, *t);
        if out.status == TrackStatus::Relocalised {
            let how = out.relocalised.clone().unwrap_or_default();
            return (Some((k, error(&out, truth), how)), nearest);
        }
        assert_eq!(
            out.status,
            TrackStatus::Lost,
            "frame {k}: {:?}",
            out.failure
        );
        assert!(out.keyframe.is_none());
    }
    (None, nearest)
}

#[test]
fn a_camera_far_from_every_tracked_pose_is_found_by_global_registration() {
    // Out of reach of the guesses: they try 15 and 30 cm, 12° and 24° around the last pose.
    let mut without = TrackerConfig::tum();
    without.relocalise.global.iterations = 0;
    let (found, nearest) = teleport(without);
    assert!(nearest > 1.0, "{nearest:.2} m + rad from a tracked pose");
    assert_eq!(found, None, "relocalised without global registration");
    let (found, _) = teleport(TrackerConfig::tum());
    let (lost, err, how) = found.expect("relocalised within 30 frames");
    eprintln!(
        "relocalised after {lost} lost frames, {:.2} cm off, {nearest:.2} m + rad from the nearest tracked pose",
        err * 100.0
    );
    assert!(err < 0.005, "{:.2} cm off", err * 100.0);
    // The spell's first attempt (0.15 s in) tries the guesses only; the second, 0.3 s in,
    // global registration too.
    assert!((5..=10).contains(&lost), "{lost}");
    // The log says how: global registration, settled by the surface score.
    assert!(how.starts_with("global registration ("), "{how}");
    assert!(how.contains("settled: "), "{how}");
}
