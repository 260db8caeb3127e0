//! The mapper stage: keyframes in; Gaussians densified and optimised
//! continuously; the trackable Gaussians out to the tracker; the map
//! checkpointed to the run directory and written as `map.ply` at the end.

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet, VecDeque};
use std::io::Write;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use opengs_eval::RunDir;
use opengs_geometry::{pose_from_tum, Intrinsics, Pose};
use opengs_ipc_schema::service::{CONSENSUS, KEYFRAMES, MAP_TARGET, RENDERS, SEGMENTS};
use opengs_ipc_schema::{
    now_ns, ConsensusHeader, KeyframeHeader, LabelCompleteness, MapTargetHeader, MapTargetParts,
    MessageKind, PixelRun, RenderHeader, SegmentsHeader, Stamp,
};
use opengs_mapping::{
    fill_holes, final_step_count, optimise_final, ConsensusUpdate, DensifyInput, KeptKeyframes,
    Mapper, MapperConfig, StoredKeyframe,
};
use opengs_runtime::{
    waitset, CallbackProgression, Inlet, Outlet, RunContext, TelemetrySink, WaitSetRunResult,
    HEARTBEAT,
};
use opengs_semantics::{CounterPruneRegion, RelabelInstruction, RelabelScope};
use opengs_splat::{read_ply_file, write_ply_file, Camera, GaussianMap};

use opengs_runtime::finish_requested_flag;

use crate::consensus_journal::{read_consensus_journal, ConsensusJournal, JournalConsensus};
use crate::keyframe_journal::{read_journal, JournalKeyframe, KeyframeJournal};

/// The mapper's flags that `opengs run` sets ([`crate::run_options::StageFlags`]); one struct for
/// parsing and for writing them.
#[derive(clap::Args, Debug, Clone, Default, PartialEq)]
pub struct MapperRunFlags {
    /// Full-resolution optimisation steps (with splitting) run when the supervisor signals
    /// the end of the data (SIGUSR1), before `map.ply` is written; 0 = none. SIGTERM during
    /// them stops early and keeps the map as it is.
    #[arg(long, default_value_t = 0)]
    pub finish_steps: usize,
    /// With `--finish-steps` > 0: at least this many steps per keyframe kept for them, when
    /// that is more than `--finish-steps` (0: `--finish-steps` exactly).
    #[arg(long, default_value_t = 0)]
    pub finish_steps_per_keyframe: usize,
}

impl MapperRunFlags {
    pub fn to_args(&self) -> Vec<String> {
        let mut args = Vec::new();
        if self.finish_steps > 0 {
            args.extend(["--finish-steps".into(), self.finish_steps.to_string()]);
            if self.finish_steps_per_keyframe > 0 {
                args.extend([
                    "--finish-steps-per-keyframe".into(),
                    self.finish_steps_per_keyframe.to_string(),
                ]);
            }
        }
        args
    }
}

/// Options of the mapper stage.
#[derive(clap::Args, Debug, Clone)]
pub struct MapperArgs {
    /// Seconds between map checkpoints while only the optimisation changes the map; a new
    /// keyframe or consensus is checkpointed within a second (the first keyframe at once).
    /// Written on a thread of their own, so optimisation never waits for the disk.
    #[arg(long, default_value_t = 3.0)]
    pub checkpoint_every: f64,
    /// Optimise at full resolution instead of half.
    #[arg(long)]
    pub full_resolution: bool,
    /// Threads for rendering and optimisation.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// K of the per-pixel top-K kept from each render for the consensus (docs/METHOD.md §3).
    #[arg(long, default_value_t = opengs_splat::DEFAULT_TOP_K)]
    pub top_k: usize,
    #[command(flatten)]
    pub run: MapperRunFlags,
    /// Full-resolution keyframes kept for those steps (about 1.5 MB each at 640×480); past
    /// this every other one is dropped.
    #[arg(long, default_value_t = 300)]
    pub finish_keyframes: usize,
}

/// How long a restarted mapper waits for the keyframe service's history (the tracker hands it
/// over within a heartbeat; a tracker that has exited never does).
const HISTORY_WAIT: Duration = Duration::from_millis(1500);

/// Full-resolution cameras of the newest keyframes, for renders the consensus asks for.
const KEPT_CAMERAS: usize = 32;
/// A consensus not back by then is given up on (dropped or refused), and renders go on.
const CONSENSUS_TIMEOUT: Duration = Duration::from_secs(5);

/// Writes atomically (temp file + rename): a crash mid-write keeps the previous checkpoint.
fn write_map_atomically(map: &GaussianMap, path: &Path) -> anyhow::Result<()> {
    let tmp = path.with_extension("ply.tmp");
    write_ply_file(map, &tmp)?;
    std::fs::rename(&tmp, path)?;
    Ok(())
}

/// What the mapper has done, kept with its checkpoint so a restarted mapper counts on and
/// knows what its checkpoint lacks.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct MapperCounters {
    pub keyframes: usize,
    pub iterations: u64,
    /// Times the mapper was restarted: from its checkpoint, or before the first one from nothing.
    pub restarts: u32,
    /// Keyframes whose Gaussians the checkpoint's map holds, by seq.
    #[serde(default)]
    pub mapped: BTreeSet<u64>,
    /// Keyframes whose consensus result the checkpoint's map holds, by seq.
    #[serde(default)]
    pub labelled: BTreeSet<u64>,
}

impl MapperCounters {
    /// The counters of the checkpoint in `run`, or none (a first start, or unreadable: said).
    fn load(run: &RunDir) -> Self {
        let path = run.map_checkpoint_counters();
        match std::fs::read_to_string(&path) {
            Ok(text) => serde_json::from_str(&text).unwrap_or_else(|e| {
                tracing::warn!("{}: {e}; counting from zero", path.display());
                Self::default()
            }),
            Err(_) => Self::default(),
        }
    }
}

/// Checkpoints off the optimisation path: the map is copied (a few MB) and written, with its
/// counters, by a thread of its own; one write at a time, each atomic.
struct Checkpointer {
    run: RunDir,
    every: Duration,
    last: Option<Instant>,
    /// (keyframes, consensus results) the last checkpoint holds.
    holds: (usize, usize),
    writing: Option<std::thread::JoinHandle<anyhow::Result<()>>>,
    /// Forgets the consensus results each checkpoint holds once it is written.
    consensus_journal: Option<ConsensusJournal>,
}

/// A new keyframe or label change is checkpointed at most this long after the last one.
const CHECKPOINT_NEWS: Duration = Duration::from_secs(1);

impl Checkpointer {
    /// Starts a write when one is due: at the first keyframe; within [`CHECKPOINT_NEWS`]
    /// of a keyframe or consensus the last checkpoint lacks (what a restart could not get
    /// back: the keyframe service's history holds only the newest few, and labels lost
    /// would come back as new ones); otherwise every `every` for the optimisation's progress.
    /// `holds`: the (keyframes, consensus results) the map holds now.
    fn maybe(
        &mut self,
        map: &GaussianMap,
        holds: (usize, usize),
        counters: impl FnOnce() -> MapperCounters,
    ) {
        let news = holds != self.holds;
        let due = match self.last {
            None => true,
            Some(t) => t.elapsed() >= self.every || (news && t.elapsed() >= CHECKPOINT_NEWS),
        };
        if map.is_empty() || !due {
            return;
        }
        if self.writing.as_ref().is_some_and(|w| !w.is_finished()) {
            return;
        }
        self.join();
        let (map, run, counters) = (map.clone(), self.run.clone(), counters());
        let journal = self.consensus_journal.clone();
        self.last = Some(Instant::now());
        self.holds = holds;
        self.writing = Some(std::thread::spawn(move || {
            write_checkpoint(&run, &map, &counters)?;
            if let Some(journal) = journal {
                journal.forget(&counters.labelled);
            }
            Ok(())
        }));
    }

    /// Waits for the write in flight, reporting its failure.
    fn join(&mut self) {
        if let Some(w) = self.writing.take() {
            match w.join() {
                Ok(Ok(())) => {}
                Ok(Err(e)) => tracing::error!("checkpoint failed: {e:#}"),
                Err(_) => tracing::error!("checkpoint writer panicked"),
            }
        }
    }
}

/// The map, then its counters, each atomically.
fn write_checkpoint(
    run: &RunDir,
    map: &GaussianMap,
    counters: &MapperCounters,
) -> anyhow::Result<()> {
    write_map_atomically(map, &run.map_checkpoint())?;
    write_counters(run, counters)
}

fn write_counters(run: &RunDir, counters: &MapperCounters) -> anyhow::Result<()> {
    let path = run.map_checkpoint_counters();
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, serde_json::to_string(counters)?)?;
    std::fs::rename(&tmp, &path)?;
    Ok(())
}

/// Where a starting mapper begins: the checkpoint's map and counters, or an empty map.
/// Every mapper writes its counters as it starts (the supervisor clears them before a run),
/// so one restarted before its first checkpoint still counts its restart; its keyframes
/// come back from the keyframe service's history.
fn resume(run: &RunDir) -> anyhow::Result<(Option<GaussianMap>, MapperCounters)> {
    let checkpoint = run.map_checkpoint();
    if !checkpoint.exists() && !run.map_checkpoint_counters().exists() {
        return Ok((None, MapperCounters::default()));
    }
    let mut counters = MapperCounters::load(run);
    counters.restarts += 1;
    let map = match checkpoint.exists() {
        true => Some(read_ply_file(&checkpoint)?),
        false => None,
    };
    if map.is_none() {
        // What no map holds.
        counters.mapped.clear();
        counters.labelled.clear();
    }
    Ok((map, counters))
}

struct MapperStage {
    mapper: Mapper,
    map_target: Outlet<MapTargetHeader>,
    renders: Outlet<RenderHeader>,
    /// Segmented keyframes not rendered yet (headers only: seq and size), by seq.
    waiting_segments: SegmentsQueue,
    /// Render sent, consensus not back yet: the next render waits for it, so it shows the
    /// labels this consensus sets (keyframe N+1 must see the result of N).
    outstanding: Option<(u64, Instant)>,
    /// The newest keyframe held, and whether any segmentation came at all: at the end of
    /// data the newest keyframe's labels are waited for (the segmenter takes the newest).
    newest_keyframe: Option<u64>,
    segments_seen: bool,
    cameras: VecDeque<(u64, Camera)>,
    top_k: usize,
    telemetry: TelemetrySink,
    map_version: u32,
    /// Counters of the checkpoint this process resumed from (zero on a first start).
    resumed: MapperCounters,
    /// Keyframes whose Gaussians the map holds (a restarted mapper: its checkpoint's too).
    /// The keyframe service's history hands a restarted mapper the newest keyframes again,
    /// and only those the map lacks are mapped.
    mapped: BTreeSet<u64>,
    /// Keyframes this process optimises against (a checkpoint's keyframe the journal lacks
    /// comes back from the history as a target only).
    targets: HashSet<u64>,
    /// Keyframes whose consensus result the map holds: a consensus killed between sending a
    /// result and recording it answers that keyframe again after its restart.
    labelled: BTreeSet<u64>,
    /// The results applied since the last checkpoint, for a restart ([`ConsensusJournal`]).
    consensus_journal: Option<ConsensusJournal>,
    out_dir: PathBuf,
    /// Full-resolution keyframes for the final optimisation (only when it is asked for).
    kept: Option<KeptKeyframes>,
    /// Every keyframe on disk, for a restart (none when the journal cannot be written).
    journal: Option<KeyframeJournal>,
}

/// Segmented keyframes waiting for their render. Replicas of the segmenter finish keyframes
/// out of order; the newest is rendered first (its labels are the freshest), the others when
/// the mapper is free again, each once. Past [`MAX_WAITING_SEGMENTS`] the oldest is dropped,
/// and the log says which.
#[derive(Default)]
struct SegmentsQueue {
    waiting: BTreeMap<u64, SegmentsHeader>,
    /// Seqs rendered already: service history (a restarted segmenter or mapper) and a swap's
    /// two processes can hand the same segmentation over twice.
    rendered: VecDeque<u64>,
}

/// Segmentations waiting for a render (a keyframe a second at most, on a slow segmenter).
const MAX_WAITING_SEGMENTS: usize = 8;

impl SegmentsQueue {
    /// Queues a segmentation for its render, unless its consensus is in the map already
    /// (`labelled`: service history hands a restarted mapper segmentations its checkpoint
    /// or journal had the labels of) or it was rendered already.
    fn push(&mut self, h: SegmentsHeader, labelled: &BTreeSet<u64>) {
        let seq = h.stamp.seq;
        if labelled.contains(&seq) {
            tracing::debug!("segments #{seq}: its consensus is in the map already");
            return;
        }
        if self.rendered.contains(&seq) {
            tracing::debug!("segments #{seq}: rendered for the consensus already");
            return;
        }
        self.waiting.insert(seq, h);
        while self.waiting.len() > MAX_WAITING_SEGMENTS {
            if let Some((old, _)) = self.waiting.pop_first() {
                tracing::info!(
                    "segments #{old}: dropped, stale ({MAX_WAITING_SEGMENTS} newer \
                     segmentations wait for a render)"
                );
            }
        }
    }

    fn take_newest(&mut self) -> Option<SegmentsHeader> {
        let (seq, h) = self.waiting.pop_last()?;
        self.rendered.push_back(seq);
        if self.rendered.len() > 64 {
            self.rendered.pop_front();
        }
        Some(h)
    }

    fn is_empty(&self) -> bool {
        self.waiting.is_empty()
    }

    /// A segmentation [`Self::take_newest`] gave out that could not be rendered yet.
    fn put_back(&mut self, h: SegmentsHeader) {
        let seq = h.stamp.seq;
        self.rendered.retain(|&s| s != seq);
        self.waiting.insert(seq, h);
    }

    fn was_rendered(&self, seq: u64) -> bool {
        self.rendered.contains(&seq)
    }
}

impl MapperStage {
    fn handle_keyframe(
        &mut self,
        pool: &rayon::ThreadPool,
        h: &KeyframeHeader,
        payload: &[u8],
    ) -> anyhow::Result<()> {
        let start = now_ns();
        let view = match h.decode(payload) {
            Ok(v) => v,
            Err(e) => {
                tracing::error!("keyframe #{} rejected: {e}", h.stamp.seq);
                self.telemetry.dropped(&h.stamp);
                return Ok(());
            }
        };
        let pose = pose_from_tum(&h.pose)?;
        let [fx, fy, cx, cy] = h.intrinsics;
        let k = Intrinsics::new(fx, fy, cx, cy, h.width, h.height);
        let stored = StoredKeyframe::new(
            h.stamp.seq,
            pose,
            k,
            view.rgb,
            view.depth,
            h.depth_scale,
            self.mapper.config(),
        );
        self.keep_keyframe(h.stamp.seq, pose, k, view.rgb, view.depth, h.depth_scale);
        self.targets.insert(h.stamp.seq);
        let in_map = self.mapped.contains(&h.stamp.seq);
        if !in_map {
            self.record_keyframe(h.stamp.seq);
        }
        if let Some(journal) = &self.journal {
            journal.append(JournalKeyframe {
                seq: h.stamp.seq,
                pose,
                intrinsics: k,
                depth_scale: h.depth_scale,
                rgb: view.rgb.to_vec(),
                depth: view.depth.to_vec(),
            });
        }
        if in_map {
            // The checkpoint's map holds its Gaussians; the journal had missed it.
            self.mapper.restore_keyframe(stored);
            tracing::info!(
                "keyframe #{} (service history): in the map already, a target again",
                h.stamp.seq
            );
            return Ok(());
        }
        let input = DensifyInput {
            points: view.points,
            covariances: view.covariances,
            pose,
            intrinsics: k,
            rgb: view.rgb,
            depth: view.depth,
            depth_scale: h.depth_scale,
        };
        let mapper = &mut self.mapper;
        let added = pool.install(|| mapper.add_keyframe(&input, stored));
        self.mapped.insert(h.stamp.seq);
        tracing::info!(
            "keyframe #{}: +{added} Gaussians ({} in the map, {} keyframes)",
            h.stamp.seq,
            self.mapper.map().len(),
            self.mapper.keyframes()
        );
        self.telemetry.processed(&h.stamp, start, now_ns());
        Ok(())
    }

    /// Densifies every waiting keyframe (a backlog in one go) and sends the tracker one
    /// target; true when there was any.
    fn take_keyframes(
        &mut self,
        pool: &rayon::ThreadPool,
        keyframes: &Inlet<KeyframeHeader>,
    ) -> anyhow::Result<bool> {
        let mut newest = None;
        while let Some(sample) = keyframes.receive()? {
            let seq = sample.user_header().stamp.seq;
            if self.targets.contains(&seq) {
                tracing::debug!("keyframe #{seq} (service history): held already");
                continue;
            }
            self.handle_keyframe(pool, sample.user_header(), sample.payload())?;
            newest = Some(sample.user_header().stamp);
        }
        if let Some(stamp) = newest {
            self.publish_target(&stamp)?;
        }
        Ok(newest.is_some())
    }

    /// Sends the trackable Gaussians to the tracker.
    fn publish_target(&mut self, input: &Stamp) -> anyhow::Result<()> {
        let t = self.mapper.trackable();
        self.map_version += 1;
        let header = MapTargetHeader::new(
            Stamp::derived(MessageKind::MapTarget, input),
            t.means.len() as u32,
            self.map_version,
        );
        let parts = MapTargetParts {
            means: &t.means,
            rotations: &t.rotations,
            scales: &t.scales,
        };
        self.map_target
            .send(header, |hd, buf| hd.encode(&parts, buf))?;
        Ok(())
    }

    fn record_keyframe(&self, seq: u64) {
        let appended = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(RunDir::new(&self.out_dir).keyframes())
            .and_then(|mut f| writeln!(f, "{seq}"));
        if let Err(e) = appended {
            tracing::warn!("keyframe list: {e}");
        }
    }

    /// A keyframe was segmented: render the map there for the consensus (GS Voting labels,
    /// per-label completeness); the top-K stays here until the consensus comes back. False
    /// when the keyframe itself has not come yet (the segmenter can overtake it while this
    /// loop applies a consensus): the segmentation waits for it.
    fn handle_segments(
        &mut self,
        pool: &rayon::ThreadPool,
        h: &SegmentsHeader,
    ) -> anyhow::Result<bool> {
        let seq = h.stamp.seq;
        let Some(camera) = self.cameras.iter().find(|(s, _)| *s == seq).map(|c| c.1) else {
            if self.newest_keyframe.is_none_or(|newest| seq > newest) {
                tracing::debug!("segments #{seq}: before its keyframe; waits for it");
                return Ok(false);
            }
            tracing::warn!(
                "segments #{seq}: dropped, stale (the keyframe is not among the newest \
                 {KEPT_CAMERAS} held here), no render"
            );
            return Ok(true);
        };
        if (camera.width(), camera.height()) != (h.width, h.height) {
            tracing::error!(
                "segments #{seq}: {}x{} label map for a {}x{} keyframe",
                h.width,
                h.height,
                camera.width(),
                camera.height()
            );
            return Ok(true);
        }
        let start = now_ns();
        let (mapper, k) = (&mut self.mapper, self.top_k);
        let r = pool.install(|| mapper.render_for_consensus(seq, &camera, k));
        let labels: Vec<LabelCompleteness> = r
            .visibility
            .iter()
            .map(|v| LabelCompleteness {
                label: v.label,
                visible: v.visible,
                total: v.total,
            })
            .collect();
        let mut stamp = Stamp::derived(MessageKind::Render, &h.stamp);
        stamp.stage_start_ns = start;
        let header = RenderHeader::new(stamp, h.width, h.height, labels.len() as u32);
        let label_map = &r.label_map;
        self.renders
            .send(header, |hd, buf| hd.encode(label_map, &labels, buf))?;
        tracing::debug!("segments #{seq}: rendered for the consensus");
        self.outstanding = Some((seq, Instant::now()));
        Ok(true)
    }

    /// Applies a consensus result: relabels via the kept top-K, counter pruning, labels for
    /// unlabelled Gaussians.
    fn handle_consensus(&mut self, h: &ConsensusHeader, payload: &[u8]) {
        let start = now_ns();
        let seq = h.stamp.seq;
        // Segmenter replicas answer out of order: only this keyframe's result frees the next.
        if self.outstanding.is_some_and(|(s, _)| s == seq) {
            self.outstanding = None;
        }
        if self.labelled.contains(&seq) {
            tracing::info!("consensus #{seq}: applied already, the repeat skipped");
            return;
        }
        if self.apply_consensus(h, payload, "") {
            if let Some(journal) = &self.consensus_journal {
                if let Err(e) = journal.append(h, payload) {
                    tracing::warn!(
                        "consensus #{seq}: not journalled ({e}); a restart before the next \
                         checkpoint would lose its labels"
                    );
                }
            }
            self.telemetry.processed(&h.stamp, start, now_ns());
        }
    }

    /// Decodes and applies a consensus result whose render is pending; true when applied.
    /// `how` qualifies the log line.
    fn apply_consensus(&mut self, h: &ConsensusHeader, payload: &[u8], how: &str) -> bool {
        let seq = h.stamp.seq;
        let view = match h.decode(payload) {
            Ok(v) => v,
            Err(e) => {
                tracing::error!("consensus #{seq} rejected: {e}");
                self.telemetry.dropped(&h.stamp);
                return false;
            }
        };
        let res = &view.result;
        let pixels = |offset: u32, count: u32| {
            res.pixels[offset as usize..(offset + count) as usize].to_vec()
        };
        let relabels: Vec<RelabelInstruction> = res
            .relabels
            .iter()
            .map(|r| RelabelInstruction {
                from: r.from,
                to: r.to,
                pixels: pixels(r.offset, r.count),
                // decode checked the scope is one of the four
                scope: match r.scope {
                    PixelRun::SCOPE_LABEL => RelabelScope::Label,
                    PixelRun::SCOPE_MERGED => RelabelScope::Merged,
                    PixelRun::SCOPE_REJOIN => RelabelScope::Rejoin,
                    _ => RelabelScope::Pixels,
                },
            })
            .collect();
        let regions: Vec<CounterPruneRegion> = res
            .prunes
            .iter()
            .map(|r| CounterPruneRegion {
                label: r.label,
                pixels: pixels(r.offset, r.count),
            })
            .collect();
        let update = ConsensusUpdate {
            seq,
            consistent_label_map: res.label_map,
            relabels: &relabels,
            counter_regions: &regions,
            // Validated by decode: finite and > 0.
            counter_prune_scale: h.counter_prune_scale,
        };
        match self.mapper.apply_consensus(&update) {
            Ok(done) => {
                tracing::info!(
                    "consensus #{seq}{how}: {} relabelled, {} labelled, {} counter Gaussians \
                     pruned",
                    done.relabelled,
                    done.labelled,
                    done.pruned
                );
                if !done.rejoined.is_empty() {
                    tracing::info!(
                        "consensus #{seq}: labels {:?} went back to the label they were split \
                         off: they lie on its surface",
                        done.rejoined
                    );
                }
                if !done.kept_off_host.is_empty() {
                    tracing::info!(
                        "consensus #{seq}: labels {:?} not absorbed: they stand off the surface \
                         of the label they lie in",
                        done.kept_off_host
                    );
                }
                self.labelled.insert(seq);
                true
            }
            Err(e) => {
                tracing::warn!("{e}");
                self.telemetry.dropped(&h.stamp);
                false
            }
        }
    }

    /// Counters of the whole run: those of the checkpoint resumed from, plus this process's.
    fn counters(&self) -> MapperCounters {
        MapperCounters {
            keyframes: self.mapped.len(),
            iterations: self.resumed.iterations + self.mapper.iterations(),
            restarts: self.resumed.restarts,
            mapped: self.mapped.clone(),
            labelled: self.labelled.clone(),
        }
    }

    /// What the map holds, in the checkpointer's terms.
    fn holds(&self) -> (usize, usize) {
        (self.mapped.len(), self.labelled.len())
    }

    /// A restarted mapper takes its journalled keyframes back: training targets, cameras for
    /// the consensus renders, and the final optimisation's keyframes. `in_map`: those its
    /// checkpoint's map holds (as targets only); otherwise those it lacks (after its
    /// checkpoint, which the keyframe service's history no longer held), mapped again from
    /// their depth where the map leaves it open (the tracker's points died with the
    /// message). Returns how many.
    fn take_journal(
        &mut self,
        pool: &rayon::ThreadPool,
        journal: &[JournalKeyframe],
        in_map: bool,
    ) -> usize {
        let mut taken = 0;
        for kf in journal {
            if self.mapped.contains(&kf.seq) != in_map || self.targets.contains(&kf.seq) {
                continue;
            }
            let stored = StoredKeyframe::new(
                kf.seq,
                kf.pose,
                kf.intrinsics,
                &kf.rgb,
                &kf.depth,
                kf.depth_scale,
                self.mapper.config(),
            );
            if in_map {
                self.mapper.restore_keyframe(stored);
            } else {
                let input = DensifyInput {
                    points: &[],
                    covariances: &[],
                    pose: kf.pose,
                    intrinsics: kf.intrinsics,
                    rgb: &kf.rgb,
                    depth: &kf.depth,
                    depth_scale: kf.depth_scale,
                };
                let mapper = &mut self.mapper;
                let added = pool.install(|| mapper.add_keyframe(&input, stored));
                tracing::info!(
                    "keyframe #{}: mapped again from the journal, +{added} Gaussians",
                    kf.seq
                );
                self.mapped.insert(kf.seq);
            }
            self.keep_keyframe(
                kf.seq,
                kf.pose,
                kf.intrinsics,
                &kf.rgb,
                &kf.depth,
                kf.depth_scale,
            );
            self.targets.insert(kf.seq);
            taken += 1;
        }
        taken
    }

    /// A restarted mapper applies again the journalled consensus results its map lacks:
    /// each through a render at its keyframe now, so the Gaussians mapped again get the
    /// labels the consensus gave (the consensus answers a keyframe once). Returns how many.
    fn apply_again(
        &mut self,
        pool: &rayon::ThreadPool,
        results: &[JournalConsensus],
        cameras: &HashMap<u64, Camera>,
    ) -> usize {
        let mut applied = 0;
        for r in results {
            let seq = r.seq();
            if self.labelled.contains(&seq) {
                continue;
            }
            let kept = self.cameras.iter().find(|(s, _)| *s == seq).map(|c| c.1);
            let Some(camera) = kept.or_else(|| cameras.get(&seq).copied()) else {
                tracing::warn!("consensus #{seq} (journal): its keyframe is not here; not applied");
                continue;
            };
            let (mapper, k) = (&mut self.mapper, self.top_k);
            pool.install(|| mapper.render_for_consensus(seq, &camera, k));
            applied += usize::from(self.apply_consensus(&r.header, r.payload(), " (journal)"));
        }
        applied
    }

    /// A keyframe's camera for the consensus renders (the newest [`KEPT_CAMERAS`]) and, when
    /// a final optimisation is asked for, its full-resolution images.
    fn keep_keyframe(
        &mut self,
        seq: u64,
        pose: Pose,
        k: Intrinsics,
        rgb: &[u8],
        depth: &[u16],
        depth_scale: f32,
    ) {
        self.cameras
            .push_back((seq, Camera::from_pose(k, &pose, self.mapper.config().near)));
        self.newest_keyframe = Some(self.newest_keyframe.map_or(seq, |n| n.max(seq)));
        while self.cameras.len() > KEPT_CAMERAS {
            self.cameras.pop_front();
        }
        if let Some(kept) = self.kept.as_mut() {
            if let Err(e) = kept.push(seq, pose, k, rgb, depth, depth_scale) {
                tracing::warn!("{e}");
            }
        }
    }
}

/// Runs the mapper stage until a termination signal; writes `map.ply` and `mapper.json` then.
pub fn run_mapper(ctx: &RunContext, out_dir: &Path, args: &MapperArgs) -> anyhow::Result<()> {
    let node = ctx.node("mapper")?;
    let keyframes = Inlet::<KeyframeHeader>::new(ctx, &node, &KEYFRAMES)?;
    let segments = Inlet::<SegmentsHeader>::new(ctx, &node, &SEGMENTS)?;
    let consensus = Inlet::<ConsensusHeader>::new(ctx, &node, &CONSENSUS)?;
    let config = MapperConfig {
        half_resolution: !args.full_resolution,
        ..MapperConfig::default()
    };
    let near = config.near;
    let run = RunDir::new(out_dir);
    let (map, resumed) = resume(&run)?;
    let map_resumed = map.is_some();
    let mapper = match map {
        Some(map) => {
            tracing::warn!(
                "restarted: resuming from {} ({} Gaussians, {} keyframes mapped before; restart {})",
                run.map_checkpoint().display(),
                map.len(),
                resumed.keyframes,
                resumed.restarts
            );
            Mapper::with_map(config.clone(), map)
        }
        None if resumed.restarts > 0 => {
            tracing::warn!(
                "restarted before its first checkpoint: an empty map; the keyframes come back \
                 from the keyframe service's history (restart {})",
                resumed.restarts
            );
            Mapper::new(config.clone())
        }
        None => Mapper::new(config.clone()),
    };
    if let Err(e) = write_counters(&run, &resumed) {
        tracing::warn!(
            "{}: {e:#}; a restart before the first checkpoint would not be counted",
            run.map_checkpoint_counters().display()
        );
    }
    let consensus_journal = match ConsensusJournal::start(&run.mapper_consensus()) {
        Ok(j) => Some(j),
        Err(e) => {
            tracing::warn!(
                "{}: {e}; a restarted mapper would lose the labels its checkpoint lacks",
                run.mapper_consensus().display()
            );
            None
        }
    };
    let mut checkpointer = Checkpointer {
        run: run.clone(),
        every: Duration::from_secs_f64(args.checkpoint_every.max(0.1)),
        last: None,
        holds: (resumed.mapped.len(), resumed.labelled.len()),
        writing: None,
        consensus_journal: consensus_journal.clone(),
    };
    let mut stage = MapperStage {
        mapper,
        map_target: Outlet::new(ctx, &node, &MAP_TARGET, 1 << 20)?,
        renders: Outlet::new(ctx, &node, &RENDERS, 640 * 480 * 4 + (1 << 16))?,
        waiting_segments: SegmentsQueue::default(),
        outstanding: None,
        newest_keyframe: None,
        segments_seen: false,
        cameras: VecDeque::new(),
        top_k: args.top_k.max(1),
        telemetry: TelemetrySink::new(ctx, &node, "mapper")?,
        map_version: 0,
        mapped: resumed.mapped.clone(),
        targets: HashSet::new(),
        labelled: resumed.labelled.clone(),
        resumed: resumed.clone(),
        consensus_journal,
        out_dir: out_dir.to_path_buf(),
        kept: (args.run.finish_steps > 0).then(|| KeptKeyframes::new(args.finish_keyframes)),
        journal: None,
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.max(1))
        .build()?;
    // Read before this process journals anything.
    let journalled = match resumed.restarts {
        0 => Vec::new(),
        _ => read_journal(&run.mapper_keyframes()),
    };
    if map_resumed {
        let restored = stage.take_journal(&pool, &journalled, true);
        tracing::warn!(
            "restarted: {restored} of the {} keyframes its map holds back from {}",
            resumed.mapped.len(),
            run.mapper_keyframes().display()
        );
    }
    stage.journal = match KeyframeJournal::start(&run.mapper_keyframes()) {
        Ok(j) => Some(j),
        Err(e) => {
            tracing::warn!(
                "{}: {e}; a restarted mapper would lose its keyframes",
                run.mapper_keyframes().display()
            );
            None
        }
    };
    let ws = waitset()?;
    let _guard = ws
        .attach_notification(keyframes.listener())
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    let _segments_guard = ws
        .attach_notification(segments.listener())
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    let _consensus_guard = ws
        .attach_notification(consensus.listener())
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    let _tick = ws
        .attach_interval(HEARTBEAT)
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    let finish = finish_requested_flag(&ws)?;
    if resumed.restarts > 0 {
        // The keyframes sent while this mapper was dead or hung are in the keyframe service's
        // history, which the tracker hands over within a heartbeat; take them before saying
        // ready, since at the end of data ready is followed by the finish signal at once.
        let started = Instant::now();
        let missed = stage.mapper.keyframes();
        while started.elapsed() < HISTORY_WAIT && !stage.take_keyframes(&pool, &keyframes)? {
            std::thread::sleep(Duration::from_millis(20));
        }
        tracing::warn!(
            "restarted: {} keyframes it had missed taken from the keyframe service's history",
            stage.mapper.keyframes() - missed
        );
        // The keyframes after the checkpoint that the history no longer holds, then the
        // labels the consensus gave all of those.
        let again = stage.take_journal(&pool, &journalled, false);
        let cameras: HashMap<u64, Camera> = journalled
            .iter()
            .map(|kf| (kf.seq, Camera::from_pose(kf.intrinsics, &kf.pose, near)))
            .collect();
        let results = read_consensus_journal(&run.mapper_consensus());
        let relabelled = stage.apply_again(&pool, &results, &cameras);
        tracing::warn!(
            "restarted: {again} keyframes the map lacked mapped again from the journal; \
             {relabelled} of {} journalled consensus results the map lacked applied again",
            results.len()
        );
    }
    stage.telemetry.ready();
    let started = Instant::now();
    let mut finishing: Option<Instant> = None;
    let mut last_connect = Instant::now();
    let mut ended_by_finish = false;
    loop {
        // Block only when there is nothing to optimise; otherwise just look for news.
        let timeout = if stage.mapper.keyframes() == 0 {
            Duration::from_secs(1)
        } else {
            Duration::ZERO
        };
        match ws.wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, timeout) {
            Ok(WaitSetRunResult::TerminationRequest) => break,
            // The finish signal interrupts the wait too.
            Ok(WaitSetRunResult::Interrupt) if !finish.load(Ordering::Relaxed) => break,
            Err(e) => anyhow::bail!("WaitSet: {e:?}"),
            Ok(_) => {}
        }
        stage.telemetry.alive();
        if last_connect.elapsed() >= HEARTBEAT {
            // A restarted tracker gets the newest map target now, not after the next keyframe.
            // ... and a restarted consensus the render it was to answer.
            for connected in [
                stage.map_target.update_connections(),
                stage.renders.update_connections(),
            ] {
                if let Err(e) = connected {
                    tracing::debug!("{e}");
                }
            }
            last_connect = Instant::now();
        }
        keyframes.clear_wakeups();
        segments.clear_wakeups();
        consensus.clear_wakeups();
        stage.take_keyframes(&pool, &keyframes)?;
        while let Some(sample) = consensus.receive()? {
            stage.handle_consensus(sample.user_header(), sample.payload());
        }
        while let Some(sample) = segments.receive()? {
            stage.segments_seen = true;
            stage
                .waiting_segments
                .push(*sample.user_header(), &stage.labelled);
        }
        if let Some((seq, _)) = stage
            .outstanding
            .take_if(|(_, since)| since.elapsed() > CONSENSUS_TIMEOUT)
        {
            tracing::info!(
                "consensus #{seq}: not back after {} s; the next render goes on without it",
                CONSENSUS_TIMEOUT.as_secs()
            );
        }
        if stage.outstanding.is_none() {
            if let Some(h) = stage.waiting_segments.take_newest() {
                if !stage.handle_segments(&pool, &h)? {
                    stage.waiting_segments.put_back(h);
                }
            }
        }
        if finish.load(Ordering::Relaxed) {
            // The newest keyframe's segmentation and its consensus still count (without them
            // the Gaussians it added stay unlabelled); then mapping ends.
            let newest_segmented = !stage.segments_seen
                || stage
                    .newest_keyframe
                    .is_none_or(|k| stage.waiting_segments.was_rendered(k));
            let semantic_done = newest_segmented
                && stage.waiting_segments.is_empty()
                && stage.outstanding.is_none();
            let since = *finishing.get_or_insert_with(Instant::now);
            if semantic_done || since.elapsed() > CONSENSUS_TIMEOUT {
                ended_by_finish = true;
                break;
            }
            std::thread::sleep(Duration::from_millis(5));
            continue;
        }
        let mapper = &mut stage.mapper;
        pool.install(|| mapper.step());
        checkpointer.maybe(stage.mapper.map(), stage.holds(), || stage.counters());
    }
    checkpointer.join();
    if let Some(journal) = stage.journal.as_mut() {
        journal.finish();
    }
    let mapping_seconds = started.elapsed().as_secs_f64();
    let counters = stage.counters();
    let finishing = ended_by_finish && stage.kept.is_some();
    if finishing && !stage.mapper.map().is_empty() {
        // The online map is safe before the final optimisation starts.
        if let Err(e) = write_checkpoint(&run, stage.mapper.map(), &counters) {
            tracing::error!("checkpoint failed: {e:#}");
        }
    }
    let MapperStage {
        mapper,
        telemetry,
        kept,
        ..
    } = stage;
    let mut map = mapper.into_map();
    let mut finish_stats = None;
    let mut holes_filled = None;
    if let Some(mut kept) = kept.filter(|_| finishing) {
        let steps = final_step_count(
            args.run.finish_steps,
            args.run.finish_steps_per_keyframe,
            kept.len(),
        );
        tracing::info!(
            "end of data: final optimisation, {steps} full-resolution steps on {} keyframes",
            kept.len()
        );
        let stop = AtomicBool::new(false);
        let (tx, rx) = std::sync::mpsc::channel::<(usize, f32)>();
        let (stats, holes) = std::thread::scope(|scope| {
            // The optimisation and the hole filling after it run on the pool; this thread
            // keeps the IPC side (progress telemetry, the watchdog's heartbeat, termination
            // requests), whose handles cannot leave it.
            let (map, kept, pool, stop, config) = (&mut map, &mut kept, &pool, &stop, &config);
            let worker = scope.spawn(move || {
                pool.install(|| {
                    let stats = optimise_final(map, kept, steps, near, |done, loss| {
                        // The receiver lives until the worker is joined.
                        let _ = tx.send((done, loss));
                        if stop.load(Ordering::Relaxed) {
                            ControlFlow::Break(())
                        } else {
                            ControlFlow::Continue(())
                        }
                    })?;
                    let done = stats.as_ref().map_or(0, |s| s.iterations);
                    let loss = stats.as_ref().map_or(f32::NAN, |s| s.last_loss);
                    // Done even after a termination request, as before it had a heartbeat: a
                    // few seconds that close what pruning opened.
                    let holes = fill_holes(map, kept, config, |_| {
                        let _ = tx.send((done, loss));
                        ControlFlow::Continue(())
                    });
                    Ok::<_, opengs_mapping::RefineError>((stats, holes))
                })
            });
            let (mut logged_tenth, mut last_log) = (0, Instant::now());
            while !worker.is_finished() {
                // Twice a second: the newest step's progress, and a look for SIGTERM.
                std::thread::sleep(Duration::from_millis(500));
                if let Some((done, loss)) = rx.try_iter().last() {
                    telemetry.progress(done as u32, steps as u32);
                    // Every tenth of the steps, and at least twice a minute.
                    if done * 10 / steps > logged_tenth || last_log.elapsed().as_secs() >= 30 {
                        logged_tenth = done * 10 / steps;
                        last_log = Instant::now();
                        tracing::info!("final optimisation: step {done}/{steps}, loss {loss:.4}");
                    }
                }
                // SIGTERM (Ctrl-C, or the supervisor's time limit) keeps what is done.
                let waited = ws.wait_and_process_once_with_timeout(
                    |_| CallbackProgression::Continue,
                    Duration::ZERO,
                );
                if matches!(waited, Ok(WaitSetRunResult::TerminationRequest)) {
                    stop.store(true, Ordering::Relaxed);
                }
            }
            let result = worker
                .join()
                .map_err(|_| anyhow::anyhow!("the final optimisation panicked"))?;
            anyhow::Ok(result?)
        })?;
        finish_stats = stats;
        let done = finish_stats.as_ref().map_or(0, |s| s.iterations);
        telemetry.progress(done as u32, steps as u32);
        holes_filled = Some(holes);
        tracing::info!(
            "after the final optimisation: {} Gaussians where the kept keyframes saw holes",
            holes_filled.unwrap_or(0)
        );
    }
    let seconds = started.elapsed().as_secs_f64();
    if !map.is_empty() {
        write_map_atomically(&map, &run.map())?;
        write_checkpoint(&run, &map, &counters)?;
    }
    let stats = serde_json::json!({
        // The whole run's, across restarts; the rate is this process's.
        "iterations": counters.iterations,
        "seconds": mapping_seconds,
        "iterations_per_s": (counters.iterations - resumed.iterations) as f64
            / mapping_seconds.max(1e-9),
        "gaussians": map.len(),
        "keyframes": counters.keyframes,
        "restarts": counters.restarts,
        "bytes_per_gaussian": GaussianMap::bytes_per_gaussian(),
        "final_optimisation": finish_stats,
        "holes_filled": holes_filled,
        "total_seconds": seconds,
    });
    std::fs::write(run.mapper_report(), serde_json::to_string_pretty(&stats)?)?;
    tracing::info!("mapper: {stats}");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_splat::Gaussian;

    fn segments(seq: u64) -> SegmentsHeader {
        let stamp = Stamp::new(MessageKind::Segments, seq, 0, 0);
        SegmentsHeader::new(stamp, 64, 48, 0, 0)
    }

    /// A mapper killed before its first checkpoint (a slow first keyframe) is counted as
    /// restarted all the same (before: mapper.json said 0 restarts, the supervisor 1).
    #[test]
    fn every_start_after_the_first_counts_a_restart_checkpoint_or_not() {
        let dir = tempfile::tempdir().expect("tmp");
        let run = RunDir::new(dir.path());
        let start = |run: &RunDir| {
            let (map, counters) = resume(run).expect("resume");
            write_counters(run, &counters).expect("counters");
            let held = (counters.mapped.len(), counters.labelled.len());
            (
                map.map(|m| m.len()),
                counters.restarts,
                counters.keyframes,
                held,
            )
        };
        assert_eq!(start(&run), (None, 0, 0, (0, 0)));
        // Killed before any checkpoint.
        assert_eq!(start(&run), (None, 1, 0, (0, 0)));
        // This one checkpoints 2 Gaussians, 3 keyframes (2 of them labelled), then dies.
        let mut map = GaussianMap::new();
        for x in [0.0, 1.0] {
            map.push(Gaussian::from_values(
                [x, 0.0, 1.0],
                [1.0, 0.0, 0.0, 0.0],
                [0.01; 3],
                0.5,
                [0.5; 3],
                0,
            ));
        }
        let counters = MapperCounters {
            keyframes: 3,
            iterations: 10,
            restarts: 1,
            mapped: BTreeSet::from([0, 10, 20]),
            labelled: BTreeSet::from([0, 10]),
        };
        write_checkpoint(&run, &map, &counters).expect("checkpoint");
        assert_eq!(start(&run), (Some(2), 2, 3, (3, 2)));
    }

    #[test]
    fn out_of_order_segmentations_are_rendered_newest_first_each_once() {
        let mut q = SegmentsQueue::default();
        // Replicas finish 12, then 10, then 11.
        for seq in [12, 10, 11] {
            q.push(segments(seq), &BTreeSet::new());
        }
        let first = q.take_newest().map(|h| h.stamp.seq);
        // 12 again (a restarted segmenter's service history): rendered already, ignored.
        q.push(segments(12), &BTreeSet::new());
        let rest: Vec<u64> = std::iter::from_fn(|| q.take_newest().map(|h| h.stamp.seq)).collect();
        assert_eq!((first, rest), (Some(12), vec![11, 10]));
        assert!(q.is_empty());
    }

    #[test]
    fn a_segmentation_ahead_of_its_keyframe_waits_and_is_rendered_later() {
        let mut q = SegmentsQueue::default();
        q.push(segments(30), &BTreeSet::new());
        let early = q.take_newest();
        assert!(q.was_rendered(30));
        // Its keyframe has not come: back in the queue, no longer counted as rendered.
        if let Some(h) = early {
            q.put_back(h);
        }
        assert!(!q.was_rendered(30));
        q.push(segments(20), &BTreeSet::new());
        let order: Vec<u64> = std::iter::from_fn(|| q.take_newest().map(|h| h.stamp.seq)).collect();
        assert_eq!(order, [30, 20]);
        assert!(q.was_rendered(30) && q.was_rendered(20));
    }

    /// Service history hands a restarted mapper the newest segmentations: those whose
    /// consensus its map holds are skipped, every other one is rendered (before: only the
    /// newest, and keyframes segmented but not yet rendered before the kill never got a
    /// consensus: beside a busy loop, keyframe #0 of the built-in room, its largest part).
    #[test]
    fn a_restarted_mapper_renders_the_history_its_map_lacks_the_consensus_of() {
        let mut q = SegmentsQueue::default();
        let labelled = BTreeSet::from([10, 40]);
        for seq in [0, 10, 20, 30, 40] {
            q.push(segments(seq), &labelled);
        }
        let order: Vec<u64> = std::iter::from_fn(|| q.take_newest().map(|h| h.stamp.seq)).collect();
        assert_eq!(order, [30, 20, 0]);
    }

    #[test]
    fn past_its_bound_the_oldest_waiting_segmentation_is_dropped() {
        let mut q = SegmentsQueue::default();
        for seq in 100..100 + MAX_WAITING_SEGMENTS as u64 + 2 {
            q.push(segments(seq), &BTreeSet::new());
        }
        let all: Vec<u64> = std::iter::from_fn(|| q.take_newest().map(|h| h.stamp.seq)).collect();
        let expected: Vec<u64> = (102..100 + MAX_WAITING_SEGMENTS as u64 + 2).rev().collect();
        assert_eq!(all, expected, "100 and 101 dropped as stale");
    }
}
