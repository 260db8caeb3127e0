//! End-to-end: a map back-projected from a small synthetic frame renders that frame well,
//! the dataset path matches timestamps and writes PNGs.

use opengs_datasets::RgbdSource;
use opengs_eval::TimedPose;
use opengs_splat::GaussianMap;

use crate::*;

#[path = "../tests/support/small_room.rs"]
mod small_room;
use small_room::{backproject, posed, small_room};

#[test]
fn backprojected_map_renders_its_frame_well() {
    let mut room = small_room();
    let k = room.intrinsics();
    let frames = posed(&mut room, &[0]);
    let map = backproject(&frames[0].0, &frames[0].1, &k);
    let f = &frames[0].0;
    let n = f.depth.len();
    let mean: [f32; 3] = [0, 1, 2].map(|c| {
        f.rgb
            .iter()
            .skip(c)
            .step_by(3)
            .map(|&v| v as f32)
            .sum::<f32>()
            / (255.0 * n as f32)
    });
    let flat = psnr_masked(&vec![mean; n], &f.rgb, &valid_depth_mask(f));
    let r = evaluate_render_quality(&map, frames, k, 1, None).expect("evaluates");
    println!("flat mean-colour image: PSNR {flat:.2} dB");
    println!(
        "same-pose render: PSNR {:.2} dB, SSIM {:.4}",
        r.psnr_db, r.ssim
    );
    assert_eq!(r.frames_evaluated, 1);
    // Measured 19.73 dB / 0.581: one ~pixel-wide Gaussian per pixel (plus the renderer's
    // 0.3 px² dilation) blurs the room's aliased 80×60 textures. A flat image of the mean
    // colour (measured 14.26 dB) is the floor to beat.
    assert!(r.psnr_db > 18.5, "{r:?}");
    assert!(r.ssim > 0.5, "{r:?}");
    assert!(r.psnr_db > flat + 4.0, "{flat} vs {r:?}");
}

#[test]
fn pixels_the_map_leaves_open_are_counted_as_holes() {
    let mut room = small_room();
    let k = room.intrinsics();
    let frames = posed(&mut room, &[0]);
    let (frame, pose) = &frames[0];
    let full = backproject(frame, pose, &k);
    let closed = evaluate_render_quality(&full, frames.clone(), k, 1, None).expect("evaluates");
    assert!(closed.holes_pct < 1.0, "{}", closed.holes_pct);
    // Drop the Gaussians of the left half of the image (columns u < 40 of 80): about half
    // the valid pixels open (a pixel-wide splat also covers its neighbour column).
    let mut half = GaussianMap::new();
    let mut i = 0;
    for v in 0..frame.height {
        for u in 0..frame.width {
            if frame.depth_m(u, v).is_none() {
                continue;
            }
            if u >= 40 {
                half.push(full.get(i));
            }
            i += 1;
        }
    }
    let valid_left = (0..frame.height)
        .flat_map(|v| (0..40).map(move |u| (u, v)))
        .filter(|&(u, v)| frame.depth_m(u, v).is_some())
        .count();
    let valid = frame.depth.iter().filter(|&&d| d != 0).count();
    let expected = 100.0 * valid_left as f64 / valid as f64;
    let r = evaluate_render_quality(&half, frames, k, 1, None).expect("evaluates");
    assert!(
        (r.holes_pct - expected).abs() < 2.5,
        "holes {:.2} % vs left half {expected:.2} %",
        r.holes_pct
    );
}

#[test]
fn dataset_evaluation_matches_trajectory_and_writes_pngs() {
    let mut room = small_room();
    let k = room.intrinsics();
    let f0 = room.frame(0).expect("frame");
    let map = backproject(&f0, &f0.gt_pose.expect("pose"), &k);
    // A trajectory.txt-like list: every frame, timestamps at µs precision, one bogus entry.
    let mut trajectory: Vec<TimedPose> = (0..12)
        .map(|i| {
            let f = room.frame(i).expect("frame");
            TimedPose {
                timestamp: (f.timestamp * 1e6).round() / 1e6,
                pose: f.gt_pose.expect("pose"),
            }
        })
        .collect();
    trajectory[6].timestamp += 0.5 / 30.0; // matches no frame
    let dir = std::env::temp_dir().join(format!("opengs-quality-pngs-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let r =
        evaluate_dataset_quality(&map, &mut room, &trajectory, 2, Some(&dir)).expect("evaluates");
    let indices: Vec<usize> = r.per_frame.iter().map(|q| q.index).collect();
    assert_eq!(indices, vec![0, 2, 4, 8, 10]);
    // PNG slots 0, 2, 3, 5 of the 6 selected poses; slot 3 (frame 6) has no frame.
    assert_eq!(r.pngs.len(), 3);
    let first = image::open(&r.pngs[0]).expect("png");
    assert_eq!((first.width(), first.height()), (4 * 80, 60));
    assert!(r.pngs[0].ends_with("render_000000.png"), "{:?}", r.pngs);
    // Frame 0 (the map's own view) scores best.
    assert!(r.per_frame[0].psnr_db >= r.per_frame[4].psnr_db, "{r:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_frames_are_errors_not_panics() {
    let mut room = small_room();
    let k = room.intrinsics();
    let mut frames = posed(&mut room, &[0]);
    frames[0].0.depth.pop();
    let e =
        evaluate_render_quality(&GaussianMap::new(), frames, k, 1, None).expect_err("short depth");
    assert!(e.to_string().starts_with("frame 0: "), "{e}");
}

#[test]
fn run_directory_evaluation_records_metrics_and_names_missing_files() {
    let mut room = small_room();
    let k = room.intrinsics();
    let dir = std::env::temp_dir().join(format!("opengs-quality-run-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("run dir");
    let e = evaluate_run_quality(&dir, &mut room, 1).expect_err("no map");
    assert!(e.to_string().contains("map.ply"), "{e}");

    let f0 = room.frame(0).expect("frame");
    let map = backproject(&f0, &f0.gt_pose.expect("pose"), &k);
    opengs_splat::write_ply_file(&map, dir.join("map.ply")).expect("write map");
    let poses: Vec<TimedPose> = (0..4)
        .map(|i| {
            let f = room.frame(i).expect("frame");
            TimedPose {
                timestamp: f.timestamp,
                pose: f.gt_pose.expect("pose"),
            }
        })
        .collect();
    opengs_eval::write_tum_trajectory(&dir.join("trajectory.txt"), &poses).expect("write");
    std::fs::write(dir.join("metrics.json"), r#"{"ate_rmse_cm": 0.3}"#).expect("write");
    let r = evaluate_run_quality(&dir, &mut room, 1).expect("evaluates");
    assert_eq!(r.frames_evaluated, 4);
    assert_eq!(r.pngs.len(), 4);
    let text = std::fs::read_to_string(dir.join("metrics.json")).expect("metrics");
    let v: serde_json::Value = serde_json::from_str(&text).expect("json");
    assert_eq!(v["ate_rmse_cm"], 0.3);
    assert!((v["psnr_db"].as_f64().expect("psnr") - r.psnr_db).abs() < 1e-9);
    let text = std::fs::read_to_string(dir.join("quality.json")).expect("quality.json");
    let q: serde_json::Value = serde_json::from_str(&text).expect("json");
    assert_eq!(q["per_frame"].as_array().map(Vec::len), Some(4));

    // No groundtruth.txt: the trajectory evaluation keeps the ATE already there.
    let m = crate::evaluate_run_trajectory(&dir).expect("evaluates");
    assert_eq!((m.frames, m.ate_rmse_cm), (4, None));
    let text = std::fs::read_to_string(dir.join("metrics.json")).expect("metrics");
    let v: serde_json::Value = serde_json::from_str(&text).expect("json");
    assert_eq!(
        (v["ate_rmse_cm"].clone(), v["frames"].clone()),
        (0.3.into(), 4.into())
    );
    assert!(v["ate_mean_cm"].is_null());
    let _ = std::fs::remove_dir_all(&dir);
}
