//! Sewing: stiff springs between seam vertex pairs that pull panels placed around a body together
//! into a garment. Each spring has a rest length r that shrinks to zero while the garment is
//! sewn (so seams close at a bounded speed that collisions can follow, as garment CAD tools do),
//! and only pulls:
//!
//! E = ½ k (d − r)² for d = |x_a − x_b| > r, else 0  (k in N/m).
//!
//! With r = 0 it is the zero-length spring ½ k |x_a − x_b|², whose Hessian k [[I, −I], [−I, I]]
//! is constant. For d > r the Hessian in Δ = x_a − x_b is k [n nᵀ + (1 − r/d)(I − n nᵀ)], which
//! is PSD (both coefficients ≥ 0).

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// Energy of one seam spring with rest length `rest_m`, joules.
pub fn energy(k_n_m: f64, rest_m: f64, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let d = (a - b).norm();
    if d <= rest_m {
        0.0
    } else {
        0.5 * k_n_m * (d - rest_m).powi(2)
    }
}

/// Gradient (6: ∂/∂a, ∂/∂b) and PSD Hessian (6×6).
pub fn gradient_hessian(
    k_n_m: f64,
    rest_m: f64,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
) -> (SVector<f64, 6>, SMatrix<f64, 6, 6>) {
    let delta = a - b;
    let d = delta.norm();
    let mut g = SVector::<f64, 6>::zeros();
    let mut h = SMatrix::<f64, 6, 6>::zeros();
    if d <= rest_m {
        return (g, h);
    }
    let (gd, hd) = if rest_m <= 0.0 {
        (delta * k_n_m, Matrix3::identity() * k_n_m)
    } else {
        let n = delta / d;
        let nn = n * n.transpose();
        (
            n * (k_n_m * (d - rest_m)),
            (nn + (Matrix3::identity() - nn) * (1.0 - rest_m / d)) * k_n_m,
        )
    };
    g.fixed_rows_mut::<3>(0).copy_from(&gd);
    g.fixed_rows_mut::<3>(3).copy_from(&-gd);
    h.fixed_view_mut::<3, 3>(0, 0).copy_from(&hd);
    h.fixed_view_mut::<3, 3>(3, 3).copy_from(&hd);
    h.fixed_view_mut::<3, 3>(0, 3).copy_from(&-hd);
    h.fixed_view_mut::<3, 3>(3, 0).copy_from(&-hd);
    (g, h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::fd;

    #[test]
    fn sewing_derivatives_match_finite_differences() {
        let x = SVector::<f64, 6>::from_column_slice(&[0.1, -0.2, 0.3, 0.05, 0.4, -0.1]);
        let split = |y: &SVector<f64, 6>| {
            (
                Vector3::new(y[0], y[1], y[2]),
                Vector3::new(y[3], y[4], y[5]),
            )
        };
        // Zero rest length (sewn) and a shrinking one shorter than the current gap.
        for rest in [0.0, 0.3] {
            let (a, b) = split(&x);
            let (g, h) = gradient_hessian(500.0, rest, &a, &b);
            fd::check_gradient(
                |y| {
                    let (a, b) = split(y);
                    energy(500.0, rest, &a, &b)
                },
                &g,
                &x,
                1e-6,
                1e-6,
            );
            fd::check_hessian(
                |y| {
                    let (a, b) = split(y);
                    gradient_hessian(500.0, rest, &a, &b).0
                },
                &h,
                &x,
                1e-6,
                1e-6,
            );
            fd::check_psd(&h);
        }
        // Closer than the rest length: no force.
        let (a, b) = split(&x);
        let gap = (a - b).norm();
        assert_eq!(energy(500.0, gap + 0.01, &a, &b), 0.0);
        assert_eq!(
            gradient_hessian(500.0, gap + 0.01, &a, &b).0,
            SVector::<f64, 6>::zeros()
        );
    }
}
