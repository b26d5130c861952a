//! `clothsr convert IN -o OUT.usda [--collider F]... [--avatar F]`: a USD scene with clothsr's
//! schema from a GarmentCode pattern or an OBJ cloth mesh plus colliders.

use std::path::PathBuf;

use clothsr::io::SceneFiles;
use clothsr::scene::Scene;

/// Arguments of `convert`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A GarmentCode JSON, an OBJ cloth mesh with vt, or a USD scene.
    input: PathBuf,
    /// Output USD file (.usda, .usd or .usdc).
    #[arg(short, long)]
    output: PathBuf,
    /// Collider: OBJ, OBJ sequence (frame_%04d.obj) or USD; repeatable.
    #[arg(long)]
    collider: Vec<PathBuf>,
    /// Avatar: a USD file with a UsdSkel-skinned or time-sampled body.
    #[arg(long)]
    avatar: Option<PathBuf>,
    /// Fabric preset for patterns and meshes without one.
    #[arg(long, default_value = "cotton")]
    fabric: String,
    /// Frames per second of the scene (OBJ sequences are read at this rate).
    #[arg(long)]
    fps: Option<f64>,
    /// Last frame to simulate (default: the end of the colliders' animation).
    #[arg(long)]
    frames: Option<i64>,
    /// Write text USD even for a .usd file.
    #[arg(long)]
    ascii: bool,
}

/// Runs `convert`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let output = super::check_output(&args.input, &args.output)?;
    let mut scene = Scene::load(&args.input, &super::fabric(&args.fabric)?)?;
    if let Some(fps) = args.fps {
        anyhow::ensure!(fps.is_finite() && fps > 0.0, "--fps must be positive");
        scene.fps = fps;
    }
    for c in args.collider.iter().chain(args.avatar.iter()) {
        scene.add_collider_file(c)?;
    }
    if let Some(n) = args.frames {
        anyhow::ensure!(n >= 0, "--frames must be >= 0");
        scene.frame_end = scene.frame_start + n;
    }
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
