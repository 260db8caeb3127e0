//! `opengs models check FILE... [--role ROLE]`: does each exported ONNX file
//! have the input/output names and shapes its runner needs?

use std::path::PathBuf;

use clap::{Args, Subcommand};
use opengs_perception::model_check::{check_model, ModelRole};

#[derive(Args)]
pub struct ModelsArgs {
    #[command(subcommand)]
    what: ModelsWhat,
}

#[derive(Subcommand)]
enum ModelsWhat {
    /// Load each model with ONNX Runtime and check its inputs/outputs against its role.
    Check {
        /// ONNX files.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// encoder, decoder, tagger, detector or proposals; guessed from the names when left out.
        #[arg(long, value_parser = parse_role)]
        role: Option<ModelRole>,
    },
}

fn parse_role(s: &str) -> Result<ModelRole, String> {
    s.parse()
}

pub fn run(args: ModelsArgs) -> anyhow::Result<()> {
    let ModelsWhat::Check { files, role } = args.what;
    if !opengs_perception::ONNX {
        anyhow::bail!(
            "this opengs was built without ONNX Runtime support; rebuild with \
             `cargo build --release --workspace --bins --features opengs-perception/onnx` \
             and set ORT_DYLIB_PATH (scripts/setup-ort.sh)"
        );
    }
    let mut failed = 0usize;
    for file in &files {
        match check_model(file, role) {
            Ok(check) => println!(
                "ok   {} ({}{})",
                file.display(),
                check.role,
                if check.guessed {
                    ", guessed from its names"
                } else {
                    ""
                }
            ),
            Err(e) => {
                failed += 1;
                println!("FAIL {e}");
            }
        }
    }
    if failed > 0 {
        anyhow::bail!("{failed} of {} models failed the check", files.len());
    }
    Ok(())
}
