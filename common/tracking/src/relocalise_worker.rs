//! Relocalisation off the tracking path. A guess costs a coarse alignment, a fine
//! registration and the checks, more than a tracked frame: tried inline every 0.15 s,
//! they made the lost frames after fr2_desk's 12 s teleport the tracker's slowest
//! (p99 63–83 ms against 22–39 ms on every other row). The worker tries one lost frame's
//! guesses at a time on a thread of its own, against the model of that moment (shared,
//! not copied); the tracker reports each lost frame at once and, when a guess has
//! verified, tracks the frame in hand from that pose.

use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::Arc;
use std::thread::JoinHandle;

use opengs_geometry::nalgebra::Point3;
use opengs_geometry::{Intrinsics, Pose};
use opengs_gicp::Cloud;

use crate::attempt::{try_guesses, Found};
use crate::model::TrackingModel;
use crate::{DepthFrame, TrackerConfig};

/// One lost frame and the guesses to try for it.
pub(crate) struct GuessJob {
    /// The lost spell it belongs to (answers from an ended spell are dropped).
    pub spell: u64,
    pub timestamp: f64,
    pub depth: Vec<u16>,
    pub depth_scale: f64,
    pub intrinsics: Intrinsics,
    pub cloud: Cloud,
    pub guesses: Vec<Pose>,
    /// Where the keyframes were taken: global registration runs when the guesses fail.
    pub viewpoints: Vec<Point3<f64>>,
    pub model: Arc<TrackingModel>,
}

/// What the guesses of one job came to.
pub(crate) struct GuessAnswer {
    pub spell: u64,
    /// The job's frame time: a verified pose is where the camera was then.
    pub timestamp: f64,
    pub result: Result<Found, String>,
}

/// The relocalisation thread and the one job it may be working on.
pub(crate) struct RelocaliseWorker {
    jobs: Option<Sender<GuessJob>>,
    answers: Receiver<GuessAnswer>,
    thread: Option<JoinHandle<()>>,
    busy: bool,
}

impl RelocaliseWorker {
    pub(crate) fn spawn(config: TrackerConfig) -> std::io::Result<Self> {
        let (jobs, job_rx) = channel::<GuessJob>();
        let (answer_tx, answers) = channel();
        let thread = std::thread::Builder::new()
            .name("relocalise".into())
            .spawn(move || {
                while let Ok(job) = job_rx.recv() {
                    let frame = DepthFrame {
                        depth: &job.depth,
                        depth_scale: job.depth_scale,
                        intrinsics: &job.intrinsics,
                        timestamp: job.timestamp,
                    };
                    let result = try_guesses(
                        &job.model,
                        &config,
                        &frame,
                        &job.cloud,
                        &job.guesses,
                        Some(&job.viewpoints),
                    );
                    let answer = GuessAnswer {
                        spell: job.spell,
                        timestamp: job.timestamp,
                        result,
                    };
                    if answer_tx.send(answer).is_err() {
                        return;
                    }
                }
            })?;
        Ok(Self {
            jobs: Some(jobs),
            answers,
            thread: Some(thread),
            busy: false,
        })
    }

    /// Whether a job is out (one at a time: a lost camera must not queue up work).
    pub(crate) fn is_busy(&self) -> bool {
        self.busy
    }

    /// Hands a job over; `false` when the thread is gone (it panicked), so the caller
    /// can try the guesses itself.
    pub(crate) fn submit(&mut self, job: GuessJob) -> bool {
        let sent = self.jobs.as_ref().is_some_and(|tx| tx.send(job).is_ok());
        self.busy = sent;
        sent
    }

    /// The answer of the job out, if it is done and belongs to `spell` (answers of an
    /// ended spell are dropped).
    pub(crate) fn answer(&mut self, spell: u64) -> Option<GuessAnswer> {
        let mut mine = None;
        for a in self.answers.try_iter() {
            self.busy = false;
            if a.spell == spell {
                mine = Some(a);
            }
        }
        mine
    }
}

impl Drop for RelocaliseWorker {
    fn drop(&mut self) {
        // Closing the channel ends the thread's loop after its current job.
        self.jobs.take();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
