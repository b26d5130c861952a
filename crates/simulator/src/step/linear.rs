//! The linear solve of each Newton iteration.

use nalgebra::Vector3;

use super::{CholeskyPreconditioner, LinearSolver, Simulator, TwoLevel};
use crate::sparse::CgStats;

/// From this many vertices [`LinearSolver::Auto`] adds the two-level coarse correction
/// (bench sim, fast mode, ms a step, block-Jacobi vs two-level with aggregates of 32 / 64:
/// 1K vertices 3.96 vs 4.52 / 4.48; 2K 8.49 vs 8.55 / 8.66; 3K 13.6 vs 11.6 / 12.2; 6K 24.4 vs
/// 23.9 / 21.1).
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
}
