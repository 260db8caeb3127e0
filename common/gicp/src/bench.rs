//! The fixed registration workload behind `opengs bench gicp`: a TUM-size
//! frame (640×480, stride 5, ~12k points) against a ~100k-point target of
//! the synthetic room, timed on local thread pools.

use crate::synthetic::{tum_camera, RoomScene, DEPTH_UNITS_PER_METRE};
use crate::{
    register, sample_depth_grid, voxel_downsample, Cloud, DepthSamples, GicpError, Registration,
    RegistrationConfig, Regularization, Target, DEFAULT_NEIGHBOURS,
};
use nalgebra::{Isometry3, Point3, Vector3};
use std::time::Instant;

/// Source sampling stride (docs/METHOD.md §7, TUM-size images).
pub const SOURCE_STRIDE: usize = 5;
/// Depths beyond this are ignored (metres).
pub const MAX_DEPTH: f64 = 10.0;

/// Small camera motion: `cm` centimetres and `deg` degrees about fixed axes.
pub fn small_motion(cm: f64, deg: f64) -> Isometry3<f64> {
    let axis = Vector3::new(0.2, 1.0, -0.3).normalize();
    let direction = Vector3::new(1.0, -0.3, 0.4).normalize();
    Isometry3::new(direction * cm / 100.0, axis * deg.to_radians())
}

/// Camera-frame samples of the room seen from `pose` on a pixel grid.
pub fn view(
    scene: &RoomScene,
    pose: &Isometry3<f64>,
    stride: usize,
) -> Result<DepthSamples, GicpError> {
    let camera = tum_camera();
    let depth = scene.render_depth(&camera, pose, DEPTH_UNITS_PER_METRE);
    sample_depth_grid(&depth, DEPTH_UNITS_PER_METRE, &camera, stride, MAX_DEPTH)
}

/// The bench's clouds: source in its camera frame, target in the world frame.
pub struct BenchPair {
    pub source: Vec<Point3<f64>>,
    /// The source with its pixel grid (for grid-window covariances).
    pub source_samples: DepthSamples,
    pub target: Vec<Point3<f64>>,
    /// Source → target transform that generated the pair.
    pub truth: Isometry3<f64>,
    /// Where registration starts (the previous frame's pose: identity).
    pub initial: Isometry3<f64>,
}

/// Target: two stride-2 views, voxelised at 1.2 cm (~100k points).
/// Source: a stride-5 view 2 cm / 1° away.
pub fn bench_pair() -> Result<BenchPair, GicpError> {
    let scene = RoomScene::default();
    let mut target = Vec::new();
    for pose in [Isometry3::identity(), small_motion(-15.0, -6.0)] {
        target.extend(view(&scene, &pose, 2)?.points.into_iter().map(|p| pose * p));
    }
    let target = voxel_downsample(&target, 0.012);
    let truth = small_motion(2.0, 1.0);
    let source_samples = view(&scene, &truth, SOURCE_STRIDE)?;
    Ok(BenchPair {
        source: source_samples.points.clone(),
        source_samples,
        target,
        truth,
        initial: Isometry3::identity(),
    })
}

/// Median of some timings.
pub fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    match values.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => values[n / 2],
        n => 0.5 * (values[n / 2 - 1] + values[n / 2]),
    }
}

/// Timings of one setting.
pub struct Timing {
    /// Source covariances by kd-tree kNN.
    pub covariance_ms: f64,
    /// Source covariances by kNN in the 5×5 grid window (tracker path).
    pub grid_covariance_ms: f64,
    pub registration_ms: f64,
    /// Process CPU time per registration (all threads), from /proc; robust
    /// to other processes competing for the cores. `None` off Linux.
    pub registration_cpu_ms: Option<f64>,
    pub result: Registration,
}

/// Median time of source covariance estimation and of registration alone
/// (target prepared once), on a pool of `threads` threads.
pub fn time_registration(
    pair: &BenchPair,
    target: &Target,
    regularization: Regularization,
    config: &RegistrationConfig,
    threads: usize,
    repeats: usize,
) -> Result<Timing, GicpError> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| GicpError::Invalid(format!("thread pool: {e}")))?;
    pool.install(|| {
        let repeats = repeats.max(1);
        let mut cov_ms = Vec::new();
        let mut grid_ms = Vec::new();
        for _ in 0..repeats {
            let start = Instant::now();
            let _ =
                Cloud::with_covariances(pair.source.clone(), DEFAULT_NEIGHBOURS, regularization)?;
            cov_ms.push(start.elapsed().as_secs_f64() * 1e3);
            let start = Instant::now();
            let _ = Cloud::from_depth_samples(
                &pair.source_samples,
                DEFAULT_NEIGHBOURS,
                regularization,
            )?;
            grid_ms.push(start.elapsed().as_secs_f64() * 1e3);
        }
        let source =
            Cloud::with_covariances(pair.source.clone(), DEFAULT_NEIGHBOURS, regularization)?;
        let mut reg_ms = Vec::new();
        let mut result = register(&source, target, &pair.initial, config)?;
        let cpu_start = process_cpu_seconds();
        for _ in 0..repeats {
            let start = Instant::now();
            result = register(&source, target, &pair.initial, config)?;
            reg_ms.push(start.elapsed().as_secs_f64() * 1e3);
        }
        let cpu_ms = cpu_start
            .zip(process_cpu_seconds())
            .map(|(a, b)| (b - a) * 1e3 / repeats as f64);
        Ok(Timing {
            covariance_ms: median(&mut cov_ms),
            grid_covariance_ms: median(&mut grid_ms),
            registration_ms: median(&mut reg_ms),
            registration_cpu_ms: cpu_ms,
            result,
        })
    })
}

/// User + system CPU seconds of this process (Linux /proc, 100 ticks/s).
pub fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name; utime and stime are 14 and 15.
    let after_name = stat.rsplit_once(')')?.1;
    let fields: Vec<&str> = after_name.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

/// Tracking throughput over a short sequence of small motions: per frame,
/// depth sampling + grid-window covariances + registration from the previous pose
/// (rendering excluded). Returns (frames per second, worst pose error in m).
pub fn sequence_fps(
    target: &Target,
    regularization: Regularization,
    config: &RegistrationConfig,
    threads: usize,
    frames: usize,
) -> Result<(f64, f64), GicpError> {
    let scene = RoomScene::default();
    let camera = tum_camera();
    let poses: Vec<Isometry3<f64>> = (0..frames)
        .map(|i| small_motion(0.5 * i as f64, 0.25 * i as f64))
        .collect();
    let depths: Vec<Vec<u16>> = poses
        .iter()
        .map(|p| scene.render_depth(&camera, p, DEPTH_UNITS_PER_METRE))
        .collect();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| GicpError::Invalid(format!("thread pool: {e}")))?;
    pool.install(|| {
        let mut pose = Isometry3::identity();
        let mut worst: f64 = 0.0;
        let start = Instant::now();
        for (depth, truth) in depths.iter().zip(&poses) {
            let samples = sample_depth_grid(
                depth,
                DEPTH_UNITS_PER_METRE,
                &camera,
                SOURCE_STRIDE,
                MAX_DEPTH,
            )?;
            let source = Cloud::from_depth_samples(&samples, DEFAULT_NEIGHBOURS, regularization)?;
            pose = register(&source, target, &pose, config)?.transform;
            worst = worst.max((pose.translation.vector - truth.translation.vector).norm());
        }
        Ok((frames as f64 / start.elapsed().as_secs_f64(), worst))
    })
}
