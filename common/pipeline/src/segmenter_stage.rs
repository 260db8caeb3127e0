//! The segmenter stage: the newest keyframe in (older ones dropped, so a slow
//! segmenter never holds the pipeline back), a label map with confidences and
//! the input Label-Class table out (docs/METHOD.md §6).
//!
//! Several processes of this stage (replicas, `replicas = N` in the deploy file) share the
//! keyframes: each takes the newest keyframe no other replica has claimed
//! ([`crate::keyframe_claims`]), so none is segmented twice.

use std::path::{Path, PathBuf};
use std::sync::mpsc::RecvTimeoutError;
use std::time::{Duration, Instant};

use opengs_datasets::open_dataset;
use opengs_geometry::Intrinsics;
use opengs_ipc_schema::service::{KEYFRAMES, SEGMENTS};
use opengs_ipc_schema::{now_ns, KeyframeHeader, MessageKind, SegmentLabel, SegmentsHeader, Stamp};
use opengs_perception::{
    PerceptionError, SamModelPaths, Segmentation, Segmenter, SegmenterInput, SegmenterKind,
    SegmenterOptions, SimulatedParams,
};
use opengs_runtime::{
    waitset, CallbackProgression, Inlet, Outlet, Received, RunContext, TelemetrySink,
    WaitSetRunResult, HEARTBEAT,
};

use crate::keyframe_claims::KeyframeClaims;
use crate::DatasetArgs;

/// Options of the segmenter stage.
#[derive(clap::Args, Debug, Clone)]
pub struct SegmenterArgs {
    /// geometry (depth-first, no weights), classic (graph-based, no weights), prior (ground
    /// truth), simulated (ground truth with SAM's failure modes), sam or mobilesamv2 (ONNX).
    #[arg(long, default_value = "geometry")]
    pub kind: String,
    /// SAM-family image encoder ONNX (for sam / mobilesamv2).
    #[arg(long)]
    pub encoder: Option<PathBuf>,
    /// SAM-family mask decoder ONNX (for sam / mobilesamv2).
    #[arg(long)]
    pub decoder: Option<PathBuf>,
    /// MobileSAMv2 box-proposal ONNX (YOLOv8 export): box prompts instead of a point grid.
    #[arg(long)]
    pub proposals: Option<PathBuf>,
    /// sam: decoder prompts on an N×N point grid per keyframe (SAM's own default is 32).
    #[arg(long, default_value_t = opengs_perception::DEFAULT_POINTS_PER_SIDE,
          value_parser = clap::value_parser!(u32).range(1..=64))]
    pub points_per_side: u32,
    /// Ensemble tagger ONNX (RAM/RAM++ export) proposing class names.
    #[arg(long)]
    pub tagger: Option<PathBuf>,
    /// Tag names, one per line, in the tagger's output order (ram_tag_list.txt).
    #[arg(long)]
    pub tag_list: Option<PathBuf>,
    /// Ensemble open-vocabulary detector ONNX (YOLO-World with a text_features input).
    #[arg(long)]
    pub detector: Option<PathBuf>,
    /// The detector's text feature of every tag: .npy float32 [tags, 512].
    #[arg(long)]
    pub text_embeddings: Option<PathBuf>,
    /// Longest one segmentation may take (seconds): heartbeats go on while it runs, so the
    /// watchdog finds a stopped process in its `watchdog_s` however slow the model; a call
    /// still running after this long stops them and is taken for hung.
    #[arg(long, default_value_t = 300.0, value_parser = crate::cli_values::positive)]
    pub longest_call_s: f64,
    /// Model kinds (sam, mobilesamv2, an ensemble): segment one blank frame before reporting
    /// ready, so that the first keyframe runs at full speed and a model that loads but cannot
    /// run fails here. The supervisor asks it of a process started beside a running one (a
    /// swap, a scale), where the old process serves meanwhile.
    #[arg(long)]
    pub warm_up: bool,
    #[command(flatten)]
    pub run: SegmenterRunFlags,
    #[command(flatten)]
    pub simulated: SimulatedArgs,
    #[command(flatten)]
    pub dataset: DatasetArgs,
}

/// The segmenter's flags that `opengs run` sets ([`crate::run_options::StageFlags`]).
#[derive(clap::Args, Debug, Clone, Default, PartialEq)]
pub struct SegmenterRunFlags {
    /// Stand-in for a slow model (tests and benchmarks of replicas on a small machine): each
    /// keyframe takes at least this many milliseconds, whatever the kind; the process sleeps
    /// out the rest, so the wait costs no CPU. 0 = as fast as the kind is.
    #[arg(long, default_value_t = 0)]
    pub min_call_ms: u64,
}

impl SegmenterRunFlags {
    pub fn to_args(&self) -> Vec<String> {
        match self.min_call_ms {
            0 => Vec::new(),
            ms => vec!["--min-call-ms".into(), ms.to_string()],
        }
    }
}

/// `simulated`'s failure modes (defaults: opengs_perception::SimulatedParams, SAM-like).
#[derive(clap::Args, Debug, Clone)]
pub struct SimulatedArgs {
    /// simulated: random seed of the corruption.
    #[arg(long, default_value_t = 0)]
    pub sim_seed: u64,
    /// simulated: probability that two touching instances are one mask in a frame.
    #[arg(long, default_value_t = SimulatedParams::default().merge_rate)]
    pub sim_merge_rate: f32,
    /// simulated: probability that an instance is cut into 2-4 parts in a frame.
    #[arg(long, default_value_t = SimulatedParams::default().split_rate)]
    pub sim_split_rate: f32,
    /// simulated: probability that an instance under --sim-small-px is missed.
    #[arg(long, default_value_t = SimulatedParams::default().miss_rate)]
    pub sim_miss_rate: f32,
    /// simulated: instances smaller than this many pixels may be missed.
    #[arg(long, default_value_t = SimulatedParams::default().small_px)]
    pub sim_small_px: usize,
    /// simulated: largest boundary displacement in pixels.
    #[arg(long, default_value_t = SimulatedParams::default().jitter_px)]
    pub sim_jitter_px: u32,
    /// simulated: keep mask ids stable across frames (SAM's are not).
    #[arg(long)]
    pub sim_no_shuffle: bool,
}

impl SimulatedArgs {
    pub fn params(&self) -> SimulatedParams {
        SimulatedParams {
            seed: self.sim_seed,
            merge_rate: self.sim_merge_rate,
            split_rate: self.sim_split_rate,
            miss_rate: self.sim_miss_rate,
            small_px: self.sim_small_px,
            jitter_px: self.sim_jitter_px,
            shuffle: !self.sim_no_shuffle,
            ..SimulatedParams::default()
        }
    }
}

/// Runs the segmenter stage until a termination signal. With `run_dir`, it claims each
/// keyframe it takes there, so replicas of the stage share the keyframes out.
pub fn run_segmenter(
    ctx: &RunContext,
    run_dir: Option<&Path>,
    args: &SegmenterArgs,
) -> anyhow::Result<()> {
    let kind: SegmenterKind = args.kind.parse()?;
    let options = SegmenterOptions {
        sam_models: match (&args.encoder, &args.decoder) {
            (Some(e), Some(d)) => Some(SamModelPaths {
                encoder: e.clone(),
                decoder: d.clone(),
            }),
            _ => None,
        },
        proposals: args.proposals.clone(),
        points_per_side: args.points_per_side,
        simulated: args.simulated.params(),
        ensemble: opengs_perception::EnsembleModelPaths {
            tagger: args.tagger.clone(),
            tag_list: args.tag_list.clone(),
            detector: args.detector.clone(),
            text_embeddings: args.text_embeddings.clone(),
        },
        ..SegmenterOptions::default()
    };
    let mut segmenter = kind.create_with(&options)?;
    // Class names of ground-truth instances (the prior segmenter reports them).
    let dataset = open_dataset(&args.dataset.spec()?)?;
    let classes = dataset.class_table();
    let runs_models =
        matches!(kind, SegmenterKind::Sam | SegmenterKind::MobileSamV2) || options.ensemble.any();
    if args.warm_up && runs_models {
        warm_up(segmenter.as_mut(), dataset.intrinsics(), &classes)?;
    }
    drop(dataset);
    let kind_id = SegmenterKind::ALL
        .iter()
        .position(|k| *k == kind)
        .unwrap_or(0) as u32;
    let node = ctx.node(&format!("segmenter_{}", std::process::id()))?;
    let keyframes = Inlet::<KeyframeHeader>::new(ctx, &node, &KEYFRAMES)?;
    let segments = Outlet::<SegmentsHeader>::new(ctx, &node, &SEGMENTS, 640 * 480 * 4 + 4096)?;
    let telemetry = TelemetrySink::new(ctx, &node, "segmenter")?;
    let ws = waitset()?;
    let _guard = ws
        .attach_notification(keyframes.listener())
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    tracing::info!("segmenter '{}' ready", segmenter.name());
    let _heartbeat = ws
        .attach_interval(HEARTBEAT)
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    let longest_call = Duration::from_secs_f64(args.longest_call_s);
    let shortest_call = Duration::from_millis(args.run.min_call_ms);
    let pid = std::process::id();
    let mut claims = match run_dir {
        Some(dir) => {
            let dir = opengs_eval::RunDir::new(dir).segmenter_claims();
            let owner = format!("{pid} {}", segmenter.name());
            match KeyframeClaims::open(&dir, &owner) {
                Ok(c) => Some(c),
                // Alone it needs no claims; replicas would then segment the same keyframes.
                Err(e) => {
                    tracing::warn!(
                        "{}: {e}; keyframes are not claimed (replicas of this stage would \
                         segment the same ones)",
                        dir.display()
                    );
                    None
                }
            }
        }
        None => None,
    };
    telemetry.ready();
    loop {
        match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => return Ok(()),
            Err(e) => anyhow::bail!("WaitSet: {e:?}"),
            Ok(_) => {}
        }
        telemetry.alive();
        // A restarted consensus or mapper gets the newest segmentations (service history).
        if let Err(e) = segments.update_connections() {
            tracing::debug!("{e}");
        }
        keyframes.clear_wakeups();
        let Some(sample) = take_keyframe(&keyframes, &mut claims)? else {
            continue;
        };
        let h = sample.user_header();
        let start = now_ns();
        let view = match h.decode(sample.payload()) {
            Ok(v) => v,
            Err(e) => {
                tracing::error!("keyframe #{} rejected: {e}", h.stamp.seq);
                telemetry.dropped(&h.stamp);
                continue;
            }
        };
        let [fx, fy, cx, cy] = h.intrinsics;
        let input = SegmenterInput {
            width: h.width,
            height: h.height,
            rgb: view.rgb,
            depth: view.depth,
            depth_scale: h.depth_scale,
            intrinsics: Intrinsics::new(fx, fy, cx, cy, h.width, h.height),
            gt_labels: view.labels,
            classes: &classes,
        };
        let seg = segment_alive(segmenter.as_mut(), &input, &telemetry, longest_call);
        // The slow-model stand-in: heartbeats go on while it waits.
        while Duration::from_nanos(now_ns().saturating_sub(start)) < shortest_call {
            let left = shortest_call - Duration::from_nanos(now_ns().saturating_sub(start));
            std::thread::sleep(left.min(HEARTBEAT));
            telemetry.alive();
        }
        let seg = match seg {
            Ok(s) => s,
            Err(e) => {
                // A frame the segmenter cannot handle is skipped, not fatal.
                tracing::error!("keyframe #{}: {e}", h.stamp.seq);
                telemetry.dropped(&h.stamp);
                continue;
            }
        };
        let labels: Vec<SegmentLabel> = seg
            .labels
            .iter()
            .map(|l| SegmentLabel::new(l.label, l.confidence, l.class.as_deref(), l.score))
            .collect();
        let mut stamp = Stamp::derived(MessageKind::Segments, &h.stamp);
        stamp.stage_start_ns = start;
        let header =
            SegmentsHeader::new(stamp, seg.width, seg.height, labels.len() as u32, kind_id);
        segments.send(header, |hd, buf| hd.encode(&seg.label_map, &labels, buf))?;
        telemetry.processed(&h.stamp, start, now_ns());
    }
}

/// Segments a blank frame of the camera's size: a model's first run allocates its buffers
/// and plans its kernels (tiny SAM alone: 760 ms against 540-700 for the next ones).
fn warm_up(
    segmenter: &mut dyn Segmenter,
    k: Intrinsics,
    classes: &[opengs_datasets::InstanceClass],
) -> anyhow::Result<()> {
    let pixels = k.width as usize * k.height as usize;
    let (rgb, depth) = (vec![128u8; pixels * 3], vec![0u16; pixels]);
    let input = SegmenterInput {
        width: k.width,
        height: k.height,
        rgb: &rgb,
        depth: &depth,
        depth_scale: 1000.0,
        intrinsics: k,
        gt_labels: None,
        classes,
    };
    let start = Instant::now();
    segmenter
        .segment(&input)
        .map_err(|e| anyhow::anyhow!("warm-up on a blank frame: {e}"))?;
    tracing::info!(
        "segmenter '{}' warmed up in {:.0} ms",
        segmenter.name(),
        start.elapsed().as_secs_f64() * 1e3
    );
    Ok(())
}

/// The newest waiting keyframe that no other replica has claimed, claimed for this one (older
/// ones are left: another replica may take them, or nobody, when all are busy).
fn take_keyframe(
    keyframes: &Inlet<KeyframeHeader>,
    claims: &mut Option<KeyframeClaims>,
) -> anyhow::Result<Option<Received<KeyframeHeader>>> {
    let (mut newest, mut older, mut taken) = (None, 0, 0);
    while let Some(sample) = keyframes.receive()? {
        let seq = sample.user_header().stamp.seq;
        if claims.as_ref().is_some_and(|c| c.is_claimed(seq)) {
            taken += 1;
        } else if newest.replace(sample).is_some() {
            older += 1;
        }
    }
    if older + taken > 0 {
        tracing::debug!("{older} older keyframes left, {taken} taken by other replicas");
    }
    let Some(sample) = newest else {
        return Ok(None);
    };
    let seq = sample.user_header().stamp.seq;
    let Some(c) = claims.as_mut() else {
        return Ok(Some(sample));
    };
    match c.claim(seq) {
        Ok(true) => Ok(Some(sample)),
        Ok(false) => {
            tracing::debug!("keyframe #{seq}: another replica was first");
            Ok(None)
        }
        Err(e) => {
            tracing::warn!("keyframe #{seq}: cannot claim it ({e}); segmenting it anyway");
            Ok(Some(sample))
        }
    }
}

/// Segments `input` on a thread of its own while this one sends heartbeats, for at most
/// `longest` (a model call can take tens of seconds on a CPU; a process stopped or a call
/// stuck past `longest` falls silent, and the watchdog takes it for hung).
fn segment_alive(
    segmenter: &mut dyn Segmenter,
    input: &SegmenterInput,
    telemetry: &TelemetrySink,
    longest: Duration,
) -> Result<Segmentation, PerceptionError> {
    let started = Instant::now();
    std::thread::scope(|scope| {
        let (done, result) = std::sync::mpsc::channel();
        let call = scope.spawn(move || {
            // The receiver outlives the scope's join below.
            let _ = done.send(segmenter.segment(input));
        });
        loop {
            match result.recv_timeout(HEARTBEAT) {
                Ok(seg) => return seg,
                Err(RecvTimeoutError::Timeout) if started.elapsed() < longest => telemetry.alive(),
                Err(RecvTimeoutError::Timeout) => {}
                // The call panicked: let the stage die of it, as it would without the thread.
                Err(RecvTimeoutError::Disconnected) => match call.join() {
                    Err(panic) => std::panic::resume_unwind(panic),
                    Ok(()) => {
                        return Err(PerceptionError::InvalidInput(
                            "the segmentation ended without a result".into(),
                        ))
                    }
                },
            }
        }
    })
}
