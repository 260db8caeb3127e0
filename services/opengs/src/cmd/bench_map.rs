//! `opengs bench map`: one mapping step (forward + backward + Adam) at two resolutions, and
//! the rates the mapper sustained in finished runs (their `mapper.json`).

use std::path::{Path, PathBuf};

use anyhow::Context;

use opengs_eval::RunDir;
use opengs_pipeline::cli_values::at_least_one;

#[derive(clap::Args)]
pub struct BenchMapArgs {
    /// Timed steps per case.
    #[arg(long, default_value_t = 15, value_parser = at_least_one)]
    steps: usize,
    /// Gaussians in the scene.
    #[arg(long, default_value_t = 100_000, value_parser = at_least_one)]
    gaussians: usize,
    /// Also report the mapper of this run directory (repeatable): online iterations per
    /// second and the final optimisation's steps per second.
    #[arg(long = "run")]
    runs: Vec<PathBuf>,
}

pub fn run(args: BenchMapArgs) -> anyhow::Result<()> {
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "mapping step ({} timed steps per case, medians; loadavg {})",
        args.steps,
        load.trim()
    );
    for (w, h) in [(640, 480), (320, 240)] {
        println!(
            "{}",
            opengs_splat::bench_train_steps(args.gaussians, w, h, args.steps)
        );
    }
    for dir in &args.runs {
        println!("{}", sustained_rates(dir)?);
    }
    Ok(())
}

/// One line from a run's `mapper.json`.
fn sustained_rates(dir: &Path) -> anyhow::Result<String> {
    let path = RunDir::new(dir).mapper_report();
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("{}: not a finished run's mapper output", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{}: invalid JSON", path.display()))?;
    let number = |key: &str| {
        v[key]
            .as_f64()
            .with_context(|| format!("{}: no number \"{key}\"", path.display()))
    };
    let mut line = format!(
        "run {}: online {:.0} iterations in {:.1} s ({:.1} it/s), {:.0} Gaussians, {:.0} keyframes",
        dir.display(),
        number("iterations")?,
        number("seconds")?,
        number("iterations_per_s")?,
        number("gaussians")?,
        number("keyframes")?
    );
    let fin = &v["final_optimisation"];
    if let (Some(steps), Some(s)) = (fin["iterations"].as_f64(), fin["seconds"].as_f64()) {
        line.push_str(&format!(
            "; final optimisation {steps:.0} full-resolution steps in {s:.1} s ({:.1} steps/s)",
            steps / s.max(1e-9)
        ));
    }
    Ok(line)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_come_from_mapper_json() {
        let dir = std::env::temp_dir().join(format!("opengs-bench-map-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        std::fs::write(
            dir.join("mapper.json"),
            r#"{"iterations": 1200, "seconds": 60.0, "iterations_per_s": 20.0, "gaussians": 86000,
                "keyframes": 61, "final_optimisation": {"iterations": 600, "seconds": 50.0}}"#,
        )
        .expect("write");
        let line = sustained_rates(&dir).expect("reads");
        assert!(line.contains("(20.0 it/s)"), "{line}");
        assert!(
            line.contains("600 full-resolution steps in 50.0 s (12.0 steps/s)"),
            "{line}"
        );
        std::fs::write(dir.join("mapper.json"), r#"{"iterations": 5}"#).expect("write");
        let err = sustained_rates(&dir).expect_err("incomplete");
        assert!(format!("{err:#}").contains("\"seconds\""), "{err:#}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
