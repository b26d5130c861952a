//! The corrector's graph (the paper's §3.1.2): the coarse mesh's vertices are the nodes, its
//! edges (both directions) and its seam pairs are the edges. No collision edges.
//!
//! Features, per node (`NODE_FEATURES`): the velocity q_i seen through the body proximity
//! b_i·q_i (3, m/s), the simulator step's velocity change beyond gravity
//! Δq_i = q_i − q_i⁰ − g·h (3, m/s; q⁰ the velocity the step started from), a mesh-boundary
//! flag, a seam flag and the body proximity b_i = max(0, 1 − d_i/`BODY_RADIUS_M`), d_i the
//! distance to the nearest collider surface.
//! Per directed edge i → j (`EDGE_FEATURES`): the material-space offset u_ij = u_i − u_j (2, m)
//! and its norm, the world-space offset x_ij = x_i − x_j (3, m) and its norm, the relative
//! velocity q_i − q_j (3, m/s), and a flag for seam edges (whose two ends lie on different
//! panels, so u_ij is set to zero: sewn vertices should coincide).
//!
//! Beyond the paper, whose node feature is the bare velocity q_i and whose corrector sees no
//! colliders: away from bodies the features are invariant to a uniform motion of the cloth.
//! Coarse and fine simulations differ through internal forces (strain, bending, damping: all
//! functions of offsets and relative velocities) and through contact (proximity and the
//! velocity towards the body); a sheet in free fall needs no correction at all. With the bare
//! velocity, a vertex one step into free fall and a vertex hanging at rest one step after the
//! coarse simulator pulled it down carry the same input (q ≈ −g·h), and a corrector trained
//! mostly on draping held a falling sheet in the air (a 5.5 mm error after ten steps).
//!
//! Δq (also beyond the paper) is what the simulator's forces (elastic, damping, contact) did
//! in the step. The coarse mesh cannot buckle inside its triangles, so from M_int (the fine
//! cloth, shortened by its wrinkles) its membrane springs back in one step, and M_int's next
//! step moves almost as if only gravity and contact acted: the target p̄ is then close to a
//! negative multiple of Δq, which explains most of its variance.
//! Δq is zero in free fall, where no correction is needed. (The elastic impulse at M_c,
//! −h·∇E(x_c)/m, is no substitute: the one-Newton-step solver's velocity change is not the
//! force at its end state; in its place the phase-1 loss stayed much higher and the
//! interleaved rollout diverged.)

use std::collections::{HashMap, VecDeque};

use nalgebra::{Vector2, Vector3};
use rayon::prelude::*;

use clothsr_geometry::mesh::ClothMesh;
use clothsr_geometry::scene::Collider;
use clothsr_sim::collide::bvh::{Aabb, Bvh};
use clothsr_sim::collide::distance::point_triangle;

/// Body proximity of every point of `x` to `colliders` at time `t_s`:
/// max(0, 1 − d/`BODY_RADIUS_M`), d the distance to the nearest collider triangle.
/// Builds the colliders' BVHs afresh; [`ProximityCache`] keeps them between calls.
pub fn body_proximity(x: &[Vector3<f64>], colliders: &[Collider], t_s: f64) -> Vec<f32> {
    ProximityCache::default().proximity(x, colliders, t_s)
}

/// [`body_proximity`] with each collider's triangle BVH kept between calls: built on the
/// first call, then refitted to the collider's points at each call (rebuilt every
/// [`ProximityCache::REBUILD_EVERY`] refits, as a tree loosens when the body deforms). A
/// static collider whose points are those cached is left as it is.
#[derive(Debug, Default)]
pub struct ProximityCache {
    bodies: Vec<CachedBody>,
}

#[derive(Debug, Default)]
struct CachedBody {
    /// The static collider's points the tree was made for (empty for an animated one).
    still: Vec<Vector3<f32>>,
    bvh: Bvh,
    points: Vec<Vector3<f64>>,
    /// The triangles' boxes (kept to reuse the allocation).
    boxes: Vec<Aabb>,
    refits: usize,
}

impl ProximityCache {
    /// Refits of a collider's tree between rebuilds.
    pub const REBUILD_EVERY: usize = 100;

    /// Body proximities, as [`body_proximity`].
    pub fn proximity(&mut self, x: &[Vector3<f64>], colliders: &[Collider], t_s: f64) -> Vec<f32> {
        self.bodies
            .resize_with(colliders.len(), CachedBody::default);
        let mut nearest = vec![BODY_RADIUS_M; x.len()];
        for (c, body) in colliders.iter().zip(&mut self.bodies) {
            if c.triangles.is_empty() {
                continue;
            }
            let unchanged = c.times_s.len() == 1
                && body.bvh.len() == c.triangles.len()
                && c.frames.first() == Some(&body.still);
            if !unchanged {
                c.positions_at(t_s, &mut body.points);
                let points = &body.points;
                body.boxes.clear();
                body.boxes.extend(
                    c.triangles
                        .iter()
                        .map(|t| Aabb::from_points(t.iter().map(|&v| &points[v as usize]))),
                );
                if body.bvh.len() != body.boxes.len() || body.refits >= Self::REBUILD_EVERY {
                    body.bvh.rebuild(&body.boxes);
                    body.refits = 0;
                } else {
                    body.bvh.refit(&body.boxes);
                    body.refits += 1;
                }
                body.still = match c.times_s.len() {
                    1 => c.frames.first().cloned().unwrap_or_default(),
                    _ => Vec::new(),
                };
            }
            let (bvh, points) = (&body.bvh, &body.points);
            x.par_iter()
                .zip(nearest.par_iter_mut())
                .with_min_len(64)
                .for_each(|(p, best)| {
                    let hit = bvh.nearest(p, *best, |i| {
                        let [a, b, c] = c.triangles[i as usize].map(|v| points[v as usize]);
                        point_triangle(p, &a, &b, &c).dist
                    });
                    if let Some((_, d)) = hit {
                        *best = best.min(d);
                    }
                });
        }
        nearest
            .iter()
            .map(|d| (1.0 - d / BODY_RADIUS_M).max(0.0) as f32)
            .collect()
    }
}

/// Features per node: proximity-weighted velocity (3), the step's velocity change beyond
/// gravity (3), boundary flag, seam flag, body proximity.
pub const NODE_FEATURES: usize = 9;
/// Features per directed edge: u_ij (2), |u_ij|, x_ij (3), |x_ij|, q_i − q_j (3), seam flag.
pub const EDGE_FEATURES: usize = 11;
/// Node features that are 0/1 flags (not normalised): their column indices.
pub const NODE_FLAGS: [usize; 3] = [6, 7, 8];
/// The node-feature column of the body proximity (in [0, 1], not normalised).
pub const BODY_COLUMN: usize = 8;

/// The velocity change of a simulator step beyond gravity, Δq = q − q⁰ − g·h, per vertex:
/// `v` the step's end velocities, `start_v` those it started from, `gravity_dt` g·h (m/s).
pub fn step_change(
    v: &[Vector3<f64>],
    start_v: &[Vector3<f64>],
    gravity_dt: Vector3<f64>,
) -> Vec<Vector3<f64>> {
    v.iter()
        .zip(start_v)
        .map(|(q, q0)| q - q0 - gravity_dt)
        .collect()
}

/// Distance from a collider at which the body-proximity feature reaches 0, m.
pub const BODY_RADIUS_M: f64 = 0.05;
/// Edge features that are 0/1 flags (not normalised).
pub const EDGE_FLAGS: [usize; 1] = [10];

/// The static graph of a coarse mesh: directed edges and per-vertex flags.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshGraph {
    /// Number of nodes (vertices).
    pub num_nodes: usize,
    /// Sender (source) vertex of each directed edge.
    pub senders: Vec<u32>,
    /// Receiver vertex of each directed edge; messages are summed at receivers.
    pub receivers: Vec<u32>,
    seam_edge: Vec<bool>,
    boundary: Vec<bool>,
    seam_vertex: Vec<bool>,
    material: Vec<Vector2<f64>>,
    /// Lumped mass of each vertex relative to the mean (a third of the material-space area
    /// of its triangles, over the mean of that): the simulator's lumped masses up to the
    /// fabric's density, the weights of [`Self::smooth`].
    pub mass: Vec<f32>,
}

impl MeshGraph {
    /// The graph of `mesh`: every mesh edge in both directions, then every seam pair in both
    /// directions.
    pub fn new(mesh: &ClothMesh) -> MeshGraph {
        let n = mesh.num_vertices();
        let mut count: HashMap<[u32; 2], u8> = HashMap::new();
        for t in &mesh.triangles {
            for [a, b] in [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]] {
                *count.entry([a.min(b), a.max(b)]).or_default() += 1;
            }
        }
        let mut boundary = vec![false; n];
        for (e, c) in &count {
            if *c == 1 {
                boundary[e[0] as usize] = true;
                boundary[e[1] as usize] = true;
            }
        }
        let mut area = vec![0.0f64; n];
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|v| mesh.material[v as usize]);
            let e = (b - a).perp(&(c - a)).abs() / 6.0;
            for v in t {
                area[*v as usize] += e;
            }
        }
        let mean_area = area.iter().sum::<f64>() / n.max(1) as f64;
        let mass = area
            .iter()
            .map(|a| {
                if mean_area > 0.0 {
                    (a / mean_area) as f32
                } else {
                    1.0
                }
            })
            .collect();
        let mut seam_vertex = vec![false; n];
        let (mut senders, mut receivers, mut seam_edge) = (Vec::new(), Vec::new(), Vec::new());
        let mut push = |a: u32, b: u32, seam: bool| {
            senders.extend([a, b]);
            receivers.extend([b, a]);
            seam_edge.extend([seam, seam]);
        };
        for [a, b] in mesh.edges() {
            push(a, b, false);
        }
        for &[a, b] in &mesh.seam_pairs {
            if a != b {
                seam_vertex[a as usize] = true;
                seam_vertex[b as usize] = true;
                push(a, b, true);
            }
        }
        MeshGraph {
            num_nodes: n,
            senders,
            receivers,
            seam_edge,
            boundary,
            seam_vertex,
            material: mesh.material.clone(),
            mass,
        }
    }

    /// Low-pass filters per-vertex vectors `p` in place: `iters` rounds of replacing each
    /// vertex's vector by the mass-weighted mean over itself and its graph neighbours (mesh
    /// edges and seam pairs). A uniform field is kept; short waves are damped far more than
    /// long ones (on a sheet of 10 mm edges, 4 rounds keep 94 % of a 200 mm wave and 22 % of
    /// per-vertex noise). Σ m·p is kept only where the neighbourhoods' masses are alike: at
    /// borders and between unequal triangles the filter moves a little momentum.
    /// `p` has one vector per graph node.
    pub fn smooth(&self, p: &mut [Vector3<f64>], iters: usize) {
        assert_eq!(p.len(), self.num_nodes, "one vector per graph node");
        if iters == 0 {
            return;
        }
        // Each vertex's mass plus its neighbours': the same every round.
        let mut weight: Vec<f64> = self.mass.iter().map(|&m| f64::from(m)).collect();
        for (&s, &r) in self.senders.iter().zip(&self.receivers) {
            weight[r as usize] += f64::from(self.mass[s as usize]);
        }
        let mut sum = vec![Vector3::zeros(); self.num_nodes];
        for _ in 0..iters {
            for ((sum, p), m) in sum.iter_mut().zip(p.iter()).zip(&self.mass) {
                *sum = p * f64::from(*m);
            }
            for (&s, &r) in self.senders.iter().zip(&self.receivers) {
                sum[r as usize] += p[s as usize] * f64::from(self.mass[s as usize]);
            }
            for ((p, sum), w) in p.iter_mut().zip(&sum).zip(&weight) {
                if *w > 0.0 {
                    *p = sum / *w;
                }
            }
        }
    }

    /// Number of directed edges.
    pub fn num_edges(&self) -> usize {
        self.senders.len()
    }

    /// Appends the node features for velocities `v`, step changes `dv` ([`step_change`]) and
    /// body proximities `body` (one each per node, [`body_proximity`]): [num_nodes,
    /// NODE_FEATURES] row-major.
    pub fn node_features(
        &self,
        v: &[Vector3<f64>],
        dv: &[Vector3<f64>],
        body: &[f32],
        out: &mut Vec<f32>,
    ) {
        debug_assert_eq!(v.len(), self.num_nodes);
        debug_assert_eq!(dv.len(), self.num_nodes);
        debug_assert_eq!(body.len(), self.num_nodes);
        for (i, (q, d)) in v.iter().zip(dv).enumerate() {
            let q = q * f64::from(body[i]);
            out.extend([
                q.x as f32,
                q.y as f32,
                q.z as f32,
                d.x as f32,
                d.y as f32,
                d.z as f32,
                f32::from(u8::from(self.boundary[i])),
                f32::from(u8::from(self.seam_vertex[i])),
                body[i],
            ]);
        }
    }

    /// Mean strain |x_i − x_j| / |u_i − u_j| − 1 of each vertex's mesh edges (seam pairs,
    /// which have no material length, left out; 0 for a vertex with none) at positions `x`.
    pub fn vertex_strain(&self, x: &[Vector3<f64>]) -> Vec<f64> {
        debug_assert_eq!(x.len(), self.num_nodes);
        let (mut sum, mut count) = (vec![0.0; self.num_nodes], vec![0u32; self.num_nodes]);
        for k in 0..self.num_edges() {
            if self.seam_edge[k] {
                continue;
            }
            let (i, j) = (self.senders[k] as usize, self.receivers[k] as usize);
            let rest = (self.material[i] - self.material[j]).norm();
            if rest > 0.0 {
                sum[j] += (x[i] - x[j]).norm() / rest - 1.0;
                count[j] += 1;
            }
        }
        sum.iter()
            .zip(&count)
            .map(|(s, &c)| if c > 0 { s / f64::from(c) } else { 0.0 })
            .collect()
    }

    /// The gated decoder's tension limit at positions `x`: per vertex
    /// w = clamp(1 − ε̄/`ramp`, 0, 1), ε̄ its [`Self::vertex_strain`]. 1 where the cloth is
    /// compressed or at rest length, 0 where it is stretched by `ramp` or more.
    pub fn tension_weight(&self, x: &[Vector3<f64>], ramp: f64) -> Vec<f32> {
        self.vertex_strain(x)
            .iter()
            .map(|e| (1.0 - e / ramp).clamp(0.0, 1.0) as f32)
            .collect()
    }

    /// Appends the edge features for positions `x` and velocities `v`: [num_edges,
    /// EDGE_FEATURES] row-major.
    pub fn edge_features(&self, x: &[Vector3<f64>], v: &[Vector3<f64>], out: &mut Vec<f32>) {
        debug_assert_eq!(x.len(), self.num_nodes);
        debug_assert_eq!(v.len(), self.num_nodes);
        for k in 0..self.num_edges() {
            let (i, j) = (self.senders[k] as usize, self.receivers[k] as usize);
            let u = if self.seam_edge[k] {
                Vector2::zeros()
            } else {
                self.material[i] - self.material[j]
            };
            let d = x[i] - x[j];
            let w = v[i] - v[j];
            out.extend([
                u.x as f32,
                u.y as f32,
                u.norm() as f32,
                d.x as f32,
                d.y as f32,
                d.z as f32,
                d.norm() as f32,
                w.x as f32,
                w.y as f32,
                w.z as f32,
                f32::from(u8::from(self.seam_edge[k])),
            ]);
        }
    }

    /// Vertices within `hops` graph steps of `centre`, in breadth-first order, with their hop
    /// distance, stopping once `max_nodes` are found.
    pub fn ball(&self, centre: u32, hops: usize, max_nodes: usize) -> Vec<(u32, usize)> {
        let mut adjacency: Vec<Vec<u32>> = vec![Vec::new(); self.num_nodes];
        for (&s, &r) in self.senders.iter().zip(&self.receivers) {
            adjacency[r as usize].push(s);
        }
        let mut dist = vec![usize::MAX; self.num_nodes];
        let mut order = Vec::new();
        let mut queue = VecDeque::from([centre]);
        dist[centre as usize] = 0;
        while let Some(v) = queue.pop_front() {
            order.push((v, dist[v as usize]));
            if order.len() >= max_nodes {
                break;
            }
            if dist[v as usize] >= hops {
                continue;
            }
            for &w in &adjacency[v as usize] {
                if dist[w as usize] == usize::MAX {
                    dist[w as usize] = dist[v as usize] + 1;
                    queue.push_back(w);
                }
            }
        }
        order
    }

    /// The sub-graph induced by `nodes` (old indices; their order gives the new indices) and
    /// the map old → new. Flags keep their values from the whole mesh: a vertex cut off at
    /// the patch's rim is not a mesh boundary.
    pub fn subgraph(&self, nodes: &[u32]) -> MeshGraph {
        let mut new_index = vec![u32::MAX; self.num_nodes];
        for (k, &v) in nodes.iter().enumerate() {
            new_index[v as usize] = k as u32;
        }
        let (mut senders, mut receivers, mut seam_edge) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..self.num_edges() {
            let (s, r) = (
                new_index[self.senders[k] as usize],
                new_index[self.receivers[k] as usize],
            );
            if s != u32::MAX && r != u32::MAX {
                senders.push(s);
                receivers.push(r);
                seam_edge.push(self.seam_edge[k]);
            }
        }
        let pick = |f: &Vec<bool>| nodes.iter().map(|&v| f[v as usize]).collect();
        MeshGraph {
            num_nodes: nodes.len(),
            senders,
            receivers,
            seam_edge,
            boundary: pick(&self.boundary),
            seam_vertex: pick(&self.seam_vertex),
            material: nodes.iter().map(|&v| self.material[v as usize]).collect(),
            mass: nodes.iter().map(|&v| self.mass[v as usize]).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clothsr_geometry::garment::Fabric;
    use clothsr_geometry::mesh::{mesh_garment, MeshOptions};
    use clothsr_geometry::scene::samples::flat_sheet;

    fn sheet() -> ClothMesh {
        sheet_with(0.05)
    }

    fn sheet_with(edge_m: f64) -> ClothMesh {
        let g = flat_sheet("s", 0.2, 0.1, Vector3::zeros(), Fabric::default());
        mesh_garment(&g, &MeshOptions::with_edge(edge_m)).expect("mesh")
    }

    #[test]
    fn smoothing_keeps_uniform_and_long_waves_and_damps_vertex_noise() {
        let g = MeshGraph::new(&sheet_with(0.01));
        let mesh_material = &g.material;
        let n = g.num_nodes;
        let rms = |p: &[Vector3<f64>]| {
            (p.iter().map(|v| v.norm_squared()).sum::<f64>() / p.len() as f64).sqrt()
        };
        // A uniform field is a fixed point.
        let mut p = vec![Vector3::new(0.3, -1.0, 2.0); n];
        g.smooth(&mut p, 5);
        for v in &p {
            assert!((v - Vector3::new(0.3, -1.0, 2.0)).norm() < 1e-12, "{v}");
        }
        // A wave 20 edges long keeps most of itself after 4 rounds ...
        let wave: Vec<Vector3<f64>> = mesh_material
            .iter()
            .map(|u| Vector3::new((u.x * std::f64::consts::TAU / 0.2).sin(), 0.0, 0.0))
            .collect();
        let mut p = wave.clone();
        g.smooth(&mut p, 4);
        let kept = rms(&p) / rms(&wave);
        assert!(kept > 0.9, "long wave kept {kept}");
        // ... and per-vertex noise very little of itself; zero rounds change nothing.
        let mut seed = 12345u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let noise: Vec<Vector3<f64>> = (0..n)
            .map(|_| Vector3::new(next(), next(), next()))
            .collect();
        let mut p = noise.clone();
        g.smooth(&mut p, 0);
        assert_eq!(p, noise);
        g.smooth(&mut p, 4);
        let kept = rms(&p) / rms(&noise);
        assert!(kept < 0.3, "noise kept {kept}");
    }

    #[test]
    fn vertex_strain_and_tension_weight_of_a_uniformly_scaled_sheet() {
        let mesh = sheet();
        let g = MeshGraph::new(&mesh);
        let at = |k: f64| -> Vec<Vector3<f64>> {
            mesh.material
                .iter()
                .map(|u| Vector3::new(u.x * k, 0.3, u.y * k))
                .collect()
        };
        for (k, w) in [(1.0, 1.0), (0.97, 1.0), (1.005, 0.5), (1.02, 0.0)] {
            for e in g.vertex_strain(&at(k)) {
                assert!((e - (k - 1.0)).abs() < 1e-12, "scale {k}: strain {e}");
            }
            for t in g.tension_weight(&at(k), 0.01) {
                assert!((f64::from(t) - w).abs() < 1e-6, "scale {k}: weight {t}");
            }
        }
    }

    #[test]
    fn edges_go_both_ways_and_boundary_is_the_outline() {
        let m = sheet();
        let g = MeshGraph::new(&m);
        assert_eq!(g.num_edges(), 2 * m.edges().len());
        for k in 0..g.num_edges() / 2 {
            assert_eq!(g.senders[2 * k], g.receivers[2 * k + 1]);
            assert_eq!(g.receivers[2 * k], g.senders[2 * k + 1]);
        }
        // On a flat 0.2 × 0.1 sheet the boundary vertices are those on its rectangle.
        let (lo, hi) = m.material.iter().fold(
            (Vector2::repeat(f64::MAX), Vector2::repeat(f64::MIN)),
            |(lo, hi), p| (lo.inf(p), hi.sup(p)),
        );
        for (i, p) in m.material.iter().enumerate() {
            let on_rim = [p.x - lo.x, hi.x - p.x, p.y - lo.y, hi.y - p.y]
                .iter()
                .any(|d| d.abs() < 1e-9);
            assert_eq!(g.boundary[i], on_rim, "vertex {i} at {p:?}");
        }
    }

    #[test]
    fn masses_are_lumped_areas_relative_to_their_mean() {
        let m = sheet();
        let g = MeshGraph::new(&m);
        let n = g.num_nodes as f32;
        assert!((g.mass.iter().sum::<f32>() / n - 1.0).abs() < 1e-5);
        // Their sum is the sheet's area over the mean vertex area.
        let mean_area = 0.2 * 0.1 / f64::from(n);
        let area: f64 = g.mass.iter().map(|&w| f64::from(w) * mean_area).sum();
        assert!((area - 0.02).abs() < 1e-9, "{area}");
        // Rim vertices carry less than inner ones.
        let mean = |rim: bool| {
            let w: Vec<f32> = (0..g.num_nodes)
                .filter(|&i| g.boundary[i] == rim)
                .map(|i| g.mass[i])
                .collect();
            w.iter().sum::<f32>() / w.len() as f32
        };
        assert!(
            mean(true) < 0.8 * mean(false),
            "{} {}",
            mean(true),
            mean(false)
        );
    }

    #[test]
    fn edge_features_are_offsets_and_norms() {
        let m = sheet();
        let g = MeshGraph::new(&m);
        let mut f = Vec::new();
        let v: Vec<Vector3<f64>> = (0..m.num_vertices())
            .map(|i| Vector3::new(0.0, -(i as f64), 0.0))
            .collect();
        g.edge_features(&m.positions, &v, &mut f);
        assert_eq!(f.len(), g.num_edges() * EDGE_FEATURES);
        let k = 3;
        let (i, j) = (g.senders[k] as usize, g.receivers[k] as usize);
        let d = m.positions[i] - m.positions[j];
        let row = &f[k * EDGE_FEATURES..(k + 1) * EDGE_FEATURES];
        assert!((row[3] as f64 - d.x).abs() < 1e-6 && (row[6] as f64 - d.norm()).abs() < 1e-6);
        // Flat sheet: world length equals material length.
        assert!((row[2] - row[6]).abs() < 1e-6);
        assert_eq!(row[8], (j as f32) - (i as f32));
        // A uniform velocity leaves every edge feature unchanged.
        let mut g2 = Vec::new();
        g.edge_features(
            &m.positions,
            &vec![Vector3::new(0.0, -2.0, 0.0); v.len()],
            &mut g2,
        );
        let mut g3 = Vec::new();
        g.edge_features(&m.positions, &vec![Vector3::zeros(); v.len()], &mut g3);
        assert_eq!(g2, g3);
    }

    #[test]
    fn body_proximity_is_one_at_the_surface_and_zero_beyond_the_radius() {
        let ball = Collider::sphere("b", Vector3::zeros(), 0.1, 4);
        let x = [
            Vector3::new(0.0, 0.1, 0.0),
            Vector3::new(0.0, 0.1 + 0.5 * BODY_RADIUS_M, 0.0),
            Vector3::new(0.0, 0.0, 0.1 + 2.0 * BODY_RADIUS_M),
        ];
        let p = body_proximity(&x, &[ball], 0.0);
        assert!(p[0] > 0.97, "{p:?}");
        // Halfway out (the faceted sphere lies up to ~1 mm inside the true one).
        assert!((p[1] - 0.5).abs() < 0.03, "{p:?}");
        assert_eq!(p[2], 0.0);
        assert_eq!(body_proximity(&x, &[], 0.0), vec![0.0; 3]);
    }

    #[test]
    fn the_proximity_cache_follows_a_moving_body_as_a_fresh_tree_does() {
        // A ball moving 5 cm along x over one second (two key frames), and a static one.
        let moving = |dx: f64| Collider::sphere("m", Vector3::new(dx, 0.0, 0.0), 0.1, 3);
        let mut ball = moving(0.0);
        ball.times_s = vec![0.0, 1.0];
        ball.frames.push(moving(0.05).frames[0].clone());
        let still = Collider::sphere("s", Vector3::new(0.0, 0.5, 0.0), 0.1, 3);
        let bodies = [ball, still];
        let x: Vec<Vector3<f64>> = (0..40)
            .map(|k| Vector3::new(-0.1 + 0.01 * k as f64, 0.11, 0.02 * (k % 3) as f64))
            .chain([Vector3::new(0.0, 0.39, 0.0)])
            .collect();
        let mut cache = ProximityCache::default();
        let mut changed = 0;
        // More calls than REBUILD_EVERY, so both refits and a rebuild are compared.
        // The points move too, as the cloth does between calls.
        for k in 0..=ProximityCache::REBUILD_EVERY + 5 {
            let t = k as f64 / (ProximityCache::REBUILD_EVERY + 5) as f64;
            let x: Vec<Vector3<f64>> = x
                .iter()
                .map(|p| p + Vector3::new(0.03 * t, 0.02 * t, -0.04 * t))
                .collect();
            let cached = cache.proximity(&x, &bodies, t);
            assert_eq!(cached, body_proximity(&x, &bodies, t), "t = {t}");
            changed += usize::from(cached != body_proximity(&x, &bodies, 0.0));
        }
        assert!(changed > 50, "the moving ball must change the proximities");
        // Another body set of the same size gets fresh trees, not the cached ones.
        let other = [
            moving(0.2),
            Collider::sphere("s2", Vector3::zeros(), 0.1, 3),
        ];
        assert_eq!(
            cache.proximity(&x, &other, 0.0),
            body_proximity(&x, &other, 0.0)
        );
    }

    #[test]
    fn ball_and_subgraph_keep_only_inner_edges() {
        let m = sheet();
        let g = MeshGraph::new(&m);
        let ball = g.ball(0, 2, usize::MAX);
        assert_eq!(ball[0], (0, 0));
        assert!(ball.iter().all(|&(_, d)| d <= 2));
        let nodes: Vec<u32> = ball.iter().map(|&(v, _)| v).collect();
        let sub = g.subgraph(&nodes);
        assert_eq!(sub.num_nodes, nodes.len());
        assert!(sub.num_edges() > 0 && sub.num_edges() < g.num_edges());
        for (&s, &r) in sub.senders.iter().zip(&sub.receivers) {
            let (a, b) = (nodes[s as usize], nodes[r as usize]);
            assert!(g
                .senders
                .iter()
                .zip(&g.receivers)
                .any(|(&x, &y)| x == a && y == b));
        }
    }
}
