//! Probe: which jumps between two frames does registration survive, and what
//! do the verification statistics look like for right and wrong answers?
//! `cargo run --release -p opengs-tracking --example jump_probe [fine]`
use opengs_datasets::synthetic::{noise::quantize_depth, raycast::render, scene::indoor_room};
use opengs_datasets::{open_dataset, DatasetSpec};
use opengs_geometry::nalgebra::{Isometry3, Vector3};
use opengs_gicp::{
    register_coarse_to_fine, sample_depth_grid, Cloud, CoarseToFine, CoarseToFineTarget,
};
use opengs_tracking::{check_visibility, DepthFrame, TrackerConfig, VisibilityMargin};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let fine_only = std::env::args().nth(1).as_deref() == Some("fine");
    let schedule = if fine_only {
        CoarseToFine::fine_only()
    } else {
        CoarseToFine::default()
    };
    let mut spec: DatasetSpec = "synthetic".parse()?;
    spec.synthetic.frames = Some(600);
    let mut src = open_dataset(&spec)?;
    let k = src.intrinsics();
    let cfg = TrackerConfig::tum();
    let cloud = |depth: &[u16], scale: f64| -> Result<Cloud, Box<dyn std::error::Error>> {
        let s = sample_depth_grid(depth, scale, &k, cfg.stride, cfg.max_depth)?;
        Ok(Cloud::from_depth_samples(
            &s,
            cfg.neighbours,
            cfg.regularization,
        )?)
    };
    let scene = indoor_room();
    let (mut right, mut total) = (0, 0);
    for base in [0usize, 150, 300, 450] {
        let f0 = src.frame(base)?;
        let p0 = f0.gt_pose.ok_or("no pose")?;
        let mut model = cloud(&f0.depth, f0.depth_scale as f64)?.transformed(&p0);
        for j in [base + 10, base + 20] {
            let f = src.frame(j)?;
            let c =
                cloud(&f.depth, f.depth_scale as f64)?.transformed(&f.gt_pose.ok_or("no pose")?);
            model.points.extend(c.points);
            model.covariances.extend(c.covariances);
        }
        let target = CoarseToFineTarget::new(model, schedule.coarse_voxel);
        for (cm, deg) in [
            (2.0f64, 1.0f64),
            (5.0, 2.5),
            (10.0, 5.0),
            (15.0, 7.0),
            (25.0, 5.0),
            (40.0, 4.0),
        ] {
            for dir in 0..3 {
                let axis = [
                    Vector3::new(0.2, 1.0, -0.3),
                    Vector3::new(1.0, 0.1, 0.2),
                    Vector3::new(-0.3, 0.3, 1.0),
                ][dir]
                    .normalize();
                let tdir = [
                    Vector3::new(1.0, -0.3, 0.4),
                    Vector3::new(-0.2, 0.1, 1.0),
                    Vector3::new(0.3, 1.0, 0.0),
                ][dir]
                    .normalize();
                let truth = p0 * Isometry3::new(tdir * cm / 100.0, axis * deg.to_radians());
                let view = render(&scene, &k, &truth);
                let depth = quantize_depth(&view.depth, 5000.0);
                let c = cloud(&depth, 5000.0)?;
                let t0 = std::time::Instant::now();
                let r = register_coarse_to_fine(&c, &target, &p0, &cfg.registration, &schedule);
                let ms = t0.elapsed().as_secs_f64() * 1e3;
                total += 1;
                match r {
                    Ok(r) => {
                        let e = truth.inverse() * r.transform;
                        let ok = e.translation.vector.norm() < 0.005;
                        let frame = DepthFrame {
                            depth: &depth,
                            depth_scale: 5000.0,
                            intrinsics: &k,
                            timestamp: 0.0,
                        };
                        let seen = check_visibility(
                            target.coarse().points(),
                            &r.transform,
                            &frame,
                            &VisibilityMargin::default(),
                        );
                        right += ok as usize;
                        println!("{} base {base:3} {cm:4.0} cm {deg:3.0}° dir {dir}: err {:6.2} cm {:5.2}° fit {:.2} rmse {:.2} cm cond {:.1e} through {:.2} it {:2} {ms:5.1} ms",
                            if ok { "ok " } else { "BAD" }, e.translation.vector.norm() * 100.0, e.rotation.angle().to_degrees(),
                            r.fitness, r.inlier_rmse * 100.0, r.conditioning, seen.violation_ratio(), r.iterations);
                    }
                    Err(e) => println!("ERR base {base} {cm} cm {deg}° dir {dir}: {e}"),
                }
            }
        }
    }
    println!("{right} of {total} within 0.5 cm");
    Ok(())
}
