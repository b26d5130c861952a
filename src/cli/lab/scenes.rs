//! `clothsr lab scenes -o DIR [--set training|held-out] [NAME…]`: writes the procedural shots
//! the generic models are trained on and measured with ([`clothsr::scene::catalogue`]) as USD.

use std::path::PathBuf;

use clothsr::io::SceneFiles;
use clothsr::scene::catalogue;

/// Which shots to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Set {
    /// The generic models' training shots.
    Training,
    /// The shots held out from them.
    HeldOut,
}

/// Arguments of `scenes`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output directory (one `NAME.usda` per shot).
    #[arg(value_parser = crate::cli::values::output_dir, short, long)]
    output: PathBuf,
    /// A fixed list of shots.
    #[arg(long, value_enum)]
    set: Option<Set>,
    /// Shots by name, `garment-fabric-collider-motion` (e.g. square-silk-sphere-still).
    names: Vec<String>,
    /// Output frames of each shot (30 a second); animated colliders are sampled this long.
    #[arg(long, default_value_t = 60)]
    frames: usize,
}

/// Runs `scenes`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let mut names = args.names.clone();
    match args.set {
        Some(Set::Training) => names.extend(catalogue::TRAINING.iter().map(|s| s.to_string())),
        Some(Set::HeldOut) => names.extend(catalogue::HELD_OUT.iter().map(|s| s.to_string())),
        None => {}
    }
    anyhow::ensure!(!names.is_empty(), "name shots or give --set");
    anyhow::ensure!(args.frames > 0, "--frames must be at least 1");
    std::fs::create_dir_all(&args.output)?;
    for name in &names {
        let scene = catalogue::scene(name, args.frames).ok_or_else(|| {
            anyhow::anyhow!(
                "'{name}' is not a shot: garment-fabric-collider-motion from {:?}, {:?}, {:?}, {:?}",
                catalogue::GARMENTS,
                catalogue::FABRICS,
                catalogue::COLLIDERS,
                catalogue::MOTIONS
            )
        })?;
        let path = args.output.join(format!("{name}.usda"));
        for w in scene.write_usd(&path, true)? {
            tracing::warn!("{}: {w}", path.display());
        }
        println!("{}", path.display());
    }
    Ok(())
}
