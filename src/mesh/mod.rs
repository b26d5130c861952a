//! Triangle meshes of garments that keep each vertex's **material coordinate** (2D, metres, in its
//! panel's plane) and panel id, so that the coarse and fine meshes of one garment share a single
//! material space (the paper's §3.2.1 rests on it).

mod from_uv;
mod pattern;
mod quality;

pub use from_uv::{cloth_from_corners, connected_components};
pub use pattern::{mesh_garment, MeshOptions, COARSE_EDGE_M, FINE_EDGE_M};
pub use quality::{MeshStats, SHARP_CORNER_DEG};

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

    /// Unique undirected edges `(i, j)` with `i < j`, sorted.
    pub fn edges(&self) -> Vec<[u32; 2]> {
        let mut e: Vec<[u32; 2]> = self
            .triangles
            .iter()
            .flat_map(|t| [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]])
            .map(|[a, b]| if a < b { [a, b] } else { [b, a] })
            .collect();
        e.sort_unstable();
        e.dedup();
        e
    }

    /// Quality statistics in material space.
    pub fn stats(&self) -> MeshStats {
        MeshStats::of(self)
    }
}
