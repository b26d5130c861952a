//! The linear solve of each Newton iteration.

use nalgebra::Vector3;

use super::{CholeskyPreconditioner, LinearSolver, Simulator, TwoLevel};
use crate::sparse::CgStats;

/// From this many vertices [`LinearSolver::Auto`] adds the two-level coarse correction: about
/// where it starts to pay off against block-Jacobi alone (`clothsr lab bench sim`, fast mode).
pub(super) const TWO_LEVEL_FROM_VERTICES: usize = 2_500;

/// Below this many vertices the Newton systems are solved on a single thread.
pub(super) const SERIAL_BELOW_VERTICES: usize = 4000;
impl Simulator {
    pub(super) fn linear_solve(
        &mut self,
        rhs: &[Vector3<f64>],
        dx: &mut [Vector3<f64>],
    ) -> CgStats {
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
