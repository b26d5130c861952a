//! One implicit-Euler step as minimisation of the incremental potential
//!
//! x⁺ = argmin ½h⁻²‖x − x̃‖²_M + E(x) + D(x),  x̃ = xₙ + h vₙ + h² g,
//!
//! with E the membrane, bending, sewing and contact-repulsion energies, and D the dissipation:
//! Coulomb friction against bodies (IPC's lagged friction potential, [`FrictionPoint`]) plus a
//! Rayleigh-style damping potential Σ_c β k_c / (2h) · (∇C_c(xₙ) · (x − xₙ))² over every
//! elastic condition C_c (weft, warp, shear of each triangle, angle of each hinge), i.e.
//! stiffness-proportional damping of the strain rates (Baraff & Witkin 1998 §5), written as a
//! potential so that line search stays consistent. Newton's method with a PSD Hessian, a
//! block-Jacobi PCG linear solve and a backtracking line search; contacts are re-detected every iteration within
//! d̂ + margin (a margin that widens with the cloth's speed) and each iteration moves no vertex
//! more than margin / 2, so no contact can appear unseen; pairs already found close by at most
//! 0.8 of their gap (see `ClosingPair`), so cloth never passes through cloth. A step that
//! yields NaN, cannot decrease the energy or still has moves cut short after the iteration cap
//! is retried as two half steps.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use super::collide::distance::{point_triangle, segment_segment};
use super::collide::repulsion::vertex_obstacle_jet;
use super::collide::{
    edge_triangle_crossings, Collider, CollisionDetector, CollisionParams, Contact, StepStart,
};
use super::energy::bending::{self, BendingHessian};
use super::energy::{sewing, Mat12, Vec12, Vec9};
use super::model::ClothModel;
use super::reduce;
use super::scatter::{for_each_vertex, ColouredElements};

/// Triangles (3 vertices, 9 blocks) and hinges (4 vertices, 16 blocks) for the coloured scatter.
type MembraneSet = ColouredElements<3, 9>;
type HingeSet = ColouredElements<4, 16>;
use super::sparse::{BlockCsr, CholeskyPreconditioner, Pcg, TwoLevel};
use crate::error::{Error, Result};

/// Simulation settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SimParams {
    /// Time step, s.
    pub dt_s: f64,
    /// Gravity, m/s².
    pub gravity_m_s2: Vector3<f64>,
    /// Sewing spring stiffness per seam vertex pair, N/m.
    pub sew_stiffness_n_m: f64,
    /// Speed at which seam rest lengths shrink to zero, m/s (they never grow back).
    pub sew_speed_m_s: f64,
    /// Most a seam spring may be stretched beyond its rest length, m: where a body or the cloth
    /// blocks a seam, its rest length stops shrinking at gap − this, so the seam pulls with at
    /// most `sew_stiffness_n_m` × this (5 N at the defaults) and cannot drag cloth through the
    /// body, as a rest length shrinking on a fixed schedule would (50 N at a 5 cm lag).
    pub sew_max_stretch_m: f64,
    /// Contact repulsion.
    pub collision: CollisionParams,
    /// Extra distance beyond d̂ within which contacts are tracked, m.
    pub detection_margin_m: f64,
    /// Coulomb friction coefficient against bodies.
    pub friction: f64,
    /// Mass-proportional (air) damping rate α, 1/s: the Rayleigh α M term, dissipating
    /// ½ (α/h) Σ m ‖x − xₙ‖².
    pub air_damping_per_s: f64,
    /// Newton iterations at most per step.
    pub newton_max_iters: usize,
    /// Most any vertex moves in one Newton iteration, m, on top of the limits that keep the
    /// contact set valid (default: `f64::INFINITY`, no cap; must be positive). Dressing caps it
    /// at ½ d̂: seam springs pulled tight accelerate the light cloth to metres per second, and
    /// uncapped the panels slam together and crumple.
    pub move_cap_m: f64,
    /// Iterate Newton to `newton_tol_m` (ground truth; the default). When false, a step ends
    /// after its first Newton iteration whose full step (α = 1) decreases the energy, as in
    /// Baraff & Witkin; further iterations run only when the line search or the per-iteration
    /// move limit had to shorten the step.
    pub newton_exact: bool,
    /// Newton stops when no vertex moves more than this, m.
    pub newton_tol_m: f64,
    /// Relative residual of the linear solve.
    pub cg_rel_tol: f64,
    /// Linear-solve iterations at most.
    pub cg_max_iters: usize,
    /// How many times a failing step may be halved: one that is not finite, finds no energy
    /// decrease, or still has moves cut short by the move limits after `newton_max_iters`
    /// (the last halving takes what it gets).
    pub max_halvings: u32,
    /// How bending Hessians are made PSD.
    pub bending_hessian: BendingHessian,
    /// Linear solver of each Newton iteration.
    pub linear_solver: LinearSolver,
}

/// How the Newton system is solved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinearSolver {
    /// Block-Jacobi PCG below 2,500 vertices, two-level PCG from there (aggregates of 32
    /// below 5K vertices, 64 above): measured on the sheet-on-sphere bench, the coarse
    /// correction cuts the iterations by a third to a half (3K: 70 → 46; 40K: 117 → 63) and
    /// pays off in time from about 2.5K vertices (3K: 13.6 → 11.6 ms a step; 40K: 276–287 →
    /// 224–273 ms). Smaller aggregates (8) cut more iterations at 3K but their coarse solve
    /// costs as much as a product.
    Auto,
    /// Conjugate gradients with a block-Jacobi preconditioner.
    JacobiPcg,
    /// Conjugate gradients preconditioned by block-Jacobi plus a coarse correction on
    /// aggregates of `aggregate` vertices ([`TwoLevel`]), refactored when the iteration
    /// count exceeds `refactor_above`.
    TwoLevelPcg {
        /// Vertices per aggregate.
        aggregate: usize,
        /// CG iterations above which the next Newton iteration refactors the coarse matrix.
        refactor_above: usize,
    },
    /// Conjugate gradients preconditioned by a sparse Cholesky factor (faer) of an earlier
    /// Newton matrix, refreshed when the iteration count exceeds `refactor_above`.
    CholeskyPcg {
        /// CG iterations above which the next Newton iteration refactors.
        refactor_above: usize,
    },
}

impl SimParams {
    /// Defaults for a model whose mean edge is `edge_m`: d̂ = 15 % of the edge (0.3–5 mm): well
    /// below the edge so that neighbouring elements sharing no vertex do not repel at rest.
    pub fn for_edge(edge_m: f64) -> SimParams {
        let dhat = (0.15 * edge_m).clamp(3e-4, 5e-3);
        SimParams {
            dt_s: crate::scene::DEFAULT_DT_S,
            gravity_m_s2: Vector3::new(0.0, -9.81, 0.0),
            sew_stiffness_n_m: 1000.0,
            sew_speed_m_s: 0.5,
            sew_max_stretch_m: 5e-3,
            collision: CollisionParams {
                dhat_m: dhat,
                kappa: 2000.0,
                self_collision: true,
            },
            detection_margin_m: dhat,
            friction: 0.3,
            air_damping_per_s: 1.0,
            newton_max_iters: 8,
            move_cap_m: f64::INFINITY,
            newton_exact: true,
            // 1 cm/s of velocity error: far below what shows in an animation.
            newton_tol_m: 3e-2 * crate::scene::DEFAULT_DT_S,
            // 1e-2 costs a third of the iterations (bench: 25 vs 75 at 3K) but, with one Newton
            // iteration per step, leaves stiff sewing springs short of closing (tests/simulator.rs
            // sewing_closes_a_two_panel_tube stalls at 10 mm).
            cg_rel_tol: 1e-3,
            cg_max_iters: 200,
            max_halvings: 4,
            bending_hessian: BendingHessian::GaussNewton,
            // Measured on the 2-core CI machine: a full sparse Cholesky preconditioner (faer's
            // factorisation ≈ 32 ms at 9K unknowns, triangular solves ≈ 4 ms) costs more than
            // the ~100 block-Jacobi iterations (≈ 0.2 ms each) it saves, at 3K and at 40K
            // vertices alike; a coarse one on aggregates pays off on large meshes.
            linear_solver: LinearSolver::Auto,
        }
    }
}

/// Positions and velocities of the cloth: plain data that the corrector may overwrite between
/// steps (the paper's interleaving).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SimState {
    /// Positions, m.
    pub x: Vec<Vector3<f64>>,
    /// Velocities, m/s.
    pub v: Vec<Vector3<f64>>,
    /// Time, s.
    pub t_s: f64,
}

/// A collision body at one instant.
#[derive(Debug, Clone, Copy)]
pub struct ColliderFrame<'a> {
    /// Points, m.
    pub points: &'a [Vector3<f64>],
    /// Triangles, counter-clockwise seen from outside.
    pub triangles: &'a [[u32; 3]],
}

/// Where a pinned vertex goes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PinTarget {
    /// A fixed point, m.
    Fixed(Vector3<f64>),
    /// A point on a collider triangle, moving with it: barycentric weights.
    Body {
        /// Collider index.
        collider: usize,
        /// Triangle of the collider.
        triangle: u32,
        /// Barycentric weights.
        bary: Vector3<f64>,
    },
}

/// A vertex attached to a target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pin {
    /// Cloth vertex.
    pub v: u32,
    /// Its target.
    pub target: PinTarget,
}

/// What one step did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepStats {
    /// Newton iterations (all sub-steps).
    pub newton_iters: usize,
    /// Conjugate-gradient iterations (all sub-steps).
    pub cg_iters: usize,
    /// Contacts in the last iteration.
    pub contacts: usize,
    /// Sub-steps taken (1 unless the step was halved).
    pub substeps: usize,
    /// Incremental potential at the end, J.
    pub energy_j: f64,
    /// Deepest cloth vertex below a collider surface, m (0 when none).
    pub max_penetration_m: f64,
}

/// Gradients of the elastic conditions at the start of a step, for the damping potential.
#[derive(Debug, Clone, Default)]
struct DampingRows {
    /// Per triangle: ∇C of weft, warp, shear and their coefficients β k A.
    mem: Vec<([Vec9; 3], [f64; 3])>,
    /// Per hinge: ∇θ and β · 2w.
    hinge: Vec<(Vec12, f64)>,
    /// Friction against bodies, lagged at the start of the step.
    friction: Vec<FrictionPoint>,
}

/// Coulomb friction of one cloth vertex against a body as a dissipative potential in the
/// Newton system (lagged friction of IPC, Li et al. 2020): the normal force and the tangent
/// plane are those at the start of the step, the sliding is the vertex's tangential
/// displacement relative to the body surface under it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrictionPoint {
    /// Cloth vertex.
    pub v: u32,
    /// μ × normal force, N.
    pub mu_lambda_n: f64,
    /// Unit normal of the body face.
    pub n: Vector3<f64>,
    /// Where the vertex is without sliding: its start-of-step position moved with the body.
    pub anchor: Vector3<f64>,
    /// Sliding displacement below which friction is static-like (ε_v h), m.
    pub eps_m: f64,
}

impl FrictionPoint {
    /// Dissipation potential μλ f₀(‖u‖), u = (I − n nᵀ)(x − anchor), with IPC's C¹ mollifier
    /// f₀(y) = y²/ε − y³/(3ε²) + ε/3 below ε and y above; its gradient μλ f₁(y)/y u (the
    /// friction force, μλ in magnitude when sliding); and as Hessian μλ f₁(y)/y P, P = I − n nᵀ.
    /// The exact Hessian is μλ [f₁/y (P − ûûᵀ) + f₁′ ûûᵀ] (û = u/y): along the slide it has
    /// f₁′ ≤ f₁/y (0 when sliding), so this one is the exact one plus a PSD term, a stiffer
    /// model along the slide. With one Newton iteration a step (fast mode) the exact one let
    /// the step overshoot and the friction chatter: the corrector's tiny training set (a silk
    /// sheet on a ball) became noise that 300 training steps could not lower (loss 0.41 →
    /// 0.42, against 0.38 → 0.20 with this one). Converged Newton reaches the same minimiser.
    pub fn energy_gradient_hessian(&self, x: &Vector3<f64>) -> (f64, Vector3<f64>, Matrix3<f64>) {
        let (e, f1_over_y, _, u) = self.eval(x);
        let p = Matrix3::identity() - self.n * self.n.transpose();
        (
            e,
            u * (self.mu_lambda_n * f1_over_y),
            p * (self.mu_lambda_n * f1_over_y),
        )
    }

    /// The potential alone.
    pub fn energy(&self, x: &Vector3<f64>) -> f64 {
        self.eval(x).0
    }

    /// (μλ f₀(y), f₁(y)/y, f₁′(y), u).
    fn eval(&self, x: &Vector3<f64>) -> (f64, f64, f64, Vector3<f64>) {
        let r = x - self.anchor;
        let u = r - self.n * self.n.dot(&r);
        let y = u.norm();
        let eps = self.eps_m.max(f64::MIN_POSITIVE);
        let (f0, f1_over_y, df1) = if y >= eps {
            (y, 1.0 / y, 0.0)
        } else {
            (
                y * y / eps - y * y * y / (3.0 * eps * eps) + eps / 3.0,
                2.0 / eps - y / (eps * eps),
                2.0 / eps - 2.0 * y / (eps * eps),
            )
        };
        (self.mu_lambda_n * f0, f1_over_y, df1, u)
    }
}

/// Sliding speed below which friction holds like static friction (IPC's ε_v), m/s: cloth
/// under a tangential load smaller than μ N creeps at most this fast.
const FRICTION_EPS_M_S: f64 = 1e-3;

/// The simulator: rest data, settings, pins and reusable buffers.
#[derive(Debug, Clone)]
pub struct Simulator {
    /// The cloth.
    pub model: ClothModel,
    /// Settings.
    pub params: SimParams,
    /// Attached vertices.
    pub pins: Vec<Pin>,
    matrix: BlockCsr,
    pcg: Pcg,
    free: Vec<bool>,
    grad: Vec<Vector3<f64>>,
    dx: Vec<Vector3<f64>>,
    rhs: Vec<Vector3<f64>>,
    /// Membranes and hinges in colours that share no vertex, with their matrix slots.
    mem_set: MembraneSet,
    hinge_set: HingeSet,
    detector: CollisionDetector,
    /// For sewn vertices: the vertices sewn to them (sorted; see [`seam_rings`]).
    seam_ring: std::collections::HashMap<u32, Vec<u32>>,
    cholesky: Option<CholeskyPreconditioner>,
    two_level: Option<TwoLevel>,
    last_cg_iters: usize,
    /// Rest length of each seam pair after the last successful step, m.
    seam_rest_m: Vec<f64>,
    /// Rest lengths of the step being solved, m.
    seam_rest_step_m: Vec<f64>,
    /// Detection margin for cloth–collider contacts, m: at least `detection_margin_m`, widened
    /// to 2.5× the largest Newton displacement of the previous step (at most 1 cm), so that
    /// cloth hitting a body at speed can take its full Newton step.
    obstacle_margin_m: f64,
    /// Upper bound of the cloth–cloth detection margin, m (see [`Simulator::self_margin_m`]).
    self_margin_cap_m: f64,
}

/// Where the colliders are at the start and the end of a whole time step (they move linearly
/// in between).
struct BodyMotion<'a, 'b> {
    start: &'b [ColliderFrame<'a>],
    end: &'b [ColliderFrame<'a>],
    dt_s: f64,
    /// The (sub)step being solved runs from this fraction of the whole step …
    from: f64,
    /// … to this one.
    to: f64,
}

/// N points of a collider.
type Points<const N: usize> = [Vector3<f64>; N];

/// A triangle's three points.
type Tri = Points<3>;

/// A segment's two end points.
type Segment = Points<2>;

impl BodyMotion<'_, '_> {
    /// Points `idx` of collider `c` at the start and at the end of the (sub)step being solved.
    fn points<const N: usize>(&self, c: u32, idx: [u32; N]) -> Option<(Points<N>, Points<N>)> {
        let (s, e) = (self.start.get(c as usize)?, self.end.get(c as usize)?);
        let mut out = ([Vector3::zeros(); N], [Vector3::zeros(); N]);
        for (k, vtx) in idx.into_iter().enumerate() {
            let (p0, p1) = (s.points.get(vtx as usize)?, e.points.get(vtx as usize)?);
            out.0[k] = p0 + (p1 - p0) * self.from;
            out.1[k] = p0 + (p1 - p0) * self.to;
        }
        Some(out)
    }

    /// Triangle `face[1]` of collider `face[0]` at the start and at the end of the (sub)step
    /// being solved.
    fn triangle(&self, face: &[u32; 2]) -> Option<(Tri, Tri)> {
        let tri = self
            .end
            .get(face[0] as usize)?
            .triangles
            .get(face[1] as usize)?;
        self.points(face[0], *tri)
    }

    /// Segment between points `ends[1]` and `ends[2]` of collider `ends[0]` at the start and
    /// at the end of the (sub)step being solved.
    fn segment(&self, ends: &[u32; 3]) -> Option<(Segment, Segment)> {
        self.points(ends[0], [ends[1], ends[2]])
    }
}

/// Upper bound of the adaptive cloth–collider detection margin, m.
const MAX_OBSTACLE_MARGIN_M: f64 = 0.01;

/// From this many vertices [`LinearSolver::Auto`] adds the two-level coarse correction
/// (bench sim, fast mode, ms a step, block-Jacobi vs two-level with aggregates of 32 / 64:
/// 1K vertices 3.96 vs 4.52 / 4.48; 2K 8.49 vs 8.55 / 8.66; 3K 13.6 vs 11.6 / 12.2; 6K 24.4 vs
/// 23.9 / 21.1).
const TWO_LEVEL_FROM_VERTICES: usize = 2_500;

/// Below this many vertices the Newton systems are solved on a single thread.
const SERIAL_BELOW_VERTICES: usize = 4000;

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
struct ClosingPair {
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
    /// not about passing through: without it the circle skirt went 3.0 mm into the legs (0.9
    /// with it); held to it in every direction, cloth sliding over a body crawled (0.2 mm an
    /// iteration at 2.5 mm edges: the fine sheet over three balls took 686 s per simulated
    /// second).
    fn all(x: &[Vector3<f64>], contacts: &[Contact], body_narrow: Option<f64>) -> Vec<ClosingPair> {
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
fn limit_pair_closing(step: &mut [Vector3<f64>], pairs: &[ClosingPair]) -> bool {
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
fn uniform_limit(dx: &[Vector3<f64>], limit: f64, pairs: &[ClosingPair]) -> f64 {
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
fn limit_step(dx: &[Vector3<f64>], limit: f64, pairs: &[ClosingPair]) -> (Vec<Vector3<f64>>, bool) {
    let (mut step, clipped) = clip_to_limit(dx, limit);
    let paired = limit_pair_closing(&mut step, pairs);
    (step, clipped || paired)
}

/// In fast mode without self-collision, how far a vertex touching a body may move in the one
/// Newton iteration that ends a step, m; a step whose iteration moved one further iterates on
/// ([`SimParams::newton_exact`]).
pub const FAST_CONTACT_MOVE_M: f64 = 1e-3;

/// The longest move `alpha · step` of a cloth vertex with a body contact, m.
fn body_contact_move(contacts: &[Contact], step: &[Vector3<f64>], alpha: f64) -> f64 {
    contacts
        .iter()
        .filter(|c| {
            matches!(
                c,
                Contact::VertexObstacle { .. } | Contact::EdgeObstacle { .. }
            )
        })
        .flat_map(|c| c.cloth_dofs().into_iter().flatten())
        .map(|v| step[v as usize].norm() * alpha)
        .fold(0.0, f64::max)
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

/// How deep the deepest cloth vertex is inside a body at positions `x` (the end of a step),
/// m. A vertex with body contacts: per collider, its depth under the face of its contacts it
/// is least deep under (nearest by |d|), the deepest over colliders. A vertex the detector
/// found inside (`depths`, at the start of the last Newton iteration) but with no contact to
/// push it out (in a concave region it may project onto none of the faces): that depth, as
/// found. The detector's figure alone is that of the iterate it was called on: with one
/// iteration a step, the inertial prediction, before any contact pushed it out.
fn penetration(x: &[Vector3<f64>], contacts: &[Contact], depths: &[f64]) -> f64 {
    // (vertex, collider, d) of every body contact, ordered: each vertex's contacts with one
    // collider are adjacent.
    let mut d: Vec<(u32, u32, f64)> = contacts
        .iter()
        .filter_map(|c| match c {
            Contact::VertexObstacle { v, face, .. } => Some((*v, face[0], c.distance(x))),
            _ => None,
        })
        .collect();
    d.sort_by_key(|a| (a.0, a.1));
    let mut touched = vec![false; depths.len()];
    let mut deepest: f64 = 0.0;
    for group in d.chunk_by(|a, b| (a.0, a.1) == (b.0, b.1)) {
        let nearest =
            group
                .iter()
                .map(|g| g.2)
                .fold(f64::INFINITY, |m, d| if d.abs() < m.abs() { d } else { m });
        deepest = deepest.max(-nearest);
        if let Some(t) = touched.get_mut(group[0].0 as usize) {
            *t = true;
        }
    }
    depths
        .iter()
        .zip(&touched)
        .filter(|(_, t)| !**t)
        .map(|(d, _)| *d)
        .fold(deepest, f64::max)
}

/// The cap of [`Simulator::self_margin_m`]: half the 10th percentile of the rest edge lengths
/// (material space). Pairs of neighbouring triangles of flat cloth are about 0.4–0.9 edge
/// lengths apart; wider, most of them would become contact candidates.
fn self_margin_cap(model: &ClothModel) -> f64 {
    let m = &model.mesh.material;
    let mut len: Vec<f64> = model
        .edges
        .iter()
        .map(|e| (m[e[0] as usize] - m[e[1] as usize]).norm())
        .filter(|l| l.is_finite() && *l > 0.0)
        .collect();
    if len.is_empty() {
        return 0.0;
    }
    let k = len.len() / 10;
    let (_, p10, _) = len.select_nth_unstable_by(k, f64::total_cmp);
    *p10 / 2.0
}

fn gather3(x: &[Vector3<f64>], v: [u32; 3]) -> [Vector3<f64>; 3] {
    v.map(|i| x[i as usize])
}

fn gather4(x: &[Vector3<f64>], v: [u32; 4]) -> [Vector3<f64>; 4] {
    v.map(|i| x[i as usize])
}

fn stack<const N: usize, const M: usize>(p: &[Vector3<f64>; N]) -> nalgebra::SVector<f64, M> {
    let mut out = nalgebra::SVector::<f64, M>::zeros();
    for (i, q) in p.iter().enumerate() {
        out.fixed_rows_mut::<3>(3 * i).copy_from(q);
    }
    out
}

/// For each sewn vertex, the other vertices sewn to it (directly or through others: the
/// classes of the seam pairs), sorted. Contacts between them are dropped, as a mesh with its
/// seams welded would have no contact between a vertex and a triangle or edge it belongs to.
/// The two-hop neighbourhoods used before left cloth within two edges of a seam with no
/// repulsion: the circle skirt's panels crossed each other there for a few frames.
fn seam_rings(model: &ClothModel) -> std::collections::HashMap<u32, Vec<u32>> {
    use std::collections::HashMap;
    let seams = &model.mesh.seam_pairs;
    let mut parent: HashMap<u32, u32> = HashMap::new();
    fn root(parent: &mut HashMap<u32, u32>, v: u32) -> u32 {
        let mut r = v;
        while let Some(&p) = parent.get(&r) {
            if p == r {
                break;
            }
            r = p;
        }
        parent.insert(v, r);
        r
    }
    for p in seams {
        for &v in p {
            parent.entry(v).or_insert(v);
        }
        let (a, b) = (root(&mut parent, p[0]), root(&mut parent, p[1]));
        if a != b {
            parent.insert(a.max(b), a.min(b));
        }
    }
    let vertices: Vec<u32> = parent.keys().copied().collect();
    let mut classes: HashMap<u32, Vec<u32>> = HashMap::new();
    for v in vertices {
        let r = root(&mut parent, v);
        classes.entry(r).or_default().push(v);
    }
    let mut rings = HashMap::new();
    for members in classes.values() {
        let mut sorted = members.clone();
        sorted.sort_unstable();
        for &v in members {
            rings.insert(v, sorted.iter().copied().filter(|&w| w != v).collect());
        }
    }
    rings
}

impl Simulator {
    /// A simulator for `model` with `params`.
    pub fn new(model: ClothModel, params: SimParams) -> Simulator {
        let n = model.num_vertices();
        let matrix = BlockCsr::with_pattern(n, model.coupled_pairs());
        Simulator {
            free: vec![true; n],
            grad: vec![Vector3::zeros(); n],
            dx: vec![Vector3::zeros(); n],
            rhs: Vec::with_capacity(n),
            mem_set: MembraneSet::new(model.membranes.iter().map(|m| m.v).collect(), &matrix),
            hinge_set: HingeSet::new(model.hinges.iter().map(|h| h.v).collect(), &matrix),
            detector: CollisionDetector::new(),
            seam_ring: seam_rings(&model),
            cholesky: None,
            two_level: None,
            last_cg_iters: usize::MAX,
            seam_rest_step_m: Vec::new(),
            seam_rest_m: model
                .mesh
                .seam_pairs
                .iter()
                .map(|p| {
                    (model.mesh.positions[p[0] as usize] - model.mesh.positions[p[1] as usize])
                        .norm()
                })
                .collect(),
            obstacle_margin_m: params.detection_margin_m,
            self_margin_cap_m: self_margin_cap(&model),
            model,
            params,
            pins: Vec::new(),
            matrix,
            // Small meshes solve their Newton systems on the step's own thread: rayon's
            // hand-offs cost more than CG's short passes there (3K vertices: 0.27 vs 0.14 ms
            // an iteration on two threads; a one-thread pool of its own took 9–11 ms a solve
            // against 7 ms inline: the matrix then lives in the other core's cache).
            // Detection, assembly and the line search use every thread at any size; their sums
            // are taken in fixed chunks ([`super::reduce`]), so a run gives the same bits on
            // any number of threads (a step's sums used to follow rayon's splits: the pencil
            // skirt's rounding-sensitive dressing ended 65 mm open on two threads, 36 on one).
            pcg: {
                let mut pcg = Pcg::default();
                pcg.set_single_threaded(n < SERIAL_BELOW_VERTICES);
                pcg
            },
        }
    }

    /// Current rest length of every seam pair, m (they shrink as seams close).
    pub fn seam_rest(&self) -> &[f64] {
        &self.seam_rest_m
    }

    /// Sets the seam rest lengths (resuming a run, or following a state set from outside).
    pub fn set_seam_rest(&mut self, rest: &[f64]) -> Result<()> {
        if rest.len() != self.seam_rest_m.len() {
            return Err(Error::Invalid(format!(
                "{} seam rest lengths for {} seam pairs",
                rest.len(),
                self.seam_rest_m.len()
            )));
        }
        self.seam_rest_m.copy_from_slice(rest);
        Ok(())
    }

    /// The cloth–collider detection margin the next step starts with, m (adapted to the last
    /// step's largest move; part of what a resumed run must restore to continue exactly).
    pub fn obstacle_margin_m(&self) -> f64 {
        self.obstacle_margin_m
    }

    /// The cloth–cloth detection margin of the next step, m: pairs closer than d̂ plus this are
    /// contact candidates, so a vertex may move half of it per Newton iteration. It follows the
    /// obstacle margin (2.5× the last step's largest move), from `detection_margin_m` up to
    /// half the mesh's short edges (see `self_margin_cap`). With the fixed
    /// `detection_margin_m` (d̂) every vertex moved at most ½ d̂ (0.075 edge lengths) per Newton
    /// iteration; found cloth–cloth pairs now close by at most 0.8 of their gap instead (see
    /// `ClosingPair`).
    pub fn self_margin_m(&self) -> f64 {
        self.obstacle_margin_m
            .min(self.self_margin_cap_m)
            .max(self.params.detection_margin_m)
    }

    /// Sets the detection margin of the next step (resuming a run); clamped to the allowed range.
    pub fn set_obstacle_margin_m(&mut self, margin_m: f64) {
        if margin_m.is_finite() {
            self.obstacle_margin_m = margin_m
                .min(MAX_OBSTACLE_MARGIN_M)
                .max(self.params.detection_margin_m);
        }
    }

    /// The cloth's edge–triangle crossings at `x` ([`edge_triangle_crossings`]), leaving out
    /// pairs next to each other through a seam (sewn panels meet there within the seam gap):
    /// 0 for cloth that never passed through itself.
    pub fn self_intersections(&self, x: &[Vector3<f64>]) -> usize {
        edge_triangle_crossings(x, &self.model.mesh.triangles, &self.model.edges, |e, t| {
            !self.sewn_together(&e, &t)
        })
        .len()
    }

    /// Whether a vertex of `a` is sewn to a vertex of `b` ([`seam_rings`]).
    fn sewn_together(&self, a: &[u32], b: &[u32]) -> bool {
        a.iter().any(|p| {
            self.seam_ring
                .get(p)
                .is_some_and(|r| b.iter().any(|q| r.binary_search(q).is_ok()))
        })
    }

    /// The widest gap between sewn vertex pairs in `x`, m (0 without seams).
    pub fn max_seam_gap_m(&self, x: &[Vector3<f64>]) -> f64 {
        self.model
            .mesh
            .seam_pairs
            .iter()
            .map(|p| (x[p[0] as usize] - x[p[1] as usize]).norm())
            .fold(0.0, f64::max)
    }

    /// The rest state: mesh positions, zero velocity, t = 0.
    pub fn initial_state(&self) -> SimState {
        let n = self.model.num_vertices();
        SimState {
            x: self.model.mesh.positions.clone(),
            v: vec![Vector3::zeros(); n],
            t_s: 0.0,
        }
    }

    /// Sets the pins (replacing earlier ones).
    pub fn set_pins(&mut self, pins: Vec<Pin>) {
        self.free.iter_mut().for_each(|f| *f = true);
        for p in &pins {
            self.free[p.v as usize] = false;
        }
        self.pins = pins;
    }

    fn pin_position(&self, pin: &Pin, colliders: &[ColliderFrame<'_>]) -> Vector3<f64> {
        match pin.target {
            PinTarget::Fixed(p) => p,
            PinTarget::Body {
                collider,
                triangle,
                bary,
            } => {
                let c = &colliders[collider];
                let t = c.triangles[triangle as usize];
                c.points[t[0] as usize] * bary.x
                    + c.points[t[1] as usize] * bary.y
                    + c.points[t[2] as usize] * bary.z
            }
        }
    }

    /// The collision detector (its counters).
    pub fn detector(&self) -> &CollisionDetector {
        &self.detector
    }

    /// The collision detector (its tuning).
    pub fn detector_mut(&mut self) -> &mut CollisionDetector {
        &mut self.detector
    }

    /// Advances `state` by one time step; colliders are given at the start and the end of the
    /// step (linearly interpolated inside when the step is subdivided).
    pub fn step(
        &mut self,
        state: &SimState,
        colliders_start: &[ColliderFrame<'_>],
        colliders_end: &[ColliderFrame<'_>],
    ) -> Result<(SimState, StepStats)> {
        self.model.update_wrinkle_bending(&state.x, &state.v);
        let mut stats = StepStats::default();
        let h = self.params.dt_s;
        // On a worker of rayon's pool: the step's many short parallel passes then start from
        // inside the pool instead of each waking it from the caller's thread.
        let next = rayon::scope(|_| {
            self.advance(
                state,
                colliders_start,
                colliders_end,
                0.0,
                1.0,
                h,
                0,
                &mut stats,
            )
        })?;
        Ok((next, stats))
    }

    #[allow(clippy::too_many_arguments)]
    fn advance(
        &mut self,
        state: &SimState,
        c0: &[ColliderFrame<'_>],
        c1: &[ColliderFrame<'_>],
        a: f64,
        b: f64,
        h: f64,
        depth: u32,
        stats: &mut StepStats,
    ) -> Result<SimState> {
        // Colliders at the end of this sub-step.
        let lerp = |w: f64| -> Vec<Vec<Vector3<f64>>> {
            c0.iter()
                .zip(c1)
                .map(|(p, q)| {
                    p.points
                        .iter()
                        .zip(q.points)
                        .map(|(x, y)| x * (1.0 - w) + y * w)
                        .collect()
                })
                .collect()
        };
        let owned;
        let end: Vec<ColliderFrame<'_>> = if b >= 1.0 {
            c1.to_vec()
        } else {
            owned = lerp(b);
            owned
                .iter()
                .zip(c1)
                .map(|(p, c)| ColliderFrame {
                    points: p,
                    triangles: c.triangles,
                })
                .collect()
        };
        // Colliders move linearly over the whole step: their velocity is (c1 − c0) / dt.
        let motion = BodyMotion {
            start: c0,
            end: c1,
            dt_s: h / (b - a),
            from: a,
            to: b,
        };
        let last_resort = depth >= self.params.max_halvings;
        match self.solve_step(state, &end, &motion, h, last_resort, stats) {
            Ok(s) => Ok(s),
            Err(e) if depth < self.params.max_halvings => {
                tracing::debug!(
                    "step at t = {:.5} s failed ({e}); halving dt to {:.2e} s",
                    state.t_s,
                    h / 2.0
                );
                let mid = 0.5 * (a + b);
                let half = self.advance(state, c0, c1, a, mid, h / 2.0, depth + 1, stats)?;
                self.advance(&half, c0, c1, mid, b, h / 2.0, depth + 1, stats)
            }
            Err(e) => Err(e),
        }
    }

    fn damping_rows(&self, x: &[Vector3<f64>]) -> DampingRows {
        let m = &self.model;
        let mem = m
            .membranes
            .par_iter()
            .zip(m.membrane_k.par_iter().zip(m.membrane_damping_s.par_iter()))
            .map(|(el, (k, beta))| {
                let p = gather3(x, el.v);
                let (wu, wv) = el.stretch_vectors(&p);
                let (nu, nv) = (wu / wu.norm().max(1e-12), wv / wv.norm().max(1e-12));
                let mut rows = [Vec9::zeros(); 3];
                for i in 0..3 {
                    rows[0]
                        .fixed_rows_mut::<3>(3 * i)
                        .copy_from(&(nu * el.cu[i]));
                    rows[1]
                        .fixed_rows_mut::<3>(3 * i)
                        .copy_from(&(nv * el.cv[i]));
                    rows[2]
                        .fixed_rows_mut::<3>(3 * i)
                        .copy_from(&(wv * el.cu[i] + wu * el.cv[i]));
                }
                let c = beta * el.area_m2;
                (rows, [c * k.weft_n_m, c * k.warp_n_m, c * k.shear_n_m])
            })
            .collect();
        let hinge = m
            .hinges
            .par_iter()
            .zip(m.hinge_damping_s.par_iter())
            .map(|(hg, beta)| {
                let p = gather4(x, hg.v);
                let grad =
                    bending::dihedral_angle_gradient(&p).map_or_else(Vec12::zeros, |(_, g)| g);
                (grad, beta * 2.0 * hg.weight)
            })
            .collect();
        DampingRows {
            mem,
            hinge,
            friction: Vec::new(),
        }
    }

    /// Total incremental potential at `x` with a fixed contact set.
    #[allow(clippy::too_many_arguments)]
    fn potential(
        &self,
        x: &[Vector3<f64>],
        x_n: &[Vector3<f64>],
        x_tilde: &[Vector3<f64>],
        h: f64,
        damping: &DampingRows,
        contacts: &[Contact],
    ) -> f64 {
        let m = &self.model;
        let air = self.params.air_damping_per_s * h;
        // Every sum in fixed chunks (reduce::sum): the Armijo test compares these energies,
        // and their bits must not depend on the thread count.
        let inertia: f64 = reduce::sum(x.len(), |i| {
            0.5 * m.mass_kg[i]
                * ((x[i] - x_tilde[i]).norm_squared() + air * (x[i] - x_n[i]).norm_squared())
        }) / (h * h);
        let elastic = m.elastic_energy(x);
        let damp_mem: f64 = reduce::sum(m.membranes.len(), |k| {
            let (el, (rows, c)) = (&m.membranes[k], &damping.mem[k]);
            let d: Vec9 = stack(&gather3(x, el.v)) - stack::<3, 9>(&gather3(x_n, el.v));
            (0..3).map(|q| c[q] * rows[q].dot(&d).powi(2)).sum::<f64>()
        });
        let damp_hinge: f64 = reduce::sum(m.hinges.len(), |k| {
            let (hg, (row, c)) = (&m.hinges[k], &damping.hinge[k]);
            let d: Vec12 = stack(&gather4(x, hg.v)) - stack::<4, 12>(&gather4(x_n, hg.v));
            c * row.dot(&d).powi(2)
        });
        let sew: f64 = m
            .mesh
            .seam_pairs
            .iter()
            .enumerate()
            .map(|(k, p)| {
                sewing::energy(
                    self.params.sew_stiffness_n_m,
                    self.seam_rest_m(k),
                    &x[p[0] as usize],
                    &x[p[1] as usize],
                )
            })
            .sum();
        let contact: f64 = reduce::sum(contacts.len(), |k| {
            contacts[k].energy(x, &self.params.collision)
        });
        let friction: f64 = reduce::sum(damping.friction.len(), |k| {
            let f = &damping.friction[k];
            f.energy(&x[f.v as usize])
        });
        inertia + elastic + (damp_mem + damp_hinge) / (2.0 * h) + sew + contact + friction
    }

    /// Assembles gradient and Hessian at `x`; returns the potential.
    #[allow(clippy::too_many_arguments)]
    fn assemble(
        &mut self,
        x: &[Vector3<f64>],
        x_n: &[Vector3<f64>],
        x_tilde: &[Vector3<f64>],
        h: f64,
        damping: &DampingRows,
        contacts: &[Contact],
    ) -> f64 {
        let inv_h2 = 1.0 / (h * h);
        let mode = self.params.bending_hessian;
        let model = &self.model;
        let contact_local: Vec<(f64, Vec12, Mat12)> = contacts
            .par_iter()
            .map(|c| c.energy_gradient_hessian(x, &self.params.collision))
            .collect();

        self.matrix.clear();
        // Inertia plus air damping ½ (α/h) m ‖x − xₙ‖² = ½ h⁻² (αh) m ‖x − xₙ‖².
        let air = self.params.air_damping_per_s * h;
        let mut energy = for_each_vertex(&mut self.matrix, &mut self.grad, |i, g, d| {
            let m = model.mass_kg[i];
            let (a, b) = (x[i] - x_tilde[i], x[i] - x_n[i]);
            *g = (a + b * air) * (m * inv_h2);
            *d += Matrix3::identity() * (m * inv_h2 * (1.0 + air));
            0.5 * m * inv_h2 * (a.norm_squared() + air * b.norm_squared())
        });
        // Elements by colour: those of one colour share no vertex, so their blocks are disjoint.
        energy += self.mem_set.add(&mut self.matrix, &mut self.grad, |k| {
            let el = &model.membranes[k];
            let (rows, c) = &damping.mem[k];
            let p = gather3(x, el.v);
            let (mut e, mut g, mut hm) = el.energy_gradient_hessian(&model.membrane_k[k], &p);
            let d: Vec9 = stack(&p) - stack::<3, 9>(&gather3(x_n, el.v));
            for q in 0..3 {
                let s = rows[q].dot(&d);
                e += c[q] * s * s / (2.0 * h);
                g.axpy(c[q] * s / h, &rows[q], 1.0);
                hm.ger(c[q] / h, &rows[q], &rows[q], 1.0);
            }
            (e, g, hm)
        });
        energy += self.hinge_set.add(&mut self.matrix, &mut self.grad, |k| {
            let hg = &model.hinges[k];
            let (row, c) = &damping.hinge[k];
            let p = gather4(x, hg.v);
            let (mut e, mut g, mut hm) = bending::energy_gradient_hessian(hg, &p, mode);
            let d: Vec12 = stack(&p) - stack::<4, 12>(&gather4(x_n, hg.v));
            let s = row.dot(&d);
            e += c * s * s / (2.0 * h);
            g.axpy(c * s / h, row, 1.0);
            hm.ger(c / h, row, row, 1.0);
            (e, g, hm)
        });
        let k_sew = self.params.sew_stiffness_n_m;
        for (k, p) in model.mesh.seam_pairs.iter().enumerate() {
            let (i, j) = (p[0], p[1]);
            let rest = self.seam_rest_m(k);
            energy += sewing::energy(k_sew, rest, &x[i as usize], &x[j as usize]);
            let (g, hm) = sewing::gradient_hessian(k_sew, rest, &x[i as usize], &x[j as usize]);
            self.grad[i as usize] += g.fixed_rows::<3>(0);
            self.grad[j as usize] += g.fixed_rows::<3>(3);
            for (a, va) in [i, j].iter().enumerate() {
                for (b, vb) in [i, j].iter().enumerate() {
                    self.matrix
                        .add(*va, *vb, &hm.fixed_view::<3, 3>(3 * a, 3 * b).into_owned());
                }
            }
        }
        for (c, (e, g, hm)) in contacts.iter().zip(&contact_local) {
            // Candidates beyond d̂ (found within the detection margin) add nothing.
            if *e == 0.0 && g.iter().all(|v| *v == 0.0) {
                continue;
            }
            energy += e;
            let dofs = c.cloth_dofs();
            for (a, va) in dofs.iter().enumerate() {
                let Some(va) = va else { continue };
                self.grad[*va as usize] += g.fixed_rows::<3>(3 * a);
                for (b, vb) in dofs.iter().enumerate() {
                    if let Some(vb) = vb {
                        self.matrix.add(
                            *va,
                            *vb,
                            &hm.fixed_view::<3, 3>(3 * a, 3 * b).into_owned(),
                        );
                    }
                }
            }
        }
        for f in &damping.friction {
            let i = f.v as usize;
            let (e, g, hm) = f.energy_gradient_hessian(&x[i]);
            energy += e;
            self.grad[i] += g;
            self.matrix.add(f.v, f.v, &hm);
        }
        for (gi, f) in self.grad.iter_mut().zip(&self.free) {
            if !f {
                *gi = Vector3::zeros();
            }
        }
        energy
    }

    /// Rest length of seam pair `k` in the step being solved.
    fn seam_rest_m(&self, k: usize) -> f64 {
        self.seam_rest_step_m[k]
    }

    fn linear_solve(
        &mut self,
        rhs: &[Vector3<f64>],
        dx: &mut [Vector3<f64>],
    ) -> super::sparse::CgStats {
        let (tol, max) = (self.params.cg_rel_tol, self.params.cg_max_iters);
        let solver = match self.params.linear_solver {
            LinearSolver::Auto if self.model.num_vertices() >= TWO_LEVEL_FROM_VERTICES => {
                LinearSolver::TwoLevelPcg {
                    aggregate: if self.model.num_vertices() < 5_000 {
                        32
                    } else {
                        64
                    },
                    refactor_above: 0,
                }
            }
            LinearSolver::Auto => LinearSolver::JacobiPcg,
            s => s,
        };
        let stats = match solver {
            LinearSolver::Auto | LinearSolver::JacobiPcg => {
                self.pcg.solve(&self.matrix, rhs, dx, &self.free, tol, max)
            }
            LinearSolver::TwoLevelPcg {
                aggregate,
                refactor_above,
            } => {
                if self.two_level.is_none() {
                    self.two_level = TwoLevel::new(&self.matrix, aggregate);
                    self.last_cg_iters = usize::MAX;
                }
                match self.two_level.as_mut() {
                    Some(coarse) => {
                        if self.last_cg_iters > refactor_above {
                            let t = std::time::Instant::now();
                            let ok = coarse.factorize(&self.matrix, &self.free);
                            tracing::trace!(
                                ok,
                                ms = t.elapsed().as_secs_f64() * 1e3,
                                "coarse refactor"
                            );
                        }
                        self.pcg.solve_two_level(
                            &self.matrix,
                            rhs,
                            dx,
                            &self.free,
                            coarse,
                            tol,
                            max,
                        )
                    }
                    None => self.pcg.solve(&self.matrix, rhs, dx, &self.free, tol, max),
                }
            }
            LinearSolver::CholeskyPcg { refactor_above } => {
                if self.cholesky.is_none() {
                    self.cholesky = CholeskyPreconditioner::new(&self.matrix);
                    if self.cholesky.is_none() {
                        tracing::warn!("sparse Cholesky analysis failed; using block-Jacobi PCG");
                    }
                }
                match self.cholesky.as_mut() {
                    Some(pre) => {
                        if !pre.is_factored() || self.last_cg_iters > refactor_above {
                            let t = std::time::Instant::now();
                            let ok = pre.factorize(&self.matrix, &self.free);
                            tracing::trace!(
                                ok,
                                ms = t.elapsed().as_secs_f64() * 1e3,
                                "cholesky refactor"
                            );
                            if !ok {
                                tracing::debug!("sparse Cholesky factorisation failed; block-Jacobi PCG this iteration");
                            }
                        }
                        if pre.is_factored() {
                            self.pcg.solve_with_factor(
                                &self.matrix,
                                rhs,
                                dx,
                                &self.free,
                                pre,
                                tol,
                                max,
                            )
                        } else {
                            self.pcg.solve(&self.matrix, rhs, dx, &self.free, tol, max)
                        }
                    }
                    None => self.pcg.solve(&self.matrix, rhs, dx, &self.free, tol, max),
                }
            }
        };
        self.last_cg_iters = stats.iterations;
        stats
    }

    /// Panels sewn together must be free to meet along the seam: no repulsion between a
    /// vertex and a triangle or edge holding a vertex sewn to it ([`seam_rings`]).
    fn drop_seam_neighbours(&self, contacts: &mut Vec<Contact>) {
        if self.seam_ring.is_empty() {
            return;
        }
        contacts.retain(|c| match c {
            Contact::VertexObstacle { .. } | Contact::EdgeObstacle { .. } => true,
            Contact::VertexTriangle { v, t } => !self.sewn_together(&[*v], t),
            Contact::EdgeEdge { a, b } => !self.sewn_together(a, b),
        });
    }

    /// The contacts at `x` of cloth that began the step at `x_n` ([`StepStart`]).
    fn contacts(
        &mut self,
        x: &[Vector3<f64>],
        since: StepStart<'_>,
        colliders: &[ColliderFrame<'_>],
    ) -> Vec<Contact> {
        let bodies: Vec<Collider<'_>> = colliders.iter().map(|c| (c.points, c.triangles)).collect();
        let mut params = self.params.collision;
        let self_margin = self.self_margin_m();
        params.dhat_m += self_margin;
        self.detector.obstacle_extra_m = (self.obstacle_margin_m - self_margin).max(0.0);
        let mut contacts = self.detector.find_contacts_since(
            x,
            since,
            &self.model.mesh.triangles,
            &self.model.edges,
            &bodies,
            &params,
        );
        self.drop_seam_neighbours(&mut contacts);
        if tracing::enabled!(tracing::Level::DEBUG) {
            let mut kinds = [0usize; 4];
            for c in &contacts {
                kinds[match c {
                    Contact::VertexObstacle { .. } => 0,
                    Contact::EdgeObstacle { .. } => 1,
                    Contact::VertexTriangle { .. } => 2,
                    Contact::EdgeEdge { .. } => 3,
                }] += 1;
            }
            tracing::debug!(
                vertex_obstacle = kinds[0],
                edge_obstacle = kinds[1],
                vertex_triangle = kinds[2],
                edge_edge = kinds[3],
                penetration_mm = self.detector.max_penetration() * 1e3,
                "contacts"
            );
        }
        contacts
    }

    fn solve_step(
        &mut self,
        state: &SimState,
        colliders: &[ColliderFrame<'_>],
        motion: &BodyMotion<'_, '_>,
        h: f64,
        last_resort: bool,
        stats: &mut StepStats,
    ) -> Result<SimState> {
        let t_prelude = std::time::Instant::now();
        let n = self.model.num_vertices();
        let shrink = self.params.sew_speed_m_s * h;
        let slack = self.params.sew_max_stretch_m;
        self.seam_rest_step_m = self
            .model
            .mesh
            .seam_pairs
            .iter()
            .zip(&self.seam_rest_m)
            .map(|(p, &r)| {
                let gap = (state.x[p[0] as usize] - state.x[p[1] as usize]).norm();
                (r - shrink).max(r.min(gap - slack)).max(0.0)
            })
            .collect();
        let x_n = &state.x;
        let g = self.params.gravity_m_s2;
        let mut x_tilde: Vec<Vector3<f64>> = (0..n)
            .map(|i| x_n[i] + state.v[i] * h + g * (h * h))
            .collect();
        // Start from the inertial prediction without gravity: free flight is then one step away.
        // Cloth landing on a body is carried through its surface by this start; contacts are
        // found knowing where each vertex began the step, so that one that came in through a
        // still table's top near its edge is pushed back out through the top, not through the
        // side nearest to it ([`CollisionDetector::find_contacts_since`]).
        let mut x: Vec<Vector3<f64>> = (0..n).map(|i| x_n[i] + state.v[i] * h).collect();
        let still: Vec<bool> = (motion.start.iter().zip(motion.end))
            .map(|(a, b)| a.points == b.points)
            .collect();
        if self.params.collision.self_collision {
            // That start is a move like any Newton step's, and must not carry cloth through
            // cloth: layers closing faster than their gap per step crossed in the initial
            // guess, before any contact was looked for there (the circle skirt on the walking
            // avatar tangled so). The pairs that may meet on the way (swept boxes) close by
            // at most 0.8 of their gap at xₙ ([`ClosingPair`]); cloth moving together, as a
            // falling sheet, keeps its whole inertial move.
            let mut pairs = self.detector.find_swept_self_pairs(
                x_n,
                &x,
                &self.model.mesh.triangles,
                &self.model.edges,
                self.params.collision.dhat_m,
            );
            self.drop_seam_neighbours(&mut pairs);
            let pairs = ClosingPair::all(x_n, &pairs, None);
            let mut inertial: Vec<Vector3<f64>> = state.v.iter().map(|v| v * h).collect();
            if limit_pair_closing(&mut inertial, &pairs) {
                x.iter_mut()
                    .zip(x_n.iter().zip(&inertial))
                    .for_each(|(x, (a, d))| *x = a + d);
            }
        }
        for pin in &self.pins {
            let p = self.pin_position(pin, colliders);
            x[pin.v as usize] = p;
            x_tilde[pin.v as usize] = p;
        }
        let mut damping = self.damping_rows(x_n);
        // Per Newton iteration no vertex moves further than keeps its contact set valid.
        // Contacts are found within d̂ plus a margin, so pairs that were not found are at least
        // that far apart: cloth–body pairs stay beyond d̂ while each vertex moves less than the
        // margin (the body holds still within an iteration), cloth–cloth pairs while each of
        // their two sides moves at most half of it. Pairs that were found close by at most 0.8
        // of their gap, and cloth approaches a body by at most max(d/2, ½ d̂) but slides
        // freely ([`ClosingPair`]).
        let max_move = if self.params.collision.self_collision {
            0.5 * self.self_margin_m()
        } else {
            self.obstacle_margin_m.max(self.params.detection_margin_m)
        };
        let cap = self.params.move_cap_m;
        if cap.is_nan() || cap <= 0.0 {
            return Err(Error::Invalid(format!(
                "move_cap_m must be positive (f64::INFINITY for no cap), not {cap}"
            )));
        }
        let max_move = max_move.min(cap);
        // With self-collision off every vertex moves up to the whole obstacle margin, as ever.
        let body_narrow = self
            .params
            .collision
            .self_collision
            .then_some((0.5 * self.params.detection_margin_m).min(cap));
        let x_start = x.clone();
        let mut contacts = Vec::new();
        let mut energy = f64::NAN;
        // Each step's solve starts from zero. Starting from the last step's displacement cut
        // CG iterations by 12 % at 40K vertices, but the unsolved part of that guess carries
        // the last motion on: a hanging sheet kept twice the kinetic energy after 150 frames.
        self.dx.iter_mut().for_each(|d| *d = Vector3::zeros());
        let prelude_ms = t_prelude.elapsed().as_secs_f64() * 1e3;
        let t_newton = std::time::Instant::now();
        for it in 0..self.params.newton_max_iters {
            let t_detect = std::time::Instant::now();
            contacts = self.contacts(
                &x,
                StepStart {
                    x: x_n,
                    still: &still,
                },
                colliders,
            );
            if it == 0 {
                damping.friction = self.friction_points(x_n, &contacts, motion);
            }
            let pairs = ClosingPair::all(&x, &contacts, body_narrow);
            let t_assemble = std::time::Instant::now();
            energy = self.assemble(&x, x_n, &x_tilde, h, &damping, &contacts);
            let t_solve = std::time::Instant::now();
            if !energy.is_finite() {
                return Err(Error::Simulation(format!(
                    "energy is not finite at t = {:.5} s",
                    state.t_s
                )));
            }
            // Reused across iterations: no per-iteration allocation of the right-hand side.
            let mut rhs = std::mem::take(&mut self.rhs);
            rhs.clear();
            rhs.extend(self.grad.iter().map(|g| -g));
            let mut dx = std::mem::take(&mut self.dx);
            let cg = self.linear_solve(&rhs, &mut dx);
            self.rhs = rhs;
            stats.cg_iters += cg.iterations;
            stats.newton_iters += 1;
            let t_search = std::time::Instant::now();
            let slope: f64 = self.grad.iter().zip(&dx).map(|(g, d)| g.dot(d)).sum();
            let longest = dx.iter().map(|d| d.norm()).fold(0.0, f64::max);
            if !longest.is_finite() || !slope.is_finite() {
                self.dx = vec![Vector3::zeros(); n];
                return Err(Error::Simulation(format!(
                    "the Newton direction is not finite at t = {:.5} s",
                    state.t_s
                )));
            }
            if slope >= 0.0 {
                self.dx = dx;
                break;
            }
            if longest < self.params.newton_tol_m {
                // Converged: the last, short Newton step is still taken (within the move
                // limits, if its energy decreases). Dropped, it was each step's gravity
                // increment once air damping nearly balanced it (h²(g − αv) < tol):
                // free-falling cloth stopped accelerating at 0.81 m/s.
                let (step, _) = limit_step(&dx, max_move, &pairs);
                let step_slope: f64 = self.grad.iter().zip(&step).map(|(g, d)| g.dot(d)).sum();
                let trial: Vec<Vector3<f64>> = x.iter().zip(&step).map(|(a, d)| a + d).collect();
                let e = self.potential(&trial, x_n, &x_tilde, h, &damping, &contacts);
                if e.is_finite() && e <= energy + 1e-4 * step_slope {
                    x = trial;
                    energy = e;
                }
                dx.iter_mut().for_each(|d| *d = Vector3::zeros());
                self.dx = dx;
                break;
            }
            // The move limit clips vertices one by one: a few vertices that want to travel far
            // (a fold pushed out of a body) no longer shrink everybody else's step, which
            // stalled whole garments at α ≈ 0.1 for every iteration. The clipped direction is
            // still a descent direction when its slope is negative; otherwise scale uniformly.
            let (mut step, mut clipped) = limit_step(&dx, max_move, &pairs);
            let mut step_slope: f64 = self.grad.iter().zip(&step).map(|(g, d)| g.dot(d)).sum();
            if clipped && step_slope >= 0.0 {
                // Uniform scaling by the tightest ratio keeps every vertex and pair within its
                // limit.
                let s = uniform_limit(&dx, max_move, &pairs);
                step.iter_mut().zip(&dx).for_each(|(o, d)| *o = d * s);
                step_slope = slope * s;
            }
            let step_longest = step.iter().map(|d| d.norm()).fold(0.0, f64::max);
            let mut alpha = 1.0;
            let mut trial: Vec<Vector3<f64>> = x.clone();
            let mut accepted = false;
            for _ in 0..12 {
                trial
                    .par_iter_mut()
                    .zip(x.par_iter().zip(step.par_iter()))
                    .for_each(|(t, (xi, di))| *t = xi + di * alpha);
                let e = self.potential(&trial, x_n, &x_tilde, h, &damping, &contacts);
                if e.is_finite() && e <= energy + 1e-4 * alpha * step_slope {
                    accepted = true;
                    energy = e;
                    break;
                }
                alpha *= 0.5;
            }
            if !accepted {
                self.dx = vec![Vector3::zeros(); n];
                if it == 0 {
                    return Err(Error::Simulation(format!(
                        "no energy decrease at t = {:.5} s",
                        state.t_s
                    )));
                }
                break;
            }
            x = trial;
            let moved = step_longest * alpha;
            clipped |= alpha < 1.0;
            tracing::trace!(
                it,
                longest,
                alpha,
                clipped,
                cg = cg.iterations,
                contacts = contacts.len(),
                energy,
                detect_ms = (t_assemble - t_detect).as_secs_f64() * 1e3,
                assemble_ms = (t_solve - t_assemble).as_secs_f64() * 1e3,
                solve_ms = (t_search - t_solve).as_secs_f64() * 1e3,
                search_ms = t_search.elapsed().as_secs_f64() * 1e3,
                "newton"
            );
            // Warm start the next solve with what is left of this direction.
            dx.par_iter_mut()
                .zip(step.par_iter())
                .for_each(|(d, s)| *d -= s * alpha);
            self.dx = dx;
            // Fast mode stops after the first full, unclipped step. Without self-collision,
            // where a vertex may move the whole obstacle margin (up to 10 mm) an iteration,
            // not when a vertex touching a body moved further than FAST_CONTACT_MOVE_M in it:
            // sliding over a body's sharp edge, one linearised step takes the repulsion of the
            // wrong side of the edge, and the next step's repulsion launches the cloth (a
            // sheet dropped 2 cm onto a table left its edge at 3.7 m/s, its energy doubled).
            // With self-collision the moves are capped at half the cloth margin and the same
            // drop keeps its energy.
            let fast_done = !self.params.newton_exact
                && !clipped
                && (self.params.collision.self_collision
                    || body_contact_move(&contacts, &step, alpha) <= FAST_CONTACT_MOVE_M);
            if moved < self.params.newton_tol_m || fast_done {
                break;
            }
            // Out of iterations with moves still cut short: the cloth lags where it should be
            // (a leg pushing a fold of skirt into the other layer). Taken as it is, the body
            // runs into cloth that could not follow; half the step asks half the move.
            if it + 1 == self.params.newton_max_iters && clipped && !last_resort {
                self.dx = vec![Vector3::zeros(); n];
                return Err(Error::Simulation(format!(
                    "the move limits still held vertices back after {} Newton iterations at t = {:.5} s",
                    it + 1,
                    state.t_s
                )));
            }
        }
        let t_epilogue = std::time::Instant::now();
        let travelled = x
            .iter()
            .zip(&x_start)
            .map(|(a, b)| (a - b).norm_squared())
            .fold(0.0, f64::max)
            .sqrt();
        self.obstacle_margin_m = (2.5 * travelled)
            .min(MAX_OBSTACLE_MARGIN_M)
            .max(self.params.detection_margin_m);
        let v: Vec<Vector3<f64>> = (0..n).map(|i| (x[i] - x_n[i]) / h).collect();
        if let Some(i) = x
            .iter()
            .chain(&v)
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            return Err(Error::Simulation(format!(
                "vertex {} is not finite at t = {:.5} s",
                i % n,
                state.t_s
            )));
        }
        stats.contacts = contacts.len();
        stats.substeps += 1;
        self.seam_rest_m.clone_from(&self.seam_rest_step_m);
        stats.energy_j = energy;
        stats.max_penetration_m =
            stats
                .max_penetration_m
                .max(penetration(&x, &contacts, self.detector.vertex_depths()));
        tracing::trace!(
            prelude_ms,
            newton_ms = (t_epilogue - t_newton).as_secs_f64() * 1e3,
            epilogue_ms = t_epilogue.elapsed().as_secs_f64() * 1e3,
            "step"
        );
        Ok(SimState {
            x,
            v,
            t_s: state.t_s + h,
        })
    }

    /// The lagged friction of a step ([`FrictionPoint`]): one per free cloth vertex touching a
    /// body, all measured at the start of the step (cloth at `x_n`, bodies at their start
    /// positions): the normal force is the magnitude of the summed repulsion of its body
    /// contacts, ‖κ Σ (d̂ − d) ∇d‖, a crease contact's shared between its edge's two vertices
    /// by where along the edge it acts; the tangent plane and the body motion under the vertex
    /// are those of the face it is least deep under (nearest by |d|), or where it touches no
    /// face, of the first crease contact listed.
    fn friction_points(
        &self,
        x_n: &[Vector3<f64>],
        contacts: &[Contact],
        motion: &BodyMotion<'_, '_>,
    ) -> Vec<FrictionPoint> {
        let mu = self.params.friction;
        if mu <= 0.0 {
            return Vec::new();
        }
        let p = &self.params.collision;
        struct Acc {
            d: f64,
            force: Vector3<f64>,
            n: Vector3<f64>,
            moved: Vector3<f64>,
        }
        let mut per: Vec<Option<Acc>> = (0..x_n.len()).map(|_| None).collect();
        for c in contacts {
            // A cloth edge against a crease: its repulsion, shared between the edge's two
            // vertices by where along the edge it acts, presses them against the crease (the
            // grip of an edge a sheet wraps over); a vertex with no face contact takes the
            // contact's direction as its normal and the crease's motion under it.
            if let Contact::EdgeObstacle { a, ends, .. } = c {
                let Some((e0, e1)) = motion.segment(ends) else {
                    continue;
                };
                let (i, j) = (a[0] as usize, a[1] as usize);
                let q = segment_segment(&x_n[i], &x_n[j], &e0[0], &e0[1]);
                if !(q.dist > 0.0 && q.dist < p.dhat_m) {
                    continue;
                }
                let on_cloth = x_n[i] + (x_n[j] - x_n[i]) * q.s;
                let on_crease = e0[0] + (e0[1] - e0[0]) * q.t;
                let Some(n) = (on_cloth - on_crease).try_normalize(1e-20) else {
                    continue;
                };
                let moved = (e1[0] - e0[0]) * (1.0 - q.t) + (e1[1] - e0[1]) * q.t;
                let force = p.kappa * (p.dhat_m - q.dist);
                for (k, w) in [(i, 1.0 - q.s), (j, q.s)] {
                    if !self.free[k] || w <= 0.0 {
                        continue;
                    }
                    let slot = per[k].get_or_insert(Acc {
                        d: f64::INFINITY,
                        force: Vector3::zeros(),
                        n,
                        moved,
                    });
                    slot.force += n * (force * w);
                }
                continue;
            }
            let Contact::VertexObstacle { v: i, face, .. } = c else {
                continue;
            };
            let (i, Some((t0, t1))) = (*i as usize, motion.triangle(face)) else {
                continue;
            };
            if !self.free[i] {
                continue;
            }
            // Distance and its gradient as the repulsion has them; the tangent plane is the
            // face's.
            let jet = vertex_obstacle_jet(&[x_n[i], t0[0], t0[1], t0[2]]);
            let d = jet.d;
            let Some(n) = (t0[1] - t0[0]).cross(&(t0[2] - t0[0])).try_normalize(1e-20) else {
                continue;
            };
            if d >= p.dhat_m {
                continue;
            }
            let push = jet.n * (p.kappa * (p.dhat_m - d));
            // p − q = Σ cᵢ xᵢ with c₀ = 1: the closest point's barycentric weights are −c₁..₃.
            let b = [-jet.coeffs[1], -jet.coeffs[2], -jet.coeffs[3]];
            let moved = (t1[0] - t0[0]) * b[0] + (t1[1] - t0[1]) * b[1] + (t1[2] - t0[2]) * b[2];
            let slot = per[i].get_or_insert(Acc {
                d: f64::INFINITY,
                force: Vector3::zeros(),
                n,
                moved,
            });
            slot.force += push;
            if d.abs() < slot.d.abs() {
                (slot.d, slot.n, slot.moved) = (d, n, moved);
            }
        }
        let eps_m = FRICTION_EPS_M_S * motion.dt_s * (motion.to - motion.from);
        per.iter()
            .enumerate()
            .filter_map(|(i, a)| {
                let a = a.as_ref()?;
                let force = a.force.norm();
                (force > 0.0).then(|| FrictionPoint {
                    v: i as u32,
                    mu_lambda_n: mu * force,
                    n: a.n,
                    anchor: x_n[i] + a.moved,
                    eps_m,
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::fd;
    use nalgebra::{SMatrix, SVector};

    fn point(eps_m: f64) -> FrictionPoint {
        FrictionPoint {
            v: 0,
            mu_lambda_n: 0.7,
            n: Vector3::new(0.2, 1.0, -0.3).normalize(),
            anchor: Vector3::new(0.01, -0.02, 0.005),
            eps_m,
        }
    }

    /// The friction potential's gradient matches finite differences where it is static-like
    /// (sliding below ε) and where it slides; its Hessian is the exact one (differences of the
    /// gradient) plus μλ (f₁/y − f₁′) ûûᵀ along the slide, and PSD; sliding, the force is μλ in
    /// the tangent plane against the slide.
    #[test]
    fn friction_derivatives_match_finite_differences() {
        let eps = 1e-3;
        let f = point(eps);
        let t1 = f.n.cross(&Vector3::x()).normalize();
        let t2 = f.n.cross(&t1);
        for slide in [0.3 * eps, 0.9 * eps, 4.0 * eps] {
            let x = f.anchor + (t1 * 0.8 + t2 * 0.6) * slide + f.n * 0.002;
            let to3 = |y: &SVector<f64, 3>| Vector3::new(y[0], y[1], y[2]);
            let x3 = SVector::<f64, 3>::from_column_slice(x.as_slice());
            let (_, g, h) = f.energy_gradient_hessian(&x);
            let g3 = SVector::<f64, 3>::from_column_slice(g.as_slice());
            fd::check_gradient(|y| f.energy(&to3(y)), &g3, &x3, 1e-7 * eps, 1e-6);
            fd::check_psd(&SMatrix::<f64, 3, 3>::from_column_slice(h.as_slice()));
            let (_, f1_over_y, df1, u) = f.eval(&x);
            let uhat = u.normalize();
            let extra = uhat * uhat.transpose() * (f.mu_lambda_n * (f1_over_y - df1));
            let exact = SMatrix::<f64, 3, 3>::from_column_slice((h - extra).as_slice());
            fd::check_hessian(
                |y| {
                    let g = f.energy_gradient_hessian(&to3(y)).1;
                    SVector::<f64, 3>::from_column_slice(g.as_slice())
                },
                &exact,
                &x3,
                1e-6 * eps,
                1e-5,
            );
            assert!(f1_over_y - df1 >= 0.0);
        }
        let x = f.anchor + t1 * (10.0 * eps) + f.n * 0.004;
        let g = f.energy_gradient_hessian(&x).1;
        assert!((g.norm() - f.mu_lambda_n).abs() < 1e-12);
        assert!(g.dot(&f.n).abs() < 1e-12 && g.dot(&t1) > 0.0);
        // At rest: 2μλ/ε across the whole tangent plane, nothing along the normal.
        let h = f.energy_gradient_hessian(&(f.anchor + f.n * 0.001)).2;
        assert!((t1.dot(&(h * t1)) - 2.0 * f.mu_lambda_n / eps).abs() < 1e-6 * h.norm());
        assert!((h * f.n).norm() < 1e-9 * h.norm());
    }

    /// A cloth edge across a crease of a moving box: the crease's repulsion grips the edge's
    /// two vertices, μ κ (d̂ − d) shared by where along the edge it acts (a quarter of the way:
    /// ¾ and ¼), normal to the crease's direction of contact, and they are anchored to the
    /// crease's own motion where the edge touches it (the box, second of two colliders, is
    /// stretched along the crease in the step: its far end moves 10 mm, the point touched, a
    /// quarter of the way along, 2.5 mm).
    #[test]
    fn a_crease_contact_grips_its_edges_vertices_moving_with_the_crease() {
        let scene = crate::scene::samples::sample("sheet_table").expect("sample");
        let sim = crate::driver::Simulation::new(&scene, 0.04, |_| {}).expect("setup");
        let s = &sim.sim;
        let p = s.params.collision;
        let mu = s.params.friction;
        assert!(mu > 0.0 && p.dhat_m < 0.01, "{mu} {}", p.dhat_m);
        let cube = crate::scene::Collider::cuboid("box", Vector3::zeros(), Vector3::repeat(1.0));
        let pts: Vec<Vector3<f64>> = cube.frames[0].iter().map(|p| p.cast::<f64>()).collect();
        let moved: Vec<Vector3<f64>> = pts
            .iter()
            .map(|q| q + Vector3::new(0.01 * q.x, 0.0, 0.0))
            .collect();
        let tris = cube.triangles;
        let far =
            crate::scene::Collider::cuboid("far", Vector3::repeat(9.0), Vector3::repeat(10.0));
        let far_pts: Vec<Vector3<f64>> = far.frames[0].iter().map(|p| p.cast::<f64>()).collect();
        // The crease y = z = 1 (along x); the closest point of the cloth edge a quarter of the
        // way from `a`, 0.3 d̂ out along (0, 1, 1)/√2; the edge runs along (0, 1, −1)/√2.
        let [a, b] = s.model.edges[0];
        let (a, b) = (a as usize, b as usize);
        let out = Vector3::new(0.0, 1.0, 1.0).normalize();
        let along = Vector3::new(0.0, 1.0, -1.0).normalize();
        let d = 0.3 * p.dhat_m;
        let c = Vector3::new(0.25, 1.0, 1.0) + out * d;
        let mut x_n = vec![Vector3::repeat(5.0); s.model.num_vertices()];
        x_n[a] = c - along * 0.025;
        x_n[b] = c + along * 0.075;
        let contacts = crate::collide::find_contacts(
            &x_n,
            &[],
            &[[a as u32, b as u32]],
            &[(&far_pts, &far.triangles), (&pts, &tris)],
            &p,
        );
        assert!(
            matches!(
                contacts[..],
                [Contact::EdgeObstacle {
                    ends: [1, _, _],
                    ..
                }]
            ),
            "{contacts:?}"
        );
        let frames = |q| {
            [
                ColliderFrame {
                    points: &far_pts,
                    triangles: &far.triangles,
                },
                ColliderFrame {
                    points: q,
                    triangles: &tris,
                },
            ]
        };
        let (start, end) = (frames(&pts), frames(&moved));
        let motion = BodyMotion {
            start: &start,
            end: &end,
            dt_s: 1.0 / 300.0,
            from: 0.0,
            to: 1.0,
        };
        let mut points = s.friction_points(&x_n, &contacts, &motion);
        points.sort_by_key(|f| f.v);
        assert_eq!(points.len(), 2, "{points:?}");
        let force = mu * p.kappa * (p.dhat_m - d);
        for f in &points {
            let w = if f.v as usize == a { 0.75 } else { 0.25 };
            assert!(
                (f.mu_lambda_n - force * w).abs() < 1e-9 * force,
                "vertex {}: {} against {}",
                f.v,
                f.mu_lambda_n,
                force * w
            );
            assert!((f.n - out).norm() < 1e-9, "{}", f.n);
            let want = x_n[f.v as usize] + Vector3::new(0.0025, 0.0, 0.0);
            assert!((f.anchor - want).norm() < 1e-12, "{} {want}", f.anchor);
        }
        // Without friction, no grip.
        let mut s = sim.sim;
        s.params.friction = 0.0;
        assert!(s.friction_points(&x_n, &contacts, &motion).is_empty());
    }

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
