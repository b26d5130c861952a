//! `clothsr convert IN... -o OUT.usda [--collider F]... [--avatar F]`: a USD scene with
//! clothsr's schema from GarmentCode patterns, OBJ or USD garments (several garments on one
//! avatar) plus colliders.

use std::path::PathBuf;

use clothsr::io::scene_files::{convert, Convert};
use clothsr::io::SceneFiles;

/// Arguments of `convert`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// GarmentCode JSON, OBJ cloth meshes or USD scenes: their garments go into one scene
    /// (several garments on one avatar; a repeated name gets a suffix). The first sets the
    /// frame rate and range.
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    /// Output USD file (.usda, .usd or .usdc).
    #[arg(value_parser = crate::cli::values::output_usd, short, long)]
    output: PathBuf,
    /// Collider: OBJ, OBJ sequence (frame_%04d.obj) or USD; repeatable.
    #[arg(value_parser = crate::cli::values::input_file, long)]
    collider: Vec<PathBuf>,
    /// Avatar: a USD file with a UsdSkel-skinned or time-sampled body.
    #[arg(value_parser = crate::cli::values::input_file, long)]
    avatar: Option<PathBuf>,
    /// Fabric preset for patterns and meshes without one.
    #[arg(long, default_value = "cotton")]
    fabric: clothsr::garment::FabricPreset,
    /// Frames per second of the scene (OBJ sequences are read at this rate).
    #[arg(value_parser = crate::cli::values::positive(1000.0), long)]
    fps: Option<f64>,
    /// Last frame to simulate (default: the end of the colliders' animation).
    #[arg(value_parser = clap::value_parser!(i64).range(0..), long)]
    frames: Option<i64>,
    /// Write text USD even for a .usd file.
    #[arg(long)]
    ascii: bool,
}

/// Runs `convert`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let fabric = args.fabric.fabric();
    for input in &args.inputs {
        super::check_output(input, &args.output)?;
    }
    let output = args.output.clone();
    let scene = convert(&Convert {
        inputs: args.inputs.clone(),
        colliders: args.collider.iter().chain(&args.avatar).cloned().collect(),
        fabric,
        fps: args.fps,
        frames: args.frames,
    })?;
    for w in scene.write_usd(&output, args.ascii)? {
        tracing::warn!("{}: {w}", output.display());
    }
    tracing::info!(
        "wrote {}: {} pattern garments, {} cloth meshes, {} colliders, frames {}..{}",
        output.display(),
        scene.garments.len(),
        scene.cloths.len(),
        scene.colliders.len(),
        scene.frame_start,
        scene.frame_end
    );
    Ok(())
}
