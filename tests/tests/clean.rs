//! End-to-end: `opengs clean` after a SIGKILLed supervisor (issue 23, item 6). The
//! stages die with the supervisor, but the run's shared memory (iceoryx2's domain segment
//! at least) and its registry entry stay until `opengs clean` removes them; a live run is
//! never touched.

use std::path::PathBuf;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use opengs_e2e::{binary, ctl_status, opengs_run, serial, Guard};
use opengs_runtime::{leftover_files, process_alive, ActiveRuns};

fn opengs_clean(args: &[&str]) -> Output {
    Command::new(binary("opengs"))
        .arg("clean")
        .args(args)
        .output()
        .expect("opengs clean runs")
}

fn text(out: &Output) -> String {
    format!(
        "exit {:?}\nstdout:\n{}\nstderr:\n{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Waits until every stage of the run has a pid and the sensor has published a few
/// frames; returns the stage pids.
fn running_stage_pids(run_id: &str, run: &mut Guard) -> Vec<u32> {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        assert!(Instant::now() < deadline, "the run never got going");
        assert!(
            run.0.try_wait().expect("wait").is_none(),
            "opengs run ended early"
        );
        if let Some(st) = ctl_status(run_id) {
            let stages = st["stages"].as_array().cloned().unwrap_or_default();
            let pids: Vec<u32> = stages
                .iter()
                .filter_map(|s| s["pid"].as_u64().map(|p| p as u32))
                .collect();
            let sensor_going = stages
                .iter()
                .any(|s| s["name"] == "sensor" && s["processed"].as_u64().unwrap_or(0) >= 5);
            if !stages.is_empty() && pids.len() == stages.len() && sensor_going {
                return pids;
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn clean_removes_what_a_killed_supervisor_left_and_refuses_a_live_run() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let run_id = format!("t{}-clean", std::process::id());
    let mut run = Guard(
        opengs_run(&run_id, &dir.path().join("run"))
            .args(["--frames", "600", "--finish-steps", "0"])
            .spawn()
            .expect("opengs run starts"),
    );
    let stage_pids = running_stage_pids(&run_id, &mut run);

    // A live run is refused by name and left alone by the clean-everything form.
    let refused = opengs_clean(&["--run", &run_id]);
    assert_eq!(refused.status.code(), Some(1), "{}", text(&refused));
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        stderr.contains(&format!("run {run_id} is running")),
        "{stderr}"
    );
    let everything = opengs_clean(&[]);
    assert!(everything.status.success(), "{}", text(&everything));
    assert!(
        !String::from_utf8_lossy(&everything.stdout).contains(&run_id),
        "{}",
        text(&everything)
    );
    assert!(
        ctl_status(&run_id).is_some(),
        "the live run stopped answering"
    );
    assert!(stage_pids.iter().all(|&p| process_alive(p)));

    // SIGKILL the supervisor and reap it (a zombie would still look alive).
    // SAFETY: signalling the child this test started.
    assert_eq!(unsafe { libc::kill(run.0.id() as i32, libc::SIGKILL) }, 0);
    run.0.wait().expect("opengs run is reaped");
    let killed = Instant::now();
    while stage_pids.iter().any(|&p| process_alive(p)) {
        assert!(
            killed.elapsed() < Duration::from_secs(5),
            "stages outlived their supervisor: {stage_pids:?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    eprintln!(
        "stages gone {:.2} s after the supervisor's SIGKILL",
        killed.elapsed().as_secs_f64()
    );

    // What the issue describes: shared memory left behind, and the run still registered.
    let left = leftover_files(&run_id);
    assert!(
        !left.is_empty(),
        "a killed supervisor left no shared memory"
    );
    eprintln!("left after the SIGKILL: {left:#?}");
    let registry = ActiveRuns::default();
    assert!(
        registry.dead().iter().any(|r| r.run_id == run_id),
        "the dead run is not in the registry"
    );

    // --dry-run lists every file and removes nothing.
    let preview = opengs_clean(&["--run", &run_id, "--dry-run"]);
    assert!(preview.status.success(), "{}", text(&preview));
    let listed = String::from_utf8_lossy(&preview.stdout);
    eprintln!("opengs clean --run {run_id} --dry-run:\n{listed}");
    assert!(listed.contains("would remove"), "{listed}");
    for path in &left {
        assert!(listed.contains(&path.display().to_string()), "{listed}");
    }
    assert_eq!(leftover_files(&run_id), left, "a dry run removed files");

    let cleaned = opengs_clean(&["--run", &run_id]);
    assert!(cleaned.status.success(), "{}", text(&cleaned));
    let said = String::from_utf8_lossy(&cleaned.stdout);
    eprintln!("opengs clean --run {run_id}:\n{said}");
    assert!(
        said.contains(&format!("removed {} shared-memory file", left.len())),
        "{said}"
    );
    assert_eq!(leftover_files(&run_id), Vec::<PathBuf>::new());
    assert!(
        !registry
            .dead()
            .iter()
            .chain(registry.live().iter())
            .any(|r| r.run_id == run_id),
        "the registry still lists {run_id}"
    );

    // Cleaning again finds nothing and is not an error.
    let again = opengs_clean(&["--run", &run_id]);
    assert!(again.status.success(), "{}", text(&again));
    assert!(
        String::from_utf8_lossy(&again.stdout).contains("nothing to remove"),
        "{}",
        text(&again)
    );
}
