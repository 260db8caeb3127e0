//! Probe: does the view after a teleport determine the pose? The tracker alone maps up to
//! the teleport frame; then, for every `every`-th later frame, the fine registration from
//! the truth and restarts 3 cm either way along its two weakest translations, each with its
//! distance from the truth, fitness and surface score ([`opengs_tracking::surface_fitness`]),
//! then the global registration's pick. The figures behind `SettleConfig`'s defaults.
//! `ambiguity_probe DATASET TELEPORT_FRAME [every] [until]`
use opengs_datasets::{open_dataset, DatasetSpec};
use opengs_geometry::nalgebra::Point3;
use opengs_geometry::Pose;
use opengs_gicp::{
    coarse_estimate, register_coarse_to_fine, register_global, CoarseToFine, FeatureCloud,
    GlobalConfig, PointTree, Registration,
};
use opengs_tracking::{
    check_visibility, restarts, surface_fitness, DepthFrame, FrameTracker, TrackerConfig,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let spec: DatasetSpec = args.next().ok_or("dataset")?.parse()?;
    let teleport: usize = args.next().ok_or("teleport frame")?.parse()?;
    let every: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(10);
    let until: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(1000);
    let mut src = open_dataset(&spec)?;
    let k = src.intrinsics();
    let cfg = TrackerConfig::for_width(k.width);
    let settle = &cfg.relocalise.settle;
    let mut tracker = FrameTracker::new(cfg.clone());
    let mut align: Option<Pose> = None;
    let mut keyframes: Vec<Point3<f64>> = Vec::new();
    for i in 0..teleport.min(src.len()) {
        let f = src.frame(i)?;
        let out = tracker.track(&DepthFrame {
            depth: &f.depth,
            depth_scale: f.depth_scale as f64,
            intrinsics: &k,
            timestamp: f.timestamp,
        });
        if out.status.has_pose() {
            align.get_or_insert(f.gt_pose.ok_or("ground truth")? * out.pose.inverse());
            if out.keyframe.is_some() {
                keyframes.push(Point3::from(out.pose.translation.vector));
            }
        }
    }
    let (Some(model), Some(align)) = (tracker.model(), align) else {
        return Err("nothing tracked before the teleport".into());
    };
    let target = model.target().fine();
    let reach = cfg.registration.max_correspondence_distance;
    let gc = GlobalConfig::default();
    let tree = PointTree::new(&keyframes);
    let features = FeatureCloud::new(
        target.cloud(),
        |p| tree.nearest(p).map_or(*p, |(j, _)| keyframes[j]),
        &gc,
    );
    for i in (teleport..until.min(src.len())).step_by(every.max(1)) {
        let f = src.frame(i)?;
        let frame = DepthFrame {
            depth: &f.depth,
            depth_scale: f.depth_scale as f64,
            intrinsics: &k,
            timestamp: f.timestamp,
        };
        // The tracker's own source cloud (`Err`: too few samples).
        let Ok((cloud, _)) = tracker.source_cloud(&frame) else {
            continue;
        };
        let truth = align.inverse() * f.gt_pose.ok_or("ground truth")?;
        let fine = |start: &Pose| {
            register_coarse_to_fine(
                &cloud,
                model.target(),
                start,
                &cfg.registration,
                &CoarseToFine::fine_only(),
            )
        };
        let through = |p: &Pose| {
            check_visibility(
                model.target().coarse().points(),
                p,
                &frame,
                &cfg.relocalise.verify.visibility_margin,
            )
            .violation_ratio()
        };
        let line = |what: &str, r: &Registration| {
            println!(
                "  {what:8} {:5.2} cm from the truth  fitness {:.3}  surface {:.3}",
                (truth.inverse() * r.transform).translation.vector.norm() * 100.0,
                r.fitness,
                surface_fitness(target, &cloud, &r.transform, reach, settle.tolerance)
            )
        };
        let restarts = |r: &Registration| {
            for start in restarts(&r.transform, &r.hessian, settle.step) {
                if let Ok(q) = fine(&start) {
                    line("restart", &q);
                }
            }
        };
        println!("frame {i}:");
        let r = fine(&truth)?;
        line("truth →", &r);
        restarts(&r);
        let source = FeatureCloud::new(&cloud, |_| Point3::origin(), &gc);
        let mut best: Option<Registration> = None;
        for h in register_global(&source, &features, &gc) {
            let coarse = coarse_estimate(
                &cloud,
                model.target(),
                &h.transform,
                &cfg.registration,
                &cfg.coarse_to_fine,
            );
            for start in [h.transform, coarse] {
                let Ok(r) = fine(&start) else { continue };
                let passes = r.fitness >= cfg.relocalise.global_verify.min_fitness
                    && through(&r.transform) <= cfg.relocalise.global_verify.max_violation;
                if passes && best.as_ref().is_none_or(|b| r.fitness > b.fitness) {
                    best = Some(r);
                }
            }
        }
        match best {
            Some(b) => {
                line("global", &b);
                restarts(&b);
            }
            None => println!("  global: no hypothesis passes"),
        }
    }
    Ok(())
}
