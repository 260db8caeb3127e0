//! `opengs ablation`: the paper's ablation table (Table IV). The same dataset is run with the
//! full method, then with each consensus module switched off, and the label scores are
//! printed side by side. With `--repeats N` every setting runs N times (interleaved, so a
//! change in machine load hits every setting alike) and the table gives mean ± std: one run
//! per setting differs by about ±1 mIoU from the next on a 2-core machine.

use std::path::{Path, PathBuf};

use opengs_pipeline::consensus_stage::Ablation;
use serde::Serialize;

use super::run::{execute, RunArgs};

#[derive(clap::Args)]
pub struct AblationArgs {
    /// Directory for the runs (one sub-directory each) and ablation.json.
    #[arg(long, default_value = "runs/ablation")]
    pub out_root: PathBuf,
    /// Runs per setting; the table gives their mean and standard deviation.
    #[arg(long, default_value_t = 1, value_parser = opengs_pipeline::cli_values::at_least_one)]
    pub repeats: usize,
    #[command(flatten)]
    pub run: RunArgs,
}

/// One run of one setting.
#[derive(Debug, Clone, Serialize)]
struct Run {
    setting: String,
    repeat: usize,
    miou: Option<f64>,
    acc: Option<f64>,
    miou_raw: Option<f64>,
    labels: Option<usize>,
    run_dir: PathBuf,
    error: Option<String>,
}

/// Mean and sample standard deviation (0 for a single value); `None` without values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
struct Spread {
    mean: f64,
    std: f64,
    n: usize,
}

impl Spread {
    fn of(values: impl IntoIterator<Item = f64>) -> Option<Self> {
        let v: Vec<f64> = values.into_iter().collect();
        if v.is_empty() {
            return None;
        }
        let n = v.len();
        let mean = v.iter().sum::<f64>() / n as f64;
        let std = if n > 1 {
            (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
        } else {
            0.0
        };
        Some(Self { mean, std, n })
    }
}

/// One row of the table: a setting over its successful runs.
#[derive(Debug, Clone, Serialize)]
struct SettingSummary {
    setting: String,
    miou: Option<Spread>,
    acc: Option<Spread>,
    miou_raw: Option<Spread>,
    labels: Option<Spread>,
    failed: usize,
}

fn summarise(settings: &[String], runs: &[Run]) -> Vec<SettingSummary> {
    settings
        .iter()
        .map(|name| {
            let mine: Vec<&Run> = runs.iter().filter(|r| &r.setting == name).collect();
            SettingSummary {
                setting: name.clone(),
                miou: Spread::of(mine.iter().filter_map(|r| r.miou)),
                acc: Spread::of(mine.iter().filter_map(|r| r.acc)),
                miou_raw: Spread::of(mine.iter().filter_map(|r| r.miou_raw)),
                labels: Spread::of(mine.iter().filter_map(|r| r.labels.map(|l| l as f64))),
                failed: mine.iter().filter(|r| r.error.is_some()).count(),
            }
        })
        .collect()
}

pub fn run(args: AblationArgs) -> anyhow::Result<()> {
    if !args.run.ablation.is_empty() || args.run.out.is_some() {
        anyhow::bail!(
            "opengs ablation runs every setting itself: drop --ablation and --out (use --out-root)"
        );
    }
    anyhow::ensure!(args.repeats > 0, "--repeats must be at least 1");
    let settings: Vec<(String, Vec<Ablation>)> = std::iter::once(("full".to_string(), vec![]))
        .chain(
            Ablation::ALL
                .iter()
                .map(|a| (a.as_str().to_string(), vec![*a])),
        )
        .collect();
    std::fs::create_dir_all(&args.out_root)?;
    let total = settings.len() * args.repeats;
    let mut runs = Vec::new();
    for repeat in 1..=args.repeats {
        for (name, ablation) in &settings {
            eprintln!(
                "== ablation run {}/{total}: {name}{}",
                runs.len() + 1,
                if args.repeats > 1 {
                    format!(" (repeat {repeat}/{})", args.repeats)
                } else {
                    String::new()
                }
            );
            let dir = if args.repeats > 1 {
                args.out_root.join(name).join(format!("run{repeat}"))
            } else {
                args.out_root.join(name)
            };
            let mut run = args.run.clone();
            run.ablation = ablation.clone();
            run.out = Some(dir.clone());
            // The final optimisation sharpens colour, not labels: skipped unless asked for.
            run.finish_steps = Some(run.finish_steps.unwrap_or(0));
            runs.push(match execute(&run) {
                Ok(summary) => {
                    let sem = summary.scores.semantics.as_ref();
                    Run {
                        setting: name.clone(),
                        repeat,
                        miou: sem.and_then(|s| s.map.as_ref()).map(|m| m.miou),
                        acc: sem.and_then(|s| s.map.as_ref()).map(|m| m.acc),
                        miou_raw: sem.and_then(|s| s.raw.as_ref()).map(|m| m.miou),
                        labels: sem.map(|s| s.labels),
                        run_dir: summary.out_dir.clone(),
                        error: None,
                    }
                }
                Err(e) => Run {
                    setting: name.clone(),
                    repeat,
                    miou: None,
                    acc: None,
                    miou_raw: None,
                    labels: None,
                    run_dir: dir,
                    error: Some(format!("{e:#}")),
                },
            });
        }
    }
    let names: Vec<String> = settings.iter().map(|(n, _)| n.clone()).collect();
    let table = summarise(&names, &runs);
    print_table(&table, args.repeats);
    for r in runs.iter().filter(|r| r.error.is_some()) {
        println!(
            "  {} run {} failed: {}",
            r.setting,
            r.repeat,
            r.error.as_deref().unwrap_or("")
        );
    }
    write_json(&args.out_root.join("ablation.json"), &table, &runs)
}

fn print_table(rows: &[SettingSummary], repeats: usize) {
    let full = rows.first();
    let fmt = |v: Option<Spread>| match v {
        Some(s) if repeats > 1 => format!("{:.2} ± {:.2}", s.mean, s.std),
        Some(s) => format!("{:.2}", s.mean),
        None => "-".to_string(),
    };
    let delta = |v: Option<Spread>, base: Option<Spread>| match (v, base) {
        (Some(v), Some(b)) => format!("{:+.2}", v.mean - b.mean),
        _ => "-".to_string(),
    };
    let w = if repeats > 1 { 14 } else { 7 };
    println!(
        "\n{:<22} {:>w$} {:>w$} {:>8} {:>8} {:>7}",
        "setting", "mIoU", "Acc", "ΔmIoU", "ΔAcc", "labels"
    );
    for r in rows {
        println!(
            "{:<22} {:>w$} {:>w$} {:>8} {:>8} {:>7}",
            r.setting,
            fmt(r.miou),
            fmt(r.acc),
            delta(r.miou, full.and_then(|f| f.miou)),
            delta(r.acc, full.and_then(|f| f.acc)),
            r.labels
                .map_or("-".to_string(), |l| format!("{:.0}", l.mean))
        );
    }
    if repeats > 1 {
        println!("(mean ± sample standard deviation over {repeats} runs per setting)");
    }
    if let Some(raw) = full.and_then(|f| f.miou_raw) {
        println!(
            "segmenter alone (per-frame labels, same matching): mIoU {:.2}",
            raw.mean
        );
    }
}

fn write_json(path: &Path, table: &[SettingSummary], runs: &[Run]) -> anyhow::Result<()> {
    let json = serde_json::json!({ "settings": table, "runs": runs });
    std::fs::write(path, serde_json::to_string_pretty(&json)? + "\n")?;
    println!("table: {}", path.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(setting: &str, miou: Option<f64>) -> Run {
        Run {
            setting: setting.into(),
            repeat: 1,
            miou,
            acc: miou.map(|m| m / 2.0),
            miou_raw: None,
            labels: Some(10),
            run_dir: PathBuf::new(),
            error: miou.is_none().then(|| "stage died".to_string()),
        }
    }

    #[test]
    fn settings_get_mean_and_sample_std_of_their_runs() {
        let runs = [
            run("full", Some(44.0)),
            run("no-part-decay", Some(41.0)),
            run("full", Some(46.0)),
            run("no-part-decay", None),
            run("full", Some(48.0)),
        ];
        let names = ["full".to_string(), "no-part-decay".to_string()];
        let t = summarise(&names, &runs);
        // full: 44, 46, 48 → mean 46, sample std 2.
        let full = t[0].miou.expect("runs");
        assert_eq!((full.mean, full.std, full.n), (46.0, 2.0, 3));
        assert_eq!(t[0].acc.expect("runs").mean, 23.0);
        // The failed run counts as failed, not as a zero.
        let nd = t[1].miou.expect("one run");
        assert_eq!((nd.mean, nd.std, nd.n), (41.0, 0.0, 1));
        assert_eq!(t[1].failed, 1);
        assert!(Spread::of([]).is_none());
    }
}
