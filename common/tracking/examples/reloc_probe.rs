//! Probe: while lost, what do the registration from the truth, global registration's
//! hypotheses and the keyframe guesses score (fitness, the share of the frame the model
//! covers and the fitness over it, how much of the model the frame sees through)?
//! `reloc_probe DATASET [every]`; `NO_GUESSES=1` skips the keyframe guesses.
use opengs_datasets::{open_dataset, DatasetSpec};
use opengs_geometry::Pose;
use opengs_gicp::{
    coarse_estimate, register_coarse_to_fine, register_global, Cloud, CoarseToFine, FeatureCloud,
    GlobalConfig, PointTree,
};
use opengs_tracking::{check_visibility, DepthFrame, FrameTracker, TrackerConfig, TrackingModel};
use std::time::Instant;

struct Stats {
    fit: f64,
    covered: f64,
    fit_covered: f64,
    through: f64,
    err_cm: f64,
    err_deg: f64,
}

/// Pixel coverage of the model at `pose`: per pixel, the nearest model depth (0 = none).
fn model_depth(model: &TrackingModel, pose: &Pose, k: &opengs_geometry::Intrinsics) -> Vec<f64> {
    let (w, h) = (k.width as i64, k.height as i64);
    let mut z = vec![0.0f64; (w * h) as usize];
    let inv = pose.inverse();
    for p in model.target().fine().points() {
        let q = inv * p;
        if q.z <= 0.1 {
            continue;
        }
        let u = (k.fx * q.x / q.z + k.cx).round() as i64;
        let v = (k.fy * q.y / q.z + k.cy).round() as i64;
        let r = ((0.02 * k.fx / q.z) / 2.0).ceil() as i64;
        for y in (v - r).max(0)..=(v + r).min(h - 1) {
            for x in (u - r).max(0)..=(u + r).min(w - 1) {
                let c = &mut z[(y * w + x) as usize];
                if *c == 0.0 || q.z < *c {
                    *c = q.z;
                }
            }
        }
    }
    z
}

fn stats(
    model: &TrackingModel,
    cfg: &TrackerConfig,
    frame: &DepthFrame,
    cloud: &Cloud,
    pose: &Pose,
    truth: &Pose,
) -> Stats {
    let k = frame.intrinsics;
    let z = model_depth(model, pose, k);
    let max_sq = cfg.registration.max_correspondence_distance.powi(2);
    let (mut covered, mut inl, mut inl_cov) = (0usize, 0usize, 0usize);
    for p in &cloud.points {
        let u = (k.fx * p.x / p.z + k.cx).round() as i64;
        let v = (k.fy * p.y / p.z + k.cy).round() as i64;
        let zm = if u >= 0 && v >= 0 && u < k.width as i64 && v < k.height as i64 {
            z[(v * k.width as i64 + u) as usize]
        } else {
            0.0
        };
        let margin = 0.05f64.max(0.04 * p.z);
        let cov = zm > 0.0 && zm <= p.z + margin;
        let w = pose * p;
        let hit = model
            .target()
            .fine()
            .tree()
            .nearest_within(&w, max_sq)
            .is_some();
        covered += cov as usize;
        inl += hit as usize;
        inl_cov += (hit && cov) as usize;
    }
    let seen = check_visibility(
        model.target().coarse().points(),
        pose,
        frame,
        &cfg.relocalise.verify.visibility_margin,
    );
    let e = truth.inverse() * pose;
    let n = cloud.points.len().max(1) as f64;
    Stats {
        fit: inl as f64 / n,
        covered: covered as f64 / n,
        fit_covered: inl_cov as f64 / covered.max(1) as f64,
        through: seen.violation_ratio(),
        err_cm: e.translation.vector.norm() * 100.0,
        err_deg: e.rotation.angle().to_degrees(),
    }
}

fn show(name: &str, s: &Stats) {
    println!(
        "  {name:10} err {:7.2} cm {:6.1}°  fit {:.2}  covered {:.2}  fit|covered {:.2}  through {:.3}",
        s.err_cm, s.err_deg, s.fit, s.covered, s.fit_covered, s.through
    );
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let spec: DatasetSpec = args.next().ok_or("dataset")?.parse()?;
    let every: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(60);
    let mut src = open_dataset(&spec)?;
    let k = src.intrinsics();
    let cfg = TrackerConfig::for_width(k.width);
    let mut tracker = FrameTracker::new(cfg.clone());
    let mut align: Option<Pose> = None;
    let mut keyframes: Vec<Pose> = Vec::new();
    let mut lost_since: Option<usize> = None;
    for i in 0..src.len() {
        let f = src.frame(i)?;
        let frame = DepthFrame {
            depth: &f.depth,
            depth_scale: f.depth_scale as f64,
            intrinsics: &k,
            timestamp: f.timestamp,
        };
        let out = tracker.track(&frame);
        let g = f.gt_pose.ok_or("ground truth")?;
        if out.status.has_pose() {
            align.get_or_insert(g * out.pose.inverse());
            if out.keyframe.is_some() {
                keyframes.push(out.pose);
            }
            if let Some(s) = lost_since.take() {
                println!("frame {i}: {:?} after {} lost", out.status, i - s);
            }
            continue;
        }
        let since = *lost_since.get_or_insert(i);
        if !(i - since).is_multiple_of(every) {
            continue;
        }
        let (Some(a), Some(model), Some(cloud)) = (align, tracker.model(), out.source.as_ref())
        else {
            continue;
        };
        let truth = a.inverse() * g;
        println!("frame {i} (lost {}): {:?}", i - since, out.failure);
        let fine = |start: &Pose, sched: &CoarseToFine| {
            register_coarse_to_fine(cloud, model.target(), start, &cfg.registration, sched)
        };
        show("truth", &stats(model, &cfg, &frame, cloud, &truth, &truth));
        let r = fine(&truth, &CoarseToFine::fine_only())?;
        show(
            "from truth",
            &stats(model, &cfg, &frame, cloud, &r.transform, &truth),
        );
        // Global registration.
        let gc = GlobalConfig::default();
        let t0 = Instant::now();
        let centres: Vec<_> = keyframes
            .iter()
            .map(|k| opengs_geometry::nalgebra::Point3::from(k.translation.vector))
            .collect();
        let ctree = PointTree::new(&centres);
        let tcloud = model.target().fine().cloud();
        let tf = FeatureCloud::new(
            tcloud,
            |p| ctree.nearest(p).map_or(*p, |(j, _)| centres[j]),
            &gc,
        );
        let t1 = Instant::now();
        let sf = FeatureCloud::new(cloud, |_| opengs_geometry::nalgebra::Point3::origin(), &gc);
        let t15 = Instant::now();
        let found = register_global(&sf, &tf, &gc);
        let t2 = Instant::now();
        println!(
            "  global: model {} → {} pts {:.0} ms, frame {} pts {:.0} ms + match {:.0} ms",
            tcloud.len(),
            tf.len(),
            (t1 - t0).as_secs_f64() * 1e3,
            sf.len(),
            (t15 - t1).as_secs_f64() * 1e3,
            (t2 - t15).as_secs_f64() * 1e3
        );
        for g in &found {
            let e = truth.inverse() * g.transform;
            println!(
                "    hyp err {:.2} cm {:.1}° fitness {:.2} inliers {}/{}",
                e.translation.vector.norm() * 100.0,
                e.rotation.angle().to_degrees(),
                g.fitness,
                g.inliers,
                g.correspondences
            );
            let est = coarse_estimate(
                cloud,
                model.target(),
                &g.transform,
                &cfg.registration,
                &cfg.coarse_to_fine,
            );
            let r = fine(&est, &CoarseToFine::fine_only())?;
            show(
                "  refined",
                &stats(model, &cfg, &frame, cloud, &r.transform, &truth),
            );
            let r = fine(&g.transform, &CoarseToFine::fine_only())?;
            show(
                "  fine only",
                &stats(model, &cfg, &frame, cloud, &r.transform, &truth),
            );
        }
        if std::env::var("NO_GUESSES").is_ok() {
            continue;
        }
        // The keyframe guesses, nearest to the truth first: coarse stages, then fine.
        let mut near: Vec<(f64, Pose)> = keyframes
            .iter()
            .map(|p| {
                let d = truth.inverse() * p;
                (d.translation.vector.norm() + d.rotation.angle(), *p)
            })
            .collect();
        near.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut wrong_best: Option<Stats> = None;
        for (j, (d, guess)) in near.iter().take(40).enumerate() {
            let est = coarse_estimate(
                cloud,
                model.target(),
                guess,
                &cfg.registration,
                &cfg.coarse_to_fine,
            );
            let r = fine(&est, &CoarseToFine::fine_only())?;
            let s = stats(model, &cfg, &frame, cloud, &r.transform, &truth);
            if j < 3 {
                println!("  nearest keyframe {j}: {d:.2} (m + rad) from the truth");
                show("its result", &s);
            }
            if s.err_cm < 5.0 {
                show("guess ok", &s);
            } else if s.fit_covered >= 0.7 && s.covered >= 0.2 {
                show("WRONG", &s);
            } else if wrong_best
                .as_ref()
                .is_none_or(|b| s.fit_covered > b.fit_covered)
            {
                wrong_best = Some(s);
            }
        }
        if let Some(s) = wrong_best {
            show("wrong best", &s);
        }
    }
    Ok(())
}
