//! Mesh quality in material space: edge lengths, angles, areas.

use std::collections::HashMap;

use super::ClothMesh;

/// Outline corners with an interior angle below this (degrees) are exempt from the min-angle
/// figure: two triangles of at least 20° cannot fit in them.
pub const SHARP_CORNER_DEG: f64 = 40.0;

/// Quality figures of a [`ClothMesh`] measured in material space.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshStats {
    /// Vertex count.
    pub vertices: usize,
    /// Triangle count.
    pub triangles: usize,
    /// Mean edge length, m.
    pub mean_edge_m: f64,
    /// Smallest triangle angle, degrees, not counting angles at outline corners sharper than
    /// [`SHARP_CORNER_DEG`] (dart tips), which bound the quality there whatever the mesher does.
    pub min_angle_deg: f64,
    /// Outline corners sharper than [`SHARP_CORNER_DEG`].
    pub sharp_corners: usize,
    /// Triangles whose area is below 1e-3 of the mean (or not positive).
    pub degenerate: usize,
    /// Total material area, m².
    pub area_m2: f64,
}

impl MeshStats {
    /// Measures `mesh`.
    pub fn of(mesh: &ClothMesh) -> MeshStats {
        let edges = mesh.edges();
        let total: f64 = edges
            .iter()
            .map(|[a, b]| (mesh.material[*a as usize] - mesh.material[*b as usize]).norm())
            .sum();
        let mut area = 0.0;
        let areas: Vec<f64> = (0..mesh.triangles.len())
            .map(|t| mesh.material_area(t))
            .collect();
        let mut angles = Vec::with_capacity(3 * mesh.triangles.len());
        let mut angle_sum = vec![0.0f64; mesh.num_vertices()];
        let mut edge_use: HashMap<[u32; 2], u32> = HashMap::new();
        for (t, tri) in mesh.triangles.iter().enumerate() {
            area += areas[t];
            let p = tri.map(|v| mesh.material[v as usize]);
            for k in 0..3 {
                let (a, b, c) = (p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
                let (u, v) = (b - a, c - a);
                let cos = u.dot(&v) / (u.norm() * v.norm()).max(f64::MIN_POSITIVE);
                let angle = cos.clamp(-1.0, 1.0).acos().to_degrees();
                angles.push((tri[k], angle));
                angle_sum[tri[k] as usize] += angle;
                let (i, j) = (tri[k], tri[(k + 1) % 3]);
                *edge_use.entry([i.min(j), i.max(j)]).or_default() += 1;
            }
        }
        let mut boundary = vec![false; mesh.num_vertices()];
        for (e, n) in &edge_use {
            if *n == 1 {
                boundary[e[0] as usize] = true;
                boundary[e[1] as usize] = true;
            }
        }
        let sharp = |v: u32| boundary[v as usize] && angle_sum[v as usize] < SHARP_CORNER_DEG;
        let sharp_corners = (0..mesh.num_vertices() as u32)
            .filter(|&v| sharp(v))
            .count();
        let min_angle = angles
            .iter()
            .filter(|(v, _)| !sharp(*v))
            .map(|(_, a)| *a)
            .fold(180.0f64, f64::min);
        let mean_area = area / mesh.triangles.len().max(1) as f64;
        let degenerate = areas
            .iter()
            .filter(|a| a.is_nan() || **a <= 1e-3 * mean_area)
            .count();
        MeshStats {
            vertices: mesh.num_vertices(),
            triangles: mesh.triangles.len(),
            mean_edge_m: total / edges.len().max(1) as f64,
            min_angle_deg: if mesh.triangles.is_empty() {
                0.0
            } else {
                min_angle
            },
            sharp_corners,
            degenerate,
            area_m2: area,
        }
    }
}
