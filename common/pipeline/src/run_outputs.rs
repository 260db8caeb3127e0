//! The files a run writes from what its supervisor collected: trajectory, lost frames and
//! ground truth, latency profile, trace and the run record. The stages write their own
//! (map, keyframes, labels, segments).

use opengs_eval::RunDir;

use crate::run_options::RunOptions;
use crate::run_record::RunRecord;
use crate::supervisor::Supervised;

pub fn write(run: &RunDir, opts: &RunOptions, supervised: &mut Supervised) -> anyhow::Result<()> {
    if !supervised.recorder.is_empty() {
        supervised.recorder.finish()?;
    }
    supervised.profile.report().write(&run.latency())?;
    supervised.trace.write(&run.trace())?;
    RunRecord {
        run_id: opts.run_id.clone(),
        dataset_args: opts.dataset.clone(),
        frames_total: supervised.frames_total,
        stages: supervised.stages.clone(),
    }
    .write(run)
}
