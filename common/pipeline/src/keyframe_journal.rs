//! The mapper's keyframes on disk (`mapper_keyframes/` in the run directory), so a restarted
//! mapper optimises against every keyframe it had, not only those that come after its
//! restart: the tracker never resends a keyframe, and a map with no targets for its older
//! parts loses detail there (2.4 dB PSNR on the built-in room before this journal).
//!
//! Each keyframe is written once, when it arrives, by a thread of its own (the optimisation
//! never waits for a disk): `<seq>.rgb.png` (8-bit RGB), `<seq>.depth.png` (16-bit, the
//! sensor's units), then a line of `index.txt`:
//! `seq depth_scale fx fy cx cy width height tx ty tz qx qy qz qw` (the pose camera → world,
//! as TUM writes it). A line is appended only after its images are complete, so whatever
//! kills the mapper, the index never names a half-written keyframe; a half-written last
//! line (no newline) is ignored.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, SyncSender, TrySendError};
use std::thread::JoinHandle;

use opengs_geometry::{pose_from_tum, pose_to_tum, Intrinsics, Pose};

/// Keyframes waiting for the writer at most; more are not journalled (said in the log).
const QUEUE: usize = 16;

/// One journalled keyframe, as the mapper received it.
#[derive(Debug, Clone, PartialEq)]
pub struct JournalKeyframe {
    pub seq: u64,
    pub pose: Pose,
    pub intrinsics: Intrinsics,
    /// Depth units per metre.
    pub depth_scale: f32,
    /// RGB8, row-major.
    pub rgb: Vec<u8>,
    pub depth: Vec<u16>,
}

/// Appends keyframes to a run's journal from a writer thread.
pub struct KeyframeJournal {
    queue: Option<SyncSender<JournalKeyframe>>,
    writer: Option<JoinHandle<()>>,
}

impl KeyframeJournal {
    /// Starts the writer for the journal in `dir` (created when missing).
    pub fn start(dir: &Path) -> std::io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        let (queue, jobs) = sync_channel::<JournalKeyframe>(QUEUE);
        let dir = dir.to_path_buf();
        let writer = std::thread::Builder::new()
            .name("keyframe-journal".into())
            .spawn(move || {
                for kf in jobs {
                    if let Err(e) = write_keyframe(&dir, &kf) {
                        tracing::warn!("keyframe journal, keyframe #{}: {e}", kf.seq);
                    }
                }
            })?;
        Ok(Self {
            queue: Some(queue),
            writer: Some(writer),
        })
    }

    /// Queues a keyframe; never blocks (a full queue drops it, with a warning).
    pub fn append(&self, kf: JournalKeyframe) {
        let Some(queue) = &self.queue else { return };
        match queue.try_send(kf) {
            Ok(()) => {}
            Err(TrySendError::Full(kf)) => {
                tracing::warn!(
                    "keyframe journal behind: keyframe #{} not journalled",
                    kf.seq
                )
            }
            Err(TrySendError::Disconnected(kf)) => {
                tracing::warn!(
                    "keyframe journal stopped: keyframe #{} not journalled",
                    kf.seq
                )
            }
        }
    }

    /// Writes what is queued, then stops the writer.
    pub fn finish(&mut self) {
        self.queue = None;
        if let Some(w) = self.writer.take() {
            if w.join().is_err() {
                tracing::error!("keyframe journal writer panicked");
            }
        }
    }
}

impl Drop for KeyframeJournal {
    fn drop(&mut self) {
        self.finish();
    }
}

fn image_path(dir: &Path, seq: u64, what: &str) -> PathBuf {
    dir.join(format!("{seq}.{what}.png"))
}

/// The images, then the index line that names them.
fn write_keyframe(dir: &Path, kf: &JournalKeyframe) -> anyhow::Result<()> {
    let (w, h) = (kf.intrinsics.width, kf.intrinsics.height);
    let rgb = image::RgbImage::from_raw(w, h, kf.rgb.clone())
        .ok_or_else(|| anyhow::anyhow!("{} RGB bytes for {w}x{h}", kf.rgb.len()))?;
    rgb.save(image_path(dir, kf.seq, "rgb"))?;
    let depth = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(w, h, kf.depth.clone())
        .ok_or_else(|| anyhow::anyhow!("{} depth values for {w}x{h}", kf.depth.len()))?;
    depth.save(image_path(dir, kf.seq, "depth"))?;
    let k = &kf.intrinsics;
    let p = pose_to_tum(&kf.pose);
    let line = format!(
        "{} {} {} {} {} {} {} {} {} {} {} {} {} {} {}\n",
        kf.seq,
        kf.depth_scale,
        k.fx,
        k.fy,
        k.cx,
        k.cy,
        w,
        h,
        p[0],
        p[1],
        p[2],
        p[3],
        p[4],
        p[5],
        p[6]
    );
    let mut index = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(dir.join("index.txt"))?;
    // One write of the whole line: a crash leaves it whole or partial, never interleaved.
    index.write_all(line.as_bytes())?;
    Ok(())
}

/// The journal's keyframes in the order they were written. A keyframe whose line or images
/// cannot be read is left out with a warning: the journal helps a restart, it never stops
/// one. No journal: none.
pub fn read_journal(dir: &Path) -> Vec<JournalKeyframe> {
    let index = dir.join("index.txt");
    let text = match std::fs::read_to_string(&index) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Vec::new(),
        Err(e) => {
            tracing::warn!("{}: {e}; no keyframes restored", index.display());
            return Vec::new();
        }
    };
    let complete = text.rfind('\n').map_or("", |i| &text[..i]);
    complete
        .lines()
        .enumerate()
        .filter_map(|(i, line)| match read_entry(dir, line) {
            Ok(kf) => Some(kf),
            Err(e) => {
                tracing::warn!("{}:{}: {e}; keyframe left out", index.display(), i + 1);
                None
            }
        })
        .collect()
}

fn read_entry(dir: &Path, line: &str) -> anyhow::Result<JournalKeyframe> {
    let f: Vec<&str> = line.split_whitespace().collect();
    anyhow::ensure!(f.len() == 15, "expected 15 fields, found {}", f.len());
    let seq: u64 = f[0].parse()?;
    let depth_scale: f32 = f[1].parse()?;
    let num = |i: usize| -> anyhow::Result<f64> {
        let v: f64 = f[i].parse()?;
        anyhow::ensure!(v.is_finite(), "field {} is not finite", i + 1);
        Ok(v)
    };
    let (w, h): (u32, u32) = (f[6].parse()?, f[7].parse()?);
    let intrinsics = Intrinsics::new(num(2)?, num(3)?, num(4)?, num(5)?, w, h);
    intrinsics.validate().map_err(anyhow::Error::msg)?;
    anyhow::ensure!(
        depth_scale.is_finite() && depth_scale > 0.0,
        "bad depth scale"
    );
    let mut tum = [0.0; 7];
    for (j, v) in tum.iter_mut().enumerate() {
        *v = num(8 + j)?;
    }
    let pose = pose_from_tum(&tum)?;
    let rgb = image::open(image_path(dir, seq, "rgb"))?.into_rgb8();
    let depth = image::open(image_path(dir, seq, "depth"))?.into_luma16();
    anyhow::ensure!(
        rgb.dimensions() == (w, h) && depth.dimensions() == (w, h),
        "images are not {w}x{h}"
    );
    Ok(JournalKeyframe {
        seq,
        pose,
        intrinsics,
        depth_scale,
        rgb: rgb.into_raw(),
        depth: depth.into_raw(),
    })
}

#[cfg(test)]
mod tests {
    use opengs_geometry::nalgebra::{Translation3, UnitQuaternion};

    use super::*;

    fn keyframe(seq: u64, w: u32, h: u32) -> JournalKeyframe {
        let n = (w * h) as usize;
        JournalKeyframe {
            seq,
            pose: Pose::from_parts(
                Translation3::new(0.25 * seq as f64, -1.5, 2.0),
                UnitQuaternion::from_euler_angles(0.1, -0.3, 0.05 * seq as f64),
            ),
            intrinsics: Intrinsics::new(40.5, 41.0, 15.5, 11.5, w, h),
            depth_scale: 5000.0,
            rgb: (0..3 * n).map(|i| (i * 7 + seq as usize) as u8).collect(),
            depth: (0..n).map(|i| (i * 131 + 1000) as u16).collect(),
        }
    }

    #[test]
    fn keyframes_come_back_bit_for_bit_in_order() {
        let dir = tempfile::tempdir().expect("tmp");
        let written: Vec<_> = [3, 9, 14].map(|s| keyframe(s, 32, 24)).into();
        let mut journal = KeyframeJournal::start(dir.path()).expect("start");
        for kf in &written {
            journal.append(kf.clone());
        }
        journal.finish();
        let back = read_journal(dir.path());
        assert_eq!(back.len(), 3);
        for (a, b) in written.iter().zip(&back) {
            assert_eq!(
                (a.seq, a.intrinsics, a.depth_scale),
                (b.seq, b.intrinsics, b.depth_scale)
            );
            assert!(
                a.rgb == b.rgb && a.depth == b.depth,
                "#{}: images differ",
                a.seq
            );
            let dt = (a.pose.translation.vector - b.pose.translation.vector).norm();
            assert!(dt < 1e-9 && a.pose.rotation.angle_to(&b.pose.rotation) < 1e-9);
        }
    }

    #[test]
    fn a_torn_or_broken_entry_is_left_out_and_the_rest_restored() {
        let dir = tempfile::tempdir().expect("tmp");
        let mut journal = KeyframeJournal::start(dir.path()).expect("start");
        for s in [1, 2, 3] {
            journal.append(keyframe(s, 16, 12));
        }
        journal.finish();
        // #2's depth image lost; a line cut short by a crash at the end.
        std::fs::remove_file(image_path(dir.path(), 2, "depth")).expect("rm");
        let mut index = std::fs::OpenOptions::new()
            .append(true)
            .open(dir.path().join("index.txt"))
            .expect("open");
        index.write_all(b"4 5000 40.5 41").expect("write");
        let seqs: Vec<u64> = read_journal(dir.path()).iter().map(|k| k.seq).collect();
        assert_eq!(seqs, vec![1, 3]);
        // No journal at all: nothing, no error.
        assert!(read_journal(&dir.path().join("none")).is_empty());
    }
}
