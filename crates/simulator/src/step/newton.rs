//! One (sub)step's Newton iteration: its start, the iterations and the end of the step.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::damping::DampingRows;
use super::line_search::{limit_pair_closing, slid_over_crease, Accepted, ClosingPair};
use super::state::BodyMotion;
use super::{ColliderFrame, SimState, Simulator, StepStats, MAX_OBSTACLE_MARGIN_M};
use crate::collide::{Contact, StepStart};
use crate::sparse::CgStats;
use clothsr_geometry::error::{Error, Result};

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

/// What the Newton iterations of one (sub)step hold fixed.
pub(super) struct Increment<'a> {
    /// Positions at the start of the step, m.
    pub(super) x_n: &'a [Vector3<f64>],
    /// The inertial prediction xₙ + h vₙ + h² g, pinned vertices at their targets, m.
    pub(super) x_tilde: &'a [Vector3<f64>],
    /// The (sub)step, s.
    pub(super) h: f64,
    /// Time at its start, s.
    t_s: f64,
    /// Per collider, whether it holds still during the step.
    still: &'a [bool],
    /// Colliders at the end of the (sub)step.
    colliders: &'a [ColliderFrame<'a>],
    /// Where the colliders are during the whole step.
    motion: &'a BodyMotion<'a, 'a>,
    /// Most any vertex moves in one Newton iteration, m.
    pub(super) max_move: f64,
    /// How far cloth may approach a body in one iteration ([`ClosingPair::all`]).
    body_narrow: Option<f64>,
    /// Whether the step may no longer be halved.
    last_resort: bool,
}

/// The potential one Newton iteration minimises: the step's, with that iteration's contact set.
pub(super) struct Potential<'a> {
    pub(super) inc: &'a Increment<'a>,
    damping: &'a DampingRows,
    contacts: &'a [Contact],
}

impl Potential<'_> {
    /// The incremental potential at `x`.
    pub(super) fn at(&self, sim: &Simulator, x: &[Vector3<f64>]) -> f64 {
        let inc = self.inc;
        sim.potential(x, inc.x_n, inc.x_tilde, inc.h, self.damping, self.contacts)
    }
}

impl Simulator {
    pub(super) fn solve_step(
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
        self.seam_rest_step_m = self.step_seam_rest(&state.x, h);
        let x_n = &state.x;
        let (x_tilde, x, still) = self.start_positions(state, h, motion, colliders);
        let damping = self.damping_rows(x_n);
        let (max_move, body_narrow) = self.move_limits()?;
        let x_start = x.clone();
        // Each step's solve starts from zero. Starting from the last step's displacement
        // saves some CG iterations, but the unsolved part of that guess carries the last
        // motion on: a hanging sheet kept far more kinetic energy than it should.
        self.dx.iter_mut().for_each(|d| *d = Vector3::zeros());
        let prelude_ms = t_prelude.elapsed().as_secs_f64() * 1e3;
        stats.times.prelude_s += prelude_ms * 1e-3;
        let t_newton = std::time::Instant::now();
        let inc = Increment {
            x_n,
            x_tilde: &x_tilde,
            h,
            t_s: state.t_s,
            still: &still,
            colliders,
            motion,
            max_move,
            body_narrow,
            last_resort,
        };
        let timed = |t: &super::PhaseTimes| t.detect_s + t.assemble_s + t.solve_s;
        let before = timed(&stats.times);
        let (x, energy, contacts) = self.newton(&inc, x, damping, stats)?;
        let t_epilogue = std::time::Instant::now();
        // The rest of the iterations' time: line searches, move limits, convergence tests.
        stats.times.search_s +=
            (t_epilogue - t_newton).as_secs_f64() - (timed(&stats.times) - before);
        let travelled = x
            .iter()
            .zip(&x_start)
            .map(|(a, b)| (a - b).norm_squared())
            .fold(0.0, f64::max)
            .sqrt();
        self.obstacle_margin_m = (2.5 * travelled)
            .min(MAX_OBSTACLE_MARGIN_M)
            .max(self.params.detection_margin_m);
        let mut v: Vec<Vector3<f64>> = (0..n).map(|i| (x[i] - x_n[i]) / h).collect();
        self.follow_welds(&mut v);
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
        stats.times.epilogue_s += t_epilogue.elapsed().as_secs_f64();
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

    /// The seam rest lengths of a step of `h` from positions `x_n`: each shrinks at the sewing
    /// speed, but not below the pair's gap less the most a seam may stretch.
    fn step_seam_rest(&self, x_n: &[Vector3<f64>], h: f64) -> Vec<f64> {
        let shrink = self.params.sew_speed_m_s * h;
        let slack = self.params.sew_max_stretch_m;
        self.model
            .mesh
            .seam_pairs
            .iter()
            .zip(&self.seam_rest_m)
            .map(|(p, &r)| {
                let gap = (x_n[p[0] as usize] - x_n[p[1] as usize]).norm();
                (r - shrink).max(r.min(gap - slack)).max(0.0)
            })
            .collect()
    }

    /// The inertial prediction x̃, the Newton iteration's start x (both with the pinned
    /// vertices at their targets) and which colliders hold still during the step.
    #[allow(clippy::type_complexity)]
    fn start_positions(
        &mut self,
        state: &SimState,
        h: f64,
        motion: &BodyMotion<'_, '_>,
        colliders: &[ColliderFrame<'_>],
    ) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>, Vec<bool>) {
        let n = self.model.num_vertices();
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
        if self.cloth_contacts_on() {
            self.limit_inertial_start(state, h, &mut x);
        }
        for pin in &self.pins {
            let p = self.pin_position(pin, colliders);
            x[pin.v as usize] = p;
            x_tilde[pin.v as usize] = p;
        }
        // A state set from outside (a corrector's, a downsampled one) may part welded vertices.
        self.follow_welds(&mut x);
        self.follow_welds(&mut x_tilde);
        (x_tilde, x, still)
    }

    /// Shortens the inertial start `x` = xₙ + h vₙ where it would carry cloth through cloth.
    fn limit_inertial_start(&mut self, state: &SimState, h: f64, x: &mut [Vector3<f64>]) {
        let x_n = &state.x;
        // That start is a move like any Newton step's, and must not carry cloth through
        // cloth: layers closing faster than their gap per step crossed in the initial
        // guess, before any contact was looked for there (the circle skirt on the walking
        // avatar tangled so). The pairs that may meet on the way (swept boxes) close by
        // at most 0.8 of their gap at xₙ ([`ClosingPair`]); cloth moving together, as a
        // falling sheet, keeps its whole inertial move.
        let mut pairs = self.detector.find_swept_self_pairs(
            x_n,
            x,
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

    /// The most any vertex moves in one Newton iteration, and how far cloth may approach a
    /// body in one ([`ClosingPair::all`]).
    fn move_limits(&self) -> Result<(f64, Option<f64>)> {
        // Per Newton iteration no vertex moves further than keeps its contact set valid.
        // Contacts are found within d̂ plus a margin, so pairs that were not found are at least
        // that far apart: cloth–body pairs stay beyond d̂ while each vertex moves less than the
        // margin (the body holds still within an iteration), cloth–cloth pairs while each of
        // their two sides moves at most half of it. Pairs that were found close by at most 0.8
        // of their gap, and cloth approaches a body by at most max(d/2, ½ d̂) but slides
        // freely ([`ClosingPair`]).
        let max_move = if self.cloth_contacts_on() {
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
            .cloth_contacts_on()
            .then_some((0.5 * self.params.detection_margin_m).min(cap));
        Ok((max_move, body_narrow))
    }

    /// Newton's iterations from `x`: the positions they end at, their energy and the contact
    /// set of the last one.
    fn newton(
        &mut self,
        inc: &Increment<'_>,
        mut x: Vec<Vector3<f64>>,
        mut damping: DampingRows,
        stats: &mut StepStats,
    ) -> Result<(Vec<Vector3<f64>>, f64, Vec<Contact>)> {
        let n = self.model.num_vertices();
        let mut contacts = Vec::new();
        let mut energy = f64::NAN;
        // The tolerance is a velocity error: shared out among a step's sub-steps.
        let tol = self.params.newton_tol_m / f64::from(self.params.substeps.max(1));
        // Whether the iterations stopped on the tolerance (or, in fast mode, on a full step).
        let mut converged = false;
        // Kept between steps for its buffers; a step that fails leaves a new one behind.
        let mut hold = std::mem::take(&mut self.pinch);
        hold.start(n);
        for it in 0..self.params.newton_max_iters {
            let t_detect = std::time::Instant::now();
            let since = StepStart {
                x: inc.x_n,
                still: inc.still,
            };
            let mut found = self.contacts(&x, since, inc.colliders);
            let held = hold.apply(&x, &contacts, &mut found);
            if held > 0 {
                tracing::trace!(it, held, "pinched vertices hold their body contacts");
            }
            contacts = found;
            if it == 0 {
                damping.friction = self.friction_points(inc.x_n, &contacts, inc.motion);
            }
            let pairs = ClosingPair::all(&x, &contacts, inc.body_narrow);
            let t_assemble = std::time::Instant::now();
            energy = self.assemble(&x, inc.x_n, inc.x_tilde, inc.h, &damping, &contacts);
            let t_solve = std::time::Instant::now();
            if !energy.is_finite() {
                return Err(Error::Simulation(format!(
                    "energy is not finite at t = {:.5} s",
                    inc.t_s
                )));
            }
            let (mut dx, cg) = self.newton_direction();
            self.follow_welds(&mut dx);
            stats.cg_iters += cg.iterations;
            stats.newton_iters += 1;
            if cg.relative_residual > self.params.cg_rel_tol {
                if self.params.strict_solves && !inc.last_resort {
                    self.dx = vec![Vector3::zeros(); n];
                    return Err(Error::Simulation(format!(
                        "the linear solve stopped at {} iterations with residual {:.1e} at t = {:.5} s",
                        cg.iterations, cg.relative_residual, inc.t_s
                    )));
                }
                stats.capped_solves += 1;
            }
            let t_search = std::time::Instant::now();
            stats.times.detect_s += (t_assemble - t_detect).as_secs_f64();
            stats.times.assemble_s += (t_solve - t_assemble).as_secs_f64();
            stats.times.solve_s += (t_search - t_solve).as_secs_f64();
            let slope: f64 = self.grad.iter().zip(&dx).map(|(g, d)| g.dot(d)).sum();
            let longest = dx.iter().map(|d| d.norm()).fold(0.0, f64::max);
            if !longest.is_finite() || !slope.is_finite() {
                self.dx = vec![Vector3::zeros(); n];
                return Err(Error::Simulation(format!(
                    "the Newton direction is not finite at t = {:.5} s",
                    inc.t_s
                )));
            }
            if slope >= 0.0 {
                // No descent left at rounding level: as converged as it gets.
                self.dx = dx;
                converged = true;
                break;
            }
            let potential = Potential {
                inc,
                damping: &damping,
                contacts: &contacts,
            };
            if longest < tol {
                // Converged: the last, short Newton step is still taken (within the move
                // limits, if its energy decreases). Dropped, it was each step's gravity
                // increment once air damping nearly balanced it (h²(g − αv) < tol):
                // free-falling cloth stopped accelerating.
                if let Some((trial, e)) = self.converged_step(&potential, &pairs, &x, &dx, energy) {
                    x = trial;
                    energy = e;
                }
                dx.iter_mut().for_each(|d| *d = Vector3::zeros());
                self.dx = dx;
                converged = true;
                break;
            }
            let Some(accepted) = self.line_search(&potential, &pairs, &x, &dx, slope, energy)
            else {
                self.dx = vec![Vector3::zeros(); n];
                if it == 0 {
                    return Err(Error::Simulation(format!(
                        "no energy decrease at t = {:.5} s",
                        inc.t_s
                    )));
                }
                // No decrease along a descent direction: the energy is flat to rounding.
                converged = true;
                break;
            };
            let Accepted {
                step,
                alpha,
                step_longest,
                ..
            } = accepted;
            // Fast mode stops after the first full, unclipped step. Without self-collision,
            // where a vertex may move the whole obstacle margin (up to 10 mm) an iteration,
            // not when a vertex touching a body slid further than FAST_CONTACT_MOVE_M within
            // reach of an edge where the body turns ([`slid_over_crease`]: a sheet dropped onto a
            // table left its edge fast, with more energy than it had). With self-collision the
            // moves are capped at half the cloth margin and the same drop keeps its energy.
            let clipped = accepted.clipped || alpha < 1.0;
            let fast_done = !self.params.newton_exact
                && !clipped
                && (self.cloth_contacts_on()
                    || !slid_over_crease(
                        &self.detector,
                        &contacts,
                        &x,
                        &step,
                        alpha,
                        self.params.collision.dhat_m + self.obstacle_margin_m,
                    ));
            x = accepted.x;
            energy = accepted.energy;
            let moved = step_longest * alpha;
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
            if moved < tol || fast_done {
                converged = true;
                break;
            }
            // Out of iterations with moves still cut short: the cloth lags where it should be
            // (a leg pushing a fold of skirt into the other layer). Taken as it is, the body
            // runs into cloth that could not follow; half the step asks half the move.
            if it + 1 == self.params.newton_max_iters && clipped && !inc.last_resort {
                self.dx = vec![Vector3::zeros(); n];
                return Err(Error::Simulation(format!(
                    "the move limits still held vertices back after {} Newton iterations at t = {:.5} s",
                    it + 1,
                    inc.t_s
                )));
            }
        }
        if !converged {
            if self.params.strict_solves && !inc.last_resort {
                self.dx = vec![Vector3::zeros(); n];
                return Err(Error::Simulation(format!(
                    "Newton's iterations ran out before the tolerance at t = {:.5} s",
                    inc.t_s
                )));
            }
            stats.unconverged_steps += 1;
        }
        self.pinch = hold;
        Ok((x, energy, contacts))
    }

    /// The Newton direction −H⁻¹g of the assembled system, solved in the reused buffer
    /// `self.dx` (taken out of it), and the solve's statistics.
    fn newton_direction(&mut self) -> (Vec<Vector3<f64>>, CgStats) {
        // Reused across iterations: no per-iteration allocation of the right-hand side.
        let mut rhs = std::mem::take(&mut self.rhs);
        rhs.clear();
        rhs.extend(self.grad.iter().map(|g| -g));
        let mut dx = std::mem::take(&mut self.dx);
        let cg = self.linear_solve(&rhs, &mut dx);
        self.rhs = rhs;
        (dx, cg)
    }
}
