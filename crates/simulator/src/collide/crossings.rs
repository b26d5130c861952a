//! Cloth edges through cloth triangles.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::body::tri_points;
use super::bvh::{Aabb, Bvh};
use super::crease::edge_boxes;

/// Boxes of triangles, inflated by `r`.
pub(super) fn triangle_boxes(pts: &[Vector3<f64>], tris: &[[u32; 3]], r: f64) -> Vec<Aabb> {
    tris.par_iter()
        .map(|t| Aabb::from_points(t.iter().map(|&i| &pts[i as usize])).inflate(r))
        .collect()
}

/// The cloth's edge–triangle crossings at `x`: pairs (edge, triangle) sharing no vertex whose
/// segment passes through the triangle, for which `keep(edge, triangle)` holds. Cloth that
/// never passed through itself has none. A diagnostic (a BVH build per call), not for the
/// step's hot path.
pub fn edge_triangle_crossings(
    x: &[Vector3<f64>],
    tris: &[[u32; 3]],
    edges: &[[u32; 2]],
    keep: impl Fn([u32; 2], [u32; 3]) -> bool + Sync,
) -> Vec<([u32; 2], [u32; 3])> {
    let tri_bvh = Bvh::build(&triangle_boxes(x, tris, 0.0));
    let edge_bvh = Bvh::build(&edge_boxes(x, edges, 0.0));
    tri_bvh.pairs_with_filter_map(&edge_bvh, |t, e| {
        let (t, e) = (tris[t as usize], edges[e as usize]);
        if t.contains(&e[0]) || t.contains(&e[1]) || !keep(e, t) {
            return None;
        }
        let [a, b, c] = tri_points(x, &t);
        segment_crosses_triangle(&x[e[0] as usize], &x[e[1] as usize], &a, &b, &c).then_some((e, t))
    })
}

/// Whether segment p–q passes through triangle a, b, c (Möller–Trumbore; a segment in the
/// triangle's plane does not count).
pub(super) fn segment_crosses_triangle(
    p: &Vector3<f64>,
    q: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> bool {
    let d = q - p;
    let (e1, e2) = (b - a, c - a);
    let pv = d.cross(&e2);
    let det = e1.dot(&pv);
    if det.abs() < 1e-18 {
        return false;
    }
    let inv = 1.0 / det;
    let tv = p - a;
    let u = tv.dot(&pv) * inv;
    let qv = tv.cross(&e1);
    let v = d.dot(&qv) * inv;
    let w = e2.dot(&qv) * inv;
    (0.0..=1.0).contains(&u) && v >= 0.0 && u + v <= 1.0 && (0.0..=1.0).contains(&w)
}
