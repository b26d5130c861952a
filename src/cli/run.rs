//! `clothsr run SCENE -o OUT.usdc --models DIR`: the whole pipeline (see
//! [`clothsr::pipeline`]) — coarse simulation, corrector, mesh super-resolution — writing the
//! fine garments as time-sampled points frame by frame.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clothsr::io::usd::{AnimationWriter, MeshOut, SolverSettings, StageOut};
use clothsr::msr::Isr;
use clothsr::pipeline::{Options, Pipeline};
use clothsr::scene::Scene;
use indicatif::{ProgressBar, ProgressStyle};

/// Arguments of `run`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene: USD (garments, colliders, solver), GarmentCode JSON or OBJ cloth.
    scene: PathBuf,
    /// Output USD file: the fine garments (and the colliders), one time sample per frame.
    #[arg(short, long)]
    output: PathBuf,
    /// Model directory: `isr/` (required, `clothsr train isr`) and `corrector/` (used when
    /// present, `clothsr train corrector`).
    #[arg(long)]
    models: PathBuf,
    /// Run without the corrector even when the models have one (the simulator alone drives
    /// the coarse mesh).
    #[arg(long)]
    no_corrector: bool,
    /// Frames to run (default: the scene's frame range).
    #[arg(long)]
    frames: Option<usize>,
    /// Coarse edge length, millimetres.
    #[arg(long, default_value_t = 20.0)]
    coarse_mm: f64,
    /// Extra colliders (OBJ, OBJ sequence, USD).
    #[arg(long)]
    collider: Vec<PathBuf>,
    /// Avatar (USD, UsdSkel or point cache).
    #[arg(long)]
    avatar: Option<PathBuf>,
    /// Fabric preset for patterns and meshes without one.
    #[arg(long, default_value = "cotton")]
    fabric: String,
    /// Iterate Newton to convergence every coarse step instead of the fast one-step solver the
    /// sample models were trained beside.
    #[arg(long)]
    converged: bool,
    /// Cloth self-collision in the coarse simulation.
    #[arg(long)]
    self_collision: bool,
    /// Write text USD even for a .usd file.
    #[arg(long)]
    ascii: bool,
}

/// Runs `run`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let output = super::check_output(&args.scene, &args.output)?;
    anyhow::ensure!(
        args.coarse_mm.is_finite() && args.coarse_mm > 0.0,
        "--coarse-mm must be positive"
    );
    let isr_dir = args.models.join("isr");
    anyhow::ensure!(
        isr_dir.join("config.json").exists(),
        "{}: no ISR model here (expected {}/config.json; train one with 'clothsr train isr')",
        args.models.display(),
        isr_dir.display()
    );
    let isr = Isr::load(&isr_dir)?;
    let corrector_dir = args.models.join("corrector");
    let corrector = (!args.no_corrector && corrector_dir.join("config.json").exists())
        .then_some(corrector_dir.as_path());
    let mut scene = Scene::load(&args.scene, &super::fabric(&args.fabric)?)?;
    for c in &args.collider {
        scene.add_collider_file(c)?;
    }
    if let Some(a) = &args.avatar {
        scene.add_collider_file(a)?;
    }
    let frames = args
        .frames
        .unwrap_or((scene.frame_end - scene.frame_start).max(0) as usize);
    anyhow::ensure!(
        frames > 0,
        "nothing to run: give --frames N (the scene's frame range is empty)"
    );
    let opts = Options {
        coarse_edge_m: args.coarse_mm * 1e-3,
        fast: !args.converged,
        self_collision: args.self_collision,
        match_contact_thickness: true,
    };
    let t_setup = Instant::now();
    let mut p = Pipeline::new(&scene, &isr, corrector, opts)
        .with_context(|| format!("setting up {}", args.scene.display()))?;
    tracing::info!(
        "coarse {} vertices, fine {} vertices ({} mm pixels), corrector {}; set up in {:.1} s",
        p.coarse.sim.model.num_vertices(),
        p.fine.num_vertices(),
        isr.cfg.pixel_m * 1e3,
        if p.has_corrector() { "on" } else { "off" },
        t_setup.elapsed().as_secs_f64()
    );
    p.super_resolve()?;

    let start = scene.frame_start as f64;
    let mut meshes: Vec<MeshOut> = p
        .fine_part_meshes
        .iter()
        .map(|(name, mesh, fabric)| {
            let mut m = MeshOut::cloth(name, mesh, fabric, isr.cfg.pixel_m);
            m.animated = true;
            m
        })
        .collect();
    for c in &scene.colliders {
        meshes.push(MeshOut::collider(c, scene.fps));
    }
    let stage = StageOut {
        fps: scene.fps,
        start,
        end: start + frames as f64,
        doc: Some(format!(
            "clothsr run {} with models {} (corrector {})",
            args.scene.display(),
            args.models.display(),
            if p.has_corrector() { "on" } else { "off" }
        )),
        ascii: args.ascii,
        garments: Vec::new(),
        meshes,
        solver: Some(SolverSettings {
            gravity_m_s2: scene.gravity_m_s2,
            dt_s: p.coarse.sim.params.dt_s,
        }),
    };
    let mut writer = AnimationWriter::create(&output, &stage)?;
    writer.write_frame(start, &p.fine_part_positions())?;
    let bar = ProgressBar::new(frames as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} frames {per_sec} eta {eta} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let t0 = Instant::now();
    let mut totals = [0.0f64; 3];
    for f in 1..=frames {
        if let Err(e) = p.advance_frame() {
            bar.abandon();
            writer
                .checkpoint()
                .context("saving the frames written so far")?;
            return Err(e).with_context(|| {
                format!(
                    "frame {f}: {} keeps the {} frames before",
                    output.display(),
                    f - 1
                )
            });
        }
        let t = p.times;
        totals[0] += t.simulator_s;
        totals[1] += t.corrector_s;
        totals[2] += t.msr_s;
        let message = format!(
            "frame {f}/{frames}: simulator {:.2} s, corrector {:.2} s, MSR {:.2} s",
            t.simulator_s, t.corrector_s, t.msr_s
        );
        if bar.is_hidden() {
            tracing::info!("{message}");
        }
        bar.set_message(message);
        bar.inc(1);
        writer.write_frame(start + f as f64, &p.fine_part_positions())?;
    }
    bar.finish();
    for w in writer.finish()? {
        tracing::warn!("{}: {w}", output.display());
    }
    let n = frames as f64;
    tracing::info!(
        "wrote {}: {frames} frames in {:.1} s; per frame: simulator {:.3} s, corrector {:.3} s, MSR {:.3} s",
        output.display(),
        t0.elapsed().as_secs_f64(),
        totals[0] / n,
        totals[1] / n,
        totals[2] / n
    );
    Ok(())
}
