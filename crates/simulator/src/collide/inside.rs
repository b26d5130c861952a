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
                PushOut::of(depth)
            })
            .reduce(PushOut::default, PushOut::add);
        total = total.add(r);
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
                    .map_or_else(PushOut::default, |(_, depth)| PushOut::of(depth))
            })
            .reduce(PushOut::default, PushOut::add);
        total = total.add(r);
    }
    total
}

impl PushOut {
    /// One point moved, from `depth` inside (`None`: it was outside, nearer than the
    /// clearance).
    fn of(depth: Option<f64>) -> PushOut {
        PushOut {
            inside: usize::from(depth.is_some()),
            moved: 1,
            max_depth_m: depth.unwrap_or(0.0),
        }
    }

    /// Both counts together.
    fn add(self, o: PushOut) -> PushOut {
        PushOut {
            inside: self.inside + o.inside,
            moved: self.moved + o.moved,
            max_depth_m: self.max_depth_m.max(o.max_depth_m),
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
        let grow = if is_closed(tris) {
            clearance_m
        } else {
            clearance_m.max(search_m)
        };
        Some(Solid {
            pts,
            tris,
            bvh: Bvh::build(&triangle_boxes(pts, tris, 0.0)),
            reach: Aabb::from_points(pts.iter()).inflate(grow),
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
