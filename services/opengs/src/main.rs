use clap::Parser;

/// opengs: open-set dense semantic SLAM with 3D Gaussian Splatting.
#[derive(Parser)]
#[command(version, about)]
struct Cli {}

fn main() -> anyhow::Result<()> {
    let _cli = Cli::parse();
    Ok(())
}
