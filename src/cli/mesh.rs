//! `clothsr mesh IN --edge-mm 20 -o OUT.usd[a|c]`: a garment meshed with material coordinates.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::bail;
use clothsr::io::usd::{write_usd, MeshOut, StageOut};
use clothsr::io::SceneFiles;
use clothsr::mesh::{mesh_garment, MeshOptions};
use clothsr::scene::Scene;

/// Arguments of `mesh`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A GarmentCode JSON or a USD scene with pattern garments.
    input: PathBuf,
    /// Target edge length in millimetres (20 coarse, 2.5 fine).
    #[arg(value_parser = crate::cli::values::positive(crate::cli::values::MAX_MM), long, default_value_t = crate::cli::COARSE_MM)]
    edge_mm: f64,
    /// Output USD file (.usdc, .usd or .usda).
    #[arg(value_parser = crate::cli::values::output_file, short, long)]
    output: PathBuf,
    /// Fabric preset for GarmentCode input.
    #[arg(long, default_value = "cotton")]
    fabric: clothsr::garment::FabricPreset,
    /// Write text USD even for a .usd file.
    #[arg(long)]
    ascii: bool,
}

/// Runs `mesh`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let output = super::check_output(&args.input, &args.output)?;
    let scene = Scene::load(&args.input, &args.fabric.fabric())?;
    if scene.garments.is_empty() {
        bail!("{}: no sewing pattern to mesh", args.input.display());
    }
    let edge_m = args.edge_mm * 1e-3;
    let mut meshes = Vec::new();
    for g in &scene.garments {
        let t = Instant::now();
        let mesh =
            mesh_garment(g, &MeshOptions::with_edge(edge_m)).map_err(|e| e.in_file(&args.input))?;
        let st = mesh.stats();
        tracing::info!(
            "{}: {} vertices, {} triangles, mean edge {:.2} mm, min angle {:.1}°, area {:.4} m² (pattern {:.4} m²), {} seam pairs, {:.2} s",
            g.name,
            st.vertices,
            st.triangles,
            st.mean_edge_m * 1e3,
            st.min_angle_deg,
            st.area_m2,
            g.area(),
            mesh.seam_pairs.len(),
            t.elapsed().as_secs_f64()
        );
        let mut out = MeshOut::cloth(&g.name, &mesh, &g.fabric, edge_m);
        out.time_codes = Some(vec![0.0]);
        out.doc = Some(format!(
            "{} meshed at {} mm by clothsr",
            g.name, args.edge_mm
        ));
        meshes.push(out);
    }
    let stage = StageOut {
        over: None,
        fps: scene.fps,
        start: 0.0,
        end: 0.0,
        doc: Some(format!("clothsr mesh of {}", args.input.display())),
        ascii: args.ascii,
        garments: Vec::new(),
        meshes,
        solver: None,
    };
    for w in write_usd(&output, &stage)? {
        tracing::warn!("{}: {w}", output.display());
    }
    tracing::info!("wrote {}", output.display());
    Ok(())
}
