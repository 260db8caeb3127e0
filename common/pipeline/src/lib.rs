//! Pipeline glue with no algorithm in it: deploy files, the supervisor that
//! starts, watches, restarts and stops stage processes, the sensor loop, and
//! the run recorder. Stage binaries in `services/` call into this crate.

pub mod consensus_stage;
pub mod dataset_args;
pub mod deploy;
pub mod final_optimisation;
pub mod logging;
pub mod mapper_stage;
pub mod metrics;
pub mod recorder;
pub mod segmenter_stage;
pub mod semantic_eval;
pub mod sensor;
pub mod stage_main;
pub mod stage_process;
pub mod status;
pub mod supervisor;
pub mod tracker_stage;

pub use dataset_args::DatasetArgs;
pub use deploy::{DeployFile, StageSpec};
pub use supervisor::{RunOptions, RunSummary, Supervisor};
