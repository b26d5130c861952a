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
    /// Sub-steps taken (1 unless the step was halved).
    pub substeps: usize,
    /// Incremental potential at the end, J.
    pub energy_j: f64,
    /// Deepest cloth vertex below a collider surface, m (0 when none).
    pub max_penetration_m: f64,
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
