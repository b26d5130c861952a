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
/// rather than metres), each connected UV chart is scaled to its own 3D area (a texture atlas
/// may give its charts different texel densities) and `rescaled` is the factor of the whole
/// layout (the square root of its 3D area over its UV area).
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

    let rescaled = rescale_charts(&mut mesh);
    mesh.validate()?;
    Ok((mesh, rescaled))
}

/// Scales each connected chart (panel) of `mesh` so that its material area equals its 3D area,
/// when the whole layout's area is off by more than 2×; returns the whole layout's factor then.
/// Each chart is scaled about its centroid, and the centroids by the whole layout's factor, so
/// that the layout keeps its arrangement.
fn rescale_charts(mesh: &mut ClothMesh) -> Option<f64> {
    let charts = mesh.panel_names.len();
    let mut area3 = vec![0.0; charts];
    let mut area_uv = vec![0.0; charts];
    let mut centroid = vec![Vector2::zeros(); charts];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let k = mesh.panel_of_vertex[tri[0] as usize] as usize;
        let [a, b, c] = tri.map(|v| mesh.positions[v as usize]);
        let a_uv = mesh.material_area(t).abs();
        area3[k] += 0.5 * (b - a).cross(&(c - a)).norm();
        area_uv[k] += a_uv;
        centroid[k] += tri
            .iter()
            .map(|&v| mesh.material[v as usize])
            .sum::<Vector2<f64>>()
            * (a_uv / 3.0);
    }
    let (total3, total_uv) = (area3.iter().sum::<f64>(), area_uv.iter().sum::<f64>());
    if !(total_uv > 0.0 && total3 > 0.0) || (0.5..=2.0).contains(&(total3 / total_uv)) {
        return None;
    }
    let s = (total3 / total_uv).sqrt();
    let scale: Vec<f64> = area3
        .iter()
        .zip(&area_uv)
        .map(|(&a3, &a2)| {
            if a2 > 0.0 && a3 > 0.0 {
                (a3 / a2).sqrt()
            } else {
                s
            }
        })
        .collect();
    for (c, &a2) in centroid.iter_mut().zip(&area_uv) {
        if a2 > 0.0 {
            *c /= a2;
        }
    }
    for (m, &k) in mesh.material.iter_mut().zip(&mesh.panel_of_vertex) {
        let k = k as usize;
        *m = centroid[k] * s + (*m - centroid[k]) * scale[k];
    }
    Some(s)
}

/// Component id of every vertex (components numbered in order of their smallest vertex).
pub fn connected_components(n: usize, triangles: &[[u32; 3]]) -> Vec<u32> {
    components_of_edges(
        n,
        triangles.iter().flat_map(|t| [[t[0], t[1]], [t[1], t[2]]]),
    )
}

/// Component id of every vertex of the graph with `edges` (components numbered in order of
/// their smallest vertex).
pub(crate) fn components_of_edges(n: usize, edges: impl IntoIterator<Item = [u32; 2]>) -> Vec<u32> {
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    for [a, b] in edges {
        let (a, b) = (find(&mut parent, a as usize), find(&mut parent, b as usize));
        if a != b {
            parent[a.max(b)] = a.min(b);
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn charts_at_different_texel_densities_get_their_own_scale() {
        // A 2 m × 1 m strip of two 1 m squares sharing the edge x = 1, each its own UV chart:
        // the left one 0.1 wide in texture space, the right one 0.3 wide.
        let points: Vec<Vector3<f64>> = [0.0, 1.0, 2.0]
            .iter()
            .flat_map(|&x| [Vector3::new(x, 0.0, 0.0), Vector3::new(x, 0.0, 1.0)])
            .collect();
        let square = |p: [u32; 4], origin: Vector2<f64>, size: f64| {
            let uv = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
                .map(|(u, v)| origin + Vector2::new(u, v) * size);
            (
                vec![p[0], p[1], p[2], p[0], p[2], p[3]],
                vec![uv[0], uv[1], uv[2], uv[0], uv[2], uv[3]],
            )
        };
        let (mut corner_point, mut corner_uv) = square([0, 2, 3, 1], Vector2::zeros(), 0.1);
        let (p, uv) = square([2, 4, 5, 3], Vector2::new(0.5, 0.5), 0.3);
        corner_point.extend(p);
        corner_uv.extend(uv);
        let (mesh, rescaled) =
            cloth_from_corners(&points, &corner_point, &corner_uv).expect("cloth");
        assert!(rescaled.is_some());
        assert_eq!(mesh.panel_names.len(), 2);
        assert_eq!(mesh.seam_pairs.len(), 2, "the shared edge is sewn");
        for [a, b] in mesh.edges() {
            let l3 = (mesh.positions[a as usize] - mesh.positions[b as usize]).norm();
            let l2 = (mesh.material[a as usize] - mesh.material[b as usize]).norm();
            assert!((l2 - l3).abs() < 1e-12, "edge {a}-{b}: {l2} vs {l3}");
        }
        // A uniform scale would have made the left square 0.63 m and the right 1.9 m wide.
        for t in 0..mesh.triangles.len() {
            assert!((mesh.material_area(t) - 0.5).abs() < 1e-12);
        }
    }

    #[test]
    fn layouts_in_metres_are_left_alone() {
        let points = vec![Vector3::zeros(), Vector3::x(), Vector3::z()];
        let uv = vec![
            Vector2::zeros(),
            Vector2::new(1.1, 0.0),
            Vector2::new(0.0, 0.9),
        ];
        let (mesh, rescaled) = cloth_from_corners(&points, &[0, 1, 2], &uv).expect("cloth");
        assert!(rescaled.is_none());
        assert_eq!(mesh.material, uv);
    }
}
