//! `opengs bench gicp`: median registration time of a TUM-size frame
//! (640×480, stride 5, ~12k points) against a ~100k-point synthetic room,
//! with 1 and 2 threads, plus tracking throughput over a short sequence.

use anyhow::Context;
use opengs_gicp::bench::{bench_pair, sequence_fps, time_registration};
use opengs_gicp::cloud_io::write_xyz;
use opengs_gicp::{Cloud, RegistrationConfig, Regularization, Solver, Target, DEFAULT_NEIGHBOURS};
use opengs_pipeline::cli_values::at_least_one;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Debug, clap::Args)]
pub struct BenchGicpArgs {
    /// Registrations per setting (the median is printed).
    #[arg(long, default_value_t = 21, value_parser = at_least_one)]
    pub repeats: usize,
    /// Frames in the throughput sequence.
    #[arg(long, default_value_t = 30, value_parser = at_least_one)]
    pub frames: usize,
    /// Thread counts to time.
    #[arg(long, value_delimiter = ',', default_value = "1,2", value_parser = at_least_one)]
    pub threads: Vec<usize>,
    /// Also time with small_gicp's plane covariances (the setting that
    /// scripts/compare_small_gicp.py reproduces).
    #[arg(long)]
    pub plane: bool,
    /// Write the clouds and settings here (for scripts/compare_small_gicp.py).
    #[arg(long)]
    pub dump: Option<PathBuf>,
}

fn dump(
    dir: &PathBuf,
    pair: &opengs_gicp::bench::BenchPair,
    config: &RegistrationConfig,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    write_xyz(&dir.join("source.xyz"), &pair.source)?;
    write_xyz(&dir.join("target.xyz"), &pair.target)?;
    let row_major = |m: opengs_gicp::nalgebra::Matrix4<f64>| -> String {
        (0..16)
            .map(|i| format!("{:.12}", m[(i / 4, i % 4)]))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let settings = format!(
        "neighbours {DEFAULT_NEIGHBOURS}\nmax_correspondence_distance {}\nmax_iterations {}\nrotation_epsilon {}\ntranslation_epsilon {}\ninit {}\ntruth {}\n",
        config.max_correspondence_distance,
        config.max_iterations,
        config.rotation_epsilon,
        config.translation_epsilon,
        row_major(pair.initial.to_homogeneous()),
        row_major(pair.truth.to_homogeneous()),
    );
    std::fs::write(dir.join("settings.txt"), settings)
        .with_context(|| format!("cannot write {}", dir.display()))?;
    println!(
        "wrote source.xyz, target.xyz, settings.txt to {}",
        dir.display()
    );
    Ok(())
}

pub fn run(args: BenchGicpArgs) -> anyhow::Result<()> {
    let pair = bench_pair()?;
    println!(
        "source {} points (640×480, stride 5), target {} points",
        pair.source.len(),
        pair.target.len()
    );
    if let Some(dir) = &args.dump {
        dump(dir, &pair, &RegistrationConfig::tum())?;
    }
    let mut regularizations = vec![("ellipse", Regularization::NormalizedEllipse)];
    if args.plane {
        regularizations.push(("plane", Regularization::Plane));
    }
    for (name, regularization) in regularizations {
        let start = Instant::now();
        let target = Target::from_points(pair.target.clone(), DEFAULT_NEIGHBOURS, regularization)?;
        println!(
            "[{name}] target covariances (kd-tree kNN) + search grid: {:.1} ms",
            start.elapsed().as_secs_f64() * 1e3
        );
        // What the tracker pays per keyframe: appending a frame and rebuilding the grid.
        let mut grown = Target::new(target.cloud().clone());
        let keyframe =
            Cloud::from_depth_samples(&pair.source_samples, DEFAULT_NEIGHBOURS, regularization)?;
        let start = Instant::now();
        grown.add_transformed(&keyframe, &pair.truth);
        println!(
            "[{name}] keyframe add ({} + {} points): {:.1} ms",
            target.len(),
            keyframe.len(),
            start.elapsed().as_secs_f64() * 1e3
        );
        for (solver_name, solver) in [
            ("GN", Solver::GaussNewton),
            ("LM", Solver::LevenbergMarquardt),
        ] {
            let config = RegistrationConfig {
                solver,
                ..RegistrationConfig::tum()
            };
            for &threads in &args.threads {
                let t = time_registration(
                    &pair,
                    &target,
                    regularization,
                    &config,
                    threads,
                    args.repeats,
                )?;
                let error_mm =
                    (t.result.transform.translation.vector - pair.truth.translation.vector).norm()
                        * 1e3;
                println!(
                    "[{name}] {solver_name} {threads} thread(s): registration median {:.2} ms wall, {} CPU ({} iterations), source covariances {:.2} ms (kd-tree) / {:.2} ms (grid), error {:.2} mm, overlap {:.3}",
                    t.registration_ms,
                    t.registration_cpu_ms.map_or("n/a".to_string(), |c| format!("{c:.2} ms")),
                    t.result.iterations, t.covariance_ms, t.grid_covariance_ms, error_mm, t.result.overlap
                );
            }
        }
        let config = RegistrationConfig::tum();
        for &threads in &args.threads {
            let (fps, worst) =
                sequence_fps(&target, regularization, &config, threads, args.frames)?;
            println!(
                "[{name}] GN {threads} thread(s): tracking {fps:.1} frames/s over {} frames (sample + grid covariances + register), worst position error {:.2} mm",
                args.frames,
                worst * 1e3
            );
        }
    }
    Ok(())
}
