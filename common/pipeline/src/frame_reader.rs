//! The sensor's frames, read ahead on a thread that yields to the tracker while it is ahead.
//!
//! Reading a frame (two PNGs decoded) took the sensor about 7 ms of CPU right after it
//! published the previous one: exactly while the tracker registered that frame on the two
//! cores it uses (its median frame 17–22 ms through the pipeline against 13–15 ms alone,
//! fr2_desk's gap region with noise). So frames are read up to [`AHEAD`] ahead on a thread
//! of their own, in Linux's idle policy while at least one read frame waits (CPU time
//! nothing else wants), in the normal policy as soon as none does: a machine whose other
//! stages take every core (a deploy file's mapper at normal priority) then delays frames by
//! a read, not for as long as it is busy. The sensor's main thread only waits and
//! publishes, on time. (At nice 19 throughout, the tracker's median frame was 14.5–18.9 ms
//! against 13.5–15.8 on idle time: a running niced thread still delays each wake-up of the
//! tracker's threads.) A ray-cast source's parallel work runs on rayon's threads, in the
//! normal policy, as before. Where a thread may not leave the idle policy again (no
//! CAP_SYS_NICE and an RLIMIT_NICE under 20, most distributions' default for users), frames
//! are read ahead in the normal policy.

use std::sync::atomic::{AtomicBool, AtomicI32, AtomicUsize, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use opengs_datasets::{RgbdFrame, RgbdSource};
use opengs_tracking::idle_time::{self, may_leave_idle};

/// Frames read and waiting, at most (each about 2 MB at 640×480).
const AHEAD: usize = 2;

/// How often a live source with nothing new looks for appended frames.
const LIVE_POLL: Duration = Duration::from_millis(200);

/// What the reader hands over, in frame order.
pub enum Read {
    Frame(RgbdFrame),
    /// A frame or the source could not be read: the message names it.
    Failed(String),
    /// The data ended (never for a live source).
    End,
}

/// What the sensor's thread and the reading thread share.
struct Shared {
    /// Read frames handed over (or being handed over) and not yet taken.
    waiting: AtomicUsize,
    /// The reading thread's kernel thread id (0 until it runs).
    tid: AtomicI32,
    /// Whether the reading thread may go idle: only where it may leave that policy again.
    idle_ok: bool,
    stop: AtomicBool,
}

/// Frames `start..` of a source, read on their own thread.
pub struct FrameReader {
    frames: Option<Receiver<Read>>,
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

impl FrameReader {
    /// Starts reading `source` from frame `start`; with `live`, after the last frame it
    /// waits for frames a recorder appends instead of ending.
    pub fn spawn(source: Box<dyn RgbdSource>, start: usize, live: bool) -> std::io::Result<Self> {
        let idle_ok = may_leave_idle();
        if !idle_ok {
            tracing::info!(
                "sensor: frames are read in the normal policy (this process may not leave the \
                 idle policy again: no CAP_SYS_NICE, RLIMIT_NICE under 20)"
            );
        }
        Self::spawn_with(source, start, live, idle_ok)
    }

    fn spawn_with(
        source: Box<dyn RgbdSource>,
        start: usize,
        live: bool,
        idle_ok: bool,
    ) -> std::io::Result<Self> {
        // Rayon's global threads inherit the policy of the thread that makes them: made here,
        // in the caller's, so a ray-cast source's parallel work is not idle-only. (Already
        // made, they were made by this process's stage thread: nothing to do.)
        let _ = rayon::ThreadPoolBuilder::new().build_global();
        let (tx, rx) = sync_channel(AHEAD);
        let shared = Arc::new(Shared {
            waiting: AtomicUsize::new(0),
            tid: AtomicI32::new(0),
            idle_ok,
            stop: AtomicBool::new(false),
        });
        let theirs = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("sensor-read".into())
            .spawn(move || read_frames(source, start, live, &tx, &theirs))?;
        Ok(Self {
            frames: Some(rx),
            shared,
            thread: Some(thread),
        })
    }

    /// The next frame, or `None` if none came within `timeout` (the caller keeps its
    /// heartbeat and looks for signals meanwhile). Once no read frame waits, the reading
    /// thread is back in the normal policy.
    pub fn next(&self, timeout: Duration) -> Option<Read> {
        let frames = self.frames.as_ref()?;
        let got = frames.recv_timeout(timeout);
        let behind = match &got {
            Ok(_) => self.shared.waiting.fetch_sub(1, Ordering::SeqCst) == 1,
            Err(_) => true,
        };
        if behind && self.shared.idle_ok {
            idle_time::set_idle(self.shared.tid.load(Ordering::SeqCst), false);
        }
        match got {
            Ok(read) => Some(read),
            Err(RecvTimeoutError::Timeout) => None,
            Err(RecvTimeoutError::Disconnected) => Some(Read::Failed(
                "the frame reading thread stopped unexpectedly".into(),
            )),
        }
    }
}

impl Drop for FrameReader {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        // A reader blocked on a full channel wakes with an error once the receiver is gone.
        self.frames = None;
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn read_frames(
    mut source: Box<dyn RgbdSource>,
    start: usize,
    live: bool,
    tx: &SyncSender<Read>,
    shared: &Shared,
) {
    let tid = idle_time::this_thread();
    shared.tid.store(tid, Ordering::SeqCst);
    let mut index = start;
    while !shared.stop.load(Ordering::Relaxed) {
        if index >= source.len() {
            if !live {
                shared.waiting.fetch_add(1, Ordering::SeqCst);
                let _ = tx.send(Read::End);
                return;
            }
            match source.refresh() {
                Ok(0) => std::thread::sleep(LIVE_POLL),
                Ok(added) => tracing::info!("sensor: {added} new frames recorded"),
                Err(e) => {
                    shared.waiting.fetch_add(1, Ordering::SeqCst);
                    let _ = tx.send(Read::Failed(format!("{}: {e}", source.name())));
                    return;
                }
            }
            continue;
        }
        // Ahead: idle time only. Checked again after the switch, since the sensor may have
        // taken the last waiting frame (and asked for the normal policy) meanwhile.
        if shared.idle_ok && shared.waiting.load(Ordering::SeqCst) > 0 {
            idle_time::set_idle(tid, true);
            if shared.waiting.load(Ordering::SeqCst) == 0 {
                idle_time::set_idle(tid, false);
            }
        }
        // On this thread, in the policy just chosen (a pool's `install` would hand the read
        // to a thread of the normal policy: the tracker's median frame 16.8–20.8 ms against
        // 13.9–17.0).
        let out = match source.frame(index) {
            Ok(frame) => Read::Frame(frame),
            Err(e) => Read::Failed(format!("frame {index}: {e}")),
        };
        let failed = matches!(out, Read::Failed(_));
        shared.waiting.fetch_add(1, Ordering::SeqCst);
        if tx.send(out).is_err() || failed {
            return;
        }
        index += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_datasets::synthetic::{SyntheticOptions, SyntheticSource};
    use opengs_datasets::{DatasetError, InstanceClass};
    use opengs_geometry::Intrinsics;
    use std::sync::mpsc::{channel, Sender};

    fn source(frames: usize) -> Box<dyn RgbdSource> {
        Box::new(
            SyntheticSource::new(SyntheticOptions {
                frames: Some(frames),
                ..SyntheticOptions::default()
            })
            .expect("synthetic room"),
        )
    }

    fn next(reader: &FrameReader) -> Read {
        reader
            .next(Duration::from_secs(30))
            .expect("a frame within 30 s")
    }

    /// A source whose frame `i` is read only once the test allows it, and which says when a
    /// read begins.
    struct Gated {
        allow: Receiver<()>,
        began: Sender<usize>,
    }

    impl RgbdSource for Gated {
        fn name(&self) -> String {
            "gated".into()
        }
        fn intrinsics(&self) -> Intrinsics {
            Intrinsics::new(2.0, 2.0, 1.0, 1.0, 2, 2)
        }
        fn len(&self) -> usize {
            10
        }
        fn frame_rate(&self) -> f64 {
            30.0
        }
        fn frame(&mut self, index: usize) -> Result<RgbdFrame, DatasetError> {
            let _ = self.began.send(index);
            let _ = self.allow.recv();
            Ok(RgbdFrame {
                index,
                timestamp: index as f64 / 30.0,
                width: 2,
                height: 2,
                rgb: vec![0; 12],
                depth: vec![5000; 4],
                depth_scale: 5000.0,
                gt_pose: None,
                labels: None,
            })
        }
        fn class_table(&self) -> Vec<InstanceClass> {
            Vec::new()
        }
    }

    fn policy(reader: &FrameReader) -> libc::c_int {
        // SAFETY: reads the scheduling policy of a thread of this process.
        unsafe { libc::sched_getscheduler(reader.shared.tid.load(Ordering::SeqCst)) }
    }

    #[test]
    fn frames_come_in_order_from_the_start_then_the_end() {
        let reader = FrameReader::spawn(source(5), 2, false).expect("thread");
        for want in 2..5 {
            match next(&reader) {
                Read::Frame(f) => assert_eq!(f.index, want),
                Read::Failed(why) => panic!("frame {want}: {why}"),
                Read::End => panic!("ended before frame {want}"),
            }
        }
        assert!(matches!(next(&reader), Read::End));
    }

    #[test]
    fn reading_ahead_runs_on_idle_time_and_behind_in_the_normal_policy() {
        let (allow, gate) = channel();
        let (began, reads) = channel();
        let reader =
            FrameReader::spawn(Box::new(Gated { allow: gate, began }), 0, false).expect("thread");
        let wait_read = |i: usize| {
            assert_eq!(reads.recv_timeout(Duration::from_secs(10)), Ok(i));
        };
        // Frame 0 with nothing waiting: the normal policy.
        wait_read(0);
        assert_eq!(policy(&reader), libc::SCHED_OTHER);
        allow.send(()).expect("gate");
        // Frame 1 while frame 0 waits: idle time only, where the thread may come back (as root
        // or with CAP_SYS_NICE; elsewhere the normal policy throughout).
        wait_read(1);
        let ahead = match may_leave_idle() {
            true => libc::SCHED_IDLE,
            false => libc::SCHED_OTHER,
        };
        assert_eq!(policy(&reader), ahead);
        // The sensor takes frame 0 while frame 1 is still being read: nothing waits, so the
        // read in progress goes on in the normal policy.
        assert!(matches!(next(&reader), Read::Frame(f) if f.index == 0));
        assert_eq!(policy(&reader), libc::SCHED_OTHER);
        // The caller's own thread keeps its class throughout.
        // SAFETY: pid 0 is the calling thread.
        assert_eq!(unsafe { libc::sched_getscheduler(0) }, libc::SCHED_OTHER);
        allow.send(()).expect("gate");
        assert!(matches!(next(&reader), Read::Frame(f) if f.index == 1));
        // Unblock the reads to come so that dropping the reader ends its thread.
        for _ in 0..10 {
            let _ = allow.send(());
        }
    }

    #[test]
    fn without_leave_to_come_back_the_reader_never_goes_idle() {
        let (allow, gate) = channel();
        let (began, reads) = channel();
        let reader =
            FrameReader::spawn_with(Box::new(Gated { allow: gate, began }), 0, false, false)
                .expect("thread");
        assert_eq!(reads.recv_timeout(Duration::from_secs(10)), Ok(0));
        allow.send(()).expect("gate");
        // Frame 1 while frame 0 waits: still the normal policy.
        assert_eq!(reads.recv_timeout(Duration::from_secs(10)), Ok(1));
        assert_eq!(policy(&reader), libc::SCHED_OTHER);
        for _ in 0..10 {
            let _ = allow.send(());
        }
    }

    #[test]
    fn a_reader_dropped_while_it_waits_on_a_full_queue_stops() {
        let reader = FrameReader::spawn(source(20), 0, false).expect("thread");
        assert!(matches!(next(&reader), Read::Frame(_)));
        // The thread has read ahead and blocks on the full queue; dropping must not hang.
        std::thread::sleep(Duration::from_millis(200));
        drop(reader);
    }
}
