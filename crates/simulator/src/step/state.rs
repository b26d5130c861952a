//! The plain data a step reads and returns: the cloth's state, colliders, pins, statistics, and
//! where the colliders are during a (sub)step.

use nalgebra::Vector3;

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
    /// Sub-steps taken (`SimParams::substeps` unless a sub-step was halved).
    pub substeps: usize,
    /// Linear solves that stopped at their iteration cap above their tolerance and were taken
    /// all the same (by a step that was not strict, or at its last halving).
    pub capped_solves: usize,
    /// (Sub)steps of exact Newton taken with their iterations run out before the tolerance.
    pub unconverged_steps: usize,
    /// Incremental potential at the end, J.
    pub energy_j: f64,
    /// Deepest cloth vertex below a collider surface, m (0 when none).
    pub max_penetration_m: f64,
    /// Where the step's time went.
    pub times: PhaseTimes,
}

/// Wall time of a step's phases, s (all sub-steps and Newton iterations).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PhaseTimes {
    /// Before the Newton iterations: seam rest lengths, inertial start, damping rows.
    pub prelude_s: f64,
    /// Contact detection and friction points.
    pub detect_s: f64,
    /// Energy, gradient and Hessian assembly.
    pub assemble_s: f64,
    /// Linear solves, preconditioner set-up included.
    pub solve_s: f64,
    /// Line searches and move limits.
    pub search_s: f64,
    /// After the iterations: velocities, checks, penetration depth.
    pub epilogue_s: f64,
}

impl PhaseTimes {
    /// The phases' names, in the order of [`Self::seconds`].
    pub const NAMES: [&'static str; 6] =
        ["prelude", "detect", "assemble", "solve", "search", "epilog"];

    /// Each phase's time, s, in the order of [`Self::NAMES`].
    pub fn seconds(&self) -> [f64; 6] {
        [
            self.prelude_s,
            self.detect_s,
            self.assemble_s,
            self.solve_s,
            self.search_s,
            self.epilogue_s,
        ]
    }

    /// The sum of the phases, s.
    pub fn total_s(&self) -> f64 {
        self.seconds().iter().sum()
    }

    /// These times multiplied by `k`.
    pub fn scaled(&self, k: f64) -> PhaseTimes {
        let [prelude_s, detect_s, assemble_s, solve_s, search_s, epilogue_s] =
            self.seconds().map(|t| t * k);
        PhaseTimes {
            prelude_s,
            detect_s,
            assemble_s,
            solve_s,
            search_s,
            epilogue_s,
        }
    }

    /// Adds `other`'s times to these.
    pub fn add(&mut self, other: &PhaseTimes) {
        self.prelude_s += other.prelude_s;
        self.detect_s += other.detect_s;
        self.assemble_s += other.assemble_s;
        self.solve_s += other.solve_s;
        self.search_s += other.search_s;
        self.epilogue_s += other.epilogue_s;
    }
}

/// Where the colliders are at the start and the end of a whole time step (they move linearly
/// in between).
pub(super) struct BodyMotion<'a, 'b> {
    pub(super) start: &'b [ColliderFrame<'a>],
    pub(super) end: &'b [ColliderFrame<'a>],
    pub(super) dt_s: f64,
    /// The (sub)step being solved runs from this fraction of the whole step …
    pub(super) from: f64,
    /// … to this one.
    pub(super) to: f64,
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
    pub(super) fn triangle(&self, face: &[u32; 2]) -> Option<(Tri, Tri)> {
        let tri = self
            .end
            .get(face[0] as usize)?
            .triangles
            .get(face[1] as usize)?;
        self.points(face[0], *tri)
    }

    /// Segment between points `ends[1]` and `ends[2]` of collider `ends[0]` at the start and
    /// at the end of the (sub)step being solved.
    pub(super) fn segment(&self, ends: &[u32; 3]) -> Option<(Segment, Segment)> {
        self.points(ends[0], [ends[1], ends[2]])
    }
}
