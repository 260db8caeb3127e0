//! What `opengs run` decides before the stages start: the deploy file, the dataset, where
//! outputs go, and the flags it sets on individual stages.

use std::path::PathBuf;

use crate::consensus_stage::ConsensusRunFlags;
use crate::deploy::{stage_names, DeployFile};
use crate::mapper_stage::MapperRunFlags;
use crate::segmenter_stage::SegmenterRunFlags;
use crate::tracker_stage::TrackerRunFlags;
use crate::viewer_args::ViewerArgs;
use crate::DatasetArgs;

/// Everything `opengs run` decides before the stages start.
pub struct RunOptions {
    pub deploy: DeployFile,
    pub dataset: DatasetArgs,
    pub out_dir: PathBuf,
    pub run_id: String,
    /// Sensor pacing (`None` = dataset rate, 0 = as fast as possible).
    pub max_rate: Option<f64>,
    /// Flags the run sets on individual stages, beyond their deploy-file arguments.
    pub stage_flags: StageFlags,
    /// Show a progress bar / periodic progress lines.
    pub progress: bool,
    /// Score rendered views against every Nth frame at the end (0 = skip).
    pub quality_every: usize,
    /// After a final optimisation, align every pose to the final map before scoring
    /// ([`crate::trajectory_refinement`]).
    pub pose_refinement: bool,
    /// At the end of the data, let stages with a `finish_timeout_s` do their final work
    /// (else every stage is stopped at once).
    pub finish_after_data: bool,
    /// No end of data: the sensor waits for frames a recorder appends until the run is
    /// stopped (`opengs ctl stop`, SIGTERM).
    pub live: bool,
    /// Where this supervisor runs: `None` on the main host (`opengs run`: the deploy file's
    /// stages without a `host`; those with one are shown from their telemetry), a host name
    /// under `opengs node` (only that host's stages; no source, runs until stopped).
    pub host: Option<String>,
    /// The run id all hosts share (bridge stages get it as `--link`); `run_id` on the main
    /// host, `<link>-<host>` on the others.
    pub link: String,
}

/// Flags a run sets on individual stages, each typed by the stage's own argument struct.
#[derive(Debug, Clone, Default)]
pub struct StageFlags {
    pub tracker: TrackerRunFlags,
    pub mapper: MapperRunFlags,
    pub consensus: ConsensusRunFlags,
    pub segmenter: SegmenterRunFlags,
    /// `--rerun` / `--rerun-connect`: they also decide whether the viewer stage starts.
    pub viewer: ViewerArgs,
}

impl StageFlags {
    /// The arguments for the stage called `name` in the deploy file.
    pub fn for_stage(&self, name: &str) -> Vec<String> {
        match name {
            stage_names::TRACKER => self.tracker.to_args(),
            stage_names::MAPPER => self.mapper.to_args(),
            stage_names::CONSENSUS => self.consensus.to_args(),
            stage_names::SEGMENTER => self.segmenter.to_args(),
            stage_names::VIEWER => self.viewer.to_args(),
            _ => Vec::new(),
        }
    }
}
