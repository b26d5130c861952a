//! Creases: collider edges sharp enough for cloth edges to catch on.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::body::tri_points;
use super::bvh::Aabb;

/// Collider edges whose two faces meet at more than this angle (degrees) get edge contacts,
/// and no face at more than this angle to the one an inside vertex came in through pushes
/// it out ([`CollisionDetector::find_contacts_since`]).
pub const SHARP_EDGE_DEG: f64 = 30.0;

/// Edges of a triangle mesh whose adjacent face normals differ by more than `angle_deg`, plus
/// boundary edges: the creases a cloth edge can catch on between its vertices.
pub fn sharp_edges(pts: &[Vector3<f64>], tris: &[[u32; 3]], angle_deg: f64) -> Vec<[u32; 2]> {
    sharp_edges_of(pts, tris, &edge_faces(tris), angle_deg)
}

/// Every edge of a triangle mesh (sorted vertex pair, sorted list) with its first two adjacent
/// faces; `u32::MAX` stands for a missing face (boundary edge). Non-manifold edges keep two.
pub(super) fn edge_faces(tris: &[[u32; 3]]) -> Vec<([u32; 2], [u32; 2])> {
    let mut half: Vec<([u32; 2], u32)> = tris
        .iter()
        .enumerate()
        .flat_map(|(k, t)| {
            [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]]
                .map(|e| ([e[0].min(e[1]), e[0].max(e[1])], k as u32))
        })
        .collect();
    half.sort_unstable();
    let mut out: Vec<([u32; 2], [u32; 2])> = Vec::with_capacity(half.len() / 2 + 1);
    for (e, k) in half {
        match out.last_mut() {
            Some((last, f)) if *last == e => {
                if f[1] == u32::MAX {
                    f[1] = k;
                } else {
                    // Three or more faces: a non-manifold edge is always a crease.
                    f[1] = u32::MAX - 1;
                }
            }
            _ => out.push((e, [k, u32::MAX])),
        }
    }
    out
}

/// [`sharp_edges`] from a precomputed [`edge_faces`] table.
pub(super) fn sharp_edges_of(
    pts: &[Vector3<f64>],
    tris: &[[u32; 3]],
    faces: &[([u32; 2], [u32; 2])],
    angle_deg: f64,
) -> Vec<[u32; 2]> {
    let cos_max = angle_deg.to_radians().cos();
    let normal = |t: u32| {
        let [a, b, c] = tri_points(pts, &tris[t as usize]);
        (b - a).cross(&(c - a)).try_normalize(1e-30)
    };
    faces
        .iter()
        .filter(|(_, f)| {
            if f[1] >= u32::MAX - 1 {
                return true;
            }
            match (normal(f[0]), normal(f[1])) {
                (Some(n1), Some(n2)) => n1.dot(&n2) < cos_max,
                _ => false,
            }
        })
        .map(|(e, _)| *e)
        .collect()
}

/// The two faces of a sharp edge, for telling a cloth edge that has crossed it from one that
/// is still outside: each face's outward unit normal with a point of its plane, and whether the
/// crease is convex (a table's edge) rather than concave (an armpit). `None` for a boundary or
/// non-manifold edge, or one with a degenerate face: those always repel.
#[derive(Debug, Clone, Copy)]
pub(super) struct CreasePlanes {
    planes: [(Vector3<f64>, Vector3<f64>); 2],
    convex: bool,
}

impl CreasePlanes {
    /// Whether point `c` lies inside the body at this crease: behind both faces' planes of a
    /// convex crease, or behind either of a concave one.
    pub(super) fn behind(&self, c: &Vector3<f64>) -> bool {
        let [b1, b2] = self.planes.map(|(n, q)| n.dot(&(c - q)) < 0.0);
        if self.convex {
            b1 && b2
        } else {
            b1 || b2
        }
    }
}

/// [`CreasePlanes`] of each of `sharp` (edges of `faces`, the table of [`edge_faces`]).
pub(super) fn crease_planes(
    pts: &[Vector3<f64>],
    tris: &[[u32; 3]],
    faces: &[([u32; 2], [u32; 2])],
    sharp: &[[u32; 2]],
) -> Vec<Option<CreasePlanes>> {
    let plane = |t: u32| {
        let [a, b, c] = tri_points(pts, &tris[t as usize]);
        (b - a).cross(&(c - a)).try_normalize(1e-30).map(|n| (n, a))
    };
    let centroid = |t: u32| {
        let [a, b, c] = tri_points(pts, &tris[t as usize]);
        (a + b + c) / 3.0
    };
    sharp
        .iter()
        .map(|e| {
            let k = faces.binary_search_by(|(f, _)| f.cmp(e)).ok()?;
            let f = faces[k].1;
            if f[1] >= u32::MAX - 1 {
                return None;
            }
            let (p1, p2) = (plane(f[0])?, plane(f[1])?);
            // Convex where the second face lies behind the first's plane, or in it facing the
            // other way (a fin: a zero-thickness plate's edge, the sharpest convex crease).
            let convex = p1.0.dot(&(centroid(f[1]) - p1.1)) <= 0.0;
            Some(CreasePlanes {
                planes: [p1, p2],
                convex,
            })
        })
        .collect()
}

/// Boxes of edges, inflated by `r`.
pub(super) fn edge_boxes(pts: &[Vector3<f64>], edges: &[[u32; 2]], r: f64) -> Vec<Aabb> {
    edges
        .par_iter()
        .map(|e| Aabb::from_points(e.iter().map(|&i| &pts[i as usize])).inflate(r))
        .collect()
}

#[cfg(test)]
mod edge_obstacle_tests {
    use super::*;
    use crate::collide::*;

    #[test]
    fn a_box_edge_between_cloth_vertices_is_a_contact() {
        // A unit cube's top edge along x at (y, z) = (1, 1); a cloth edge crossing it 1 mm above,
        // with both cloth vertices far from every face (so no vertex contact can see it).
        let cube = clothsr_geometry::scene::Collider::cuboid(
            "cube",
            Vector3::zeros(),
            Vector3::repeat(1.0),
        );
        let pts: Vec<Vector3<f64>> = cube.frames[0].iter().map(|p| p.cast::<f64>()).collect();
        let tris = cube.triangles;
        let sharp = sharp_edges(&pts, &tris, SHARP_EDGE_DEG);
        assert_eq!(
            sharp.len(),
            12,
            "a cube has 12 creases, its face diagonals are flat"
        );
        let x = [Vector3::new(0.5, 1.3, 0.7), Vector3::new(0.5, 0.7, 1.3)];
        let lifted: Vec<Vector3<f64>> = x
            .iter()
            .map(|p| p + Vector3::new(0.0, 0.001, 0.001) / 2f64.sqrt())
            .collect();
        let params = CollisionParams {
            dhat_m: 0.003,
            kappa: 1000.0,
            self_collision: false,
        };
        let contacts = find_contacts(&lifted, &[], &[[0, 1]], &[(&pts, &tris)], &params);
        let edge: Vec<&Contact> = contacts
            .iter()
            .filter(|c| matches!(c, Contact::EdgeObstacle { .. }))
            .collect();
        assert_eq!(edge.len(), 1, "{contacts:?}");
        let d = edge[0].distance(&lifted);
        assert!((d - 0.001).abs() < 1e-9, "distance {d}");
        // Its force pushes the cloth edge away from the crease (outwards along (0, 1, 1)).
        let (_, g, _) = edge[0].energy_gradient_hessian(&lifted, &params);
        let push = -(g.fixed_rows::<3>(0) + g.fixed_rows::<3>(3));
        assert!(push.dot(&Vector3::new(0.0, 1.0, 1.0)) > 0.0);
        // Far away: no contact.
        let far: Vec<Vector3<f64>> = x.iter().map(|p| p + Vector3::new(0.0, 0.1, 0.1)).collect();
        assert!(find_contacts(&far, &[], &[[0, 1]], &[(&pts, &tris)], &params).is_empty());
        // It names the collider and the crease's two points (where friction reads its motion).
        let Contact::EdgeObstacle {
            edge: ends_at,
            ends,
            ..
        } = edge[0]
        else {
            unreachable!()
        };
        assert_eq!(ends[0], 0);
        assert_eq!(
            [pts[ends[1] as usize], pts[ends[2] as usize]],
            *ends_at,
            "the contact's points are the collider's"
        );
        // The same edge 1 mm inside the cube has crossed the crease: one-sided, it is left to
        // the vertices' contacts instead of being held there from inside …
        let sunk: Vec<Vector3<f64>> = x
            .iter()
            .map(|p| p - Vector3::new(0.0, 0.001, 0.001) / 2f64.sqrt())
            .collect();
        let inside = find_contacts(&sunk, &[], &[[0, 1]], &[(&pts, &tris)], &params);
        assert!(inside.is_empty(), "{inside:?}");
        // … but an edge whose closest point is behind one face's plane only (above the top,
        // 0.5 mm short of the back face's plane) is still outside and is held off the crease.
        let over = [
            Vector3::new(0.5, 1.3, 0.9995),
            Vector3::new(0.5, 1.0005, 0.9995),
        ];
        let c = find_contacts(&over, &[], &[[0, 1]], &[(&pts, &tris)], &params);
        let creases = c
            .iter()
            .filter(|c| matches!(c, Contact::EdgeObstacle { .. }));
        assert_eq!(creases.count(), 1, "{c:?}");
        // With crease contacts off the edge may cut the crease: nothing is reported.
        let mut det = CollisionDetector::new();
        det.crease_contacts = false;
        let off = det.find_contacts(&lifted, &[], &[[0, 1]], &[(&pts, &tris)], &params);
        assert!(off.is_empty(), "{off:?}");
    }

    /// Inside a box seen from within (its faces turned inwards, as a room's walls), the same
    /// edges are concave creases: a cloth edge in the room's corner is held off it, one that
    /// has gone into either wall has crossed.
    #[test]
    fn a_concave_crease_holds_edges_in_the_corner_and_lets_crossed_ones_go() {
        let cube = clothsr_geometry::scene::Collider::cuboid(
            "room",
            Vector3::zeros(),
            Vector3::repeat(1.0),
        );
        let pts: Vec<Vector3<f64>> = cube.frames[0].iter().map(|p| p.cast::<f64>()).collect();
        let tris: Vec<[u32; 3]> = cube.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect();
        let planes = {
            let faces = edge_faces(&tris);
            let sharp = sharp_edges_of(&pts, &tris, &faces, SHARP_EDGE_DEG);
            crease_planes(&pts, &tris, &faces, &sharp)
        };
        assert_eq!(planes.len(), 12);
        assert!(planes.iter().all(|p| p.is_some_and(|p| !p.convex)));
        let params = CollisionParams {
            dhat_m: 0.003,
            kappa: 1000.0,
            self_collision: false,
        };
        // The top-back edge (y = z = 1); a cloth edge across it, 1 mm into the room's corner.
        let x = [Vector3::new(0.5, 0.7, 1.3), Vector3::new(0.5, 1.3, 0.7)];
        let at = |off: Vector3<f64>| -> Vec<Vector3<f64>> { x.iter().map(|p| p + off).collect() };
        let count = |x: &[Vector3<f64>]| {
            find_contacts(x, &[], &[[0, 1]], &[(&pts, &tris)], &params)
                .iter()
                .filter(|c| matches!(c, Contact::EdgeObstacle { .. }))
                .count()
        };
        let corner = at(-Vector3::new(0.0, 0.001, 0.001) / 2f64.sqrt());
        assert_eq!(count(&corner), 1);
        // A fin (two triangles back to back in one plane, as a zero-thickness plate's edge)
        // is convex: a cloth edge passing just off its edge, its closest point a hair to one
        // side of the plane, is held off it.
        let fin_pts = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.5, 1.0, 0.0),
            Vector3::new(0.6, 1.0, 0.0),
        ];
        let fin_tris = [[0, 1, 2], [1, 0, 3]];
        let faces = edge_faces(&fin_tris);
        let sharp = sharp_edges_of(&fin_pts, &fin_tris, &faces, SHARP_EDGE_DEG);
        let fin = crease_planes(&fin_pts, &fin_tris, &faces, &[[0, 1]]);
        assert!(sharp.contains(&[0, 1]));
        assert!(fin[0].is_some_and(|p| p.convex));
        let past = [
            Vector3::new(0.5, -0.001, -0.3),
            Vector3::new(0.5, -0.002, 0.3),
        ];
        let c = find_contacts(&past, &[], &[[0, 1]], &[(&fin_pts, &fin_tris)], &params);
        let creases = c
            .iter()
            .filter(|c| matches!(c, Contact::EdgeObstacle { .. }));
        assert_eq!(creases.count(), 1, "{c:?}");
        // An edge gone into the top wall (its end 0.5 mm above y = 1, in front of the back
        // wall's plane): crossed.
        let wall = [
            Vector3::new(0.5, 1.0005, 0.7),
            Vector3::new(0.5, 1.0005, 0.9995),
        ];
        assert_eq!(count(&wall), 0);
        // The same edge 0.5 mm below the top wall is in the room: held off the crease.
        assert_eq!(
            count(&[
                wall[0] - Vector3::new(0.0, 0.001, 0.0),
                wall[1] - Vector3::new(0.0, 0.001, 0.0)
            ]),
            1
        );
    }
}
