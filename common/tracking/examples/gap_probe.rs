//! Probe: at one frame after a gap, what do the candidate registrations and the
//! ground truth score? `gap_probe DATASET FRAME`
use opengs_datasets::{open_dataset, DatasetSpec};
use opengs_gicp::{
    register_coarse_to_fine, sample_depth_grid, Cloud, CoarseToFine, CoarseToFineTarget,
};
use opengs_tracking::{check_visibility, DepthFrame, TrackerConfig, VisibilityMargin};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let spec: DatasetSpec = args.next().ok_or("dataset")?.parse()?;
    let at: usize = args.next().ok_or("frame")?.parse()?;
    let mut src = open_dataset(&spec)?;
    let k = src.intrinsics();
    let cfg = TrackerConfig::tum();
    let cloud = |f: &opengs_datasets::RgbdFrame| -> Result<Cloud, Box<dyn std::error::Error>> {
        let s = sample_depth_grid(
            &f.depth,
            f.depth_scale as f64,
            &k,
            cfg.stride,
            cfg.max_depth,
        )?;
        Ok(Cloud::from_depth_samples(
            &s,
            cfg.neighbours,
            cfg.regularization,
        )?)
    };
    // Model: every 10th frame before `at`, at its true pose.
    let mut model = Cloud::default();
    for i in (0..at).step_by(10) {
        let f = src.frame(i)?;
        let c = cloud(&f)?.transformed(&f.gt_pose.ok_or("gt")?);
        model.points.extend(c.points);
        model.covariances.extend(c.covariances);
    }
    let target = CoarseToFineTarget::new(model.voxel_subsample(0.01), 0.05);
    let prev = src.frame(at - 1)?;
    let f = src.frame(at)?;
    let truth = f.gt_pose.ok_or("gt")?;
    let c = cloud(&f)?;
    let frame = DepthFrame {
        depth: &f.depth,
        depth_scale: f.depth_scale as f64,
        intrinsics: &k,
        timestamp: f.timestamp,
    };
    let starts = [("previous", prev.gt_pose.ok_or("gt")?), ("truth", truth)];
    for (name, start) in starts {
        for (sname, sched) in [
            ("fine", CoarseToFine::fine_only()),
            ("c2f", CoarseToFine::default()),
        ] {
            let r = register_coarse_to_fine(&c, &target, &start, &cfg.registration, &sched)?;
            let e = truth.inverse() * r.transform;
            let seen = check_visibility(
                target.coarse().points(),
                &r.transform,
                &frame,
                &VisibilityMargin::default(),
            );
            println!("{name:8} {sname:4}: err {:5.2} cm {:4.2}° fit {:.4} rmse {:.2} mm error/inlier {:.4} through {:.3} it {}",
                e.translation.vector.norm() * 100.0, e.rotation.angle().to_degrees(), r.fitness, r.inlier_rmse * 1e3,
                r.error / r.inliers as f64, seen.violation_ratio(), r.iterations);
        }
    }
    // Restarts around the coarse-to-fine answer from the previous pose.
    let base = register_coarse_to_fine(
        &c,
        &target,
        &starts[0].1,
        &cfg.registration,
        &CoarseToFine::default(),
    )?
    .transform;
    for (axis, d) in [
        (0, 0.03),
        (0, -0.03),
        (1, 0.03),
        (1, -0.03),
        (2, 0.03),
        (2, -0.03),
    ] {
        let mut t = opengs_geometry::nalgebra::Vector3::zeros();
        t[axis] = d;
        let start = base * opengs_geometry::Pose::translation(t.x, t.y, t.z);
        let r = register_coarse_to_fine(
            &c,
            &target,
            &start,
            &cfg.registration,
            &CoarseToFine::fine_only(),
        )?;
        let e = truth.inverse() * r.transform;
        println!(
            "restart axis {axis} {d:+}: err {:5.2} cm fit {:.4}",
            e.translation.vector.norm() * 100.0,
            r.fitness
        );
    }
    Ok(())
}
