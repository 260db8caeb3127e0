//! `opengs run` as a systemd service: a live run follows a TUM folder a recorder is still
//! writing, talks sd_notify (READY, STATUS, WATCHDOG, STOPPING) to the socket systemd would
//! give it, ends on SIGTERM with every output written, and `deploy/opengs.service` passes
//! `systemd-analyze verify` with a command line `opengs` accepts.

use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use opengs_e2e::{binary, ctl_status, opengs_run, serial, Guard};

fn repo_file(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
}

/// Sensor and tracker only: poses are what the test follows.
fn write_deploy(dir: &Path) -> PathBuf {
    let path = dir.join("deploy.toml");
    std::fs::write(
        &path,
        r#"description = "test: live sensor + tracker"
terminal_stage = "tracker"
drain_timeout_s = 5
[[stages]]
name = "tracker"
binary = "opengs-tracker"
args = ["--threads", "1"]
[[stages]]
name = "sensor"
binary = "opengs-sensor"
role = "source"
"#,
    )
    .expect("write deploy");
    path
}

/// The lines of a TUM list that carry data (no comments).
fn data_lines(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .expect("list")
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .map(String::from)
        .collect()
}

fn append(path: &Path, lines: &[String]) {
    use std::io::Write;
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .create(true)
        .open(path)
        .expect("open list");
    for l in lines {
        writeln!(f, "{l}").expect("append");
    }
}

fn poses(run_id: &str) -> u64 {
    ctl_status(run_id)
        .and_then(|s| s["poses"].as_u64())
        .unwrap_or(0)
}

fn wait_poses(run_id: &str, n: u64, deadline: Instant) {
    while poses(run_id) < n {
        assert!(
            Instant::now() < deadline,
            "the live run never reached {n} poses"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn a_live_run_follows_a_growing_recording_and_talks_to_systemd() {
    let _serial = serial();
    const FIRST: usize = 15;
    const ALL: usize = 30;
    let dir = tempfile::tempdir().expect("tmp");
    // The whole recording, then a folder that holds only its first FIRST frames.
    let full = dir.path().join("full");
    let synth = Command::new(binary("opengs"))
        .args(["synth", "--frames", &ALL.to_string(), "--out"])
        .arg(&full)
        .output()
        .expect("synth runs");
    assert!(
        synth.status.success(),
        "{}",
        String::from_utf8_lossy(&synth.stderr)
    );
    let live = dir.path().join("recording");
    std::fs::create_dir(&live).expect("mkdir");
    for entry in std::fs::read_dir(&full).expect("ls") {
        let p = entry.expect("entry").path();
        let name = p.file_name().expect("name").to_owned();
        match name.to_str() {
            Some("rgb.txt" | "depth.txt" | "labels.txt") => {}
            _ => {
                let status = Command::new("cp").arg("-r").arg(&p).arg(&live).status();
                assert!(status.expect("cp").success());
            }
        }
    }
    let rgb = data_lines(&full.join("rgb.txt"));
    let depth = data_lines(&full.join("depth.txt"));
    assert_eq!((rgb.len(), depth.len()), (ALL, ALL));
    append(&live.join("depth.txt"), &depth[..FIRST]);
    append(&live.join("rgb.txt"), &rgb[..FIRST]);

    // The socket systemd would pass as NOTIFY_SOCKET; a 2 s watchdog asks for 1 s pings.
    let socket_path = dir.path().join("notify.sock");
    let socket = UnixDatagram::bind(&socket_path).expect("bind");
    socket
        .set_read_timeout(Some(Duration::from_millis(200)))
        .expect("timeout");
    let messages: Arc<Mutex<Vec<(Instant, String)>>> = Arc::default();
    let done = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let reader = {
        let (messages, done) = (messages.clone(), done.clone());
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while !done.load(std::sync::atomic::Ordering::Relaxed) {
                if let Ok(n) = socket.recv(&mut buf) {
                    let text = String::from_utf8_lossy(&buf[..n]).into_owned();
                    messages.lock().expect("lock").push((Instant::now(), text));
                }
            }
        })
    };

    let run_id = format!("t{}-live", std::process::id());
    let out = dir.path().join("run");
    let deploy = write_deploy(dir.path());
    let started = Instant::now();
    let mut run = Guard(
        opengs_run(&run_id, &out)
            .arg("--live")
            .arg("--dataset")
            .arg(format!("tum:{}", live.display()))
            .args(["--max-rate", "10", "--quality-every", "0", "--deploy"])
            .arg(&deploy)
            .env("NOTIFY_SOCKET", &socket_path)
            .env("WATCHDOG_USEC", "2000000")
            .spawn()
            .expect("run starts"),
    );
    let deadline = Instant::now() + Duration::from_secs(90);
    wait_poses(&run_id, FIRST as u64, deadline);
    // At the end of what is recorded the run waits: no end of data.
    std::thread::sleep(Duration::from_secs(2));
    assert!(
        run.0.try_wait().expect("wait").is_none(),
        "the live run ended on its own"
    );
    assert_eq!(poses(&run_id), FIRST as u64);
    // The recorder goes on: images are there, their lines come now (depth first).
    append(&live.join("depth.txt"), &depth[FIRST..]);
    append(&live.join("rgb.txt"), &rgb[FIRST..]);
    wait_poses(&run_id, ALL as u64, deadline);
    // systemd stops the service with SIGTERM: exit 130, outputs written.
    // SAFETY: signalling the child this test started.
    unsafe { libc::kill(run.0.id() as i32, libc::SIGTERM) };
    let stop_deadline = Instant::now() + Duration::from_secs(60);
    let status = loop {
        if let Some(s) = run.0.try_wait().expect("wait") {
            break s;
        }
        assert!(Instant::now() < stop_deadline, "no exit after SIGTERM");
        std::thread::sleep(Duration::from_millis(50));
    };
    let ran = started.elapsed();
    std::thread::sleep(Duration::from_millis(300));
    done.store(true, std::sync::atomic::Ordering::Relaxed);
    reader.join().expect("reader");
    assert_eq!(
        status.code(),
        Some(130),
        "SIGTERM ends a live run as interrupted"
    );
    let trajectory = data_lines(&out.join("trajectory.txt"));
    assert_eq!(trajectory.len(), ALL, "a pose for every recorded frame");

    let messages = messages.lock().expect("lock").clone();
    let with = |key: &str| -> Vec<Instant> {
        messages
            .iter()
            .filter(|(_, m)| m.lines().any(|l| l == key))
            .map(|(t, _)| *t)
            .collect()
    };
    let ready = with("READY=1");
    let stopping = with("STOPPING=1");
    let pings = with("WATCHDOG=1");
    assert_eq!(ready.len(), 1, "{messages:?}");
    assert_eq!(stopping.len(), 1, "{messages:?}");
    assert!(ready[0] < stopping[0]);
    // Pings every second (half of WATCHDOG_USEC) between ready and stopping: never a gap
    // near the 2 s at which systemd would kill the service.
    let running = stopping[0].duration_since(ready[0]).as_secs_f64();
    let between: Vec<Instant> = pings
        .into_iter()
        .filter(|t| *t > ready[0] && *t < stopping[0])
        .collect();
    assert!(
        between.len() as f64 >= running - 2.0,
        "{} pings in {running:.1} s",
        between.len()
    );
    let mut last = ready[0];
    for t in between.iter().chain(std::iter::once(&stopping[0])) {
        let gap = t.duration_since(last).as_secs_f64();
        assert!(gap < 1.6, "{gap:.2} s without a watchdog ping");
        last = *t;
    }
    let statuses: Vec<&str> = messages
        .iter()
        .flat_map(|(_, m)| m.lines())
        .filter_map(|l| l.strip_prefix("STATUS="))
        .collect();
    assert!(
        statuses.iter().any(|s| s.contains(&format!("{ALL} poses"))),
        "{statuses:?}"
    );
    eprintln!(
        "live run: {ALL} poses, {} watchdog pings in {running:.1} s, {} status lines, {:.1} s in all",
        between.len(),
        statuses.len(),
        ran.as_secs_f64()
    );
}

#[test]
fn the_unit_file_verifies_and_its_command_line_parses() {
    let unit = std::fs::read_to_string(repo_file("deploy/opengs.service")).expect("unit");
    let exec = unit
        .lines()
        .find_map(|l| l.strip_prefix("ExecStart="))
        .expect("ExecStart");
    let mut words = exec.split_whitespace();
    assert_eq!(words.next(), Some("/usr/local/bin/opengs"));
    let args: Vec<&str> = words.collect();
    // The unit's flags are ones `opengs` has: it gets as far as opening the dataset
    // (exit 1, naming it), not a command-line error (exit 2).
    let out = Command::new(binary("opengs"))
        .args(&args)
        .output()
        .expect("opengs runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("/var/lib/opengs/recording"), "{stderr}");

    let Ok(analyze) = Command::new("systemd-analyze").arg("--version").output() else {
        eprintln!("systemd-analyze is not installed: unit syntax not checked");
        return;
    };
    assert!(analyze.status.success());
    // verify wants ExecStart's binary to exist: point it at the one just built.
    let dir = tempfile::tempdir().expect("tmp");
    let copy = dir.path().join("opengs.service");
    let built = binary("opengs");
    std::fs::write(
        &copy,
        unit.replace("/usr/local/bin/opengs", &built.display().to_string()),
    )
    .expect("write");
    let verify = Command::new("systemd-analyze")
        .arg("verify")
        .arg(&copy)
        .output()
        .expect("verify runs");
    let said = format!(
        "{}{}",
        String::from_utf8_lossy(&verify.stdout),
        String::from_utf8_lossy(&verify.stderr)
    );
    // Unknown keys are only warnings: any output is a finding.
    assert!(verify.status.success() && said.trim().is_empty(), "{said}");
}
