//! The camera clock: which ticks of a fixed-rate clock become frames. A real
//! camera that misses a frame leaves a hole in its timestamps; it does not
//! repeat the previous image. Frames here keep their tick (`t = tick / fps`),
//! so every drop, from the mocap rows or from the stress options, shows as
//! a jump in the timestamps.

use opengs_geometry::Pose;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::trajectory::StampedPose;

/// Stream of the random frame drops, apart from the loop's jitter stream of the same seed.
const DROP_STREAM: u64 = 0xD0D0_5EED;

/// A frame on the camera clock: tick `k` is at `k / fps` seconds from the path's start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockFrame {
    pub tick: u64,
    pub pose: Pose,
}

/// Clock ticks without a frame just before frame `frame`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gap {
    /// Index of the first frame after the gap.
    pub frame: usize,
    /// Timestamp of that frame (seconds).
    pub time_s: f64,
    /// Clock ticks dropped.
    pub dropped: usize,
    /// Seconds of the clock with no frame (`dropped / fps`).
    pub missing_s: f64,
}

/// Samples a trajectory on a clock of `fps` ticks per second starting at its
/// first row: a tick takes the nearest row within half a frame period, and a
/// tick with no row that close is dropped (the camera "dropped that frame").
pub fn sample_trajectory(trajectory: &[StampedPose], fps: f64) -> Vec<ClockFrame> {
    let (Some(first), Some(last)) = (trajectory.first(), trajectory.last()) else {
        return Vec::new();
    };
    let times: Vec<f64> = trajectory.iter().map(|(t, _)| *t).collect();
    let ticks = ((last.0 - first.0) * fps).floor() as u64 + 1;
    let half_period = 0.5 / fps;
    (0..ticks)
        .filter_map(|tick| {
            let t = first.0 + tick as f64 / fps;
            crate::text::nearest_within(&times, t, half_period).map(|i| ClockFrame {
                tick,
                pose: trajectory[i].1,
            })
        })
        .collect()
}

/// The nearest row for every tick, gaps or not: the sampling the fixed
/// room's placement was fitted on before ticks could be dropped, kept so
/// that scene 0 places a trajectory exactly as it always did.
pub fn nearest_per_tick(trajectory: &[StampedPose], fps: f64) -> Vec<Pose> {
    let (Some(first), Some(last)) = (trajectory.first(), trajectory.last()) else {
        return Vec::new();
    };
    let times: Vec<f64> = trajectory.iter().map(|(t, _)| *t).collect();
    let ticks = ((last.0 - first.0) * fps).floor() as u64 + 1;
    (0..ticks)
        .filter_map(|tick| {
            let t = first.0 + tick as f64 / fps;
            crate::text::nearest_within(&times, t, f64::INFINITY).map(|i| trajectory[i].1)
        })
        .collect()
}

/// First tick at or after `start_s` seconds.
pub fn start_tick(start_s: f64, fps: f64) -> u64 {
    // The epsilon keeps e.g. 10 s × 30 Hz on tick 300 despite rounding.
    (start_s * fps - 1e-9).ceil().max(0.0) as u64
}

/// Frames from `start_s` seconds on.
pub fn window(frames: Vec<ClockFrame>, start_s: f64, fps: f64) -> Vec<ClockFrame> {
    let first = start_tick(start_s, fps);
    frames.into_iter().filter(|f| f.tick >= first).collect()
}

/// Every `speed`-th tick from `first_tick`, re-timed onto the same clock, so
/// the camera moves `speed` times faster per frame; drops stay drops.
pub fn speed_up(frames: Vec<ClockFrame>, first_tick: u64, speed: usize) -> Vec<ClockFrame> {
    let k = speed.max(1) as u64;
    frames
        .into_iter()
        .filter(|f| f.tick >= first_tick && (f.tick - first_tick).is_multiple_of(k))
        .map(|f| ClockFrame {
            tick: first_tick + (f.tick - first_tick) / k,
            pose: f.pose,
        })
        .collect()
}

/// Drops `rate` of the frames at random, in bursts of `burst` consecutive
/// frames: the frames are cut into blocks of `burst` and `round(rate ·
/// blocks)` blocks go (at least one block always stays). Deterministic for `seed`.
pub fn drop_bursts(frames: Vec<ClockFrame>, rate: f64, burst: usize, seed: u64) -> Vec<ClockFrame> {
    if rate <= 0.0 || frames.is_empty() {
        return frames;
    }
    let burst = burst.max(1);
    let blocks = frames.len().div_ceil(burst);
    let dropped_blocks = ((rate * blocks as f64).round() as usize).min(blocks - 1);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ DROP_STREAM);
    let mut dropped = vec![false; blocks];
    for b in rand::seq::index::sample(&mut rng, blocks, dropped_blocks) {
        dropped[b] = true;
    }
    frames
        .into_iter()
        .enumerate()
        .filter(|(i, _)| !dropped[i / burst])
        .map(|(_, f)| f)
        .collect()
}

/// Every hole in the ticks of consecutive frames.
pub fn gaps(frames: &[ClockFrame], fps: f64) -> Vec<Gap> {
    frames
        .windows(2)
        .enumerate()
        .filter_map(|(i, w)| {
            let dropped = w[1].tick.saturating_sub(w[0].tick + 1) as usize;
            (dropped > 0).then(|| Gap {
                frame: i + 1,
                time_s: w[1].tick as f64 / fps,
                dropped,
                missing_s: dropped as f64 / fps,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn clock(ticks: impl IntoIterator<Item = u64>) -> Vec<ClockFrame> {
        ticks
            .into_iter()
            .map(|tick| ClockFrame {
                tick,
                pose: Pose::identity(),
            })
            .collect()
    }

    fn ticks(frames: &[ClockFrame]) -> Vec<u64> {
        frames.iter().map(|f| f.tick).collect()
    }

    #[test]
    fn ticks_without_a_row_are_dropped_not_frozen() {
        // Rows at 100 Hz for 1 s, none in [0.4, 0.6), rows again to 1 s.
        let rows: Vec<StampedPose> = (0..=100)
            .filter(|i| !(40..60).contains(i))
            .map(|i| (100.0 + i as f64 / 100.0, Pose::identity()))
            .collect();
        let frames = sample_trajectory(&rows, 10.0);
        // Tick 4 (0.4 s) has the row at 0.39 s within 0.05 s; ticks 5 has none.
        assert_eq!(ticks(&frames), vec![0, 1, 2, 3, 4, 6, 7, 8, 9, 10]);
        let g = gaps(&frames, 10.0);
        assert_eq!(g.len(), 1);
        assert_eq!((g[0].frame, g[0].dropped), (5, 1));
        assert!((g[0].time_s - 0.6).abs() < 1e-12 && (g[0].missing_s - 0.1).abs() < 1e-12);
    }

    #[test]
    fn window_and_speed_retime_the_clock() {
        let frames = window(clock(0..100), 1.0, 30.0);
        assert_eq!(frames[0].tick, 30);
        assert_eq!(frames.len(), 70);
        let fast = speed_up(frames, 30, 3);
        // Ticks 30, 33, …, 99 become 30, 31, …, 53.
        assert_eq!(ticks(&fast), (30..54).collect::<Vec<_>>());
        // A missing tick that would have been kept stays missing.
        let holed = clock((0..30).filter(|&t| t != 6));
        assert_eq!(
            ticks(&speed_up(holed, 0, 3)),
            vec![0, 1, 3, 4, 5, 6, 7, 8, 9]
        );
    }

    #[test]
    fn drops_come_in_bursts_with_the_expected_count() {
        let frames = clock(0..400);
        let kept = drop_bursts(frames.clone(), 0.25, 5, 7);
        // 80 blocks of 5, 20 of them dropped.
        assert_eq!(kept.len(), 300);
        let g = gaps(&kept, 30.0);
        assert!(g.iter().all(|g| g.dropped % 5 == 0), "{g:?}");
        assert!(!g.is_empty());
        assert_eq!(kept, drop_bursts(frames.clone(), 0.25, 5, 7));
        assert_ne!(kept, drop_bursts(frames.clone(), 0.25, 5, 8));
        // A rate that rounds to every block still leaves one.
        assert_eq!(drop_bursts(clock(0..4), 0.9, 1, 1).len(), 1);
    }
}
