//! `opengs node`: the stages a deploy file puts on another host (`host = "NAME"`), started
//! and watched on that host (restarted when they die or hang, scaled and swapped with
//! `opengs ctl --run RUN-NAME`), until Ctrl-C, SIGTERM or `opengs ctl --run RUN-NAME stop`.
//! The host's bridge stage carries their messages to and from the run's main host.

use std::path::{Path, PathBuf};

use opengs_pipeline::supervisor::{Ending, Supervisor};
use opengs_pipeline::{DatasetArgs, DeployFile, RunOptions, StageFlags};

#[derive(clap::Args)]
pub struct NodeArgs {
    /// Deploy file of the run (the same file `opengs run` was given): a path, or
    /// `desktop` / `edge`.
    #[arg(long)]
    deploy: PathBuf,
    /// This host's name in the deploy file: its stages are the ones with `host = NAME`.
    #[arg(long)]
    host: String,
    /// The run id of the run on the main host (`opengs run --run-id`): bridges use it to find
    /// each other. This host's own services use RUN-HOST.
    #[arg(long)]
    run_id: String,
    /// This host's run directory (logs, the segmenter's claims, the consensus's label table).
    /// Default: runs/node-HOST-<timestamp>/.
    #[arg(long)]
    out: Option<PathBuf>,
    /// The dataset, for stages with `dataset = true` (class names of the prior segmenter).
    #[command(flatten)]
    dataset: DatasetArgs,
}

pub fn run(args: NodeArgs) -> anyhow::Result<()> {
    let deploy = DeployFile::load(&args.deploy)?;
    let names: Vec<&str> = deploy
        .stages
        .iter()
        .filter(|s| s.host.as_deref() == Some(args.host.as_str()))
        .map(|s| s.name.as_str())
        .collect();
    if names.is_empty() {
        anyhow::bail!(
            "deploy file {} puts no stage on host '{}' (hosts named there: {})",
            args.deploy.display(),
            args.host,
            match deploy.hosts().as_slice() {
                [] => "none".to_string(),
                hosts => hosts.join(", "),
            }
        );
    }
    let local_id = format!("{}-{}", args.run_id, args.host);
    if !opengs_runtime::RunContext::valid_run_id(&local_id) {
        anyhow::bail!(
            "--run-id {} with --host {}: '{local_id}' must be at most 40 letters, digits, '-' \
             and '_'",
            args.run_id,
            args.host
        );
    }
    crate::cmd::clean::dead_runs_at_start();
    let now = chrono::Local::now();
    let out_dir = args.out.clone().unwrap_or_else(|| {
        Path::new("runs").join(format!(
            "node-{}-{}",
            args.host,
            now.format("%Y%m%d-%H%M%S")
        ))
    });
    eprintln!(
        "opengs node {} of run {}: stages {}; this host's services: run {local_id} \
         (opengs ctl --run {local_id} status); output {}; Ctrl-C stops them",
        args.host,
        args.run_id,
        names.join(", "),
        out_dir.display()
    );
    let opts = RunOptions {
        deploy,
        dataset: args.dataset.clone(),
        out_dir,
        run_id: local_id,
        max_rate: None,
        stage_flags: StageFlags::default(),
        progress: false,
        quality_every: 0,
        pose_refinement: false,
        finish_after_data: false,
        live: false,
        host: Some(args.host.clone()),
        link: args.run_id.clone(),
    };
    let supervised = Supervisor::supervise(&opts)?;
    for s in &supervised.stages {
        eprintln!(
            "  {:<12} processed {:>6}, restarts {}",
            opengs_pipeline::stage_process::replica_label(&s.name, s.replica),
            s.processed,
            s.restarts
        );
    }
    match supervised.ending? {
        Ending::StageFailed(why) | Ending::BadInput(why) => anyhow::bail!("{why}"),
        Ending::Interrupted => Err(crate::exit::Interrupted.into()),
        Ending::EndOfData | Ending::StopRequested => Ok(()),
    }
}
