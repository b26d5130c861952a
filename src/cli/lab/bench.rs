//! `clothsr lab bench sim`: the simulator's benchmark ([`clothsr::sim::bench`]: a 1 m² sheet
//! dropped 2 cm above a sphere of radius 0.3 m, dt 1/300 s, at ~3K and ~40K vertices), side by
//! side with Newton 1.8 on the same scene when `tools/bench/setup-newton.sh` has been run.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use clothsr::garment::Fabric;
use clothsr::io::SceneFiles;
use clothsr::scene::Scene;
use clothsr::sim::bench::{
    parse_vertices, phase_columns, phase_header, sheet_on_sphere, time_steps, Timing, WARM_UP_STEPS,
};
use clothsr::sim::driver::Simulation;
use clothsr::sim::step::{LinearSolver, SolverMode};
use nalgebra::Vector3;

/// Arguments of `bench`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// What to benchmark: `sim` (the simulator beside Newton 1.8) or `pipeline` (the paper's
    /// Table 1 for a scene: coarse step, corrector, ISR and fine step times).
    #[arg(value_enum, default_value_t = What::Sim)]
    what: What,
    /// `pipeline`: the scenes, one row of the table each (default: the three sheet samples).
    #[arg(value_parser = crate::cli::values::input_file,
        long,
        value_delimiter = ',',
        default_value = "samples/sheet_three_balls.usda,samples/sheet_table.usda,samples/sheet_sphere.usda"
    )]
    scene: Vec<std::path::PathBuf>,
    /// `pipeline`: the model directory (`isr/`, optional `corrector/`), as for `clothsr run`.
    #[arg(value_parser = crate::cli::values::input_dir, long)]
    models: Option<std::path::PathBuf>,
    /// `pipeline`: frames to time (both the pipeline and the fine simulation run them from the
    /// scene's start).
    #[arg(long, default_value_t = 10)]
    frames: usize,
    /// Sheet resolutions as approximate vertex counts.
    #[arg(long, default_value = "3k,40k", value_delimiter = ',', value_parser = size)]
    sizes: Vec<String>,
    /// Timed steps per size (after 20 warm-up steps that bring the sheet onto the sphere).
    #[arg(long, default_value_t = 30)]
    steps: usize,
    /// Runs of each case, interleaved; the table gives the median run's time per step (and
    /// Newton 1.8's median over as many runs).
    #[arg(long, default_value_t = 1)]
    runs: usize,
    /// Skip the Newton 1.8 side-by-side run.
    #[arg(long)]
    no_peer: bool,
    /// Cloth self-collision, `on` or `off`, on both sides (clothsr's vertex-triangle and
    /// edge-edge repulsion; Style3D's default self-collision, XPBD's particle contacts). Off
    /// by default: the sheet on a sphere barely touches itself, so the default times the
    /// solvers alone.
    #[arg(long, default_value = "off", value_name = "on|off", value_parser = crate::cli::values::on_off(), action = clap::ArgAction::Set)]
    self_collision: bool,
    /// Solver modes to time: `converged` (Newton to tolerance, the simulator's default),
    /// `fast` (one full Newton step when the line search accepts it, as in Baraff & Witkin and
    /// Style3D; the pipeline's coarse simulation, which the corrector fixes), `data` (the fine
    /// simulation of data sets: fast sub-steps whose linear solves converged) and `tight`.
    #[arg(long, default_value = "converged,fast", value_delimiter = ',', value_parser = mode)]
    modes: Vec<String>,
    /// Relative residual of the linear solve (default: the simulator's).
    #[arg(long, value_parser = crate::cli::values::positive(1.0))]
    cg_tol: Option<f64>,
    /// Linear-solve iterations at most (default: the simulator's).
    #[arg(long)]
    cg_max: Option<usize>,
    /// Preconditioner: `jacobi`, `two-level` or `cholesky` (default: the simulator's).
    #[arg(long, value_enum)]
    solver: Option<Preconditioner>,
    /// `two-level`: vertices per aggregate.
    #[arg(long, default_value_t = 16)]
    aggregate: usize,
    /// `two-level`, `cholesky`: CG iterations above which the next Newton iteration refactors.
    #[arg(long, default_value_t = 0)]
    refactor_above: usize,
}

/// What `bench` times.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum What {
    /// The simulator beside Newton 1.8.
    Sim,
    /// The paper's Table 1 for a scene.
    Pipeline,
}

/// The linear solve's preconditioner.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Preconditioner {
    /// Jacobi.
    Jacobi,
    /// Two-level (aggregates).
    TwoLevel,
    /// Incomplete Cholesky.
    Cholesky,
}

/// A sheet size: an approximate vertex count (`3k`, `40000`), kept as written for the peer.
fn size(s: &str) -> Result<String, String> {
    match parse_vertices(s) {
        Some(v) if v.is_finite() && (4.0..=1e7).contains(&v) => Ok(s.trim().to_string()),
        _ => Err(format!(
            "'{s}': a vertex count from 4 to 10M (e.g. 3k, 40000)"
        )),
    }
}

/// A solver mode's name ([`SolverMode::name`]).
fn mode(s: &str) -> Result<String, String> {
    SolverMode::from_name(s.trim())
        .map(|m| m.name().to_string())
        .ok_or_else(|| format!("'{s}': fast, data, converged or tight"))
}

fn parse_size(s: &str) -> anyhow::Result<f64> {
    parse_vertices(s).ok_or_else(|| anyhow::anyhow!("bad size '{s}' (e.g. 3k, 40000)"))
}

/// Runs `bench`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.what == What::Pipeline {
        return pipeline(&args);
    }
    let solver = args.solver.map(|s| match s {
        Preconditioner::Jacobi => LinearSolver::JacobiPcg,
        Preconditioner::TwoLevel => LinearSolver::TwoLevelPcg {
            aggregate: args.aggregate,
            refactor_above: args.refactor_above,
        },
        Preconditioner::Cholesky => LinearSolver::CholeskyPcg {
            refactor_above: args.refactor_above,
        },
    });
    let cases: Vec<(&str, f64)> = args
        .modes
        .iter()
        .flat_map(|m| args.sizes.iter().map(move |s| (m.as_str(), s)))
        .map(|(m, s)| Ok((m, parse_size(s)?)))
        .collect::<anyhow::Result<_>>()?;
    anyhow::ensure!(args.runs >= 1, "--runs must be at least 1");
    let mut timings: Vec<Vec<Timing>> = vec![Vec::new(); cases.len()];
    for _ in 0..args.runs {
        for (k, &(mode, verts)) in cases.iter().enumerate() {
            let mut sim = sheet_on_sphere(verts, |p| {
                p.collision.self_collision = args.self_collision;
                if let Some(m) = SolverMode::from_name(mode) {
                    m.apply(p);
                }
                if let Some(t) = args.cg_tol {
                    p.cg_rel_tol = t;
                }
                if let Some(m) = args.cg_max {
                    p.cg_max_iters = m;
                }
                if let Some(s) = solver {
                    p.linear_solver = s;
                }
            })?;
            timings[k].push(time_steps(&mut sim, WARM_UP_STEPS, args.steps)?);
        }
    }
    println!(
        "{:>10} {:>8} {:>8} {:>9} {:>7} {:>7} {:>8} | ms/step:{}",
        "mode",
        "verts",
        "tris",
        "ms/step",
        "newton",
        "cg/nt",
        "contacts",
        phase_header()
    );
    let mut ours = Vec::new();
    for (&(mode, _), runs) in cases.iter().zip(&mut timings) {
        runs.sort_by(|a, b| a.ms_per_step.total_cmp(&b.ms_per_step));
        let t = runs[runs.len() / 2];
        println!(
            "{mode:>10} {:>8} {:>8} {:>9.2} {:>7.2} {:>7.1} {:>8} |         {}",
            t.vertices,
            t.triangles,
            t.ms_per_step,
            t.newton_per_step,
            t.cg_per_newton,
            t.contacts,
            phase_columns(&t.phases)
        );
        ours.push((mode, t.vertices, t.ms_per_step));
    }
    if args.no_peer {
        return Ok(());
    }
    newton_peer(&args, &ours)
}

/// Runs Newton 1.8 on the same scene `args.runs` times and prints its median time per step
/// beside `ours` ((mode, vertices, ms per step) of each case).
fn newton_peer(args: &Args, ours: &[(&str, usize, f64)]) -> anyhow::Result<()> {
    let root = clothsr::io::python::repo_root();
    let python = root.join("tools/bench/.venv-newton/bin/python");
    let script = root.join("tools/bench/newton_peer.py");
    if !python.exists() || !script.exists() {
        println!("Newton 1.8 peer: not installed (run `bash tools/bench/setup-newton.sh`)");
        return Ok(());
    }
    println!(
        "Newton 1.8 on the same scene (Warp CPU), self-collision {}:",
        if args.self_collision { "on" } else { "off" }
    );
    // (solver, vertices) → each run's median ms per step.
    let mut peer_ms: Vec<(String, f64, Vec<f64>)> = Vec::new();
    for _ in 0..args.runs {
        let mut peer = Command::new(&python);
        peer.arg(&script)
            .arg("--res")
            .arg(args.sizes.join(","))
            .arg("--steps")
            .arg(args.steps.min(10).to_string())
            .current_dir(Path::new(&root));
        if args.self_collision {
            peer.arg("--self-collision");
        }
        let out = peer.output()?;
        anyhow::ensure!(
            out.status.success(),
            "Newton peer failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        for line in String::from_utf8_lossy(&out.stdout).lines() {
            let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
                continue;
            };
            let (Some(solver), Some(verts), Some(ms)) = (
                v["solver"].as_str(),
                v["verts"].as_f64(),
                v["ms_per_step"].as_f64(),
            ) else {
                continue;
            };
            match peer_ms.iter_mut().find(|p| p.0 == solver && p.1 == verts) {
                Some(p) => p.2.push(ms),
                None => peer_ms.push((solver.to_string(), verts, vec![ms])),
            }
        }
    }
    for (solver, verts, mut runs) in peer_ms {
        runs.sort_by(f64::total_cmp);
        let ms = runs[runs.len() / 2];
        for mode in &args.modes {
            let mine = ours
                .iter()
                .filter(|o| o.0 == mode)
                .min_by(|a, b| ((a.1 as f64 - verts).abs()).total_cmp(&(b.1 as f64 - verts).abs()));
            if let Some((_, n, m)) = mine {
                println!(
                    "  {solver:<10} {verts:>6} verts {ms:>9.2} ms/step | clothsr {mode:<9} {m:>9.2} ms at {n} verts: ratio {:.2}",
                    m / ms
                );
            }
        }
    }
    Ok(())
}

/// The paper's Table 1 on this machine for one scene.
/// One row of the paper's Table 1.
struct TableRow {
    name: String,
    fine: (usize, usize),
    coarse: (usize, usize),
    /// Coarse step, corrector call per step, ISR per frame, fine step; seconds.
    t_c: f64,
    t_g: Option<f64>,
    /// The corrector's network alone per call, fused CPU pass and burn; seconds.
    network: Option<(f64, f64)>,
    t_i: f64,
    t_f: f64,
    steps: usize,
}

fn pipeline(args: &Args) -> anyhow::Result<()> {
    use clothsr::msr::Isr;
    let models = args
        .models
        .as_ref()
        .ok_or_else(|| anyhow::anyhow!("bench pipeline needs --models DIR (isr/, corrector/)"))?;
    anyhow::ensure!(args.frames > 0, "--frames must be at least 1");
    let isr = Isr::load(&models.join("isr"))?;
    let mut rows = Vec::new();
    for scene in &args.scene {
        rows.push(pipeline_row(args, models, &isr, scene)?);
    }
    println!(
        "Table 1 on this machine: {} frames per scene, models {}; times in ms",
        args.frames,
        models.display()
    );
    println!(
        "{:<20} {:>15} {:>13} {:>8} {:>8} {:>8} {:>9} {:>9} {:>10} {:>9}",
        "scene",
        "HR verts/tris",
        "LR verts/tris",
        "t_c",
        "t_g",
        "t_i",
        "t_f",
        "t_sf",
        "t_ff",
        "t_ff/t_sf"
    );
    for r in &rows {
        let t_g = r.t_g.unwrap_or(0.0);
        let t_sf = r.steps as f64 * (r.t_c + t_g) + r.t_i;
        let t_ff = r.steps as f64 * r.t_f;
        println!(
            "{:<20} {:>15} {:>13} {:>8.2} {:>8} {:>8.1} {:>9.1} {:>9.1} {:>10.1} {:>8.2}×",
            r.name,
            format!("{}/{}", r.fine.0, r.fine.1),
            format!("{}/{}", r.coarse.0, r.coarse.1),
            r.t_c * 1e3,
            r.t_g.map_or("-".to_string(), |g| format!("{:.2}", g * 1e3)),
            r.t_i * 1e3,
            r.t_f * 1e3,
            t_sf * 1e3,
            t_ff * 1e3,
            t_ff / t_sf
        );
    }
    println!("t_sf = steps·(t_c + t_g) + t_i (the SR frame), t_ff = steps·t_f (the fine frame)");
    for r in &rows {
        if let Some((fused, burn)) = r.network {
            println!(
                "{}: the corrector's network alone {:.2} ms a call (fused CPU pass), {:.2} ms on \
                 burn ({:.2}×)",
                r.name,
                fused * 1e3,
                burn * 1e3,
                burn / fused
            );
        }
    }
    Ok(())
}

/// The corrector in `dir`'s network alone per call on `sim`'s current state, with the fused
/// CPU forward pass and with burn: seconds, the means of `reps` calls each, alternated.
fn network_times(dir: &Path, sim: &Simulation, reps: usize) -> anyhow::Result<(f64, f64)> {
    use clothsr::corrector::Corrector;
    let mesh = &sim.sim.model.mesh;
    let fused = Corrector::load(dir, mesh)?;
    let mut burn = Corrector::load(dir, mesh)?;
    burn.use_burn();
    let x = &sim.state.x;
    let v = &sim.state.v;
    let dv = vec![Vector3::zeros(); x.len()];
    let body = clothsr::corrector::graph::body_proximity(x, &sim.colliders, sim.state.t_s);
    let (mut t_fused, mut t_burn) = (0.0, 0.0);
    for k in 0..=reps {
        for (c, t) in [(&fused, &mut t_fused), (&burn, &mut t_burn)] {
            let start = Instant::now();
            c.predict(x, v, &dv, &body)?;
            // The first call of each warms up and is not counted.
            if k > 0 {
                *t += start.elapsed().as_secs_f64();
            }
        }
    }
    Ok((t_fused / reps as f64, t_burn / reps as f64))
}

fn pipeline_row(
    args: &Args,
    models: &Path,
    isr: &clothsr::msr::Isr,
    scene_path: &Path,
) -> anyhow::Result<TableRow> {
    use clothsr::pipeline::models::has_corrector;
    use clothsr::pipeline::{options_for_run, Options, Pipeline};
    let scene = Scene::load(scene_path, &Fabric::default())?;
    let corrector_dir = models.join("corrector");
    let corrector = has_corrector(models).then_some(corrector_dir.as_path());
    // The coarse model `clothsr run` would use with these models.
    let (opts, _) = options_for_run(models, corrector, Options::default())?;
    let mut p = Pipeline::new(&scene, isr, corrector, opts)?;
    p.super_resolve()?;
    let steps = p.coarse.steps_per_frame;
    let (mut tc, mut tg, mut ti) = (0.0, 0.0, 0.0);
    for _ in 0..args.frames {
        p.advance_frame()?;
        tc += p.times.simulator_s;
        tg += p.times.corrector_s;
        ti += p.times.msr_s;
    }
    let n = args.frames as f64;
    let network = match corrector {
        Some(dir) => Some(network_times(dir, &p.coarse, 50)?),
        None => None,
    };
    let mut fine = clothsr::data::new_simulation(
        &scene,
        isr.cfg.pixel_m,
        opts.self_collision,
        opts.coarse_solver,
        None,
    )?;
    let t = Instant::now();
    for _ in 0..args.frames {
        fine.advance_frame(|_| {})?;
    }
    let tf = t.elapsed().as_secs_f64() / (n * fine.steps_per_frame as f64);
    let (cm, fm) = (&p.coarse.sim.model.mesh, &fine.sim.model.mesh);
    Ok(TableRow {
        name: scene_path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
        fine: (fm.num_vertices(), fm.triangles.len()),
        coarse: (cm.num_vertices(), cm.triangles.len()),
        t_c: tc / (n * steps as f64),
        t_g: p.has_corrector().then(|| tg / (n * steps as f64)),
        network,
        t_i: ti / n,
        t_f: tf,
        steps,
    })
}
