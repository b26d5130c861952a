//! Cloth meshes from triangle meshes with texture coordinates (OBJ `vt`, USD `primvars:st`):
//! texture coordinates become material coordinates, points split along UV seams are sewn back
//! together, and connected pieces become panels.

use std::collections::HashMap;

use nalgebra::{Vector2, Vector3};

use super::ClothMesh;
use crate::error::{Error, Result};

/// Builds a cloth mesh from per-corner data: `corner_point[c]` is the 3D point of corner `c`
/// (three corners per triangle) and `corner_uv[c]` its texture coordinate. Corners sharing a
/// point and a UV become one vertex; vertices of one point with different UVs are sewn.
///
/// When the UV layout's area differs from the 3D area by more than 2× (texture space in [0, 1]
/// rather than metres), UVs are scaled uniformly to the 3D area and `rescaled` is set.
pub fn cloth_from_corners(
    points: &[Vector3<f64>],
    corner_point: &[u32],
    corner_uv: &[Vector2<f64>],
) -> Result<(ClothMesh, Option<f64>)> {
    if corner_point.len() != corner_uv.len() || !corner_point.len().is_multiple_of(3) {
        return Err(Error::Invalid(
            "texture coordinates do not match the faces".into(),
        ));
    }
    let mut index: HashMap<(u32, u64, u64), u32> = HashMap::new();
    let mut mesh = ClothMesh::default();
    let mut point_of_vertex = Vec::new();
    let mut corners = Vec::with_capacity(corner_point.len());
    for (&p, uv) in corner_point.iter().zip(corner_uv) {
        if p as usize >= points.len() {
            return Err(Error::Invalid(format!(
                "face index {p} is outside the {} points",
                points.len()
            )));
        }
        let key = (p, uv.x.to_bits(), uv.y.to_bits());
        let v = *index.entry(key).or_insert_with(|| {
            mesh.positions.push(points[p as usize]);
            mesh.material.push(*uv);
            point_of_vertex.push(p);
            (mesh.positions.len() - 1) as u32
        });
        corners.push(v);
    }
    mesh.triangles = corners
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    // Orient triangles counter-clockwise in material space; drop none (validate reports zero area).
    for t in &mut mesh.triangles {
        let [a, b, c] = t.map(|v| mesh.material[v as usize]);
        if (b - a).perp(&(c - a)) < 0.0 {
            t.swap(1, 2);
        }
    }
    // Sew vertices that share a 3D point.
    let mut by_point: HashMap<u32, Vec<u32>> = HashMap::new();
    for (v, &p) in point_of_vertex.iter().enumerate() {
        by_point.entry(p).or_default().push(v as u32);
    }
    for group in by_point.values() {
        for w in group.windows(2) {
            mesh.seam_pairs.push([w[0], w[1]]);
        }
    }
    mesh.seam_pairs.sort_unstable();
    mesh.panel_of_vertex = connected_components(mesh.positions.len(), &mesh.triangles);
    let panels = mesh
        .panel_of_vertex
        .iter()
        .copied()
        .max()
        .map_or(0, |m| m + 1);
    mesh.panel_names = (0..panels).map(|i| format!("panel_{i}")).collect();

    let area3: f64 = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
            0.5 * (b - a).cross(&(c - a)).norm()
        })
        .sum();
    let area_uv: f64 = (0..mesh.triangles.len())
        .map(|t| mesh.material_area(t).abs())
        .sum();
    let mut rescaled = None;
    if area_uv > 0.0 && area3 > 0.0 && !(0.5..=2.0).contains(&(area3 / area_uv)) {
        let s = (area3 / area_uv).sqrt();
        for m in &mut mesh.material {
            *m *= s;
        }
        rescaled = Some(s);
    }
    mesh.validate()?;
    Ok((mesh, rescaled))
}

/// Component id of every vertex (components numbered in order of their smallest vertex).
pub fn connected_components(n: usize, triangles: &[[u32; 3]]) -> Vec<u32> {
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    for t in triangles {
        for k in 0..2 {
            let (a, b) = (
                find(&mut parent, t[k] as usize),
                find(&mut parent, t[k + 1] as usize),
            );
            if a != b {
                parent[a.max(b)] = a.min(b);
            }
        }
    }
    let mut ids = HashMap::new();
    (0..n)
        .map(|v| {
            let r = find(&mut parent, v);
            let next = ids.len() as u32;
            *ids.entry(r).or_insert(next)
        })
        .collect()
}
