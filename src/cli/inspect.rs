//! `clothsr inspect FILE`: panels, seams, areas, vertex counts at 20 mm and 2.5 mm (patterns
//! meshed, garment meshes flattened where they have no texture coordinates and remeshed),
//! meshes and collider frame ranges.

use std::path::PathBuf;

use clothsr::garment::{garmentcode, Garment};
use clothsr::io::scene_files::{obj_cloth, FileKind, SceneFiles};
use clothsr::io::{obj, usd};
use clothsr::mesh::{mesh_garment, remesh, ClothMesh, MeshOptions, COARSE_EDGE_M, FINE_EDGE_M};
use clothsr::scene::Scene;

/// Arguments of `inspect`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A GarmentCode JSON, OBJ or USD file.
    file: PathBuf,
    /// Skip meshing (vertex counts at 20 mm and 2.5 mm).
    #[arg(long)]
    no_mesh: bool,
}

fn print_garment(g: &Garment, mesh: bool) -> anyhow::Result<()> {
    println!(
        "garment '{}': {} panels, {} seams, area {:.4} m², fabric {}",
        g.name,
        g.panels.len(),
        g.seams.len(),
        g.area(),
        g.fabric.name
    );
    for p in &g.panels {
        let perimeter: f64 = (0..p.edges.len()).map(|e| p.edge_length(e)).sum();
        let curved = p
            .edges
            .iter()
            .filter(|e| e.curve != clothsr::garment::Curve::Straight)
            .count();
        println!(
            "  panel {:<20} {:>2} edges ({curved} curved)  area {:.4} m²  perimeter {:.3} m",
            p.name,
            p.edges.len(),
            p.signed_area().abs(),
            perimeter
        );
    }
    for s in &g.seams {
        println!(
            "  seam  {}[{}] — {}[{}]{}",
            g.panels[s.a.panel].name,
            s.a.edge,
            g.panels[s.b.panel].name,
            s.b.edge,
            if s.reversed { " (reversed)" } else { "" }
        );
    }
    if mesh {
        for h in [COARSE_EDGE_M, FINE_EDGE_M] {
            let t = std::time::Instant::now();
            let m = mesh_garment(g, &MeshOptions::with_edge(h))?;
            let st = m.stats();
            println!(
                "  at {:>4} mm: {:>7} vertices, {:>7} triangles, {} seam pairs (meshed in {:.2} s)",
                h * 1e3,
                st.vertices,
                st.triangles,
                m.seam_pairs.len(),
                t.elapsed().as_secs_f64()
            );
        }
    }
    Ok(())
}

/// A mesh garment as cloth (`heading`: what it is), and, with `remeshed`, remeshed chart by
/// chart at 20 mm and 2.5 mm as `run` does.
fn print_cloth(heading: &str, mesh: &ClothMesh, remeshed: bool) {
    let st = mesh.stats();
    println!(
        "{heading}: {} panels, {} seam pairs, material area {:.4} m², mean edge {:.1} mm",
        mesh.panel_names.len(),
        mesh.seam_pairs.len(),
        st.area_m2,
        st.mean_edge_m * 1e3
    );
    if !remeshed {
        return;
    }
    for h in [COARSE_EDGE_M, FINE_EDGE_M] {
        let t = std::time::Instant::now();
        match remesh(mesh, &MeshOptions::with_edge(h)) {
            Ok(m) => println!(
                "  at {:>4} mm: {:>7} vertices, {:>7} triangles, {} seam pairs (remeshed in {:.2} s)",
                h * 1e3,
                m.num_vertices(),
                m.triangles.len(),
                m.seam_pairs.len(),
                t.elapsed().as_secs_f64()
            ),
            Err(e) => println!(
                "  at {:>4} mm: not remeshed, simulated at its own resolution: {e}",
                h * 1e3
            ),
        }
    }
}

/// Runs `inspect`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let path = &args.file;
    println!("{}", path.display());
    match FileKind::of(path)? {
        FileKind::GarmentCode => {
            let g = garmentcode::read(path, Default::default())?;
            print_garment(&g, !args.no_mesh)?;
        }
        FileKind::Obj => {
            let m = obj::read_obj(path)?;
            println!(
                "OBJ mesh: {} points, {} triangles, texture coordinates: {}",
                m.positions.len(),
                m.triangles.len(),
                if m.uv.is_some() { "yes" } else { "no" }
            );
            let (c, flattening) = obj_cloth(path, Default::default())?;
            if let Some(f) = flattening {
                let d = &f.distortion;
                println!(
                    "  flattened into {} charts: area distortion mean {:.2} % / max {:.2} %, \
                     angle distortion mean {:.2}° / max {:.2}°",
                    f.charts,
                    d.area_mean * 100.0,
                    d.area_max * 100.0,
                    d.angle_mean_deg,
                    d.angle_max_deg
                );
            }
            print_cloth("  as cloth", &c.mesh, !args.no_mesh);
        }
        FileKind::Usd => {
            let s = usd::inspect_usd(path)?;
            println!(
                "USD stage: upAxis {}, metersPerUnit {}, {} time codes/s, time codes {}..{}",
                s.up_axis, s.meters_per_unit, s.fps, s.start, s.end
            );
            if let Some(solver) = s.solver {
                println!(
                    "  solver: dt {:.6} s, gravity {:?} m/s²",
                    solver.dt_s,
                    solver.gravity_m_s2.as_slice()
                );
            }
            for m in &s.meshes {
                let frames = match (m.time_codes.first(), m.time_codes.last()) {
                    (Some(a), Some(b)) if m.time_codes.len() > 1 => {
                        format!("{} frames, time codes {a}..{b}", m.time_codes.len())
                    }
                    _ => "static".to_string(),
                };
                println!(
                    "  mesh {} [{:?}{}]: {} points, {} faces, {frames}",
                    m.path,
                    m.role,
                    if m.skinned { ", UsdSkel skinned" } else { "" },
                    m.num_points,
                    m.num_faces
                );
            }
            for g in &s.garments {
                print_garment(g, !args.no_mesh)?;
            }
            if !args.no_mesh && s.meshes.iter().any(|m| m.role == usd::MeshRole::Cloth) {
                for c in Scene::load(path, &Default::default())?.cloths {
                    print_cloth(&format!("garment mesh '{}'", c.name), &c.mesh, true);
                }
            }
        }
    }
    Ok(())
}
