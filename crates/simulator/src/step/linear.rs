//! The linear solve of each Newton iteration.

use nalgebra::Vector3;

use super::{CholeskyPreconditioner, LinearSolver, Simulator, TwoLevel};
use crate::sparse::CgStats;

/// From this many vertices [`LinearSolver::Auto`] adds the two-level coarse correction: about
/// where it starts to pay off against block-Jacobi alone (`clothsr lab bench sim`, fast mode).
pub(super) const TWO_LEVEL_FROM_VERTICES: usize = 2_500;

/// Below this many vertices the Newton systems are solved on a single thread.
pub(super) const SERIAL_BELOW_VERTICES: usize = 4000;

/// After a solve rescued by a sparse Cholesky factor ([`SimParams::rescue_capped_solves`]),
/// this many following solves go straight to a factor of their own matrix: where one solve
/// ran into its cap the next ones of the same stretch do too, and each would waste its cap's
/// iterations before being rescued.
///
/// [`SimParams::rescue_capped_solves`]: super::SimParams::rescue_capped_solves
const RESCUE_STICKS_FOR: usize = 8;

impl Simulator {
    /// Solves the Newton system `matrix · dx = rhs` (warm-started from `dx`) with the
    /// configured solver; a solve stopped at its cap is, when
    /// [`SimParams::rescue_capped_solves`](super::SimParams::rescue_capped_solves) is set,
    /// carried on preconditioned by a sparse Cholesky factor of its own matrix.
    pub(super) fn linear_solve(
        &mut self,
        rhs: &[Vector3<f64>],
        dx: &mut [Vector3<f64>],
    ) -> CgStats {
        if !self.params.rescue_capped_solves {
            return self.configured_solve(rhs, dx);
        }
        if self.rescue_sticky > 0 {
            self.rescue_sticky -= 1;
            if let Some(stats) = self.factored_solve(rhs, dx, 0) {
                return stats;
            }
        }
        let first = self.configured_solve(rhs, dx);
        if first.relative_residual <= self.params.cg_rel_tol {
            return first;
        }
        match self.factored_solve(rhs, dx, first.iterations) {
            Some(stats) => {
                self.rescue_sticky = RESCUE_STICKS_FOR;
                tracing::trace!(
                    first = first.iterations,
                    then = stats.iterations - first.iterations,
                    "capped solve rescued by a Cholesky factor"
                );
                stats
            }
            None => first,
        }
    }

    /// PCG from `dx` preconditioned by a sparse Cholesky factor of the present matrix (its
    /// pattern part), `before` iterations already spent on this system; `None` when the
    /// factorisation fails (the matrix is not numerically positive definite).
    fn factored_solve(
        &mut self,
        rhs: &[Vector3<f64>],
        dx: &mut [Vector3<f64>],
        before: usize,
    ) -> Option<CgStats> {
        if self.cholesky.is_none() {
            self.cholesky = CholeskyPreconditioner::new(&self.matrix);
        }
        let pre = self.cholesky.as_mut()?;
        if !pre.factorize(&self.matrix, &self.solve_free) {
            tracing::debug!("sparse Cholesky factorisation failed; the capped solve stands");
            return None;
        }
        let stats = self.pcg.solve_with_factor(
            &self.matrix,
            rhs,
            dx,
            &self.solve_free,
            pre,
            self.params.cg_rel_tol,
            self.params.cg_max_iters,
        );
        self.last_cg_iters = stats.iterations;
        Some(CgStats {
            iterations: before + stats.iterations,
            relative_residual: stats.relative_residual,
        })
    }

    /// The solve of [`SimParams::linear_solver`](super::SimParams::linear_solver).
    fn configured_solve(&mut self, rhs: &[Vector3<f64>], dx: &mut [Vector3<f64>]) -> CgStats {
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
                self.pcg
                    .solve(&self.matrix, rhs, dx, &self.solve_free, tol, max)
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
                            let ok = coarse.factorize(&self.matrix, &self.solve_free);
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
                            &self.solve_free,
                            coarse,
                            tol,
                            max,
                        )
                    }
                    None => self
                        .pcg
                        .solve(&self.matrix, rhs, dx, &self.solve_free, tol, max),
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
                            let ok = pre.factorize(&self.matrix, &self.solve_free);
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
                                &self.solve_free,
                                pre,
                                tol,
                                max,
                            )
                        } else {
                            self.pcg
                                .solve(&self.matrix, rhs, dx, &self.solve_free, tol, max)
                        }
                    }
                    None => self
                        .pcg
                        .solve(&self.matrix, rhs, dx, &self.solve_free, tol, max),
                }
            }
        };
        self.last_cg_iters = stats.iterations;
        stats
    }
}
