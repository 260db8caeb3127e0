//! Tracks a dataset offline (the tracker's own keyframe model, no mapper) and prints the
//! time per frame, the fine iterations and the ATE: a quick look at the tracker alone.
//! `cargo run --release -p opengs-tracking --example track_dataset -- tum:DIR [frames]`
use std::time::Instant;

use opengs_datasets::{open_dataset, DatasetSpec};
use opengs_eval::ate_of_positions;
use opengs_geometry::nalgebra::Point3;
use opengs_tracking::{DepthFrame, FrameTracker, TrackerConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let spec: DatasetSpec = args
        .next()
        .ok_or("usage: track_dataset DATASET [frames]")?
        .parse()?;
    let mut source = open_dataset(&spec)?;
    let frames = match args.next() {
        Some(n) => n.parse::<usize>()?.min(source.len()),
        None => source.len(),
    };
    let k = source.intrinsics();
    let mut tracker = FrameTracker::new(TrackerConfig::for_width(k.width));
    let (mut est, mut gt, mut ms, mut its) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut lost = 0;
    let mut first: Option<opengs_geometry::Pose> = None;
    let mut last_t = f64::NAN;
    for i in 0..frames {
        let f = source.frame(i)?;
        let gap = f.timestamp - last_t;
        last_t = f.timestamp;
        let t0 = Instant::now();
        let out = tracker.track(&DepthFrame {
            depth: &f.depth,
            depth_scale: f.depth_scale as f64,
            intrinsics: &k,
            timestamp: f.timestamp,
        });
        ms.push(t0.elapsed().as_secs_f64() * 1e3);
        its.push(out.iterations as f64);
        if let Some(why) = &out.failure {
            lost += 1;
            println!("frame {i}: {:?} {why}", out.status);
        }
        if let Some(how) = &out.relocalised {
            println!("frame {i}: relocalised from {how}");
        }
        if let (Some(g), true) = (f.gt_pose, out.status.has_pose()) {
            // Error against the ground truth aligned at the first frame.
            let align = *first.get_or_insert(g * out.pose.inverse());
            let err = ((align * out.pose).translation.vector - g.translation.vector).norm();
            if gap > 0.05 || err > 0.02 || (170..180).contains(&i) {
                println!(
                    "frame {i} t {:.2} gap {gap:.2} s: {:?} err {:.1} cm fitness {:.2}",
                    f.timestamp,
                    out.status,
                    err * 100.0,
                    out.fitness
                );
            }
        }
        if out.status.has_pose() {
            if let Some(g) = f.gt_pose {
                est.push(Point3::from(out.pose.translation.vector));
                gt.push(Point3::from(g.translation.vector));
            }
        }
    }
    let pct = |v: &mut Vec<f64>, p: f64| {
        v.sort_by(f64::total_cmp);
        v[((v.len() - 1) as f64 * p) as usize]
    };
    let ate = ate_of_positions(&est, &gt)
        .map(|a| a.rmse * 100.0)
        .unwrap_or(f64::NAN);
    println!(
        "{frames} frames: ms p50 {:.1} p90 {:.1} p99 {:.1} max {:.1}; fine iterations p50 {} p90 {}; lost {lost}; ATE {ate:.3} cm; model {} points",
        pct(&mut ms, 0.5), pct(&mut ms, 0.9), pct(&mut ms, 0.99), pct(&mut ms, 1.0),
        pct(&mut its, 0.5), pct(&mut its, 0.9), tracker.model_size()
    );
    Ok(())
}
