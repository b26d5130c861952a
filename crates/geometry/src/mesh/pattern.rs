//! Meshing of sewing-pattern panels with spade's constrained Delaunay triangulation and Delaunay
//! refinement.
//!
//! Every panel edge is split into segments of (about) the target length, equally spaced in arc
//! length; the two edges of a seam get the **same** number of segments so that sewing pairs are
//! one-to-one. The outline becomes the constraint edges of a CDT, which spade refines (keeping the
//! constraint edges, so seam counts survive) until no triangle is larger than an area derived from
//! the target edge length or has an angle below the limit.

use std::collections::HashMap;

use nalgebra::Vector2;
use spade::{
    AngleLimit, ConstrainedDelaunayTriangulation, Point2, RefinementParameters, Triangulation,
};

use super::ClothMesh;
use crate::error::{Error, Result};
use crate::garment::{segments_cross, EdgeRef, Garment, Panel};

/// The paper's coarse resolution: 20 mm edges.
pub const COARSE_EDGE_M: f64 = 0.020;
/// The paper's fine resolution: 2.5 mm edges (8× the coarse one).
pub const FINE_EDGE_M: f64 = 0.0025;

/// How to mesh a garment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshOptions {
    /// Target mean edge length, metres.
    pub edge_m: f64,
    /// Smallest triangle angle the refinement aims for, degrees.
    pub min_angle_deg: f64,
}

impl Default for MeshOptions {
    fn default() -> Self {
        MeshOptions {
            edge_m: COARSE_EDGE_M,
            min_angle_deg: 28.0,
        }
    }
}

impl MeshOptions {
    /// Options for a target edge length in metres.
    pub fn with_edge(edge_m: f64) -> Self {
        MeshOptions {
            edge_m,
            ..Default::default()
        }
    }
}

/// Largest triangle area the refinement accepts, as a multiple of the equilateral triangle of the
/// target edge (√3/4·h²). Refinement leaves triangles smaller than the bound, so the bound sits
/// above 1; calibrated so that the mean edge length matches the target on real patterns.
const AREA_FACTOR: f64 = 1.6;

/// The most vertices one panel may mesh into (a 2.5 mm mesh of about 15 m²).
pub const MAX_PANEL_VERTICES: f64 = 5e6;

/// Meshes every panel of `garment` and records seam vertex pairs. World positions come from each
/// panel's placement.
pub fn mesh_garment(garment: &Garment, opts: &MeshOptions) -> Result<ClothMesh> {
    let h = opts.edge_m;
    if !(h.is_finite() && h > 0.0) {
        return Err(Error::Invalid(format!(
            "edge length must be positive, got {h} m"
        )));
    }
    // A garment of wrong units (a pattern in centimetres read as metres) would mesh into
    // billions of vertices: refused before any work.
    for p in &garment.panels {
        let area = p.signed_area().abs();
        let vertices = area / (0.433 * h * h);
        if !vertices.is_finite() || vertices > MAX_PANEL_VERTICES {
            return Err(Error::Invalid(format!(
                "panel '{}': {area:.1} m² would mesh into about {vertices:.1e} vertices at {:.1} mm \
                 (more than {MAX_PANEL_VERTICES:.0e}): check the pattern's units",
                p.name,
                h * 1e3
            )));
        }
    }
    // Segments per edge; seams share the larger count of their two sides.
    let mut segments: HashMap<EdgeRef, usize> = HashMap::new();
    for seam in &garment.seams {
        let len = |r: EdgeRef| garment.panels[r.panel].edge_length(r.edge);
        let n = (len(seam.a).max(len(seam.b)) / h).round() as usize;
        segments.insert(seam.a, n);
        segments.insert(seam.b, n);
    }

    let mut mesh = ClothMesh::default();
    // For each panel and edge: the global indices of its boundary vertices, start to end.
    let mut edge_vertices: HashMap<EdgeRef, Vec<u32>> = HashMap::new();
    for (pi, panel) in garment.panels.iter().enumerate() {
        let counts: Vec<usize> = (0..panel.edges.len())
            .map(|e| {
                segments
                    .get(&EdgeRef { panel: pi, edge: e })
                    .copied()
                    .unwrap_or_else(|| (panel.edge_length(e) / h).round() as usize)
            })
            .collect();
        let offset = mesh.material.len() as u32;
        let (material, triangles, boundary_runs) = mesh_panel(panel, &counts, opts)
            .map_err(|m| Error::Invalid(format!("panel '{}': {m}", panel.name)))?;
        for (e, run) in boundary_runs.into_iter().enumerate() {
            edge_vertices.insert(
                EdgeRef { panel: pi, edge: e },
                run.into_iter().map(|v| v + offset).collect(),
            );
        }
        mesh.positions
            .extend(material.iter().map(|uv| panel.placement.apply(*uv)));
        mesh.panel_of_vertex
            .extend(std::iter::repeat_n(pi as u32, material.len()));
        mesh.material.extend(material);
        mesh.triangles
            .extend(triangles.into_iter().map(|t| t.map(|v| v + offset)));
        mesh.panel_names.push(panel.name.clone());
    }
    for seam in &garment.seams {
        let a = &edge_vertices[&seam.a];
        let b = &edge_vertices[&seam.b];
        debug_assert_eq!(a.len(), b.len());
        let n = a.len();
        for (k, &va) in a.iter().enumerate() {
            let vb = b[if seam.reversed { n - 1 - k } else { k }];
            // A dart sews two adjacent edges of one panel: their shared corner pairs with itself.
            if va != vb {
                mesh.seam_pairs.push([va.min(vb), va.max(vb)]);
            }
        }
    }
    mesh.seam_pairs.sort_unstable();
    mesh.seam_pairs.dedup();
    mesh.reorder_for_locality();
    mesh.validate()?;
    Ok(mesh)
}

/// Material coordinates and triangles of a meshed outline.
pub(super) type OutlineMesh = (Vec<Vector2<f64>>, Vec<[u32; 3]>);

/// Material coordinates, triangles and, per outline edge, the local indices of its vertices.
type PanelMesh = (Vec<Vector2<f64>>, Vec<[u32; 3]>, Vec<Vec<u32>>);

/// Meshes one panel whose edge `e` is split into `counts[e]` segments (0: merged away).
fn mesh_panel(panel: &Panel, counts: &[usize], opts: &MeshOptions) -> Result<PanelMesh> {
    // Boundary points in loop order; the outline is made counter-clockwise for spade but the
    // per-edge runs keep the pattern's own direction.
    let mut boundary: Vec<Vector2<f64>> = Vec::new();
    let mut runs: Vec<Vec<u32>> = Vec::with_capacity(panel.edges.len());
    // An edge shorter than half the target length gets no segment: its two corners merge into
    // one vertex (the start of the next edge), instead of a sliver next to full-length segments.
    for (e, &n) in counts.iter().enumerate() {
        let start = boundary.len() as u32;
        if n > 0 {
            let pts = panel.sample_edge(e, n);
            boundary.extend_from_slice(&pts[..n]);
        }
        runs.push((0..=n as u32).map(|k| start + k).collect());
    }
    let nb = boundary.len() as u32;
    if nb < 3 {
        return Err(Error::Invalid(format!(
            "too small for {:.1} mm edges",
            opts.edge_m * 1e3
        )));
    }
    for run in &mut runs {
        if let Some(last) = run.last_mut() {
            *last %= nb;
        }
    }
    let ends = [boundary.len()];
    let (material, triangles) = mesh_outline(boundary, &ends, panel.signed_area().abs(), opts)?;
    Ok((material, triangles, runs))
}

/// Meshes the inside of the closed outline `boundary` (loops one after the other, loop `k`
/// ending before `loop_ends[k]`, each in loop order, either orientation: an outline and its
/// holes; `area` m² inside): a constrained Delaunay triangulation of the loops, refined to the
/// target edge length and angle; faces enclosed by an even number of loops (outside, or in a
/// hole) are left out. The outline points keep their indices; the points the refinement adds
/// come after them. Triangles are counter-clockwise.
pub(super) fn mesh_outline(
    boundary: Vec<Vector2<f64>>,
    loop_ends: &[usize],
    area: f64,
    opts: &MeshOptions,
) -> Result<OutlineMesh> {
    let mut cdt = ConstrainedDelaunayTriangulation::<Point2<f64>>::new();
    let mut handles = Vec::with_capacity(boundary.len());
    for (i, p) in boundary.iter().enumerate() {
        let hnd = cdt.insert(Point2::new(p.x, p.y)).map_err(|e| {
            Error::Invalid(format!(
                "outline point {i} ({}, {}) cannot be inserted: {e:?}",
                p.x, p.y
            ))
        })?;
        if hnd.index() != i {
            return Err(Error::Invalid(format!(
                "outline points {} and {i} coincide at ({:.4}, {:.4}) m: outline too thin for {:.1} mm edges",
                hnd.index(),
                p.x,
                p.y,
                opts.edge_m * 1e3
            )));
        }
        handles.push(hnd);
    }
    let mut loop_start = 0;
    for i in 0..handles.len() {
        // The last point of a loop closes it back to the loop's first.
        let end = loop_ends
            .iter()
            .copied()
            .find(|&e| e > i)
            .unwrap_or(handles.len());
        let j = if i + 1 == end { loop_start } else { i + 1 };
        if i + 1 == end {
            loop_start = end;
        }
        let (a, b) = (handles[i], handles[j]);
        if !cdt.can_add_constraint(a, b) {
            let (p, q) = (boundary[i], boundary[j]);
            let other = (0..boundary.len())
                .map(|k| (k, boundary[k], boundary[(k + 1) % boundary.len()]))
                .find(|&(k, c, d)| k != i && k != j && segments_cross(p, q, c, d))
                .map_or(String::new(), |(k, c, d)| {
                    format!(
                        " (segment {k}, ({:.4}, {:.4})–({:.4}, {:.4}) m)",
                        c.x, c.y, d.x, d.y
                    )
                });
            return Err(Error::Invalid(format!(
                "outline segment {i}, ({:.4}, {:.4})–({:.4}, {:.4}) m, crosses another one{other} \
                 at {:.1} mm edges: the panel is too narrow for this resolution",
                p.x,
                p.y,
                q.x,
                q.y,
                opts.edge_m * 1e3
            )));
        }
        cdt.add_constraint(a, b);
    }
    let target_area = AREA_FACTOR * 3f64.sqrt() / 4.0 * opts.edge_m * opts.edge_m;
    let expected = (area / target_area * 2.0) as usize + 16 * handles.len() + 64;
    let result = cdt.refine(
        RefinementParameters::<f64>::new()
            .exclude_outer_faces(true)
            .keep_constraint_edges()
            .with_max_allowed_area(target_area)
            .with_angle_limit(AngleLimit::from_deg(opts.min_angle_deg))
            .with_max_additional_vertices(expected),
    );
    let excluded: std::collections::HashSet<_> = result.excluded_faces.iter().copied().collect();

    // Keep boundary points at their indices, then every vertex used by a kept face.
    let mut index_of: Vec<Option<u32>> = vec![None; cdt.num_vertices()];
    let mut material: Vec<Vector2<f64>> = boundary.clone();
    for (i, slot) in index_of.iter_mut().enumerate().take(boundary.len()) {
        *slot = Some(i as u32);
    }
    let mut triangles = Vec::new();
    for face in cdt.inner_faces() {
        if excluded.contains(&face.fix()) {
            continue;
        }
        let vs = face.vertices();
        let mut tri = [0u32; 3];
        for (k, v) in vs.iter().enumerate() {
            let fixed = v.fix().index();
            tri[k] = *index_of[fixed].get_or_insert_with(|| {
                let p = v.position();
                material.push(Vector2::new(p.x, p.y));
                (material.len() - 1) as u32
            });
        }
        triangles.push(tri);
    }
    if triangles.is_empty() {
        return Err(Error::Invalid("meshing produced no triangles".into()));
    }
    Ok((material, triangles))
}
