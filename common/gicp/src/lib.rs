//! Generalized-ICP registration (docs/METHOD.md §7), laid out like small_gicp:
//! one concern per file, each reading like the maths it implements.
//!
//! Pipeline of the tracker:
//! 1. [`sample_depth_grid`] back-projects a depth image on a pixel grid,
//! 2. [`Cloud::from_depth_samples`] estimates per-point covariances from the
//!    k nearest neighbours within a 5×5 grid window (fast), or
//!    [`Cloud::with_covariances`] from a kd-tree kNN (any cloud), both
//!    regularised by a [`Regularization`],
//! 3. [`Target`] holds the map side (points or Gaussians, a kd-tree and a
//!    hashed [`NeighbourGrid`] for fast radius-bounded correspondences),
//!    and grows with [`Target::add_transformed`] at keyframes,
//! 4. [`register`] runs Gauss-Newton or Levenberg-Marquardt on SE(3) and
//!    reports the pose, fit statistics and the keyframe overlap fraction;
//!    [`register_coarse_to_fine`] runs it wide on a coarse [`CoarseToFineTarget`]
//!    first, so jumps of 10 cm and 5° between frames converge,
//! 5. [`register_global`] finds a cloud in a model with no guess ([`fpfh`] features
//!    and RANSAC), for relocalisation far from anywhere the tracker has been.
//!
//! Threads: everything parallel runs on the current rayon pool; wrap calls
//! in `pool.install(..)` of a local `rayon::ThreadPool` to bound them.
//!
//! Conventions: `transform` maps source coordinates into target
//! coordinates (`p_t ≈ T · p_s`); updates are left perturbations
//! `T ← [exp(ω) | v] · T` (see [`lie`]).

pub mod bench;
mod cloud;
pub mod cloud_io;
mod coarse_to_fine;
mod config;
mod covariance;
mod error;
pub mod factor;
mod fpfh;
mod global;
mod grid_covariance;
mod kdtree;
pub mod lie;
mod neighbour_grid;
mod optimizer;
mod points;
pub mod synthetic;
mod target;
mod voxel;

pub use cloud::Cloud;
pub use coarse_to_fine::{
    coarse_estimate, register_coarse_to_fine, CoarseToFine, CoarseToFineTarget, Stage,
};
pub use config::{RegistrationConfig, Solver};
pub use covariance::{
    covariance_from_gaussian, estimate_covariances, regularize, Regularization, DEFAULT_NEIGHBOURS,
};
pub use error::GicpError;
pub use fpfh::{fpfh, least_spread_direction, oriented_normals, Fpfh, FPFH_LEN};
pub use global::{register_global, FeatureCloud, GlobalConfig, GlobalMatch};
pub use grid_covariance::estimate_covariances_on_grid;
pub use kdtree::PointTree;
pub use neighbour_grid::NeighbourGrid;
pub use optimizer::{register, Registration};
pub use points::{sample_depth_grid, DepthSamples};
pub use target::{Gaussian, Target, DEFAULT_SEARCH_RADIUS};
pub use voxel::voxel_downsample;

pub use nalgebra;
pub use nalgebra::{Isometry3, Matrix3, Point3};
pub use rayon;
