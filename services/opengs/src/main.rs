//! `opengs`: the one user-facing command.

mod cmd;
mod exit;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Open-set dense semantic SLAM with 3D Gaussian Splatting, as a zero-copy
/// multi-process pipeline. `opengs run` with no arguments runs the embedded
/// synthetic scene end to end.
#[derive(Parser)]
#[command(version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the pipeline on a dataset (default: the embedded synthetic room).
    Run(cmd::run::RunArgs),
    /// Run the consensus ablation (everything on, then each module off) on one dataset and print the table.
    Ablation(cmd::ablation::AblationArgs),
    /// Talk to a running pipeline: status, stop, swap, scale.
    Ctl(cmd::ctl::CtlArgs),
    /// Run the stages a deploy file puts on this host (`host = "NAME"`) for a run whose
    /// main host runs `opengs run`; a bridge stage on each side carries their messages.
    Node(cmd::node::NodeArgs),
    /// Remove the shared memory and registry entries of runs whose supervisor died.
    Clean(cmd::clean::CleanArgs),
    /// Recompute a finished run's metrics (ATE) from its files.
    Eval(cmd::eval::EvalArgs),
    /// Print the per-stage latency table of a finished run.
    Profile(cmd::profile::ProfileArgs),
    /// Write the synthetic room as a TUM or Replica dataset with ground truth.
    Synth(cmd::synth::SynthArgs),
    /// Render colour, depth and labels of a Gaussian map (PLY) at a pose.
    Render(cmd::render::RenderArgs),
    /// Objects of a finished map: list, pick, extract, remove, move, rotate, render-edit.
    Objects(cmd::objects::ObjectsArgs),
    /// Keep optimising a finished run's map offline; report PSNR/SSIM before and after.
    Refine(cmd::refine::RefineArgs),
    /// Register two point clouds (PLY or `x y z` text) with G-ICP.
    Register(cmd::register::RegisterArgs),
    /// Check exported ONNX models against their role (encoder, decoder, tagger, detector, proposals).
    Models(cmd::models::ModelsArgs),
    /// Benchmarks that print figures.
    Bench(cmd::bench::BenchArgs),
    /// (internal) subscriber side of `opengs bench ipc`.
    #[command(hide = true)]
    IpcSink(cmd::bench_ipc::SinkArgs),
}

fn main() -> ExitCode {
    opengs_pipeline::logging::init("warn");
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run(a) => cmd::run::run(a),
        Command::Ablation(a) => cmd::ablation::run(a),
        Command::Ctl(a) => cmd::ctl::run(a),
        Command::Node(a) => cmd::node::run(a),
        Command::Clean(a) => cmd::clean::run(a),
        Command::Eval(a) => cmd::eval::run(a),
        Command::Profile(a) => cmd::profile::run(a),
        Command::Synth(a) => cmd::synth::run(a),
        Command::Render(a) => cmd::render::run(a),
        Command::Objects(a) => cmd::objects::run(a),
        Command::Refine(a) => cmd::refine::run(a),
        Command::Register(a) => cmd::register::run(a),
        Command::Models(a) => cmd::models::run(a),
        Command::Bench(a) => cmd::bench::run(a),
        Command::IpcSink(a) => cmd::bench_ipc::run_sink(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => exit::code_of(&e),
    }
}
