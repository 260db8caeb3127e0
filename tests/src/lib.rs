//! Support for the end-to-end tests in `tests/tests/`: locating the built
//! binaries, and the frame checksum the probe process and the tests share.

use std::path::PathBuf;
use std::sync::{Mutex, MutexGuard};

/// One pipeline at a time: the tests of a file run in parallel threads, and two
/// real-time pipelines on a 2-core machine would starve each other's trackers.
pub fn serial() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// FNV-1a over a frame's planes: cheap, and any flipped byte changes it.
pub fn frame_checksum(depth: &[u16], rgb: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |b: u8| {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    };
    for d in depth {
        for b in d.to_le_bytes() {
            eat(b);
        }
    }
    for &b in rgb {
        eat(b);
    }
    h
}

/// A workspace binary in the same target directory as the running test.
pub fn binary(name: &str) -> PathBuf {
    let exe = std::env::current_exe().unwrap_or_default();
    // Test executables live in target/<profile>/deps; binaries one level up.
    let dir = exe
        .parent()
        .and_then(|d| d.parent())
        .map(PathBuf::from)
        .unwrap_or_default();
    let path = dir.join(name);
    assert!(
        path.exists(),
        "{} is not built; run `cargo build --release --workspace --bins` (the README test command does)",
        path.display()
    );
    path
}

/// `opengs run --quiet --run-id ID --out OUT` with stdout and stderr piped; each test adds
/// its own options (dataset size, rate, deploy file, ...).
pub fn opengs_run(run_id: &str, out: &std::path::Path) -> std::process::Command {
    let mut cmd = std::process::Command::new(binary("opengs"));
    cmd.args(["run", "--quiet", "--run-id", run_id])
        .arg("--out")
        .arg(out)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped());
    cmd
}

/// `opengs ctl --run ID status --json`, parsed; `None` while the run does not answer yet.
pub fn ctl_status(run_id: &str) -> Option<serde_json::Value> {
    let out = std::process::Command::new(binary("opengs"))
        .args(["ctl", "--run", run_id, "status", "--json"])
        .output()
        .ok()?;
    serde_json::from_slice(&out.stdout).ok()
}

/// The pid of a stage of a running pipeline, from `ctl status`.
pub fn stage_pid(run_id: &str, stage: &str) -> Option<i32> {
    let st = ctl_status(run_id)?;
    let stages = st["stages"].as_array()?;
    let s = stages.iter().find(|s| s["name"] == stage)?;
    s["pid"].as_u64().map(|p| p as i32)
}

/// SIGINT (Ctrl-C) to a running `opengs run`; its exit status, which must come `within`.
pub fn interrupt(
    child: &mut std::process::Child,
    within: std::time::Duration,
) -> std::process::ExitStatus {
    // SAFETY: signalling a child process the caller started.
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let started = std::time::Instant::now();
    loop {
        if let Some(s) = child.try_wait().expect("wait") {
            return s;
        }
        assert!(started.elapsed() < within, "run did not stop on SIGINT");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// Kills a child on drop, so a failing assertion leaves no process behind.
pub struct Guard(pub std::process::Child);

impl Guard {
    /// Waits for the child and collects what it wrote to its piped stdout and stderr.
    pub fn wait_with_output(&mut self) -> std::process::Output {
        use std::io::Read;
        let read = |pipe: Option<Box<dyn Read + Send>>| {
            std::thread::spawn(move || {
                let mut text = Vec::new();
                if let Some(mut p) = pipe {
                    let _ = p.read_to_end(&mut text);
                }
                text
            })
        };
        let out = read(
            self.0
                .stdout
                .take()
                .map(|p| Box::new(p) as Box<dyn Read + Send>),
        );
        let err = read(
            self.0
                .stderr
                .take()
                .map(|p| Box::new(p) as Box<dyn Read + Send>),
        );
        let status = self.0.wait().expect("wait for the child");
        std::process::Output {
            status,
            stdout: out.join().unwrap_or_default(),
            stderr: err.join().unwrap_or_default(),
        }
    }
}

impl Drop for Guard {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}
