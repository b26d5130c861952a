//! A 50 cm silk sheet dropped 2 cm onto the bunny fixture (`tests/data/colliders/bunny.obj`,
//! scaled to a 25 cm rabbit), timed per simulated second, its last positions written out:
//!
//! ```text
//! cargo run --release -p clothsr-sim --example drape -- EDGE_MM SECONDS fast|converged OUT.bin [CG_TOL|-] [self|noself] [SHIFT_MM]
//! cargo run --release -p clothsr-sim --example drape -- compare A.bin B.bin
//! ```
//!
//! `compare` prints the mean and largest distance between two runs' positions, mm.

use std::io::Write;
use std::time::Instant;

use clothsr_sim::driver::Simulation;

use nalgebra::Vector3;

type Error = Box<dyn std::error::Error>;

/// The scene, the sheet shifted by `shift_m` along x (another start of the same drape).
fn bunny_scene(shift_m: f64) -> Result<clothsr_geometry::scene::Scene, Error> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../tests/data/colliders/bunny.obj"
    );
    let (models, _) = tobj::load_obj(path, &tobj::GPU_LOAD_OPTIONS)?;
    let mesh = &models.first().ok_or("no mesh in the bunny")?.mesh;
    let points: Vec<Vector3<f64>> = mesh
        .positions
        .chunks_exact(3)
        .map(|p| Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64) * 0.025)
        .collect();
    let triangles: Vec<[u32; 3]> = mesh
        .indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    let top = points.iter().map(|p| p.y).fold(f64::MIN, f64::max);
    let centre = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let fabric = clothsr_geometry::garment::Fabric::preset("silk").ok_or("no silk preset")?;
    let sheet = clothsr_geometry::scene::samples::flat_sheet(
        "sheet",
        0.5,
        0.5,
        Vector3::new(centre.x + shift_m, top + 0.02, centre.z),
        fabric,
    );
    let mut scene = clothsr_geometry::scene::Scene {
        garments: vec![sheet],
        ..Default::default()
    };
    scene
        .colliders
        .push(clothsr_geometry::scene::Collider::fixed(
            "bunny", points, triangles,
        ));
    Ok(scene)
}

fn read(path: &str) -> Result<Vec<f64>, Error> {
    Ok(std::fs::read(path)?
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
        .collect())
}

fn main() -> Result<(), Error> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().is_some_and(|a| a == "compare") {
        let (a, b) = (read(&args[1])?, read(&args[2])?);
        let d: Vec<f64> = a
            .chunks_exact(3)
            .zip(b.chunks_exact(3))
            .map(|(p, q)| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>().sqrt())
            .collect();
        let mean = d.iter().sum::<f64>() / d.len().max(1) as f64;
        let max = d.iter().copied().fold(0.0, f64::max);
        println!("mean {:.3} mm, max {:.3} mm", mean * 1e3, max * 1e3);
        return Ok(());
    }
    let edge_mm: f64 = args.first().map_or(Ok(2.5), |s| s.parse())?;
    let seconds: f64 = args.get(1).map_or(Ok(1.0), |s| s.parse())?;
    let converged = args.get(2).is_some_and(|m| m == "converged");
    let out = args.get(3).cloned().unwrap_or_else(|| "drape.bin".into());
    let cg_tol: Option<f64> = match args.get(4).map(String::as_str) {
        None | Some("-") => None,
        Some(s) => Some(s.parse()?),
    };
    let self_collision = args.get(5).is_none_or(|s| s != "noself");
    let shift_m: f64 = args.get(6).map_or(Ok(0.0), |s| s.parse::<f64>())? * 1e-3;
    let mut sim = Simulation::new(&bunny_scene(shift_m)?, edge_mm * 1e-3, |p| {
        p.newton_exact = converged;
        p.collision.self_collision = self_collision;
        if let Some(t) = cg_tol {
            p.cg_rel_tol = t;
        }
    })?;
    let frames = (seconds * sim.fps).round() as usize;
    let (mut newton, mut steps) = (0usize, 0usize);
    let t = Instant::now();
    for _ in 0..frames {
        let f = sim.advance_frame(|_| {})?;
        newton += f.steps.newton_iters;
        steps += f.step_count;
    }
    let s = t.elapsed().as_secs_f64();
    println!(
        "{} vertices, {frames} frames, {steps} steps: {:.1} s per simulated second, {:.2} Newton iterations a step, {:.1} ms a step",
        sim.sim.model.num_vertices(),
        s / seconds,
        newton as f64 / steps.max(1) as f64,
        s * 1e3 / steps.max(1) as f64
    );
    let mut f = std::io::BufWriter::new(std::fs::File::create(&out)?);
    for p in &sim.state.x {
        for c in p.iter() {
            f.write_all(&c.to_le_bytes())?;
        }
    }
    Ok(())
}
