//! The collision detector: its cached hierarchies, clearances and cloth–body detection.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::body::{classify_vertex, tri_points};
use super::bvh::{Aabb, Bvh};
use super::contact::{Collider, CollisionParams, Contact, StepStart};
use super::crease::{crease_planes, edge_boxes, edge_faces, sharp_edges_of, SHARP_EDGE_DEG};
use super::crossings::triangle_boxes;
use super::distance::{point_segment, segment_segment};
use super::OBSTACLE_SEARCH_M;

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
pub(super) struct Clearance {
    clear_m: f64,
    travel_m: f64,
    body_mark_m: f64,
}

/// A hierarchy kept between calls, refitted while its primitives' indices stay the same.
#[derive(Debug, Clone, Default)]
pub(super) struct CachedBvh {
    key: Vec<u32>,
    pub(super) bvh: Bvh,
    /// Collider edges and their faces ([`edge_faces`]), for the key's triangles; filled on
    /// first use.
    edge_faces: Option<Vec<([u32; 2], [u32; 2])>>,
    refits: u32,
    valid: bool,
    /// Whether the last [`CachedBvh::update_points`] found other points (or triangles) than
    /// the call before.
    moved: bool,
}

impl CachedBvh {
    /// [`CachedBvh::update`] with the boxes of triangles `tris` on `pts`, unless these are the
    /// triangles of the previous call on the same points (`still`; a body held still, as while
    /// dressing or through a step's Newton iterations): the refit would give the same
    /// hierarchy, so only its count goes on (the rebuild schedule, and so the contacts, stay
    /// the same).
    fn update_points(
        &mut self,
        pts: &[Vector3<f64>],
        tris: &[[u32; 3]],
        still: bool,
        rebuild_every: u32,
    ) {
        let key = tris.as_flattened();
        let same = still && self.valid && self.key == key;
        self.moved = !same;
        if same && self.refits < rebuild_every {
            self.refits += 1;
            return;
        }
        self.update(key, &triangle_boxes(pts, tris, 0.0), rebuild_every);
    }

    pub(super) fn update(&mut self, key: &[u32], boxes: &[Aabb], rebuild_every: u32) {
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
    /// Keep each collider's edges where its surface turns, for
    /// [`CollisionDetector::crease_within`] (default false: only fast mode asks).
    pub surface_turns: bool,
    /// Which cloth–cloth pairs are reported ([`ClothPairs`]); `None`: every pair.
    pub cloth_pairs: Option<std::sync::Arc<ClothPairs>>,
    /// Every cloth–cloth pair between the garments `cloth_pairs` keeps active is reported
    /// (self-collision asked for), not only those it names.
    pub every_cloth_pair: bool,
    colliders: Vec<CachedBvh>,
    clearance: Vec<Clearance>,
    clearance_x: Vec<Vector3<f64>>,
    clearance_bodies: Vec<Vec<Vector3<f64>>>,
    /// Sum over calls of the largest collider point displacement since the previous call, m:
    /// an upper bound of how far any collider point has travelled.
    body_travel_m: f64,
    skipped: usize,
    pub(super) cloth_tris: CachedBvh,
    pub(super) cloth_edges: CachedBvh,
    depth: Vec<f64>,
    /// Per collider, its edges where the surface turns at the last call
    /// ([`CollisionDetector::crease_within`]).
    creases: Vec<Creases>,
}

/// Angle between the faces of a collider edge beyond which the surface counts as turning there
/// ([`CollisionDetector::crease_within`]): a fine tessellation of a smooth body (the bench's
/// sphere turns by about 4° an edge) stays below it.
pub const SURFACE_TURN_DEG: f64 = 10.0;

/// A collider's edges where its surface turns, as found by one call, with a hierarchy over
/// them; and its sharp edges for crease contacts. Kept while the collider's points and the
/// settings they were found with stay the same.
#[derive(Debug, Clone, Default)]
struct Creases {
    /// End points of each such edge, m.
    segments: Vec<[Vector3<f64>; 2]>,
    /// Over the segments' boxes; `None` when there are none.
    bvh: Option<Bvh>,
    /// The sharp edges, their faces' planes and a hierarchy over their boxes inflated by half
    /// the obstacle contact distance it holds; `None` until crease contacts ask.
    sharp: Option<SharpEdges>,
    /// Whether `segments` were found with the surface turns asked for.
    turns_found: bool,
    /// Whether this is filled for the collider's present points.
    filled: bool,
}

/// A collider's sharp edges ([`SHARP_EDGE_DEG`]) for crease contacts.
#[derive(Debug, Clone)]
struct SharpEdges {
    edges: Vec<[u32; 2]>,
    planes: Vec<Option<super::crease::CreasePlanes>>,
    /// Over the edges' boxes inflated by `half_dhat_m`.
    bvh: Option<Bvh>,
    half_dhat_m: f64,
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
            cloth_pairs: None,
            every_cloth_pair: false,
            obstacle_extra_m: 0.0,
            skip_clear_vertices: true,
            crease_contacts: true,
            surface_turns: false,
            colliders: Vec::new(),
            clearance: Vec::new(),
            clearance_x: Vec::new(),
            clearance_bodies: Vec::new(),
            body_travel_m: 0.0,
            skipped: 0,
            cloth_tris: CachedBvh::default(),
            cloth_edges: CachedBvh::default(),
            depth: Vec::new(),
            creases: Vec::new(),
        }
    }

    /// Drops what the detector kept from earlier calls (hierarchies, clearances, creases),
    /// keeping its settings: the next call finds the same contacts as a new detector's would,
    /// in the same order. A run resumed from a saved state starts with a new detector; one
    /// that forgets at the same points gives the same result without the stop.
    pub fn forget(&mut self) {
        *self = CollisionDetector {
            rebuild_every: self.rebuild_every,
            obstacle_extra_m: self.obstacle_extra_m,
            skip_clear_vertices: self.skip_clear_vertices,
            crease_contacts: self.crease_contacts,
            surface_turns: self.surface_turns,
            ..CollisionDetector::new()
        };
    }

    /// Whether an edge of collider `collider` where its surface turns by more than
    /// [`SURFACE_TURN_DEG`], as the last call found them, passes within `r` of `p` (false
    /// unless [`Self::surface_turns`] is set).
    pub fn crease_within(&self, collider: usize, p: &Vector3<f64>, r: f64) -> bool {
        let Some(c) = self.creases.get(collider) else {
            return false;
        };
        let Some(bvh) = &c.bvh else { return false };
        let mut near = false;
        bvh.query_ball(p, r, |i| {
            if !near {
                let [a, b] = &c.segments[i as usize];
                near = point_segment(p, a, b).dist <= r;
            }
        });
        near
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

    /// As [`find_contacts`](super::find_contacts), reusing (refitting) the hierarchies of the previous call.
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
        // The colliders' points at the last call are those `track_travel` keeps.
        for (k, (cache, (pts, tris))) in self.colliders.iter_mut().zip(colliders).enumerate() {
            let still = self
                .clearance_bodies
                .get(k)
                .is_some_and(|last| last.as_slice() == *pts);
            cache.update_points(pts, tris, still, rebuild_every);
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

        // Collider edges where the surface turns: remembered for [`Self::crease_within`];
        // the sharp ones (creases) against cloth edges.
        self.creases.resize_with(colliders.len(), Creases::default);
        let mut cloth_edge_bvh: Option<Bvh> = None;
        for (k, (cache, (pts, tris))) in self.colliders.iter_mut().zip(colliders).enumerate() {
            let creases = &mut self.creases[k];
            if cache.moved || !creases.filled || creases.turns_found != self.surface_turns {
                *creases = Creases::default();
            }
            if tris.is_empty() {
                continue;
            }
            let faces = cache.edge_faces.get_or_insert_with(|| edge_faces(tris));
            if !creases.filled {
                if self.surface_turns {
                    let turns = sharp_edges_of(pts, tris, faces, SURFACE_TURN_DEG);
                    creases.segments.extend(
                        turns
                            .iter()
                            .map(|e| [pts[e[0] as usize], pts[e[1] as usize]]),
                    );
                    if !turns.is_empty() {
                        creases.bvh = Some(Bvh::build(&edge_boxes(pts, &turns, 0.0)));
                    }
                }
                creases.turns_found = self.surface_turns;
                creases.filled = true;
            }
            if !(self.crease_contacts && dhat > 0.0 && !cloth_edges.is_empty()) {
                continue;
            }
            let half_dhat = 0.5 * obstacle_dhat;
            if creases
                .sharp
                .as_ref()
                .is_none_or(|s| s.half_dhat_m != half_dhat)
            {
                // Only the hierarchy depends on the contact distance.
                let (edges, planes) = match creases.sharp.take() {
                    Some(s) => (s.edges, s.planes),
                    None => {
                        let edges = sharp_edges_of(pts, tris, faces, SHARP_EDGE_DEG);
                        let planes = crease_planes(pts, tris, faces, &edges);
                        (edges, planes)
                    }
                };
                let bvh =
                    (!edges.is_empty()).then(|| Bvh::build(&edge_boxes(pts, &edges, half_dhat)));
                creases.sharp = Some(SharpEdges {
                    edges,
                    planes,
                    bvh,
                    half_dhat_m: half_dhat,
                });
            }
            let Some(SharpEdges {
                edges: sharp,
                planes,
                bvh: Some(body),
                ..
            }) = creases.sharp.as_ref()
            else {
                continue;
            };
            let cloth_edge_bvh = cloth_edge_bvh
                .get_or_insert_with(|| Bvh::build(&edge_boxes(cloth_x, cloth_edges, half_dhat)));
            contacts.extend(cloth_edge_bvh.pairs_with_filter_map(body, |i, j| {
                let a = cloth_edges[i as usize];
                let e = sharp[j as usize];
                let (p0, p1) = (&pts[e[0] as usize], &pts[e[1] as usize]);
                let (c0, c1) = (&cloth_x[a[0] as usize], &cloth_x[a[1] as usize]);
                let q = segment_segment(c0, c1, p0, p1);
                // One-sided: an edge whose closest point lies inside the body has crossed
                // the crease (a 20 mm edge passes a table's edge within a step) and is left
                // to its vertices' contacts; the unsigned repulsion would hold it there
                // from inside, dragging the cloth towards the crease.
                let crossed = planes[j as usize].is_some_and(|p| p.behind(&(c0 + (c1 - c0) * q.s)));
                (q.dist < obstacle_dhat && !crossed).then_some(Contact::EdgeObstacle {
                    a,
                    edge: [*p0, *p1],
                    ends: [k as u32, e[0], e[1]],
                })
            }));
        }

        self.find_self_contacts_into(cloth_x, cloth_tris, cloth_edges, params, &mut contacts);
        contacts
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
        let ball = clothsr_geometry::scene::Collider::sphere("ball", Vector3::zeros(), 0.3, 3);
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

/// Which cloth–cloth pairs the detector reports: those within one panel, those between two
/// garments, or both (every one with [`CollisionDetector::every_cloth_pair`]); pairs with a
/// vertex of a parked garment (one left out of the simulation for now) never.
#[derive(Debug, Clone, PartialEq)]
pub struct ClothPairs {
    /// The panel of each cloth vertex.
    pub panel: Vec<u32>,
    /// The garment of each cloth vertex.
    pub garment: Vec<u32>,
    /// Per garment: whether it takes part in contacts.
    pub active: Vec<bool>,
    /// Pairs within one panel are reported.
    pub within_panels: bool,
    /// Pairs between two garments are reported.
    pub between_garments: bool,
}

impl ClothPairs {
    /// Whether the pair of elements starting at vertices `a` and `b` is reported (`every`:
    /// any pair between active garments).
    pub fn keep(&self, a: u32, b: u32, every: bool) -> bool {
        let (a, b) = (a as usize, b as usize);
        let (ga, gb) = (self.garment[a], self.garment[b]);
        if !self.active[ga as usize] || !self.active[gb as usize] {
            return false;
        }
        every
            || (self.within_panels && self.panel[a] == self.panel[b])
            || (self.between_garments && ga != gb)
    }
}

#[cfg(test)]
mod cloth_pairs_tests {
    use super::ClothPairs;

    /// Two garments: vertices 0–1 (panel 0) and 2 (panel 1) in garment 0, 3 (panel 2) in
    /// garment 1.
    fn pairs(within: bool, between: bool, active: [bool; 2]) -> ClothPairs {
        ClothPairs {
            panel: vec![0, 0, 1, 2],
            garment: vec![0, 0, 0, 1],
            active: active.to_vec(),
            within_panels: within,
            between_garments: between,
        }
    }

    #[test]
    fn pairs_are_kept_within_panels_between_garments_and_among_active_garments() {
        // (same panel, two panels of one garment, two garments)
        let kept = |p: &ClothPairs, every: bool| {
            (
                p.keep(0, 1, every),
                p.keep(0, 2, every),
                p.keep(0, 3, every),
            )
        };
        // Sewing one garment: within panels only.
        assert_eq!(
            kept(&pairs(true, false, [true; 2]), false),
            (true, false, false)
        );
        // An outfit's run: between garments only.
        assert_eq!(
            kept(&pairs(false, true, [true; 2]), false),
            (false, false, true)
        );
        // Sewing an outfit's layer: both.
        assert_eq!(
            kept(&pairs(true, true, [true; 2]), false),
            (true, false, true)
        );
        // Self-collision: every pair.
        assert_eq!(
            kept(&pairs(false, true, [true; 2]), true),
            (true, true, true)
        );
        // A parked garment meets nothing, even with self-collision.
        assert_eq!(
            kept(&pairs(true, true, [true, false]), true),
            (true, true, false)
        );
        assert_eq!(
            kept(&pairs(true, true, [false, true]), true),
            (false, false, false)
        );
    }
}
