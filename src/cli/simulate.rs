//! `clothsr simulate SCENE --edge-mm 20 --frames N -o OUT.usdc`: the cloth simulator alone,
//! writing time-sampled points frame by frame.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use clothsr::io::usd::{AnimationWriter, MeshOut, SolverSettings, StageOut};
use clothsr::io::SceneFiles;
use clothsr::scene::Scene;
use clothsr::sim::driver::{FrameStats, Simulation};
use indicatif::{ProgressBar, ProgressStyle};

/// Arguments of `simulate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene: USD (garments, colliders, solver), GarmentCode JSON or OBJ cloth.
    scene: PathBuf,
    /// Cloth edge length for sewing patterns, millimetres.
    #[arg(value_parser = crate::cli::values::positive(crate::cli::values::MAX_MM), long, default_value_t = crate::cli::COARSE_MM)]
    edge_mm: f64,
    /// Frames to simulate (default: the scene's frame range).
    #[arg(long)]
    frames: Option<usize>,
    /// Output USD file.
    #[arg(value_parser = crate::cli::values::output_usd, short, long)]
    output: PathBuf,
    /// Extra colliders (OBJ, OBJ sequence, USD).
    #[arg(value_parser = crate::cli::values::input_file, long)]
    collider: Vec<PathBuf>,
    /// Scale applied to the --collider files' points (their units to metres).
    #[arg(value_parser = crate::cli::values::positive(crate::cli::values::MAX_FACTOR), long, default_value_t = 1.0)]
    collider_scale: f64,
    /// Offset (x,y,z metres) applied to the --collider files after scaling.
    #[arg(long, value_parser = crate::cli::values::triple, allow_hyphen_values = true)]
    collider_offset: Option<[f64; 3]>,
    /// Avatar (USD, UsdSkel or point cache).
    #[arg(value_parser = crate::cli::values::input_file, long)]
    avatar: Option<PathBuf>,
    /// Fabric preset for patterns and meshes without one.
    #[arg(long, default_value = "cotton")]
    fabric: clothsr::garment::FabricPreset,
    /// Time step in seconds (default: the scene's, else 1/300).
    #[arg(value_parser = crate::cli::values::positive(1.0), long)]
    dt: Option<f64>,
    /// Stiffness κ of the contact repulsion ½κ(d̂ − d)², N/m (default 2000)
    #[arg(value_parser = crate::cli::values::positive(1e12), long)]
    contact_stiffness: Option<f64>,
    /// Coulomb friction coefficient against colliders (default 0.3)
    #[arg(value_parser = crate::cli::values::non_negative(100.0), long)]
    friction: Option<f64>,
    /// Cloth self-collision, `on` or `off`.
    #[arg(long, default_value = "on", value_name = "on|off", value_parser = crate::cli::values::on_off(), action = clap::ArgAction::Set)]
    self_collision: bool,
    /// Write text USD even for a .usd file.
    #[arg(long)]
    ascii: bool,
    /// One Newton iteration per step when its full step is accepted (Baraff & Witkin style,
    /// faster: `docs/benchmarks.md`) instead of iterating to convergence.
    #[arg(long)]
    fast: bool,
    /// Skip dressing: by default garments with seams are first sewn with gravity off and the
    /// colliders held at the first frame, then settled under gravity, before frame one.
    #[arg(long)]
    no_dress: bool,
    /// Longest sewing phase of dressing, simulated seconds.
    #[arg(value_parser = crate::cli::values::non_negative(crate::cli::values::MAX_S), long, default_value_t = 2.0)]
    dress_max_s: f64,
    /// Settling under gravity after sewing, simulated seconds.
    #[arg(value_parser = crate::cli::values::non_negative(crate::cli::values::MAX_S), long, default_value_t = 0.3)]
    settle_s: f64,
}

/// Runs `simulate`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let output = super::check_output(&args.scene, &args.output)?;
    let scene = load_scene(&args)?;
    let frames = args
        .frames
        .unwrap_or((scene.frame_end - scene.frame_start).max(0) as usize);
    anyhow::ensure!(
        frames > 0,
        "nothing to simulate: give --frames N (the scene's frame range is empty)"
    );
    let mut sim = new_simulation(&scene, &args)?;
    if !args.no_dress && !sim.sim.model.mesh.seam_pairs.is_empty() {
        dress(&mut sim, args.dress_max_s, args.settle_s)?;
    }
    log_model(&sim);

    let stage = stage(&args, &scene, &sim, frames);
    let start = stage.start;
    let mut writer = AnimationWriter::create(&output, &stage)?;
    writer.write_frame(start, &sim.part_positions())?;

    let bar = ProgressBar::new((frames * sim.steps_per_frame) as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} steps {per_sec} eta {eta} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let t0 = Instant::now();
    let tangled_frames = animate(&mut sim, &mut writer, &bar, &output, start, frames, t0)?;
    bar.finish();
    if tangled_frames > 0 {
        tracing::warn!(
            "{}: the cloth passed through itself in {tangled_frames} of {frames} frames",
            output.display()
        );
    }
    for w in writer.finish()? {
        tracing::warn!("{}: {w}", output.display());
    }
    let secs = t0.elapsed().as_secs_f64();
    tracing::info!(
        "wrote {}: {frames} frames in {secs:.1} s ({:.2} ms per step, {:.1} s per simulated second)",
        output.display(),
        secs * 1e3 / (frames * sim.steps_per_frame) as f64,
        secs / (frames as f64 / scene.fps)
    );
    Ok(())
}

/// The scene with the extra colliders, the avatar and the time step given.
fn load_scene(args: &Args) -> anyhow::Result<Scene> {
    let offset = nalgebra::Vector3::from(args.collider_offset.unwrap_or_default());
    let mut scene = Scene::load(&args.scene, &args.fabric.fabric())?;
    for c in &args.collider {
        scene.add_collider_file_transformed(c, args.collider_scale, offset)?;
    }
    if let Some(a) = &args.avatar {
        scene.add_collider_file(a)?;
    }
    if let Some(dt) = args.dt {
        scene.dt_s = dt;
    }
    Ok(scene)
}

/// The simulation of `scene` at `--edge-mm` under the solver flags given.
fn new_simulation(scene: &Scene, args: &Args) -> anyhow::Result<Simulation> {
    let (self_collision, fast) = (args.self_collision, args.fast);
    let sim = Simulation::new(scene, args.edge_mm * 1e-3, |p| {
        p.collision.self_collision = self_collision;
        p.newton_exact = !fast;
        if let Some(k) = args.contact_stiffness {
            p.collision.kappa = k;
        }
        if let Some(mu) = args.friction {
            p.friction = mu;
        }
    })?;
    Ok(sim)
}

/// Sews the garments with seams, then settles them, before the first frame.
fn dress(sim: &mut Simulation, dress_max_s: f64, settle_s: f64) -> anyhow::Result<()> {
    let t = Instant::now();
    let d = sim
        .dress(dress_max_s, settle_s, 1e-3)
        .context("dressing the garments (sewing before the animation)")?;
    tracing::info!(
        "dressed: {} panels rolled around the body; {} sewing + {} settling steps in {:.1} s; widest seam gap {:.1} → {:.2} mm, seams pulled up to {}× as hard, penetration {:.2} mm",
        d.wrapped_panels,
        d.sew_steps,
        d.settle_steps,
        t.elapsed().as_secs_f64(),
        d.initial_seam_gap_m * 1e3,
        d.seam_gap_m * 1e3,
        1u32 << d.harder_pulls,
        d.max_penetration_m * 1e3
    );
    Ok(())
}

/// Logs the cloth model's size and the solver's time step and contact distance.
fn log_model(sim: &Simulation) {
    let model = &sim.sim.model;
    tracing::info!(
        "{} vertices, {} triangles, {} hinges, {} seam pairs; dt {:.5} s, {} steps per frame, d̂ {:.1} mm",
        model.num_vertices(),
        model.mesh.triangles.len(),
        model.hinges.len(),
        model.mesh.seam_pairs.len(),
        sim.sim.params.dt_s,
        sim.steps_per_frame,
        sim.sim.params.collision.dhat_m * 1e3
    );
}

/// The output stage: the animated cloth parts and the colliders over `frames` frames.
fn stage(args: &Args, scene: &Scene, sim: &Simulation, frames: usize) -> StageOut<'static> {
    let model = &sim.sim.model;
    let start = scene.frame_start as f64;
    let mut meshes: Vec<MeshOut> = (0..model.parts.len())
        .map(|i| {
            let part = &model.parts[i];
            let mut m = MeshOut::cloth(&part.name, &model.part_mesh(i), &part.fabric, sim.edge_m);
            m.animated = true;
            m
        })
        .collect();
    for c in &scene.colliders {
        meshes.push(MeshOut::collider(c, scene.fps));
    }
    StageOut {
        over: None,
        fps: scene.fps,
        start,
        end: start + frames as f64,
        doc: Some(format!(
            "clothsr simulate {} at {} mm",
            args.scene.display(),
            args.edge_mm
        )),
        ascii: args.ascii,
        garments: Vec::new(),
        meshes,
        solver: Some(SolverSettings {
            gravity_m_s2: scene.gravity_m_s2,
            dt_s: sim.sim.params.dt_s,
        }),
    }
}

/// Simulates frames 1..=`frames` and writes each one, checkpointing the file every ten
/// seconds; returns how many frames the cloth passed through itself in. On a failure the
/// frames simulated so far are saved.
fn animate(
    sim: &mut Simulation,
    writer: &mut AnimationWriter,
    bar: &ProgressBar,
    output: &Path,
    start: f64,
    frames: usize,
    t0: Instant,
) -> anyhow::Result<usize> {
    let mut last_checkpoint = Instant::now();
    // Cloth passing through itself is what users see first and the solver must never do:
    // counted every frame (a BVH pass, a few ms at 4K vertices), reported when it happens.
    let self_collision = sim.sim.params.collision.self_collision;
    let mut tangled_frames = 0usize;
    for f in 1..=frames {
        let result = sim.advance_frame(|_| bar.inc(1));
        let stats = match result {
            Ok(s) => s,
            Err(e) => {
                bar.abandon();
                writer
                    .checkpoint()
                    .context("saving the frames simulated so far")?;
                return Err(e).with_context(|| {
                    format!(
                        "frame {f}: {} keeps the {} frames simulated before",
                        output.display(),
                        f - 1
                    )
                });
            }
        };
        let crossings = if self_collision {
            sim.sim.self_intersections(&sim.state.x)
        } else {
            0
        };
        if crossings > 0 {
            tangled_frames += 1;
            if tangled_frames == 1 {
                tracing::warn!(
                    "frame {f}: the cloth passes through itself ({crossings} edges through triangles)"
                );
            }
        }
        let message = frame_message(f, frames, &stats, crossings);
        if bar.is_hidden() {
            // No terminal (batch, CI, DCC pipelines): log instead of drawing a bar.
            tracing::info!("{message}  ({:.1} s elapsed)", t0.elapsed().as_secs_f64());
        }
        bar.set_message(message);
        writer.write_frame(start + f as f64, &sim.part_positions())?;
        if last_checkpoint.elapsed().as_secs_f64() > 10.0 {
            writer.checkpoint()?;
            last_checkpoint = Instant::now();
        }
    }
    Ok(tangled_frames)
}

/// The progress line of frame `f`: solver iterations, contacts, penetration, crossings.
fn frame_message(f: usize, frames: usize, stats: &FrameStats, crossings: usize) -> String {
    format!(
        "frame {f}/{frames}  newton {:.1}/step  cg {:.0}/step  substeps {}  contacts {}  max penetration {:.2} mm{}",
        stats.steps.newton_iters as f64 / stats.step_count as f64,
        stats.steps.cg_iters as f64 / stats.step_count as f64,
        stats.steps.substeps,
        stats.steps.contacts,
        stats.max_penetration_m * 1e3,
        if crossings > 0 {
            format!("  crossings {crossings}")
        } else {
            String::new()
        }
    )
}
