//! How far one Newton iteration may move the cloth: the per-vertex move limit, the closing
//! limits of found pairs ([`ClosingPair`]) and the backtracking line search.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::newton::Potential;
use super::Simulator;
use crate::collide::distance::{point_triangle, segment_segment};
use crate::collide::{CollisionDetector, Contact};

/// Most a found cloth–cloth pair may close in one Newton iteration, as a fraction of its gap.
const PAIR_CLOSE_FRACTION: f64 = 0.8;

/// A found cloth–cloth pair (vertex–triangle or edge–edge) and how far it may close in one
/// Newton iteration. The quadratic repulsion is finite, so a pair that closes by more than its
/// gap d within one iteration can land on the other side, where nothing pushes it back, and
/// the line search, which sees only the end points, accepts it. Along a linear move the gap
/// closes by at most (bounds of the move, each valid for every step length α ≤ 1 and scaling
/// with it):
/// - isotropic: the largest relative move of a vertex of one side against one of the other,
///   max ‖Δaᵢ − Δbⱼ‖ (the bound of additive CCD, Li, Kaufman & Jiang 2021);
/// - normal: with c_a, c_b the moves of the closest points (their barycentric blends) and n
///   the unit vector from b's closest point to a's,
///   max(0, −n·(c_a − c_b)) + max ‖Δaᵢ − c_a‖ + max ‖Δbⱼ − c_b‖. Each side is within its
///   vertices' deviation of its closest point's translate, and the distance between two
///   convex sets is convex in their relative translation, so it stays above its tangent.
///   Layers sliding over each other close by ~0.
///
/// The smaller is kept below `PAIR_CLOSE_FRACTION` × d.
#[derive(Debug, Clone, Copy)]
pub(super) struct ClosingPair {
    /// Cloth vertices: side a is `v[..split]`, side b `v[split..count]` (empty for a body,
    /// which holds still within a Newton iteration).
    v: [u32; 4],
    /// 1 for a vertex against a triangle or a body face, 2 for an edge against an edge.
    split: usize,
    /// Cloth vertices in `v`: 4, or `split` against a body.
    count: usize,
    /// Barycentric weights of each side's closest point.
    w: [f64; 4],
    /// Unit vector from b's closest point to a's (zero when they touch).
    n: Vector3<f64>,
    /// Most the gap may close, m.
    allowed: f64,
}

impl ClosingPair {
    /// The found cloth–cloth pairs of `contacts` at positions `x`, and with `body_narrow`
    /// the cloth–body ones: a cloth vertex (or edge) at signed distance d from a body face (or
    /// sharp edge) may approach it by at most max(d/2, `body_narrow`) per iteration, along the
    /// face's outward normal (or away from the edge), and slide freely. The repulsion is
    /// one-sided, so this is about how deep one iteration may drive cloth into a moving body,
    /// not about passing through: without it a skirt went several times deeper into the
    /// legs; held to it in every direction, cloth sliding over a body crawled (a fraction of
    /// a millimetre an iteration on fine meshes).
    pub(super) fn all(
        x: &[Vector3<f64>],
        contacts: &[Contact],
        body_narrow: Option<f64>,
    ) -> Vec<ClosingPair> {
        contacts
            .iter()
            .filter_map(|c| {
                let p = |i: u32| x[i as usize];
                let (v, split, count, w, n, allowed) = match *c {
                    Contact::VertexTriangle { v, t } => {
                        let q = point_triangle(&p(v), &p(t[0]), &p(t[1]), &p(t[2]));
                        let [b0, b1, b2] = q.bary;
                        let w = [1.0, b0, b1, b2];
                        let n = p(v) - (p(t[0]) * b0 + p(t[1]) * b1 + p(t[2]) * b2);
                        (
                            [v, t[0], t[1], t[2]],
                            1,
                            4,
                            w,
                            n,
                            PAIR_CLOSE_FRACTION * q.dist,
                        )
                    }
                    Contact::EdgeEdge { a, b } => {
                        let q = segment_segment(&p(a[0]), &p(a[1]), &p(b[0]), &p(b[1]));
                        let w = [1.0 - q.s, q.s, 1.0 - q.t, q.t];
                        let n =
                            (p(a[0]) * w[0] + p(a[1]) * w[1]) - (p(b[0]) * w[2] + p(b[1]) * w[3]);
                        (
                            [a[0], a[1], b[0], b[1]],
                            2,
                            4,
                            w,
                            n,
                            PAIR_CLOSE_FRACTION * q.dist,
                        )
                    }
                    Contact::VertexObstacle { v, tri, .. } => {
                        let narrow = body_narrow?;
                        let n = (tri[1] - tri[0]).cross(&(tri[2] - tri[0]));
                        let allowed = (0.5 * c.distance(x)).max(narrow);
                        ([v, 0, 0, 0], 1, 1, [1.0, 0.0, 0.0, 0.0], n, allowed)
                    }
                    Contact::EdgeObstacle { a, edge, .. } => {
                        let narrow = body_narrow?;
                        let q = segment_segment(&p(a[0]), &p(a[1]), &edge[0], &edge[1]);
                        let w = [1.0 - q.s, q.s, 0.0, 0.0];
                        let n = (p(a[0]) * w[0] + p(a[1]) * w[1])
                            - (edge[0] * (1.0 - q.t) + edge[1] * q.t);
                        let allowed = (0.5 * q.dist).max(narrow);
                        ([a[0], a[1], 0, 0], 2, 2, w, n, allowed)
                    }
                };
                Some(ClosingPair {
                    v,
                    split,
                    count,
                    w,
                    n: n.try_normalize(1e-12).unwrap_or_else(Vector3::zeros),
                    allowed,
                })
            })
            .collect()
    }

    /// Bound on how much the gap closes along `step`: the smaller of the isotropic and normal
    /// bounds (`relative`), or the absolute max ‖Δaᵢ‖ + max ‖Δbⱼ‖, which only shrinks when
    /// any vertex's move does.
    fn closing(&self, step: &[Vector3<f64>], relative: bool) -> f64 {
        let d = self.v.map(|i| step[i as usize]);
        let (a, b) = d[..self.count].split_at(self.split);
        if !relative {
            let m = |s: &[Vector3<f64>]| s.iter().map(|p| p.norm()).fold(0.0, f64::max);
            return m(a) + m(b);
        }
        let isotropic = if b.is_empty() {
            a.iter().map(|p| p.norm()).fold(0.0, f64::max)
        } else {
            a.iter()
                .flat_map(|p| b.iter().map(move |q| (p - q).norm()))
                .fold(0.0, f64::max)
        };
        if self.n == Vector3::zeros() {
            return isotropic;
        }
        let (wa, wb) = self.w[..self.count].split_at(self.split);
        let centre = |s: &[Vector3<f64>], w: &[f64]| -> Vector3<f64> {
            s.iter().zip(w).map(|(p, w)| p * *w).sum()
        };
        let (ca, cb) = (centre(a, wa), centre(b, wb));
        let spread = |s: &[Vector3<f64>], c: &Vector3<f64>| {
            s.iter().map(|p| (p - c).norm()).fold(0.0, f64::max)
        };
        let normal = (-self.n.dot(&(ca - cb))).max(0.0) + spread(a, &ca) + spread(b, &cb);
        normal.min(isotropic)
    }
}

/// Shortens the moves of the vertices of every pair in `pairs` that `step` would close by more
/// than it may ([`ClosingPair`]); whether any was. Scaling one pair's vertices can undo another
/// pair's relative bound, so a few passes use the relative bound and a last one the absolute
/// bound, which later scalings cannot undo: every pair then holds.
pub(super) fn limit_pair_closing(step: &mut [Vector3<f64>], pairs: &[ClosingPair]) -> bool {
    let mut any = false;
    for pass in 0..4 {
        let relative = pass < 3;
        let mut changed = false;
        for p in pairs {
            let c = p.closing(step, relative);
            if c > p.allowed {
                let s = p.allowed / c;
                for &i in &p.v[..p.count] {
                    step[i as usize] *= s;
                }
                changed = true;
            }
        }
        any |= changed;
        if !changed {
            break;
        }
    }
    any
}

/// The largest uniform scale of `dx` within the move limit and the pairs' closing limits (at
/// most 1).
pub(super) fn uniform_limit(dx: &[Vector3<f64>], limit: f64, pairs: &[ClosingPair]) -> f64 {
    let per_vertex = dx
        .iter()
        .map(|d| limit / d.norm().max(f64::MIN_POSITIVE))
        .fold(1.0, f64::min);
    pairs
        .iter()
        .map(|p| p.allowed / p.closing(dx, true).max(f64::MIN_POSITIVE))
        .fold(per_vertex, f64::min)
}

/// `dx` within the move limit and the pairs' closing limits; and whether it was shortened.
pub(super) fn limit_step(
    dx: &[Vector3<f64>],
    limit: f64,
    pairs: &[ClosingPair],
) -> (Vec<Vector3<f64>>, bool) {
    let (mut step, clipped) = clip_to_limit(dx, limit);
    let paired = limit_pair_closing(&mut step, pairs);
    (step, clipped || paired)
}

/// In fast mode without self-collision, how far a vertex touching a body may move near an edge
/// where the body's surface turns in the one Newton iteration that ends a step, m; a step whose iteration
/// moved one further iterates on ([`SimParams::newton_exact`]).
pub const FAST_CONTACT_MOVE_M: f64 = 1e-3;

/// Whether a cloth vertex touching a body moved more than [`FAST_CONTACT_MOVE_M`] (by
/// `alpha · step` from `x`) where the body's surface turns within its reach: an edge of that
/// body turning by more than [`SURFACE_TURN_DEG`](crate::collide::SURFACE_TURN_DEG) within
/// the move plus `reach` of where it started, or a crease contact of its own. One linearised
/// step of cloth sliding over a sharp edge takes the repulsion of the wrong side of the edge,
/// and the next step's repulsion launches the cloth; where the body is flat across the move
/// (a finely tessellated smooth body, a face away from its edges) the linearisation holds.
pub(super) fn slid_over_crease(
    detector: &CollisionDetector,
    contacts: &[Contact],
    x: &[Vector3<f64>],
    step: &[Vector3<f64>],
    alpha: f64,
    reach: f64,
) -> bool {
    let moved = |v: u32| step[v as usize].norm() * alpha;
    contacts.iter().any(|c| match c {
        Contact::VertexObstacle { v, face, .. } => {
            let m = moved(*v);
            m > FAST_CONTACT_MOVE_M
                && detector.crease_within(face[0] as usize, &x[*v as usize], m + reach)
        }
        Contact::EdgeObstacle { a, .. } => a.iter().any(|&v| moved(v) > FAST_CONTACT_MOVE_M),
        _ => false,
    })
}

/// `dx` with each vertex's move shortened to `limit`; and whether any was.
fn clip_to_limit(dx: &[Vector3<f64>], limit: f64) -> (Vec<Vector3<f64>>, bool) {
    let step: Vec<Vector3<f64>> = dx
        .par_iter()
        .map(|d| {
            let l = d.norm();
            if l > limit {
                d * (limit / l)
            } else {
                *d
            }
        })
        .collect();
    let clipped = dx.iter().any(|d| d.norm() > limit);
    (step, clipped)
}

/// A step the line search accepted.
pub(super) struct Accepted {
    /// The (limited) direction searched along.
    pub(super) step: Vec<Vector3<f64>>,
    /// Whether the move limits shortened it.
    pub(super) clipped: bool,
    /// Its longest vertex move, m.
    pub(super) step_longest: f64,
    /// The step length taken.
    pub(super) alpha: f64,
    /// The positions reached.
    pub(super) x: Vec<Vector3<f64>>,
    /// Their potential.
    pub(super) energy: f64,
}

impl Simulator {
    /// The last, short step of a converged Newton iteration (`dx` within the move limits):
    /// the positions it reaches and their energy, if that decreases on `energy` at `x`.
    pub(super) fn converged_step(
        &self,
        potential: &Potential<'_>,
        pairs: &[ClosingPair],
        x: &[Vector3<f64>],
        dx: &[Vector3<f64>],
        energy: f64,
    ) -> Option<(Vec<Vector3<f64>>, f64)> {
        let (mut step, _) = limit_step(dx, potential.inc.max_move, pairs);
        self.tie_welds(&mut step);
        let step_slope: f64 = self.grad.iter().zip(&step).map(|(g, d)| g.dot(d)).sum();
        let trial: Vec<Vector3<f64>> = x.iter().zip(&step).map(|(a, d)| a + d).collect();
        let e = potential.at(self, &trial);
        (e.is_finite() && e <= energy + 1e-4 * step_slope).then_some((trial, e))
    }

    /// Backtracking (Armijo) line search from `x`, with potential `energy`, along the Newton
    /// direction `dx` of slope `slope`, limited to the move limits; `None` when twelve
    /// halvings find no decrease.
    pub(super) fn line_search(
        &self,
        potential: &Potential<'_>,
        pairs: &[ClosingPair],
        x: &[Vector3<f64>],
        dx: &[Vector3<f64>],
        slope: f64,
        energy: f64,
    ) -> Option<Accepted> {
        let max_move = potential.inc.max_move;
        // The move limit clips vertices one by one: a few vertices that want to travel far
        // (a fold pushed out of a body) no longer shrink everybody else's step, which
        // stalled whole garments at α ≈ 0.1 for every iteration. The clipped direction is
        // still a descent direction when its slope is negative; otherwise scale uniformly.
        let (mut step, clipped) = limit_step(dx, max_move, pairs);
        self.tie_welds(&mut step);
        let mut step_slope: f64 = self.grad.iter().zip(&step).map(|(g, d)| g.dot(d)).sum();
        if clipped && step_slope >= 0.0 {
            // Uniform scaling by the tightest ratio keeps every vertex and pair within its
            // limit.
            let s = uniform_limit(dx, max_move, pairs);
            step.iter_mut().zip(dx).for_each(|(o, d)| *o = d * s);
            step_slope = slope * s;
        }
        let step_longest = step.iter().map(|d| d.norm()).fold(0.0, f64::max);
        let mut alpha = 1.0;
        let mut trial: Vec<Vector3<f64>> = x.to_vec();
        for _ in 0..12 {
            trial
                .par_iter_mut()
                .zip(x.par_iter().zip(step.par_iter()))
                .for_each(|(t, (xi, di))| *t = xi + di * alpha);
            let e = potential.at(self, &trial);
            if e.is_finite() && e <= energy + 1e-4 * alpha * step_slope {
                return Some(Accepted {
                    step,
                    clipped,
                    step_longest,
                    alpha,
                    x: trial,
                    energy: e,
                });
            }
            alpha *= 0.5;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cloth vertex 1 mm above a body face approaches it by at most max(d/2, narrow) in an
    /// iteration, and slides along it freely; without a narrow limit body contacts are not
    /// limited at all.
    #[test]
    fn cloth_on_a_body_slides_freely_but_approaches_slowly() {
        let tri = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
        ];
        let x = vec![Vector3::new(0.2, 0.2, 0.001)];
        let contacts = vec![Contact::VertexObstacle {
            v: 0,
            tri,
            face: [0, 0],
        }];
        let narrow = 0.0015;
        let pairs = ClosingPair::all(&x, &contacts, Some(narrow));
        let mut slide = vec![Vector3::new(0.004, -0.003, 0.0)];
        assert!(!limit_pair_closing(&mut slide, &pairs));
        let mut dive = vec![Vector3::new(0.004, 0.0, -0.005)];
        assert!(limit_pair_closing(&mut dive, &pairs));
        assert!((-dive[0].z - narrow).abs() < 1e-12, "{:?}", dive[0]);
        assert!(ClosingPair::all(&x, &contacts, None).is_empty());
    }

    /// After `limit_pair_closing`, no found pair comes closer than (1 − 0.8) of its gap
    /// anywhere along the step, sampled finely, for random close pairs and random steps many
    /// times their gap; a pair moving together or sliding is left alone.
    #[test]
    fn limited_steps_never_close_a_pair_past_its_gap() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut r = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut limited = 0;
        for case in 0..400 {
            // A triangle, a vertex above it, an edge above it and one of its own edges; a few
            // millimetres apart.
            let mut x: Vec<Vector3<f64>> = vec![
                Vector3::new(0.0, 0.0, 0.0),
                Vector3::new(0.02, 0.0, 0.0),
                Vector3::new(0.0, 0.02, 0.0),
            ];
            x.push(Vector3::new(
                0.005 + 0.01 * r(),
                0.005 + 0.01 * r(),
                0.002 + 0.003 * r(),
            ));
            x.push(Vector3::new(0.003, 0.01 + 0.01 * r(), 0.004 + 0.003 * r()));
            x.push(Vector3::new(0.012, -0.01 + 0.01 * r(), 0.003 + 0.003 * r()));
            let contacts = vec![
                Contact::VertexTriangle { v: 3, t: [0, 1, 2] },
                Contact::VertexTriangle { v: 4, t: [0, 1, 2] },
                Contact::EdgeEdge {
                    a: [4, 5],
                    b: [1, 2],
                },
                Contact::EdgeEdge {
                    a: [3, 4],
                    b: [0, 2],
                },
            ];
            let pairs = ClosingPair::all(&x, &contacts, None);
            let dx: Vec<Vector3<f64>> = (0..x.len())
                .map(|_| Vector3::new(r(), r(), r()) * 0.03)
                .collect();
            let mut step = dx.clone();
            if limit_pair_closing(&mut step, &pairs) {
                limited += 1;
            }
            for (s, d) in step.iter().zip(&dx) {
                assert!(s.norm() <= d.norm() * (1.0 + 1e-12), "only shortened");
            }
            for (c, p) in contacts.iter().zip(&pairs) {
                let d0 = c.distance(&x);
                for k in 0..=200 {
                    let t = k as f64 / 200.0;
                    let y: Vec<Vector3<f64>> =
                        x.iter().zip(&step).map(|(a, s)| a + s * t).collect();
                    let d = c.distance(&y);
                    assert!(
                        d >= d0 - p.allowed - 1e-12,
                        "case {case}: {c:?} from {d0} to {d} at t = {t}"
                    );
                }
            }
            // A vertex sliding over the still triangle, parallel to it, is never shortened.
            let mut slide = vec![Vector3::zeros(); x.len()];
            slide[3] = Vector3::new(r(), r(), 0.0) * 0.05;
            let only_vt = [pairs[0]];
            assert!(!limit_pair_closing(&mut slide, &only_vt), "{:?}", pairs[0]);
            // The whole configuration moving rigidly (a translation) is never shortened.
            let shift = Vector3::new(r(), r(), r()) * 0.05;
            let mut together = vec![shift; x.len()];
            assert!(!limit_pair_closing(&mut together, &pairs));
            assert!(together.iter().all(|s| *s == shift));
            x.clear();
        }
        assert!(
            limited > 300,
            "most random steps had to be limited: {limited}"
        );
    }
}
