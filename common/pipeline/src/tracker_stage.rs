//! The tracker stage: frames in, a pose for every frame and keyframes out.

use crate::frame_backlog::{FrameBacklog, BACKLOG_FRAMES};
use opengs_geometry::{pose_from_tum, pose_to_tum, Intrinsics};
use opengs_ipc_schema::service::{FRAMES, KEYFRAMES, MAP_TARGET, POSES};
use opengs_ipc_schema::{
    now_ns, FrameHeader, FrameView, KeyframeHeader, KeyframeParts, MapTargetHeader, MessageKind,
    PoseHeader, PoseStatus, Stamp,
};
use opengs_runtime::{
    waitset, CallbackProgression, Inlet, Outlet, RunContext, TelemetrySink, WaitSetRunResult,
    HEARTBEAT,
};
use opengs_tracking::{
    DepthFrame, FrameTracker, MapGaussians, ModelUpdate, TrackOutcome, TrackStatus, TrackerConfig,
};

/// Options of the tracker stage.
#[derive(clap::Args, Debug, Clone)]
pub struct TrackerArgs {
    /// Threads for registration.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    #[command(flatten)]
    pub run: TrackerRunFlags,
    /// Keep tracking against the tracker's own keyframe model even when the mapper sends Gaussians.
    #[arg(long)]
    pub ignore_map: bool,
    /// Set by the supervisor when it restarts the tracker: a TUM file of the verified keyframe
    /// poses and, last, the last verified pose, which the tracker goes on from (not the identity).
    #[arg(long)]
    pub resume: Option<std::path::PathBuf>,
}

/// Writes the poses a restarted tracker goes on from (`poses`: the verified keyframes, then the
/// last verified pose) to `path`; the tracker's arguments that read them.
pub fn resume_args(
    path: &std::path::Path,
    poses: &[opengs_eval::TimedPose],
) -> Result<Vec<String>, opengs_eval::TrajectoryError> {
    opengs_eval::write_tum_trajectory(path, poses)?;
    Ok(vec!["--resume".into(), path.display().to_string()])
}

/// The tracker's flags that `opengs run` sets ([`crate::run_options::StageFlags`]); one struct for
/// parsing and for writing them, so the two cannot disagree.
#[derive(clap::Args, Debug, Clone, Default, PartialEq)]
pub struct TrackerRunFlags {
    /// Start at the frame's ground-truth pose instead of the identity.
    #[arg(long)]
    pub gt_first_pose: bool,
}

impl TrackerRunFlags {
    pub fn to_args(&self) -> Vec<String> {
        match self.gt_first_pose {
            true => vec!["--gt-first-pose".into()],
            false => Vec::new(),
        }
    }
}

fn status_of(s: TrackStatus) -> PoseStatus {
    match s {
        TrackStatus::Initial => PoseStatus::Initial,
        TrackStatus::Tracked => PoseStatus::Tracked,
        TrackStatus::Relocalised => PoseStatus::Relocalised,
        TrackStatus::Lost => PoseStatus::Lost,
        TrackStatus::TooFewPoints => PoseStatus::TooFewPoints,
        TrackStatus::NoDepth => PoseStatus::NoDepth,
    }
}

/// A keyframe message with its planes copied out of the frame.
struct OwnedKeyframe {
    header: KeyframeHeader,
    points: Vec<[f32; 3]>,
    covariances: Vec<[f32; 6]>,
    depth: Vec<u16>,
    labels: Option<Vec<u16>>,
    rgb: Vec<u8>,
}

/// What went out since a start that does not stand yet ([`FrameTracker::keep_start`]): a
/// frame lost before it stands starts tracking again, and what the start given up saw must
/// never reach the map. So its keyframes are held back (ten frames' worth in a normal run),
/// and the poses are kept to be published again as lost.
#[derive(Default)]
struct SinceStart {
    poses: Vec<PoseHeader>,
    keyframes: Vec<OwnedKeyframe>,
}

struct TrackerStage {
    tracker: Option<FrameTracker>,
    /// While the start does not stand.
    since_start: Option<SinceStart>,
    /// Keyframes of a start that stood, going out one per frame, oldest first (newer ones
    /// queue behind them): the mapper renders and the segmenter segments each on its own,
    /// as they would have live. (All at once, one object of the default run fell from
    /// 0.31–0.40 IoU in four runs before any was held to 0.19 in two; one at a time, 0.34–0.35.)
    released: std::collections::VecDeque<OwnedKeyframe>,
    /// Where a restarted tracker goes on from (pose, capture time), and its keyframe poses.
    resume: Option<(opengs_geometry::Pose, f64, Vec<opengs_geometry::Pose>)>,
    /// A map that arrived before the first frame (a restart: the newest map is kept for it).
    early_map: Option<(u64, MapGaussians)>,
    pool: rayon::ThreadPool,
    poses: Outlet<PoseHeader>,
    keyframes: Outlet<KeyframeHeader>,
    telemetry: TelemetrySink,
    gt_first_pose: bool,
}

impl TrackerStage {
    /// Hands the map's trackable Gaussians to the tracker (docs/METHOD.md §7); its model is rebuilt
    /// on the tracker's model thread and used from the frame after it is ready.
    fn handle_map_target(&mut self, h: &MapTargetHeader, payload: &[u8]) {
        let view = match h.decode(payload) {
            Ok(v) => v,
            Err(e) => {
                tracing::error!("map target v{} rejected: {e}", h.map_version);
                return;
            }
        };
        let gaussians = MapGaussians {
            means: view.means.to_vec(),
            rotations: view.rotations.to_vec(),
            scales: view.scales.to_vec(),
        };
        let Some(tracker) = self.tracker.as_mut() else {
            self.early_map = Some((h.stamp.seq, gaussians));
            return;
        };
        tracing::debug!(
            "map v{} as of keyframe #{} ({} Gaussians) to the model thread",
            h.map_version,
            h.stamp.seq,
            gaussians.means.len()
        );
        tracker.set_map(h.stamp.seq, gaussians);
    }

    fn handle(&mut self, h: &FrameHeader, payload: &[u8]) -> anyhow::Result<()> {
        let start = now_ns();
        let view = match h.decode(payload) {
            Ok(v) => v,
            Err(e) => {
                tracing::error!("frame #{} rejected: {e}", h.stamp.seq);
                self.telemetry.dropped(&h.stamp);
                return Ok(());
            }
        };
        let [fx, fy, cx, cy] = h.intrinsics;
        let k = Intrinsics::new(fx, fy, cx, cy, h.width, h.height);
        let gt_first = self.gt_first_pose;
        if self.tracker.is_none() {
            let mut t = FrameTracker::threaded(TrackerConfig::for_width(h.width))?;
            let had_map = self.early_map.is_some();
            if let Some((seq, map)) = self.early_map.take() {
                t.set_map(seq, map);
            }
            if let Some((pose, time, keyframes)) = self.resume.take() {
                tracing::info!(
                    "restarted: going on from the last published pose (t = {time:.3} s); {}",
                    if had_map {
                        "registering against the map"
                    } else {
                        "no map yet: a new model starts there"
                    }
                );
                t.resume_from(pose, time, keyframes);
            }
            self.tracker = Some(t);
        }
        let Some(tracker) = self.tracker.as_mut() else {
            return Ok(());
        };
        // Every frame: a frame that starts tracking again gets the same convention.
        if gt_first && h.has_gt() {
            if let Ok(p) = pose_from_tum(&h.gt_pose) {
                tracker.set_first_pose(p);
            }
        }
        let frame = DepthFrame {
            depth: view.depth,
            depth_scale: h.depth_scale as f64,
            intrinsics: &k,
            timestamp: h.stamp.capture_ns as f64 * 1e-9,
        };
        let out = self.pool.install(|| tracker.track(&frame));
        let last = h.is_last();
        if last {
            // No frame comes to decide: the start stands.
            tracker.keep_start();
        }
        let start_stands = tracker.start_stands();
        log_outcome(h.stamp.seq, &out);
        if let Some(again) = &out.started_again {
            self.give_up_start(h.stamp.seq, &again.why)?;
        }
        let mut stamp = Stamp::derived(MessageKind::Pose, &h.stamp);
        stamp.stage_start_ns = start;
        let pose = PoseHeader {
            stamp,
            pose: pose_to_tum(&out.pose),
            gt_pose: h.gt_pose,
            has_gt: h.has_gt() as u32,
            status: status_of(out.status) as u32,
            is_keyframe: out.keyframe.is_some() as u32,
            iterations: out.iterations as u32,
            inliers: out.inliers as u32,
            overlap: out.overlap.clamp(0.0, 1.0) as f32,
        };
        self.poses.send_header(pose)?;
        if start_stands {
            self.release_start();
            if out.keyframe.is_some() {
                match self.released.is_empty() {
                    true => self.send_keyframe(h, &view, &out, start)?,
                    false => self
                        .released
                        .extend(keyframe_message(h, &view, &out, start)),
                }
            }
            // At the last frame no later one comes to send the rest.
            self.send_released(if last { usize::MAX } else { 1 })?;
        } else {
            let held = self.since_start.get_or_insert_with(SinceStart::default);
            if out.status.has_pose() {
                held.poses.push(pose);
            }
            if out.keyframe.is_some() {
                held.keyframes
                    .extend(keyframe_message(h, &view, &out, start));
            }
        }
        self.telemetry.processed(&h.stamp, start, now_ns());
        Ok(())
    }

    /// The tracker started again at frame `seq`: the keyframes held since the start given
    /// up go nowhere, and its frames' poses are published again as lost (the recorder keeps
    /// the newest pose of a frame).
    fn give_up_start(&mut self, seq: u64, why: &str) -> anyhow::Result<()> {
        let held = self.since_start.take().unwrap_or_default();
        let frames = match (held.poses.first(), held.poses.last()) {
            (Some(a), Some(b)) => format!("frames #{}–#{}", a.stamp.seq, b.stamp.seq),
            _ => "no frame".to_string(),
        };
        tracing::warn!(
            "frame #{seq}: tracking starts again here ({why}); {frames} since the start given \
             up are left out of the map ({} keyframes held back) and counted as lost",
            held.keyframes.len()
        );
        for pose in held.poses {
            self.poses.send_header(PoseHeader {
                status: PoseStatus::Lost as u32,
                is_keyframe: 0,
                ..pose
            })?;
        }
        Ok(())
    }

    /// The start stands: the keyframes held since it go out to the mapper and the segmenter.
    fn release_start(&mut self) {
        if let Some(held) = self.since_start.take() {
            self.released.extend(held.keyframes);
        }
    }

    /// Sends up to `n` released keyframes, oldest first.
    fn send_released(&mut self, n: usize) -> anyhow::Result<()> {
        for _ in 0..n {
            let Some(k) = self.released.pop_front() else {
                break;
            };
            let parts = KeyframeParts {
                points: &k.points,
                covariances: &k.covariances,
                depth: &k.depth,
                labels: k.labels.as_deref(),
                rgb: &k.rgb,
            };
            self.publish_keyframe(k.header, &parts)?;
        }
        Ok(())
    }

    fn publish_keyframe(
        &self,
        header: KeyframeHeader,
        parts: &KeyframeParts,
    ) -> anyhow::Result<()> {
        self.keyframes
            .send(header, |hd, buf| hd.encode(parts, buf))?;
        Ok(())
    }

    /// Keyframe for the mapper: source points and covariances in the world frame, plus the
    /// images (encoded straight from the frame).
    fn send_keyframe(
        &self,
        h: &FrameHeader,
        view: &FrameView,
        out: &TrackOutcome,
        start: u64,
    ) -> anyhow::Result<()> {
        let Some(cloud) = out.world_cloud() else {
            return Ok(());
        };
        let header = keyframe_header(h, view, out, cloud.points.len(), start);
        let parts = KeyframeParts {
            points: &cloud.points,
            covariances: &cloud.covariances,
            depth: view.depth,
            labels: view.labels,
            rgb: view.rgb,
        };
        self.publish_keyframe(header, &parts)
    }
}

fn keyframe_header(
    h: &FrameHeader,
    view: &FrameView,
    out: &TrackOutcome,
    points: usize,
    start: u64,
) -> KeyframeHeader {
    let mut stamp = Stamp::derived(MessageKind::Keyframe, &h.stamp);
    stamp.stage_start_ns = start;
    KeyframeHeader::new(
        stamp,
        pose_to_tum(&out.pose),
        h.intrinsics,
        h.width,
        h.height,
        h.depth_scale,
        points as u32,
        view.labels.is_some(),
        h.frame_index,
    )
}

/// A keyframe held back while the start does not stand (its planes copied out of the frame).
fn keyframe_message(
    h: &FrameHeader,
    view: &FrameView,
    out: &TrackOutcome,
    start: u64,
) -> Option<OwnedKeyframe> {
    let cloud = out.world_cloud()?;
    let header = keyframe_header(h, view, out, cloud.points.len(), start);
    Some(OwnedKeyframe {
        header,
        points: cloud.points,
        covariances: cloud.covariances,
        depth: view.depth.to_vec(),
        labels: view.labels.map(<[u16]>::to_vec),
        rgb: view.rgb.to_vec(),
    })
}

/// Logs what went wrong with a frame, and model changes.
fn log_outcome(seq: u64, out: &TrackOutcome) {
    for update in &out.model_updates {
        match update {
            ModelUpdate::Installed {
                points,
                map_seq,
                keyframes,
            } => tracing::info!(
                "frame #{seq}: tracking against {points} points (map as of keyframe {}, {keyframes} newer keyframes)",
                map_seq.map_or_else(|| "none".to_string(), |s| format!("#{s}"))
            ),
            ModelUpdate::Refused(why) => tracing::warn!("{why}; keeping the current model"),
        }
    }
    tracing::trace!("frame #{seq}: {} iterations", out.iterations);
    if let Some(why) = &out.wide_search {
        tracing::debug!("frame #{seq}: wide search ({why})");
    }
    match (&out.failure, out.status) {
        (Some(why), _) => tracing::warn!("frame #{seq}: {:?} ({why})", out.status),
        (None, TrackStatus::Relocalised) => tracing::warn!(
            "frame #{seq}: relocalised (fitness {:.2}; from {})",
            out.fitness,
            out.relocalised.as_deref().unwrap_or("an unrecorded search")
        ),
        _ => {}
    }
}

/// How long a restarted tracker waits for the mapper's newest map before its first frame.
const RESUME_MAP_WAIT: std::time::Duration = std::time::Duration::from_secs(2);

/// A restarted tracker's map: the newest map target, which the mapper hands to new
/// subscribers (service history); none when there is no mapper or it has no map yet.
fn wait_for_map(
    map_target: &Inlet<MapTargetHeader>,
) -> anyhow::Result<Option<(u64, MapGaussians)>> {
    let started = std::time::Instant::now();
    while started.elapsed() < RESUME_MAP_WAIT {
        if let (Some(sample), _) = map_target.receive_newest()? {
            let h = sample.user_header();
            match h.decode(sample.payload()) {
                Ok(view) => {
                    return Ok(Some((
                        h.stamp.seq,
                        MapGaussians {
                            means: view.means.to_vec(),
                            rotations: view.rotations.to_vec(),
                            scales: view.scales.to_vec(),
                        },
                    )))
                }
                Err(e) => tracing::error!("map target v{} rejected: {e}", h.map_version),
            }
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    tracing::warn!(
        "restarted: no map within {} s; going on with a model of its own",
        RESUME_MAP_WAIT.as_secs()
    );
    Ok(None)
}

/// Runs the tracker stage until a termination signal.
pub fn run_tracker(ctx: &RunContext, args: &TrackerArgs) -> anyhow::Result<()> {
    let node = ctx.node("tracker")?;
    let frames = Inlet::<FrameHeader>::new(ctx, &node, &FRAMES)?;
    let map_target = Inlet::<MapTargetHeader>::new(ctx, &node, &MAP_TARGET)?;
    let resume = match &args.resume {
        Some(path) => {
            let poses = opengs_eval::read_tum_trajectory(path)?;
            let last = poses
                .last()
                .ok_or_else(|| anyhow::anyhow!("--resume {}: no poses", path.display()))?;
            let (pose, time) = (last.pose, last.timestamp);
            Some((pose, time, poses.into_iter().map(|p| p.pose).collect()))
        }
        None => None,
    };
    let mut stage = TrackerStage {
        tracker: None,
        since_start: None,
        released: Default::default(),
        resume,
        early_map: None,
        pool: rayon::ThreadPoolBuilder::new()
            .num_threads(args.threads.max(1))
            .build()?,
        poses: Outlet::new(ctx, &node, &POSES, 8)?,
        keyframes: Outlet::new(ctx, &node, &KEYFRAMES, 640 * 480 * 5 + 12_288 * 36 + 256)?,
        telemetry: TelemetrySink::new(ctx, &node, "tracker")?,
        gt_first_pose: args.run.gt_first_pose,
    };
    let ws = waitset()?;
    let _guard = ws
        .attach_notification(frames.listener())
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    let _heartbeat = ws
        .attach_interval(HEARTBEAT)
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    if stage.resume.is_some() {
        stage.early_map = wait_for_map(&map_target)?;
    }
    stage.telemetry.ready();
    let mut backlog = FrameBacklog::new(BACKLOG_FRAMES);
    let mut last_connect = std::time::Instant::now();
    loop {
        match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => {
                // Stopped before the start stood: what it mapped is all there is, and is kept.
                stage.release_start();
                if let Err(e) = stage.send_released(usize::MAX) {
                    tracing::warn!("keyframes held back since the start could not be sent: {e}");
                }
                return Ok(());
            }
            Err(e) => anyhow::bail!("WaitSet: {e:?}"),
            Ok(_) => {}
        }
        stage.telemetry.alive();
        if last_connect.elapsed() >= HEARTBEAT {
            // A restarted mapper gets the keyframes it missed (the service's history) now,
            // not at the next keyframe, which may never come after the end of data.
            if let Err(e) = stage.keyframes.update_connections() {
                tracing::debug!("{e}");
            }
            last_connect = std::time::Instant::now();
        }
        map_target.clear_wakeups();
        // Only the newest map matters.
        if let (Some(sample), _) = map_target.receive_newest()? {
            if !args.ignore_map {
                stage.handle_map_target(sample.user_header(), sample.payload());
            }
        }
        frames.clear_wakeups();
        loop {
            match backlog.pop() {
                Some(frame) => {
                    stage.handle(&frame.header, frame.payload())?;
                    backlog.recycle(frame);
                }
                None => match frames.receive()? {
                    Some(sample) => stage.handle(sample.user_header(), sample.payload())?,
                    None => break,
                },
            }
            stage.telemetry.alive();
            // What arrived while that frame was tracked waits here, not in the service's
            // 8-frame buffer, which would drop the oldest (crate::frame_backlog).
            while let Some(sample) = frames.receive()? {
                if let Some(old) = backlog.push(sample.user_header(), sample.payload()) {
                    tracing::warn!(
                        "frame #{} dropped: the tracker is {} frames behind",
                        old.stamp.seq,
                        backlog.limit()
                    );
                    stage.telemetry.dropped(&old.stamp);
                }
            }
            if let (Some(sample), _) = map_target.receive_newest()? {
                if !args.ignore_map {
                    stage.handle_map_target(sample.user_header(), sample.payload());
                }
            }
        }
    }
}
