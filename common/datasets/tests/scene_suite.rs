//! The scene suite: scene 0 is the fixed room, scenes ≥ 1 are generated
//! around the camera path; the camera clock drops frames instead of freezing.

use std::path::PathBuf;
use std::time::Instant;

use nalgebra::Point3;
use opengs_datasets::synthetic::path::{default_start_pose, fit_start_pose};
use opengs_datasets::synthetic::scene::{indoor_room, Scene, STRUCTURAL_CLASSES};
use opengs_datasets::synthetic::scene_suite::{
    room_around_trajectory, room_with_loop, CAMERA_CLEARANCE, MIN_OBJECTS,
};
use opengs_datasets::trajectory::read_tum_trajectory;
use opengs_datasets::{RgbdSource, SyntheticOptions, SyntheticSource};
use opengs_geometry::Pose;

fn trajectories() -> PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/tum_trajectories")
}

fn fr2_desk() -> PathBuf {
    trajectories().join("fr2_desk_groundtruth.txt")
}

fn fr1_xyz() -> PathBuf {
    trajectories().join("freiburg1_xyz-groundtruth.txt")
}

fn fr2_desk_rows() -> Vec<Pose> {
    read_tum_trajectory(&fr2_desk())
        .expect("fr2_desk")
        .into_iter()
        .map(|(_, p)| p)
        .collect()
}

fn source(options: SyntheticOptions) -> SyntheticSource {
    SyntheticSource::new(options).expect("synthetic source")
}

/// Ids of the room's walls, floor and ceiling.
fn structural_ids(scene: &Scene) -> Vec<u16> {
    scene
        .classes
        .iter()
        .filter(|c| STRUCTURAL_CLASSES.contains(&c.class.as_str()))
        .map(|c| c.id)
        .collect()
}

/// Smallest distance from any centre to any object part's bounds, and
/// whether every centre is inside the room.
fn clearance(scene: &Scene, centres: &[Point3<f64>]) -> (f64, bool) {
    let structural = structural_ids(scene);
    let mut nearest = f64::INFINITY;
    for part in scene
        .parts
        .iter()
        .filter(|p| !structural.contains(&p.instance))
    {
        let (lo, hi) = part.shape.bounds();
        for c in centres {
            let d = nalgebra::Vector3::from_fn(|i, _| (lo[i] - c[i]).max(c[i] - hi[i]).max(0.0));
            nearest = nearest.min(d.norm());
        }
    }
    let (min, max) = (scene.room.min, scene.room.max);
    let inside = centres
        .iter()
        .all(|c| (0..3).all(|i| min[i] < c[i] && c[i] < max[i]));
    (nearest, inside)
}

#[test]
fn scene_zero_is_the_fixed_room() {
    let looped = source(SyntheticOptions {
        frames: Some(3),
        ..SyntheticOptions::default()
    });
    assert_eq!(looped.scene(), &indoor_room());
    assert_eq!(looped.class_table(), indoor_room().classes);
    assert_eq!(
        looped.scene().room_size(),
        nalgebra::Vector3::new(5.0, 4.0, 2.8)
    );
    assert_eq!(looped.timestamps(), &[0.0, 1.0 / 30.0, 2.0 / 30.0]);
    // Today's placement: the path re-centred to start at the default view,
    // shifted just enough to fit the room (fr2_desk is larger than it).
    let rows = read_tum_trajectory(&fr2_desk()).expect("fr2_desk");
    let nearest_per_tick: Vec<Pose> = (0..2981)
        .map(|k| {
            let t = rows[0].0 + k as f64 / 30.0;
            let row = rows
                .iter()
                .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
                .expect("rows");
            row.1
        })
        .collect();
    let margin = nalgebra::Vector3::repeat(0.3);
    let room = indoor_room().room;
    let start = fit_start_pose(
        &nearest_per_tick,
        &(room.min + margin),
        &(room.max - margin),
    );
    let along = source(SyntheticOptions {
        frames: Some(3),
        trajectory: Some(fr2_desk()),
        ..SyntheticOptions::default()
    });
    assert_eq!(along.scene(), &indoor_room());
    let same = |a: &Pose, b: &Pose| (a.to_homogeneous() - b.to_homogeneous()).abs().max() < 1e-12;
    assert!(
        same(&along.poses()[0], &start),
        "{:?} vs {start:?}",
        along.poses()[0]
    );
    assert!((start.rotation.angle_to(&default_start_pose().rotation)).abs() < 1e-12);
    let small = source(SyntheticOptions {
        frames: Some(3),
        trajectory: Some(fr1_xyz()),
        ..SyntheticOptions::default()
    });
    assert!(same(&small.poses()[0], &default_start_pose()));
}

#[test]
fn generated_rooms_hold_many_objects_clear_of_every_camera() {
    let rows = fr2_desk_rows();
    for seed in 1..=6 {
        let start = Instant::now();
        let fitted = room_around_trajectory(seed, &rows);
        let elapsed = start.elapsed().as_secs_f64();
        let scene = &fitted.scene;
        let centres: Vec<Point3<f64>> = rows
            .iter()
            .map(|p| Point3::from(p.translation.vector + fitted.shift))
            .collect();
        let (nearest, inside) = clearance(scene, &centres);
        let size = scene.room_size();
        eprintln!(
            "fr2_desk scene {seed}: {} objects, room {:.2}×{:.2}×{:.2} m, nearest object {nearest:.3} m, {elapsed:.3} s",
            scene.object_count(),
            size.x,
            size.y,
            size.z
        );
        assert!(scene.object_count() >= MIN_OBJECTS, "scene {seed}");
        assert!(inside, "scene {seed}: the camera leaves the room");
        assert!(nearest >= CAMERA_CLEARANCE, "scene {seed}: {nearest} m");
        assert!(elapsed < 1.0, "scene {seed} took {elapsed} s");
        // Walls 1–2.2 m beyond the path's box; the floor below the camera.
        let lowest = centres.iter().map(|c| c.z).fold(f64::MAX, f64::min);
        assert!(
            lowest > 1.0 && size.z >= 2.4 && size.z <= 3.2,
            "{lowest} {size:?}"
        );
        for c in STRUCTURAL_CLASSES {
            assert!(scene.classes.iter().any(|k| k.class == c));
        }
        // The source shows the same room with the trajectory moved the same way.
        let src = source(SyntheticOptions {
            scene: seed,
            trajectory: Some(fr2_desk()),
            frames: Some(2),
            ..SyntheticOptions::default()
        });
        assert_eq!(src.scene(), scene);
        assert_eq!(src.poses()[0].translation.vector, centres[0].coords);
        assert_eq!(src.poses()[0].rotation, rows[0].rotation);

        // The generated loop, for two jitter seeds.
        let looped = room_with_loop(seed);
        for jitter in [0, 7] {
            let src = source(SyntheticOptions {
                scene: seed,
                seed: jitter,
                ..SyntheticOptions::default()
            });
            assert_eq!(src.scene(), &looped.scene);
            let centres: Vec<Point3<f64>> = src
                .poses()
                .iter()
                .map(|p| Point3::from(p.translation.vector))
                .collect();
            let (nearest, inside) = clearance(&looped.scene, &centres);
            assert!(
                inside && nearest >= CAMERA_CLEARANCE,
                "loop {seed}/{jitter}: {nearest}"
            );
        }
        let size = looped.scene.room_size();
        eprintln!(
            "loop scene {seed}: {} objects, room {:.2}×{:.2}×{:.2} m",
            looped.scene.object_count(),
            size.x,
            size.y,
            size.z
        );
        assert!(looped.scene.object_count() >= MIN_OBJECTS, "loop {seed}");
        assert!(size.x >= 4.0 && size.y >= 3.5, "loop {seed}: {size:?}");
    }
}

/// Union of each object instance's part bounds, with its class.
fn object_bounds(scene: &Scene) -> Vec<(String, Point3<f64>, Point3<f64>)> {
    let structural = structural_ids(scene);
    scene
        .classes
        .iter()
        .filter(|c| !structural.contains(&c.id))
        .map(|c| {
            let (lo, hi) = scene
                .parts
                .iter()
                .filter(|p| p.instance == c.id)
                .map(|p| p.shape.bounds())
                .fold(
                    (Point3::from([f64::MAX; 3]), Point3::from([f64::MIN; 3])),
                    |(a, b), (lo, hi)| (a.inf(&lo), b.sup(&hi)),
                );
            (c.class.clone(), lo, hi)
        })
        .collect()
}

#[test]
fn rooms_hold_small_thin_and_stacked_objects() {
    let rows = fr2_desk_rows();
    for seed in 1..=6 {
        for (kind, scene) in [
            ("fr2_desk", room_around_trajectory(seed, &rows).scene),
            ("loop", room_with_loop(seed).scene),
        ] {
            let objects = object_bounds(&scene);
            let extent = |lo: &Point3<f64>, hi: &Point3<f64>| hi - lo;
            let small = objects
                .iter()
                .filter(|(_, lo, hi)| extent(lo, hi).max() <= 0.10)
                .count();
            let thin = objects
                .iter()
                .filter(|(_, lo, hi)| extent(lo, hi).min() <= 0.02)
                .count();
            // One object resting on another that is not the table.
            let stacked = objects.iter().any(|(_, lo, hi)| {
                objects.iter().any(|(class, blo, bhi)| {
                    class != "table"
                        && (lo.z - bhi.z).abs() < 1e-9
                        && lo.x < bhi.x
                        && blo.x < hi.x
                        && lo.y < bhi.y
                        && blo.y < hi.y
                })
            });
            let on_floor = objects
                .iter()
                .filter(|(_, lo, _)| lo.z.abs() < 1e-9)
                .count();
            eprintln!("{kind} {seed}: {small} small, {thin} thin, {on_floor} on the floor");
            assert!(small >= 1 && thin >= 1 && stacked, "{kind} {seed}");
            assert!(on_floor >= 4, "{kind} {seed}: {on_floor} on the floor");
        }
    }
}

#[test]
fn same_seed_same_scene_other_seed_other_scene() {
    let rows = fr2_desk_rows();
    assert_eq!(
        room_around_trajectory(3, &rows),
        room_around_trajectory(3, &rows)
    );
    assert_ne!(
        room_around_trajectory(3, &rows).scene,
        room_around_trajectory(4, &rows).scene
    );
    assert_eq!(room_with_loop(5), room_with_loop(5));
    assert_ne!(room_with_loop(5).scene, room_with_loop(6).scene);
    // A window of the trajectory sees the room of the whole loop.
    let whole = source(SyntheticOptions {
        scene: 2,
        trajectory: Some(fr2_desk()),
        frames: Some(1),
        ..SyntheticOptions::default()
    });
    let window = source(SyntheticOptions {
        scene: 2,
        trajectory: Some(fr2_desk()),
        start_s: 50.0,
        speed: 2,
        drop_rate: 0.3,
        ..SyntheticOptions::default()
    });
    assert_eq!(whole.scene(), window.scene());
}

/// Share of pixels on objects and with valid depth, over some frames of a source.
fn coverage(src: &mut SyntheticSource, frames: &[usize]) -> Vec<(f64, f64)> {
    let structural = structural_ids(src.scene());
    frames
        .iter()
        .map(|&i| {
            let f = src.frame(i).expect("frame");
            let labels = f.labels.unwrap_or_default();
            let n = labels.len() as f64;
            let objects = labels.iter().filter(|l| !structural.contains(l)).count() as f64;
            let valid = f.depth.iter().filter(|&&d| d > 0).count() as f64;
            (objects / n, valid / n)
        })
        .collect()
}

#[test]
fn objects_fill_the_views_along_fr2_desk() {
    for seed in [1, 2] {
        let mut src = source(SyntheticOptions {
            scene: seed,
            trajectory: Some(fr2_desk()),
            ..SyntheticOptions::default()
        });
        let n = src.len();
        let picks = [n / 10, n * 4 / 10, n * 7 / 10];
        for (i, (objects, valid)) in picks.iter().zip(coverage(&mut src, &picks)) {
            eprintln!("scene {seed} frame {i}: {objects:.3} on objects, {valid:.3} valid depth");
            assert!(
                objects >= 0.10,
                "scene {seed} frame {i}: {objects} on objects"
            );
            assert!(valid >= 0.90, "scene {seed} frame {i}: {valid} valid depth");
        }
    }
    let mut looped = source(SyntheticOptions {
        scene: 3,
        ..SyntheticOptions::default()
    });
    for (objects, valid) in coverage(&mut looped, &[0, 300]) {
        assert!(objects >= 0.10 && valid >= 0.999, "{objects} {valid}");
    }
}

#[test]
fn fr2_desk_clock_drops_frames_and_keeps_its_long_gap() {
    let src = source(SyntheticOptions {
        trajectory: Some(fr2_desk()),
        ..SyntheticOptions::default()
    });
    let fps = 30.0;
    // 99.4 s on a 30 Hz clock is 2981 ticks; the mocap gaps take 718 of them.
    assert_eq!(src.len(), 2263);
    assert!(src.len() < (99.0 * fps) as usize);
    let long: Vec<_> = src.gaps().iter().filter(|g| g.missing_s > 5.0).collect();
    assert_eq!(long.len(), 1, "{:?}", src.gaps());
    let g = long[0];
    assert!((11.5..12.5).contains(&g.missing_s), "{g:?}");
    let t = src.timestamps();
    // The gap starts at about 31.7 s and its first frame comes ~12 s later.
    assert!((31.6..31.8).contains(&t[g.frame - 1]), "{}", t[g.frame - 1]);
    assert!((g.time_s - t[g.frame]).abs() < 1e-12);
    assert!((t[g.frame] - t[g.frame - 1] - (g.dropped + 1) as f64 / fps).abs() < 1e-9);
    // Timestamps always increase; every jump is a listed gap.
    for (i, w) in t.windows(2).enumerate() {
        let ticks = ((w[1] - w[0]) * fps).round() as usize;
        assert!(ticks >= 1);
        if ticks > 1 {
            assert!(src
                .gaps()
                .iter()
                .any(|g| g.frame == i + 1 && g.dropped == ticks - 1));
        }
    }
    let over_a_second = src.gaps().iter().filter(|g| g.missing_s > 1.0).count();
    assert_eq!(over_a_second, 5, "{:?}", src.gaps());
    assert_eq!(src.dropped_frames(), 2981 - 2263);
}

#[test]
fn stress_options_give_the_expected_counts() {
    let fps = 30.0;
    // Drops: 300 frames in blocks of 5, a fifth of the blocks go.
    let dropped = source(SyntheticOptions {
        scene: 1,
        frames: Some(300),
        drop_rate: 0.2,
        drop_burst: 5,
        ..SyntheticOptions::default()
    });
    assert_eq!(dropped.len(), 240);
    assert!(dropped.gaps().iter().all(|g| g.dropped % 5 == 0));
    let full = source(SyntheticOptions {
        scene: 1,
        frames: Some(300),
        ..SyntheticOptions::default()
    });
    for (pose, t) in dropped.poses().iter().zip(dropped.timestamps()) {
        let k = (t * fps).round() as usize;
        assert_eq!(pose, &full.poses()[k], "a kept frame keeps its tick's pose");
    }

    // Speed: every third tick, re-timed at 30 Hz.
    let base = source(SyntheticOptions {
        trajectory: Some(fr1_xyz()),
        ..SyntheticOptions::default()
    });
    assert_eq!(base.len(), 901);
    let fast = source(SyntheticOptions {
        trajectory: Some(fr1_xyz()),
        speed: 3,
        ..SyntheticOptions::default()
    });
    assert!((298..=302).contains(&fast.len()), "{}", fast.len());
    assert!((fast.timestamps()[100] - 100.0 / fps).abs() < 1e-9);
    assert_eq!(fast.poses()[100], base.poses()[300]);

    // Window: from 10 s on, the same poses as the whole run from there.
    let late = source(SyntheticOptions {
        trajectory: Some(fr1_xyz()),
        start_s: 10.0,
        ..SyntheticOptions::default()
    });
    assert!((late.timestamps()[0] - 10.0).abs() < 1e-9);
    assert_eq!(late.len(), 901 - 300);
    assert_eq!(late.poses()[0], base.poses()[300]);
    // `frames` still caps the count.
    let capped = source(SyntheticOptions {
        trajectory: Some(fr1_xyz()),
        start_s: 10.0,
        frames: Some(50),
        ..SyntheticOptions::default()
    });
    assert_eq!(capped.len(), 50);

    // The loop: a window and speed sample the same loop further on.
    let loop_fast = source(SyntheticOptions {
        start_s: 2.0,
        speed: 2,
        frames: Some(100),
        ..SyntheticOptions::default()
    });
    let loop_base = source(SyntheticOptions {
        frames: Some(400),
        ..SyntheticOptions::default()
    });
    assert_eq!(loop_fast.len(), 100);
    assert_eq!(loop_fast.poses()[10], loop_base.poses()[60 + 20]);
    assert!((loop_fast.timestamps()[10] - 70.0 / fps).abs() < 1e-9);
}

#[test]
fn bad_stress_options_name_their_flag() {
    let message = |o: SyntheticOptions| match SyntheticSource::new(o) {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    };
    let cases = [
        (
            SyntheticOptions {
                drop_rate: 1.0,
                ..SyntheticOptions::default()
            },
            "--drop-frames",
        ),
        (
            SyntheticOptions {
                drop_rate: -0.1,
                ..SyntheticOptions::default()
            },
            "--drop-frames",
        ),
        (
            SyntheticOptions {
                drop_burst: 0,
                ..SyntheticOptions::default()
            },
            "--drop-burst",
        ),
        (
            SyntheticOptions {
                speed: 0,
                ..SyntheticOptions::default()
            },
            "--speed",
        ),
        (
            SyntheticOptions {
                start_s: -1.0,
                ..SyntheticOptions::default()
            },
            "--start",
        ),
        (
            SyntheticOptions {
                trajectory: Some(fr1_xyz()),
                start_s: 40.0,
                ..SyntheticOptions::default()
            },
            "past the end",
        ),
    ];
    for (options, expected) in cases {
        let e = message(options);
        assert!(e.contains(expected), "{e}");
    }
}
