//! When the sensor publishes each frame: as the camera delivered it.
//!
//! A frame is due its recorded time after the previous one (`Δt` of the two
//! timestamps), so the frames a recording dropped keep their gap: a camera that
//! lost 0.3 s of frames delivered nothing for 0.3 s, and the stages downstream
//! had that time. A rate cap (`--max-rate`) only ever stretches a step. A
//! timestamp that does not advance falls back to the dataset's nominal period.
//! A sensor that fell behind (a slow disk, a machine under load) publishes at
//! once and does not burst to catch up.

use std::time::{Duration, Instant};

/// Behind schedule by more than this, the schedule restarts from now.
const CATCH_UP_LIMIT: Duration = Duration::from_millis(250);

/// A gap in the recording at least this long is announced in the log.
pub const ANNOUNCED_GAP: Duration = Duration::from_secs(1);

/// A longer gap is replayed this long (a timestamp hours ahead is a broken clock, and a
/// run that waits for it looks hung).
pub const LONGEST_GAP: Duration = Duration::from_secs(60);

/// The publishing schedule of one sensor.
#[derive(Debug, Clone)]
pub struct Pacer {
    /// The dataset's nominal frame period, for timestamps that do not advance.
    nominal: Duration,
    /// The shortest step the rate cap allows (zero: none).
    min_step: Duration,
    /// Whether frames are paced at all (`--max-rate 0`: as fast as possible).
    paced: bool,
    /// The previous frame's due time and timestamp (s).
    previous: Option<(Instant, f64)>,
    /// How far past its scheduled time the last frame was asked for (zero when on time).
    late: Duration,
}

impl Pacer {
    /// `frame_rate`: the dataset's nominal rate (Hz); `max_rate`: the cap (Hz), `Some(0)`
    /// or less for no pacing at all.
    pub fn new(frame_rate: f64, max_rate: Option<f64>) -> Self {
        let period = |hz: f64| match hz.is_finite() && hz > 0.0 {
            true => Duration::from_secs_f64(1.0 / hz),
            false => Duration::ZERO,
        };
        Self {
            nominal: period(frame_rate),
            min_step: max_rate.map_or(Duration::ZERO, period),
            paced: max_rate.is_none_or(|r| r > 0.0),
            previous: None,
            late: Duration::ZERO,
        }
    }

    /// The recorded step before a frame at `timestamp` (s): what the camera took.
    pub fn recorded_step(&self, timestamp: f64) -> Option<Duration> {
        let (_, previous) = self.previous?;
        let dt = timestamp - previous;
        Some(match dt.is_finite() && dt > 0.0 {
            true => Duration::try_from_secs_f64(dt).map_or(LONGEST_GAP, |d| d.min(LONGEST_GAP)),
            false => self.nominal,
        })
    }

    /// When the frame at `timestamp` (s) is due, asked at `now`; the answer becomes the
    /// previous frame's due time for the next call.
    pub fn due(&mut self, timestamp: f64, now: Instant) -> Instant {
        self.late = Duration::ZERO;
        let due = match (self.paced, self.previous, self.recorded_step(timestamp)) {
            (true, Some((last_due, _)), Some(step)) => {
                match last_due.checked_add(step.max(self.min_step)) {
                    Some(due) => {
                        self.late = now.saturating_duration_since(due);
                        match self.late <= CATCH_UP_LIMIT {
                            true => due,
                            false => now,
                        }
                    }
                    None => now,
                }
            }
            _ => now,
        };
        self.previous = Some((due, timestamp));
        due
    }

    /// How late the frame of the last [`Pacer::due`] call was asked for against its
    /// schedule: the time a sensor that reads frames too slowly lost on it.
    pub fn lateness(&self) -> Duration {
        self.late
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    /// Offsets (ms, rounded) of the due times from the first frame's, each asked on time.
    fn schedule(pacer: &mut Pacer, timestamps: &[f64]) -> Vec<u128> {
        let start = Instant::now();
        let mut now = start;
        timestamps
            .iter()
            .map(|&t| {
                let due = pacer.due(t, now);
                now = now.max(due);
                (due.duration_since(start).as_secs_f64() * 1e3).round() as u128
            })
            .collect()
    }

    #[test]
    fn dropped_frames_keep_their_gap() {
        // 30 Hz with frames 2–4 dropped, then a 1.7 s gap (fr2_desk).
        let ts = [
            10.0,
            10.0 + 1.0 / 30.0,
            10.0 + 5.0 / 30.0,
            10.0 + 6.0 / 30.0,
            11.9,
        ];
        let due = schedule(&mut Pacer::new(30.0, None), &ts);
        assert_eq!(due, vec![0, 33, 167, 200, 1900]);
    }

    #[test]
    fn a_rate_cap_stretches_steps_and_keeps_longer_gaps() {
        // 30 Hz capped at 10 Hz: 100 ms steps, but a 300 ms gap stays 300 ms.
        let ts = [0.0, 1.0 / 30.0, 2.0 / 30.0, 2.0 / 30.0 + 0.3];
        let due = schedule(&mut Pacer::new(30.0, Some(10.0)), &ts);
        assert_eq!(due, vec![0, 100, 200, 500]);
    }

    #[test]
    fn timestamps_that_do_not_advance_take_the_nominal_period() {
        let ts = [5.0, 5.0, 4.0, f64::NAN, 5.1];
        let due = schedule(&mut Pacer::new(20.0, None), &ts);
        // 50 ms each; the last one is 5.1 − NaN: nominal too.
        assert_eq!(due, vec![0, 50, 100, 150, 200]);
    }

    #[test]
    fn a_gap_of_hours_is_replayed_as_the_longest_gap() {
        let due = schedule(&mut Pacer::new(30.0, None), &[0.0, 7200.0, 1e300]);
        assert_eq!(due, vec![0, 60_000, 120_000]);
    }

    #[test]
    fn unpaced_is_always_now() {
        let mut pacer = Pacer::new(30.0, Some(0.0));
        let now = Instant::now();
        assert_eq!(pacer.due(0.0, now), now);
        assert_eq!(pacer.due(5.0, now), now);
    }

    #[test]
    fn a_sensor_far_behind_publishes_now_instead_of_bursting() {
        let mut pacer = Pacer::new(30.0, None);
        let start = Instant::now();
        assert_eq!(pacer.due(0.0, start), start);
        // Asked 1 s late for the next frame: due now, and the one after a step later.
        let late = start + Duration::from_secs(1);
        assert_eq!(pacer.due(1.0 / 30.0, late), late);
        let next = pacer.due(2.0 / 30.0, late);
        assert_eq!(next.duration_since(late).as_millis(), 33);
        // A little late (under the limit) keeps the schedule.
        let slightly = next + ms(100);
        let after = pacer.due(3.0 / 30.0, slightly);
        assert_eq!(after.duration_since(next).as_millis(), 33);
        // Asked 100 ms after the previous due time, 33.3 ms after which it was due.
        assert_eq!(pacer.lateness().as_millis(), 66);
        // On time: not late.
        pacer.due(4.0 / 30.0, after);
        assert_eq!(pacer.lateness(), Duration::ZERO);
    }
}
