//! The contact set the solver consumes: its kinds, their distances and repulsion.

use nalgebra::Vector3;

use super::detector::CollisionDetector;
use super::distance::{point_triangle, segment_segment};
use super::repulsion::{
    edge_edge_jet, obstacle_eval, penalty, penalty_energy, vertex_obstacle_jet,
    vertex_triangle_jet, DistanceJet, HessianKind,
};
use crate::energy::{Mat12, Vec12};

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
