//! `clothsr bench sim`: the simulator's benchmark (a 1 m² sheet dropped 2 cm above a sphere of
//! radius 0.3 m, dt 1/300 s, at ~3K and ~40K vertices), side by side with Newton 1.8 on the same
//! scene when `benches/setup-newton.sh` has been run.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use clothsr::garment::Fabric;
use clothsr::scene::samples::flat_sheet;
use clothsr::scene::{Collider, Scene};
use clothsr::sim::driver::Simulation;
use nalgebra::Vector3;

/// Arguments of `bench`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// What to benchmark (only `sim` for now).
    #[arg(default_value = "sim")]
    what: String,
    /// Sheet resolutions as approximate vertex counts.
    #[arg(long, default_value = "3k,40k", value_delimiter = ',')]
    sizes: Vec<String>,
    /// Timed steps per size (after 20 warm-up steps that bring the sheet onto the sphere).
    #[arg(long, default_value_t = 30)]
    steps: usize,
    /// Skip the Newton 1.8 side-by-side run.
    #[arg(long)]
    no_peer: bool,
}

fn parse_size(s: &str) -> anyhow::Result<f64> {
    let t = s.trim().to_ascii_lowercase();
    let (num, mult) = match t.strip_suffix('k') {
        Some(n) => (n, 1e3),
        None => (t.as_str(), 1.0),
    };
    Ok(num
        .parse::<f64>()
        .map_err(|_| anyhow::anyhow!("bad size '{s}' (e.g. 3k, 40000)"))?
        * mult)
}

/// Runs `bench`.
pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.what == "sim",
        "unknown benchmark '{}' (known: sim)",
        args.what
    );
    println!(
        "{:>8} {:>8} {:>10} {:>10} {:>10} {:>9}",
        "verts", "tris", "ms/step", "newton/st", "cg/newton", "contacts"
    );
    let mut ours = Vec::new();
    for s in &args.sizes {
        let verts = parse_size(s)?;
        // 1 m² of pattern holds ≈ 2950 vertices at 20 mm edges, scaling with 1/h².
        let edge_m = 0.020 * (2950.0 / verts).sqrt();
        let mut scene = Scene {
            garments: vec![flat_sheet(
                "sheet",
                1.0,
                1.0,
                Vector3::new(0.0, 0.32, 0.0),
                Fabric::preset("cotton").unwrap_or_default(),
            )],
            ..Scene::default()
        };
        scene
            .colliders
            .push(Collider::sphere("sphere", Vector3::zeros(), 0.3, 4));
        let mut sim = Simulation::new(&scene, edge_m, |p| p.collision.self_collision = false)?;
        sim.steps_per_frame = 1;
        for _ in 0..20 {
            sim.advance_frame(|_| {})?;
        }
        let (mut newton, mut cg, mut contacts) = (0usize, 0usize, 0usize);
        let t = Instant::now();
        for _ in 0..args.steps {
            let f = sim.advance_frame(|_| {})?;
            newton += f.steps.newton_iters;
            cg += f.steps.cg_iters;
            contacts = f.steps.contacts;
        }
        let ms = t.elapsed().as_secs_f64() * 1e3 / args.steps as f64;
        let n = sim.sim.model.num_vertices();
        println!(
            "{n:>8} {:>8} {ms:>10.2} {:>10.2} {:>10.1} {contacts:>9}",
            sim.sim.model.mesh.triangles.len(),
            newton as f64 / args.steps as f64,
            cg as f64 / newton.max(1) as f64
        );
        ours.push((n, ms));
    }
    if args.no_peer {
        return Ok(());
    }
    let root = clothsr::io::python::repo_root();
    let python = root.join("benches/.venv-newton/bin/python");
    let script = root.join("benches/newton_peer.py");
    if !python.exists() || !script.exists() {
        println!("Newton 1.8 peer: not installed (run `bash benches/setup-newton.sh`)");
        return Ok(());
    }
    println!("Newton 1.8 on the same scene (Warp CPU):");
    let out = Command::new(&python)
        .arg(&script)
        .arg("--res")
        .arg(args.sizes.join(","))
        .arg("--steps")
        .arg(args.steps.min(10).to_string())
        .current_dir(Path::new(&root))
        .output()?;
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
        let mine = ours
            .iter()
            .min_by(|a, b| ((a.0 as f64 - verts).abs()).total_cmp(&(b.0 as f64 - verts).abs()));
        match mine {
            Some((n, m)) => println!(
                "  {solver:<12} {verts:>8} verts {ms:>10.2} ms/step   clothsr {m:.2} ms at {n} verts: clothsr / {solver} = {:.2}",
                m / ms
            ),
            None => println!("  {solver:<12} {verts:>8} verts {ms:>10.2} ms/step"),
        }
    }
    Ok(())
}
