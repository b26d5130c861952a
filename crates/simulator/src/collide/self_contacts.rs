//! Cloth against cloth: close pairs and pairs that may meet along a move.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::body::tri_points;
use super::bvh::Aabb;
use super::contact::{CollisionParams, Contact};
use super::crease::edge_boxes;
use super::crossings::triangle_boxes;
use super::detector::{ClothPairs, CollisionDetector};
use super::distance::{point_triangle, segment_segment};

impl CollisionDetector {
    /// Cloth–cloth pairs (vertex–triangle, then edge–edge) that may come within `r` of each
    /// other while every vertex moves on a straight line from `x0` to `x1`: those whose swept
    /// boxes (inflated by `r`) overlap and whose gap at `x0` less the most it can close
    /// (the largest relative move of a point of one side against one of the other) is under
    /// `r`. Cloth moving together makes few: its neighbours' relative moves are small.
    pub fn find_swept_self_pairs(
        &mut self,
        x0: &[Vector3<f64>],
        x1: &[Vector3<f64>],
        cloth_tris: &[[u32; 3]],
        cloth_edges: &[[u32; 2]],
        r: f64,
    ) -> Vec<Contact> {
        let mut out = Vec::new();
        if x0.len() != x1.len() || r.is_nan() || r <= 0.0 {
            return out;
        }
        let rebuild_every = self.rebuild_every;
        let (pairs, every) = (self.cloth_pairs.clone(), self.every_cloth_pair);
        let keep = |a: &[u32], b: &[u32]| Self::keep_self_pair(pairs.as_deref(), every, a, b);
        let swept = |ids: &[u32], pad: f64| {
            Aabb::from_points(ids.iter().flat_map(|&i| [&x0[i as usize], &x1[i as usize]]))
                .inflate(pad)
        };
        let closing = |a: &[u32], b: &[u32]| {
            a.iter()
                .flat_map(|&i| {
                    b.iter().map(move |&j| {
                        ((x1[i as usize] - x0[i as usize]) - (x1[j as usize] - x0[j as usize]))
                            .norm()
                    })
                })
                .fold(0.0, f64::max)
        };
        if !cloth_tris.is_empty() {
            let boxes: Vec<Aabb> = cloth_tris.par_iter().map(|t| swept(t, r)).collect();
            self.cloth_tris
                .update(cloth_tris.as_flattened(), &boxes, rebuild_every);
            let tri_bvh = &self.cloth_tris.bvh;
            let vt: Vec<Vec<Contact>> = (0..x0.len() as u32)
                .into_par_iter()
                .map(|v| {
                    let mut found = Vec::new();
                    tri_bvh.query(&swept(&[v], 0.0), |t| {
                        let t = cloth_tris[t as usize];
                        if t.contains(&v) {
                            return;
                        }
                        let [a, b, c] = tri_points(x0, &t);
                        let d = point_triangle(&x0[v as usize], &a, &b, &c).dist;
                        if d - closing(&[v], &t) < r && keep(&[v], &t) {
                            found.push(Contact::VertexTriangle { v, t });
                        }
                    });
                    found
                })
                .collect();
            out.extend(vt.into_iter().flatten());
        }
        if !cloth_edges.is_empty() {
            let boxes: Vec<Aabb> = cloth_edges.par_iter().map(|e| swept(e, 0.5 * r)).collect();
            self.cloth_edges
                .update(cloth_edges.as_flattened(), &boxes, rebuild_every);
            let ee = self.cloth_edges.bvh.self_pairs_filter_map(|i, j| {
                let (a, b) = (cloth_edges[i as usize], cloth_edges[j as usize]);
                if a.contains(&b[0]) || a.contains(&b[1]) {
                    return None;
                }
                let x = |k: u32| &x0[k as usize];
                let d = segment_segment(x(a[0]), x(a[1]), x(b[0]), x(b[1])).dist;
                (d - closing(&a, &b) < r && keep(&a, &b)).then_some(Contact::EdgeEdge { a, b })
            });
            out.extend(ee);
        }
        out
    }

    /// Whether a cloth–cloth pair between the features `a` and `b` (vertex ids) is reported:
    /// always, unless contacts are kept within panels (`within`: each vertex's panel) and the
    /// two lie in different ones.
    fn keep_self_pair(pairs: Option<&ClothPairs>, every: bool, a: &[u32], b: &[u32]) -> bool {
        pairs.is_none_or(|p| p.keep(a[0], b[0], every))
    }

    pub(super) fn find_self_contacts_into(
        &mut self,
        cloth_x: &[Vector3<f64>],
        cloth_tris: &[[u32; 3]],
        cloth_edges: &[[u32; 2]],
        params: &CollisionParams,
        contacts: &mut Vec<Contact>,
    ) {
        let dhat = params.dhat_m.max(0.0);
        let rebuild_every = self.rebuild_every;
        let (pairs, every) = (self.cloth_pairs.clone(), self.every_cloth_pair);
        let keep = |a: &[u32], b: &[u32]| Self::keep_self_pair(pairs.as_deref(), every, a, b);
        if params.self_collision && dhat > 0.0 && !cloth_tris.is_empty() {
            self.cloth_tris.update(
                cloth_tris.as_flattened(),
                &triangle_boxes(cloth_x, cloth_tris, dhat),
                rebuild_every,
            );
            let tri_bvh = &self.cloth_tris.bvh;
            let vt: Vec<Vec<Contact>> = cloth_x
                .par_iter()
                .enumerate()
                .map(|(v, p)| {
                    let v = v as u32;
                    let mut out = Vec::new();
                    tri_bvh.query(&Aabb::from_point(p), |t| {
                        let t = cloth_tris[t as usize];
                        if t.contains(&v) {
                            return;
                        }
                        let [a, b, c] = tri_points(cloth_x, &t);
                        if point_triangle(p, &a, &b, &c).dist < dhat && keep(&[v], &t) {
                            out.push(Contact::VertexTriangle { v, t });
                        }
                    });
                    out
                })
                .collect();
            contacts.extend(vt.into_iter().flatten());
        }
        if params.self_collision && dhat > 0.0 && !cloth_edges.is_empty() {
            self.cloth_edges.update(
                cloth_edges.as_flattened(),
                &edge_boxes(cloth_x, cloth_edges, 0.5 * dhat),
                rebuild_every,
            );
            let ee = self.cloth_edges.bvh.self_pairs_filter_map(|i, j| {
                let (a, b) = (cloth_edges[i as usize], cloth_edges[j as usize]);
                if a.contains(&b[0]) || a.contains(&b[1]) {
                    return None;
                }
                let x = |k: u32| &cloth_x[k as usize];
                let d = segment_segment(x(a[0]), x(a[1]), x(b[0]), x(b[1])).dist;
                (d < dhat && keep(&a, &b)).then_some(Contact::EdgeEdge { a, b })
            });
            contacts.extend(ee);
        }
    }
}

#[cfg(test)]
mod swept_tests {
    use super::*;
    use crate::collide::inside::is_closed;
    use crate::collide::*;

    /// An edge through the middle of a triangle crosses it; one beside it, one above it and
    /// one sharing a vertex with it do not.
    #[test]
    fn edge_triangle_crossings_find_an_edge_through_a_triangle() {
        let x = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(0.1, 0.0, 0.0),
            Vector3::new(0.0, 0.1, 0.0),
            Vector3::new(0.02, 0.02, 0.01),
            Vector3::new(0.02, 0.02, -0.01),
            Vector3::new(0.2, 0.2, 0.01),
            Vector3::new(0.2, 0.2, -0.01),
            Vector3::new(0.02, 0.02, 0.02),
        ];
        let tris = [[0u32, 1, 2]];
        let edges = [[3u32, 4], [5, 6], [3, 7], [0, 4]];
        let all = edge_triangle_crossings(&x, &tris, &edges, |_, _| true);
        assert_eq!(all, vec![([3, 4], [0, 1, 2])]);
        assert!(edge_triangle_crossings(&x, &tris, &edges, |e, _| e != [3, 4]).is_empty());
    }

    /// A vertex that flies through a triangle from 5 cm away is found; one that moves as fast
    /// alongside it, and one that flies past outside it, are not; nor is a vertex that moves
    /// with the triangle, however far.
    #[test]
    fn swept_pairs_are_those_that_may_meet_on_the_way() {
        let tri = [[0u32, 1, 2]];
        let base = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(0.1, 0.0, 0.0),
            Vector3::new(0.0, 0.1, 0.0),
        ];
        let r = 0.003;
        let pairs = |p0: Vector3<f64>, p1: Vector3<f64>, tri_move: Vector3<f64>| {
            let mut x0 = base.to_vec();
            x0.push(p0);
            let mut x1: Vec<Vector3<f64>> = base.iter().map(|p| p + tri_move).collect();
            x1.push(p1);
            let mut det = CollisionDetector::new();
            det.find_swept_self_pairs(&x0, &x1, &tri, &[], r)
        };
        let still = Vector3::zeros();
        let through = pairs(
            Vector3::new(0.02, 0.02, 0.05),
            Vector3::new(0.02, 0.02, -0.05),
            still,
        );
        assert_eq!(through.len(), 1, "{through:?}");
        assert!(matches!(through[0], Contact::VertexTriangle { v: 3, .. }));
        let alongside = pairs(
            Vector3::new(0.02, 0.02, 0.05),
            Vector3::new(0.07, 0.02, 0.05),
            still,
        );
        assert!(alongside.is_empty(), "{alongside:?}");
        let past = pairs(
            Vector3::new(0.2, 0.2, 0.05),
            Vector3::new(0.2, 0.2, -0.05),
            still,
        );
        assert!(past.is_empty(), "{past:?}");
        let together = pairs(
            Vector3::new(0.02, 0.02, 0.05),
            Vector3::new(0.02, 0.02, -0.05),
            Vector3::new(0.0, 0.0, -0.1),
        );
        assert!(together.is_empty(), "{together:?}");
    }

    /// `push_out` against the cube [−0.1, 0.1]³ with 0.5 mm clearance: a point 2 mm under the
    /// top goes to 0.5 mm over it straight up; one 0.1 mm over the top goes to 0.5 mm; one
    /// 5 mm over stays; one 0.5 mm inside the side x+ goes out through the side; one equally
    /// near the top and the side (the medial axis) goes out along their pseudo-normal, then
    /// straight up to the clearance; one at a corner ends at the clearance from the corner;
    /// one at the cube's centre, 100 mm deep, is beyond the search and stays.
    #[test]
    fn push_out_moves_points_out_of_a_body_to_the_clearance() {
        let (pts, tris) = crate::collide::tests::cube();
        let c = 5e-4;
        // Distance from a point outside the cube to it (0 inside).
        let gap = |p: &Vector3<f64>| p.map(|v| (v.abs() - 0.1).max(0.0)).norm();
        let mut x = vec![
            Vector3::new(0.03, 0.098, -0.02),
            Vector3::new(0.03, 0.1001, -0.02),
            Vector3::new(0.03, 0.105, -0.02),
            Vector3::new(0.0995, 0.09, 0.04),
            Vector3::new(0.099, 0.099, 0.04),
            Vector3::new(0.099, 0.099, 0.099),
            Vector3::zeros(),
        ];
        let before = x.clone();
        let r = push_out(&mut x, &[(&pts, &tris)], c);
        assert_eq!((r.inside, r.moved), (4, 5), "{r:?}");
        assert!((r.max_depth_m - 2e-3).abs() < 1e-12, "{r:?}");
        let near = |a: &Vector3<f64>, b: Vector3<f64>| (a - b).norm() < 1e-12;
        assert!(
            near(&x[0], Vector3::new(0.03, 0.1 + c, -0.02)),
            "{:?}",
            x[0]
        );
        assert!(
            near(&x[1], Vector3::new(0.03, 0.1 + c, -0.02)),
            "{:?}",
            x[1]
        );
        assert_eq!(x[2], before[2]);
        assert!(near(&x[3], Vector3::new(0.1 + c, 0.09, 0.04)), "{:?}", x[3]);
        let s = c / 2f64.sqrt();
        let medial = [
            Vector3::new(0.099 + s, 0.1 + c, 0.04),
            Vector3::new(0.1 + c, 0.099 + s, 0.04),
        ];
        assert!(medial.iter().any(|m| near(&x[4], *m)), "{:?}", x[4]);
        assert!((gap(&x[5]) - c).abs() < 1e-12, "{:?}", x[5]);
        assert_eq!(x[6], before[6]);
        // An open body (the cube's top face alone, a floor) has its inside below it, however
        // far the box of its points: a point 2 mm under it goes up; the closed cube is closed.
        assert!(is_closed(&tris) && !is_closed(&tris[6..8]));
        let mut under = [Vector3::new(0.03, 0.098, -0.02)];
        let floor = push_out(&mut under, &[(&pts, &tris[6..8])], c);
        assert_eq!((floor.inside, floor.moved), (1, 1), "{floor:?}");
        assert!(
            near(&under[0], Vector3::new(0.03, 0.1 + c, -0.02)),
            "{:?}",
            under[0]
        );
        // Counted without moving: the same points inside, the same depth.
        let counted = count_inside(&before, &[(&pts, &tris)], OBSTACLE_SEARCH_M);
        assert_eq!(
            (counted.inside, counted.max_depth_m),
            (r.inside, r.max_depth_m)
        );
        // Pushed out, every point is outside: a second pass finds nothing to move.
        let again = push_out(&mut x, &[(&pts, &tris)], c);
        assert_eq!((again.inside, again.moved), (0, 0), "{again:?}");
        // An empty collider list, or a collider with no triangles, moves nothing.
        let mut y = before.clone();
        assert_eq!(push_out(&mut y, &[], c), PushOut::default());
        assert_eq!(push_out(&mut y, &[(&pts, &[])], c), PushOut::default());
        assert_eq!(y, before);
    }

    /// An L-shaped prism: its inner corner is a reflex edge, where the outside is a quarter
    /// wedge. Points inside near that edge go out from one face, into the other's slab, and
    /// must still end outside both, at the clearance.
    #[test]
    fn push_out_clears_the_inside_corner_of_a_concave_body() {
        let l = [
            (0.0, 0.0),
            (2.0, 0.0),
            (2.0, 1.0),
            (1.0, 1.0),
            (1.0, 2.0),
            (0.0, 2.0),
        ];
        let (s, h) = (0.1, 0.1);
        let mut pts: Vec<Vector3<f64>> = l
            .iter()
            .map(|&(x, y)| Vector3::new(x * s, y * s, 0.0))
            .collect();
        pts.extend(l.iter().map(|&(x, y)| Vector3::new(x * s, y * s, h)));
        let cap = [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]];
        let mut tris: Vec<[u32; 3]> = cap.iter().map(|t| [t[0], t[2], t[1]]).collect();
        tris.extend(cap.iter().map(|t| t.map(|v| v + 6)));
        for i in 0..6u32 {
            let j = (i + 1) % 6;
            tris.push([i, j, j + 6]);
            tris.push([i, j + 6, i + 6]);
        }
        assert!(is_closed(&tris));
        let c = 1e-3;
        let mut x = Vec::new();
        for a in -6..=6 {
            for b in -6..=6 {
                let (u, v) = (a as f64 * 5e-4, b as f64 * 5e-4);
                if u < 0.0 || v < 0.0 {
                    x.push(Vector3::new(s + u, s + v, 0.5 * h));
                }
            }
        }
        let r = push_out(&mut x, &[(&pts, &tris)], c);
        assert_eq!(r.inside, x.len(), "{r:?}");
        let left = count_inside(&x, &[(&pts, &tris)], 0.05);
        assert_eq!(
            left.inside,
            0,
            "{} points left inside, {:.3} mm deep",
            left.inside,
            left.max_depth_m * 1e3
        );
        for p in &x {
            // Outside the L near its inner corner means x ≥ s and y ≥ s.
            assert!(
                p.x >= s + c * (1.0 - 1e-6) && p.y >= s + c * (1.0 - 1e-6),
                "{p:?}"
            );
        }
    }
}
