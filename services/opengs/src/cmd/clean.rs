//! `opengs clean`: remove the shared memory and registry entries of runs whose supervisor
//! died (SIGKILL, a crash); a live run is never touched.

use std::io::Write;

use opengs_runtime::{ActiveRuns, CleanedRun};

/// `println!` that ends quietly on a closed pipe (`| head`) instead of panicking.
macro_rules! say {
    ($($arg:tt)*) => {{
        let _ = writeln!(std::io::stdout().lock(), $($arg)*);
    }};
}

#[derive(clap::Args)]
pub struct CleanArgs {
    /// Clean only this run (refused while it runs). Default: every run whose supervisor is
    /// gone, and files of runs no registry entry names.
    #[arg(long, value_name = "ID")]
    pub run: Option<String>,
    /// List what would be removed, remove nothing.
    #[arg(long)]
    pub dry_run: bool,
}

pub fn run(args: CleanArgs) -> anyhow::Result<()> {
    let registry = ActiveRuns::default();
    let verb = if args.dry_run {
        "would remove"
    } else {
        "removed"
    };
    if let Some(run_id) = &args.run {
        let cleaned = registry.clean_run(run_id, args.dry_run)?;
        if cleaned.is_empty() {
            say!("run {run_id}: nothing to remove (no shared memory, no registry entry)");
        } else {
            print_run(&cleaned, verb);
        }
        return Ok(());
    }
    let report = registry.clean_dead(args.dry_run);
    for cleaned in &report.cleaned {
        print_run(cleaned, verb);
    }
    for skipped in &report.skipped {
        eprintln!("left alone: {skipped}");
    }
    let files: usize = report.cleaned.iter().map(|c| c.files.len()).sum();
    match report.cleaned.len() {
        0 => say!("nothing to remove: no dead run left shared memory or a registry entry"),
        n => say!(
            "{verb} the shared memory of {n} dead run{} ({files} file{})",
            plural(n),
            plural(files)
        ),
    }
    for failed in report.failed.iter().skip(1) {
        eprintln!("error: {failed}");
    }
    match report.failed.into_iter().next() {
        Some(first) => Err(first.into()),
        None => Ok(()),
    }
}

/// At the start of `opengs run`: clean runs whose supervisor was killed, in one line; a
/// failure only warns, since the new run does not need that memory.
pub fn dead_runs_at_start() {
    let report = ActiveRuns::default().clean_dead(false);
    if !report.cleaned.is_empty() {
        let ids: Vec<&str> = report.cleaned.iter().map(|c| c.run_id.as_str()).collect();
        eprintln!(
            "removed shared memory of {} dead run{}: {}",
            ids.len(),
            plural(ids.len()),
            ids.join(", ")
        );
    }
    for failed in &report.failed {
        eprintln!("warning: cleaning a dead run: {failed}");
    }
}

fn print_run(cleaned: &CleanedRun, verb: &str) {
    let who = match cleaned.pid {
        Some(pid) => format!("supervisor pid {pid} gone"),
        None => "not registered".to_string(),
    };
    let n = cleaned.files.len();
    let entry = if cleaned.registry_entry.is_some() {
        " and its registry entry"
    } else {
        ""
    };
    say!(
        "run {} ({who}): {verb} {n} shared-memory file{}{entry}",
        cleaned.run_id,
        plural(n)
    );
    for path in cleaned.files.iter().chain(&cleaned.registry_entry) {
        say!("  {}", path.display());
    }
}

fn plural(n: usize) -> &'static str {
    if n == 1 {
        ""
    } else {
        "s"
    }
}
