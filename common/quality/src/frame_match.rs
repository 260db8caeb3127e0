//! Finds the dataset frame of a trajectory timestamp without decoding the whole dataset.
//!
//! trajectory.txt holds frame timestamps (µs precision). Datasets only give timestamps by
//! reading a frame, so the matcher guesses the index from the frame rate and the last frame
//! it read, then narrows a bracket [before, after] of frames known to lie either side.

use opengs_datasets::{DatasetError, RgbdFrame, RgbdSource};

/// A trajectory timestamp matches a frame within this many seconds.
pub const MATCH_TOLERANCE_S: f64 = 1e-3;
/// Reads tried per timestamp before giving up (the bracket normally closes in 1–3).
const MAX_READS: usize = 64;

/// Matches timestamps (in increasing order for speed; any order works) to frames of a source
/// whose timestamps increase with the index.
pub struct FrameMatcher<'a> {
    source: &'a mut dyn RgbdSource,
    fps: f64,
    /// Index and timestamp of the last frame read: the anchor of the next guess.
    anchor: Option<(usize, f64)>,
    reads: usize,
}

impl<'a> FrameMatcher<'a> {
    pub fn new(source: &'a mut dyn RgbdSource) -> Self {
        let fps = source.frame_rate();
        let fps = if fps.is_finite() && fps > 0.0 {
            fps
        } else {
            30.0
        };
        Self {
            source,
            fps,
            anchor: None,
            reads: 0,
        }
    }

    /// Frames read so far (a measure of the search cost).
    pub fn reads(&self) -> usize {
        self.reads
    }

    /// The frame within [`MATCH_TOLERANCE_S`] of `t` (the nearest one, as frames are further
    /// apart than 2 ms), or `None` when the dataset has no such frame.
    pub fn frame_at(&mut self, t: f64) -> Result<Option<RgbdFrame>, DatasetError> {
        let n = self.source.len() as i64;
        // Frames known to be before (lo) and after (hi) t; the match lies strictly between.
        let (mut lo, mut hi) = (-1i64, n);
        let mut guess = match self.anchor {
            Some((i, ti)) => i as i64 + ((t - ti) * self.fps).round() as i64,
            None => 0,
        };
        for _ in 0..MAX_READS {
            if lo + 1 > hi - 1 {
                return Ok(None);
            }
            guess = guess.clamp(lo + 1, hi - 1);
            let frame = self.source.frame(guess as usize)?;
            self.reads += 1;
            self.anchor = Some((guess as usize, frame.timestamp));
            let dt = t - frame.timestamp;
            if dt.abs() <= MATCH_TOLERANCE_S {
                return Ok(Some(frame));
            }
            let step = ((dt.abs() * self.fps).round() as i64).max(1);
            if dt > 0.0 {
                lo = guess;
                guess += step;
            } else {
                hi = guess;
                guess -= step;
            }
        }
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_datasets::InstanceClass;
    use opengs_geometry::Intrinsics;

    /// 2×1 frames at given timestamps.
    struct Timestamps(Vec<f64>);

    impl RgbdSource for Timestamps {
        fn name(&self) -> String {
            "timestamps".into()
        }
        fn intrinsics(&self) -> Intrinsics {
            Intrinsics::new(1.0, 1.0, 0.5, 0.0, 2, 1)
        }
        fn len(&self) -> usize {
            self.0.len()
        }
        fn frame_rate(&self) -> f64 {
            30.0
        }
        fn frame(&mut self, index: usize) -> Result<RgbdFrame, DatasetError> {
            Ok(RgbdFrame {
                index,
                timestamp: self.0[index],
                width: 2,
                height: 1,
                rgb: vec![0; 6],
                depth: vec![1000; 2],
                depth_scale: 1000.0,
                gt_pose: None,
                labels: None,
            })
        }
        fn class_table(&self) -> Vec<InstanceClass> {
            Vec::new()
        }
    }

    #[test]
    fn finds_jittered_frames_skips_missing_ones_and_reads_little() {
        // ~30 fps with jitter and a dropped stretch (frames 40..50 of the clock are missing).
        let times: Vec<f64> = (0..200)
            .filter(|i| !(40..50).contains(i))
            .map(|i| 1305031102.0 + i as f64 / 30.0 + 0.004 * ((i * 7) % 5) as f64)
            .collect();
        let mut source = Timestamps(times.clone());
        let mut m = FrameMatcher::new(&mut source);
        for (i, &t) in times.iter().enumerate().step_by(3) {
            // Trajectory files keep µs precision.
            let t_file = (t * 1e6).round() / 1e6;
            let f = m.frame_at(t_file).expect("reads").expect("present");
            assert_eq!(f.index, i);
        }
        let per_lookup = m.reads() as f64 / times.len().div_ceil(3) as f64;
        assert!(per_lookup < 2.5, "{per_lookup} reads per lookup");
        assert!(m.frame_at(times[10] + 0.015).expect("reads").is_none());
        assert!(m.frame_at(0.0).expect("reads").is_none());
        assert!(m.frame_at(times[189] + 10.0).expect("reads").is_none());
        // Out of order still works.
        assert_eq!(
            m.frame_at(times[5]).expect("reads").map(|f| f.index),
            Some(5)
        );
    }
}
