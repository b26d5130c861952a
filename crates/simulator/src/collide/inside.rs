//! Cloth inside bodies: pushing it out, counting it and measuring how deep it is.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::body::{classify_vertex, nearest_side, tri_points};
use super::bvh::{Aabb, Bvh};
use super::contact::Collider;
use super::crossings::triangle_boxes;
use super::distance::point_triangle;
use super::repulsion::{obstacle_eval_with, ObstacleEval};
use super::OBSTACLE_SEARCH_M;

/// What [`push_out`] did to a point set.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PushOut {
    /// Points that were inside a collider.
    pub inside: usize,
    /// Points moved: those inside, and those outside but nearer a collider than the clearance.
    pub moved: usize,
    /// How deep the deepest point was inside a collider, m (0 when none was).
    pub max_depth_m: f64,
    /// Of the points inside, those where a closed collider overlaps itself: inside two of its
    /// parts at once (winding number two or more, [`winding_number`]), as where a skinned
    /// body's thighs pass into each other. No place outside the body is near such a point.
    pub in_overlap: usize,
}

/// Moves every point of `x` that lies inside a collider, or outside it but nearer than
/// `clearance_m`, to `clearance_m` outside the collider's surface: from the closest surface
/// point along the angle-weighted pseudo-normal there for a point inside (the sign test of the
/// module docs), straight away from the surface for one outside. For meshes that no solver held
/// off the bodies, such as the MSR module's fine output: the network places fine vertices
/// from the coarse mesh's surface, and where that mesh wraps a body its chords and the
/// network's wrinkles cut into it. Points deeper than [`OBSTACLE_SEARCH_M`] are not found.
/// Colliders are taken in turn; a point pushed out of one into another (a gap narrower than
/// the clearance) ends outside the last. The counts are those of the first move.
pub fn push_out(x: &mut [Vector3<f64>], colliders: &[Collider<'_>], clearance_m: f64) -> PushOut {
    let mut total = PushOut::default();
    for (pts, tris) in colliders {
        let Some(solid) = Solid::new(pts, tris, clearance_m, OBSTACLE_SEARCH_M) else {
            continue;
        };
        let r = x
            .par_iter_mut()
            .map_init(Vec::new, |cands, p| {
                let Some((to, depth)) = solid.push(p, cands) else {
                    return PushOut::default();
                };
                let overlap = depth.is_some() && solid.in_overlap(p);
                *p = to;
                // A point on the medial axis (equally near two faces) goes out from the
                // closest point of one along their pseudo-normal and may end nearer the
                // other than the clearance, which the next move fixes.
                for _ in 0..3 {
                    match solid.push(p, cands) {
                        Some((to, _)) => *p = to,
                        None => break,
                    }
                }
                PushOut::of(depth, overlap)
            })
            .reduce(PushOut::default, |a, b| a + b);
        total = total + r;
    }
    total
}

/// How many points of `x` lie inside a collider (up to `search_m` deep), and the deepest:
/// [`push_out`]'s `inside` and `max_depth_m`, moving nothing.
pub fn count_inside(x: &[Vector3<f64>], colliders: &[Collider<'_>], search_m: f64) -> PushOut {
    let mut total = PushOut::default();
    for (pts, tris) in colliders {
        let Some(solid) = Solid::new(pts, tris, 0.0, search_m) else {
            continue;
        };
        let r = x
            .par_iter()
            .map_init(Vec::new, |cands, p| {
                solid
                    .push(p, cands)
                    .map_or_else(PushOut::default, |(_, depth)| {
                        PushOut::of(depth, depth.is_some() && solid.in_overlap(p))
                    })
            })
            .reduce(PushOut::default, |a, b| a + b);
        total = total + r;
    }
    total
}

impl PushOut {
    /// One point moved, from `depth` inside (`None`: it was outside, nearer than the
    /// clearance), `overlap`: where the collider overlaps itself.
    fn of(depth: Option<f64>, overlap: bool) -> PushOut {
        PushOut {
            inside: usize::from(depth.is_some()),
            moved: 1,
            max_depth_m: depth.unwrap_or(0.0),
            in_overlap: usize::from(overlap),
        }
    }
}

impl std::ops::Add for PushOut {
    type Output = PushOut;

    /// Both counts together (two frames', or two colliders').
    fn add(self, o: PushOut) -> PushOut {
        PushOut {
            inside: self.inside + o.inside,
            moved: self.moved + o.moved,
            max_depth_m: self.max_depth_m.max(o.max_depth_m),
            in_overlap: self.in_overlap + o.in_overlap,
        }
    }
}

/// A collider prepared for [`push_out`] and [`count_inside`].
pub(super) struct Solid<'a> {
    pts: &'a [Vector3<f64>],
    tris: &'a [[u32; 3]],
    bvh: Bvh,
    /// Only a point in here can be inside the body or nearer than the clearance.
    reach: Aabb,
    /// Whether every edge is shared by two triangles (a winding number is defined).
    closed: bool,
    clearance_m: f64,
    search_m: f64,
}

impl<'a> Solid<'a> {
    /// `None` for a collider without triangles.
    fn new(
        pts: &'a [Vector3<f64>],
        tris: &'a [[u32; 3]],
        clearance_m: f64,
        search_m: f64,
    ) -> Option<Solid<'a>> {
        if tris.is_empty() {
            return None;
        }
        // A closed body's points' box grown by the clearance holds every point inside or
        // near it; an open one (a floor, a wall) has an inside as deep as the search behind.
        let closed = is_closed(tris);
        let grow = if closed {
            clearance_m
        } else {
            clearance_m.max(search_m)
        };
        Some(Solid {
            pts,
            tris,
            bvh: Bvh::build(&triangle_boxes(pts, tris, 0.0)),
            reach: Aabb::from_points(pts.iter()).inflate(grow),
            closed,
            clearance_m,
            search_m,
        })
    }

    /// Where point `at` goes, and how deep it was inside (`None`: outside): to the clearance
    /// from the closest surface point, along the pseudo-normal there from inside, straight
    /// away from the surface from outside. `None` for a point outside at least the clearance
    /// away, or with no face within the search. `cands` is scratch space.
    fn push(
        &self,
        at: &Vector3<f64>,
        cands: &mut Vec<(u32, ObstacleEval)>,
    ) -> Option<(Vector3<f64>, Option<f64>)> {
        if self.reach.distance_sq(at) > 0.0 {
            return None;
        }
        let tri = |t: u32| tri_points(self.pts, &self.tris[t as usize]);
        let (_, umin) = self.bvh.nearest(at, self.search_m, |t| {
            let [a, b, c] = tri(t);
            point_triangle(at, &a, &b, &c).dist
        })?;
        cands.clear();
        let tie = 1e-12 + 1e-9 * umin;
        self.bvh.query_ball(at, umin + tie, |t| {
            let [a, b, c] = tri(t);
            let closest = point_triangle(at, &a, &b, &c);
            cands.push((t, obstacle_eval_with(at, &a, &b, &c, closest)));
        });
        let (q, pseudo) = nearest_side(self.pts, self.tris, cands, umin)?;
        let away = at - q;
        let inside = umin > 0.0 && away.dot(&pseudo) < 0.0;
        if !inside && umin >= self.clearance_m * (1.0 - 1e-9) {
            return None;
        }
        let dir = if inside || umin <= 1e-12 {
            pseudo.try_normalize(1e-12)?
        } else {
            away / umin
        };
        Some((q + dir * self.clearance_m, inside.then_some(umin)))
    }

    /// Whether `at` lies where the collider overlaps itself (winding number two or more);
    /// false for an open collider.
    fn in_overlap(&self, at: &Vector3<f64>) -> bool {
        self.closed && winding_number(self.pts, self.tris, &self.bvh, at) >= 2
    }
}

/// The winding number of the closed surface `tris` (counter-clockwise seen from outside) about
/// `at`: 0 outside, 1 inside, 2 inside two parts that pass into each other, and so on. Counted
/// along rays from `at` in +x, +y and +z as the faces they leave through less those they enter
/// through; the median of the three, so that one ray grazing an edge or a vertex (where the
/// count is undefined) does not decide. `bvh` holds the faces' boxes.
fn winding_number(pts: &[Vector3<f64>], tris: &[[u32; 3]], bvh: &Bvh, at: &Vector3<f64>) -> i32 {
    let top = bvh.root_aabb().max;
    let mut w = [0i32; 3];
    for (k, wk) in w.iter_mut().enumerate() {
        // The ray's axis k and the plane across it (i, j), cyclic so that the face normal's
        // k-component is the projected triangle's signed area.
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        let mut ray = Aabb::from_point(at);
        ray.max[k] = ray.max[k].max(top[k]);
        bvh.query(&ray, |t| {
            let [a, b, c] = tri_points(pts, &tris[t as usize]);
            let orient = |p: &Vector3<f64>, q: &Vector3<f64>| {
                (p[i] - at[i]) * (q[j] - at[j]) - (p[j] - at[j]) * (q[i] - at[i])
            };
            let (wa, wb, wc) = (orient(&b, &c), orient(&c, &a), orient(&a, &b));
            let area = wa + wb + wc;
            let inside = (wa > 0.0 && wb > 0.0 && wc > 0.0) || (wa < 0.0 && wb < 0.0 && wc < 0.0);
            if !inside {
                return;
            }
            let hit = (wa * a[k] + wb * b[k] + wc * c[k]) / area;
            if hit > at[k] {
                *wk += if area > 0.0 { 1 } else { -1 };
            }
        });
    }
    w.sort_unstable();
    w[1]
}

/// Whether every edge of `tris` is shared by exactly two of them (a closed surface).
pub(super) fn is_closed(tris: &[[u32; 3]]) -> bool {
    let mut edges: Vec<(u32, u32)> = tris
        .iter()
        .flat_map(|t| (0..3).map(move |k| (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]))))
        .collect();
    edges.sort_unstable();
    edges.chunk_by(|a, b| a == b).all(|run| run.len() == 2)
}

/// The deepest penetration (metres, ≥ 0) of any cloth vertex into any collider: the distance to
/// the nearest collider face for vertices classified inside (see the module docs), searched up
/// to [`OBSTACLE_SEARCH_M`]; 0 when none is inside. A progress metric.
pub fn max_penetration(cloth_x: &[Vector3<f64>], colliders: &[Collider<'_>]) -> f64 {
    let bvhs: Vec<Bvh> = colliders
        .iter()
        .map(|(pts, tris)| Bvh::build(&triangle_boxes(pts, tris, 0.0)))
        .collect();
    cloth_x
        .par_iter()
        .map_init(Vec::new, |scratch, p| {
            bvhs.iter()
                .zip(colliders)
                .map(|(bvh, (pts, tris))| {
                    classify_vertex(
                        p,
                        None,
                        pts,
                        tris,
                        bvh,
                        0.0,
                        OBSTACLE_SEARCH_M,
                        scratch,
                        |_| {},
                    )
                    .0
                })
                .fold(0.0, f64::max)
        })
        .reduce(|| 0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two cubes [−0.1, 0.1]³, the second moved by `shift`, as one closed surface that passes
    /// into itself (as a skinned body's thighs do).
    fn two_cubes(shift: Vector3<f64>) -> (Vec<Vector3<f64>>, Vec<[u32; 3]>) {
        let (mut pts, mut tris) = crate::collide::tests::cube();
        let n = pts.len() as u32;
        let moved: Vec<Vector3<f64>> = pts.iter().map(|p| p + shift).collect();
        let second: Vec<[u32; 3]> = tris.iter().map(|t| t.map(|v| v + n)).collect();
        pts.extend(moved);
        tris.extend(second);
        (pts, tris)
    }

    /// The winding number about points spread over both cubes and around them is the number
    /// of cubes each lies in; and counting cloth inside tells the points where the body
    /// overlaps itself from those inside one part only.
    #[test]
    fn the_winding_number_counts_the_parts_of_a_body_a_point_is_in() {
        let shift = Vector3::new(0.15, 0.02, 0.03);
        let (pts, tris) = two_cubes(shift);
        assert!(is_closed(&tris));
        let bvh = Bvh::build(&triangle_boxes(&pts, &tris, 0.0));
        let in_cube = |p: Vector3<f64>| usize::from(p.iter().all(|v| v.abs() < 0.1));
        // A lattice with irrational-looking steps, so that no ray runs along a face's edge.
        let mut seen = [0usize; 3];
        for a in 0..17 {
            for b in 0..13 {
                for c in 0..11 {
                    let p = Vector3::new(
                        -0.13 + a as f64 * 0.02617,
                        -0.12 + b as f64 * 0.02131,
                        -0.11 + c as f64 * 0.02293,
                    );
                    let want = in_cube(p) + in_cube(p - shift);
                    assert_eq!(winding_number(&pts, &tris, &bvh, &p), want as i32, "{p:?}");
                    seen[want] += 1;
                }
            }
        }
        assert!(seen.iter().all(|&n| n > 100), "{seen:?}");
        // A ray along the edge two faces share (where its count is undefined) is outvoted:
        // inside the first cube only, the +x ray of a point with y = z runs along the x+
        // face's diagonal, the +y ray of one with x = z along the y+ face's.
        for p in [
            Vector3::new(-0.05, 0.01, 0.01),
            Vector3::new(-0.03, 0.01, -0.03),
        ] {
            assert_eq!(winding_number(&pts, &tris, &bvh, &p), 1, "{p:?}");
        }
        // Both under the first cube's top face, 3–5 mm deep: one also inside the second cube.
        let x = [
            Vector3::new(0.09, 0.095, 0.05),
            Vector3::new(-0.05, 0.097, 0.01),
        ];
        let r = count_inside(&x, &[(&pts, &tris)], OBSTACLE_SEARCH_M);
        assert_eq!((r.inside, r.in_overlap), (2, 1), "{r:?}");
        let mut moved = x;
        let pushed = push_out(&mut moved, &[(&pts, &tris)], 1e-3);
        assert_eq!((pushed.inside, pushed.in_overlap), (2, 1), "{pushed:?}");
        // An open surface (the first cube without its top) has no winding number.
        let open = &tris[..6];
        let r = count_inside(&x, &[(&pts, open)], OBSTACLE_SEARCH_M);
        assert_eq!(r.in_overlap, 0, "{r:?}");
    }
}
