//! Relocalisation off the tracking path. A guess costs a coarse alignment, a fine
//! registration and the checks, more than a tracked frame: tried inline every 0.15 s,
//! they made the lost frames after fr2_desk's 12 s teleport the tracker's slowest
//! (p99 63–83 ms against 22–39 ms on every other row). The worker tries one lost frame's
//! guesses at a time on a thread of its own, against the model of that moment (shared,
//! not copied); the tracker reports each lost frame at once and, when a guess has
//! verified, tracks the frame in hand from that pose.
//!
//! A pose found from one view can be centimetres off (scene 1 along fr2_desk's teleport:
//! found 2.60 cm off by global registration, settled by 0.781 against 0.767 for a pose
//! 4.4 cm away), and keyframes taken at once keep the offset in the map. So a found pose is
//! tracked on here, over the lost frames the tracker hands over while the job is out, for
//! [`crate::RelocaliseConfig::track_on_s`] and until it has caught up with the camera, with
//! no keyframe; the answer is the pose it reached, and a pose that fails to track on is
//! no answer. Tracked on in the tracker instead, these frames (half their view unmapped)
//! took 35–125 ms each and put its p99 over 50 ms.

use std::collections::VecDeque;
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;

use opengs_geometry::nalgebra::Point3;
use opengs_geometry::{Intrinsics, Pose};
use opengs_gicp::Cloud;

use crate::attempt::{try_guesses, Found};
use crate::from_prior;
use crate::model::TrackingModel;
use crate::motion::VELOCITY_BASELINE_S;
use crate::{ConstantVelocity, DepthFrame, TrackerConfig};

/// One lost frame and the guesses to try for it.
pub(crate) struct GuessJob {
    pub frame: LostFrame,
    pub guesses: Vec<Pose>,
    /// Where the keyframes were taken: global registration runs when the guesses fail.
    pub viewpoints: Vec<Point3<f64>>,
}

/// A lost frame with the model of its moment: a job's, or one handed over while a job is
/// out, to track a found pose on.
pub(crate) struct LostFrame {
    /// The lost spell it belongs to (answers from an ended spell are dropped).
    pub spell: u64,
    pub timestamp: f64,
    pub depth: Vec<u16>,
    pub depth_scale: f64,
    pub intrinsics: Intrinsics,
    pub cloud: Cloud,
    pub model: Arc<TrackingModel>,
}

impl LostFrame {
    /// A copy of `frame` (the tracker's buffer is not kept) and its source cloud.
    pub(crate) fn new(
        spell: u64,
        frame: &DepthFrame,
        cloud: &Cloud,
        model: &Arc<TrackingModel>,
    ) -> Self {
        Self {
            spell,
            timestamp: frame.timestamp,
            depth: frame.depth.to_vec(),
            depth_scale: frame.depth_scale,
            intrinsics: *frame.intrinsics,
            cloud: cloud.clone(),
            model: Arc::clone(model),
        }
    }

    fn depth_frame(&self) -> DepthFrame<'_> {
        DepthFrame {
            depth: &self.depth,
            depth_scale: self.depth_scale,
            intrinsics: &self.intrinsics,
            timestamp: self.timestamp,
        }
    }
}

/// What the guesses of one job came to.
pub(crate) struct GuessAnswer {
    pub spell: u64,
    /// The time of the last view the pose was tracked on to: where the camera was then.
    pub timestamp: f64,
    pub result: Result<Found, String>,
    /// The motion the pose was tracked on with (no velocity when it was not).
    pub motion: ConstantVelocity,
}

/// The lost frames handed over and not yet taken, oldest first, and whether the tracker
/// is gone.
#[derive(Default)]
struct Handed {
    frames: VecDeque<LostFrame>,
    closed: bool,
}

/// Lost frames kept at most (depth and cloud: up to about 2 MB a frame at 640 × 480):
/// when full, every second one is dropped, so the frames kept still span the search that
/// ran meanwhile, more thinly.
const HANDED_AT_MOST: usize = 16;

/// A found pose waits this long for a lost frame to track it on (the camera stopped).
const FRAMES_STOPPED: std::time::Duration = std::time::Duration::from_secs(2);

/// The frames the tracker hands over and the thread waits on.
type Slot = Arc<(Mutex<Handed>, Condvar)>;

/// The relocalisation thread and the one job it may be working on.
pub(crate) struct RelocaliseWorker {
    jobs: Option<Sender<GuessJob>>,
    answers: Receiver<GuessAnswer>,
    handed: Slot,
    thread: Option<JoinHandle<()>>,
    busy: bool,
}

impl RelocaliseWorker {
    pub(crate) fn spawn(config: TrackerConfig) -> std::io::Result<Self> {
        let (jobs, job_rx) = channel::<GuessJob>();
        let (answer_tx, answers) = channel();
        let handed = Slot::default();
        let slot = Arc::clone(&handed);
        let thread = std::thread::Builder::new()
            .name("relocalise".into())
            .spawn(move || {
                while let Ok(job) = job_rx.recv() {
                    let answer = answer_job(&job, &config, &slot);
                    if answer_tx.send(answer).is_err() {
                        return;
                    }
                }
            })?;
        Ok(Self {
            jobs: Some(jobs),
            answers,
            handed,
            thread: Some(thread),
            busy: false,
        })
    }

    /// Hands over a lost frame while a job is out.
    pub(crate) fn offer(&self, frame: LostFrame) {
        hand_over(&self.handed, frame);
    }

    /// Whether a job is out (one at a time: a lost camera must not queue up work).
    pub(crate) fn is_busy(&self) -> bool {
        self.busy
    }

    /// Hands a job over; `false` when the thread is gone (it panicked), so the caller
    /// can try the guesses itself.
    pub(crate) fn submit(&mut self, job: GuessJob) -> bool {
        if let Ok(mut handed) = self.handed.0.lock() {
            handed.frames.clear();
        }
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
        // Closing the channel ends the thread's loop after its current job; a pose being
        // tracked on stops waiting for frames.
        self.jobs.take();
        let (lock, ready) = &*self.handed;
        if let Ok(mut handed) = lock.lock() {
            handed.closed = true;
            ready.notify_one();
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The guesses of one job, and a found pose tracked on.
fn answer_job(job: &GuessJob, config: &TrackerConfig, slot: &Slot) -> GuessAnswer {
    let lost = &job.frame;
    let found = try_guesses(
        &lost.model,
        config,
        &lost.depth_frame(),
        &lost.cloud,
        &job.guesses,
        Some(&job.viewpoints),
    );
    let mut motion = ConstantVelocity::default();
    let (timestamp, result) = match found {
        Ok(found) => {
            motion.update(found.registration.transform, lost.timestamp);
            track_on(found, job, config, slot, &mut motion)
        }
        Err(why) => (lost.timestamp, Err(why)),
    };
    GuessAnswer {
        spell: lost.spell,
        timestamp,
        result,
        motion,
    }
}

/// Queues a lost frame for the thread (every second one dropped when full).
fn hand_over(slot: &Slot, frame: LostFrame) {
    let (lock, ready) = &**slot;
    if let Ok(mut handed) = lock.lock() {
        if handed.frames.len() >= HANDED_AT_MOST {
            let mut k = 0;
            handed.frames.retain(|_| {
                k += 1;
                k % 2 == 1
            });
        }
        handed.frames.push_back(frame);
        ready.notify_one();
    }
}

/// `found` (on the job's view) tracked on over the lost frames handed over, in steps of at
/// most [`VELOCITY_BASELINE_S`] where the frames allow, for at least `track_on_s` and until
/// the newest frame: the pose at the last of them and its time, or why it failed. Short
/// steps keep a tracked frame's registrations and checks: with steps of up to 0.25 s, and
/// the first from the found pose a wide search, right poses slid 2.4–2.8 cm off on the
/// first step in three of nine runs and once on to 12 cm (back within 0.1 cm by the end);
/// straight from the search's view to the newest frame, 1.2 s later, a right pose fitted
/// 0.699 of a half-mapped view, under the 0.70 a pose without a motion prior needs.
fn track_on(
    found: Found,
    job: &GuessJob,
    config: &TrackerConfig,
    slot: &Slot,
    motion: &mut ConstantVelocity,
) -> (f64, Result<Found, String>) {
    let how = found.how;
    let mut at = job.frame.timestamp;
    let mut views = 0;
    let step = VELOCITY_BASELINE_S;
    let registration = loop {
        let Some((next, newest)) = next_frame(slot, job.frame.spell, at, step) else {
            return (
                at,
                Err(format!("{how}; no later lost view came to track it on")),
            );
        };
        let frame = next.depth_frame();
        let gap = next.timestamp - at > config.wide_search_after_s;
        let r = match from_prior::register(&next.model, config, motion, &frame, &next.cloud, gap).0
        {
            Ok(r) => r,
            Err(why) => {
                return (
                    at,
                    Err(format!(
                        "{how}; tracked on over {views} views, then the view {:.2} s after it \
                         failed: {why}",
                        next.timestamp - job.frame.timestamp
                    )),
                )
            }
        };
        motion.update(r.transform, next.timestamp);
        at = next.timestamp;
        views += 1;
        // A view that fits little of the model is leaving it: the map must grow to follow.
        let leaving = r.fitness < config.relocalise.track_on_min_fitness;
        if leaving || (newest && at - job.frame.timestamp >= config.relocalise.track_on_s) {
            break r;
        }
    };
    let how = format!(
        "{how}; tracked on over {views} later views for {:.2} s",
        at - job.frame.timestamp
    );
    (at, Ok(Found { registration, how }))
}

/// Waits for a lost frame of `spell` newer than `after`, and takes the newest within
/// `step` of it (the oldest newer one when none is), dropping those before it; whether
/// it was the newest handed over. `None`: the tracker is gone, or no frame came for
/// [`FRAMES_STOPPED`].
fn next_frame(slot: &Slot, spell: u64, after: f64, step: f64) -> Option<(LostFrame, bool)> {
    let (lock, ready) = &**slot;
    let mut handed = lock.lock().ok()?;
    loop {
        if handed.closed {
            return None;
        }
        handed
            .frames
            .retain(|f| f.spell == spell && f.timestamp > after);
        if !handed.frames.is_empty() {
            break;
        }
        let (h, waited) = ready.wait_timeout(handed, FRAMES_STOPPED).ok()?;
        handed = h;
        if waited.timed_out() && handed.frames.is_empty() {
            return None;
        }
    }
    let within = handed
        .frames
        .iter()
        .take_while(|f| f.timestamp <= after + step)
        .count();
    for _ in 1..within {
        handed.frames.pop_front();
    }
    let next = handed.frames.pop_front()?;
    Some((next, handed.frames.is_empty()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ModelBuilder;
    use opengs_geometry::nalgebra::Matrix3;

    fn frame(spell: u64, k: usize, model: &Arc<TrackingModel>) -> LostFrame {
        LostFrame {
            spell,
            timestamp: k as f64 / 30.0,
            depth: vec![0; 4],
            depth_scale: 5000.0,
            intrinsics: Intrinsics::new(1.0, 1.0, 1.0, 1.0, 2, 2),
            cloud: Cloud::default(),
            model: Arc::clone(model),
        }
    }

    fn model() -> Arc<TrackingModel> {
        let points: Vec<_> = (0..100)
            .map(|i| Point3::new((i % 10) as f64 * 0.02, (i / 10) as f64 * 0.02, 1.0))
            .collect();
        let covariances = vec![Matrix3::identity() * 1e-4; points.len()];
        let mut builder = ModelBuilder::inline(0.05);
        builder.add_keyframe(
            0,
            Cloud::from_parts(points, covariances).expect("same length"),
        );
        let built = builder.finished().pop().expect("one model");
        Arc::new(built.expect("a model"))
    }

    fn times(slot: &Slot) -> Vec<usize> {
        let handed = slot.0.lock().expect("lock");
        handed
            .frames
            .iter()
            .map(|f| (f.timestamp * 30.0).round() as usize)
            .collect()
    }

    #[test]
    fn frames_handed_over_while_a_search_runs_are_thinned_to_span_it() {
        let (slot, model) = (Slot::default(), model());
        for k in 0..20 {
            hand_over(&slot, frame(1, k, &model));
        }
        // Full at 16: every second one of 0–15 dropped, then 16–19 queued.
        assert_eq!(times(&slot), [0, 2, 4, 6, 8, 10, 12, 14, 16, 17, 18, 19]);
    }

    #[test]
    fn a_found_pose_is_tracked_on_to_the_newest_frame_within_each_step() {
        let (slot, model) = (Slot::default(), model());
        for k in 0..20 {
            hand_over(&slot, frame(1, k, &model));
        }
        // Steps of 0.25 s: from the search's view (frame 0), the newest within 7.5 frames is 6.
        let take = |after: usize| {
            next_frame(&slot, 1, after as f64 / 30.0, 0.25)
                .map(|(f, newest)| ((f.timestamp * 30.0).round() as usize, newest))
        };
        assert_eq!(take(0), Some((6, false)));
        assert_eq!(take(6), Some((12, false)));
        // Within 0.25 s of frame 12: 14, 16, 17, 18, 19; the newest of all.
        assert_eq!(take(12), Some((19, true)));
        // Another spell's frame is not tracked on.
        hand_over(&slot, frame(2, 20, &model));
        hand_over(&slot, frame(1, 21, &model));
        assert_eq!(take(19), Some((21, true)));
        // The tracker gone: no waiting for frames.
        slot.0.lock().expect("lock").closed = true;
        assert_eq!(take(21), None);
    }

    #[test]
    fn a_gap_in_the_frames_is_stepped_over_to_the_next_one() {
        let (slot, model) = (Slot::default(), model());
        for k in [0, 1, 30, 31] {
            hand_over(&slot, frame(1, k, &model));
        }
        let got = next_frame(&slot, 1, 1.0 / 30.0, 0.25).map(|(f, n)| (f.timestamp, n));
        assert_eq!(got, Some((1.0, false)));
    }
}
