//! Collision detection and quadratic repulsion (the paper's §4.4.4: "BVH collision detection
//! with quadratic repulsion (body and self)").
//!
//! * [`bvh`]: axis-aligned boxes and a linear BVH (Karras 2012) with refit, box, nearest and pair
//!   queries;
//! * [`distance`]: exact point–triangle and segment–segment closest points (Ericson 2005);
//! * [`repulsion`]: E = ½ κ (d̂ − d)² for d < d̂ with exact distance derivatives per
//!   closest-feature case and a Gauss-Newton (PSD) Hessian;
//! * this module: the [`Contact`] set the solver consumes and its detection
//!   ([`find_contacts`], [`CollisionDetector`]).
//!
//! # Contacts
//!
//! * **Obstacles** (cloth vertex against collider faces, counter-clockwise seen from outside):
//!   each cloth vertex is first classified inside/outside a collider like a signed distance
//!   field: the nearest collider face is found among the faces within d̂ (a BVH ball query)
//!   or, when there is none, by a BVH branch-and-bound nearest query up to
//!   [`OBSTACLE_SEARCH_M`]; the sign of (p − q)·N at the closest point q uses the
//!   angle-weighted pseudo-normal N of the faces that tie for nearest (Bærentzen & Aanæs,
//!   "Signed distance computation using the angle weighted pseudonormal", IEEE TVCG 2005), so the
//!   sign is right at edges and vertices too. An *outside* vertex gets a contact with every face
//!   within d̂ whose plane it is above (n·(p − a) ≥ 0). An *inside* vertex (penetration depth
//!   δ = distance to the nearest face) gets a contact with every face within δ + d̂ that it
//!   projects into and is below: the signed distance is then negative and the repulsion pushes
//!   it out along +n. Near a sharp edge those faces can be the wrong ones: a vertex that came
//!   in through a table's top within a step's travel of its edge is near the side too, or
//!   nearer it. When the detector knows where the vertex began the step and the collider held
//!   still ([`CollisionDetector::find_contacts_since`]), the last face its path from there
//!   went in through (the entry face) decides: faces at more than [`SHARP_EDGE_DEG`] to it get
//!   no contact, and when the nearest face is one of those, depth and reach are measured from
//!   the entry face's plane, so the vertex goes back out the way it came (if no face in line
//!   with the entry lies over it, the rule above holds). Where every face within reach lies
//!   within that angle of the entry face (a finely tessellated smooth body) nothing changes;
//!   against a moving body the rule above holds, as the path would have to be taken in the
//!   body's frame. Vertices deeper than [`OBSTACLE_SEARCH_M`] are not found (and not pushed).
//!   Only cloth vertices are tested against collider faces (no collider-vertex/edge against
//!   cloth face/edge contacts).
//! * **Creases** (cloth edge against a collider's sharp edge, faces at more than
//!   [`SHARP_EDGE_DEG`]; [`CollisionDetector::crease_contacts`]): an edge closer than d̂ to a
//!   crease, so a box's edge cannot slice between two cloth vertices. One-sided like the
//!   vertex contacts: an edge whose closest point to the crease lies behind both faces of a
//!   convex crease (or either face of a concave one) has crossed it and gets no contact, as
//!   the unsigned distance would otherwise hold it there from inside. The side is judged at
//!   the positions detected, not along the step: an edge the solver's first guess carries past
//!   a crease is released, not pushed back (vertices have the entry-face rule for that). The
//!   simulator gives these contacts friction (a sheet grips the edge it wraps over).
//! * **Self** (cloth against cloth, unsigned distance): vertex–triangle pairs (vertex not in the
//!   triangle) and edge–edge pairs (no shared vertex) closer than d̂, found with a BVH over the
//!   triangles inflated by d̂ (point queries) and a BVH over the edges inflated by d̂/2 (self
//!   pairs). d̂ must stay well below the cloth's edge lengths: elements of the same flat patch that
//!   share no vertex but are closer than d̂ at rest would repel.
//!
//! The contact set is fixed while the solver iterates; [`Contact::energy_gradient_hessian`]
//! re-evaluates the distance (and its closest features) at the solver's current positions.

pub mod bvh;
pub mod distance;
pub mod repulsion;

use nalgebra::Vector3;
use rayon::prelude::*;

use crate::energy::{Mat12, Vec12};
use bvh::{Aabb, Bvh};
use distance::{point_triangle, segment_segment, TriangleFeature};
use repulsion::{
    edge_edge_jet, face_normal, obstacle_eval, obstacle_eval_with, penalty, penalty_energy,
    vertex_obstacle_jet, vertex_triangle_jet, DistanceJet, HessianKind, ObstacleEval,
};

/// How deep (metres) a cloth vertex may be inside a collider and still be found and pushed out;
/// also the search radius of [`max_penetration`]. Never less than d̂ in detection.
pub const OBSTACLE_SEARCH_M: f64 = 0.05;

/// A collider at the current time: its points and its triangles (counter-clockwise seen from
/// outside).
pub type Collider<'a> = (&'a [Vector3<f64>], &'a [[u32; 3]]);

/// Where each cloth vertex began the step ([`CollisionDetector::find_contacts_since`]), and
/// which colliders held still over it (their points the same at its start and end).
#[derive(Debug, Clone, Copy)]
pub struct StepStart<'a> {
    /// Cloth positions at the start of the step, as many as the cloth's.
    pub x: &'a [Vector3<f64>],
    /// Per collider: whether it held still.
    pub still: &'a [bool],
}

/// One active contact. Cloth vertices are indices into the cloth's positions; collider points
/// are copied in.
#[derive(Debug, Clone, PartialEq)]
pub enum Contact {
    /// Cloth vertex `v` against a collider triangle (points at the current time, outward
    /// counter-clockwise).
    VertexObstacle {
        /// Cloth vertex.
        v: u32,
        /// Collider triangle points, counter-clockwise seen from outside.
        tri: [Vector3<f64>; 3],
        /// Which collider (index in the detector's input) and which of its triangles: where
        /// the body's own motion is read (friction acts on the velocity relative to it).
        face: [u32; 2],
    },
    /// Cloth vertex `v` against cloth triangle `t` (v not in t).
    VertexTriangle {
        /// Cloth vertex.
        v: u32,
        /// Cloth triangle.
        t: [u32; 3],
    },
    /// Cloth edge `a` against a sharp collider edge (points at the current time): keeps box
    /// edges and other creases from slicing between cloth vertices.
    EdgeObstacle {
        /// Cloth edge.
        a: [u32; 2],
        /// Collider edge end points.
        edge: [Vector3<f64>; 2],
        /// Which collider (index in the detector's input) and the collider points of the
        /// edge's two ends: where the crease's own motion is read (friction acts on the
        /// velocity relative to it).
        ends: [u32; 3],
    },
    /// Cloth edge `a` against cloth edge `b` (no shared vertex).
    EdgeEdge {
        /// First cloth edge.
        a: [u32; 2],
        /// Second cloth edge.
        b: [u32; 2],
    },
}

/// Contact parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CollisionParams {
    /// Repulsion thickness d̂, metres: contacts act while the distance is below it.
    pub dhat_m: f64,
    /// Repulsion stiffness κ, N/m (E = ½ κ (d̂ − d)²).
    pub kappa: f64,
    /// Whether cloth–cloth contacts are detected.
    pub self_collision: bool,
}

impl Contact {
    /// The cloth vertices this contact's 12 local coordinates belong to, in order (None for
    /// collider points).
    pub fn cloth_dofs(&self) -> [Option<u32>; 4] {
        match *self {
            Contact::VertexObstacle { v, .. } => [Some(v), None, None, None],
            Contact::VertexTriangle { v, t } => [Some(v), Some(t[0]), Some(t[1]), Some(t[2])],
            Contact::EdgeEdge { a, b } => [Some(a[0]), Some(a[1]), Some(b[0]), Some(b[1])],
            Contact::EdgeObstacle { a, .. } => [Some(a[0]), Some(a[1]), None, None],
        }
    }

    /// The contact's four points at cloth positions `x` (vertex + triangle, or edge + edge).
    pub fn points(&self, x: &[Vector3<f64>]) -> [Vector3<f64>; 4] {
        match self {
            Contact::VertexObstacle { v, tri, .. } => [x[*v as usize], tri[0], tri[1], tri[2]],
            Contact::EdgeObstacle { a, edge, .. } => {
                [x[a[0] as usize], x[a[1] as usize], edge[0], edge[1]]
            }
            _ => self
                .cloth_dofs()
                .map(|i| i.map_or_else(Vector3::zeros, |i| x[i as usize])),
        }
    }

    /// The distance with its gradient and closest-feature case at cloth positions `x`.
    pub fn distance_jet(&self, x: &[Vector3<f64>]) -> DistanceJet {
        let p = self.points(x);
        match self {
            Contact::VertexObstacle { .. } => vertex_obstacle_jet(&p),
            Contact::VertexTriangle { .. } => vertex_triangle_jet(&p),
            Contact::EdgeEdge { .. } | Contact::EdgeObstacle { .. } => edge_edge_jet(&p),
        }
    }

    /// Energy, gradient (12) and PSD (Gauss-Newton) Hessian (12×12) at cloth positions `x`.
    /// Entries of collider points (where [`Contact::cloth_dofs`] is `None`) are derivatives with
    /// respect to the prescribed collider positions: drop them when assembling.
    pub fn energy_gradient_hessian(
        &self,
        x: &[Vector3<f64>],
        params: &CollisionParams,
    ) -> (f64, Vec12, Mat12) {
        self.energy_gradient_hessian_with(x, params, HessianKind::GaussNewton)
    }

    /// As [`Contact::energy_gradient_hessian`] with a chosen Hessian.
    pub fn energy_gradient_hessian_with(
        &self,
        x: &[Vector3<f64>],
        params: &CollisionParams,
        kind: HessianKind,
    ) -> (f64, Vec12, Mat12) {
        let p = self.points(x);
        let jet = self.distance_jet(x);
        penalty(&p, &jet, params.dhat_m, params.kappa, kind)
    }

    /// Energy only (line search).
    pub fn energy(&self, x: &[Vector3<f64>], params: &CollisionParams) -> f64 {
        penalty_energy(self.distance(x), params.dhat_m, params.kappa)
    }

    /// Current distance (signed for obstacles where the vertex projects inside the face),
    /// metres.
    pub fn distance(&self, x: &[Vector3<f64>]) -> f64 {
        let p = self.points(x);
        match self {
            Contact::VertexObstacle { .. } => obstacle_eval(&p[0], &p[1], &p[2], &p[3]).distance(),
            Contact::VertexTriangle { .. } => point_triangle(&p[0], &p[1], &p[2], &p[3]).dist,
            Contact::EdgeEdge { .. } | Contact::EdgeObstacle { .. } => {
                segment_segment(&p[0], &p[1], &p[2], &p[3]).dist
            }
        }
    }
}

/// Finds all contacts with distance < d̂ among cloth (positions, triangles, edges) and colliders
/// (each: points + triangles), using BVHs (see the module docs for the rules). Builds the
/// hierarchies from scratch; [`CollisionDetector`] keeps them between calls.
pub fn find_contacts(
    cloth_x: &[Vector3<f64>],
    cloth_tris: &[[u32; 3]],
    cloth_edges: &[[u32; 2]],
    colliders: &[Collider<'_>],
    params: &CollisionParams,
) -> Vec<Contact> {
    CollisionDetector::new().find_contacts(cloth_x, cloth_tris, cloth_edges, colliders, params)
}

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
struct Solid<'a> {
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
fn is_closed(tris: &[[u32; 3]]) -> bool {
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

/// Boxes of triangles, inflated by `r`.
fn triangle_boxes(pts: &[Vector3<f64>], tris: &[[u32; 3]], r: f64) -> Vec<Aabb> {
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
fn segment_crosses_triangle(
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
fn edge_faces(tris: &[[u32; 3]]) -> Vec<([u32; 2], [u32; 2])> {
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
fn sharp_edges_of(
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
struct CreasePlanes {
    planes: [(Vector3<f64>, Vector3<f64>); 2],
    convex: bool,
}

impl CreasePlanes {
    /// Whether point `c` lies inside the body at this crease: behind both faces' planes of a
    /// convex crease, or behind either of a concave one.
    fn behind(&self, c: &Vector3<f64>) -> bool {
        let [b1, b2] = self.planes.map(|(n, q)| n.dot(&(c - q)) < 0.0);
        if self.convex {
            b1 && b2
        } else {
            b1 || b2
        }
    }
}

/// [`CreasePlanes`] of each of `sharp` (edges of `faces`, the table of [`edge_faces`]).
fn crease_planes(
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
fn edge_boxes(pts: &[Vector3<f64>], edges: &[[u32; 2]], r: f64) -> Vec<Aabb> {
    edges
        .par_iter()
        .map(|e| Aabb::from_points(e.iter().map(|&i| &pts[i as usize])).inflate(r))
        .collect()
}

fn tri_points(pts: &[Vector3<f64>], t: &[u32; 3]) -> [Vector3<f64>; 3] {
    [pts[t[0] as usize], pts[t[1] as usize], pts[t[2] as usize]]
}

/// Interior angle of triangle `x` at local vertex `k`.
fn corner_angle(x: &[Vector3<f64>; 3], k: usize) -> f64 {
    let e1 = x[(k + 1) % 3] - x[k];
    let e2 = x[(k + 2) % 3] - x[k];
    e1.angle(&e2)
}

/// The face of a collider through which the path `start` → `p` last went in: its unit
/// normal, and how far `p` is below its plane. A face counts where `start` is on or above its
/// plane, `p` below it, and the path passes through the triangle; of several (a path in, out
/// and in again), the last is the one the region `p` is in was entered by. Slivers, whose
/// normals are noise, do not count.
fn entry_face(
    start: &Vector3<f64>,
    p: &Vector3<f64>,
    pts: &[Vector3<f64>],
    tris: &[[u32; 3]],
    bvh: &Bvh,
) -> Option<(Vector3<f64>, f64)> {
    let mut last: Option<(f64, Vector3<f64>, f64)> = None;
    bvh.query(&Aabb::from_points([start, p]), |t| {
        let [a, b, c] = tri_points(pts, &tris[t as usize]);
        // Slivers get no normal from `obstacle_eval_with` either (and so no contact).
        let Some((nrm, n2)) = face_normal(&a, &b, &c) else {
            return;
        };
        let n = nrm / n2.sqrt();
        let (above, below) = (n.dot(&(start - a)), -n.dot(&(p - a)));
        if above < 0.0 || below <= 0.0 || !segment_crosses_triangle(start, p, &a, &b, &c) {
            return;
        }
        let at = above / (above + below);
        if last.is_none_or(|f| at > f.0) {
            last = Some((at, n, below));
        }
    });
    last.map(|(_, n, below)| (n, below))
}

/// The closest surface point and the angle-weighted pseudo-normal (Bærentzen & Aanæs; not
/// normalised) of the faces of `cands` (gathered around a point) that tie for nearest at
/// `umin`: a point is inside where it lies behind that normal. `None` when none ties.
fn nearest_side(
    pts: &[Vector3<f64>],
    tris: &[[u32; 3]],
    cands: &[(u32, ObstacleEval)],
    umin: f64,
) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let tie = 1e-12 + 1e-9 * umin;
    let mut pseudo = Vector3::zeros();
    let mut q: Option<Vector3<f64>> = None;
    for (t, e) in cands.iter() {
        if e.closest.dist > umin + tie {
            continue;
        }
        let x = tri_points(pts, &tris[*t as usize]);
        if q.is_none() {
            let b = e.closest.bary;
            q = Some(x[0] * b[0] + x[1] * b[1] + x[2] * b[2]);
        }
        if let Some(n) = e.normal {
            let w = match e.closest.feature {
                TriangleFeature::Vertex(k) => corner_angle(&x, k),
                _ => 1.0,
            };
            pseudo += n * w;
        }
    }
    q.map(|q| (q, pseudo))
}

/// Classifies cloth point `p` against one collider and calls `emit(face)` for each contact
/// face (module docs); `start`, where `p` began the step against this collider (`None`: not
/// known), gives the face an inside point came in through. `cands` is scratch space. Returns
/// the penetration depth (0 when outside or farther than `search`; below the entry face's
/// plane when the nearest face is turned away from it) and the clearance (0 when inside).
#[allow(clippy::too_many_arguments)]
fn classify_vertex(
    p: &Vector3<f64>,
    start: Option<&Vector3<f64>>,
    pts: &[Vector3<f64>],
    tris: &[[u32; 3]],
    bvh: &Bvh,
    dhat: f64,
    search: f64,
    cands: &mut Vec<(u32, ObstacleEval)>,
    mut emit: impl FnMut(u32),
) -> (f64, f64) {
    let tri = |t: u32| tri_points(pts, &tris[t as usize]);
    let tie = |u: f64| 1e-12 + 1e-9 * u;
    // Gathers the faces within `r`, returning the nearest distance among them.
    let gather = |r: f64, cands: &mut Vec<(u32, ObstacleEval)>| {
        cands.clear();
        let mut umin = f64::INFINITY;
        bvh.query_ball(p, r, |t| {
            let [a, b, c] = tri(t);
            let closest = point_triangle(p, &a, &b, &c);
            if closest.dist <= r {
                umin = umin.min(closest.dist);
                cands.push((t, obstacle_eval_with(p, &a, &b, &c, closest)));
            }
        });
        umin
    };
    // Common case first: faces within d̂ (then the nearest one is among them).
    let mut rho = dhat;
    let mut umin = if dhat > 0.0 {
        gather(dhat, cands)
    } else {
        f64::INFINITY
    };
    if umin.is_infinite() || umin + tie(umin) > dhat {
        // None within d̂: is the vertex deep inside, or just away? One query, out to 4× the
        // search: beyond the search only the clearance needs the distance.
        let nearest = bvh.nearest(p, 4.0 * search, |t| {
            let [a, b, c] = tri(t);
            point_triangle(p, &a, &b, &c).dist
        });
        let u = match nearest {
            Some((_, u)) if u <= search => u,
            // No face within the search: far outside, or deeper inside than the search
            // reaches, where a full pass finds it (inside) once it comes within the search of
            // a face. Its side is unknown, so what is certified is how far it may move before
            // it can come within the search of a face: its distance beyond the search, which
            // the caller's test against d̂ then takes on top.
            _ => return (0.0, nearest.map_or(3.0 * search, |(_, u)| u - search)),
        };
        rho = u + dhat;
        umin = gather(rho, cands);
    }
    let (q, pseudo) = match nearest_side(pts, tris, cands, umin) {
        Some((q, n)) => (Some(q), n),
        None => (None, Vector3::zeros()),
    };
    let inside = umin > 0.0 && q.is_some_and(|q| (p - q).dot(&pseudo) < 0.0);
    if inside {
        // Where it is known, the face the vertex came in through decides which faces push it
        // out: those that meet it at a sharp angle do not (a vertex that came in through a
        // table's top near its edge is not pushed sideways by the side, nor one that came in
        // through the side upwards by the top). When even its nearest face is one of those,
        // it goes out the way it came: depth and reach are measured from the entry plane.
        let cos_sharp = SHARP_EDGE_DEG.to_radians().cos();
        let entry = start
            .filter(|s| *s != p)
            .and_then(|s| entry_face(s, p, pts, tris, bvh));
        let turned = entry.filter(|(n0, _)| {
            pseudo
                .try_normalize(0.0)
                .is_some_and(|m| m.dot(n0) < cos_sharp)
        });
        // Without an entry face: every face within the nearest one's distance plus d̂ (or the
        // faces already gathered, if further) that the vertex projects into and is below.
        let nearest_reach = rho.max(umin + dhat);
        let (depth, reach) = match turned {
            Some((_, below)) => (below, below + dhat),
            None => (umin, nearest_reach),
        };
        let mut gathered = rho;
        if gathered < reach {
            gather(reach, cands);
            gathered = reach;
        }
        let pushes = |e: &ObstacleEval, r: f64| {
            e.projects_inside && e.signed_plane < 0.0 && e.closest.dist <= r
        };
        let mut found = false;
        for (t, e) in cands.iter() {
            let aligned =
                entry.is_none_or(|(n0, _)| e.normal.is_some_and(|n| n.dot(&n0) >= cos_sharp));
            if pushes(e, reach) && aligned {
                emit(*t);
                found = true;
            }
        }
        if found || entry.is_none() {
            return (depth, 0.0);
        }
        // No face in line with the entry lies over it: the faces it would have without one.
        if gathered < nearest_reach {
            gather(nearest_reach, cands);
        }
        for (t, e) in cands.iter() {
            if pushes(e, nearest_reach) {
                emit(*t);
            }
        }
        (umin, 0.0)
    } else {
        for (t, e) in cands.iter() {
            if e.signed_plane >= 0.0 && e.closest.dist < dhat {
                emit(*t);
            }
        }
        (0.0, umin)
    }
}

/// What [`CollisionDetector`] knows of a cloth vertex's distance to the colliders: when it
/// was last classified, it lay outside every collider, at least `clear_m` from the nearest
/// face; it has travelled `travel_m` since, and the colliders had travelled `body_mark_m`
/// (the detector's running total) by then. Distance to a surface is 1-Lipschitz in the point
/// and in the surface's points, so while clear − travel − (colliders' travel since) stays
/// above the detection distance, the vertex is still outside and has no contact: it is
/// skipped. The contacts are exactly those of a full classification for closed, consistently
/// oriented colliders; around the boundary of an open one, a vertex's side can change without
/// passing within d̂ of a face, and it is then classified when it next comes within d̂ of one.
#[derive(Debug, Clone, Copy, Default)]
struct Clearance {
    clear_m: f64,
    travel_m: f64,
    body_mark_m: f64,
}

/// A hierarchy kept between calls, refitted while its primitives' indices stay the same.
#[derive(Debug, Clone, Default)]
struct CachedBvh {
    key: Vec<u32>,
    bvh: Bvh,
    /// Collider edges and their faces ([`edge_faces`]), for the key's triangles; filled on
    /// first use.
    edge_faces: Option<Vec<([u32; 2], [u32; 2])>>,
    refits: u32,
    valid: bool,
}

impl CachedBvh {
    fn update(&mut self, key: &[u32], boxes: &[Aabb], rebuild_every: u32) {
        if self.valid && self.refits < rebuild_every && self.key == key {
            self.bvh.refit(boxes);
            self.refits += 1;
        } else {
            self.bvh.rebuild(boxes);
            if self.key != key {
                self.edge_faces = None;
            }
            self.key.clear();
            self.key.extend_from_slice(key);
            self.refits = 0;
            self.valid = true;
        }
    }
}

/// Contact detection that keeps its BVHs between calls: while the triangles (and edges) are the
/// same index lists, the hierarchies are refitted to the new positions instead of rebuilt, and
/// rebuilt every [`CollisionDetector::rebuild_every`] calls to bound the loss of tree quality.
#[derive(Debug, Clone)]
pub struct CollisionDetector {
    /// Refits between full rebuilds (0: rebuild on every call). Default 16.
    pub rebuild_every: u32,
    /// Extra distance, beyond `dhat_m`, within which cloth–collider contacts are reported
    /// (default 0). A solver whose vertices move fast against bodies widens this alone,
    /// without widening the (denser) cloth–cloth search.
    pub obstacle_extra_m: f64,
    /// Skip cloth vertices certified far from every collider (default true); see
    /// [`Clearance`]. Off, every vertex is classified on every call: the contacts are the
    /// same, only slower (tests compare the two).
    pub skip_clear_vertices: bool,
    /// Report cloth edges against sharp collider edges ([`Contact::EdgeObstacle`]; default
    /// true). Off, only cloth vertices meet colliders, so a cloth edge may cut across a crease
    /// as the downsampled fine cloth does: a 20 mm coarse edge between a vertex on a table's
    /// top and one down its side passes through the table's corner in M_int, where the crease
    /// contact holds the coarse sheet out from the side.
    pub crease_contacts: bool,
    colliders: Vec<CachedBvh>,
    clearance: Vec<Clearance>,
    clearance_x: Vec<Vector3<f64>>,
    clearance_bodies: Vec<Vec<Vector3<f64>>>,
    /// Sum over calls of the largest collider point displacement since the previous call, m:
    /// an upper bound of how far any collider point has travelled.
    body_travel_m: f64,
    skipped: usize,
    cloth_tris: CachedBvh,
    cloth_edges: CachedBvh,
    depth: Vec<f64>,
}

impl Default for CollisionDetector {
    fn default() -> Self {
        CollisionDetector::new()
    }
}

impl CollisionDetector {
    /// A detector with no cached hierarchies.
    pub fn new() -> CollisionDetector {
        CollisionDetector {
            rebuild_every: 16,
            obstacle_extra_m: 0.0,
            skip_clear_vertices: true,
            crease_contacts: true,
            colliders: Vec::new(),
            clearance: Vec::new(),
            clearance_x: Vec::new(),
            clearance_bodies: Vec::new(),
            body_travel_m: 0.0,
            skipped: 0,
            cloth_tris: CachedBvh::default(),
            cloth_edges: CachedBvh::default(),
            depth: Vec::new(),
        }
    }

    /// The deepest collider penetration seen by the last [`CollisionDetector::find_contacts`]
    /// or [`CollisionDetector::find_contacts_since`] (as [`max_penetration`], searched to
    /// max(d̂, [`OBSTACLE_SEARCH_M`]); below the entry face's plane where that decided).
    pub fn max_penetration(&self) -> f64 {
        self.depth.iter().copied().fold(0.0, f64::max)
    }

    /// Per cloth vertex, how deep inside a collider the last
    /// [`CollisionDetector::find_contacts`] found it, m (0 outside).
    pub fn vertex_depths(&self) -> &[f64] {
        &self.depth
    }

    /// Cloth vertices the last [`CollisionDetector::find_contacts`] skipped as certified far
    /// from every collider ([`Clearance`]).
    pub fn skipped_vertices(&self) -> usize {
        self.skipped
    }

    /// Adds each cloth vertex's and the colliders' displacement since the previous call to
    /// their travelled distances ([`Clearance`]); starts over (nothing certified) when the
    /// cloth or the colliders (`same_meshes`: their triangles) are not the ones of the previous
    /// call.
    fn track_travel(
        &mut self,
        cloth_x: &[Vector3<f64>],
        colliders: &[Collider<'_>],
        same_meshes: bool,
    ) {
        let same = same_meshes
            && self.clearance.len() == cloth_x.len()
            && self.clearance_bodies.len() == colliders.len()
            && self
                .clearance_bodies
                .iter()
                .zip(colliders)
                .all(|(a, (b, _))| a.len() == b.len());
        if !same {
            self.clearance = vec![Clearance::default(); cloth_x.len()];
            self.clearance_x = cloth_x.to_vec();
            self.clearance_bodies = colliders.iter().map(|(p, _)| p.to_vec()).collect();
            self.body_travel_m = 0.0;
            return;
        }
        let moved = self
            .clearance_bodies
            .iter_mut()
            .zip(colliders)
            .map(|(old, (new, _))| {
                let m = old
                    .par_iter()
                    .zip(new.par_iter())
                    .map(|(a, b)| (a - b).norm())
                    .reduce(|| 0.0, f64::max);
                old.copy_from_slice(new);
                m
            })
            .fold(0.0, f64::max);
        self.body_travel_m += moved;
        self.clearance
            .par_iter_mut()
            .zip(self.clearance_x.par_iter_mut().zip(cloth_x.par_iter()))
            .for_each(|(c, (old, new))| {
                c.travel_m += (new - *old).norm();
                *old = *new;
            });
    }

    /// As [`find_contacts`], reusing (refitting) the hierarchies of the previous call.
    /// Contacts come ordered: obstacles, then vertex–triangle, then edge–edge, each by cloth
    /// element (deterministic regardless of the thread count).
    pub fn find_contacts(
        &mut self,
        cloth_x: &[Vector3<f64>],
        cloth_tris: &[[u32; 3]],
        cloth_edges: &[[u32; 2]],
        colliders: &[Collider<'_>],
        params: &CollisionParams,
    ) -> Vec<Contact> {
        self.find_contacts_impl(cloth_x, None, cloth_tris, cloth_edges, colliders, params)
    }

    /// As [`CollisionDetector::find_contacts`], knowing where each cloth vertex began the step
    /// ([`StepStart`]): a vertex inside a collider that held still is pushed out only by faces
    /// in line with the one it came in through, back out the way it came (module docs).
    pub fn find_contacts_since(
        &mut self,
        cloth_x: &[Vector3<f64>],
        since: StepStart<'_>,
        cloth_tris: &[[u32; 3]],
        cloth_edges: &[[u32; 2]],
        colliders: &[Collider<'_>],
        params: &CollisionParams,
    ) -> Vec<Contact> {
        let since = (since.x.len() == cloth_x.len()).then_some(since);
        self.find_contacts_impl(cloth_x, since, cloth_tris, cloth_edges, colliders, params)
    }

    fn find_contacts_impl(
        &mut self,
        cloth_x: &[Vector3<f64>],
        since: Option<StepStart<'_>>,
        cloth_tris: &[[u32; 3]],
        cloth_edges: &[[u32; 2]],
        colliders: &[Collider<'_>],
        params: &CollisionParams,
    ) -> Vec<Contact> {
        let dhat = params.dhat_m.max(0.0);
        let obstacle_dhat = dhat + self.obstacle_extra_m.max(0.0);
        let search = OBSTACLE_SEARCH_M.max(obstacle_dhat);
        let rebuild_every = self.rebuild_every;

        // The same collider meshes as last call (their points may move): what the clearance
        // bounds of the cloth vertices were measured against.
        let same_meshes = self.colliders.len() == colliders.len()
            && self
                .colliders
                .iter()
                .zip(colliders)
                .all(|(cache, (_, tris))| cache.valid && cache.key == tris.as_flattened());
        self.colliders
            .resize_with(colliders.len(), CachedBvh::default);
        for (cache, (pts, tris)) in self.colliders.iter_mut().zip(colliders) {
            cache.update(
                tris.as_flattened(),
                &triangle_boxes(pts, tris, 0.0),
                rebuild_every,
            );
        }
        self.track_travel(cloth_x, colliders, same_meshes);
        let caches = &self.colliders;
        let (clearance, body_travel) = (&self.clearance, self.body_travel_m);
        let skip = self.skip_clear_vertices;
        // (depth, contacts, new clearance when classified)
        type PerVertex = (f64, Vec<Contact>, Option<f64>);
        let per_vertex: Vec<PerVertex> = cloth_x
            .par_iter()
            .enumerate()
            .map_init(Vec::new, |scratch, (v, p)| {
                let c = &clearance[v];
                if skip && c.clear_m - c.travel_m - (body_travel - c.body_mark_m) > obstacle_dhat {
                    return (0.0, Vec::new(), None);
                }
                let mut out = Vec::new();
                let (mut depth, mut clear): (f64, f64) = (0.0, f64::INFINITY);
                for (k, (cache, (pts, tris))) in caches.iter().zip(colliders).enumerate() {
                    let bvh = &cache.bvh;
                    // Only against a body that held still: against a moving one the path
                    // would have to be taken in the body's own frame.
                    let start = since
                        .filter(|st| st.still.get(k).copied().unwrap_or(false))
                        .map(|st| &st.x[v]);
                    let (d, u) = classify_vertex(
                        p,
                        start,
                        pts,
                        tris,
                        bvh,
                        obstacle_dhat,
                        search,
                        scratch,
                        |t| {
                            out.push(Contact::VertexObstacle {
                                v: v as u32,
                                tri: tri_points(pts, &tris[t as usize]),
                                face: [k as u32, t],
                            })
                        },
                    );
                    depth = depth.max(d);
                    clear = clear.min(u);
                }
                (depth, out, Some(if depth > 0.0 { 0.0 } else { clear }))
            })
            .collect();
        self.depth.clear();
        self.depth.extend(per_vertex.iter().map(|p| p.0));
        self.skipped = per_vertex.iter().filter(|p| p.2.is_none()).count();
        for (c, (_, _, new)) in self.clearance.iter_mut().zip(&per_vertex) {
            if let Some(clear_m) = *new {
                *c = Clearance {
                    clear_m,
                    travel_m: 0.0,
                    body_mark_m: body_travel,
                };
            }
        }
        let mut contacts: Vec<Contact> = per_vertex.into_iter().flat_map(|p| p.1).collect();

        // Sharp collider edges (creases) against cloth edges.
        if self.crease_contacts
            && dhat > 0.0
            && !cloth_edges.is_empty()
            && colliders.iter().any(|(_, t)| !t.is_empty())
        {
            let mut cloth_edge_bvh: Option<Bvh> = None;
            for (k, (cache, (pts, tris))) in self.colliders.iter_mut().zip(colliders).enumerate() {
                let faces = cache.edge_faces.get_or_insert_with(|| edge_faces(tris));
                let sharp = sharp_edges_of(pts, tris, faces, SHARP_EDGE_DEG);
                if sharp.is_empty() {
                    continue;
                }
                let planes = crease_planes(pts, tris, faces, &sharp);
                let cloth_edge_bvh = cloth_edge_bvh.get_or_insert_with(|| {
                    Bvh::build(&edge_boxes(cloth_x, cloth_edges, 0.5 * obstacle_dhat))
                });
                let body = Bvh::build(&edge_boxes(pts, &sharp, 0.5 * obstacle_dhat));
                contacts.extend(cloth_edge_bvh.pairs_with_filter_map(&body, |i, j| {
                    let a = cloth_edges[i as usize];
                    let e = sharp[j as usize];
                    let (p0, p1) = (&pts[e[0] as usize], &pts[e[1] as usize]);
                    let (c0, c1) = (&cloth_x[a[0] as usize], &cloth_x[a[1] as usize]);
                    let q = segment_segment(c0, c1, p0, p1);
                    // One-sided: an edge whose closest point lies inside the body has crossed
                    // the crease (a 20 mm edge passes a table's edge within a step) and is left
                    // to its vertices' contacts; the unsigned repulsion would hold it there
                    // from inside, dragging the cloth towards the crease.
                    let crossed =
                        planes[j as usize].is_some_and(|p| p.behind(&(c0 + (c1 - c0) * q.s)));
                    (q.dist < obstacle_dhat && !crossed).then_some(Contact::EdgeObstacle {
                        a,
                        edge: [*p0, *p1],
                        ends: [k as u32, e[0], e[1]],
                    })
                }));
            }
        }

        self.find_self_contacts_into(cloth_x, cloth_tris, cloth_edges, params, &mut contacts);
        contacts
    }

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
                        if d - closing(&[v], &t) < r {
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
                (d - closing(&a, &b) < r).then_some(Contact::EdgeEdge { a, b })
            });
            out.extend(ee);
        }
        out
    }

    fn find_self_contacts_into(
        &mut self,
        cloth_x: &[Vector3<f64>],
        cloth_tris: &[[u32; 3]],
        cloth_edges: &[[u32; 2]],
        params: &CollisionParams,
        contacts: &mut Vec<Contact>,
    ) {
        let dhat = params.dhat_m.max(0.0);
        let rebuild_every = self.rebuild_every;
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
                        if point_triangle(p, &a, &b, &c).dist < dhat {
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
                (d < dhat).then_some(Contact::EdgeEdge { a, b })
            });
            contacts.extend(ee);
        }
    }
}

#[cfg(test)]
mod clearance_tests {
    use super::*;

    /// A vertex deeper inside a body than the search reaches is certified only for the
    /// distance it may move before it comes within the search of a face: moved closer, it is
    /// found inside and pushed, as a full pass would.
    #[test]
    fn a_vertex_deep_inside_is_found_once_it_comes_within_the_search() {
        let ball = crate::scene::Collider::sphere("ball", Vector3::zeros(), 0.3, 3);
        let pts: Vec<Vector3<f64>> = ball.frames[0].iter().map(|p| p.cast::<f64>()).collect();
        let params = CollisionParams {
            dhat_m: 0.003,
            kappa: 1000.0,
            self_collision: false,
        };
        let mut det = CollisionDetector::new();
        let body = [(pts.as_slice(), ball.triangles.as_slice())];
        // 6 cm under the top (the polyhedron's faces sit a little inside the sphere).
        let mut x = [Vector3::new(0.0, 0.24, 0.0)];
        assert!(det.find_contacts(&x, &[], &[], &body, &params).is_empty());
        assert_eq!(det.max_penetration(), 0.0, "beyond the search");
        // 2 cm closer to the surface: within the search, found inside.
        x[0].y += 0.02;
        let c = det.find_contacts(&x, &[], &[], &body, &params);
        assert_eq!(det.skipped_vertices(), 0);
        assert!(!c.is_empty());
        assert!(det.max_penetration() > 0.03, "{}", det.max_penetration());
    }

    /// A vertex certified far from a collider is classified again when the collider's
    /// triangles change, even with the same points: its clearance was measured against the
    /// old faces.
    #[test]
    fn new_collider_triangles_void_the_clearance_of_every_vertex() {
        let pts = [
            // A square 1 m below the vertex.
            Vector3::new(-1.0, -1.0, -1.0),
            Vector3::new(1.0, -1.0, -1.0),
            Vector3::new(1.0, -1.0, 1.0),
            Vector3::new(-1.0, -1.0, 1.0),
            // A small triangle 1 mm below it.
            Vector3::new(-0.1, -0.001, -0.1),
            Vector3::new(0.1, -0.001, -0.1),
            Vector3::new(0.0, -0.001, 0.1),
        ];
        let far = [[0u32, 2, 1], [0, 3, 2]];
        let near = [[4u32, 6, 5]];
        let cloth = [Vector3::zeros()];
        let params = CollisionParams {
            dhat_m: 0.003,
            kappa: 1000.0,
            self_collision: false,
        };
        let mut det = CollisionDetector::new();
        for _ in 0..2 {
            assert!(det
                .find_contacts(&cloth, &[], &[], &[(&pts, &far)], &params)
                .is_empty());
        }
        assert_eq!(det.skipped_vertices(), 1, "certified far from the square");
        let c = det.find_contacts(&cloth, &[], &[], &[(&pts, &near)], &params);
        assert_eq!(det.skipped_vertices(), 0);
        assert_eq!(c.len(), 1, "{c:?}");
    }
}

#[cfg(test)]
mod edge_obstacle_tests {
    use super::*;

    #[test]
    fn a_box_edge_between_cloth_vertices_is_a_contact() {
        // A unit cube's top edge along x at (y, z) = (1, 1); a cloth edge crossing it 1 mm above,
        // with both cloth vertices far from every face (so no vertex contact can see it).
        let cube = crate::scene::Collider::cuboid("cube", Vector3::zeros(), Vector3::repeat(1.0));
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
        let cube = crate::scene::Collider::cuboid("room", Vector3::zeros(), Vector3::repeat(1.0));
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::collide::distance::tests::Lcg;
    use crate::energy::fd::check_psd;
    use std::collections::{BTreeMap, BTreeSet};

    /// A sphere of radius `r` around `c`: an octahedron with each face split into n² triangles,
    /// projected to the sphere; counter-clockwise seen from outside.
    fn sphere(c: Vector3<f64>, r: f64, n: usize) -> (Vec<Vector3<f64>>, Vec<[u32; 3]>) {
        let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
        let faces = [
            [x, y, z],
            [y, -x, z],
            [-x, -y, z],
            [-y, x, z],
            [y, x, -z],
            [-x, y, -z],
            [-y, -x, -z],
            [x, -y, -z],
        ];
        let mut pts = Vec::new();
        let mut tris = Vec::new();
        for [a, b, cc] in faces {
            let mut idx = vec![vec![0u32; n + 1]; n + 1];
            for (i, row) in idx.iter_mut().enumerate() {
                for (j, slot) in row.iter_mut().enumerate().take(n + 1 - i) {
                    let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                    let p = a * (1.0 - u - v) + b * u + cc * v;
                    *slot = pts.len() as u32;
                    pts.push(c + p.normalize() * r);
                }
            }
            for i in 0..n {
                for j in 0..n - i {
                    tris.push([idx[i][j], idx[i + 1][j], idx[i][j + 1]]);
                    if j + 1 < n - i {
                        tris.push([idx[i + 1][j], idx[i + 1][j + 1], idx[i][j + 1]]);
                    }
                }
            }
        }
        (pts, tris)
    }

    /// A flat grid sheet of (m+1)² vertices at height z over [x0, x0 + m·h] × [y0, y0 + m·h].
    fn sheet(m: usize, h: f64, o: Vector3<f64>) -> (Vec<Vector3<f64>>, Vec<[u32; 3]>) {
        let mut x = Vec::new();
        for i in 0..=m {
            for j in 0..=m {
                x.push(o + Vector3::new(i as f64 * h, j as f64 * h, 0.0));
            }
        }
        let id = |i: usize, j: usize| (i * (m + 1) + j) as u32;
        let mut t = Vec::new();
        for i in 0..m {
            for j in 0..m {
                t.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                t.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        (x, t)
    }

    fn edges_of(tris: &[[u32; 3]]) -> Vec<[u32; 2]> {
        let mut s = BTreeSet::new();
        for t in tris {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                s.insert([a.min(b), a.max(b)]);
            }
        }
        s.into_iter().collect()
    }

    #[test]
    fn sphere_mesh_is_outward() {
        let (p, t) = sphere(Vector3::zeros(), 1.0, 4);
        for tri in &t {
            let [a, b, c] = tri_points(&p, tri);
            let n = (b - a).cross(&(c - a));
            assert!(n.dot(&(a + b + c)) > 0.0);
        }
    }

    /// Expected obstacle contacts by brute force over all faces: per vertex, the sorted contact
    /// distances, and the penetration depth.
    fn brute_obstacle(
        p: &Vector3<f64>,
        pts: &[Vector3<f64>],
        tris: &[[u32; 3]],
        dhat: f64,
    ) -> (Vec<f64>, f64) {
        let evals: Vec<ObstacleEval> = tris
            .iter()
            .map(|t| {
                let [a, b, c] = tri_points(pts, t);
                obstacle_eval(p, &a, &b, &c)
            })
            .collect();
        let umin = evals
            .iter()
            .map(|e| e.closest.dist)
            .fold(f64::INFINITY, f64::min);
        if umin > OBSTACLE_SEARCH_M.max(dhat) {
            return (vec![], 0.0);
        }
        // The sphere is convex: inside iff below every face plane.
        let inside = evals.iter().all(|e| e.signed_plane < 0.0);
        let mut d: Vec<f64> = if inside {
            evals
                .iter()
                .filter(|e| e.projects_inside && e.closest.dist <= umin + dhat)
                .map(|e| e.distance())
                .collect()
        } else {
            evals
                .iter()
                .filter(|e| e.signed_plane >= 0.0 && e.closest.dist < dhat)
                .map(|e| e.distance())
                .collect()
        };
        d.sort_by(f64::total_cmp);
        (d, if inside { umin } else { 0.0 })
    }

    /// Asserts the obstacle contacts of `x` equal brute force over all faces of the convex
    /// collider; returns the expected per-vertex distances and the deepest penetration.
    fn compare_with_brute(
        x: &[Vector3<f64>],
        contacts: &[Contact],
        pts: &[Vector3<f64>],
        tris: &[[u32; 3]],
        dhat: f64,
    ) -> (BTreeMap<u32, Vec<f64>>, f64) {
        let mut got: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
        for c in contacts {
            // Crease contacts are compared in their own test.
            if matches!(c, Contact::EdgeObstacle { .. }) {
                assert!(c.distance(x) < dhat);
                continue;
            }
            let Contact::VertexObstacle { v, .. } = c else {
                panic!("self contact with self_collision off");
            };
            got.entry(*v).or_default().push(c.distance(x));
            assert!(c.distance(x) < dhat);
            assert_eq!(c.cloth_dofs(), [Some(*v), None, None, None]);
        }
        for d in got.values_mut() {
            d.sort_by(f64::total_cmp);
        }
        let mut want: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
        let mut deepest: f64 = 0.0;
        for (v, p) in x.iter().enumerate() {
            let (d, depth) = brute_obstacle(p, pts, tris, dhat);
            deepest = deepest.max(depth);
            if !d.is_empty() {
                want.insert(v as u32, d);
            }
        }
        assert_eq!(
            got.keys().collect::<Vec<_>>(),
            want.keys().collect::<Vec<_>>()
        );
        for (v, d) in &want {
            assert_eq!(got[v].len(), d.len(), "vertex {v}");
            for (a, b) in got[v].iter().zip(d) {
                assert!((a - b).abs() < 1e-14);
            }
        }
        (want, deepest)
    }

    /// A cube [−0.1, 0.1]³, two counter-clockwise triangles per face.
    pub(super) fn cube() -> (Vec<Vector3<f64>>, Vec<[u32; 3]>) {
        let pts: Vec<Vector3<f64>> = (0..8)
            .map(|i| {
                let c = |b: usize| if i & b != 0 { 0.1 } else { -0.1 };
                Vector3::new(c(1), c(2), c(4))
            })
            .collect();
        let quads = [
            [0, 2, 3, 1], // z−
            [4, 5, 7, 6], // z+
            [0, 1, 5, 4], // y−
            [2, 6, 7, 3], // y+
            [0, 4, 6, 2], // x−
            [1, 3, 7, 5], // x+
        ];
        let tris: Vec<[u32; 3]> = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        (pts, tris)
    }

    /// The contacts of one cloth vertex at `p` that began the step at `from` (a slice: one
    /// of another length is tested too) against one collider, held still or not.
    fn contacts_since(
        det: &mut CollisionDetector,
        p: Vector3<f64>,
        from: &[Vector3<f64>],
        still: bool,
        body: Collider<'_>,
        params: &CollisionParams,
    ) -> Vec<Contact> {
        let since = StepStart {
            x: from,
            still: &[still],
        };
        det.find_contacts_since(&[p], since, &[], &[], &[body], params)
    }

    /// A vertex that a step carried 1.7 mm through a cube's top, 0.5 mm in from its side, is
    /// nearer the side: found alone it is pushed out sideways (a sheet landing on a table slid
    /// off it so). Knowing where it began the step, it goes back out through the top, and
    /// vertices whose nearest face is the one they came in by, or that began inside, are found
    /// as before.
    #[test]
    fn a_vertex_that_came_in_through_the_top_near_an_edge_goes_back_out_through_it() {
        let (pts, tris) = cube();
        let params = CollisionParams {
            dhat_m: 0.001,
            kappa: 1e3,
            self_collision: false,
        };
        let bodies = [(pts.as_slice(), tris.as_slice())];
        let normals = |contacts: &[Contact]| -> Vec<Vector3<f64>> {
            contacts
                .iter()
                .map(|c| match c {
                    Contact::VertexObstacle { tri: [a, b, c], .. } => {
                        (b - a).cross(&(c - a)).normalize()
                    }
                    other => panic!("not a vertex–obstacle contact: {other:?}"),
                })
                .collect()
        };
        let faces = |contacts: &[Contact]| -> Vec<[u32; 2]> {
            contacts
                .iter()
                .filter_map(|c| match c {
                    Contact::VertexObstacle { face, .. } => Some(*face),
                    _ => None,
                })
                .collect()
        };
        let mut det = CollisionDetector::new();
        let p = Vector3::new(0.0995, 0.0983, 0.02);
        let above = Vector3::new(0.098, 0.1004, 0.021);
        let alone = det.find_contacts(&[p], &[], &[], &bodies, &params);
        assert!(!alone.is_empty());
        for n in normals(&alone) {
            assert!((n - Vector3::x()).norm() < 1e-12, "nearest face {n}");
        }
        assert!((det.vertex_depths()[0] - 0.0005).abs() < 1e-12);

        let since = contacts_since(&mut det, p, &[above], true, bodies[0], &params);
        assert!(!since.is_empty());
        for n in normals(&since) {
            assert!((n - Vector3::y()).norm() < 1e-12, "entry face {n}");
        }
        assert!((det.vertex_depths()[0] - 0.0017).abs() < 1e-12);
        // Pushed up, not sideways: the repulsion's force on the vertex is along +y.
        let force: Vector3<f64> = since
            .iter()
            .map(|c| {
                let (_, g, _) = c.energy_gradient_hessian(&[p], &params);
                -Vector3::new(g[0], g[1], g[2])
            })
            .sum();
        assert!(
            force.y > 0.0 && force.x.abs() < 1e-9 * force.y,
            "force {force}"
        );

        // Came in through the side: its nearest face, as before.
        let beside = Vector3::new(0.1004, 0.0983, 0.02);
        let side = contacts_since(&mut det, p, &[beside], true, bodies[0], &params);
        assert_eq!(faces(&side), faces(&alone));
        // Began inside (a body that moved onto it): as before.
        let inside = Vector3::new(0.0990, 0.0990, 0.02);
        let began_in = contacts_since(&mut det, p, &[inside], true, bodies[0], &params);
        assert_eq!(faces(&began_in), faces(&alone));
        // Deep in the cube's middle, from above: the top is both nearest and entry.
        let q = Vector3::new(0.0, 0.098, 0.0);
        let middle = contacts_since(
            &mut det,
            q,
            &[q + Vector3::y() * 0.003],
            true,
            bodies[0],
            &params,
        );
        assert_eq!(
            faces(&middle),
            faces(&det.find_contacts(&[q], &[], &[], &bodies, &params))
        );
        // A start of another length than the positions is not used.
        let wrong = contacts_since(&mut det, p, &[above, above], true, bodies[0], &params);
        assert_eq!(faces(&wrong), faces(&alone));
        // Nearer the top it came in by, but within reach of the side: found alone, the side
        // pushes it too; knowing where it came from, only the top does.
        let r = Vector3::new(0.0985, 0.0990, 0.02);
        let alone = det.find_contacts(&[r], &[], &[], &bodies, &params);
        assert!(normals(&alone)
            .iter()
            .any(|n| (n - Vector3::x()).norm() < 1e-12));
        let since = contacts_since(&mut det, r, &[above], true, bodies[0], &params);
        assert!(!since.is_empty());
        for n in normals(&since) {
            assert!((n - Vector3::y()).norm() < 1e-12, "entry face {n}");
        }
        assert!((det.vertex_depths()[0] - 0.001).abs() < 1e-12);
        // A moving cube (held still: false): the nearest face, as alone.
        let moving = contacts_since(&mut det, p, &[above], false, bodies[0], &params);
        assert_eq!(
            faces(&moving),
            faces(&det.find_contacts(&[p], &[], &[], &bodies, &params))
        );
        // A faceted sphere (neighbouring faces 6–12° apart): from wherever outside a vertex
        // came in, the same contacts and depth as alone.
        let (spts, stris) = sphere(Vector3::zeros(), 0.1, 8);
        let ball = [(spts.as_slice(), stris.as_slice())];
        let mut rng = Lcg(5);
        for _ in 0..200 {
            let dir = rng.v3(1.0).normalize();
            let p = dir * (0.097 - 0.002 * rng.next());
            let from = p + dir * 0.012 + rng.v3(0.003);
            assert!(from.norm() > 0.1, "starts outside");
            let alone = det.find_contacts(&[p], &[], &[], &ball, &params);
            let depth = det.vertex_depths()[0];
            let since = contacts_since(&mut det, p, &[from], true, ball[0], &params);
            assert!(!alone.is_empty() && depth > 0.0);
            assert_eq!(faces(&since), faces(&alone), "at {p} from {from}");
            assert_eq!(det.vertex_depths()[0], depth);
        }
    }

    #[test]
    fn cube_edges_and_corners_match_brute_force() {
        let (pts, tris) = cube();
        for t in &tris {
            let [a, b, c] = tri_points(&pts, t);
            assert!(
                (b - a).cross(&(c - a)).dot(&(a + b + c)) > 0.0,
                "cube orientation"
            );
        }
        // Points in a shell around the surface, many near edges and corners, some inside.
        let mut rng = Lcg(17);
        let x: Vec<Vector3<f64>> = (0..3000)
            .map(|_| {
                let p = rng.v3(0.115);
                // Snap some coordinates close to the faces to populate edge and corner regions.
                p.map(|c| {
                    if rng.next() < 0.5 {
                        c.signum() * (0.1 + 0.01 * (rng.next() - 0.3))
                    } else {
                        c
                    }
                })
            })
            .collect();
        let dhat = 0.006;
        let params = CollisionParams {
            dhat_m: dhat,
            kappa: 1e3,
            self_collision: false,
        };
        let colliders: Vec<Collider> = vec![(&pts, &tris)];
        let contacts = find_contacts(&x, &[], &[], &colliders, &params);
        let (want, deepest) = compare_with_brute(&x, &contacts, &pts, &tris, dhat);
        assert!(want.len() > 500, "{} vertices in contact", want.len());
        assert!(deepest > 0.002);
        assert!((max_penetration(&x, &colliders) - deepest).abs() < 1e-15);
        // Every contact pushes its vertex away from the cube (outward along the SDF gradient),
        // or at worst sideways; the sum per vertex strictly outward.
        let mut total: BTreeMap<usize, (Vector3<f64>, Vector3<f64>)> = BTreeMap::new();
        for c in &contacts {
            let (_, g, _) = c.energy_gradient_hessian(&x, &params);
            let v = c.cloth_dofs()[0].map_or(0, |v| v as usize);
            let p = x[v];
            // Outward direction of the cube's distance field at p (for the box it is the
            // clamped-difference direction outside, the nearest-face normal inside).
            let q = p.map(|c| c.clamp(-0.1, 0.1));
            let out = if (p - q).norm() > 0.0 {
                (p - q).normalize()
            } else {
                let k = p.iamax();
                let mut n = Vector3::zeros();
                n[k] = p[k].signum();
                n
            };
            let f = -g.fixed_rows::<3>(0);
            assert!(
                f.dot(&out) > -1e-9 * f.norm(),
                "contact pulls vertex {v} inward: p {p:?}, d {}, f {f:?}",
                c.distance(&x)
            );
            total.entry(v).or_insert((Vector3::zeros(), out)).0 += f;
        }
        for (v, (f, out)) in total {
            assert!(f.dot(&out) > 0.0, "vertex {v}: net force {f:?} not outward");
        }
    }

    #[test]
    fn sheet_above_sphere_finds_exactly_the_vertices_within_dhat() {
        let r = 0.3;
        let (spts, stris) = sphere(Vector3::zeros(), r, 12);
        let dhat = 0.01;
        // Sheet touching the top: the central vertices are within d̂ of the sphere.
        let (mut x, t) = sheet(20, 0.01, Vector3::new(-0.1, -0.1, r + 0.002));
        // Push a few vertices inside, one shallow one deeper, and lift one far away.
        x[220].z = r - 0.004;
        x[221].z = r - 0.02;
        x[0].z += 0.2;
        let e = edges_of(&t);
        let params = CollisionParams {
            dhat_m: dhat,
            kappa: 1e3,
            self_collision: false,
        };
        let colliders: Vec<Collider> = vec![(&spts, &stris)];
        let contacts = find_contacts(&x, &t, &e, &colliders, &params);
        let (want, deepest) = compare_with_brute(&x, &contacts, &spts, &stris, dhat);
        assert!(
            want.len() > 20 && want.len() < x.len() / 2,
            "{} vertices in contact",
            want.len()
        );
        assert!(want.contains_key(&220) && want.contains_key(&221) && !want.contains_key(&0));
        // Penetrating vertices have negative distances and get pushed outward.
        for c in contacts
            .iter()
            .filter(|c| matches!(c, Contact::VertexObstacle { v: 221, .. }))
        {
            assert!(c.distance(&x) < -0.015);
            let (e, g, h) = c.energy_gradient_hessian(&x, &params);
            assert!(e > 0.0 && (-g.fixed_rows::<3>(0)).dot(&x[221]) > 0.0);
            check_psd(&h);
        }
        let mp = max_penetration(&x, &colliders);
        assert!(
            (mp - deepest).abs() < 1e-15 && mp > 0.015 && mp < 0.02,
            "{mp} vs {deepest}"
        );
        let mut det = CollisionDetector::new();
        det.find_contacts(&x, &t, &e, &colliders, &params);
        assert_eq!(det.max_penetration(), mp);

        // The same through a detector that refits a moved collider.
        let shift = Vector3::new(0.0, 0.0, 0.003);
        let moved: Vec<Vector3<f64>> = spts.iter().map(|p| p + shift).collect();
        let colliders2: Vec<Collider> = vec![(&moved, &stris)];
        let again = det.find_contacts(&x, &t, &e, &colliders2, &params);
        let fresh = find_contacts(&x, &t, &e, &colliders2, &params);
        let key = |v: &[Contact]| {
            let mut s: Vec<String> = v.iter().map(|c| format!("{c:?}")).collect();
            s.sort();
            s
        };
        assert_eq!(key(&again), key(&fresh));
        assert!(again.len() > contacts.len());
    }

    #[test]
    fn self_contacts_match_brute_force() {
        let (mut x, mut t) = sheet(6, 0.01, Vector3::zeros());
        let (x2, t2) = sheet(6, 0.01, Vector3::new(0.003, 0.002, 0.004));
        let off = x.len() as u32;
        x.extend(x2);
        t.extend(t2.iter().map(|tri| tri.map(|i| i + off)));
        // Crumple the top sheet a little.
        let mut rng = Lcg(9);
        for p in x.iter_mut().skip(off as usize) {
            p.z += 0.002 * rng.next();
        }
        let e = edges_of(&t);
        let dhat = 0.005;
        let params = CollisionParams {
            dhat_m: dhat,
            kappa: 1e3,
            self_collision: true,
        };
        let contacts = find_contacts(&x, &t, &e, &[], &params);
        let mut vt = BTreeSet::new();
        let mut ee = BTreeSet::new();
        for c in &contacts {
            match c {
                Contact::VertexTriangle { v, t } => assert!(vt.insert((*v, *t))),
                Contact::EdgeEdge { a, b } => assert!(ee.insert((*a, *b))),
                Contact::VertexObstacle { .. } | Contact::EdgeObstacle { .. } => {
                    panic!("no colliders")
                }
            }
            assert!(c.distance(&x) < dhat);
            let (en, g, h) = c.energy_gradient_hessian(&x, &params);
            assert!(en > 0.0 && g.norm() > 0.0);
            check_psd(&h);
        }
        let mut want_vt = BTreeSet::new();
        for (v, p) in x.iter().enumerate() {
            for tri in &t {
                let [a, b, c] = tri_points(&x, tri);
                if !tri.contains(&(v as u32)) && point_triangle(p, &a, &b, &c).dist < dhat {
                    want_vt.insert((v as u32, *tri));
                }
            }
        }
        let mut want_ee = BTreeSet::new();
        for (i, a) in e.iter().enumerate() {
            for b in &e[i + 1..] {
                let shared = a.contains(&b[0]) || a.contains(&b[1]);
                let d = segment_segment(
                    &x[a[0] as usize],
                    &x[a[1] as usize],
                    &x[b[0] as usize],
                    &x[b[1] as usize],
                )
                .dist;
                if !shared && d < dhat {
                    want_ee.insert((*a, *b));
                }
            }
        }
        assert!(want_vt.len() > 30 && want_ee.len() > 30);
        assert_eq!(vt, want_vt);
        assert_eq!(ee, want_ee);
        // Off means off.
        let off = CollisionParams {
            self_collision: false,
            ..params
        };
        assert!(find_contacts(&x, &t, &e, &[], &off).is_empty());
    }

    /// Detection timings on an ~80K-triangle sphere with a 10K-vertex sheet draped on it (print
    /// only; `--release -- --nocapture detection_timing`).
    #[test]
    fn detection_timing_80k_collider() {
        let r = 0.3;
        let (spts, stris) = sphere(Vector3::zeros(), r, 100);
        let (mut x, t) = sheet(99, 0.006, Vector3::new(-0.297, -0.297, 0.0));
        for p in x.iter_mut() {
            // Drape: lie on the sphere at 1 mm (plus noise) where above it, flat elsewhere.
            let rho2 = p.x * p.x + p.y * p.y;
            p.z = if rho2 < r * r {
                (r * r - rho2).sqrt() + 0.001
            } else {
                0.001
            };
        }
        let e = edges_of(&t);
        let colliders: Vec<Collider> = vec![(&spts, &stris)];
        let params = CollisionParams {
            dhat_m: 0.003,
            kappa: 1e3,
            self_collision: true,
        };
        let mut det = CollisionDetector::new();
        let t0 = std::time::Instant::now();
        let c1 = det.find_contacts(&x, &t, &e, &colliders, &params);
        let first = t0.elapsed();
        let best_of = |det: &mut CollisionDetector, p: &CollisionParams| {
            let mut best = std::time::Duration::MAX;
            let mut c = Vec::new();
            for _ in 0..5 {
                let t0 = std::time::Instant::now();
                c = det.find_contacts(&x, &t, &e, &colliders, p);
                best = best.min(t0.elapsed());
            }
            (c, best)
        };
        let (c2, refit) = best_of(&mut det, &params);
        let no_self = CollisionParams {
            self_collision: false,
            ..params
        };
        let (c3, obstacles_only) = best_of(&mut det, &no_self);
        let t0 = std::time::Instant::now();
        let s: f64 = c2
            .par_iter()
            .map(|c| c.energy_gradient_hessian(&x, &params).0)
            .sum();
        let eval = t0.elapsed();
        let t0 = std::time::Instant::now();
        let mp = max_penetration(&x, &colliders);
        let pen = t0.elapsed();
        println!(
            "detection: {} collider tris, {} cloth verts / {} tris / {} edges, {} threads: first call {:?}, refit call {:?} ({} contacts), obstacles only {:?} ({} contacts), parallel GN eval {:?} (E = {s:.3e}), max_penetration from scratch {:?} ({mp})",
            stris.len(),
            x.len(),
            t.len(),
            e.len(),
            rayon::current_num_threads(),
            first,
            refit,
            c2.len(),
            obstacles_only,
            c3.len(),
            eval,
            pen
        );
        assert_eq!(c1, c2);
        assert!(c2.len() > 1000);
    }
}

#[cfg(test)]
mod swept_tests {
    use super::*;

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
        let (pts, tris) = super::tests::cube();
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
}
