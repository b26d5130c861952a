//! `clothsr lab fork DATA --frame K [--offset x,y,z] -o DIR`: a data set continued from one of
//! its frames with the fine garment moved a little (by default 0.1 mm), to measure how far
//! such a change carries: the ground truth's predictability floor (`clothsr lab rollout --floor`).

use std::path::PathBuf;

use nalgebra::Vector3;

/// Arguments of `fork`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The data set to fork (a `clothsr lab dataset` directory made from scene files).
    data: PathBuf,
    /// Its last frame the fork shares: the fine garment is moved at the end of this frame.
    #[arg(long)]
    frame: usize,
    /// Move the fine garment by x,y,z metres.
    #[arg(
        long,
        value_parser = crate::cli::values::triple,
        allow_hyphen_values = true,
        default_value = "0.0001,0,0"
    )]
    offset: [f64; 3],
    /// Frames in all, the shared ones included (default: as many as the data set has).
    #[arg(long)]
    frames: Option<usize>,
    /// Output directory (created; the same fork already there is resumed).
    #[arg(value_parser = crate::cli::values::output_dir, short, long)]
    output: PathBuf,
}

/// Runs `fork`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let offset = args.offset;
    let source = clothsr::data::read_manifest(&args.data)?;
    let frames = args.frames.unwrap_or(source.frames_done);
    anyhow::ensure!(
        frames > args.frame,
        "--frames ({frames}) must be more than --frame ({}): the fork simulates the frames after it",
        args.frame
    );
    let Some(files) = &source.source else {
        anyhow::bail!(
            "{}: the data set does not name its scene files (made by an older clothsr or from \
             a scene in memory), so it cannot be continued",
            args.data.join("manifest.json").display()
        );
    };
    let scene = files.load()?;
    let m = clothsr::dataset::fork(&args.data, args.frame, Vector3::from(offset), &args.output)?;
    tracing::info!(
        "forked {} at frame {} (fine garment moved by {:?} m) into {}",
        args.data.display(),
        args.frame,
        offset,
        args.output.display()
    );
    super::dataset::generate_with_progress(
        &scene,
        &m.scene,
        &clothsr::dataset::Options::of_manifest(&m, frames),
        &args.output,
    )?;
    Ok(())
}
