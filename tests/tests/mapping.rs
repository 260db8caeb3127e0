//! End-to-end mapping: a killed mapper resumes from its checkpoint, and the run ends with a map.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use opengs_e2e::{binary, serial, stage_pid};

#[test]
fn killed_mapper_resumes_from_its_checkpoint() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let deploy = dir.path().join("deploy.toml");
    std::fs::write(
        &deploy,
        r#"description = "test: mapper checkpoints every second"
terminal_stage = "tracker"
drain_timeout_s = 10
[[stages]]
name = "mapper"
binary = "opengs-mapper"
args = ["--checkpoint-every", "1"]
[[stages]]
name = "tracker"
binary = "opengs-tracker"
[[stages]]
name = "sensor"
binary = "opengs-sensor"
role = "source"
"#,
    )
    .expect("deploy");
    let out = dir.path().join("run");
    let run_id = format!("t{}-mapper", std::process::id());
    let run = Command::new(binary("opengs"))
        .args([
            "run",
            "--quiet",
            "--frames",
            "240",
            "--run-id",
            &run_id,
            "--max-rate",
            "15",
        ])
        .arg("--deploy")
        .arg(&deploy)
        .arg("--out")
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run starts");
    // Wait for a checkpoint, then SIGKILL the mapper.
    let deadline = Instant::now() + Duration::from_secs(120);
    while !out.join("map_checkpoint.ply").exists() {
        assert!(Instant::now() < deadline, "no checkpoint written");
        std::thread::sleep(Duration::from_millis(100));
    }
    let pid = loop {
        assert!(Instant::now() < deadline, "no mapper pid");
        if let Some(p) = stage_pid(&run_id, "mapper") {
            break p;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    // SAFETY: signalling a process this test's run started.
    assert_eq!(unsafe { libc::kill(pid, libc::SIGKILL) }, 0);
    let output = run.wait_with_output().expect("run ends");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(stderr.contains("restarted mapper"), "{stderr}");
    let log = std::fs::read_to_string(out.join("logs/mapper.log")).expect("mapper log");
    assert!(log.contains("resuming from"), "{log}");
    let map = std::fs::read(out.join("map.ply")).expect("map.ply written at the end");
    assert!(map.starts_with(b"ply\n"));
    let stats: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("mapper.json")).expect("mapper.json"),
    )
    .expect("json");
    assert!(stats["gaussians"].as_u64().unwrap_or(0) > 1000, "{stats}");
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).expect("metrics"))
            .expect("json");
    assert!(
        metrics["ate_rmse_cm"].as_f64().expect("ate") < 1.0,
        "{metrics}"
    );
    assert_eq!(
        opengs_runtime::leftover_files(&run_id),
        Vec::<std::path::PathBuf>::new()
    );
}
