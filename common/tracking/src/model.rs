//! The model the tracker registers against, and where it is built.
//!
//! The model is the map's trackable Gaussians (docs/METHOD.md §7) plus the points of
//! the keyframes the map does not contain yet (before the first map: the
//! keyframes' points alone), at two resolutions for coarse-to-fine
//! registration. Building it (covariances, hash grids, kd-trees) takes tens
//! of milliseconds for 100k Gaussians, several times a second at 30 Hz, so a
//! [`ModelBuilder`] can do it on a thread of its own, on idle CPU time, and hand
//! each model over whole: the tracker never waits for one, it registers against
//! the newest that is ready.

use std::sync::mpsc::{channel, Receiver, Sender, TryRecvError};
use std::thread::JoinHandle;

use opengs_gicp::{Cloud, CoarseToFineTarget, Gaussian, GicpError, Regularization};

/// A model ready to register against.
pub struct TrackingModel {
    target: CoarseToFineTarget,
    /// Seq of the newest keyframe in the map part (`None`: keyframe points only).
    map_seq: Option<u64>,
    /// Keyframe clouds added on top of the map part.
    keyframes: usize,
    /// Seq of the newest keyframe whose points it holds (through the map or its own cloud).
    newest_keyframe: Option<u64>,
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
        })
    }
}

/// Puts the calling thread in Linux's `SCHED_IDLE` class: it runs only on CPU time nothing
/// else wants. A build (after every keyframe and map update) beside the frame being
/// registered slowed it: on 2 cores, frames near a keyframe took 52–66 ms through the
/// pipeline and at most 33 ms alone. An older model for a few more frames costs nothing.
/// Elsewhere the thread keeps its normal priority.
fn run_on_idle_time() {
    #[cfg(target_os = "linux")]
    {
        let param = libc::sched_param { sched_priority: 0 };
        // SAFETY: pid 0 is the calling thread; `param` is a valid, initialised struct.
        let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) };
        if rc != 0 {
            // Not fatal: the builder then competes with the tracker as before.
            eprintln!(
                "tracking-model thread: SCHED_IDLE refused ({})",
                std::io::Error::last_os_error()
            );
        }
    }
}

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
        built: Receiver<Result<TrackingModel, String>>,
        thread: Option<JoinHandle<()>>,
    },
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
    pub fn background(coarse_voxel: f64) -> std::io::Result<Self> {
        let (jobs, job_rx) = channel::<Job>();
        let (built_tx, built) = channel();
        let thread = std::thread::Builder::new()
            .name("tracking-model".into())
            .spawn(move || {
                run_on_idle_time();
                let mut inputs = ModelInputs {
                    coarse_voxel,
                    ..ModelInputs::default()
                };
                while let Ok(first) = job_rx.recv() {
                    let mut refused = Vec::new();
                    let mut pending = Some(first);
                    while let Some(job) = pending {
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
                        if built_tx.send(o).is_err() {
                            return;
                        }
                    }
                }
            })?;
        Ok(Self {
            mode: Mode::Background {
                jobs: Some(jobs),
                built,
                thread: Some(thread),
            },
        })
    }

    fn submit(&mut self, job: Job) {
        match &mut self.mode {
            Mode::Inline { inputs, ready } => {
                let result = inputs
                    .apply(job)
                    .and_then(|()| inputs.build().map_err(|e| e.to_string()));
                ready.push(result);
            }
            Mode::Background { jobs, .. } => {
                // A builder thread that is gone has panicked; tracking goes on with the last model.
                if let Some(tx) = jobs {
                    let _ = tx.send(job);
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

    /// Models (or refusals) finished since the last call, oldest first.
    pub(crate) fn finished(&mut self) -> Vec<Result<TrackingModel, String>> {
        match &mut self.mode {
            Mode::Inline { ready, .. } => std::mem::take(ready),
            Mode::Background { built, .. } => built.try_iter().collect(),
        }
    }

    /// Blocks until the builder has produced something (the very first model only:
    /// the second frame cannot be tracked without it).
    pub(crate) fn wait(&mut self) -> Vec<Result<TrackingModel, String>> {
        match &mut self.mode {
            Mode::Inline { ready, .. } => std::mem::take(ready),
            Mode::Background { built, .. } => built.recv().map(|r| vec![r]).unwrap_or_default(),
        }
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

    #[cfg(target_os = "linux")]
    #[test]
    fn the_builder_thread_runs_on_idle_time_only() {
        let mut b = ModelBuilder::background(0.05).expect("thread");
        // Once it has built a model the thread has set its class.
        b.add_keyframe(1, plane_cloud(0.0, 10));
        assert!(b.wait()[0].is_ok());
        let tasks = std::fs::read_dir("/proc/self/task").expect("/proc/self/task");
        let tid = tasks
            .filter_map(Result::ok)
            .find(|t| {
                std::fs::read_to_string(t.path().join("comm"))
                    .is_ok_and(|c| c.trim() == "tracking-model")
            })
            .and_then(|t| t.file_name().to_str()?.parse::<libc::pid_t>().ok())
            .expect("a thread named tracking-model");
        // SAFETY: reads the scheduling policy of a thread of this process.
        let policy = unsafe { libc::sched_getscheduler(tid) };
        assert_eq!(policy, libc::SCHED_IDLE);
        // The caller's thread keeps its class.
        // SAFETY: pid 0 is the calling thread.
        assert_ne!(unsafe { libc::sched_getscheduler(0) }, libc::SCHED_IDLE);
    }
}
