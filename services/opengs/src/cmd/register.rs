//! `opengs register SOURCE TARGET`: stand-alone G-ICP of two point clouds.

use anyhow::{bail, Context};
use opengs_gicp::cloud_io::read_cloud;
use opengs_gicp::{
    register, voxel_downsample, Cloud, Isometry3, RegistrationConfig, Regularization, Solver,
    Target,
};
use opengs_pipeline::cli_values::{at_least_one, at_least_three, positive};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum SolverArg {
    /// Gauss-Newton.
    Gn,
    /// Levenberg-Marquardt.
    Lm,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum CovarianceArg {
    /// GS-ICP's normalised ellipse (docs/METHOD.md §7).
    Ellipse,
    /// small_gicp's plane: eigenvalues (1, 1, 1e-3).
    Plane,
}

/// Registers SOURCE onto TARGET (PLY or `x y z` text) and prints the
/// source → target transform.
#[derive(Debug, clap::Args)]
pub struct RegisterArgs {
    /// Cloud to move (.ply or x y z text).
    pub source: PathBuf,
    /// Cloud to align to (.ply or x y z text).
    pub target: PathBuf,
    /// Initial source → target transform: 16 numbers, row-major.
    #[arg(long)]
    pub init: Option<String>,
    /// Voxel-downsample both clouds with this voxel size (metres, > 0) first.
    #[arg(long, value_parser = positive)]
    pub voxel: Option<f64>,
    /// Worker threads (≥ 1; default: all cores).
    #[arg(long, value_parser = at_least_one)]
    pub threads: Option<usize>,
    /// Maximum correspondence distance (metres, > 0).
    #[arg(long, default_value_t = 0.03, value_parser = positive)]
    pub max_corr: f64,
    /// Gauss-Newton or Levenberg-Marquardt.
    #[arg(long, value_enum, default_value = "gn")]
    pub solver: SolverArg,
    /// How neighbourhood covariances are regularised.
    #[arg(long, value_enum, default_value = "ellipse")]
    pub covariance: CovarianceArg,
    /// Neighbours per covariance (≥ 3).
    #[arg(long, default_value_t = opengs_gicp::DEFAULT_NEIGHBOURS, value_parser = at_least_three)]
    pub neighbours: usize,
}

/// Parses "16 numbers row-major" into a rigid transform.
fn parse_init(text: &str) -> anyhow::Result<Isometry3<f64>> {
    let values: Vec<f64> = text
        .split(|c: char| c.is_whitespace() || c == ',')
        .filter(|t| !t.is_empty())
        .map(|t| {
            t.parse::<f64>()
                .with_context(|| format!("--init: '{t}' is not a number"))
        })
        .collect::<anyhow::Result<_>>()?;
    if values.len() != 16 {
        bail!(
            "--init needs 16 numbers (a row-major 4×4 matrix), got {}",
            values.len()
        );
    }
    let m = opengs_gicp::nalgebra::Matrix4::from_row_slice(&values);
    opengs_gicp::lie::isometry_from_matrix(&m).context("--init is not a rigid transform")
}

pub fn run(args: RegisterArgs) -> anyhow::Result<()> {
    let initial = match &args.init {
        Some(text) => parse_init(text)?,
        None => Isometry3::identity(),
    };
    let mut source_points = read_cloud(&args.source)?;
    let mut target_points = read_cloud(&args.target)?;
    if let Some(voxel) = args.voxel {
        source_points = voxel_downsample(&source_points, voxel);
        target_points = voxel_downsample(&target_points, voxel);
    }
    let regularization = match args.covariance {
        CovarianceArg::Ellipse => Regularization::NormalizedEllipse,
        CovarianceArg::Plane => Regularization::Plane,
    };
    let config = RegistrationConfig {
        solver: match args.solver {
            SolverArg::Gn => Solver::GaussNewton,
            SolverArg::Lm => Solver::LevenbergMarquardt,
        },
        max_correspondence_distance: args.max_corr,
        ..RegistrationConfig::tum()
    };
    let mut pool = opengs_gicp::rayon::ThreadPoolBuilder::new();
    if let Some(n) = args.threads {
        pool = pool.num_threads(n);
    }
    let pool = pool.build().context("cannot start the worker threads")?;
    let (n_source, n_target) = (source_points.len(), target_points.len());
    let (result, elapsed) = pool.install(|| -> anyhow::Result<_> {
        let start = Instant::now();
        let target = Target::from_points(target_points, args.neighbours, regularization)
            .with_context(|| format!("target {}", args.target.display()))?;
        let source = Cloud::with_covariances(source_points, args.neighbours, regularization)
            .with_context(|| format!("source {}", args.source.display()))?;
        let result = register(&source, &target, &initial, &config).with_context(|| {
            format!(
                "registering {} onto {}",
                args.source.display(),
                args.target.display()
            )
        })?;
        Ok((result, start.elapsed()))
    })?;
    let m = result.transform.to_homogeneous();
    println!("source {n_source} points, target {n_target} points");
    println!("transform (source → target):");
    for r in 0..4 {
        println!(
            "  {:>12.8} {:>12.8} {:>12.8} {:>12.8}",
            m[(r, 0)],
            m[(r, 1)],
            m[(r, 2)],
            m[(r, 3)]
        );
    }
    println!(
        "fitness {:.4} ({} inliers), inlier RMSE {:.5} m, overlap {:.4}",
        result.fitness, result.inliers, result.inlier_rmse, result.overlap
    );
    println!(
        "iterations {} ({}), time {:.2} ms (covariances + registration)",
        result.iterations,
        if result.converged {
            "converged"
        } else {
            "not converged"
        },
        elapsed.as_secs_f64() * 1e3
    );
    Ok(())
}
