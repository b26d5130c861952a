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
    /// Each step is solved as this many equal sub-steps (at least 1), the colliders moving
    /// linearly through them; `newton_tol_m` is shared out among them.
    pub substeps: u32,
    /// A (sub)step whose linear solve stopped at `cg_max_iters` above `cg_rel_tol`, or whose
    /// Newton iterations ran out before `newton_tol_m` (exact mode), is halved instead of
    /// accepted; at the last halving it is taken and counted in [`StepStats`](super::StepStats).
    /// Off, such steps are only counted.
    pub strict_solves: bool,
    /// A linear solve stopped at `cg_max_iters` above `cg_rel_tol` carries on preconditioned
    /// by a sparse Cholesky factor of its own matrix before it counts as capped (and, with
    /// `strict_solves`, halves the step): stiff fabrics at millimetre resolution outgrow what
    /// PCG reaches in its cap, where a factor solves in a few iterations. The next few solves
    /// then factor straight away.
    pub rescue_capped_solves: bool,
}

/// How accurately each step is solved: the presets behind the pipeline's coarse simulation, the
/// fine simulation that makes data sets, and the references they are checked against
/// (`clothsr lab converge`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SolverMode {
    /// One Newton iteration a step when its full step is accepted, the linear solve to its
    /// tolerance or cap (Baraff & Witkin): the pipeline's coarse simulation.
    Fast,
    /// The fine simulation behind data sets, fits and floors: four sub-steps a step, each
    /// taken as in `Fast` but only when its linear solve converged (a solve stopped at its cap
    /// carries on with a sparse Cholesky factor; one that still fails halves the sub-step):
    /// stiff fabrics at millimetre resolution stay on the converged solution.
    Data,
    /// Newton to `newton_tol_m` at the scene's time step (the simulator's default).
    Converged,
    /// The tight reference: Newton to a thousandth of the velocity tolerance, the linear
    /// solve to 1e-6 with no practical cap, never accepted short.
    Tight,
}

impl SolverMode {
    /// Every mode, in the order of [`SolverMode::name`]'s names.
    pub const ALL: [SolverMode; 4] = [
        SolverMode::Fast,
        SolverMode::Data,
        SolverMode::Converged,
        SolverMode::Tight,
    ];

    /// The mode's name on the command line and in manifests.
    pub fn name(self) -> &'static str {
        match self {
            SolverMode::Fast => "fast",
            SolverMode::Data => "data",
            SolverMode::Converged => "converged",
            SolverMode::Tight => "tight",
        }
    }

    /// The mode named `name` ([`SolverMode::name`]).
    pub fn from_name(name: &str) -> Option<SolverMode> {
        SolverMode::ALL.into_iter().find(|m| m.name() == name)
    }

    /// Sets the solver settings of this mode in `p` (time step, gravity, contact and fabric
    /// settings are left as they are).
    pub fn apply(self, p: &mut SimParams) {
        let defaults = SimParams::for_edge(1e-2);
        p.newton_max_iters = defaults.newton_max_iters;
        p.newton_tol_m = defaults.newton_tol_m;
        p.cg_rel_tol = defaults.cg_rel_tol;
        p.cg_max_iters = defaults.cg_max_iters;
        p.max_halvings = defaults.max_halvings;
        p.substeps = 1;
        p.strict_solves = false;
        p.rescue_capped_solves = false;
        match self {
            SolverMode::Fast => p.newton_exact = false,
            SolverMode::Data => {
                p.newton_exact = false;
                p.substeps = DATA_SUBSTEPS;
                p.strict_solves = true;
                p.rescue_capped_solves = true;
                p.max_halvings = 6;
            }
            SolverMode::Converged => p.newton_exact = true,
            SolverMode::Tight => {
                p.newton_exact = true;
                p.newton_tol_m = 1e-3 * defaults.newton_tol_m;
                p.newton_max_iters = 40;
                p.cg_rel_tol = 1e-6;
                p.cg_max_iters = 100_000;
                p.strict_solves = true;
                p.max_halvings = 8;
            }
        }
    }
}

/// Sub-steps a step of [`SolverMode::Data`].
pub const DATA_SUBSTEPS: u32 = 4;

impl std::fmt::Display for SolverMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
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
            dt_s: clothsr_geometry::scene::DEFAULT_DT_S,
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
            newton_tol_m: 3e-2 * clothsr_geometry::scene::DEFAULT_DT_S,
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
            substeps: 1,
            strict_solves: false,
            rescue_capped_solves: false,
        }
    }
}
