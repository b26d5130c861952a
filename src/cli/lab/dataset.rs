//! `clothsr lab dataset SCENE --coarse-mm 20 --fine-mm 2.5 --frames N -o DIR`: training data
//! (the paper's §3.3.1) from a fine simulation; see [`clothsr::data`] for the format.

use std::path::{Path, PathBuf};
use std::time::Instant;

use clothsr::data::Manifest;
use clothsr::dataset::{generate, Options};
use clothsr::scene::Scene;
use indicatif::{ProgressBar, ProgressStyle};

/// Arguments of `dataset`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene: USD, GarmentCode JSON or OBJ cloth.
    scene: PathBuf,
    /// Output directory (created; a run already there with the same settings is resumed).
    #[arg(value_parser = crate::cli::values::output_dir, short, long)]
    output: PathBuf,
    /// Coarse edge length, millimetres.
    #[arg(value_parser = crate::cli::values::positive(crate::cli::values::MAX_MM), long, default_value_t = crate::cli::COARSE_MM)]
    coarse_mm: f64,
    /// Fine edge length, millimetres (the ground truth).
    #[arg(value_parser = crate::cli::values::positive(crate::cli::values::MAX_MM), long, default_value_t = 2.5)]
    fine_mm: f64,
    /// Output frames (each `1/(fps·dt)` steps).
    #[arg(long)]
    frames: usize,
    #[command(flatten)]
    inputs: crate::cli::SceneInputs,
    #[command(flatten)]
    variation: crate::cli::VariationArgs,
    /// Cloth self-collision at both resolutions, `on` or `off`.
    #[arg(long, default_value = "on", value_name = "on|off", value_parser = crate::cli::values::on_off(), action = clap::ArgAction::Set)]
    self_collision: bool,
    /// Skip sewing and settling before frame 0.
    #[arg(long)]
    no_dress: bool,
    /// The coarse steps (M_c) in fast mode, one Newton iteration a step when its full step is
    /// accepted, as the pipeline's coarse simulation runs; the corrector then learns beside
    /// the same solver.
    #[arg(long)]
    fast: bool,
    /// The fine simulation's solver mode: `data` (checked against a tight reference by
    /// `clothsr lab converge`) or `tight` (the reference itself, slower).
    #[arg(long, default_value = "data", value_parser = fine_mode)]
    fine_mode: clothsr::sim::step::SolverMode,
    /// Keep the coarse mesh's own contact thickness d̂ (15 % of its edge) instead of the fine
    /// simulation's (garments with seams always keep their own).
    #[arg(long)]
    coarse_contact_thickness: bool,
}

fn fine_mode(s: &str) -> Result<clothsr::sim::step::SolverMode, String> {
    use clothsr::sim::step::SolverMode;
    match SolverMode::from_name(s) {
        Some(m @ (SolverMode::Data | SolverMode::Tight)) => Ok(m),
        _ => Err(format!(
            "'{s}': the fine simulation runs in 'data' or 'tight' mode"
        )),
    }
}

/// Runs `dataset`.
pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.coarse_mm.is_finite() && args.fine_mm.is_finite() && args.fine_mm > 0.0,
        "--coarse-mm and --fine-mm must be positive"
    );
    anyhow::ensure!(
        args.coarse_mm > args.fine_mm,
        "--coarse-mm ({}) must be larger than --fine-mm ({})",
        args.coarse_mm,
        args.fine_mm
    );
    anyhow::ensure!(args.frames > 0, "--frames must be at least 1");
    let variation = args.variation.variation();
    let scene = args.inputs.load(&args.scene)?;
    let opts = Options {
        coarse_edge_m: args.coarse_mm * 1e-3,
        fine_edge_m: args.fine_mm * 1e-3,
        frames: args.frames,
        dress: !args.no_dress,
        self_collision: args.self_collision,
        variation,
        fast: args.fast,
        fine_mode: args.fine_mode,
        match_contact_thickness: !args.coarse_contact_thickness,
        source: Some(args.inputs.source(&args.scene).absolute()),
    };
    generate_with_progress(
        &scene,
        &args.scene.display().to_string(),
        &opts,
        &args.output,
    )?;
    Ok(())
}

/// [`generate`] with a progress bar (log lines when the bar is hidden) and a closing summary.
pub(super) fn generate_with_progress(
    scene: &Scene,
    scene_name: &str,
    opts: &Options,
    output: &Path,
) -> anyhow::Result<Manifest> {
    let bar = ProgressBar::new(opts.frames as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} frames {per_sec} eta {eta} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let t0 = Instant::now();
    let mut resumed_at = None;
    let m = generate(scene, scene_name, opts, output, |p| {
        if resumed_at.is_none() {
            resumed_at = Some(p.frames_done);
            bar.set_position(p.frames_done as u64);
            bar.reset_eta();
            if p.frames_done > 0 {
                tracing::info!("resuming after frame {}", p.frames_done);
            }
        } else {
            bar.set_position(p.frames_done as u64);
        }
        if bar.is_hidden() {
            tracing::info!(
                "frame {}/{} ({:.1} s elapsed)",
                p.frames_done,
                p.frames,
                t0.elapsed().as_secs_f64()
            );
        }
    })?;
    bar.finish_and_clear();
    tracing::info!(
        "wrote {}: {} frames, coarse {} / fine {} vertices, {:.1} s",
        output.display(),
        m.frames_done,
        m.coarse_vertices,
        m.fine_vertices,
        t0.elapsed().as_secs_f64()
    );
    Ok(m)
}
