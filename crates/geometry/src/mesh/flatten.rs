//! Material coordinates for garment meshes that have none (a modelled or scanned garment without
//! `st` / `vt`): the surface is cut into charts, each chart is flattened into the plane and the
//! charts are laid out side by side, so the rest of the pipeline can treat the mesh like a sewing
//! pattern whose panels are the charts.
//!
//! # Algorithm
//!
//! 1. **Charts.** Two triangles may share a chart only across an edge that is manifold (exactly
//!    two triangles), consistently oriented, and not a sharp crease (dihedral angle above
//!    [`FlattenOptions::crease_deg`]). Charts are grown breadth-first from seed triangles, and
//!    stay topological discs throughout: a triangle joins across one edge when it brings a new
//!    point, or across two edges when it fills a notch of the boundary. When no triangle can
//!    join so, one that touches the chart joins across a single edge with its third point
//!    copied, which cuts the chart along its two other edges, and growth goes on. Region
//!    growing was chosen over cutting along paths to the boundary because it needs no genus
//!    or boundary-loop analysis and handles every topology alike: a closed tube grows around
//!    until its fronts meet and is cut there, a closed surface is cut along a tree of edges,
//!    and non-manifold regions simply end charts. Triangles wound against their neighbours
//!    are turned over first (a non-orientable surface is cut where the winding disagrees). Every chart is a disc by
//!    construction, which LSCM and ARAP need; cutting inside a chart keeps tubes whole instead
//!    of leaving a strip one triangle wide where the fronts met.
//! 2. **Flattening.** Each chart is flattened with least-squares conformal maps (Lévy et al.
//!    2002; two pinned vertices, far apart) solved as a sparse least-squares problem through its
//!    normal equations with faer's sparse Cholesky factorisation, scaled so that its area equals
//!    its 3D area (conformal maps shrink curved regions), then improved by local/global
//!    as-rigid-as-possible iterations (Liu et al. 2008), which make edge lengths (the cloth's
//!    rest lengths) close to the 3D ones, and scaled to its 3D area again.
//! 3. **Splitting.** A chart whose flattening flips a triangle, lies over itself (its outline
//!    crosses itself) or whose mean area distortion exceeds
//!    [`FlattenOptions::max_area_distortion`] is grown again, inside its own triangles,
//!    with a normal-cone limit (every triangle within a cone around its seed's normal), the
//!    cone halving until the pieces flatten well or the cone reaches
//!    [`FlattenOptions::min_cone_deg`]; small pieces left between the cones are given to
//!    their neighbours. Developable pieces (a tube, a bent panel) stay whole; doubly curved
//!    ones (a hemisphere) are split into pieces of bounded curvature.
//! 4. **Layout.** Each chart is turned so that its principal axis lies along x, and the charts
//!    are packed on shelves, tallest first, with a gap between them: no two charts overlap.

use std::collections::{HashMap, VecDeque};

use faer::linalg::solvers::SolveCore;
use nalgebra::{Vector2, Vector3};

use crate::error::{Error, Result};
use crate::garment::segments_cross;

/// Settings of [`flatten`].
#[derive(Debug, Clone, PartialEq)]
pub struct FlattenOptions {
    /// Edges whose dihedral angle (between the two triangles' normals) exceeds this, degrees,
    /// are creases: charts are cut along them.
    pub crease_deg: f64,
    /// A chart whose area-weighted mean area distortion (|A_2d / A_3d − 1|) exceeds this is
    /// split into smaller charts.
    pub max_area_distortion: f64,
    /// Smallest normal-cone half angle, degrees, used when splitting: a chart grown with this
    /// cone is kept however it flattens.
    pub min_cone_deg: f64,
    /// Local/global ARAP iterations after LSCM (0: LSCM only).
    pub arap_iterations: usize,
    /// Gap between packed charts, as a fraction of the square root of the mesh's area.
    pub gap: f64,
}

impl Default for FlattenOptions {
    fn default() -> Self {
        FlattenOptions {
            crease_deg: 60.0,
            max_area_distortion: 0.05,
            min_cone_deg: 20.0,
            arap_iterations: 20,
            gap: 0.05,
        }
    }
}

/// How far a flattening is from an isometry.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Distortion {
    /// Area-weighted mean over triangles of |A_2d / A_3d − 1|.
    pub area_mean: f64,
    /// Largest |A_2d / A_3d − 1| of any triangle.
    pub area_max: f64,
    /// Area-weighted mean over triangles of the mean |angle_2d − angle_3d| of its three
    /// corners, degrees.
    pub angle_mean_deg: f64,
    /// Largest per-triangle mean |angle_2d − angle_3d|, degrees.
    pub angle_max_deg: f64,
    /// Triangles whose orientation flipped in the plane (their 2D area is not positive).
    pub flipped: usize,
}

/// Result of [`flatten`].
#[derive(Debug, Clone, PartialEq)]
pub struct Flattening {
    /// Flattened coordinate of each triangle corner (three per triangle, in triangle order), in
    /// the points' units (metres when the points are). Corners of one point in one chart share
    /// their coordinate; points on chart boundaries have one per chart. Triangles come out
    /// counter-clockwise, except those wound against their neighbours in the input (clockwise).
    pub corner_uv: Vec<Vector2<f64>>,
    /// Chart of each triangle.
    pub chart_of_triangle: Vec<u32>,
    /// Number of charts.
    pub charts: usize,
    /// Distortion over the whole mesh.
    pub distortion: Distortion,
}

impl Flattening {
    /// This flattening's distortion against other flat coordinates of the same triangles'
    /// corners (`reference[3 t + j]`: corner `j` of triangle `t`), such as the sewing pattern a
    /// garment was cut from: how well it recovers them up to a rigid motion of each chart.
    /// Mirrored charts count as recovered (`flipped` stays 0); areas are weighted by the
    /// reference's.
    pub fn distortion_against(&self, reference: &[Vector2<f64>]) -> Distortion {
        let angles = |p: [Vector2<f64>; 3]| {
            [0, 1, 2].map(|j| {
                let (e1, e2) = (p[(j + 1) % 3] - p[j], p[(j + 2) % 3] - p[j]);
                e1.perp(&e2).abs().atan2(e1.dot(&e2)).to_degrees()
            })
        };
        let area = |p: [Vector2<f64>; 3]| 0.5 * (p[1] - p[0]).perp(&(p[2] - p[0])).abs();
        let mut d = Distortion::default();
        let mut total = 0.0;
        for (uv, r) in self
            .corner_uv
            .chunks_exact(3)
            .zip(reference.chunks_exact(3))
        {
            let (p, q) = ([uv[0], uv[1], uv[2]], [r[0], r[1], r[2]]);
            let a_ref = area(q);
            if a_ref <= 0.0 {
                continue;
            }
            let da = (area(p) / a_ref - 1.0).abs();
            let (gp, gq) = (angles(p), angles(q));
            let dg = (0..3).map(|j| (gp[j] - gq[j]).abs()).sum::<f64>() / 3.0;
            d.area_mean += a_ref * da;
            d.angle_mean_deg += a_ref * dg;
            d.area_max = d.area_max.max(da);
            d.angle_max_deg = d.angle_max_deg.max(dg);
            total += a_ref;
        }
        if total > 0.0 {
            d.area_mean /= total;
            d.angle_mean_deg /= total;
        }
        d
    }
}

/// Flattens a triangle mesh into charts laid out in the plane (see the module documentation).
///
/// Errors, naming the element, on an empty mesh, an index out of range, a point that is not
/// finite, or a triangle of zero area (such triangles are reported, not skipped: the cloth mesh
/// could not use them either).
pub fn flatten(
    points: &[Vector3<f64>],
    triangles: &[[u32; 3]],
    opts: &FlattenOptions,
) -> Result<Flattening> {
    check_input(points, triangles)?;
    let surface = Surface::new(points, triangles, opts.crease_deg);
    let all: Vec<u32> = (0..triangles.len() as u32).collect();
    let mut work: Vec<(Chart, Option<f64>)> = surface
        .grow_charts(&all, None)
        .into_iter()
        .map(|c| (c, None))
        .collect();
    let mut charts: Vec<Chart> = Vec::new();
    while let Some((grown, cone)) = work.pop() {
        let chart = surface.flatten_chart(grown, opts.arap_iterations)?;
        let d = surface.chart_distortion(&chart);
        let overlaps = outline_overlaps(&chart);
        let bad = d.flipped > 0 || d.area_mean > opts.max_area_distortion || overlaps;
        if !bad || chart.tris.len() < 2 {
            charts.push(chart);
            continue;
        }
        // A chart that flattens well but lies over itself (a tube cut open, its ends
        // wrapping past each other) is cut in two across its length: the fewest new seams.
        let halve = |chart: &Chart| -> Vec<(Chart, Option<f64>)> {
            surface
                .halves(&chart.tris)
                .iter()
                .flat_map(|half| surface.grow_charts(half, None))
                .map(|c| (c, None))
                .collect()
        };
        if overlaps && d.flipped == 0 && d.area_mean <= opts.max_area_distortion {
            work.extend(halve(&chart));
            continue;
        }
        // Split with a narrower cone until the chart comes apart or the cone is at its limit.
        let mut next = cone.map_or(90.0, |c| c / 2.0);
        let pieces = loop {
            if next < opts.min_cone_deg {
                break None;
            }
            let pieces = surface.grow_charts(&chart.tris, Some(next));
            if pieces.len() > 1 {
                break Some(pieces);
            }
            next /= 2.0;
        };
        match pieces {
            Some(p) => work.extend(p.into_iter().map(|c| (c, Some(next)))),
            // One the cone cannot tell apart (a nearly flat spiral) is halved too.
            None if overlaps => work.extend(halve(&chart)),
            None => charts.push(chart),
        }
    }
    charts.sort_by_key(|c| c.tris.iter().min().copied().unwrap_or(0));
    let gap = opts.gap.max(0.0) * surface.area3.iter().sum::<f64>().sqrt();
    pack(&mut charts, gap);
    let mut corner_uv = vec![Vector2::zeros(); 3 * triangles.len()];
    let mut chart_of_triangle = vec![0u32; triangles.len()];
    for (k, chart) in charts.iter().enumerate() {
        for (&t, local) in chart.tris.iter().zip(&chart.corners) {
            chart_of_triangle[t as usize] = k as u32;
            for j in 0..3 {
                corner_uv[3 * t as usize + j] = chart.uv[local[j] as usize];
            }
        }
    }
    let distortion = surface.distortion(&all, |t, j| corner_uv[3 * t + j]);
    // Back to the input's winding.
    for (t, _) in surface.flipped.iter().enumerate().filter(|(_, &f)| f) {
        corner_uv.swap(3 * t + 1, 3 * t + 2);
    }
    Ok(Flattening {
        corner_uv,
        chart_of_triangle,
        charts: charts.len(),
        distortion,
    })
}

/// Whether a flattened chart's outline crosses itself: the chart then lies over itself in the
/// plane (a global overlap, with no triangle flipped), which no pattern panel can.
fn outline_overlaps(chart: &Chart) -> bool {
    // Boundary edges: those of one triangle only (by chart vertex).
    let mut count: HashMap<(u32, u32), u32> = HashMap::new();
    for c in &chart.corners {
        for j in 0..3 {
            let (a, b) = (c[j], c[(j + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let mut segs: Vec<(u32, u32, Vector2<f64>, Vector2<f64>)> = count
        .into_iter()
        .filter(|&(_, n)| n == 1)
        .map(|((a, b), _)| (a, b, chart.uv[a as usize], chart.uv[b as usize]))
        .collect();
    segs.sort_by(|s, t| s.2.x.min(s.3.x).total_cmp(&t.2.x.min(t.3.x)));
    for (i, &(a, b, p, q)) in segs.iter().enumerate() {
        let x_max = p.x.max(q.x);
        for &(c, d, r, s) in &segs[i + 1..] {
            if r.x.min(s.x) > x_max {
                break;
            }
            if a == c || a == d || b == c || b == d {
                continue;
            }
            if segments_cross(p, q, r, s) {
                return true;
            }
        }
    }
    false
}

fn check_input(points: &[Vector3<f64>], triangles: &[[u32; 3]]) -> Result<()> {
    if triangles.is_empty() || points.is_empty() {
        return Err(Error::Invalid("cannot flatten an empty mesh".into()));
    }
    if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(Error::Invalid(format!("point {i} is not finite")));
    }
    for (t, tri) in triangles.iter().enumerate() {
        if let Some(v) = tri.iter().find(|&&v| v as usize >= points.len()) {
            return Err(Error::Invalid(format!(
                "triangle {t}: point index {v} is outside the {} points",
                points.len()
            )));
        }
        let [a, b, c] = tri.map(|v| points[v as usize]);
        let longest = (b - a)
            .norm_squared()
            .max((c - b).norm_squared())
            .max((a - c).norm_squared());
        if (b - a).cross(&(c - a)).norm() <= 1e-12 * longest || longest == 0.0 {
            return Err(Error::Invalid(format!("triangle {t} has zero area")));
        }
    }
    Ok(())
}

/// The mesh with what chart growing and flattening need per triangle.
struct Surface<'a> {
    points: &'a [Vector3<f64>],
    /// The triangles, wound consistently with their neighbours.
    tris: Vec<[u32; 3]>,
    /// Whether each triangle's winding is the input's reversed (corners 1 and 2 swapped).
    flipped: Vec<bool>,
    normals: Vec<Vector3<f64>>,
    area3: Vec<f64>,
    /// `neighbour[t][k]`: the triangle across edge (tri[k], tri[k+1]) when a chart may cross it.
    neighbour: Vec<[Option<u32>; 3]>,
}

/// One flattened chart: its triangles, points and coordinates.
struct Chart {
    tris: Vec<u32>,
    /// Mesh point of each chart vertex.
    verts: Vec<u32>,
    /// Chart vertex of each corner of each triangle.
    corners: Vec<[u32; 3]>,
    uv: Vec<Vector2<f64>>,
}

/// Charts grown with a normal cone smaller than this (triangles) are given to their
/// neighbours.
const SMALL_CHART: usize = 16;

/// Slot of a triangle not yet in a chart (chart, index in chart otherwise).
const FREE: (u32, u32) = (u32::MAX, u32::MAX);

/// One use of an edge: (triangle, local edge k from corner k to k + 1, whether it runs from
/// the smaller point index to the larger).
type EdgeUse = (u32, usize, bool);

/// Every triangle using each edge (smaller point, larger point).
fn edge_uses(tris: &[[u32; 3]]) -> HashMap<(u32, u32), Vec<EdgeUse>> {
    let mut edges: HashMap<(u32, u32), Vec<EdgeUse>> = HashMap::new();
    for (t, tri) in tris.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            edges
                .entry((a.min(b), a.max(b)))
                .or_default()
                .push((t as u32, k, a < b));
        }
    }
    edges
}

/// Which triangles to turn over so that neighbours across manifold edges agree on their
/// winding (breadth-first from the lowest triangle of each piece). A non-orientable surface
/// keeps a disagreement somewhere, where charts are then cut.
fn consistent_winding(tris: &[[u32; 3]]) -> Vec<bool> {
    let mut across: Vec<Vec<(u32, bool)>> = vec![Vec::new(); tris.len()];
    for uses in edge_uses(tris).values() {
        if let &[(t0, _, f0), (t1, _, f1)] = uses.as_slice() {
            // Same direction along the shared edge: the two disagree.
            across[t0 as usize].push((t1, f0 == f1));
            across[t1 as usize].push((t0, f0 == f1));
        }
    }
    let mut flip: Vec<Option<bool>> = vec![None; tris.len()];
    for start in 0..tris.len() {
        if flip[start].is_some() {
            continue;
        }
        flip[start] = Some(false);
        let mut queue = VecDeque::from([start]);
        while let Some(t) = queue.pop_front() {
            let ft = flip[t].unwrap_or(false);
            for &(n, disagree) in &across[t] {
                if flip[n as usize].is_none() {
                    flip[n as usize] = Some(ft ^ disagree);
                    queue.push_back(n as usize);
                }
            }
        }
    }
    flip.into_iter().map(|f| f.unwrap_or(false)).collect()
}

/// A chart being grown: its triangles and numbered corners so far.
struct Growth {
    id: u32,
    chart: Chart,
    /// A chart vertex of each mesh point in the chart.
    in_chart: HashMap<u32, u32>,
    /// Edges on the chart's boundary.
    boundary_edges: usize,
}

impl Growth {
    /// Adds triangle `t` with chart vertices `ids` (`None`: a new vertex).
    fn add(
        &mut self,
        surface: &Surface,
        slot: &mut HashMap<u32, (u32, u32)>,
        t: u32,
        ids: [Option<u32>; 3],
    ) {
        let tri = surface.tris[t as usize];
        let shared = ids.iter().flatten().count();
        let corners = [0, 1, 2].map(|j| {
            ids[j].unwrap_or_else(|| {
                self.chart.verts.push(tri[j]);
                let v = (self.chart.verts.len() - 1) as u32;
                self.in_chart.entry(tri[j]).or_insert(v);
                v
            })
        });
        // One shared edge (two known corners) adds one boundary edge, two shared edges remove
        // one, the seed brings three.
        self.boundary_edges = match shared {
            3 => self.boundary_edges - 1,
            2 => self.boundary_edges + 1,
            _ => 3,
        };
        slot.insert(t, (self.id, self.chart.tris.len() as u32));
        self.chart.tris.push(t);
        self.chart.corners.push(corners);
    }

    /// Joins free triangles from `queue` and their neighbours, within `cone` (a normal and the
    /// cosine of its half angle) if given, cutting the chart open when nothing else can join.
    fn grow(
        &mut self,
        surface: &Surface,
        slot: &mut HashMap<u32, (u32, u32)>,
        mut queue: VecDeque<u32>,
        cone: Option<(Vector3<f64>, f64)>,
    ) {
        let mut deferred = Vec::new();
        loop {
            // Join every triangle that keeps the chart a disc without a cut...
            while let Some(t) = queue.pop_front() {
                let outside =
                    cone.is_some_and(|(n, cos)| surface.normals[t as usize].dot(&n) < cos);
                if slot.get(&t) != Some(&FREE) || outside {
                    continue;
                }
                match self.join(surface, slot, t) {
                    Some(ids) => {
                        self.add(surface, slot, t, ids);
                        queue.extend(surface.neighbour[t as usize].iter().flatten());
                    }
                    None => deferred.push(t),
                }
            }
            // ...then cut: join one waiting triangle by one edge, its third point copied.
            let mut cut = None;
            while let Some(t) = deferred.pop() {
                if slot.get(&t) == Some(&FREE) {
                    cut = self.join_with_cut(surface, slot, t).map(|ids| (t, ids));
                    if cut.is_some() {
                        break;
                    }
                }
            }
            let Some((t, ids)) = cut else { break };
            self.add(surface, slot, t, ids);
            queue.extend(surface.neighbour[t as usize].iter().flatten());
        }
    }

    /// The chart vertices of `t`'s corners as its chart neighbours number them, per edge
    /// shared with the chart: `(edge k, [vertex of corner k, vertex of corner k + 1])`.
    fn shared_edges(
        &self,
        surface: &Surface,
        slot: &HashMap<u32, (u32, u32)>,
        t: u32,
    ) -> Vec<(usize, [u32; 2])> {
        let tri = surface.tris[t as usize];
        (0..3)
            .filter_map(|k| {
                let n = surface.neighbour[t as usize][k]?;
                let &(chart, index) = slot.get(&n)?;
                if chart != self.id {
                    return None;
                }
                let ntri = surface.tris[n as usize];
                let corners = self.chart.corners[index as usize];
                let id = |v: u32| (0..3).find(|&j| ntri[j] == v).map(|j| corners[j]);
                Some((k, [id(tri[k])?, id(tri[(k + 1) % 3])?]))
            })
            .collect()
    }

    /// The corners `t` joins the chart with, keeping it a disc without a cut: across one edge
    /// bringing a point new to the chart, or across two edges filling a notch of its boundary.
    fn join(
        &self,
        surface: &Surface,
        slot: &HashMap<u32, (u32, u32)>,
        t: u32,
    ) -> Option<[Option<u32>; 3]> {
        let tri = surface.tris[t as usize];
        let shared = self.shared_edges(surface, slot, t);
        let mut ids = [None; 3];
        for &(k, [a, b]) in &shared {
            for (j, v) in [(k, a), ((k + 1) % 3, b)] {
                if ids[j].is_some_and(|w| w != v) {
                    return None; // the point is on a cut: joining would close it
                }
                ids[j] = Some(v);
            }
        }
        match shared.len() {
            1 => {
                let c = (shared[0].0 + 2) % 3;
                (!self.in_chart.contains_key(&tri[c])).then_some(ids)
            }
            2 => (self.boundary_edges > 3).then_some(ids),
            _ => None,
        }
    }

    /// The corners `t` joins the chart with across one shared edge, its third corner a new
    /// chart vertex (a cut along its other two edges); `None` when it touches no chart edge.
    fn join_with_cut(
        &self,
        surface: &Surface,
        slot: &HashMap<u32, (u32, u32)>,
        t: u32,
    ) -> Option<[Option<u32>; 3]> {
        let &(k, [a, b]) = self.shared_edges(surface, slot, t).first()?;
        let mut ids = [None; 3];
        ids[k] = Some(a);
        ids[(k + 1) % 3] = Some(b);
        Some(ids)
    }
}

impl<'a> Surface<'a> {
    fn new(points: &'a [Vector3<f64>], input: &[[u32; 3]], crease_deg: f64) -> Self {
        let flipped = consistent_winding(input);
        let tris: Vec<[u32; 3]> = input
            .iter()
            .zip(&flipped)
            .map(|(t, &f)| if f { [t[0], t[2], t[1]] } else { *t })
            .collect();
        let mut normals = Vec::with_capacity(tris.len());
        let mut area3 = Vec::with_capacity(tris.len());
        for t in &tris {
            let [a, b, c] = t.map(|v| points[v as usize]);
            let n = (b - a).cross(&(c - a));
            area3.push(0.5 * n.norm());
            normals.push(n.normalize());
        }
        let cos_crease = crease_deg.to_radians().cos();
        let mut neighbour = vec![[None; 3]; tris.len()];
        for uses in edge_uses(&tris).values() {
            let &[(t0, k0, f0), (t1, k1, f1)] = uses.as_slice() else {
                continue; // boundary or non-manifold
            };
            let smooth = normals[t0 as usize].dot(&normals[t1 as usize]) >= cos_crease;
            if f0 != f1 && smooth && t0 != t1 {
                neighbour[t0 as usize][k0] = Some(t1);
                neighbour[t1 as usize][k1] = Some(t0);
            }
        }
        Surface {
            points,
            tris,
            flipped,
            normals,
            area3,
            neighbour,
        }
    }

    /// Grows disc-shaped charts covering `region` (see the module documentation); with `cone`
    /// (half angle, degrees), every triangle of a chart lies within that cone around its
    /// seed's normal, except that pieces of fewer than [`SMALL_CHART`] triangles left between
    /// charts are given to their neighbours where they can join. Returned charts have their
    /// corners numbered (`corners`, `verts`), a point on a cut inside a chart having one vertex
    /// per side; `uv` is left empty.
    fn grow_charts(&self, region: &[u32], cone: Option<f64>) -> Vec<Chart> {
        let mut slot: HashMap<u32, (u32, u32)> = region.iter().map(|&t| (t, FREE)).collect();
        let mean: Vector3<f64> = region
            .iter()
            .map(|&t| self.normals[t as usize] * self.area3[t as usize])
            .sum();
        let mut seeds = region.to_vec();
        seeds.sort_by(|&a, &b| {
            let (da, db) = (
                self.normals[a as usize].dot(&mean),
                self.normals[b as usize].dot(&mean),
            );
            db.total_cmp(&da).then(a.cmp(&b))
        });
        let cos_cone = cone.map_or(-2.0, |c| c.to_radians().cos());
        let mut growths = self.grow_from_seeds(&seeds, &mut slot, cos_cone, Vec::new());
        if cone.is_some() && growths.len() > 1 {
            // Free the small pieces, let the others grow into them without the cone, and grow
            // what is left from seeds again.
            let small: Vec<usize> = (0..growths.len())
                .filter(|&k| growths[k].chart.tris.len() < SMALL_CHART)
                .collect();
            if small.len() < growths.len() {
                for &k in &small {
                    for &t in &growths[k].chart.tris {
                        slot.insert(t, FREE);
                    }
                    growths[k].chart.tris.clear();
                }
                for g in growths.iter_mut().filter(|g| !g.chart.tris.is_empty()) {
                    let queue = g
                        .chart
                        .tris
                        .iter()
                        .flat_map(|&t| self.neighbour[t as usize].iter().flatten().copied())
                        .collect();
                    g.grow(self, &mut slot, queue, None);
                }
                growths = self.grow_from_seeds(&seeds, &mut slot, -2.0, growths);
            }
        }
        growths
            .into_iter()
            .map(|g| g.chart)
            .filter(|c| !c.tris.is_empty())
            .collect()
    }

    /// `region` cut in two halves across its length: by the median of the triangles'
    /// centroids along the line through two centroids far apart.
    fn halves(&self, region: &[u32]) -> [Vec<u32>; 2] {
        let centroid = |t: u32| {
            self.tris[t as usize]
                .iter()
                .map(|&v| self.points[v as usize])
                .sum::<Vector3<f64>>()
                / 3.0
        };
        let c: Vec<Vector3<f64>> = region.iter().map(|&t| centroid(t)).collect();
        let mean = c.iter().sum::<Vector3<f64>>() / c.len().max(1) as f64;
        let far = |from: Vector3<f64>| {
            c.iter()
                .copied()
                .max_by(|a, b| {
                    (a - from)
                        .norm_squared()
                        .total_cmp(&(b - from).norm_squared())
                })
                .unwrap_or(from)
        };
        let p0 = far(mean);
        let axis = far(p0) - p0;
        let mut order: Vec<usize> = (0..region.len()).collect();
        order.sort_by(|&a, &b| c[a].dot(&axis).total_cmp(&c[b].dot(&axis)).then(a.cmp(&b)));
        let (lo, hi) = order.split_at(order.len() / 2);
        [
            lo.iter().map(|&k| region[k]).collect(),
            hi.iter().map(|&k| region[k]).collect(),
        ]
    }

    /// Grows a chart from each free triangle of `seeds` in turn (see [`Surface::grow_charts`])
    /// after the `growths` there are already.
    fn grow_from_seeds(
        &self,
        seeds: &[u32],
        slot: &mut HashMap<u32, (u32, u32)>,
        cos_cone: f64,
        mut growths: Vec<Growth>,
    ) -> Vec<Growth> {
        for &seed in seeds {
            if slot.get(&seed) != Some(&FREE) {
                continue;
            }
            let mut g = Growth {
                id: growths.len() as u32,
                chart: Chart {
                    tris: Vec::new(),
                    verts: Vec::new(),
                    corners: Vec::new(),
                    uv: Vec::new(),
                },
                in_chart: HashMap::new(),
                boundary_edges: 0,
            };
            g.add(self, slot, seed, [None; 3]);
            let queue = self.neighbour[seed as usize]
                .iter()
                .flatten()
                .copied()
                .collect();
            let cone = (cos_cone > -1.0).then(|| (self.normals[seed as usize], cos_cone));
            g.grow(self, slot, queue, cone);
            growths.push(g);
        }
        growths
    }

    /// Triangle `t` in an orthonormal frame of its plane (counter-clockwise, first corner at 0).
    fn local_triangle(&self, t: usize) -> [Vector2<f64>; 3] {
        let [a, b, c] = self.tris[t].map(|v| self.points[v as usize]);
        let x = (b - a).normalize();
        let y = self.normals[t].cross(&x);
        [
            Vector2::zeros(),
            Vector2::new((b - a).dot(&x), 0.0),
            Vector2::new((c - a).dot(&x), (c - a).dot(&y)),
        ]
    }

    /// Gradients of the three linear hat functions of triangle `t` in its local frame, and its
    /// area.
    fn gradients(&self, t: usize) -> ([Vector2<f64>; 3], f64) {
        let p = self.local_triangle(t);
        let two_a = (p[1] - p[0]).perp(&(p[2] - p[0]));
        let g = [0, 1, 2].map(|j| {
            let e = p[(j + 2) % 3] - p[(j + 1) % 3];
            Vector2::new(-e.y, e.x) / two_a
        });
        (g, 0.5 * two_a)
    }

    /// Flattens a disc-shaped chart: LSCM, area rescale, ARAP, area rescale.
    fn flatten_chart(&self, mut chart: Chart, arap_iterations: usize) -> Result<Chart> {
        chart.uv = self.lscm(&chart)?;
        self.match_area(&mut chart);
        if arap_iterations > 0 && chart.tris.len() > 1 {
            let before = self.chart_distortion(&chart);
            let lscm = chart.uv.clone();
            // ARAP only improves on LSCM: where it fails or flips triangles, LSCM stays.
            let ok = self.arap(&mut chart, arap_iterations).is_ok();
            self.match_area(&mut chart);
            let after = self.chart_distortion(&chart);
            if !ok || after.flipped > before.flipped || !after.area_mean.is_finite() {
                chart.uv = lscm;
            }
        }
        Ok(chart)
    }

    /// Least-squares conformal map of a chart with its two farthest-apart (approximately)
    /// vertices pinned.
    fn lscm(&self, chart: &Chart) -> Result<Vec<Vector2<f64>>> {
        let n = chart.verts.len();
        let pos = |i: usize| self.points[chart.verts[i] as usize];
        let far = |from: usize| {
            (0..n)
                .max_by(|&a, &b| {
                    (pos(a) - pos(from))
                        .norm_squared()
                        .total_cmp(&(pos(b) - pos(from)).norm_squared())
                })
                .unwrap_or(0)
        };
        let p0 = far(0);
        let p1 = far(p0);
        let pinned = [
            (p0, Vector2::zeros()),
            (p1, Vector2::new((pos(p1) - pos(p0)).norm(), 0.0)),
        ];
        // Unknowns: (u, v) of every free vertex; pinned vertices go to the right-hand side.
        let mut unknown = vec![usize::MAX; n];
        let mut free = 0;
        for (i, slot) in unknown.iter_mut().enumerate() {
            if i != p0 && i != p1 {
                *slot = free;
                free += 1;
            }
        }
        let mut lower = Vec::new();
        let mut rhs = vec![0.0; 2 * free];
        for (&t, c) in chart.tris.iter().zip(&chart.corners) {
            let (g, area) = self.gradients(t as usize);
            // Residuals (∇v − R90 ∇u)·sqrt(A): row x = Σ v g.x + u g.y, row y = Σ v g.y − u g.x.
            let mut rows = [[0.0; 6]; 2];
            for j in 0..3 {
                rows[0][2 * j] = g[j].y;
                rows[0][2 * j + 1] = g[j].x;
                rows[1][2 * j] = -g[j].x;
                rows[1][2 * j + 1] = g[j].y;
            }
            let index = |slot: usize| {
                let i = c[slot / 2] as usize;
                (unknown[i] != usize::MAX).then(|| 2 * unknown[i] + slot % 2)
            };
            let known = |slot: usize| {
                let i = c[slot / 2] as usize;
                pinned
                    .iter()
                    .find(|(p, _)| *p == i)
                    .map_or(0.0, |(_, uv)| uv[slot % 2])
            };
            for row in &rows {
                let fixed: f64 = (0..6).map(|s| row[s] * known(s)).sum();
                for a in 0..6 {
                    let Some(ia) = index(a) else { continue };
                    rhs[ia] -= area * row[a] * fixed;
                    for b in 0..6 {
                        if let Some(ib) = index(b).filter(|&ib| ib >= ia) {
                            lower.push(faer::sparse::Triplet::new(ib, ia, area * row[a] * row[b]));
                        }
                    }
                }
            }
        }
        solve_spd(2 * free, &lower, &mut rhs, 1)?;
        Ok((0..n)
            .map(|i| match pinned.iter().find(|(p, _)| *p == i) {
                Some((_, uv)) => *uv,
                None => Vector2::new(rhs[2 * unknown[i]], rhs[2 * unknown[i] + 1]),
            })
            .collect())
    }

    /// Local/global ARAP: fits a rotation to each triangle's Jacobian, then solves the
    /// cotangent-Laplacian system for the coordinates (first vertex held), `iterations` times.
    fn arap(&self, chart: &mut Chart, iterations: usize) -> Result<()> {
        let n = chart.verts.len();
        let grads: Vec<([Vector2<f64>; 3], f64)> = chart
            .tris
            .iter()
            .map(|&t| self.gradients(t as usize))
            .collect();
        // K = Σ A gᵢ·gⱼ over free vertices 1..n (vertex 0 is held where it is).
        let mut lower = Vec::new();
        for ((g, area), c) in grads.iter().zip(&chart.corners) {
            for a in 0..3 {
                for b in 0..3 {
                    let (i, j) = (c[a] as usize, c[b] as usize);
                    if i >= j && j > 0 {
                        lower.push(faer::sparse::Triplet::new(
                            i - 1,
                            j - 1,
                            area * g[a].dot(&g[b]),
                        ));
                    }
                }
            }
        }
        let m = n - 1;
        let llt = factor_spd(m, &lower)?;
        let held = chart.uv[0];
        for _ in 0..iterations {
            let mut rhs = vec![0.0; 2 * m];
            for ((g, area), c) in grads.iter().zip(&chart.corners) {
                // Jacobian rows ∇u, ∇v and the nearest rotation.
                let mut ju = Vector2::zeros();
                let mut jv = Vector2::zeros();
                for j in 0..3 {
                    let uv = chart.uv[c[j] as usize];
                    ju += g[j] * uv.x;
                    jv += g[j] * uv.y;
                }
                let theta = (jv.x - ju.y).atan2(ju.x + jv.y);
                let (s, co) = theta.sin_cos();
                let (ru, rv) = (Vector2::new(co, -s), Vector2::new(s, co));
                for a in 0..3 {
                    let i = c[a] as usize;
                    let mut bu = area * g[a].dot(&ru);
                    let mut bv = area * g[a].dot(&rv);
                    // Move the held vertex's terms to the right-hand side.
                    for b in 0..3 {
                        if c[b] == 0 {
                            let k = area * g[a].dot(&g[b]);
                            bu -= k * held.x;
                            bv -= k * held.y;
                        }
                    }
                    if i > 0 {
                        rhs[i - 1] += bu;
                        rhs[m + i - 1] += bv;
                    }
                }
            }
            llt.solve_in_place_with_conj(
                faer::Conj::No,
                faer::MatMut::from_column_major_slice_mut(&mut rhs, m, 2),
            );
            for i in 1..n {
                chart.uv[i] = Vector2::new(rhs[i - 1], rhs[m + i - 1]);
            }
        }
        Ok(())
    }

    /// Scales a chart's coordinates so that its flattened area equals its 3D area.
    fn match_area(&self, chart: &mut Chart) {
        let (mut a2, mut a3) = (0.0, 0.0);
        for (&t, c) in chart.tris.iter().zip(&chart.corners) {
            let [p, q, r] = c.map(|i| chart.uv[i as usize]);
            a2 += 0.5 * (q - p).perp(&(r - p));
            a3 += self.area3[t as usize];
        }
        if a2 > 0.0 && a3 > 0.0 {
            let s = (a3 / a2).sqrt();
            for uv in &mut chart.uv {
                *uv *= s;
            }
        }
    }

    fn chart_distortion(&self, chart: &Chart) -> Distortion {
        let index: HashMap<u32, usize> = chart
            .tris
            .iter()
            .enumerate()
            .map(|(k, &t)| (t, k))
            .collect();
        self.distortion(&chart.tris, |t, j| {
            chart.uv[chart.corners[index[&(t as u32)]][j] as usize]
        })
    }

    /// Distortion of `tris` whose corner `j` of triangle `t` lies at `uv(t, j)`.
    fn distortion(&self, tris: &[u32], uv: impl Fn(usize, usize) -> Vector2<f64>) -> Distortion {
        let angles = |p: [Vector2<f64>; 3]| {
            [0, 1, 2].map(|j| {
                let (e1, e2) = (p[(j + 1) % 3] - p[j], p[(j + 2) % 3] - p[j]);
                e1.perp(&e2).abs().atan2(e1.dot(&e2)).to_degrees()
            })
        };
        let mut d = Distortion::default();
        let mut total = 0.0;
        for &t in tris {
            let t = t as usize;
            let p2 = [0, 1, 2].map(|j| uv(t, j));
            let a2 = 0.5 * (p2[1] - p2[0]).perp(&(p2[2] - p2[0]));
            let a3 = self.area3[t];
            if a2 <= 0.0 {
                d.flipped += 1;
            }
            let area = (a2 / a3 - 1.0).abs();
            let (g2, g3) = (angles(p2), angles(self.local_triangle(t)));
            let angle = (0..3).map(|j| (g2[j] - g3[j]).abs()).sum::<f64>() / 3.0;
            d.area_mean += a3 * area;
            d.angle_mean_deg += a3 * angle;
            d.area_max = d.area_max.max(area);
            d.angle_max_deg = d.angle_max_deg.max(angle);
            total += a3;
        }
        if total > 0.0 {
            d.area_mean /= total;
            d.angle_mean_deg /= total;
        }
        d
    }
}

/// Turns each chart so that its principal axis lies along x and packs the charts on shelves
/// (tallest first), `gap` apart, in rows about as wide as the square root of their total
/// bounding-box area.
fn pack(charts: &mut [Chart], gap: f64) {
    for chart in charts.iter_mut() {
        let n = chart.uv.len().max(1) as f64;
        let mean: Vector2<f64> = chart.uv.iter().sum::<Vector2<f64>>() / n;
        let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
        for p in &chart.uv {
            let d = p - mean;
            sxx += d.x * d.x;
            sxy += d.x * d.y;
            syy += d.y * d.y;
        }
        let theta = 0.5 * (2.0 * sxy).atan2(sxx - syy);
        let (s, c) = theta.sin_cos();
        let lo = chart
            .uv
            .iter()
            .fold(Vector2::repeat(f64::INFINITY), |lo, p| {
                let d = p - mean;
                lo.inf(&Vector2::new(c * d.x + s * d.y, -s * d.x + c * d.y))
            });
        for p in &mut chart.uv {
            let d = *p - mean;
            *p = Vector2::new(c * d.x + s * d.y, -s * d.x + c * d.y) - lo;
        }
    }
    let size = |c: &Chart| {
        c.uv.iter()
            .fold(Vector2::zeros(), |m: Vector2<f64>, p| m.sup(p))
    };
    let sizes: Vec<Vector2<f64>> = charts.iter().map(size).collect();
    let mut order: Vec<usize> = (0..charts.len()).collect();
    order.sort_by(|&a, &b| sizes[b].y.total_cmp(&sizes[a].y).then(a.cmp(&b)));
    let box_area: f64 = sizes.iter().map(|s| (s.x + gap) * (s.y + gap)).sum();
    let widest = sizes.iter().map(|s| s.x).fold(0.0, f64::max);
    let row_width = box_area.sqrt().max(widest);
    let (mut x, mut y, mut shelf) = (0.0, 0.0, 0.0f64);
    for k in order {
        if x > 0.0 && x + sizes[k].x > row_width {
            x = 0.0;
            y += shelf + gap;
            shelf = 0.0;
        }
        let offset = Vector2::new(x, y);
        for p in &mut charts[k].uv {
            *p += offset;
        }
        x += sizes[k].x + gap;
        shelf = shelf.max(sizes[k].y);
    }
}

type Llt = faer::sparse::linalg::solvers::Llt<usize, f64>;

/// Sparse Cholesky factorisation of the symmetric positive definite `n × n` matrix given by its
/// lower-triangle entries (duplicates summed).
fn factor_spd(n: usize, lower: &[faer::sparse::Triplet<usize, usize, f64>]) -> Result<Llt> {
    let fail = |what: &str| Error::Invalid(format!("flattening a chart failed: {what}"));
    let a = faer::sparse::SparseColMat::<usize, f64>::try_new_from_triplets(n, n, lower)
        .map_err(|e| fail(&format!("{e:?}")))?;
    a.sp_cholesky(faer::Side::Lower)
        .map_err(|_| fail("the system is singular (a chart that is not a disc?)"))
}

/// Solves `A x = rhs` in place (`cols` right-hand sides, column-major) for the matrix of
/// [`factor_spd`].
fn solve_spd(
    n: usize,
    lower: &[faer::sparse::Triplet<usize, usize, f64>],
    rhs: &mut [f64],
    cols: usize,
) -> Result<()> {
    if n == 0 {
        return Ok(());
    }
    let llt = factor_spd(n, lower)?;
    llt.solve_in_place_with_conj(
        faer::Conj::No,
        faer::MatMut::from_column_major_slice_mut(rhs, n, cols),
    );
    if rhs.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(Error::Invalid(
            "flattening a chart failed: the solution is not finite".into(),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// An `nx × ny` grid of quads over `[0, w] × [0, h]`, two triangles per quad, lifted to 3D
    /// by `lift`.
    fn grid(
        nx: usize,
        ny: usize,
        w: f64,
        h: f64,
        lift: impl Fn(f64, f64) -> Vector3<f64>,
    ) -> (Vec<Vector3<f64>>, Vec<[u32; 3]>) {
        let mut points = Vec::new();
        for j in 0..=ny {
            for i in 0..=nx {
                points.push(lift(w * i as f64 / nx as f64, h * j as f64 / ny as f64));
            }
        }
        let id = |i: usize, j: usize| (j * (nx + 1) + i) as u32;
        let mut tris = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        (points, tris)
    }

    /// Largest relative difference between flattened and 3D edge lengths.
    fn edge_error(points: &[Vector3<f64>], tris: &[[u32; 3]], f: &Flattening) -> f64 {
        let mut worst = 0.0f64;
        for (t, tri) in tris.iter().enumerate() {
            for j in 0..3 {
                let l3 = (points[tri[(j + 1) % 3] as usize] - points[tri[j] as usize]).norm();
                let l2 = (f.corner_uv[3 * t + (j + 1) % 3] - f.corner_uv[3 * t + j]).norm();
                worst = worst.max((l2 / l3 - 1.0).abs());
            }
        }
        worst
    }

    /// Every chart is a connected disc: Euler characteristic V − E + F = 1, its vertices being
    /// (point, coordinate) pairs, so that a point on a cut inside a chart counts once per side.
    fn assert_charts_are_discs(tris: &[[u32; 3]], f: &Flattening) {
        for k in 0..f.charts as u32 {
            let mine: Vec<usize> = (0..tris.len())
                .filter(|&t| f.chart_of_triangle[t] == k)
                .collect();
            let key = |t: usize, j: usize| {
                let uv = f.corner_uv[3 * t + j];
                (tris[t][j], uv.x.to_bits(), uv.y.to_bits())
            };
            let mut v: Vec<_> = mine
                .iter()
                .flat_map(|&t| (0..3).map(move |j| key(t, j)))
                .collect();
            v.sort_unstable();
            v.dedup();
            let mut e: Vec<_> = mine
                .iter()
                .flat_map(|&t| {
                    (0..3).map(move |j| {
                        let (a, b) = (key(t, j), key(t, (j + 1) % 3));
                        (a.min(b), a.max(b))
                    })
                })
                .collect();
            e.sort_unstable();
            e.dedup();
            let chi = v.len() as i64 - e.len() as i64 + mine.len() as i64;
            assert_eq!(chi, 1, "chart {k} is not a disc");
        }
    }

    /// Bounding boxes of the charts in the plane are pairwise disjoint.
    fn assert_charts_apart(f: &Flattening) {
        let mut boxes = vec![
            (
                Vector2::repeat(f64::INFINITY),
                Vector2::repeat(f64::NEG_INFINITY)
            );
            f.charts
        ];
        for (c, uv) in f.corner_uv.iter().enumerate() {
            let b = &mut boxes[f.chart_of_triangle[c / 3] as usize];
            b.0 = b.0.inf(uv);
            b.1 = b.1.sup(uv);
        }
        for i in 0..boxes.len() {
            for j in i + 1..boxes.len() {
                let (a, b) = (boxes[i], boxes[j]);
                let apart = a.1.x < b.0.x || b.1.x < a.0.x || a.1.y < b.0.y || b.1.y < a.0.y;
                assert!(apart, "charts {i} and {j} overlap: {a:?} {b:?}");
            }
        }
    }

    fn tube(
        n_around: usize,
        n_along: usize,
        r: f64,
        len: f64,
    ) -> (Vec<Vector3<f64>>, Vec<[u32; 3]>) {
        let mut points = Vec::new();
        for j in 0..=n_along {
            for i in 0..n_around {
                let a = 2.0 * PI * i as f64 / n_around as f64;
                points.push(Vector3::new(
                    r * a.cos(),
                    len * j as f64 / n_along as f64,
                    r * a.sin(),
                ));
            }
        }
        let id = |i: usize, j: usize| (j * n_around + i % n_around) as u32;
        let mut tris = Vec::new();
        for j in 0..n_along {
            for i in 0..n_around {
                tris.push([id(i, j), id(i, j + 1), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i + 1, j)]);
            }
        }
        (points, tris)
    }

    fn hemisphere(n_lat: usize, n_lon: usize, r: f64) -> (Vec<Vector3<f64>>, Vec<[u32; 3]>) {
        let mut points = vec![Vector3::new(0.0, r, 0.0)];
        for j in 1..=n_lat {
            let polar = 0.5 * PI * j as f64 / n_lat as f64;
            for i in 0..n_lon {
                let a = 2.0 * PI * i as f64 / n_lon as f64;
                points.push(
                    r * Vector3::new(polar.sin() * a.cos(), polar.cos(), polar.sin() * a.sin()),
                );
            }
        }
        let id = |i: usize, j: usize| (1 + (j - 1) * n_lon + i % n_lon) as u32;
        let mut tris = Vec::new();
        for i in 0..n_lon {
            tris.push([0, id(i + 1, 1), id(i, 1)]);
        }
        for j in 1..n_lat {
            for i in 0..n_lon {
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        (points, tris)
    }

    /// Triangles in each chart.
    fn chart_sizes(f: &Flattening) -> Vec<usize> {
        let mut sizes = vec![0usize; f.charts];
        for &c in &f.chart_of_triangle {
            sizes[c as usize] += 1;
        }
        sizes
    }

    fn report(name: &str, f: &Flattening) {
        let d = f.distortion;
        eprintln!("{name}: chart sizes {:?}", chart_sizes(f));
        eprintln!(
            "{name}: {} charts, area mean {:.2e} max {:.2e}, angle mean {:.2e}° max {:.2e}°, {} flipped",
            f.charts, d.area_mean, d.area_max, d.angle_mean_deg, d.angle_max_deg, d.flipped
        );
    }

    #[test]
    fn flat_grid_flattens_isometrically() {
        // A square tilted in 3D, in centimetres (any units).
        let (u, v) = (Vector3::new(0.6, 0.8, 0.0), Vector3::new(0.0, 0.0, 1.0));
        let (points, tris) = grid(12, 12, 50.0, 50.0, |x, y| {
            Vector3::new(3.0, -2.0, 7.0) + u * x + v * y
        });
        let f = flatten(&points, &tris, &FlattenOptions::default()).expect("flatten");
        report("grid", &f);
        assert_eq!(f.charts, 1);
        assert_eq!(f.corner_uv.len(), 3 * tris.len());
        assert!(edge_error(&points, &tris, &f) < 1e-6);
        assert!(f.distortion.area_max < 1e-6 && f.distortion.angle_max_deg < 1e-4);
        assert_eq!(f.distortion.flipped, 0);
        // Corners of one point share their coordinate within the chart.
        let mut at: HashMap<u32, Vector2<f64>> = HashMap::new();
        for (c, &p) in tris.iter().flatten().enumerate() {
            let uv = *at.entry(p).or_insert(f.corner_uv[c]);
            assert!((uv - f.corner_uv[c]).norm() < 1e-12);
        }
    }

    #[test]
    fn lscm_alone_is_exact_on_a_developable_chart() {
        let (points, tris) = grid(8, 5, 1.0, 0.6, |x, y| Vector3::new(x, y, 0.3 * x * x));
        let opts = FlattenOptions {
            arap_iterations: 0,
            ..Default::default()
        };
        let f = flatten(&points, &tris, &opts).expect("flatten");
        // A parabolic cylinder made of planar quads: developable, conformal = isometric.
        assert_eq!(f.charts, 1);
        assert!(
            edge_error(&points, &tris, &f) < 1e-6,
            "{}",
            edge_error(&points, &tris, &f)
        );
    }

    #[test]
    fn distortion_against_a_reference_is_zero_for_itself_and_known_for_a_stretch() {
        let (points, tris) = hemisphere(8, 24, 0.3);
        let f = flatten(&points, &tris, &FlattenOptions::default()).expect("flatten");
        let same = f.distortion_against(&f.corner_uv);
        assert!(
            same.area_max < 1e-12 && same.angle_max_deg < 1e-9,
            "{same:?}"
        );
        // Mirrored and moved: still the same up to a rigid motion and reflection.
        let mirrored: Vec<Vector2<f64>> = f
            .corner_uv
            .iter()
            .map(|p| Vector2::new(3.0 - p.x, p.y + 1.0))
            .collect();
        let m = f.distortion_against(&mirrored);
        assert!(m.area_max < 1e-9 && m.angle_max_deg < 1e-7, "{m:?}");
        // The reference stretched 1.25× along x: every triangle's area is 1/1.25 of it.
        let stretched: Vec<Vector2<f64>> = f
            .corner_uv
            .iter()
            .map(|p| Vector2::new(1.25 * p.x, p.y))
            .collect();
        let s = f.distortion_against(&stretched);
        assert!(
            (s.area_mean - 0.2).abs() < 1e-9 && (s.area_max - 0.2).abs() < 1e-9,
            "{s:?}"
        );
        assert!(s.angle_mean_deg > 0.5, "{s:?}");
    }

    #[test]
    fn tube_is_cut_into_discs_and_flattens_with_low_distortion() {
        let (points, tris) = tube(32, 20, 0.1, 0.5);
        let f = flatten(&points, &tris, &FlattenOptions::default()).expect("flatten");
        report("tube", &f);
        assert_charts_are_discs(&tris, &f);
        assert_charts_apart(&f);
        assert_eq!(f.charts, 1, "the tube is cut open, not cut apart");
        assert!(f.distortion.area_mean < 0.02, "{:?}", f.distortion);
        assert!(
            edge_error(&points, &tris, &f) < 1e-6,
            "{}",
            edge_error(&points, &tris, &f)
        );
        assert_eq!(f.distortion.flipped, 0);
    }

    /// A gently rising ramp wound one and a quarter turns: nearly developable, it would
    /// flatten into an annulus of 450°, lying over itself. It is split into charts that don't.
    #[test]
    fn a_chart_that_would_lie_over_itself_is_split() {
        let (nr, nt) = (4, 120);
        let (points, tris) = grid(nr, nt, 0.1, 2.5 * PI, |r, t| {
            let r = 0.2 + r;
            Vector3::new(r * t.cos(), 0.01 * t, r * t.sin())
        });
        let f = flatten(&points, &tris, &FlattenOptions::default()).expect("flatten");
        report("ramp", &f);
        assert!(f.charts > 1, "one chart lies over itself");
        assert_charts_are_discs(&tris, &f);
        assert_charts_apart(&f);
        assert_eq!(f.distortion.flipped, 0);
        // No chart's outline crosses itself.
        for k in 0..f.charts as u32 {
            let mut chart = Chart {
                tris: Vec::new(),
                verts: Vec::new(),
                corners: Vec::new(),
                uv: Vec::new(),
            };
            for t in (0..tris.len()).filter(|&t| f.chart_of_triangle[t] == k) {
                let c = [0, 1, 2].map(|j| {
                    chart.uv.push(f.corner_uv[3 * t + j]);
                    (chart.uv.len() - 1) as u32
                });
                chart.corners.push(c);
            }
            // Corners of one point share their coordinate: merge them so edges are shared.
            let mut id: HashMap<(u64, u64), u32> = HashMap::new();
            let uv = chart.uv.clone();
            for c in &mut chart.corners {
                *c = c.map(|i| {
                    let p = uv[i as usize];
                    *id.entry((p.x.to_bits(), p.y.to_bits())).or_insert(i)
                });
            }
            assert!(!outline_overlaps(&chart), "chart {k} lies over itself");
        }
    }

    #[test]
    fn hemisphere_flattens_with_bounded_distortion() {
        let (points, tris) = hemisphere(16, 48, 0.3);
        let f = flatten(&points, &tris, &FlattenOptions::default()).expect("flatten");
        report("hemisphere", &f);
        assert_charts_are_discs(&tris, &f);
        // Pieces left between cones are given to their neighbours: no slivers.
        assert!(chart_sizes(&f).iter().all(|&n| n >= SMALL_CHART));
        assert_charts_apart(&f);
        assert!(f.distortion.area_mean < 0.05, "{:?}", f.distortion);
        assert!(f.distortion.area_max < 0.5, "{:?}", f.distortion);
        assert!(f.distortion.angle_mean_deg < 5.0, "{:?}", f.distortion);
        assert_eq!(f.distortion.flipped, 0);
        // Without splitting (one chart, any distortion accepted) it is worse: splitting matters.
        let one = FlattenOptions {
            max_area_distortion: f64::INFINITY,
            ..Default::default()
        };
        let g = flatten(&points, &tris, &one).expect("flatten");
        report("hemisphere, one chart", &g);
        assert_eq!(g.charts, 1);
        assert!(g.distortion.area_mean > f.distortion.area_mean);
        // On that one doubly curved chart, ARAP brings edge lengths closer than LSCM alone.
        let lscm = FlattenOptions {
            arap_iterations: 0,
            ..one
        };
        let h = flatten(&points, &tris, &lscm).expect("flatten");
        report("hemisphere, one chart, LSCM only", &h);
        let (e_arap, e_lscm) = (
            edge_error(&points, &tris, &g),
            edge_error(&points, &tris, &h),
        );
        eprintln!(
            "hemisphere, one chart: worst edge length error ARAP {e_arap:.3}, LSCM {e_lscm:.3}"
        );
        assert!(e_arap < 0.8 * e_lscm, "ARAP {e_arap} vs LSCM {e_lscm}");
        assert!(g.distortion.angle_mean_deg < h.distortion.angle_mean_deg + 5.0);
    }

    #[test]
    fn closed_sphere_is_cut_and_split_into_discs() {
        let (mut points, mut tris) = hemisphere(12, 36, 0.2);
        // The other half, mirrored (y → −y) and wound the other way, sharing the equator.
        let n = points.len() as u32;
        let equator = n - 36;
        let mirrored: Vec<Vector3<f64>> = points[..equator as usize]
            .iter()
            .map(|p| Vector3::new(p.x, -p.y, p.z))
            .collect();
        points.extend(mirrored);
        let mirror = |v: u32| if v >= equator { v } else { v + n };
        let lower: Vec<[u32; 3]> = tris
            .iter()
            .map(|t| [mirror(t[0]), mirror(t[2]), mirror(t[1])])
            .collect();
        tris.extend(lower);
        let f = flatten(&points, &tris, &FlattenOptions::default()).expect("flatten");
        report("sphere", &f);
        assert_charts_are_discs(&tris, &f);
        assert!(chart_sizes(&f).iter().all(|&n| n >= SMALL_CHART));
        assert_charts_apart(&f);
        assert!(f.charts > 1);
        assert!(f.distortion.area_mean < 0.05, "{:?}", f.distortion);
        assert_eq!(f.distortion.flipped, 0);
    }

    #[test]
    fn folded_panel_recovers_its_true_lengths() {
        // A 0.8 m × 0.5 m panel folded by 90° along x = 0.3, then turned in space.
        let fold = |x: f64, y: f64| {
            let p = if x <= 0.3 {
                Vector3::new(x, y, 0.0)
            } else {
                Vector3::new(0.3, y, x - 0.3)
            };
            let (s, c) = 0.7f64.sin_cos();
            Vector3::new(c * p.x - s * p.z, p.y, s * p.x + c * p.z) + Vector3::new(1.0, 0.5, 0.2)
        };
        let (points, tris) = grid(16, 10, 0.8, 0.5, fold);
        // The fold is a crease: two charts, each exact.
        let f = flatten(&points, &tris, &FlattenOptions::default()).expect("flatten");
        report("folded, creased", &f);
        assert_eq!(f.charts, 2);
        assert_charts_apart(&f);
        assert!(edge_error(&points, &tris, &f) < 1e-6);
        // With creases allowed up to 100°, the panel comes back whole, still exact.
        let whole = FlattenOptions {
            crease_deg: 100.0,
            ..Default::default()
        };
        let g = flatten(&points, &tris, &whole).expect("flatten");
        report("folded, whole", &g);
        assert_eq!(g.charts, 1);
        assert!(
            edge_error(&points, &tris, &g) < 1e-6,
            "{}",
            edge_error(&points, &tris, &g)
        );
        assert!(g.distortion.area_max < 1e-6);
        let area: f64 = (0..tris.len())
            .map(|t| {
                let [a, b, c] = [0, 1, 2].map(|j| g.corner_uv[3 * t + j]);
                0.5 * (b - a).perp(&(c - a))
            })
            .sum();
        assert!((area - 0.4).abs() < 1e-9, "{area}");
    }

    #[test]
    fn garment_panels_placed_in_3d_recover_their_pattern_lengths() {
        // The skirt sample's panels, meshed and placed around the body, without their material
        // coordinates: flattening must give back the pattern's edge lengths.
        let g = crate::scene::samples::skirt(crate::garment::Fabric::default());
        let mesh = crate::mesh::mesh_garment(&g, &crate::mesh::MeshOptions::with_edge(0.03))
            .expect("mesh");
        let f =
            flatten(&mesh.positions, &mesh.triangles, &FlattenOptions::default()).expect("flatten");
        report("skirt panels", &f);
        assert_eq!(f.charts, mesh.panel_names.len());
        assert_charts_apart(&f);
        for (t, tri) in mesh.triangles.iter().enumerate() {
            for j in 0..3 {
                let (a, b) = (tri[j] as usize, tri[(j + 1) % 3] as usize);
                let pattern = (mesh.material[b] - mesh.material[a]).norm();
                let flat = (f.corner_uv[3 * t + (j + 1) % 3] - f.corner_uv[3 * t + j]).norm();
                assert!(
                    (flat - pattern).abs() < 1e-6 * pattern.max(1.0),
                    "{flat} vs {pattern}"
                );
            }
        }
    }

    #[test]
    fn bent_panel_recovers_its_true_lengths() {
        // A panel rolled onto a cylinder of radius 0.2 m (smooth, developable, no crease).
        let bend =
            |x: f64, y: f64| Vector3::new(0.2 * (x / 0.2).sin(), y, 0.2 * (1.0 - (x / 0.2).cos()));
        let (points, tris) = grid(40, 10, 0.9, 0.5, bend);
        let f = flatten(&points, &tris, &FlattenOptions::default()).expect("flatten");
        report("bent", &f);
        assert_eq!(f.charts, 1);
        assert!(edge_error(&points, &tris, &f) < 1e-6);
    }

    #[test]
    fn bad_input_is_an_error() {
        let opts = FlattenOptions::default();
        let p = vec![
            Vector3::zeros(),
            Vector3::x(),
            Vector3::y(),
            Vector3::new(2.0, 0.0, 0.0),
        ];
        let err = |pts: &[Vector3<f64>], tris: &[[u32; 3]]| {
            flatten(pts, tris, &opts)
                .expect_err("bad input")
                .to_string()
        };
        assert!(err(&p, &[]).contains("empty"));
        assert!(err(&[], &[[0, 1, 2]]).contains("empty"));
        assert!(err(&p, &[[0, 1, 9]]).contains("outside"));
        let mut nan = p.clone();
        nan[2].y = f64::NAN;
        assert!(err(&nan, &[[0, 1, 2]]).contains("point 2"));
        assert!(err(&p, &[[0, 1, 2], [0, 1, 3]]).contains("triangle 1 has zero area"));
        assert!(err(&p, &[[0, 0, 2]]).contains("zero area"));
    }

    #[test]
    fn triangles_wound_against_their_neighbours_are_turned_over() {
        let (points, mut tris) = grid(6, 6, 1.0, 1.0, |x, y| Vector3::new(x, 0.2 * y, y));
        for t in tris.iter_mut().step_by(3) {
            t.swap(0, 1);
        }
        let f = flatten(&points, &tris, &FlattenOptions::default()).expect("flatten");
        assert_eq!(f.charts, 1);
        assert!(edge_error(&points, &tris, &f) < 1e-9);
        assert!(f.distortion.area_max < 1e-9 && f.distortion.flipped == 0);
        // Corners keep the input's winding: triangles wound one way come out counter-clockwise,
        // the others clockwise.
        let ccw = |t: usize| {
            let [a, b, c] = [0, 1, 2].map(|j| f.corner_uv[3 * t + j]);
            (b - a).perp(&(c - a)) > 0.0
        };
        for t in 0..tris.len() {
            assert_eq!(ccw(t) == ccw(0), t % 3 == 0, "triangle {t}");
        }
    }

    #[test]
    fn non_manifold_edges_cut_charts() {
        // Three triangles on one edge (a fin), and a fourth wound the other way (turned over,
        // it joins its neighbour).
        let p = vec![
            Vector3::zeros(),
            Vector3::x(),
            Vector3::y(),
            Vector3::new(0.5, -1.0, 0.0),
            Vector3::new(0.5, 0.0, 1.0),
            Vector3::new(1.0, 1.0, 0.0),
        ];
        let tris = [[0, 1, 2], [1, 0, 3], [0, 1, 4], [1, 2, 5]];
        let f = flatten(&p, &tris, &FlattenOptions::default()).expect("flatten");
        assert_eq!(f.charts, 3);
        assert_eq!(f.chart_of_triangle[0], f.chart_of_triangle[3]);
        assert!(edge_error(&p, &tris, &f) < 1e-9);
        assert_charts_apart(&f);
    }
}
