//! The simulator's settings.

use nalgebra::Vector3;

use crate::collide::CollisionParams;
use crate::energy::bending::BendingHessian;

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
    /// below 5K vertices, 64 above): on the sheet-on-sphere bench (`clothsr lab bench sim`)
    /// the coarse correction cuts the iterations substantially and pays off in time from
    /// about that size. Smaller aggregates (8) cut more iterations on small meshes but their
    /// coarse solve costs as much as a product.
    Auto,
    /// Conjugate gradients with a block-Jacobi preconditioner.
    JacobiPcg,
    /// Conjugate gradients preconditioned by block-Jacobi plus a coarse correction on
    /// aggregates of `aggregate` vertices ([`TwoLevel`](crate::sparse::TwoLevel)), refactored when the iteration
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
            // 1e-2 costs far fewer iterations but, with one Newton iteration per step, leaves
            // stiff sewing springs short of closing (tests/simulator.rs
            // sewing_closes_a_two_panel_tube stalls).
            cg_rel_tol: 1e-3,
            cg_max_iters: 200,
            max_halvings: 4,
            bending_hessian: BendingHessian::GaussNewton,
            // A full sparse Cholesky preconditioner (faer's factorisation and triangular
            // solves) costs more than the block-Jacobi iterations it saves, on small and large
            // meshes alike; a coarse one on aggregates pays off on large meshes.
            linear_solver: LinearSolver::Auto,
        }
    }
}
