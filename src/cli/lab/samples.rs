//! `clothsr lab samples -o samples/`: regenerates the sample scenes (usda) shipped in the repository.

use std::path::PathBuf;

use clothsr::io::SceneFiles;
use clothsr::scene::samples::{sample, SAMPLE_NAMES};

/// Arguments of `samples`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output directory.
    #[arg(value_parser = crate::cli::values::output_dir, short, long, default_value = "samples")]
    output: PathBuf,
}

/// Runs `samples`.
pub fn run(args: Args) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.output)?;
    for name in SAMPLE_NAMES {
        let scene = sample(name).ok_or_else(|| anyhow::anyhow!("unknown sample {name}"))?;
        let path = args.output.join(format!("{name}.usda"));
        for w in scene.write_usd(&path, true)? {
            tracing::warn!("{}: {w}", path.display());
        }
        tracing::info!("wrote {}", path.display());
    }
    Ok(())
}
