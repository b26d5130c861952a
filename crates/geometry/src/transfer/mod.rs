//! Moving cloth states between the coarse and fine meshes of one garment (the paper's §3.3.1).
//!
//! Both meshes come from the same sewing pattern, so every vertex has a material coordinate in
//! its panel's plane, shared by the two resolutions. Each coarse vertex is embedded in the fine
//! triangle of the same panel that contains its material coordinate (barycentric weights), and
//! each fine vertex in a coarse triangle likewise:
//!
//! * **downsample** a fine state (positions or velocities) to the coarse mesh: M_int, the
//!   corrector's target;
//! * **upsample** a coarse state to the fine mesh: the no-learning baseline that every
//!   evaluation compares against.
//!
//! Curved panel edges are polylines at both resolutions, so a vertex on a curve can lie a hair
//! outside the other mesh; it then takes the nearest point of the nearest triangle of its panel.

use nalgebra::{Vector2, Vector3};

use crate::error::{Error, Result};
use crate::mesh::ClothMesh;

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

/// Area-weighted vertex normals of `triangles` at positions `x` (unit length; zero for a
/// vertex in no triangle).
pub fn vertex_normals(triangles: &[[u32; 3]], x: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
    let mut n = vec![Vector3::zeros(); x.len()];
    for t in triangles {
        let (a, b, c) = (x[t[0] as usize], x[t[1] as usize], x[t[2] as usize]);
        let f = (b - a).cross(&(c - a));
        for &i in t {
            n[i as usize] += f;
        }
    }
    for v in &mut n {
        let l = v.norm();
        if l > 0.0 {
            *v /= l;
        }
    }
    n
}

/// Phong tessellation (Boubekeur & Alexa 2008) of the triangle with corners `x` and vertex
/// normals `n` at barycentric weights `w`: the linear point projected onto each corner's
/// tangent plane, those projections interpolated, blended with the linear point by `alpha`
/// (0: linear). A curved surface sampled at the corners is recovered to second order, which
/// removes most of the chord error of piecewise-linear upsampling (its "sagitta").
pub fn phong_point(
    x: [Vector3<f64>; 3],
    n: [Vector3<f64>; 3],
    w: [f64; 3],
    alpha: f64,
) -> Vector3<f64> {
    let p = x[0] * w[0] + x[1] * w[1] + x[2] * w[2];
    if alpha == 0.0 {
        return p;
    }
    let q: Vector3<f64> = (0..3)
        .map(|k| (p - n[k] * (p - x[k]).dot(&n[k])) * w[k])
        .sum();
    p * (1.0 - alpha) + q * alpha
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

    /// Host positions `host_x` interpolated at the embedded vertices by Phong tessellation
    /// ([`phong_point`]) with the host's vertex normals `host_n`.
    pub fn apply_phong(
        &self,
        host_x: &[Vector3<f64>],
        host_n: &[Vector3<f64>],
        alpha: f64,
    ) -> Vec<Vector3<f64>> {
        self.verts
            .iter()
            .zip(&self.weights)
            .map(|(v, w)| {
                let g = |k: usize| v[k] as usize;
                phong_point(
                    [host_x[g(0)], host_x[g(1)], host_x[g(2)]],
                    [host_n[g(0)], host_n[g(1)], host_n[g(2)]],
                    *w,
                    alpha,
                )
            })
            .collect()
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

/// Both directions between the coarse and fine meshes of one garment (or of a whole model:
/// panel names carry the part's name).
#[derive(Debug, Clone, PartialEq)]
pub struct Transfer {
    /// Coarse vertices in fine triangles: downsampling.
    pub coarse_in_fine: Embedding,
    /// Fine vertices in coarse triangles: upsampling.
    pub fine_in_coarse: Embedding,
}

impl Transfer {
    /// Embeddings between `coarse` and `fine`.
    pub fn new(coarse: &ClothMesh, fine: &ClothMesh) -> Result<Transfer> {
        Ok(Transfer {
            coarse_in_fine: Embedding::new(coarse, fine)?,
            fine_in_coarse: Embedding::new(fine, coarse)?,
        })
    }

    /// A fine state (positions or velocities) on the coarse mesh.
    pub fn downsample(&self, fine: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
        self.coarse_in_fine.apply(fine)
    }

    /// A coarse state on the fine mesh (piecewise-linear: the baseline without learning).
    pub fn upsample(&self, coarse: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
        self.fine_in_coarse.apply(coarse)
    }

    /// Coarse positions on the fine mesh by Phong tessellation of the coarse mesh
    /// (`coarse_triangles`) with blend `alpha` ([`phong_point`]).
    pub fn upsample_phong(
        &self,
        coarse: &[Vector3<f64>],
        coarse_triangles: &[[u32; 3]],
        alpha: f64,
    ) -> Vec<Vector3<f64>> {
        let n = vertex_normals(coarse_triangles, coarse);
        self.fine_in_coarse.apply_phong(coarse, &n, alpha)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phong_is_linear_on_flat_triangles_and_recovers_sphere_curvature() {
        let x = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(0.02, 0.0, 0.0),
            Vector3::new(0.0, 0.0, 0.02),
        ];
        let w = [0.2, 0.3, 0.5];
        let lin = x[0] * w[0] + x[1] * w[1] + x[2] * w[2];
        // Flat: the normals are the plane's; nothing moves, whatever alpha.
        let n = [Vector3::y(); 3];
        assert!((phong_point(x, n, w, 0.75) - lin).norm() < 1e-15);
        // Alpha 0 is linear on any triangle.
        let r = 0.07;
        let on_sphere = |d: Vector3<f64>| d.normalize() * r;
        let dirs = [
            Vector3::new(0.0, 1.0, 0.0),
            Vector3::new(0.3, 1.0, 0.0),
            Vector3::new(0.0, 1.0, 0.3),
        ];
        let xs = dirs.map(on_sphere);
        let ns = dirs.map(|d| d.normalize());
        let lin = xs[0] * w[0] + xs[1] * w[1] + xs[2] * w[2];
        assert!((phong_point(xs, ns, w, 0.0) - lin).norm() < 1e-15);
        // A sphere sampled at the corners: the chord lies inside by the sagitta; Phong
        // tessellation comes much closer to the surface.
        let lin_err = (lin.norm() - r).abs();
        let ph_err = (phong_point(xs, ns, w, 0.75).norm() - r).abs();
        assert!(lin_err > 1e-4, "{lin_err}");
        assert!(ph_err < 0.5 * lin_err, "Phong {ph_err} vs linear {lin_err}");
        // Vertex normals of a flat fan point along its normal.
        let tris = [[0u32, 2, 1]];
        let vn = vertex_normals(&tris, &x);
        assert!((vn[0] - Vector3::y()).norm() < 1e-12);
    }
    use crate::garment::Fabric;
    use crate::mesh::{mesh_garment, MeshOptions};
    use crate::scene::samples::flat_sheet;

    fn meshes(coarse_m: f64, fine_m: f64) -> (ClothMesh, ClothMesh) {
        let g = flat_sheet("s", 0.4, 0.3, Vector3::zeros(), Fabric::default());
        (
            mesh_garment(&g, &MeshOptions::with_edge(coarse_m)).expect("coarse"),
            mesh_garment(&g, &MeshOptions::with_edge(fine_m)).expect("fine"),
        )
    }

    /// A smooth bump over material space (metres): curvature radius ≳ 0.1 m.
    fn bump(m: &Vector2<f64>) -> Vector3<f64> {
        Vector3::new(
            m.x,
            0.02 * (m.x * 12.0).sin() * (m.y * 9.0).cos(),
            m.y + 0.01 * (m.x * 7.0).cos(),
        )
    }

    #[test]
    fn flat_sheet_downsamples_exactly() {
        let (c, f) = meshes(0.02, 0.0025);
        let t = Transfer::new(&c, &f).expect("transfer");
        // Positions affine in material coordinates: interpolation is exact.
        let lift = |m: &ClothMesh| -> Vec<Vector3<f64>> {
            m.material
                .iter()
                .map(|p| Vector3::new(0.3 + p.x, 1.0 - 0.5 * p.y, 0.2 * p.x + p.y))
                .collect()
        };
        let down = t.downsample(&lift(&f));
        let err = down
            .iter()
            .zip(&lift(&c))
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(err < 1e-12, "M_int of a flat sheet is off by {err:e} m");
    }

    #[test]
    fn down_then_up_on_a_smooth_surface_is_within_a_tenth_of_a_millimetre() {
        let (c, f) = meshes(0.02, 0.0025);
        let t = Transfer::new(&c, &f).expect("transfer");
        let fine: Vec<Vector3<f64>> = f.material.iter().map(bump).collect();
        let coarse_truth: Vec<Vector3<f64>> = c.material.iter().map(bump).collect();
        let down = t.downsample(&fine);
        let down_err = down
            .iter()
            .zip(&coarse_truth)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        // The fine mesh samples the surface every 2.5 mm: a coarse vertex read from it is off by
        // the fine mesh's chordal error only.
        assert!(down_err < 1e-4, "downsample error {:.4} mm", down_err * 1e3);
        // Up again: the coarse mesh is piecewise linear at 20 mm, its chordal error is ~h²κ/8.
        let up = t.upsample(&down);
        let mean = up
            .iter()
            .zip(&fine)
            .map(|(a, b)| (a - b).norm())
            .sum::<f64>()
            / fine.len() as f64;
        assert!(mean < 1e-4, "down∘up mean error {:.4} mm", mean * 1e3);
        // And the coarse mesh's own vertices come back where they were.
        let back = t.downsample(&up);
        let err = back
            .iter()
            .zip(&down)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(
            err < 1e-4,
            "down∘up∘down moves coarse vertices {:.4} mm",
            err * 1e3
        );
    }

    #[test]
    fn a_point_outside_takes_the_nearest_triangle() {
        let (c, _) = meshes(0.05, 0.05);
        let loc = TriLocator::new(&c, 0);
        let (t, b) = loc.locate(&Vector2::new(-0.01, 0.1), true).expect("found");
        assert!(b.iter().all(|&w| w >= 0.0));
        let tri = c.triangles[t as usize].map(|v| c.material[v as usize]);
        let q = tri[0] * b[0] + tri[1] * b[1] + tri[2] * b[2];
        assert!(
            (q - Vector2::new(0.0, 0.1)).norm() < 1e-9,
            "nearest point {q:?}"
        );
        let (_, e) = loc.locate(&Vector2::new(-0.01, 0.1), false).expect("found");
        assert!(e.iter().any(|&w| w < 0.0), "extrapolated weights {e:?}");
    }
}
