//! The consensus stage: joins the segmenter's segments and the mapper's GS Voting render of
//! the same keyframe (by seq), runs docs/METHOD.md §5, and sends the result to the mapper. It owns
//! the global Label-Class table and keeps it in the run directory (`label_table.json`), so a
//! restarted consensus resumes with the labels the map already carries.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use opengs_datasets::DatasetKind;
use opengs_eval::RunDir;
use opengs_ipc_schema::service::{CONSENSUS, RENDERS, SEGMENTS};
use opengs_ipc_schema::{
    now_ns, ConsensusHeader, ConsensusResult, MessageKind, PixelRun, PruneRun, RenderHeader,
    SegmentsHeader, Stamp,
};
use opengs_runtime::{
    waitset, CallbackProgression, Inlet, Outlet, RunContext, TelemetrySink, WaitSetRunResult,
    HEARTBEAT,
};
use opengs_semantics::{
    ConsensusConfig, ConsensusOutput, GlobalLabelTable, InputLabelClass, LabelConsensus,
    LabelTarget, RelabelScope, RenderedInput, SegmenterInput,
};

use crate::DatasetArgs;

/// A module of the consensus that can be switched off (the paper's ablation, Table IV).
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum Ablation {
    /// No segmentation counter pruning (§5.3).
    NoCounterPruning,
    /// No input confidence update from completeness (§5.2).
    NoConfidenceUpdate,
    /// No part label decay (§5.1).
    NoPartDecay,
    /// No Inside relation (§5.5; not in the paper): absorbed objects stay in the larger label.
    NoInsideSplit,
    /// Unmapped pixels count in a = I/|ℓs| (§5.5; the paper's table): a segment half over
    /// unmapped space is "other".
    NoUnmappedAbstain,
    /// Unsegmented pixels count in b = I/|ℓr| and in counter pruning (§5.5; the paper's table):
    /// a map label that also renders where the segmenter says nothing cannot be a Whole part.
    NoUnsegmentedAbstain,
    /// No Majority relation (§5.5; not in the paper): a segment that misses the table's
    /// thresholds is "other" even when it and a map label share over half of each.
    NoMajorityMatch,
    /// No fragment absorption (§5.5; not in the paper): a map label too small to be a Whole
    /// part of the segment around it keeps its label for good.
    NoFragmentAbsorb,
    /// Whole merges relabel only the Gaussians the view meets (§5.5; the paper's reach): the
    /// hidden rest of a merged part keeps its label.
    NoWholeLabelMerge,
    /// Every Partial part that beats ℓr takes a fresh label (§5.5; the paper's table), also one
    /// that holds most of ℓr.
    NoPartialKeeper,
    /// No Inside for a segment mostly over unlabelled Gaussians beside held labels (§5.5; not
    /// in the paper): an object the map once left unlabelled stays so.
    NoUnlabelledSplit,
}

impl Ablation {
    pub const ALL: [Ablation; 11] = [
        Self::NoCounterPruning,
        Self::NoConfidenceUpdate,
        Self::NoPartDecay,
        Self::NoInsideSplit,
        Self::NoUnmappedAbstain,
        Self::NoUnsegmentedAbstain,
        Self::NoMajorityMatch,
        Self::NoFragmentAbsorb,
        Self::NoWholeLabelMerge,
        Self::NoPartialKeeper,
        Self::NoUnlabelledSplit,
    ];

    pub fn as_str(&self) -> &'static str {
        match self {
            Self::NoCounterPruning => "no-counter-pruning",
            Self::NoConfidenceUpdate => "no-confidence-update",
            Self::NoPartDecay => "no-part-decay",
            Self::NoInsideSplit => "no-inside-split",
            Self::NoUnmappedAbstain => "no-unmapped-abstain",
            Self::NoUnsegmentedAbstain => "no-unsegmented-abstain",
            Self::NoMajorityMatch => "no-majority-match",
            Self::NoFragmentAbsorb => "no-fragment-absorb",
            Self::NoWholeLabelMerge => "no-whole-label-merge",
            Self::NoPartialKeeper => "no-partial-keeper",
            Self::NoUnlabelledSplit => "no-unlabelled-split",
        }
    }

    fn apply(&self, config: &mut ConsensusConfig) {
        match self {
            Self::NoCounterPruning => config.enable_counter_pruning = false,
            Self::NoConfidenceUpdate => config.enable_confidence_update = false,
            Self::NoPartDecay => config.enable_part_decay = false,
            Self::NoInsideSplit => config.enable_inside_split = false,
            Self::NoUnmappedAbstain => config.unmapped_pixels_abstain = false,
            Self::NoUnsegmentedAbstain => config.unsegmented_pixels_abstain = false,
            Self::NoMajorityMatch => config.majority_match = false,
            Self::NoFragmentAbsorb => config.absorb_fragments = false,
            Self::NoWholeLabelMerge => config.merge_whole_labels = false,
            Self::NoPartialKeeper => config.partial_majority_keeps = false,
            Self::NoUnlabelledSplit => config.split_unlabelled_objects = false,
        }
    }
}

/// The consensus's flags that `opengs run` sets ([`crate::run_options::StageFlags`]); one struct for
/// parsing and for writing them.
#[derive(clap::Args, Debug, Clone, Default, PartialEq)]
pub struct ConsensusRunFlags {
    /// Switch a module off (repeatable).
    #[arg(long, value_enum)]
    pub ablation: Vec<Ablation>,
}

impl ConsensusRunFlags {
    pub fn to_args(&self) -> Vec<String> {
        self.ablation
            .iter()
            .flat_map(|a| ["--ablation".to_string(), a.as_str().to_string()])
            .collect()
    }
}

/// Options of the consensus stage.
#[derive(clap::Args, Debug, Clone)]
pub struct ConsensusArgs {
    #[command(flatten)]
    pub run: ConsensusRunFlags,
    /// θ (m): counter Gaussians larger than this are pruned. Default: 0.25 for TUM and ROS 2
    /// bags (real sensors), 0.10 otherwise (docs/METHOD.md §5.3).
    #[arg(long)]
    pub counter_prune_scale: Option<f32>,
    /// Don't save each segmenter label map as segments/NNNNNN.png (used for `miou_raw`).
    #[arg(long)]
    pub no_segment_pngs: bool,
    #[command(flatten)]
    pub dataset: DatasetArgs,
}

impl ConsensusArgs {
    pub fn config(&self) -> anyhow::Result<ConsensusConfig> {
        let theta = match self.counter_prune_scale {
            Some(theta) => theta,
            None if matches!(
                self.dataset.spec()?.kind,
                DatasetKind::Tum(_) | DatasetKind::Rosbag2(_)
            ) =>
            {
                0.25
            }
            None => 0.10,
        };
        let mut config = ConsensusConfig {
            counter_prune_scale: theta,
            ..ConsensusConfig::default()
        };
        for a in &self.run.ablation {
            a.apply(&mut config);
        }
        config.validate()?;
        Ok(config)
    }
}

/// Owned copy of one segments message.
struct OwnedSegments {
    stamp: Stamp,
    width: usize,
    height: usize,
    label_map: Vec<u32>,
    confidence: BTreeMap<u32, f32>,
    classes: BTreeMap<u32, InputLabelClass>,
}

/// Owned copy of one render message.
struct OwnedRender {
    label_map: Vec<u32>,
    completeness: BTreeMap<u32, f32>,
}

/// Segmentations kept while their render is missing: the mapper renders the newest one it
/// has seen when it is free, which can be seconds behind the segmenter on a busy machine.
const MAX_WAITING_SEGMENTS: usize = 24;
/// Renders kept while their segmentation is missing (it normally comes first).
const MAX_WAITING_RENDERS: usize = 4;

struct ConsensusStage {
    consensus: LabelConsensus,
    segments: BTreeMap<u64, OwnedSegments>,
    renders: BTreeMap<u64, OwnedRender>,
    out: Outlet<ConsensusHeader>,
    telemetry: TelemetrySink,
    out_dir: PathBuf,
    save_pngs: bool,
    /// Seq of the newest keyframe answered (by this process or, restarted, its predecessor).
    last_answered: Option<u64>,
    /// The newest keyframes answered ([`ANSWERED_KEPT`]), so none is answered twice.
    answered: BTreeSet<u64>,
    /// Restarted: the first keyframe answered after the restart is still to be reported.
    resumed: bool,
    /// Restarted: the predecessor's newest answer, to be given again (see [`RedoAnswer`]).
    redo: Option<RedoAnswer>,
}

/// The newest answer's keyframe and the table from before it. The answer can die with the
/// process before the mapper reads it (a sample in a dead sender's memory is lost), and the map
/// then lacks every label it made; the restarted consensus answers that keyframe again from
/// this table, so with the same ids (the consensus is deterministic), and the mapper skips the
/// repeat when it had the first.
#[derive(serde::Serialize, serde::Deserialize)]
struct RedoAnswer {
    seq: u64,
    table_before: GlobalLabelTable,
}

/// What `consensus_progress.json` keeps: the keyframes answered and the table after them, in
/// one file, so a restart never resumes a table that is ahead of or behind its answers.
#[derive(serde::Serialize, serde::Deserialize)]
struct ConsensusProgress {
    last_answered: u64,
    /// The newest keyframes answered (out of order with segmenter replicas). Absent in files
    /// of older runs: then every keyframe up to `last_answered` counts as answered.
    #[serde(default)]
    answered: Option<Vec<u64>>,
    /// The table right after the last answer. Absent in files of older runs: then the table
    /// comes from `label_table.json`.
    #[serde(default)]
    table: Option<GlobalLabelTable>,
    /// The newest answer, to be given again after a restart. Absent in files of older runs.
    #[serde(default)]
    redo: Option<RedoAnswer>,
}

impl ConsensusProgress {
    /// The keyframes a restarted consensus must not answer again.
    fn answered(&self) -> BTreeSet<u64> {
        match &self.answered {
            Some(seqs) => seqs.iter().copied().collect(),
            None => (self.last_answered.saturating_sub(ANSWERED_KEPT as u64)..=self.last_answered)
                .collect(),
        }
    }
}

/// Answered keyframes remembered (far more than the segmentations that can wait).
const ANSWERED_KEPT: usize = 256;

impl ConsensusStage {
    fn take_segments(&mut self, h: &SegmentsHeader, payload: &[u8]) {
        let view = match h.decode(payload) {
            Ok(v) => v,
            Err(e) => {
                tracing::error!("segments #{} rejected: {e}", h.stamp.seq);
                self.telemetry.dropped(&h.stamp);
                return;
            }
        };
        let mut confidence = BTreeMap::new();
        let mut classes = BTreeMap::new();
        for l in view.labels {
            confidence.insert(l.label, l.confidence);
            classes.insert(
                l.label,
                InputLabelClass {
                    class: l.class().map(str::to_string),
                    score: l.score,
                },
            );
        }
        let seg = OwnedSegments {
            stamp: h.stamp,
            width: h.width as usize,
            height: h.height as usize,
            label_map: view.label_map.to_vec(),
            confidence,
            classes,
        };
        if self.save_pngs {
            let path = RunDir::new(&self.out_dir)
                .segments_dir()
                .join(format!("{:06}.png", h.stamp.seq));
            if let Err(e) = opengs_eval::write_label_png(&path, h.width, h.height, &seg.label_map) {
                tracing::warn!("segments #{}: {e}", h.stamp.seq);
            }
        }
        insert_bounded(
            &mut self.segments,
            h.stamp.seq,
            seg,
            MAX_WAITING_SEGMENTS,
            "segmentation without a render",
        );
    }

    fn take_render(&mut self, h: &RenderHeader, payload: &[u8]) {
        let view = match h.decode(payload) {
            Ok(v) => v,
            Err(e) => {
                tracing::error!("render #{} rejected: {e}", h.stamp.seq);
                self.telemetry.dropped(&h.stamp);
                return;
            }
        };
        let completeness = view
            .labels
            .iter()
            .filter(|c| c.total > 0)
            .map(|c| (c.label, c.visible as f32 / c.total as f32))
            .collect();
        let render = OwnedRender {
            label_map: view.label_map.to_vec(),
            completeness,
        };
        insert_bounded(
            &mut self.renders,
            h.stamp.seq,
            render,
            MAX_WAITING_RENDERS,
            "render without a segmentation",
        );
    }

    /// Runs every keyframe that has both halves, oldest first. Segmenter replicas finish
    /// keyframes out of order and the mapper renders the newest first, so an older keyframe
    /// still waiting for its render is kept (until [`MAX_WAITING_SEGMENTS`] newer ones push it
    /// out); each keyframe is answered once.
    fn run_joined(&mut self) -> anyhow::Result<()> {
        // The predecessor's newest answer first: any other answer would make it unrepeatable.
        while let Some(seq) = self.next_joined() {
            let (Some(seg), Some(render)) = (self.segments.remove(&seq), self.renders.remove(&seq))
            else {
                break;
            };
            if self.answered.contains(&seq) {
                // Service history hands a restarted consensus what its predecessor answered.
                match self.redo.take_if(|r| r.seq == seq) {
                    Some(redo) => self.answer_again(redo, &seg, &render)?,
                    None => tracing::debug!("keyframe #{seq}: answered already"),
                }
                continue;
            }
            // A new answer changes the table: the predecessor's can no longer be repeated.
            self.redo = None;
            if std::mem::take(&mut self.resumed) {
                tracing::warn!(
                    "restarted: first keyframe answered #{seq}; the last before the restart was \
                     #{}; keyframes between them that were segmented meanwhile got no consensus",
                    self.last_answered
                        .map_or("-".to_string(), |s| s.to_string())
                );
            }
            self.process(&seg, &render, Answer::First)?;
        }
        Ok(())
    }

    /// The keyframe to answer next: the one to repeat ([`RedoAnswer`]) if both its halves are
    /// here, else the oldest with both.
    fn next_joined(&self) -> Option<u64> {
        let joined = |s: &u64| self.segments.contains_key(s) && self.renders.contains_key(s);
        self.redo
            .as_ref()
            .map(|r| r.seq)
            .filter(joined)
            .or_else(|| self.segments.keys().find(|s| joined(s)).copied())
    }

    /// Gives the predecessor's newest answer again ([`RedoAnswer`]): from the table before it,
    /// which then ends where the predecessor's did.
    fn answer_again(
        &mut self,
        redo: RedoAnswer,
        seg: &OwnedSegments,
        render: &OwnedRender,
    ) -> anyhow::Result<()> {
        let seq = redo.seq;
        tracing::info!(
            "keyframe #{seq}: the predecessor's last answer, given again (it may have died \
             with it before the mapper read it)"
        );
        let after = self.consensus.table().clone();
        let config = self.consensus.config().clone();
        self.consensus = LabelConsensus::with_table(config, redo.table_before)?;
        self.process(seg, render, Answer::Again)?;
        if self.consensus.table() != &after {
            tracing::warn!(
                "keyframe #{seq}: answered again, the table differs from the one saved after it"
            );
        }
        Ok(())
    }

    /// Records `seq` as answered, with the table after it in the same file, once its answer
    /// is sent. Killed in between, the restarted process answers `seq` again from the service
    /// history with the table from before it, so it allocates the same ids (the consensus is
    /// deterministic) and the mapper skips the repeat; a table saved apart from the answered
    /// set would allocate every New label of `seq` a second time. Killed after, it answers
    /// `seq` again all the same ([`RedoAnswer`]), from `table_before`.
    fn persist_answered(&mut self, seq: u64, table_before: GlobalLabelTable) -> anyhow::Result<()> {
        self.last_answered = Some(self.last_answered.map_or(seq, |l| l.max(seq)));
        self.answered.insert(seq);
        while self.answered.len() > ANSWERED_KEPT {
            self.answered.pop_first();
        }
        let progress = serde_json::to_vec(&ConsensusProgress {
            last_answered: self.last_answered.unwrap_or(seq),
            answered: Some(self.answered.iter().copied().collect()),
            table: Some(self.consensus.table().clone()),
            redo: Some(RedoAnswer { seq, table_before }),
        })?;
        let run = RunDir::new(&self.out_dir);
        let path = run.consensus_progress();
        if let Err(e) = opengs_eval::write_atomically(&path, &progress) {
            tracing::error!("{}: {e}", path.display());
        }
        // The run's label table for readers (scoring, `opengs objects`).
        if let Err(e) = self.consensus.table().save(&run.label_table()) {
            tracing::error!("saving the label table: {e:#}");
        }
        Ok(())
    }

    fn process(
        &mut self,
        seg: &OwnedSegments,
        render: &OwnedRender,
        answer: Answer,
    ) -> anyhow::Result<()> {
        let start = now_ns();
        let seq = seg.stamp.seq;
        let input = SegmenterInput {
            width: seg.width,
            height: seg.height,
            label_map: &seg.label_map,
            confidence: &seg.confidence,
            classes: &seg.classes,
        };
        let rendered = RenderedInput {
            label_map: &render.label_map,
            completeness: &render.completeness,
        };
        let table_before = self.consensus.table().clone();
        let out = match self.consensus.process(&input, &rendered) {
            Ok(o) => o,
            Err(e) => {
                tracing::error!("keyframe #{seq}: consensus refused the inputs: {e}");
                self.telemetry.dropped(&seg.stamp);
                return self.persist_answered(seq, table_before);
            }
        };
        let wire = WireResult::new(&out);
        let parts = wire.parts(&out.consistent_label_map);
        let mut stamp = Stamp::derived(MessageKind::Consensus, &seg.stamp);
        stamp.stage_start_ns = start;
        let theta = self.consensus.config().counter_prune_scale;
        let header =
            ConsensusHeader::new(stamp, seg.width as u32, seg.height as u32, theta, &parts);
        self.out.send(header, |hd, buf| hd.encode(&parts, buf))?;
        self.persist_answered(seq, table_before)?;
        tracing::info!(
            "keyframe #{seq}: {} input labels → {} global labels, {} relabel regions, {} counter regions",
            out.assignments.len(),
            self.consensus.table().len(),
            out.relabels.len(),
            out.counter_pruning.len()
        );
        if tracing::enabled!(tracing::Level::DEBUG) {
            let table = self.consensus.table();
            tracing::debug!(
                "keyframe #{seq}: {}",
                out.describe(|label| table.confidence(label))
            );
        }
        // A repeat is no keyframe more: the stage's count stays that of keyframes answered.
        if answer == Answer::First {
            self.telemetry.processed(&seg.stamp, start, now_ns());
        }
        Ok(())
    }
}

/// Whether [`ConsensusStage::process`] answers a keyframe for the first time or repeats the
/// predecessor's newest answer ([`RedoAnswer`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Answer {
    First,
    Again,
}

/// Keeps `value` until its other half comes, dropping the oldest (logged as stale) past `cap`.
fn insert_bounded<T>(map: &mut BTreeMap<u64, T>, seq: u64, value: T, cap: usize, what: &str) {
    map.insert(seq, value);
    while map.len() > cap {
        if let Some((old, _)) = map.pop_first() {
            tracing::info!("keyframe #{old}: {what} dropped, stale ({cap} newer ones wait)");
        }
    }
}

/// A consensus output laid out as the wire message wants it (runs over one pixel list).
struct WireResult {
    mapping: Vec<[u32; 2]>,
    relabels: Vec<PixelRun>,
    prunes: Vec<PruneRun>,
    pixels: Vec<u32>,
}

impl WireResult {
    fn new(out: &ConsensusOutput) -> Self {
        let mapping = out
            .assignments
            .iter()
            .map(|a| match a.target {
                LabelTarget::Label(t) => [a.input_label, t],
                LabelTarget::Background | LabelTarget::RenderedParts(_) => [a.input_label, 0],
            })
            .collect();
        let mut pixels = Vec::new();
        // Appends a region's pixels to the one list; returns its (offset, count) there.
        let mut span = |px: &[u32]| {
            let offset = pixels.len() as u32;
            pixels.extend_from_slice(px);
            (offset, px.len() as u32)
        };
        let relabels = out
            .relabels
            .iter()
            .map(|r| {
                let (offset, count) = span(&r.pixels);
                PixelRun {
                    from: r.from,
                    to: r.to,
                    offset,
                    count,
                    scope: match r.scope {
                        RelabelScope::Pixels => PixelRun::SCOPE_PIXELS,
                        RelabelScope::Label => PixelRun::SCOPE_LABEL,
                        RelabelScope::Merged => PixelRun::SCOPE_MERGED,
                        RelabelScope::Rejoin => PixelRun::SCOPE_REJOIN,
                    },
                }
            })
            .collect();
        let prunes = out
            .counter_pruning
            .iter()
            .map(|r| {
                let (offset, count) = span(&r.pixels);
                PruneRun {
                    label: r.label,
                    offset,
                    count,
                }
            })
            .collect();
        Self {
            mapping,
            relabels,
            prunes,
            pixels,
        }
    }

    fn parts<'a>(&'a self, label_map: &'a [u32]) -> ConsensusResult<'a> {
        ConsensusResult {
            label_map,
            mapping: &self.mapping,
            relabels: &self.relabels,
            prunes: &self.prunes,
            pixels: &self.pixels,
        }
    }
}

/// Runs the consensus stage until a termination signal.
pub fn run_consensus(ctx: &RunContext, out_dir: &Path, args: &ConsensusArgs) -> anyhow::Result<()> {
    let config = args.config()?;
    let on = |b: bool| if b { "on" } else { "off" };
    tracing::info!(
        "consensus: τ1 {} τ2 {} τ3 {} δ {} θ {} m; counter pruning {}, confidence update {}, part decay {}",
        config.tau_full,
        config.tau_part,
        config.tau_min,
        config.part_decay,
        config.counter_prune_scale,
        on(config.enable_counter_pruning),
        on(config.enable_confidence_update),
        on(config.enable_part_decay)
    );
    let mut progress = std::fs::read(RunDir::new(out_dir).consensus_progress())
        .ok()
        .and_then(|bytes| serde_json::from_slice::<ConsensusProgress>(&bytes).ok());
    let table = match progress.as_mut().and_then(|p| p.table.take()) {
        Some(table) => Some(table),
        None => GlobalLabelTable::load(&RunDir::new(out_dir).label_table())?,
    };
    let consensus = match table {
        Some(table) => {
            tracing::info!("resuming with {} global labels", table.len());
            LabelConsensus::with_table(config, table)?
        }
        None => LabelConsensus::new(config)?,
    };
    let resumed_from = progress.as_ref().map(|p| p.last_answered);
    let redo = progress.as_mut().and_then(|p| p.redo.take());
    std::fs::create_dir_all(out_dir)?;
    if !args.no_segment_pngs {
        std::fs::create_dir_all(RunDir::new(out_dir).segments_dir())?;
    }
    let node = ctx.node("consensus")?;
    let segments = Inlet::<SegmentsHeader>::new(ctx, &node, &SEGMENTS)?;
    let renders = Inlet::<RenderHeader>::new(ctx, &node, &RENDERS)?;
    let mut stage = ConsensusStage {
        consensus,
        segments: BTreeMap::new(),
        renders: BTreeMap::new(),
        out: Outlet::new(ctx, &node, &CONSENSUS, 640 * 480 * 16 + (1 << 20))?,
        telemetry: TelemetrySink::new(ctx, &node, "consensus")?,
        out_dir: out_dir.to_path_buf(),
        save_pngs: !args.no_segment_pngs,
        last_answered: resumed_from,
        answered: progress.map(|p| p.answered()).unwrap_or_default(),
        resumed: resumed_from.is_some(),
        redo,
    };
    let ws = waitset()?;
    let _g1 = ws
        .attach_notification(segments.listener())
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    let _g2 = ws
        .attach_notification(renders.listener())
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    let _heartbeat = ws
        .attach_interval(HEARTBEAT)
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    stage.telemetry.ready();
    loop {
        match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => break,
            Err(e) => anyhow::bail!("WaitSet: {e:?}"),
            Ok(_) => {}
        }
        stage.telemetry.alive();
        segments.clear_wakeups();
        renders.clear_wakeups();
        while let Some(s) = segments.receive()? {
            stage.take_segments(s.user_header(), s.payload());
        }
        while let Some(r) = renders.receive()? {
            stage.take_render(r.user_header(), r.payload());
        }
        stage.run_joined()?;
    }
    let table_path = RunDir::new(out_dir).label_table();
    stage.consensus.table().save(&table_path)?;
    tracing::info!("consensus: {} global labels", stage.consensus.table().len());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_restarted_consensus_knows_which_keyframes_it_answered() {
        // Out of order (segmenter replicas): 41 answered, 40 not yet.
        let now: ConsensusProgress =
            serde_json::from_str(r#"{"last_answered": 42, "answered": [39, 41, 42]}"#)
                .expect("parses");
        assert_eq!(now.answered(), BTreeSet::from([39, 41, 42]));
        // A file from before replicas: everything up to the last answered counts.
        let old: ConsensusProgress =
            serde_json::from_str(r#"{"last_answered": 3}"#).expect("parses");
        assert_eq!(old.answered(), BTreeSet::from([0, 1, 2, 3]));
    }

    #[test]
    fn the_newest_answer_given_again_from_the_table_before_it_is_the_same_answer() {
        // 4×2 pixels: keyframe 1 sees objects 1 and 2 in an empty map; keyframe 2 sees object 2
        // (rendered as global label 2 where keyframe 1 put it) and a new object 3.
        let one = [1, 1, 2, 2, 1, 1, 2, 2];
        let two = [2, 2, 3, 3, 2, 2, 3, 3];
        let rendered_two = [2, 2, 0, 0, 2, 2, 0, 0];
        let confidence = BTreeMap::from([(1, 0.9), (2, 0.9), (3, 0.9)]);
        let classes = BTreeMap::new();
        let input = |label_map| SegmenterInput {
            width: 4,
            height: 2,
            label_map,
            confidence: &confidence,
            classes: &classes,
        };
        let completeness = BTreeMap::from([(2, 1.0)]);
        let mut consensus = LabelConsensus::new(ConsensusConfig::default()).expect("config");
        let empty = BTreeMap::new();
        let first = consensus
            .process(
                &input(&one),
                &RenderedInput {
                    label_map: &[0; 8],
                    completeness: &empty,
                },
            )
            .expect("keyframe 1");
        assert_eq!(first.consistent_label_map, [1, 1, 2, 2, 1, 1, 2, 2]);
        let rendered = RenderedInput {
            label_map: &rendered_two,
            completeness: &completeness,
        };
        // What persist_answered writes for keyframe 2, read back as a restart reads it.
        let table_before = consensus.table().clone();
        let answer = consensus
            .process(&input(&two), &rendered)
            .expect("keyframe 2");
        let saved = serde_json::to_vec(&ConsensusProgress {
            last_answered: 2,
            answered: Some(vec![1, 2]),
            table: Some(consensus.table().clone()),
            redo: Some(RedoAnswer {
                seq: 2,
                table_before,
            }),
        })
        .expect("serialises");
        let restart: ConsensusProgress = serde_json::from_slice(&saved).expect("parses");
        let redo = restart.redo.expect("the newest answer is kept");
        assert_eq!(redo.seq, 2);
        let mut again = LabelConsensus::with_table(ConsensusConfig::default(), redo.table_before)
            .expect("table");
        let repeat = again.process(&input(&two), &rendered).expect("again");
        // Object 3 gets the same fresh id both times, and the table ends where it ended.
        assert_eq!(repeat, answer);
        assert_eq!(answer.consistent_label_map, [2, 2, 3, 3, 2, 2, 3, 3]);
        assert_eq!(Some(again.table()), restart.table.as_ref());
        // Answered from the table after it instead, object 3 would take a second id.
        let mut after =
            LabelConsensus::with_table(ConsensusConfig::default(), consensus.into_table())
                .expect("table");
        let twice = after.process(&input(&two), &rendered).expect("twice");
        assert_ne!(twice.consistent_label_map, answer.consistent_label_map);
    }
}
