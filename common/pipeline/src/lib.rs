//! Pipeline glue: deploy files, the stage loops that connect the algorithm crates to their
//! IPC services (`*_stage`), the supervisor that starts, watches, restarts and stops stage
//! processes, and what a run does around it ([`run`]): its outputs, its scores, its progress
//! display. Stage binaries in `services/` call into this crate.

pub mod cli_values;
pub mod consensus_journal;
pub mod consensus_stage;
pub mod dataset_args;
pub mod deploy;
pub mod frame_backlog;
pub mod frame_reader;
pub mod keyframe_claims;
pub mod keyframe_journal;
pub mod logging;
pub mod mapper_stage;
pub mod pacing;
pub mod progress;
pub mod recorder;
pub mod run;
pub mod run_options;
pub mod run_outputs;
pub mod run_record;
pub mod scale;
pub mod scoring;
pub mod segmenter_stage;
pub mod sensor;
pub mod service_notify;
pub mod stage_main;
pub mod stage_process;
pub mod status;
pub mod supervisor;
pub mod swap;
pub mod tracker_stage;
pub mod trajectory_refinement;
pub mod viewer_args;
pub mod watchdog;

pub use dataset_args::DatasetArgs;
pub use deploy::{DeployFile, StageSpec};
pub use run::{run, RunSummary, StageFailed, StoppedOnBadInput};
pub use run_options::{RunOptions, StageFlags};
pub use run_record::{RunRecord, StageRecord};
pub use supervisor::{Supervised, Supervisor};
