//! One run of the pipeline, start to finish: the [`Supervisor`] runs the stages and hands back
//! what it collected; [`run_outputs`](crate::run_outputs) writes it into the run directory
//! (nothing collected is lost, whatever ended the run); [`scoring`](crate::scoring) scores the
//! result against the dataset's ground truth.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use opengs_eval::RunDir;
use opengs_telemetry::LatencyReport;

use crate::deploy::stage_names;
use crate::recorder::Recorder;
use crate::run_options::RunOptions;
use crate::scoring::Scores;
use crate::supervisor::{Ending, Supervisor};
use crate::trajectory_refinement::{self, TrajectoryRefinement};

/// What a finished run produced.
pub struct RunSummary {
    pub out_dir: PathBuf,
    pub frames_published: u64,
    pub poses: usize,
    pub keyframes: usize,
    /// Frames without a verified pose, relocalisations after them, and those among them whose
    /// verified pose was withdrawn when tracking started again.
    pub lost_frames: usize,
    pub relocalisations: usize,
    pub withdrawn: usize,
    pub elapsed_s: f64,
    /// Seconds until the data ended (or the run stopped), without the stages' final work.
    pub streaming_s: f64,
    pub latency: LatencyReport,
    pub restarts: BTreeMap<String, u32>,
    pub interrupted: bool,
    /// Files of this run still in /dev/shm or the iceoryx2 root after shutdown (should be none).
    pub leftover_files: Vec<PathBuf>,
    pub recorder: Recorder,
    /// The end-of-run alignment of the poses to the final map, when it ran.
    pub pose_refinement: Option<TrajectoryRefinement>,
    pub scores: Scores,
}

/// Runs the pipeline as `opts` say, writes the run directory and scores it. A stage that
/// failed for good is an error, reported after the outputs so far are written.
pub fn run(opts: RunOptions) -> anyhow::Result<RunSummary> {
    let started = Instant::now();
    // The viewer stage asked for but not built: refused before any stage starts.
    opts.stage_flags.viewer.check_ready()?;
    let segmenter_kinds = opengs_perception::SegmenterKind::ALL.map(|k| k.as_str());
    for stage in opts
        .deploy
        .stages
        .iter()
        .filter(|s| s.name == stage_names::SEGMENTER)
    {
        stage
            .check_kinds(&segmenter_kinds)
            .map_err(anyhow::Error::msg)?;
    }
    let mut supervised = Supervisor::supervise(&opts)?;
    let run_dir = RunDir::new(&opts.out_dir);
    // A mapper killed before it wrote map.ply (hung in its final work, say) left its checkpoint.
    if !run_dir.map().exists() && run_dir.map_checkpoint().exists() {
        match std::fs::copy(run_dir.map_checkpoint(), run_dir.map()) {
            Ok(_) => eprintln!("map.ply is the mapper's last checkpoint: it did not finish"),
            Err(e) => eprintln!("map.ply from the mapper's checkpoint: {e}"),
        }
    }
    // Outputs are written on every path: nothing produced is lost.
    crate::run_outputs::write(&run_dir, &opts, &mut supervised)?;
    // Only after the data ended: a stopped or failed run is scored as it is.
    let ended = matches!(supervised.ending, Ok(Ending::EndOfData));
    let pose_refinement = match trajectory_refinement::skip_reason(&run_dir, &opts, !ended) {
        Some(why) => {
            if opts.pose_refinement && ended {
                eprintln!("poses not refined against the map: {why}");
            }
            None
        }
        None => {
            eprintln!("refining every pose against the final map ...");
            trajectory_refinement::refine_trajectory(&run_dir, &opts, opts.progress)
                .map_err(|e| eprintln!("pose refinement: {e:#}; the tracker's poses are kept"))
                .ok()
                .flatten()
        }
    };
    let scores = crate::scoring::score(&run_dir, &opts, !supervised.recorder.is_empty());
    let summary = RunSummary {
        out_dir: opts.out_dir.clone(),
        frames_published: supervised.processed(stage_names::SENSOR),
        poses: supervised.recorder.len(),
        keyframes: supervised.recorder.keyframes(),
        lost_frames: supervised.recorder.lost(),
        relocalisations: supervised.recorder.relocalised(),
        withdrawn: supervised.recorder.withdrawn(),
        elapsed_s: started.elapsed().as_secs_f64(),
        streaming_s: supervised.streaming_s,
        latency: supervised.profile.report(),
        restarts: supervised
            .stages
            .iter()
            .map(|s| (s.name.clone(), s.restarts))
            .collect(),
        interrupted: matches!(supervised.ending, Ok(Ending::Interrupted)),
        leftover_files: supervised.leftover_files,
        recorder: supervised.recorder,
        pose_refinement,
        scores,
    };
    match supervised.ending? {
        Ending::StageFailed(why) => Err(anyhow::Error::new(StageFailed {
            why,
            out_dir: opts.out_dir.clone(),
        })),
        Ending::BadInput(why) => Err(anyhow::Error::new(StoppedOnBadInput {
            why,
            out_dir: opts.out_dir.clone(),
        })),
        _ => Ok(summary),
    }
}

/// A stage died more often than its restart limit allows; the run stopped there.
#[derive(Debug, thiserror::Error)]
#[error("{why}; outputs so far are in {}", out_dir.display())]
pub struct StageFailed {
    pub why: String,
    pub out_dir: PathBuf,
}

/// A stage stopped on input it cannot use (a corrupt frame); the run stopped there.
#[derive(Debug, thiserror::Error)]
#[error("{why}\noutputs so far are in {}", out_dir.display())]
pub struct StoppedOnBadInput {
    pub why: String,
    pub out_dir: PathBuf,
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;
    use crate::consensus_stage::{Ablation, ConsensusArgs, ConsensusRunFlags};
    use crate::mapper_stage::{MapperArgs, MapperRunFlags};
    use crate::run_options::StageFlags;
    use crate::segmenter_stage::{SegmenterArgs, SegmenterRunFlags};
    use crate::tracker_stage::{TrackerArgs, TrackerRunFlags};
    use crate::viewer_args::ViewerArgs;

    fn parse<A: clap::Args>(args: &[String]) -> A {
        #[derive(Parser)]
        struct Cli<A: clap::Args> {
            #[command(flatten)]
            a: A,
        }
        let argv = std::iter::once("stage".to_string()).chain(args.iter().cloned());
        Cli::<A>::try_parse_from(argv)
            .expect("the stage parses what the run wrote")
            .a
    }

    #[test]
    fn each_stage_reads_back_the_flags_the_run_sets() {
        let flags = StageFlags {
            tracker: TrackerRunFlags {
                gt_first_pose: true,
            },
            mapper: MapperRunFlags {
                finish_steps: 250,
                finish_steps_per_keyframe: 4,
            },
            consensus: ConsensusRunFlags {
                ablation: vec![Ablation::NoPartDecay, Ablation::NoCounterPruning],
            },
            segmenter: SegmenterRunFlags { min_call_ms: 2000 },
            viewer: ViewerArgs {
                rerun: Some("/tmp/a run.rrd".into()),
                rerun_connect: Some("rerun+http://laptop:9876/proxy".into()),
            },
        };
        let tracker: TrackerArgs = parse(&flags.for_stage(stage_names::TRACKER));
        assert_eq!(tracker.run, flags.tracker);
        let mapper: MapperArgs = parse(&flags.for_stage(stage_names::MAPPER));
        assert_eq!(mapper.run, flags.mapper);
        let consensus: ConsensusArgs = parse(&flags.for_stage(stage_names::CONSENSUS));
        assert_eq!(consensus.run, flags.consensus);
        let viewer: ViewerArgs = parse(&flags.for_stage(stage_names::VIEWER));
        assert_eq!(viewer, flags.viewer);
        let segmenter: SegmenterArgs = parse(&flags.for_stage(stage_names::SEGMENTER));
        assert_eq!(segmenter.run, flags.segmenter);
        // Defaults write nothing, so a deploy file's own arguments stand alone.
        let none = StageFlags::default();
        for name in [
            stage_names::TRACKER,
            stage_names::MAPPER,
            stage_names::CONSENSUS,
            stage_names::SEGMENTER,
            stage_names::VIEWER,
        ] {
            assert!(none.for_stage(name).is_empty(), "{name}");
        }
        assert!(flags.for_stage(stage_names::SENSOR).is_empty());
    }

    #[test]
    fn a_restarted_tracker_reads_back_the_poses_to_resume_from() {
        use opengs_geometry::nalgebra::{Translation3, UnitQuaternion};
        let dir = tempfile::tempdir().expect("tmp");
        let pose = |x: f64| {
            opengs_geometry::Pose::from_parts(
                Translation3::new(x, 0.5, -2.0),
                UnitQuaternion::from_euler_angles(0.1, -0.2, x),
            )
        };
        let poses = [0.0, 0.25, 0.5].map(|x| opengs_eval::TimedPose {
            timestamp: 1305031102.175 + x,
            pose: pose(x),
        });
        let path = dir.path().join("tracker_resume.txt");
        let args = crate::tracker_stage::resume_args(&path, &poses).expect("written");
        let tracker: TrackerArgs = parse(&args);
        let back = opengs_eval::read_tum_trajectory(&tracker.resume.expect("file")).expect("read");
        assert_eq!(back.len(), 3);
        let last = back.last().expect("last");
        assert!((last.pose.translation.vector - pose(0.5).translation.vector).norm() < 1e-6);
        assert!(last.pose.rotation.angle_to(&pose(0.5).rotation) < 1e-6);
        assert!((last.timestamp - 1305031102.675).abs() < 1e-6);
    }
}
