//! Triangle meshes of garments that keep each vertex's **material coordinate** (2D, metres, in its
//! panel's plane) and panel id, so that the coarse and fine meshes of one garment share a single
//! material space (the paper's §3.2.1 rests on it).

mod flatten;
mod from_uv;
mod locate;
mod pattern;
mod polygon;
mod quality;
mod remesh;

pub use flatten::{flatten, Distortion, FlattenOptions, Flattening};
pub use from_uv::{cloth_from_corners, connected_components};
pub use locate::{barycentric, Embedding, TriLocator};
pub use pattern::{mesh_garment, MeshOptions, COARSE_EDGE_M, FINE_EDGE_M, MAX_PANEL_VERTICES};
pub use polygon::triangulate_polygon;
pub use quality::{MeshStats, SHARP_CORNER_DEG};
pub use remesh::{remesh, CORNER_DEG};

use nalgebra::{Vector2, Vector3};

use crate::error::{Error, Result};

/// A cloth mesh: vertices with material and world coordinates, triangles, panels, seams.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ClothMesh {
    /// Material (pattern) coordinate of each vertex in its panel's frame, metres.
    pub material: Vec<Vector2<f64>>,
    /// World position of each vertex, metres (y up).
    pub positions: Vec<Vector3<f64>>,
    /// Triangles, counter-clockwise in material space.
    pub triangles: Vec<[u32; 3]>,
    /// Panel index of each vertex.
    pub panel_of_vertex: Vec<u32>,
    /// Panel names (index = panel id).
    pub panel_names: Vec<String>,
    /// Pairs of vertices sewn together (zero-length springs in the simulator).
    pub seam_pairs: Vec<[u32; 2]>,
}

impl ClothMesh {
    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }

    /// Checks array lengths, index ranges, finiteness and non-degenerate material triangles.
    pub fn validate(&self) -> Result<()> {
        let n = self.positions.len();
        if self.material.len() != n || self.panel_of_vertex.len() != n {
            return Err(Error::Invalid(format!(
                "mesh arrays disagree: {} positions, {} material coordinates, {} panel ids",
                n,
                self.material.len(),
                self.panel_of_vertex.len()
            )));
        }
        if let Some(i) = self
            .positions
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            return Err(Error::Invalid(format!(
                "vertex {i}: position is not finite"
            )));
        }
        if let Some(i) = self
            .material
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            return Err(Error::Invalid(format!(
                "vertex {i}: material coordinate is not finite"
            )));
        }
        for (t, tri) in self.triangles.iter().enumerate() {
            if tri.iter().any(|&v| v as usize >= n) {
                return Err(Error::Invalid(format!(
                    "triangle {t}: vertex index out of range"
                )));
            }
            let [a, b, c] = tri.map(|v| self.material[v as usize]);
            if (b - a).perp(&(c - a)).abs() < 1e-14 {
                return Err(Error::Invalid(format!(
                    "triangle {t}: zero area in material space (degenerate or missing texture coordinates)"
                )));
            }
        }
        if let Some(p) = self
            .seam_pairs
            .iter()
            .find(|p| p.iter().any(|&v| v as usize >= n))
        {
            return Err(Error::Invalid(format!(
                "seam pair {p:?}: vertex index out of range"
            )));
        }
        Ok(())
    }

    /// Material-space area of triangle `t`, m² (positive for counter-clockwise).
    pub fn material_area(&self, t: usize) -> f64 {
        let [a, b, c] = self.triangles[t].map(|v| self.material[v as usize]);
        0.5 * (b - a).perp(&(c - a))
    }

    /// Unique undirected edges `(i, j)` with `i < j`, sorted ([`unique_edges`]).
    pub fn edges(&self) -> Vec<[u32; 2]> {
        unique_edges(&self.triangles)
    }

    /// Quality statistics in material space.
    pub fn stats(&self) -> MeshStats {
        MeshStats::of(self)
    }

    /// Renumbers vertices along a Z-order (Morton) curve of their material coordinates, panel
    /// after panel, and sorts triangles by their smallest new vertex index, so that vertices
    /// and elements close on the cloth are close in memory. The mesher's insertion order
    /// scatters neighbours across the whole index range (at 40K vertices a run of 128
    /// consecutive triangles spanned ~24K vertex indices), which costs the simulator's sparse
    /// matrix and its parallel assembly their cache locality. The mesh is the same surface.
    pub fn reorder_for_locality(&mut self) {
        let n = self.num_vertices();
        if n == 0 {
            return;
        }
        let (mut lo, mut hi) = (
            Vector2::repeat(f64::INFINITY),
            Vector2::repeat(f64::NEG_INFINITY),
        );
        for m in &self.material {
            lo = lo.inf(m);
            hi = hi.sup(m);
        }
        let scale = (hi - lo).max().max(1e-12);
        let morton = |m: &Vector2<f64>| -> u64 {
            let q = |t: f64| ((t / scale).clamp(0.0, 1.0) * f64::from(u16::MAX)) as u64;
            let spread = |mut v: u64| {
                v &= 0xffff;
                v = (v | (v << 8)) & 0x00ff_00ff;
                v = (v | (v << 4)) & 0x0f0f_0f0f;
                v = (v | (v << 2)) & 0x3333_3333;
                (v | (v << 1)) & 0x5555_5555
            };
            let d = m - lo;
            spread(q(d.x)) | (spread(q(d.y)) << 1)
        };
        let mut order: Vec<u32> = (0..n as u32).collect();
        order.sort_by_key(|&v| {
            let v = v as usize;
            (
                self.panel_of_vertex.get(v).copied().unwrap_or(0),
                morton(&self.material[v]),
                v,
            )
        });
        let mut new_of = vec![0u32; n];
        for (new, &old) in order.iter().enumerate() {
            new_of[old as usize] = new as u32;
        }
        let permute = |v: &[u32]| -> Vec<u32> { order.iter().map(|&o| v[o as usize]).collect() };
        self.material = order.iter().map(|&o| self.material[o as usize]).collect();
        self.positions = order.iter().map(|&o| self.positions[o as usize]).collect();
        if self.panel_of_vertex.len() == n {
            self.panel_of_vertex = permute(&self.panel_of_vertex);
        }
        for t in &mut self.triangles {
            *t = t.map(|v| new_of[v as usize]);
        }
        self.triangles
            .sort_by_key(|t| (*t.iter().min().unwrap_or(&0), t[0], t[1], t[2]));
        for p in &mut self.seam_pairs {
            *p = p.map(|v| new_of[v as usize]);
        }
        self.seam_pairs.sort_unstable();
    }
}

/// The unique undirected edges `(i, j)`, `i < j`, of `triangles`, sorted.
pub fn unique_edges(triangles: &[[u32; 3]]) -> Vec<[u32; 2]> {
    let mut e: Vec<[u32; 2]> = triangles
        .iter()
        .flat_map(|t| [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]])
        .map(|[a, b]| if a < b { [a, b] } else { [b, a] })
        .collect();
    e.sort_unstable();
    e.dedup();
    e
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::garment::Fabric;
    use crate::scene::samples::flat_sheet;

    #[test]
    fn reordering_for_locality_keeps_the_surface_and_brings_neighbours_close() {
        let g = flat_sheet("s", 0.6, 0.4, Vector3::zeros(), Fabric::default());
        let mesh = crate::mesh::mesh_garment(&g, &MeshOptions::with_edge(0.01)).expect("mesh");
        // mesh_garment reorders already: scramble it back to compare.
        let n = mesh.num_vertices();
        let scramble: Vec<u32> = (0..n as u32).map(|i| (i * 7919) % n as u32).collect();
        let mut s = mesh.clone();
        for (new, &old) in scramble.iter().enumerate() {
            s.material[new] = mesh.material[old as usize];
            s.positions[new] = mesh.positions[old as usize];
        }
        let mut inv = vec![0u32; n];
        for (new, &old) in scramble.iter().enumerate() {
            inv[old as usize] = new as u32;
        }
        for t in &mut s.triangles {
            *t = t.map(|v| inv[v as usize]);
        }
        let area = |m: &ClothMesh| {
            (0..m.triangles.len())
                .map(|t| m.material_area(t))
                .sum::<f64>()
        };
        let span = |m: &ClothMesh| {
            m.triangles
                .chunks(64)
                .map(|c| {
                    let f = c.iter().flatten();
                    (f.clone().max().copied().unwrap_or(0) - f.min().copied().unwrap_or(0)) as f64
                })
                .sum::<f64>()
                / m.triangles.len().div_ceil(64) as f64
        };
        let (a0, span0) = (area(&s), span(&s));
        let mut r = s.clone();
        r.reorder_for_locality();
        r.validate().expect("valid after reordering");
        // Same surface: every triangle keeps its (counter-clockwise) area, the total is equal.
        assert!((area(&r) - a0).abs() < 1e-12 * a0.max(1.0));
        assert!(r
            .triangles
            .iter()
            .enumerate()
            .all(|(t, _)| r.material_area(t) > 0.0));
        let key = |m: &ClothMesh| {
            let mut k: Vec<[i64; 2]> = m
                .material
                .iter()
                .map(|p| [(p.x * 1e9).round() as i64, (p.y * 1e9).round() as i64])
                .collect();
            k.sort_unstable();
            k
        };
        assert_eq!(key(&r), key(&s));
        assert!(span(&r) * 4.0 < span0, "span {} vs {}", span(&r), span0);
    }
}
