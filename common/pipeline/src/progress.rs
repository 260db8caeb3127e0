//! What `opengs run` shows while stages run: a bar on a terminal, a line every few seconds
//! otherwise.

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use crate::deploy::StageRole;
use crate::stage_process::StageProcess;

/// Progress display: a bar on a terminal, a line every few seconds otherwise.
pub struct Progress {
    bar: Option<indicatif::ProgressBar>,
    last_line: Instant,
}

impl Progress {
    pub fn new(total: Option<usize>) -> Self {
        let bar = std::io::stderr().is_terminal().then(|| {
            let b = indicatif::ProgressBar::new(total.unwrap_or(0) as u64);
            let style = indicatif::ProgressStyle::with_template(
                "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} frames  {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar());
            b.set_style(style);
            b
        });
        Self {
            bar,
            last_line: Instant::now(),
        }
    }

    pub fn update(&mut self, stages: &[StageProcess], poses: usize, started: Instant) {
        let secs = started.elapsed().as_secs_f64().max(1e-3);
        let per_stage: Vec<String> = stages
            .iter()
            .map(|s| {
                let restarts = if s.restarts > 0 {
                    format!(" r{}", s.restarts)
                } else {
                    String::new()
                };
                format!(
                    "{} {:.1}/s{restarts}",
                    s.spec.name,
                    s.processed as f64 / secs
                )
            })
            .collect();
        let msg = per_stage.join("  ");
        let done = stages
            .iter()
            .find(|s| s.spec.role == StageRole::Source)
            .map_or(poses as u64, |s| s.processed);
        match &self.bar {
            Some(b) => {
                b.set_position(done);
                b.set_message(msg);
            }
            None if self.last_line.elapsed() > Duration::from_secs(5) => {
                self.last_line = Instant::now();
                eprintln!("[{secs:6.1} s] {done} frames  {msg}");
            }
            None => {}
        }
    }

    pub fn println(&self, msg: &str) {
        match &self.bar {
            Some(b) => b.println(msg),
            None => eprintln!("{msg}"),
        }
    }

    pub fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}
