//! Garment meshes remeshed like sewing patterns: a mesh garment (an OBJ or USD mesh with
//! material coordinates, its own or from [`super::flatten`]) is meshed again at the
//! resolution the pipeline asks for (20 mm coarse, 2.5 mm fine), so that it gets the same two
//! levels in one material space as a GarmentCode pattern.
//!
//! Each chart (panel) of the mesh becomes the outline of a pattern panel:
//!
//! 1. **Seams.** Vertices sewn together (the mesh's seam pairs: one 3D point split along chart
//!    boundaries) form weld classes. A boundary edge of one chart whose two ends weld to the two
//!    ends of a boundary edge of another chart (or of another part of its own outline) is
//!    sewn to it.
//! 2. **Outline edges.** Each chart's boundary loop is cut where what it is sewn to changes
//!    (free, or which stretch of which chart), and at corners sharper than [`CORNER_DEG`]. A
//!    cut at a point cuts every loop through that point's weld class, so the two sides of a
//!    seam are cut alike. A loop keeps at least three edges.
//! 3. **Meshing.** Each outline edge (a polyline in material space) is sampled equally in arc
//!    length, both sides of a seam with the same count, and the outline is meshed as a pattern
//!    panel is ([`super::mesh_garment`]): constrained Delaunay refinement to the target edge.
//!    Where the resampled outline crosses itself (chords across a narrow slit, which
//!    flattening leaves where it cut a chart open), every old boundary edge is split equally
//!    instead, which keeps the old outline exactly.
//! 4. **Positions.** New vertices take the 3D positions of the old mesh at their material
//!    coordinates (barycentric in the old chart's triangles).
//!
//! A chart whose boundary is not one simple loop (a hole, or a boundary that touches itself)
//! cannot be an outline: [`remesh`] reports it and the caller keeps the mesh as it is.

use std::collections::HashMap;

use nalgebra::{Vector2, Vector3};

use super::from_uv::components_of_edges;
use super::pattern::mesh_outline;
use super::Embedding;
use super::{ClothMesh, MeshOptions, MAX_PANEL_VERTICES};
use crate::error::{Error, Result};

/// Turns of a chart's boundary sharper than this, degrees, stay corners of its outline.
pub const CORNER_DEG: f64 = 40.0;

/// One stretch of a chart's boundary loop between two cuts: one outline edge of the new panel.
#[derive(Debug, Clone)]
struct Run {
    /// Boundary loop it belongs to.
    lp: usize,
    /// Position in the loop of its first vertex.
    start: usize,
    /// Boundary edges it spans.
    edges: usize,
    /// The first edge's mate, as (panel, position in that loop), when the run is sewn.
    mate: Option<(usize, usize)>,
    /// Its polyline in material space.
    points: Vec<Vector2<f64>>,
}

impl Run {
    /// Length of each of its old boundary edges in material space.
    fn edge_lengths(&self) -> Vec<f64> {
        self.points
            .windows(2)
            .map(|w| (w[1] - w[0]).norm())
            .collect()
    }

    /// Its points, `counts` segments long: one count for the whole run, equally spaced in arc
    /// length, or one per old edge, each split equally.
    fn sample(&self, counts: &[usize]) -> Vec<Vector2<f64>> {
        if counts.len() == 1 {
            return sample_polyline(&self.points, counts[0]);
        }
        let mut out = vec![self.points[0]];
        for (w, &n) in self.points.windows(2).zip(counts) {
            out.extend((1..=n).map(|k| w[0] + (w[1] - w[0]) * (k as f64 / n as f64)));
        }
        out
    }
}

/// Remeshes `mesh` chart by chart at `opts.edge_m` (see the module documentation): material
/// coordinates, panels and panel names are kept, seams are sewn again between the new
/// outlines, and positions come from the old mesh. Errors name the chart that cannot be
/// remeshed and why.
pub fn remesh(mesh: &ClothMesh, opts: &MeshOptions) -> Result<ClothMesh> {
    remesh_sampled(mesh, opts, Sampling::ArcLength).or_else(|e| {
        if e.to_string().contains("crosses") {
            remesh_sampled(mesh, opts, Sampling::PerEdge)
        } else {
            Err(e)
        }
    })
}

/// How outline edges are sampled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Sampling {
    /// Equally in arc length along the whole outline edge: even boundary edges, but chords cut
    /// the polyline's corners, and where two stretches of outline run closer than that (the
    /// two sides of a narrow slit a flattening left) they can cross.
    ArcLength,
    /// Every old boundary edge split into equal parts: the outline keeps the old boundary
    /// exactly, so it crosses itself nowhere the old one did not.
    PerEdge,
}

fn remesh_sampled(mesh: &ClothMesh, opts: &MeshOptions, sampling: Sampling) -> Result<ClothMesh> {
    let h = opts.edge_m;
    if !(h.is_finite() && h > 0.0) {
        return Err(Error::Invalid(format!(
            "edge length must be positive, got {h} m"
        )));
    }
    mesh.validate()?;
    let n = mesh.num_vertices();
    let panels = mesh
        .panel_of_vertex
        .iter()
        .map(|&p| p as usize + 1)
        .max()
        .unwrap_or(0)
        .max(mesh.panel_names.len());
    let name = |p: usize| {
        mesh.panel_names
            .get(p)
            .cloned()
            .unwrap_or_else(|| format!("panel_{p}"))
    };
    // Weld classes: the vertices sewn together, directly or not.
    let class = components_of_edges(n, mesh.seam_pairs.iter().copied());
    let (loops, loop_panel) = boundary_loops(mesh, panels, &name)?;
    let m = &mesh.material;

    // Sewn boundary edges: those whose end classes match another boundary edge's.
    let mut by_key: HashMap<(u32, u32), Vec<(usize, usize)>> = HashMap::new();
    for (l, lp) in loops.iter().enumerate() {
        for i in 0..lp.len() {
            let (a, b) = (
                class[lp[i] as usize],
                class[lp[(i + 1) % lp.len()] as usize],
            );
            if a != b {
                by_key.entry((a.min(b), a.max(b))).or_default().push((l, i));
            }
        }
    }
    let mate: Vec<Vec<Option<(usize, usize)>>> = loops
        .iter()
        .enumerate()
        .map(|(l, lp)| {
            (0..lp.len())
                .map(|i| {
                    let (a, b) = (
                        class[lp[i] as usize],
                        class[lp[(i + 1) % lp.len()] as usize],
                    );
                    by_key
                        .get(&(a.min(b), a.max(b)))
                        .and_then(|es| es.iter().find(|&&e| e != (l, i)).copied())
                })
                .collect()
        })
        .collect();

    // Cuts, as weld classes: where the mate changes, and at corners.
    let mut cut = vec![false; n];
    for (l, lp) in loops.iter().enumerate() {
        let len = lp.len();
        for i in 0..len {
            let prev = (i + len - 1) % len;
            let continuous = match (mate[l][prev], mate[l][i]) {
                (None, None) => true,
                (Some((q1, j1)), Some((q2, j2))) => {
                    let lq = loops[q1].len();
                    q1 == q2 && (j2 == (j1 + 1) % lq || j1 == (j2 + 1) % lq)
                }
                _ => false,
            };
            let (a, v, b) = (
                m[lp[prev] as usize],
                m[lp[i] as usize],
                m[lp[(i + 1) % len] as usize],
            );
            let (d0, d1) = (v - a, b - v);
            let turn = d0.perp(&d1).atan2(d0.dot(&d1)).abs().to_degrees();
            if !continuous || turn > CORNER_DEG {
                cut[class[lp[i] as usize] as usize] = true;
            }
        }
    }
    // At least three edges per outline: more cuts, spread along the loop, where a loop has
    // fewer (they cut the loops sewn to it too, so repeat until every loop has three).
    loop {
        let mut changed = false;
        for lp in &loops {
            let cuts: Vec<usize> = (0..lp.len())
                .filter(|&i| cut[class[lp[i] as usize] as usize])
                .collect();
            if cuts.len() >= 3 {
                continue;
            }
            let arc = arc_lengths(lp, m);
            let total = arc[lp.len()];
            let s0 = cuts.first().map_or(0.0, |&i| arc[i]);
            let targets: Vec<f64> = if cuts.is_empty() {
                vec![0.0, total / 3.0, 2.0 * total / 3.0]
            } else {
                vec![s0 + total / 3.0, s0 + 2.0 * total / 3.0]
            };
            for target in targets.into_iter().take(3 - cuts.len()) {
                let target = target % total.max(f64::MIN_POSITIVE);
                let d = |i: usize| {
                    let d = (arc[i] - target).abs();
                    d.min(total - d)
                };
                let best = (0..lp.len())
                    .filter(|&i| !cut[class[lp[i] as usize] as usize])
                    .min_by(|&i, &j| d(i).total_cmp(&d(j)));
                if let Some(i) = best {
                    cut[class[lp[i] as usize] as usize] = true;
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }

    // Runs between cuts.
    let mut runs: Vec<Run> = Vec::new();
    let mut run_of: Vec<Vec<usize>> = loops.iter().map(|lp| vec![0; lp.len()]).collect();
    let mut loop_runs: Vec<std::ops::Range<usize>> = Vec::with_capacity(loops.len());
    for (l, lp) in loops.iter().enumerate() {
        let len = lp.len();
        let cuts: Vec<usize> = (0..len)
            .filter(|&i| cut[class[lp[i] as usize] as usize])
            .collect();
        let first = runs.len();
        for (k, &s) in cuts.iter().enumerate() {
            let e = cuts[(k + 1) % cuts.len()];
            let edges = (e + len - s) % len;
            let edges = if edges == 0 { len } else { edges };
            for j in 0..edges {
                run_of[l][(s + j) % len] = runs.len();
            }
            runs.push(Run {
                lp: l,
                start: s,
                edges,
                mate: mate[l][s],
                points: (0..=edges).map(|j| m[lp[(s + j) % len] as usize]).collect(),
            });
        }
        loop_runs.push(first..runs.len());
    }

    // Segments per run, and the seams between runs (run, mate run, reversed).
    // Segments per run: one count for the whole run (arc length), or one per old edge.
    let counts = |lengths: &[f64]| -> Vec<usize> {
        match sampling {
            Sampling::ArcLength => vec![(lengths.iter().sum::<f64>() / h).round() as usize],
            Sampling::PerEdge => lengths
                .iter()
                .map(|l| ((l / h).round() as usize).max(1))
                .collect(),
        }
    };
    let mut segments: Vec<Vec<usize>> = runs.iter().map(|r| counts(&r.edge_lengths())).collect();
    let mut seams: Vec<(usize, usize, bool)> = Vec::new();
    for (r, run) in runs.iter().enumerate() {
        let Some((q, j)) = run.mate else { continue };
        let other = run_of[q][j];
        let o = &runs[other];
        let lp = &loops[run.lp];
        let lq = &loops[q];
        let v0 = class[lp[run.start] as usize];
        // The mate's edge j runs from lq[j] to lq[j + 1]: the same way as this run's first edge,
        // or against it.
        let same = class[lq[j] as usize] == v0;
        let expected = if same {
            o.start
        } else {
            (o.start + o.edges - 1) % lq.len()
        };
        if other == r || o.edges != run.edges || j != expected {
            return Err(Error::Invalid(format!(
                "panel '{}': its seam with panel '{}' does not match stretch for stretch",
                name(loop_panel[run.lp]),
                name(loop_panel[q])
            )));
        }
        if r < other {
            // Both sides get the counts of the longer, edge for edge (the mate's edges run the
            // other way when it is sewn against this run).
            let mut mine = run.edge_lengths();
            let mut theirs = o.edge_lengths();
            if !same {
                theirs.reverse();
            }
            for (a, b) in mine.iter_mut().zip(&theirs) {
                *a = a.max(*b);
            }
            let c = counts(&mine);
            let mut c_other = c.clone();
            if !same {
                c_other.reverse();
            }
            segments[r] = c;
            segments[other] = c_other;
            seams.push((r, other, !same));
        }
    }

    // Mesh each outline.
    let mut out = ClothMesh {
        panel_names: (0..panels).map(name).collect(),
        ..Default::default()
    };
    let mut run_vertices: Vec<Vec<u32>> = vec![Vec::new(); runs.len()];
    for p in 0..panels {
        // The outer loop first (boundary_loops sorts them so), then the holes.
        let mine: Vec<usize> = (0..loops.len()).filter(|&l| loop_panel[l] == p).collect();
        let area: f64 = mine.iter().map(|&l| loop_area(&loops[l], m)).sum();
        let vertices = area / (0.433 * h * h);
        if !vertices.is_finite() || vertices > MAX_PANEL_VERTICES {
            return Err(Error::Invalid(format!(
                "panel '{}': {area:.1} m² would mesh into about {vertices:.1e} vertices at {:.1} mm \
                 (more than {MAX_PANEL_VERTICES:.0e}): check the mesh's units",
                name(p),
                h * 1e3
            )));
        }
        let mut boundary: Vec<Vector2<f64>> = Vec::new();
        let mut loop_ends: Vec<usize> = Vec::new();
        let mut local: Vec<(usize, Vec<u32>)> = Vec::new();
        for (k, &l) in mine.iter().enumerate() {
            let loop_start = boundary.len();
            let mut these = Vec::new();
            for r in loop_runs[l].clone() {
                let n: usize = segments[r].iter().sum();
                let start = boundary.len() as u32;
                if n > 0 {
                    boundary.extend_from_slice(&runs[r].sample(&segments[r])[..n]);
                }
                these.push((r, (0..=n as u32).map(|i| start + i).collect::<Vec<u32>>()));
            }
            if boundary.len() - loop_start < 3 {
                if k == 0 {
                    return Err(Error::Invalid(format!(
                        "panel '{}': too small for {:.1} mm edges",
                        name(p),
                        h * 1e3
                    )));
                }
                // A hole smaller than the mesh's edges is filled at this resolution.
                boundary.truncate(loop_start);
                continue;
            }
            // The loop's last run ends where its first began.
            let end = boundary.len() as u32;
            for (_, vs) in &mut these {
                vs.iter_mut()
                    .filter(|v| **v == end)
                    .for_each(|v| *v = loop_start as u32);
            }
            loop_ends.push(boundary.len());
            local.extend(these);
        }
        let (material, triangles) = mesh_outline(boundary, &loop_ends, area, opts)
            .map_err(|e| Error::Invalid(format!("panel '{}': {e}", name(p))))?;
        let offset = out.material.len() as u32;
        for (r, vs) in local {
            run_vertices[r] = vs.into_iter().map(|v| v + offset).collect();
        }
        out.panel_of_vertex
            .extend(std::iter::repeat_n(p as u32, material.len()));
        out.material.extend(material);
        out.triangles
            .extend(triangles.into_iter().map(|t| t.map(|v| v + offset)));
    }
    for &(a, b, reversed) in &seams {
        let (va, vb) = (&run_vertices[a], &run_vertices[b]);
        let k = va.len();
        if k != vb.len() {
            continue; // one side is a filled hole
        }
        for (i, &x) in va.iter().enumerate() {
            let y = vb[if reversed { k - 1 - i } else { i }];
            if x != y {
                out.seam_pairs.push([x.min(y), x.max(y)]);
            }
        }
    }
    out.seam_pairs.sort_unstable();
    out.seam_pairs.dedup();
    out.positions = vec![Vector3::zeros(); out.material.len()];
    out.positions = Embedding::new(&out, mesh)?.apply(&mesh.positions);
    out.reorder_for_locality();
    out.validate()?;
    Ok(out)
}

/// The boundary loops of every panel and the panel of each: per panel, its outer loop
/// (counter-clockwise in material space) first, then its holes (clockwise). Errors when a
/// boundary touches itself or a panel has no outer loop.
fn boundary_loops(
    mesh: &ClothMesh,
    panels: usize,
    name: &impl Fn(usize) -> String,
) -> Result<(Vec<Vec<u32>>, Vec<usize>)> {
    let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let p = mesh.panel_of_vertex[tri[0] as usize];
        if tri.iter().any(|&v| mesh.panel_of_vertex[v as usize] != p) {
            return Err(Error::Invalid(format!(
                "triangle {t} spans two panels: a panel must be a connected chart"
            )));
        }
        for k in 0..3 {
            *directed.entry((tri[k], tri[(k + 1) % 3])).or_default() += 1;
        }
    }
    let mut next: HashMap<u32, u32> = HashMap::new();
    for (&(a, b), &count) in &directed {
        if count > 1 {
            return Err(Error::Invalid(format!(
                "panel '{}': edge ({a}, {b}) belongs to {count} triangles of the same winding",
                name(mesh.panel_of_vertex[a as usize] as usize)
            )));
        }
        if !directed.contains_key(&(b, a)) && next.insert(a, b).is_some() {
            return Err(Error::Invalid(format!(
                "panel '{}': its boundary touches itself at vertex {a}",
                name(mesh.panel_of_vertex[a as usize] as usize)
            )));
        }
    }
    let mut starts: Vec<u32> = next.keys().copied().collect();
    starts.sort_unstable();
    let mut per_panel: Vec<Vec<Vec<u32>>> = vec![Vec::new(); panels];
    let mut seen = vec![false; mesh.num_vertices()];
    for s in starts {
        if seen[s as usize] {
            continue;
        }
        let p = mesh.panel_of_vertex[s as usize] as usize;
        let mut lp = vec![s];
        seen[s as usize] = true;
        let mut v = s;
        while let Some(&w) = next.get(&v) {
            if w == s {
                break;
            }
            if seen[w as usize] {
                return Err(Error::Invalid(format!(
                    "panel '{}': its boundary does not close",
                    name(p)
                )));
            }
            seen[w as usize] = true;
            lp.push(w);
            v = w;
        }
        per_panel[p].push(lp);
    }
    let (mut loops, mut panel_of) = (Vec::new(), Vec::new());
    for (p, mut lps) in per_panel.into_iter().enumerate() {
        // The outer loop encloses the most area.
        lps.sort_by(|a, b| loop_area(b, &mesh.material).total_cmp(&loop_area(a, &mesh.material)));
        match lps.first() {
            Some(outer) if loop_area(outer, &mesh.material) > 0.0 => {}
            _ => {
                return Err(Error::Invalid(format!(
                    "panel '{}': no outer boundary (a closed surface, or triangles wound \
                     clockwise)",
                    name(p)
                )))
            }
        }
        panel_of.extend(std::iter::repeat_n(p, lps.len()));
        loops.extend(lps);
    }
    Ok((loops, panel_of))
}

/// Signed area of a loop of vertices in material space.
fn loop_area(lp: &[u32], m: &[Vector2<f64>]) -> f64 {
    let k = lp.len();
    0.5 * (0..k)
        .map(|i| m[lp[i] as usize].perp(&m[lp[(i + 1) % k] as usize]))
        .sum::<f64>()
}

/// Arc length at each vertex of a closed loop (and the whole length at index `len`).
fn arc_lengths(lp: &[u32], m: &[Vector2<f64>]) -> Vec<f64> {
    let k = lp.len();
    let mut s = vec![0.0; k + 1];
    for i in 0..k {
        s[i + 1] = s[i] + (m[lp[(i + 1) % k] as usize] - m[lp[i] as usize]).norm();
    }
    s
}

/// `n + 1` points along a polyline, equally spaced in arc length, from its first to its last.
fn sample_polyline(points: &[Vector2<f64>], n: usize) -> Vec<Vector2<f64>> {
    let mut arc = vec![0.0];
    for w in points.windows(2) {
        arc.push(arc[arc.len() - 1] + (w[1] - w[0]).norm());
    }
    let total = arc[arc.len() - 1];
    let mut out = Vec::with_capacity(n + 1);
    let mut seg = 0;
    for k in 0..=n {
        let s = total * k as f64 / n.max(1) as f64;
        while seg + 2 < arc.len() && arc[seg + 1] < s {
            seg += 1;
        }
        let (a, b) = (arc[seg], arc[(seg + 1).min(arc.len() - 1)]);
        let t = if b > a {
            ((s - a) / (b - a)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let q = points[(seg + 1).min(points.len() - 1)];
        out.push(points[seg] + (q - points[seg]) * t);
    }
    if let (Some(first), Some(last)) = (out.first_mut(), points.first()) {
        *first = *last;
    }
    if let (Some(o), Some(p)) = (out.last_mut(), points.last()) {
        *o = *p;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::garment::Fabric;
    use crate::mesh::{cloth_from_corners, flatten, mesh_garment, FlattenOptions};
    use crate::scene::samples::{skirt, two_panel_tube};
    use std::f64::consts::PI;

    /// A cloth mesh of a triangle surface with no texture coordinates: flattened, as the
    /// readers make it.
    fn flattened(points: &[Vector3<f64>], tris: &[[u32; 3]]) -> ClothMesh {
        let f = flatten(points, tris, &FlattenOptions::default()).expect("flatten");
        let corners: Vec<u32> = tris.iter().flatten().copied().collect();
        cloth_from_corners(points, &corners, &f.corner_uv)
            .expect("cloth")
            .0
    }

    /// Points welded by position, and triangles of them, from triangles given by corners.
    fn welded(corners: &[[Vector3<f64>; 3]]) -> (Vec<Vector3<f64>>, Vec<[u32; 3]>) {
        let mut index: HashMap<[i64; 3], u32> = HashMap::new();
        let mut points = Vec::new();
        let tris = corners
            .iter()
            .map(|t| {
                t.map(|p| {
                    let key = p.map(|c| (c * 1e9).round() as i64).into();
                    *index.entry(key).or_insert_with(|| {
                        points.push(p);
                        (points.len() - 1) as u32
                    })
                })
            })
            .collect();
        (points, tris)
    }

    /// A tube of radius `r` and length `len` around y, `n` quads around and `m` along.
    fn tube(n: usize, m: usize, r: f64, len: f64) -> (Vec<Vector3<f64>>, Vec<[u32; 3]>) {
        let p = |i: usize, j: usize| {
            let a = 2.0 * PI * i as f64 / n as f64;
            Vector3::new(r * a.cos(), len * j as f64 / m as f64, r * a.sin())
        };
        let mut corners = Vec::new();
        for j in 0..m {
            for i in 0..n {
                corners.push([p(i, j), p(i, j + 1), p(i + 1, j + 1)]);
                corners.push([p(i, j), p(i + 1, j + 1), p(i + 1, j)]);
            }
        }
        welded(&corners)
    }

    /// A box of side `s` open at the top: five square faces, `n` × `n` quads each, meeting at
    /// right angles (creases: five charts).
    fn open_box(n: usize, s: f64) -> (Vec<Vector3<f64>>, Vec<[u32; 3]>) {
        let faces: [(Vector3<f64>, Vector3<f64>, Vector3<f64>); 5] = [
            (Vector3::zeros(), Vector3::x(), Vector3::z()),
            (Vector3::zeros(), Vector3::y(), Vector3::x()),
            (Vector3::z(), Vector3::x(), Vector3::y()),
            (Vector3::zeros(), Vector3::z(), Vector3::y()),
            (Vector3::x(), Vector3::y(), Vector3::z()),
        ];
        let mut corners = Vec::new();
        for (o, u, v) in faces {
            let p = |i: usize, j: usize| {
                (o + u * (i as f64 / n as f64) + v * (j as f64 / n as f64)) * s
            };
            for j in 0..n {
                for i in 0..n {
                    corners.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
                    corners.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
                }
            }
        }
        welded(&corners)
    }

    fn area(m: &ClothMesh) -> f64 {
        (0..m.triangles.len()).map(|t| m.material_area(t)).sum()
    }

    fn widest_seam_gap(m: &ClothMesh) -> f64 {
        m.seam_pairs
            .iter()
            .map(|p| (m.positions[p[0] as usize] - m.positions[p[1] as usize]).norm())
            .fold(0.0, f64::max)
    }

    #[test]
    fn a_tube_remeshes_to_the_target_edge_on_its_own_surface() {
        let (r, len) = (0.1, 0.5);
        let old = flattened(&tube(32, 20, r, len).0, &tube(32, 20, r, len).1);
        assert_eq!(old.panel_names.len(), 1, "the tube flattens into one chart");
        for h in [0.02, 0.01, 0.005] {
            let new = remesh(&old, &MeshOptions::with_edge(h)).expect("remesh");
            let stats = new.stats();
            assert!(
                (stats.mean_edge_m / h - 1.0).abs() < 0.2,
                "mean edge {} at {h}",
                stats.mean_edge_m
            );
            assert!((area(&new) / area(&old) - 1.0).abs() < 0.01);
            assert!(new
                .triangles
                .iter()
                .enumerate()
                .all(|(t, _)| new.material_area(t) > 0.0));
            // On the old surface: within its chords' sagitta of the cylinder.
            let sagitta = r * (1.0 - (PI / 32.0).cos());
            for p in &new.positions {
                let d = ((p.x * p.x + p.z * p.z).sqrt() - r).abs();
                assert!(d <= sagitta + 1e-9, "{d} off the cylinder");
                assert!(p.y > -1e-9 && p.y < len + 1e-9);
            }
            // The cut along the tube is sewn again, point for point. The flattening's cut runs
            // along the tube, partly zig-zagging across its quads' diagonals.
            let (straight, zigzag) = ((len / h).round() as usize + 1, (1.3 * len / h) as usize + 1);
            let pairs = new.seam_pairs.len();
            assert!(
                (straight..=zigzag).contains(&pairs),
                "{pairs} seam pairs at {h}"
            );
            assert!(
                widest_seam_gap(&new) < 0.05 * h,
                "{}",
                widest_seam_gap(&new)
            );
        }
    }

    /// The fallback for outlines that cross once resampled: every old boundary point stays on
    /// the new outline, and both sides of the cut are split alike.
    #[test]
    fn per_edge_sampling_keeps_the_old_outline() {
        let (points, tris) = tube(32, 20, 0.1, 0.5);
        let old = flattened(&points, &tris);
        let h = 0.005;
        let new =
            remesh_sampled(&old, &MeshOptions::with_edge(h), Sampling::PerEdge).expect("remesh");
        let on_new = |p: &Vector2<f64>| new.material.iter().any(|q| (q - p).norm() < 1e-12);
        let (loops, _) = boundary_loops(&old, 1, &|p| format!("{p}")).expect("loops");
        assert!(loops[0].iter().all(|&v| on_new(&old.material[v as usize])));
        assert!(
            (area(&new) / area(&old) - 1.0).abs() < 1e-9,
            "the same outline"
        );
        assert!(widest_seam_gap(&new) < 1e-9, "{}", widest_seam_gap(&new));
        assert!((new.stats().mean_edge_m / h - 1.0).abs() < 0.2);
    }

    #[test]
    fn an_open_box_is_sewn_again_along_its_eight_edges() {
        let s = 0.3;
        let (points, tris) = open_box(12, s);
        let old = flattened(&points, &tris);
        assert_eq!(old.panel_names.len(), 5, "one chart per face");
        let h = 0.02;
        let new = remesh(&old, &MeshOptions::with_edge(h)).expect("remesh");
        assert_eq!(new.panel_names, old.panel_names);
        assert!((area(&new) / (5.0 * s * s) - 1.0).abs() < 0.01);
        // Eight edges of 15 segments, 16 points each: one pair per point per edge.
        assert_eq!(new.seam_pairs.len(), 8 * 16);
        assert!(
            widest_seam_gap(&new) < 1e-3 * h,
            "{}",
            widest_seam_gap(&new)
        );
        // The corners of the faces stay corners: every point of the box's corners is a vertex.
        for c in [
            Vector3::zeros(),
            Vector3::x() * s,
            Vector3::new(s, 0.0, s),
            Vector3::z() * s,
        ] {
            let at = new
                .positions
                .iter()
                .filter(|p| (*p - c).norm() < 1e-9)
                .count();
            assert_eq!(at, 3, "corner {c:?} in three faces");
        }
    }

    #[test]
    fn a_sewn_pattern_remeshes_like_the_pattern() {
        for g in [
            skirt(Fabric::default()),
            two_panel_tube(0.5, 0.4, 0.1, Fabric::default()),
        ] {
            let fine = mesh_garment(&g, &MeshOptions::with_edge(0.01)).expect("mesh");
            let direct = mesh_garment(&g, &MeshOptions::with_edge(0.02)).expect("mesh");
            let new = remesh(&fine, &MeshOptions::with_edge(0.02)).expect("remesh");
            let ratio = new.num_vertices() as f64 / direct.num_vertices() as f64;
            assert!(
                (ratio - 1.0).abs() < 0.05,
                "{} vs {}",
                new.num_vertices(),
                direct.num_vertices()
            );
            assert!((area(&new) / area(&direct) - 1.0).abs() < 0.01);
            let pairs = new.seam_pairs.len() as f64 / direct.seam_pairs.len() as f64;
            assert!(
                (pairs - 1.0).abs() < 0.1,
                "{} vs {}",
                new.seam_pairs.len(),
                direct.seam_pairs.len()
            );
        }
    }

    /// A flat ring of radii `r0` and `r1` in the plane z = 0, with texture coordinates x, y.
    fn ring(r0: f64, r1: f64) -> ClothMesh {
        let n = 48;
        let p = |i: usize, r: f64| {
            let a = 2.0 * PI * i as f64 / n as f64;
            Vector3::new(r * a.cos(), r * a.sin(), 0.0)
        };
        let mut corners = Vec::new();
        for i in 0..n {
            corners.push([p(i, r0), p(i, r1), p(i + 1, r1)]);
            corners.push([p(i, r0), p(i + 1, r1), p(i + 1, r0)]);
        }
        let (points, tris) = welded(&corners);
        let uv: Vec<Vector2<f64>> = tris
            .iter()
            .flatten()
            .map(|&v| points[v as usize].xy())
            .collect();
        let corner_point: Vec<u32> = tris.iter().flatten().copied().collect();
        cloth_from_corners(&points, &corner_point, &uv)
            .expect("cloth")
            .0
    }

    #[test]
    fn a_hole_stays_a_hole_unless_narrower_than_the_edges() {
        let old = ring(0.1, 0.2);
        let new = remesh(&old, &MeshOptions::with_edge(0.01)).expect("remesh");
        assert!(
            (area(&new) / area(&old) - 1.0).abs() < 0.01,
            "{} vs {}",
            area(&new),
            area(&old)
        );
        let inner = new
            .material
            .iter()
            .map(|m| m.norm())
            .fold(f64::INFINITY, f64::min);
        assert!((inner - 0.1).abs() < 1e-3, "innermost vertex at {inner}");
        // A hole of 8 mm at 20 mm edges is filled.
        let small = ring(0.004, 0.2);
        let filled = remesh(&small, &MeshOptions::with_edge(0.02)).expect("remesh");
        let disc = PI * 0.2f64.powi(2);
        assert!(
            (area(&filled) / disc - 1.0).abs() < 0.02,
            "{}",
            area(&filled)
        );
    }

    #[test]
    fn a_boundary_that_touches_itself_is_reported() {
        // Two triangles meeting at one vertex: one panel whose boundary passes vertex 0 twice.
        let points = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(0.1, 0.0, 0.0),
            Vector3::new(0.1, 0.1, 0.0),
            Vector3::new(-0.1, 0.0, 0.0),
            Vector3::new(-0.1, -0.1, 0.0),
        ];
        let corner_point = [0, 1, 2, 0, 3, 4];
        let uv: Vec<Vector2<f64>> = corner_point
            .iter()
            .map(|&v| points[v as usize].xy())
            .collect();
        let (bowtie, _) = cloth_from_corners(&points, &corner_point, &uv).expect("cloth");
        assert_eq!(bowtie.panel_names.len(), 1);
        let e = remesh(&bowtie, &MeshOptions::with_edge(0.02)).expect_err("a pinch");
        assert!(e.to_string().contains("touches itself"), "{e}");
    }
}
