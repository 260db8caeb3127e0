//! The mapper stage: keyframes in; Gaussians densified and optimised
//! continuously; the trackable Gaussians out to the tracker; the map
//! checkpointed to the run directory and written as `map.ply` at the end.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use opengs_geometry::{pose_from_tum, Intrinsics};
use opengs_ipc_schema::service::{KEYFRAMES, MAP_TARGET};
use opengs_ipc_schema::{
    now_ns, KeyframeHeader, MapTargetHeader, MapTargetParts, MessageKind, Stamp,
};
use opengs_mapping::{DensifyInput, Mapper, MapperConfig, StoredKeyframe};
use opengs_runtime::{
    waitset, CallbackProgression, Inlet, Outlet, RunContext, TelemetrySink, WaitSetRunResult,
};
use opengs_splat::{read_ply_file, write_ply_file, GaussianMap};

/// Options of the mapper stage.
#[derive(clap::Args, Debug, Clone)]
pub struct MapperArgs {
    /// Seconds between map checkpoints.
    #[arg(long, default_value_t = 10.0)]
    pub checkpoint_every: f64,
    /// Optimise at full resolution instead of half.
    #[arg(long)]
    pub full_resolution: bool,
    /// Threads for rendering and optimisation.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
}

const CHECKPOINT: &str = "map_checkpoint.ply";

/// Writes atomically (temp file + rename): a crash mid-write keeps the previous checkpoint.
fn write_map_atomically(map: &GaussianMap, path: &Path) -> anyhow::Result<()> {
    let tmp = path.with_extension("ply.tmp");
    write_ply_file(map, &tmp)?;
    std::fs::rename(&tmp, path)?;
    Ok(())
}

struct MapperStage {
    mapper: Mapper,
    map_target: Outlet<MapTargetHeader>,
    telemetry: TelemetrySink,
    map_version: u32,
    out_dir: PathBuf,
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
        let input = DensifyInput {
            points: view.points,
            covariances: view.covariances,
            pose,
            intrinsics: k,
            rgb: view.rgb,
        };
        let mapper = &mut self.mapper;
        let added = pool.install(|| mapper.add_keyframe(&input, stored));
        tracing::info!(
            "keyframe #{}: +{added} Gaussians ({} in the map, {} keyframes)",
            h.stamp.seq,
            self.mapper.map().len(),
            self.mapper.keyframes()
        );
        self.publish_target(&h.stamp)?;
        self.telemetry.processed(&h.stamp, start, now_ns());
        Ok(())
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

    fn checkpoint(&self) {
        if self.mapper.map().is_empty() {
            return;
        }
        if let Err(e) = write_map_atomically(self.mapper.map(), &self.out_dir.join(CHECKPOINT)) {
            tracing::error!("checkpoint failed: {e:#}");
        }
    }
}

/// Runs the mapper stage until a termination signal; writes `map.ply` and `mapper.json` then.
pub fn run_mapper(ctx: &RunContext, out_dir: &Path, args: &MapperArgs) -> anyhow::Result<()> {
    let node = ctx.node("mapper")?;
    let keyframes = Inlet::<KeyframeHeader>::new(ctx, &node, &KEYFRAMES)?;
    let config = MapperConfig {
        half_resolution: !args.full_resolution,
        ..MapperConfig::default()
    };
    let checkpoint = out_dir.join(CHECKPOINT);
    let mapper = if checkpoint.exists() {
        let map = read_ply_file(&checkpoint)?;
        tracing::info!(
            "resuming from {} ({} Gaussians)",
            checkpoint.display(),
            map.len()
        );
        Mapper::with_map(config, map)
    } else {
        Mapper::new(config)
    };
    let mut stage = MapperStage {
        mapper,
        map_target: Outlet::new(ctx, &node, &MAP_TARGET, 1 << 20)?,
        telemetry: TelemetrySink::new(ctx, &node, "mapper")?,
        map_version: 0,
        out_dir: out_dir.to_path_buf(),
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.max(1))
        .build()?;
    let ws = waitset()?;
    let _guard = ws
        .attach_notification(keyframes.listener())
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    let _tick = ws
        .attach_interval(Duration::from_secs(3600))
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    stage.telemetry.ready();
    let started = Instant::now();
    let mut last_checkpoint = Instant::now();
    loop {
        // Block only when there is nothing to optimise; otherwise just look for news.
        let timeout = if stage.mapper.keyframes() == 0 {
            Duration::from_secs(1)
        } else {
            Duration::ZERO
        };
        match ws.wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, timeout) {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => break,
            Err(e) => anyhow::bail!("WaitSet: {e:?}"),
            Ok(_) => {}
        }
        keyframes.clear_wakeups();
        while let Some(sample) = keyframes.receive()? {
            stage.handle_keyframe(&pool, sample.user_header(), sample.payload())?;
        }
        let mapper = &mut stage.mapper;
        pool.install(|| mapper.step());
        if last_checkpoint.elapsed().as_secs_f64() >= args.checkpoint_every {
            stage.checkpoint();
            last_checkpoint = Instant::now();
        }
    }
    let seconds = started.elapsed().as_secs_f64();
    let map = stage.mapper.map();
    if !map.is_empty() {
        write_map_atomically(map, &out_dir.join("map.ply"))?;
        stage.checkpoint();
    }
    let stats = serde_json::json!({
        "iterations": stage.mapper.iterations(),
        "seconds": seconds,
        "iterations_per_s": stage.mapper.iterations() as f64 / seconds.max(1e-9),
        "gaussians": map.len(),
        "keyframes": stage.mapper.keyframes(),
        "bytes_per_gaussian": GaussianMap::bytes_per_gaussian(),
    });
    std::fs::write(
        out_dir.join("mapper.json"),
        serde_json::to_string_pretty(&stats)?,
    )?;
    tracing::info!("mapper: {stats}");
    Ok(())
}
