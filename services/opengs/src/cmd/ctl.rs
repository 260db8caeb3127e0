//! `opengs ctl`: talk to a running pipeline through its control services.

use std::time::Duration;

use clap::{Args, Subcommand};
use opengs_ipc_schema::service::{CONTROL_REPLIES, CONTROL_REQUESTS};
use opengs_ipc_schema::{ControlCommand, ControlHeader};
use opengs_pipeline::scale::ScaleOutcome;
use opengs_pipeline::status::PipelineStatus;
use opengs_pipeline::swap::SwapOutcome;
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
    /// Replace a stage's implementation while the pipeline runs (make-before-break): the new
    /// kind starts with its own arguments (`[stages.kinds.KIND]` in the deploy file) and checks
    /// its models; once it is ready the old process stops after its current keyframe (killed
    /// after a 5 s grace period). Waits for the outcome: the new pid, the time to its first
    /// output and the gap downstream. Exits 0 only when the swap succeeded.
    Swap {
        /// The stage to swap, e.g. `segmenter`.
        stage: String,
        /// The new kind.
        #[arg(long, value_parser = crate::cmd::run::segmenter_kinds())]
        to: String,
    },
    /// Change how many processes (replicas) of a stage share its work while the pipeline runs
    /// (only the segmenter can). Up: new replicas start beside the running ones and join once
    /// ready. Down: the newest replicas stop after their current keyframe (killed after a 5 s
    /// grace period); the others never stop. Exits 0 only when the count was reached.
    Scale {
        /// The stage to scale, e.g. `segmenter`.
        stage: String,
        /// Replicas to run.
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..=opengs_pipeline::deploy::MAX_REPLICAS as i64))]
        to: u32,
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
        CtlWhat::Status { .. } => (ControlCommand::Status, String::new(), ANSWER_WAIT),
        CtlWhat::Stop => (ControlCommand::Stop, String::new(), ANSWER_WAIT),
        CtlWhat::Swap { stage, to } => {
            eprintln!("swapping {stage} of run {} to {to} …", run.run_id);
            (ControlCommand::Swap, format!("{stage} {to}"), SWAP_WAIT)
        }
        CtlWhat::Scale { stage, to } => {
            eprintln!("scaling {stage} of run {} to {to} …", run.run_id);
            (ControlCommand::Scale, format!("{stage} {to}"), SWAP_WAIT)
        }
    };
    let (ok, reply) = request(&run.run_id, command, &text, wait)?;
    // Swaps and scales answer with their outcome, or (refused before anything started) a
    // plain reason.
    match args.what {
        CtlWhat::Swap { .. } => {
            return outcome::<SwapOutcome>(&reply, |o| (o.ok, o.describe()));
        }
        CtlWhat::Scale { .. } => {
            return outcome::<ScaleOutcome>(&reply, |o| (o.ok, o.describe()));
        }
        _ => {}
    }
    if !ok {
        anyhow::bail!(
            "the supervisor refused: {}",
            serde_json::from_str::<String>(&reply).unwrap_or(reply)
        );
    }
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
        CtlWhat::Swap { .. } | CtlWhat::Scale { .. } => {}
    }
    Ok(())
}

/// Prints a swap's or scale's outcome (an error unless it succeeded), or the refusal.
fn outcome<T: serde::de::DeserializeOwned>(
    reply: &str,
    ok_and_text: impl Fn(&T) -> (bool, String),
) -> anyhow::Result<()> {
    match serde_json::from_str::<T>(reply).map(|o| ok_and_text(&o)) {
        Ok((true, text)) => {
            println!("{text}");
            Ok(())
        }
        Ok((false, text)) => anyhow::bail!("{text}"),
        Err(_) => anyhow::bail!(
            "the supervisor refused: {}",
            serde_json::from_str::<String>(reply).unwrap_or_else(|_| reply.to_string())
        ),
    }
}

/// How long status and stop may take: the supervisor answers between two 100 ms ticks.
const ANSWER_WAIT: Duration = Duration::from_secs(3);
/// A swap (or scale) answers when it is over: the new process's start (the deploy file's
/// `startup_timeout_s`), the old one's grace period and the wait for the first output
/// (`opengs_pipeline::swap`); longer than any of that, and cut short if the run dies.
const SWAP_WAIT: Duration = Duration::from_secs(15 * 60);

/// Sends one control request and waits up to `wait` for the matching reply: (ok, text).
fn request(
    run_id: &str,
    command: ControlCommand,
    text: &str,
    wait: Duration,
) -> anyhow::Result<(bool, String)> {
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
    while started.elapsed() < wait {
        match ws.wait_and_process_once_with_timeout(
            |_| CallbackProgression::Continue,
            Duration::from_secs(1),
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
                return Ok((view.ok, view.text.to_string()));
            }
        }
        if !ActiveRuns::default()
            .live()
            .iter()
            .any(|r| r.run_id == run_id)
        {
            anyhow::bail!("run {run_id} ended before it answered");
        }
    }
    anyhow::bail!("run {run_id} did not answer within {} s", wait.as_secs())
}
