//! The watchdog's clock: how long a stage has been silent *by its own fault*.
//!
//! A stage is hung when it sends nothing (no output, no heartbeat) for longer than its
//! `watchdog_s`. Wall time alone cannot say that of an idle-scheduled stage (the mapper):
//! on a busy machine the kernel may not run it for seconds, and it is then starved, not
//! hung, and a restart would not help. So silence is counted in the supervisor's ticks,
//! and a tick does not count while the process wants a CPU and does not get one:
//!
//! ```text
//!   starved tick  ⇔  some thread is runnable ('R' in /proc/PID/task/*/stat)
//!                    ∧ the process got < ½ of the tick's wall time as CPU time
//!   silence       =  Σ over ticks since last heard of (starved ? 0 : tick)
//! ```
//!
//! A SIGSTOPped process ('T'), a deadlocked one ('S'/'D', waiting on itself) and one that
//! spins without heartbeats while it gets the CPU all accumulate silence at wall speed. A
//! process that spins *and* is starved cannot be told from a starved one; it waits until
//! the machine has time for it. Without `/proc` every tick counts (plain wall time).

use std::time::{Duration, Instant};

/// What `/proc` says about a process at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CpuSample {
    /// Some thread is running or waiting on a run queue.
    pub runnable: bool,
    /// User + system CPU time of all its threads, in clock ticks.
    pub cpu_ticks: u64,
}

/// Reads every thread's state and CPU time; `None` when the process or `/proc` is gone.
pub fn sample_process(pid: u32) -> Option<CpuSample> {
    let tasks = std::fs::read_dir(format!("/proc/{pid}/task")).ok()?;
    let mut sample = CpuSample {
        runnable: false,
        cpu_ticks: 0,
    };
    let mut any = false;
    for task in tasks.flatten() {
        // A thread that exits between the listing and the read is skipped.
        let Ok(stat) = std::fs::read_to_string(task.path().join("stat")) else {
            continue;
        };
        let Some((state, ticks)) = parse_stat(&stat) else {
            continue;
        };
        any = true;
        sample.runnable |= state == 'R';
        sample.cpu_ticks += ticks;
    }
    any.then_some(sample)
}

/// State and utime + stime from one `/proc/…/stat` line. The command name in parentheses
/// may hold spaces and parentheses, so fields are counted from the last ')'.
fn parse_stat(stat: &str) -> Option<(char, u64)> {
    let rest = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // After the name: state is field 3 of the line (index 0 here), utime 14, stime 15.
    let state = fields.first()?.chars().next()?;
    let utime: u64 = fields.get(11)?.parse().ok()?;
    let stime: u64 = fields.get(12)?.parse().ok()?;
    Some((state, utime + stime))
}

/// Clock ticks per second (`sysconf(_SC_CLK_TCK)`, 100 on Linux).
fn clock_ticks_per_s() -> f64 {
    // SAFETY: sysconf has no preconditions.
    let t = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if t > 0 {
        t as f64
    } else {
        100.0
    }
}

/// Silence of one process, excluding the ticks it spent starved of CPU.
#[derive(Debug, Clone)]
pub struct SilenceClock {
    last_tick: Instant,
    last_sample: Option<CpuSample>,
    silent: Duration,
    ticks_per_s: f64,
}

impl SilenceClock {
    pub fn new(now: Instant) -> Self {
        Self {
            last_tick: now,
            last_sample: None,
            silent: Duration::ZERO,
            ticks_per_s: clock_ticks_per_s(),
        }
    }

    /// The process was heard from (or started): silence starts again from zero.
    pub fn heard(&mut self, now: Instant) {
        self.last_tick = now;
        self.last_sample = None;
        self.silent = Duration::ZERO;
    }

    /// Advances to `now` with the process's sample at `now` (`None`: unknown, the tick
    /// counts) and returns the silence so far.
    pub fn tick(&mut self, now: Instant, sample: Option<CpuSample>) -> Duration {
        let wall = now.saturating_duration_since(self.last_tick);
        self.last_tick = now;
        let starved = match (self.last_sample, sample) {
            (Some(before), Some(after)) => {
                let cpu_s =
                    after.cpu_ticks.saturating_sub(before.cpu_ticks) as f64 / self.ticks_per_s;
                after.runnable && cpu_s < 0.5 * wall.as_secs_f64()
            }
            // The first tick of a silence has nothing to compare with.
            _ => false,
        };
        self.last_sample = sample;
        if !starved {
            self.silent += wall;
        }
        self.silent
    }

    /// When the clock last advanced (or was reset).
    pub fn last_tick(&self) -> Instant {
        self.last_tick
    }

    /// Silence so far, without advancing.
    pub fn silent(&self) -> Duration {
        self.silent
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(start: Instant, ms: u64) -> Instant {
        start + Duration::from_millis(ms)
    }

    fn clock(start: Instant) -> SilenceClock {
        let mut c = SilenceClock::new(start);
        c.ticks_per_s = 100.0;
        c
    }

    #[test]
    fn parses_a_stat_line_with_a_hostile_command_name() {
        // Fields after the name: state ppid pgrp session tty tpgid flags minflt cminflt
        // majflt cmajflt utime stime ...
        let line = "4242 (opengs) (x) R) S 1 4242 4242 0 -1 4194304 10 0 0 0 250 17 0 0 20 0";
        assert_eq!(parse_stat(line), Some(('S', 267)));
        assert_eq!(parse_stat("4242 (short) R 1 2"), None);
        assert_eq!(parse_stat("no parenthesis"), None);
    }

    #[test]
    fn a_stopped_process_is_silent_at_wall_speed() {
        let t0 = Instant::now();
        let mut c = clock(t0);
        let stopped = Some(CpuSample {
            runnable: false,
            cpu_ticks: 500,
        });
        for k in 1..=10 {
            c.tick(at(t0, 500 * k), stopped);
        }
        assert_eq!(c.silent(), Duration::from_millis(5000));
    }

    #[test]
    fn a_starved_process_is_not_silent_and_a_spinning_one_is() {
        let t0 = Instant::now();
        // Runnable, 1 tick (10 ms) of CPU per 500 ms tick: waiting for a CPU.
        let mut starved = clock(t0);
        for k in 0..=10u64 {
            starved.tick(
                at(t0, 500 * k),
                Some(CpuSample {
                    runnable: true,
                    cpu_ticks: 100 + k,
                }),
            );
        }
        // Only the first tick counts (nothing to compare with yet): 0 ms after t0.
        assert_eq!(starved.silent(), Duration::ZERO);
        // Runnable and on the CPU the whole time (50 ticks per 500 ms): spinning, hung.
        let mut spinning = clock(t0);
        for k in 0..=10u64 {
            spinning.tick(
                at(t0, 500 * k),
                Some(CpuSample {
                    runnable: true,
                    cpu_ticks: 100 + 50 * k,
                }),
            );
        }
        assert_eq!(spinning.silent(), Duration::from_millis(5000));
    }

    #[test]
    fn hearing_from_the_process_resets_the_silence() {
        let t0 = Instant::now();
        let mut c = clock(t0);
        c.tick(at(t0, 3000), None);
        assert_eq!(c.silent(), Duration::from_secs(3));
        c.heard(at(t0, 3000));
        assert_eq!(c.tick(at(t0, 3200), None), Duration::from_millis(200));
    }

    /// A spinning shell pinned to CPU 0, idle-scheduled if asked.
    fn spinner(idle: bool) -> std::process::Child {
        use std::os::unix::process::CommandExt;
        let mut cmd = std::process::Command::new("sh");
        cmd.args(["-c", "while :; do :; done"]);
        // SAFETY: only async-signal-safe libc calls between fork and exec.
        unsafe {
            cmd.pre_exec(move || {
                let mut set: libc::cpu_set_t = std::mem::zeroed();
                libc::CPU_SET(0, &mut set);
                libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set);
                if idle {
                    let param = libc::sched_param { sched_priority: 0 };
                    libc::sched_setscheduler(0, libc::SCHED_IDLE, &param);
                }
                Ok(())
            });
        }
        cmd.spawn().expect("sh")
    }

    #[test]
    fn an_idle_process_starved_by_a_busy_cpu_is_not_counted_silent() {
        let busy = spinner(false);
        let idle = spinner(true);
        let t0 = Instant::now();
        let mut c = SilenceClock::new(t0);
        let mut runnable = 0;
        for _ in 0..8 {
            std::thread::sleep(Duration::from_millis(250));
            let sample = sample_process(idle.id());
            runnable += usize::from(sample.is_some_and(|s| s.runnable));
            c.tick(Instant::now(), sample);
        }
        for mut child in [busy, idle] {
            let _ = child.kill();
            let _ = child.wait();
        }
        assert_eq!(runnable, 8, "the starved spinner waits on the run queue");
        // Only the first tick (nothing to compare with) counts: 2 s of wall time, ~0.25 s silent.
        assert!(
            c.silent() < Duration::from_millis(700),
            "silent {:?} of {:?}",
            c.silent(),
            t0.elapsed()
        );
    }

    #[test]
    fn proc_tells_a_stopped_child_from_a_running_one() {
        let mut child = std::process::Command::new("sh")
            .args(["-c", "while :; do :; done"])
            .spawn()
            .expect("sh");
        let pid = child.id();
        std::thread::sleep(Duration::from_millis(300));
        let running = sample_process(pid).expect("a live child has a /proc entry");
        assert!(running.runnable, "a spinning shell is runnable");
        // SAFETY: signalling our own child.
        unsafe { libc::kill(pid as i32, libc::SIGSTOP) };
        std::thread::sleep(Duration::from_millis(300));
        let stopped = sample_process(pid).expect("a stopped child has a /proc entry");
        assert!(!stopped.runnable, "a stopped shell is not runnable");
        let _ = child.kill();
        let _ = child.wait();
        assert_eq!(
            sample_process(pid),
            None,
            "a reaped child has no /proc entry"
        );
    }
}
