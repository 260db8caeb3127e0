//! Evaluation metrics (docs/METHOD.md §9).

pub mod ate;
pub mod label_png;
pub mod run_dir;
pub mod segmentation;
pub mod trajectory;

pub use ate::{
    absolute_trajectory_error, associate, ate_of_positions, umeyama_rigid, AteError, AteResult,
    DEFAULT_MAX_TIME_DIFFERENCE,
};
pub use label_png::{read_label_png, write_label_png};
pub use run_dir::{write_atomically, RunDir};
pub use segmentation::{InstanceScore, LabelConfusion, SegmentationScore};
pub use trajectory::{
    format_tum_trajectory, parse_tum_trajectory, read_tum_trajectory, write_tum_trajectory,
    TimedPose, TrajectoryError,
};
