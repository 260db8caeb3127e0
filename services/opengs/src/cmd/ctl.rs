//! `opengs ctl`: talk to a running pipeline through its control services.

use std::time::Duration;

use clap::{Args, Subcommand};
use opengs_ipc_schema::service::{CONTROL_REPLIES, CONTROL_REQUESTS};
use opengs_ipc_schema::{ControlCommand, ControlHeader};
use opengs_pipeline::status::PipelineStatus;
use opengs_runtime::{
    waitset, ActiveRuns, CallbackProgression, Inlet, Outlet, RunContext, WaitSetRunResult,
};

#[derive(Args)]
pub struct CtlArgs {
    /// Run id (default: the only running pipeline).
    #[arg(long, global = true)]
    run: Option<String>,
    #[command(subcommand)]
    what: CtlWhat,
}

#[derive(Subcommand)]
enum CtlWhat {
    /// List stages, PIDs, state, restarts and messages processed.
    Status {
        /// Print the raw JSON instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Stop the pipeline cleanly (as Ctrl-C would); outputs are written.
    Stop,
    /// Replace a stage's implementation while the pipeline runs (make-before-break):
    /// the new process starts, and the old one stops once the new one is ready.
    Swap {
        /// The stage to swap, e.g. `segmenter`.
        stage: String,
        /// The new kind.
        #[arg(long, value_parser = crate::cmd::run::segmenter_kinds())]
        to: String,
    },
}

pub fn run(args: CtlArgs) -> anyhow::Result<()> {
    let runs = ActiveRuns::default().live();
    let run = match &args.run {
        Some(id) => runs
            .into_iter()
            .find(|r| &r.run_id == id)
            .ok_or_else(|| anyhow::anyhow!("no running pipeline with run id '{id}'"))?,
        None => match runs.len() {
            0 => anyhow::bail!("no pipeline is running (start one with `opengs run`)"),
            1 => runs
                .into_iter()
                .next()
                .ok_or_else(|| anyhow::anyhow!("no pipeline is running"))?,
            _ => anyhow::bail!(
                "{} pipelines are running; choose one with --run: {}",
                runs.len(),
                runs.iter()
                    .map(|r| r.run_id.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        },
    };
    let (command, text, wait) = match &args.what {
        CtlWhat::Status { .. } => (ControlCommand::Status, String::new(), 3),
        CtlWhat::Stop => (ControlCommand::Stop, String::new(), 3),
        // A model-based segmenter may take a while to load its weights.
        CtlWhat::Swap { stage, to } => (ControlCommand::Swap, format!("{stage} {to}"), 120),
    };
    let reply = request(&run.run_id, command, &text, Duration::from_secs(wait))?;
    match args.what {
        CtlWhat::Status { json: true } => println!("{reply}"),
        CtlWhat::Status { json: false } => {
            let status: PipelineStatus = serde_json::from_str(&reply)?;
            print!("{}", status.table());
        }
        CtlWhat::Stop => println!(
            "run {}: stopping; outputs go to {}",
            run.run_id,
            run.out_dir.display()
        ),
        CtlWhat::Swap { .. } => println!(
            "{}",
            serde_json::from_str::<String>(&reply).unwrap_or(reply)
        ),
    }
    Ok(())
}

/// Sends one control request and waits up to `wait` for the matching reply.
fn request(
    run_id: &str,
    command: ControlCommand,
    text: &str,
    wait: Duration,
) -> anyhow::Result<String> {
    let ctx = RunContext::new(run_id)?;
    let node = ctx.node(&format!("ctl_{}", std::process::id()))?;
    let replies = Inlet::<ControlHeader>::new(&ctx, &node, &CONTROL_REPLIES)?;
    let requests = Outlet::<ControlHeader>::new(&ctx, &node, &CONTROL_REQUESTS, 256)?;
    let id = u64::from(std::process::id()) << 32 | 1;
    let header = ControlHeader::new(command, id, true, text);
    requests.send(header, |h, buf| h.encode(text, buf))?;
    let ws = waitset()?;
    let _guard = ws
        .attach_deadline(replies.listener(), wait)
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let started = std::time::Instant::now();
    while started.elapsed() < Duration::from_secs(3) {
        match ws.wait_and_process_once_with_timeout(
            |_| CallbackProgression::Continue,
            Duration::from_secs(3),
        ) {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => {
                anyhow::bail!("interrupted")
            }
            Err(e) => anyhow::bail!("WaitSet: {e:?}"),
            Ok(_) => {}
        }
        replies.clear_wakeups();
        while let Some(sample) = replies.receive()? {
            let view = sample.user_header().decode(sample.payload())?;
            if view.request_id == id && view.command == ControlCommand::Reply {
                if !view.ok {
                    anyhow::bail!("the supervisor refused: {}", view.text);
                }
                return Ok(view.text.to_string());
            }
        }
    }
    anyhow::bail!("run {run_id} did not answer within {} s", wait.as_secs())
}
