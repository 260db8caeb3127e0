//! The model the tracker registers against, and where it is built.
//!
//! The model is the map's trackable Gaussians (docs/METHOD.md §7) plus the points of
//! the keyframes the map does not contain yet (before the first map: the
//! keyframes' points alone), at two resolutions for coarse-to-fine
//! registration. Building it (covariances, hash grids, kd-trees) takes tens
//! of milliseconds for 100k Gaussians, several times a second at 30 Hz, so a
//! [`ModelBuilder`] can do it on a thread of its own, on idle CPU time (lifted to the
//! normal policy when an input has waited too long), and hand each model over whole: the
//! tracker never waits for one, it registers against the newest that is ready.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicI32, Ordering};
use std::sync::mpsc::{channel, Receiver, Sender, TryRecvError};
use std::sync::{Arc, OnceLock};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::idle_time;

use opengs_geometry::nalgebra::Point3;
use opengs_gicp::{
    Cloud, CoarseToFineTarget, FeatureCloud, Gaussian, GicpError, GlobalConfig, PointTree,
    Regularization,
};

/// A model ready to register against.
pub struct TrackingModel {
    target: CoarseToFineTarget,
    /// Seq of the newest keyframe in the map part (`None`: keyframe points only).
    map_seq: Option<u64>,
    /// Keyframe clouds added on top of the map part.
    keyframes: usize,
    /// Seq of the newest keyframe whose points it holds (through the map or its own cloud).
    newest_keyframe: Option<u64>,
    /// Features for global registration, made when a relocalisation first needs them.
    features: OnceLock<FeatureCloud>,
}

impl TrackingModel {
    pub fn target(&self) -> &CoarseToFineTarget {
        &self.target
    }

    pub fn map_seq(&self) -> Option<u64> {
        self.map_seq
    }

    pub fn keyframes(&self) -> usize {
        self.keyframes
    }

    /// Whether the points of keyframe `seq` are in the model (in the map part, or a
    /// keyframe cloud at least as new).
    pub fn holds_keyframe(&self, seq: u64) -> bool {
        self.newest_keyframe.is_some_and(|n| n >= seq)
    }

    pub fn len(&self) -> usize {
        self.target.len()
    }

    /// The fine points' features for global registration (made on the first call, some
    /// 0.3 s for 50k points; later calls get the same), normals facing the nearest of
    /// `viewpoints` (where the keyframes were taken; none: the origin).
    pub fn features(&self, viewpoints: &[Point3<f64>], config: &GlobalConfig) -> &FeatureCloud {
        self.features.get_or_init(|| {
            let tree = PointTree::new(viewpoints);
            FeatureCloud::new(
                self.target.fine().cloud(),
                |p| {
                    tree.nearest(p)
                        .map_or(Point3::origin(), |(i, _)| viewpoints[i])
                },
                config,
            )
        })
    }

    pub fn is_empty(&self) -> bool {
        self.target.is_empty()
    }
}

/// What happened to the model since the last frame (for the stage's log).
#[derive(Debug, Clone, PartialEq)]
pub enum ModelUpdate {
    /// A new model is in use.
    Installed {
        points: usize,
        map_seq: Option<u64>,
        keyframes: usize,
    },
    /// A map could not be used (the previous model stays).
    Refused(String),
}

/// What models are built from: the newest map and the keyframes newer than it.
#[derive(Default)]
struct ModelInputs {
    map: Option<(u64, Cloud)>,
    keyframes: Vec<(u64, Cloud)>,
    coarse_voxel: f64,
}

/// The map's trackable Gaussians as messages carry them (copied out of shared memory; the
/// conversion to the tracker's terms happens on the builder's thread).
#[derive(Debug, Clone, Default)]
pub struct MapGaussians {
    pub means: Vec<[f32; 3]>,
    /// Unit quaternions (w, x, y, z).
    pub rotations: Vec<[f32; 4]>,
    /// Per-axis standard deviations (m).
    pub scales: Vec<[f32; 3]>,
}

impl MapGaussians {
    fn to_gaussians(&self) -> Vec<Gaussian> {
        self.means
            .iter()
            .zip(&self.rotations)
            .zip(&self.scales)
            .map(|((m, r), s)| Gaussian {
                mean: [m[0] as f64, m[1] as f64, m[2] as f64].into(),
                rotation: r.map(|v| v as f64),
                scale: [s[0] as f64, s[1] as f64, s[2] as f64].into(),
            })
            .collect()
    }
}

/// One change to the inputs.
enum Job {
    Map {
        seq: u64,
        gaussians: MapGaussians,
        regularization: Regularization,
    },
    Keyframe {
        seq: u64,
        cloud: Cloud,
    },
    /// Everything goes: tracking starts again.
    Clear,
}

impl ModelInputs {
    /// Applies a job; `Err` when a map is unusable (the inputs keep the old one).
    fn apply(&mut self, job: Job) -> Result<(), String> {
        match job {
            Job::Map {
                seq,
                gaussians,
                regularization,
            } => {
                let cloud = Cloud::from_gaussians(&gaussians.to_gaussians(), regularization)
                    .map_err(|e| format!("map #{seq}: {e}"))?;
                if let Err(e) = cloud.check_registrable("map") {
                    return Err(format!("map #{seq} cannot fix a pose yet: {e}"));
                }
                self.map = Some((seq, cloud));
                // The map holds every keyframe up to its seq: their own points go.
                self.keyframes.retain(|(s, _)| *s > seq);
            }
            Job::Keyframe { seq, cloud } => self.keyframes.push((seq, cloud)),
            Job::Clear => {
                self.map = None;
                self.keyframes.clear();
            }
        }
        Ok(())
    }

    fn build(&self) -> Result<TrackingModel, GicpError> {
        let mut cloud = self
            .map
            .as_ref()
            .map(|(_, c)| c.clone())
            .unwrap_or_default();
        for (_, k) in &self.keyframes {
            cloud.points.extend_from_slice(&k.points);
            cloud.covariances.extend_from_slice(&k.covariances);
        }
        let target = CoarseToFineTarget::new(cloud, self.coarse_voxel);
        target.fine().check_registrable()?;
        let map_seq = self.map.as_ref().map(|(s, _)| *s);
        Ok(TrackingModel {
            target,
            map_seq,
            keyframes: self.keyframes.len(),
            newest_keyframe: self.keyframes.iter().map(|(s, _)| *s).chain(map_seq).max(),
            features: OnceLock::new(),
        })
    }
}

/// How long a submitted input may wait on a builder in the idle policy before the builder
/// is lifted to the normal one (until it has handed the next model over). Beside stages
/// that take every core (two CPU hogs, a SAM segmenter), idle time never came: the tracker
/// went on against an ever older model and lost the frames it no longer covered.
const STARVED: Duration = Duration::from_millis(300);

/// Builds models inline (deterministic: tests, offline tools) or on a thread.
pub struct ModelBuilder {
    mode: Mode,
}

enum Mode {
    Inline {
        inputs: ModelInputs,
        ready: Vec<Result<TrackingModel, String>>,
    },
    Background {
        jobs: Option<Sender<Job>>,
        /// Each result with the number of jobs applied when it was built.
        built: Receiver<(usize, Result<TrackingModel, String>)>,
        /// The builder thread's kernel id (0 until it runs).
        tid: Arc<AtomicI32>,
        pending: Pending,
        /// Results built before the newest [`ModelBuilder::clear`] (fewer jobs applied) are
        /// of inputs that are gone.
        cleared_at: usize,
        thread: Option<JoinHandle<()>>,
    },
}

/// Jobs submitted and not yet in a result, by when they were submitted.
#[derive(Default)]
struct Pending {
    submitted: usize,
    applied: usize,
    since: VecDeque<Instant>,
}

impl Pending {
    fn submit(&mut self, now: Instant) {
        self.submitted += 1;
        self.since.push_back(now);
    }

    /// A result built with the first `applied` jobs arrived.
    fn built_with(&mut self, applied: usize) {
        while self.applied < applied.min(self.submitted) {
            self.applied += 1;
            self.since.pop_front();
        }
    }

    /// Whether the oldest job not yet in a result has waited `STARVED` or longer.
    fn starved(&self, now: Instant) -> bool {
        self.since
            .front()
            .is_some_and(|t| now.saturating_duration_since(*t) >= STARVED)
    }
}

impl ModelBuilder {
    /// Builds each model when its input arrives, on the caller's thread.
    pub fn inline(coarse_voxel: f64) -> Self {
        Self {
            mode: Mode::Inline {
                inputs: ModelInputs {
                    coarse_voxel,
                    ..ModelInputs::default()
                },
                ready: Vec::new(),
            },
        }
    }

    /// Builds models on a thread of its own; inputs that arrive while it builds are
    /// folded into the next build.
    ///
    /// The first model is built in the normal policy (the tracker's second frame waits for
    /// it), every later one on idle CPU time where the thread may come back from it
    /// ([`idle_time`]): a build beside the frame being registered slowed it (on 2 cores,
    /// frames near a keyframe took 52–66 ms through the pipeline and at most 33 ms alone),
    /// and an older model for a few more frames costs nothing. The thread goes idle only
    /// after it has handed a model over: idle before that, the hand-over itself starved.
    pub fn background(coarse_voxel: f64) -> std::io::Result<Self> {
        let (jobs, job_rx) = channel::<Job>();
        let (built_tx, built) = channel();
        let tid = Arc::new(AtomicI32::new(0));
        let theirs = Arc::clone(&tid);
        let idle_ok = idle_time::may_leave_idle();
        let thread = std::thread::Builder::new()
            .name("tracking-model".into())
            .spawn(move || {
                let me = idle_time::this_thread();
                theirs.store(me, Ordering::SeqCst);
                let mut inputs = ModelInputs {
                    coarse_voxel,
                    ..ModelInputs::default()
                };
                let mut applied = 0;
                while let Ok(first) = job_rx.recv() {
                    let mut refused = Vec::new();
                    let mut pending = Some(first);
                    while let Some(job) = pending {
                        applied += 1;
                        if let Err(e) = inputs.apply(job) {
                            refused.push(e);
                        }
                        pending = match job_rx.try_recv() {
                            Ok(j) => Some(j),
                            Err(TryRecvError::Empty) => None,
                            Err(TryRecvError::Disconnected) => return,
                        };
                    }
                    let mut out: Vec<Result<TrackingModel, String>> =
                        refused.into_iter().map(Err).collect();
                    if inputs.map.is_some() || !inputs.keyframes.is_empty() {
                        out.push(inputs.build().map_err(|e| e.to_string()));
                    }
                    for o in out {
                        if built_tx.send((applied, o)).is_err() {
                            return;
                        }
                    }
                    if idle_ok {
                        idle_time::set_idle(me, true);
                    }
                }
            })?;
        Ok(Self {
            mode: Mode::Background {
                jobs: Some(jobs),
                built,
                tid,
                pending: Pending::default(),
                cleared_at: 0,
                thread: Some(thread),
            },
        })
    }

    fn submit(&mut self, job: Job) {
        match &mut self.mode {
            Mode::Inline { inputs, ready } if matches!(job, Job::Clear) => {
                ready.clear();
                let _ = inputs.apply(job);
            }
            Mode::Inline { inputs, ready } => {
                let result = inputs
                    .apply(job)
                    .and_then(|()| inputs.build().map_err(|e| e.to_string()));
                ready.push(result);
            }
            Mode::Background { jobs, pending, .. } => {
                // A builder thread that is gone has panicked; tracking goes on with the last model.
                if let Some(tx) = jobs {
                    if tx.send(job).is_ok() {
                        pending.submit(Instant::now());
                    }
                }
            }
        }
    }

    /// The map's trackable Gaussians as of keyframe `seq`.
    pub fn set_map(&mut self, seq: u64, gaussians: MapGaussians, regularization: Regularization) {
        self.submit(Job::Map {
            seq,
            gaussians,
            regularization,
        });
    }

    /// A keyframe's new points (world frame), used until a map contains that keyframe.
    pub fn add_keyframe(&mut self, seq: u64, cloud: Cloud) {
        self.submit(Job::Keyframe { seq, cloud });
    }

    /// Drops every input and every model not handed over yet: the next model holds only
    /// what comes after this.
    pub fn clear(&mut self) {
        self.submit(Job::Clear);
        if let Mode::Background {
            pending,
            cleared_at,
            ..
        } = &mut self.mode
        {
            *cleared_at = pending.submitted;
        }
    }

    /// Models (or refusals) finished since the last call, oldest first. A builder that has
    /// starved on idle time (an input waiting [`STARVED`] or longer) is lifted to the normal
    /// policy until its next model is handed over.
    pub(crate) fn finished(&mut self) -> Vec<Result<TrackingModel, String>> {
        match &mut self.mode {
            Mode::Inline { ready, .. } => std::mem::take(ready),
            Mode::Background {
                built,
                pending,
                tid,
                cleared_at,
                ..
            } => {
                let out = built
                    .try_iter()
                    .filter_map(|(applied, result)| {
                        pending.built_with(applied);
                        (applied >= *cleared_at).then_some(result)
                    })
                    .collect();
                if pending.starved(Instant::now()) {
                    lift(tid);
                }
                out
            }
        }
    }

    /// Blocks until the builder has produced something (the very first model only:
    /// the second frame cannot be tracked without it), in the normal policy meanwhile.
    pub(crate) fn wait(&mut self) -> Vec<Result<TrackingModel, String>> {
        match &mut self.mode {
            Mode::Inline { ready, .. } => std::mem::take(ready),
            Mode::Background {
                built,
                pending,
                tid,
                cleared_at,
                ..
            } => {
                lift(tid);
                while let Ok((applied, result)) = built.recv() {
                    pending.built_with(applied);
                    if applied >= *cleared_at {
                        // A builder quicker than this call went idle after its hand-over
                        // and was lifted above, then left waiting in the normal policy:
                        // with nothing left to build it goes back, as after any hand-over.
                        if pending.applied == pending.submitted && idle_time::may_leave_idle() {
                            idle_time::set_idle(tid.load(Ordering::SeqCst), true);
                        }
                        return vec![result];
                    }
                }
                Vec::new()
            }
        }
    }
}

/// Puts the builder thread back in the normal policy if it is idle. It goes idle only where
/// the probe said it may come back, so a refusal is a race with a thread that ended.
fn lift(tid: &AtomicI32) {
    let tid = tid.load(Ordering::SeqCst);
    if idle_time::is_idle(tid) && !idle_time::set_idle(tid, false) {
        eprintln!(
            "tracking-model thread {tid}: the normal policy was refused ({})",
            std::io::Error::last_os_error()
        );
    }
}

impl Drop for ModelBuilder {
    fn drop(&mut self) {
        if let Mode::Background { jobs, thread, .. } = &mut self.mode {
            // Closing the channel ends the thread's loop.
            jobs.take();
            if let Some(t) = thread.take() {
                let _ = t.join();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_gicp::nalgebra::{Matrix3, Point3};

    fn plane_cloud(z: f64, n: usize) -> Cloud {
        let mut points = Vec::new();
        for i in 0..n {
            for j in 0..n {
                points.push(Point3::new(
                    i as f64 * 0.02,
                    j as f64 * 0.02,
                    z + 0.01 * (i % 3) as f64,
                ));
            }
        }
        let covariances = vec![Matrix3::identity(); points.len()];
        Cloud::from_parts(points, covariances).expect("same length")
    }

    fn gaussians(n: usize) -> MapGaussians {
        let means: Vec<[f32; 3]> = plane_cloud(1.0, n)
            .points
            .iter()
            .map(|p| [p.x as f32, p.y as f32, p.z as f32])
            .collect();
        MapGaussians {
            rotations: vec![[1.0, 0.0, 0.0, 0.0]; means.len()],
            scales: vec![[0.01, 0.01, 0.001]; means.len()],
            means,
        }
    }

    #[test]
    fn a_map_replaces_the_keyframes_it_contains() {
        let mut b = ModelBuilder::inline(0.05);
        b.add_keyframe(3, plane_cloud(0.0, 10));
        b.add_keyframe(7, plane_cloud(2.0, 10));
        let models = b.finished();
        let last = models.last().expect("built").as_ref().expect("ok");
        assert_eq!(
            (last.len(), last.keyframes(), last.map_seq()),
            (200, 2, None)
        );
        // A map as of keyframe 5: keyframe 3's points go, keyframe 7's stay.
        b.set_map(5, gaussians(20), Regularization::default());
        let models = b.finished();
        let m = models[0].as_ref().expect("ok");
        assert_eq!(
            (m.len(), m.keyframes(), m.map_seq()),
            (400 + 100, 1, Some(5))
        );
    }

    #[test]
    fn an_unusable_map_is_refused_and_the_old_inputs_stay() {
        let mut b = ModelBuilder::inline(0.05);
        b.add_keyframe(1, plane_cloud(0.0, 10));
        let _ = b.finished();
        let mut bad = gaussians(5);
        bad.rotations[2] = [0.0; 4];
        b.set_map(4, bad, Regularization::default());
        let out = b.finished();
        assert!(
            matches!(&out[0], Err(e) if e.contains("map #4")),
            "{:?}",
            out.len()
        );
    }

    #[test]
    fn the_background_builder_hands_over_whole_models() {
        let mut b = ModelBuilder::background(0.05).expect("thread");
        b.add_keyframe(1, plane_cloud(0.0, 10));
        let first = b.wait();
        assert_eq!(first[0].as_ref().map(TrackingModel::len).ok(), Some(100));
        b.set_map(2, gaussians(20), Regularization::default());
        let mut got = Vec::new();
        while got.is_empty() {
            got = b.wait();
        }
        assert_eq!(got[0].as_ref().map(|m| m.map_seq()).ok(), Some(Some(2)));
    }

    #[test]
    fn a_cleared_builder_builds_only_what_came_after_it() {
        for mut b in [
            ModelBuilder::inline(0.05),
            ModelBuilder::background(0.05).expect("thread"),
        ] {
            b.add_keyframe(0, plane_cloud(0.0, 10));
            b.set_map(0, gaussians(20), Regularization::default());
            // Neither is waited for: a build of them still on its way is not handed over.
            b.clear();
            b.add_keyframe(4, plane_cloud(2.0, 5));
            let mut got = b.finished();
            while got.is_empty() {
                got = b.wait();
            }
            let m = got.pop().expect("built").expect("model");
            assert_eq!((m.len(), m.keyframes(), m.map_seq()), (25, 1, None));
            assert!(got.is_empty(), "{} older models handed over", got.len());
        }
    }

    #[test]
    fn a_model_holds_the_keyframes_of_its_map_and_its_own() {
        let mut b = ModelBuilder::inline(0.05);
        b.add_keyframe(5, plane_cloud(0.0, 10));
        let model = b.finished().pop().expect("built").expect("model");
        assert!(model.holds_keyframe(5) && model.holds_keyframe(0));
        assert!(!model.holds_keyframe(6));
        // A map as of keyframe 9 holds 6 to 9, and not 12.
        b.set_map(9, gaussians(20), Regularization::default());
        let model = b.finished().pop().expect("built").expect("model");
        assert!(model.holds_keyframe(9) && model.holds_keyframe(6));
        assert!(!model.holds_keyframe(12));
    }

    #[test]
    fn an_input_waiting_300_ms_without_a_result_is_starved() {
        let t0 = Instant::now();
        let ms = |n| t0 + Duration::from_millis(n);
        let mut p = Pending::default();
        assert!(!p.starved(ms(10_000)));
        p.submit(ms(0));
        p.submit(ms(200));
        assert!(!p.starved(ms(299)));
        assert!(p.starved(ms(300)));
        // A result built with the first job: the second has waited 100 ms at 300.
        p.built_with(1);
        assert!(!p.starved(ms(300)) && p.starved(ms(500)));
        // A result with both (a count past what was submitted changes nothing more).
        p.built_with(5);
        assert!(!p.starved(ms(10_000)));
        assert_eq!((p.submitted, p.applied), (2, 2));
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn the_builder_thread_runs_on_idle_time_after_the_first_model() {
        let mut b = ModelBuilder::background(0.05).expect("thread");
        let Mode::Background { tid, .. } = &b.mode else {
            panic!("a background builder");
        };
        let tid = Arc::clone(tid);
        let idle_soon = |want: bool| {
            let t0 = Instant::now();
            while idle_time::is_idle(tid.load(Ordering::SeqCst)) != want {
                assert!(
                    t0.elapsed() < Duration::from_secs(10),
                    "never idle = {want}"
                );
                std::thread::sleep(Duration::from_millis(1));
            }
        };
        let may = idle_time::may_leave_idle();
        // The first model is built in the normal policy.
        while tid.load(Ordering::SeqCst) == 0 {
            std::thread::sleep(Duration::from_millis(1));
        }
        assert!(!idle_time::is_idle(tid.load(Ordering::SeqCst)));
        b.add_keyframe(1, plane_cloud(0.0, 10));
        assert!(b.wait()[0].is_ok());
        // Then idle time, where the thread may come back (as root or with CAP_SYS_NICE);
        // elsewhere the normal policy throughout.
        idle_soon(may);
        if may {
            // Lifted, then idle again once it has handed the next model over.
            lift(&tid);
            assert!(!idle_time::is_idle(tid.load(Ordering::SeqCst)));
            b.add_keyframe(2, plane_cloud(1.0, 10));
            assert!(b.wait()[0].is_ok());
            idle_soon(true);
        }
        // The caller's thread keeps its class.
        assert!(!idle_time::is_idle(idle_time::this_thread()));
    }
}
