//! `opengs ablation`: the paper's ablation table (Table IV). The same dataset is run four
//! times — full method, then each consensus module switched off — and the label scores are
//! printed side by side.

use std::path::{Path, PathBuf};

use opengs_pipeline::consensus_stage::Ablation;
use serde::Serialize;

use super::run::{execute, RunArgs};

#[derive(clap::Args)]
pub struct AblationArgs {
    /// Directory for the four runs (one sub-directory each) and ablation.json.
    #[arg(long, default_value = "runs/ablation")]
    pub out_root: PathBuf,
    #[command(flatten)]
    pub run: RunArgs,
}

#[derive(Debug, Serialize)]
struct Row {
    setting: String,
    miou: Option<f64>,
    acc: Option<f64>,
    miou_raw: Option<f64>,
    labels: Option<usize>,
    run_dir: PathBuf,
    error: Option<String>,
}

pub fn run(args: AblationArgs) -> anyhow::Result<()> {
    if !args.run.ablation.is_empty() || args.run.out.is_some() {
        anyhow::bail!(
            "opengs ablation runs every setting itself: drop --ablation and --out (use --out-root)"
        );
    }
    let settings: Vec<(String, Vec<Ablation>)> = std::iter::once(("full".to_string(), vec![]))
        .chain(
            Ablation::ALL
                .iter()
                .map(|a| (a.as_str().to_string(), vec![*a])),
        )
        .collect();
    std::fs::create_dir_all(&args.out_root)?;
    let mut rows = Vec::new();
    for (i, (name, ablation)) in settings.iter().enumerate() {
        eprintln!("== ablation {}/{}: {name}", i + 1, settings.len());
        let mut run = args.run.clone();
        run.ablation = ablation.clone();
        run.out = Some(args.out_root.join(name));
        // The final optimisation sharpens colour, not labels: skipped unless asked for.
        run.finish_steps = Some(run.finish_steps.unwrap_or(0));
        let row = match execute(&run) {
            Ok(summary) => {
                let sem = summary.semantics.as_ref();
                Row {
                    setting: name.clone(),
                    miou: sem.and_then(|s| s.map.as_ref()).map(|m| m.miou),
                    acc: sem.and_then(|s| s.map.as_ref()).map(|m| m.acc),
                    miou_raw: sem.and_then(|s| s.raw.as_ref()).map(|m| m.miou),
                    labels: sem.map(|s| s.labels),
                    run_dir: summary.out_dir.clone(),
                    error: None,
                }
            }
            Err(e) => Row {
                setting: name.clone(),
                miou: None,
                acc: None,
                miou_raw: None,
                labels: None,
                run_dir: args.out_root.join(name),
                error: Some(format!("{e:#}")),
            },
        };
        rows.push(row);
    }
    print_table(&rows);
    write_json(&args.out_root.join("ablation.json"), &rows)
}

fn print_table(rows: &[Row]) {
    let full = rows.first();
    let fmt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    let delta = |v: Option<f64>, base: Option<f64>| match (v, base) {
        (Some(v), Some(b)) => format!("{:+.2}", v - b),
        _ => "-".to_string(),
    };
    println!(
        "\n{:<22} {:>7} {:>7} {:>8} {:>8} {:>7}",
        "setting", "mIoU", "Acc", "ΔmIoU", "ΔAcc", "labels"
    );
    for r in rows {
        println!(
            "{:<22} {:>7} {:>7} {:>8} {:>8} {:>7}",
            r.setting,
            fmt(r.miou),
            fmt(r.acc),
            delta(r.miou, full.and_then(|f| f.miou)),
            delta(r.acc, full.and_then(|f| f.acc)),
            r.labels.map_or("-".to_string(), |l| l.to_string())
        );
        if let Some(e) = &r.error {
            println!("  failed: {e}");
        }
    }
    if let Some(raw) = full.and_then(|f| f.miou_raw) {
        println!("segmenter alone (per-frame labels, same matching): mIoU {raw:.2}");
    }
}

fn write_json(path: &Path, rows: &[Row]) -> anyhow::Result<()> {
    std::fs::write(path, serde_json::to_string_pretty(rows)? + "\n")?;
    println!("table: {}", path.display());
    Ok(())
}
