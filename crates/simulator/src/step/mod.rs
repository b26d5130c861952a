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
//! 0.8 of their gap (see `ClosingPair`), so cloth never passes through cloth. Cloth caught
//! where a body overlaps itself keeps its body contacts through the step's iterations
//! (`PinchHold`), which otherwise flip between the overlapping parts. A step that
//! yields NaN, cannot decrease the energy or still has moves cut short after the iteration cap
//! is retried as two half steps.

mod contacts;
mod damping;
mod friction;
mod line_search;
mod linear;
mod newton;
mod params;
mod potential;
mod state;

pub use friction::FrictionPoint;
pub use line_search::FAST_CONTACT_MOVE_M;
pub use params::{LinearSolver, SimParams, SolverMode, DATA_SUBSTEPS};
pub use state::{ColliderFrame, PhaseTimes, Pin, PinTarget, SimState, StepStats};

use nalgebra::Vector3;

use super::collide::{edge_triangle_crossings, ClothPairs, CollisionDetector};
use super::model::ClothModel;
use super::scatter::ColouredElements;
use super::sparse::{BlockCsr, CholeskyPreconditioner, Pcg, TwoLevel};
use clothsr_geometry::error::{Error, Result};
use contacts::{seam_rings, self_margin_cap, PinchHold};
use linear::SERIAL_BELOW_VERTICES;
use state::BodyMotion;

/// Triangles (3 vertices, 9 blocks) and hinges (4 vertices, 16 blocks) for the coloured scatter.
type MembraneSet = ColouredElements<3, 9>;
type HingeSet = ColouredElements<4, 16>;

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
    /// For each vertex, the vertex it is welded to (the first of its seam group, itself when
    /// not sewn) once the seams are welded ([`Simulator::weld_seams`]); empty before.
    weld: Vec<u32>,
    /// The linear solve's unknowns: `free` less the welded vertices that follow another.
    solve_free: Vec<bool>,
    grad: Vec<Vector3<f64>>,
    dx: Vec<Vector3<f64>>,
    rhs: Vec<Vector3<f64>>,
    /// Membranes and hinges in colours that share no vertex, with their matrix slots.
    mem_set: MembraneSet,
    hinge_set: HingeSet,
    detector: CollisionDetector,
    /// For sewn vertices: the vertices sewn to them (sorted; see [`seam_rings`]).
    seam_ring: std::collections::HashMap<u32, Vec<u32>>,
    /// Body contacts held through a step's Newton iterations ([`PinchHold`]).
    pinch: PinchHold,
    cholesky: Option<CholeskyPreconditioner>,
    two_level: Option<TwoLevel>,
    last_cg_iters: usize,
    /// Solves left that go straight to a Cholesky factor after a rescued one.
    rescue_sticky: usize,
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
/// What [`Simulator::weld_seams`] welded.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Welded {
    /// Seam pairs welded.
    pub pairs: usize,
    /// The widest gap among them before welding, m.
    pub widest_gap_m: f64,
}

/// Upper bound of the adaptive cloth–collider detection margin, m.
pub(crate) const MAX_OBSTACLE_MARGIN_M: f64 = 0.01;
impl Simulator {
    /// A simulator for `model` with `params`.
    pub fn new(model: ClothModel, params: SimParams) -> Simulator {
        let n = model.num_vertices();
        let matrix = BlockCsr::with_pattern(n, model.coupled_pairs());
        Simulator {
            free: vec![true; n],
            weld: Vec::new(),
            solve_free: vec![true; n],
            grad: vec![Vector3::zeros(); n],
            dx: vec![Vector3::zeros(); n],
            rhs: Vec::with_capacity(n),
            mem_set: MembraneSet::new(model.membranes.iter().map(|m| m.v).collect(), &matrix),
            hinge_set: HingeSet::new(model.hinges.iter().map(|h| h.v).collect(), &matrix),
            detector: CollisionDetector::new(),
            seam_ring: seam_rings(&model),
            pinch: PinchHold::default(),
            cholesky: None,
            two_level: None,
            last_cg_iters: usize::MAX,
            rescue_sticky: 0,
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
            // hand-offs cost more than CG's short passes there (a one-thread pool of its own
            // is slower than solving inline: the matrix then lives in the other core's cache).
            // Detection, assembly and the line search use every thread at any size; their sums
            // are taken in fixed chunks ([`super::reduce`]), so a run gives the same bits on
            // any number of threads (a step's sums used to follow rayon's splits, and the
            // pencil skirt's rounding-sensitive dressing ended differently on two threads
            // than on one).
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

    /// Which cloth–cloth pairs are detected besides self-collision's (every pair, when
    /// `params.collision.self_collision` is on): those within one panel (`within_panels`),
    /// those between two garments (`between_garments`), or both, among the garments `active`
    /// (all when `None`; the others' vertices take part in no cloth–cloth contact, even with
    /// self-collision). `None` as a whole: only self-collision's.
    pub fn set_cloth_pairs(&mut self, pairs: Option<(bool, bool, Option<Vec<bool>>)>) {
        self.detector.cloth_pairs = pairs.map(|(within_panels, between_garments, active)| {
            let mut garment = vec![0u32; self.model.num_vertices()];
            for (g, part) in self.model.parts.iter().enumerate() {
                garment[part.vertices.clone()].fill(g as u32);
            }
            let garments = self.model.parts.len().max(1);
            std::sync::Arc::new(ClothPairs {
                panel: self.model.mesh.panel_of_vertex.clone(),
                garment,
                active: active
                    .filter(|a| a.len() == garments)
                    .unwrap_or_else(|| vec![true; garments]),
                within_panels,
                between_garments,
            })
        });
    }

    /// Whether cloth–cloth contacts are detected: self-collision, or some pairs named by
    /// [`Self::set_cloth_pairs`].
    pub fn cloth_contacts_on(&self) -> bool {
        self.params.collision.self_collision || self.detector.cloth_pairs.is_some()
    }

    /// The pins ([`Self::set_pins`]).
    pub fn pins(&self) -> &[Pin] {
        &self.pins
    }

    /// Drops what steps carry from one to the next besides the state, the seam rest lengths
    /// and the detection margin (cached hierarchies, clearances, preconditioner factors), so
    /// that the next step is the one a new simulator restored to the same state would take.
    /// Called at the points a run can be resumed from, it makes a resumed run bit-identical.
    pub fn forget_history(&mut self) {
        self.detector.forget();
        self.last_cg_iters = usize::MAX;
        self.rescue_sticky = 0;
        if let Some(c) = self.cholesky.as_mut() {
            c.forget();
        }
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
    pub(super) fn sewn_together(&self, a: &[u32], b: &[u32]) -> bool {
        a.iter().any(|p| {
            self.seam_ring
                .get(p)
                .is_some_and(|r| b.iter().any(|q| r.binary_search(q).is_ok()))
        })
    }

    /// The widest gap between sewn vertex pairs in `x`, m (0 without seams), over the pairs
    /// with a free side (one pinned at both ends cannot close).
    pub fn max_seam_gap_m(&self, x: &[Vector3<f64>]) -> f64 {
        self.model
            .mesh
            .seam_pairs
            .iter()
            .filter(|p| self.free[p[0] as usize] || self.free[p[1] as usize])
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
        self.update_solve_free();
    }

    /// Welded groups follow a pinned member when they have one (else the group's first
    /// vertex), so that a pin on a sewn vertex holds its whole group.
    fn weld_to_pins(&mut self) {
        if self.weld.is_empty() {
            return;
        }
        let mut lead: Vec<u32> = (0..self.weld.len() as u32).collect();
        for (i, w) in self.weld.iter().enumerate() {
            if !self.free[i] {
                lead[*w as usize] = i as u32;
            }
        }
        for w in &mut self.weld {
            *w = lead[*w as usize];
        }
    }

    fn update_solve_free(&mut self) {
        self.weld_to_pins();
        self.solve_free.clone_from(&self.free);
        for (i, w) in self.weld.iter().enumerate() {
            if *w as usize != i {
                self.solve_free[i] = false;
            }
        }
    }

    /// Welds the seams, as a sewing machine does once a tailor has pinned them: the vertices
    /// of each seam pair no more than `max_gap_m` apart in `state` (and of pairs sharing a
    /// vertex with one, where three panels meet) become one point for the rest of the
    /// simulation, each group moved to its mass-weighted mean position and velocity. Sewing
    /// springs only pull seams closed; under load they stay open by force over stiffness,
    /// and where a body blocks them (an armpit, a waistband on the hips) they stay open by the
    /// contact thickness. Welded, the two sides are one unknown of each Newton system (their
    /// gradients and matrix rows summed) and every step moves them together; wider pairs stay
    /// on their springs. Called again, it welds the pairs that have closed since into the
    /// groups already welded (a no-op without seams); `max_gap_m` 0 finds the welds of a
    /// state saved from a welded run (their sides coincide exactly). Returns how many pairs
    /// were welded by this call, from how far apart.
    pub fn weld_seams(&mut self, state: &mut SimState, max_gap_m: f64) -> Welded {
        let n = self.model.num_vertices();
        let mut welded = Welded::default();
        if self.model.mesh.seam_pairs.is_empty() || state.x.len() != n {
            return welded;
        }
        let gap = |p: &[u32; 2]| (state.x[p[0] as usize] - state.x[p[1] as usize]).norm();
        let apart_now = |p: &[u32; 2]| {
            self.weld.is_empty() || self.weld[p[0] as usize] != self.weld[p[1] as usize]
        };
        let close: Vec<[u32; 2]> = self
            .model
            .mesh
            .seam_pairs
            .iter()
            .filter(|p| apart_now(p) && gap(p) <= max_gap_m)
            .copied()
            .collect();
        if close.is_empty() {
            return welded;
        }
        welded.pairs = close.len();
        welded.widest_gap_m = close.iter().map(gap).fold(0.0, f64::max);
        // Each vertex's group lead is its parent: groups welded before stay whole.
        let mut parent: Vec<u32> = if self.weld.is_empty() {
            (0..n as u32).collect()
        } else {
            self.weld.clone()
        };
        fn root(parent: &mut [u32], i: u32) -> u32 {
            let mut r = i;
            while parent[r as usize] != r {
                r = parent[r as usize];
            }
            let mut j = i;
            while parent[j as usize] != r {
                let next = parent[j as usize];
                parent[j as usize] = r;
                j = next;
            }
            r
        }
        for p in &close {
            let (a, b) = (root(&mut parent, p[0]), root(&mut parent, p[1]));
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
        let weld: Vec<u32> = (0..n as u32).map(|i| root(&mut parent, i)).collect();
        // Each group at its centre of mass, moving with its momentum.
        let mut sums = vec![(0.0, Vector3::zeros(), Vector3::zeros()); n];
        for (i, w) in weld.iter().enumerate() {
            let m = self.model.mass_kg[i];
            let s = &mut sums[*w as usize];
            s.0 += m;
            s.1 += state.x[i] * m;
            s.2 += state.v[i] * m;
        }
        // Groups already on one point (a state saved from a welded run) keep its exact bits.
        let mut apart = vec![false; n];
        for (i, w) in weld.iter().enumerate() {
            let w = *w as usize;
            apart[w] |= state.x[i] != state.x[w] || state.v[i] != state.v[w];
        }
        for (i, w) in weld.iter().enumerate() {
            let (m, x, v) = sums[*w as usize];
            if apart[*w as usize] && m > 0.0 {
                state.x[i] = x / m;
                state.v[i] = v / m;
            }
        }
        // The pattern gains the blocks the welded rows fold into.
        let pairs = self.model.coupled_pairs();
        let folded: Vec<(u32, u32)> = pairs
            .iter()
            .map(|&(i, j)| (weld[i as usize], weld[j as usize]))
            .collect();
        self.matrix = BlockCsr::with_pattern(n, pairs.into_iter().chain(folded));
        self.mem_set = MembraneSet::new(
            self.model.membranes.iter().map(|m| m.v).collect(),
            &self.matrix,
        );
        self.hinge_set = HingeSet::new(
            self.model.hinges.iter().map(|h| h.v).collect(),
            &self.matrix,
        );
        self.cholesky = None;
        self.two_level = None;
        self.last_cg_iters = usize::MAX;
        self.rescue_sticky = 0;
        for (r, p) in self.seam_rest_m.iter_mut().zip(&self.model.mesh.seam_pairs) {
            if weld[p[0] as usize] == weld[p[1] as usize] {
                *r = 0.0;
            }
        }
        self.weld = weld;
        self.update_solve_free();
        welded
    }

    /// Whether the seams are welded ([`Simulator::weld_seams`]).
    pub fn welded(&self) -> bool {
        !self.weld.is_empty()
    }

    /// Welded vertices at their group's point: each follows the vertex it is welded to.
    pub(super) fn follow_welds(&self, x: &mut [Vector3<f64>]) {
        for (i, w) in self.weld.iter().enumerate() {
            if *w as usize != i {
                x[i] = x[*w as usize];
            }
        }
    }

    /// A step direction (already within the move limits) that moves every welded group as
    /// one: each group by the shortest of its members' moves (they are parallel, shortened
    /// one by one from the same direction).
    pub(super) fn tie_welds(&self, step: &mut [Vector3<f64>]) {
        for (i, w) in self.weld.iter().enumerate() {
            let w = *w as usize;
            if w != i && step[i].norm_squared() < step[w].norm_squared() {
                step[w] = step[i];
            }
        }
        self.follow_welds(step);
    }

    /// Sums the gradient and the matrix rows of each welded vertex into those of the vertex
    /// it follows (the chain rule for x_slave = x_master).
    pub(super) fn fold_welds(&mut self) {
        if self.weld.is_empty() {
            return;
        }
        for i in 0..self.weld.len() {
            let w = self.weld[i] as usize;
            if w != i {
                let g = std::mem::replace(&mut self.grad[i], Vector3::zeros());
                self.grad[w] += g;
            }
        }
        self.matrix.fold(&self.weld);
    }

    pub(super) fn pin_position(&self, pin: &Pin, colliders: &[ColliderFrame<'_>]) -> Vector3<f64> {
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
        let n = self.params.substeps.max(1);
        let h = self.params.dt_s / f64::from(n);
        // On a worker of rayon's pool: the step's many short parallel passes then start from
        // inside the pool instead of each waking it from the caller's thread.
        let span = |k: u32| (f64::from(k) / f64::from(n), f64::from(k + 1) / f64::from(n));
        let next = rayon::scope(|_| {
            let (c0, c1) = (colliders_start, colliders_end);
            let (a, b) = span(0);
            let mut next = self.advance(state, c0, c1, a, b, h, 0, &mut stats)?;
            for k in 1..n {
                let (a, b) = span(k);
                next = self.advance(&next, c0, c1, a, b, h, 0, &mut stats)?;
            }
            Ok::<_, Error>(next)
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
}
