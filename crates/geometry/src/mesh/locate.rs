//! Material coordinates located in a mesh: the triangle of a panel that holds a point of the
//! panel's plane, and every vertex of one mesh of a garment embedded in a triangle of another
//! (the remesher carries positions this way; [`crate::transfer`] moves states between the
//! coarse and fine meshes with it).

use nalgebra::{Vector2, Vector3};

use super::ClothMesh;
use crate::error::{Error, Result};

/// Finds, for 2D points of one panel, the containing (or nearest) triangle of a mesh.
#[derive(Debug, Clone)]
pub struct TriLocator {
    origin: Vector2<f64>,
    cell_m: f64,
    nx: usize,
    ny: usize,
    /// Indices into `tris` per cell, row-major.
    cells: Vec<Vec<u32>>,
    /// The panel's triangles (indices into the mesh) and their material corners.
    tris: Vec<u32>,
    corners: Vec<[Vector2<f64>; 3]>,
}

/// Barycentric coordinates of `p` in triangle `t` (may be negative outside).
pub fn barycentric(p: &Vector2<f64>, t: &[Vector2<f64>; 3]) -> [f64; 3] {
    let (e1, e2, d) = (t[1] - t[0], t[2] - t[0], p - t[0]);
    let det = e1.perp(&e2);
    if det.abs() < 1e-300 {
        return [1.0, 0.0, 0.0];
    }
    let b1 = d.perp(&e2) / det;
    let b2 = e1.perp(&d) / det;
    [1.0 - b1 - b2, b1, b2]
}

/// Closest point of triangle `t` to `p`, as barycentric coordinates (all ≥ 0).
fn closest_barycentric(p: &Vector2<f64>, t: &[Vector2<f64>; 3]) -> [f64; 3] {
    let b = barycentric(p, t);
    if b.iter().all(|&w| w >= 0.0) {
        return b;
    }
    // Outside: the closest point lies on one of the edges.
    let mut best = (f64::INFINITY, [1.0, 0.0, 0.0]);
    for k in 0..3 {
        let (a, c) = (t[k], t[(k + 1) % 3]);
        let e = c - a;
        let s = ((p - a).dot(&e) / e.norm_squared().max(1e-300)).clamp(0.0, 1.0);
        let d = (a + e * s - p).norm_squared();
        if d < best.0 {
            let mut w = [0.0; 3];
            w[k] = 1.0 - s;
            w[(k + 1) % 3] = s;
            best = (d, w);
        }
    }
    best.1
}

impl TriLocator {
    /// Buckets the triangles of `mesh` whose vertices belong to `panel`.
    pub fn new(mesh: &ClothMesh, panel: u32) -> TriLocator {
        let tris: Vec<u32> = (0..mesh.triangles.len() as u32)
            .filter(|&t| mesh.panel_of_vertex[mesh.triangles[t as usize][0] as usize] == panel)
            .collect();
        let corners: Vec<[Vector2<f64>; 3]> = tris
            .iter()
            .map(|&t| mesh.triangles[t as usize].map(|v| mesh.material[v as usize]))
            .collect();
        let (mut lo, mut hi) = (
            Vector2::repeat(f64::INFINITY),
            Vector2::repeat(f64::NEG_INFINITY),
        );
        let mut edge_sum = 0.0;
        for c in &corners {
            for p in c {
                lo = lo.inf(p);
                hi = hi.sup(p);
            }
            edge_sum += (c[1] - c[0]).norm();
        }
        if corners.is_empty() {
            lo = Vector2::zeros();
            hi = Vector2::zeros();
        }
        // Cells about two edges wide: a handful of triangles each.
        let cell_m = (2.0 * edge_sum / corners.len().max(1) as f64).max(1e-6);
        let nx = (((hi.x - lo.x) / cell_m).floor() as usize + 1).min(4096);
        let ny = (((hi.y - lo.y) / cell_m).floor() as usize + 1).min(4096);
        let mut cells = vec![Vec::new(); nx * ny];
        let cell_of =
            |p: f64, o: f64, n: usize| (((p - o) / cell_m).floor().max(0.0) as usize).min(n - 1);
        for (k, c) in corners.iter().enumerate() {
            let (a, b) = (c[0].inf(&c[1]).inf(&c[2]), c[0].sup(&c[1]).sup(&c[2]));
            for iy in cell_of(a.y, lo.y, ny)..=cell_of(b.y, lo.y, ny) {
                for ix in cell_of(a.x, lo.x, nx)..=cell_of(b.x, lo.x, nx) {
                    cells[iy * nx + ix].push(k as u32);
                }
            }
        }
        TriLocator {
            origin: lo,
            cell_m,
            nx,
            ny,
            cells,
            tris,
            corners,
        }
    }

    /// The triangle containing `p` with its barycentric coordinates; for a point outside the
    /// panel, the nearest triangle and the barycentrics of the nearest point (`clamp`) or the
    /// unclamped ones (linear extrapolation of that triangle). `None` for an empty panel.
    pub fn locate(&self, p: &Vector2<f64>, clamp: bool) -> Option<(u32, [f64; 3])> {
        let ix = ((p.x - self.origin.x) / self.cell_m).floor() as i64;
        let iy = ((p.y - self.origin.y) / self.cell_m).floor() as i64;
        let mut best: Option<(f64, u32)> = None;
        let max_ring = self.nx.max(self.ny) as i64 + 1;
        for ring in 0..=max_ring {
            for cy in iy - ring..=iy + ring {
                for cx in ix - ring..=ix + ring {
                    let on_ring = (cy - iy).abs() == ring || (cx - ix).abs() == ring;
                    if !on_ring || cx < 0 || cy < 0 || cx >= self.nx as i64 || cy >= self.ny as i64
                    {
                        continue;
                    }
                    for &t in &self.cells[cy as usize * self.nx + cx as usize] {
                        let c = &self.corners[t as usize];
                        let b = barycentric(p, c);
                        let outside = -b.iter().copied().fold(0.0, f64::min);
                        if outside <= 1e-12 {
                            return Some((self.tris[t as usize], b));
                        }
                        let w = closest_barycentric(p, c);
                        let q = c[0] * w[0] + c[1] * w[1] + c[2] * w[2];
                        let d = (q - p).norm();
                        if best.is_none_or(|(bd, _)| d < bd) {
                            best = Some((d, t));
                        }
                    }
                }
            }
            // Every cell of the next ring is at least `ring · cell` away.
            if let Some((d, _)) = best {
                if d < ring as f64 * self.cell_m {
                    break;
                }
            }
        }
        best.map(|(_, k)| {
            let c = &self.corners[k as usize];
            let b = if clamp {
                closest_barycentric(p, c)
            } else {
                barycentric(p, c)
            };
            (self.tris[k as usize], b)
        })
    }
}

/// Every vertex of one mesh as a barycentric combination of a triangle of another mesh of the
/// same garment.
#[derive(Debug, Clone, PartialEq)]
pub struct Embedding {
    /// Vertices of the host triangle, per embedded vertex.
    pub verts: Vec<[u32; 3]>,
    /// Barycentric weights, per embedded vertex.
    pub weights: Vec<[f64; 3]>,
}

impl Embedding {
    /// Embeds every vertex of `src` in `host` by material coordinate, panel by panel (panels
    /// matched by name).
    pub fn new(src: &ClothMesh, host: &ClothMesh) -> Result<Embedding> {
        let mut verts = vec![[0u32; 3]; src.num_vertices()];
        let mut weights = vec![[0.0; 3]; src.num_vertices()];
        for (p, name) in src.panel_names.iter().enumerate() {
            let Some(hp) = host.panel_names.iter().position(|n| n == name) else {
                return Err(Error::Invalid(format!(
                    "panel '{name}' is missing from the other resolution's mesh"
                )));
            };
            let locator = TriLocator::new(host, hp as u32);
            for v in (0..src.num_vertices()).filter(|&v| src.panel_of_vertex[v] == p as u32) {
                let Some((t, b)) = locator.locate(&src.material[v], true) else {
                    return Err(Error::Invalid(format!(
                        "panel '{name}' has no triangles in the other resolution's mesh"
                    )));
                };
                verts[v] = host.triangles[t as usize];
                weights[v] = b;
            }
        }
        Ok(Embedding { verts, weights })
    }

    /// Values of the host mesh's vertices interpolated at the embedded vertices.
    pub fn apply(&self, host_values: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
        self.verts
            .iter()
            .zip(&self.weights)
            .map(|(v, w)| {
                host_values[v[0] as usize] * w[0]
                    + host_values[v[1] as usize] * w[1]
                    + host_values[v[2] as usize] * w[2]
            })
            .collect()
    }
}
