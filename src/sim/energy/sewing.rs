//! Sewing: stiff zero-length springs between seam vertex pairs, E = ½ k |x_a − x_b|² (k in N/m),
//! pulling panels placed around a body together into a garment.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// Energy of one seam spring, joules.
pub fn energy(k_n_m: f64, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    0.5 * k_n_m * (a - b).norm_squared()
}

/// Gradient (6: ∂/∂a, ∂/∂b) and the constant PSD Hessian k [[I, −I], [−I, I]].
pub fn gradient_hessian(
    k_n_m: f64,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
) -> (SVector<f64, 6>, SMatrix<f64, 6, 6>) {
    let d = (a - b) * k_n_m;
    let mut g = SVector::<f64, 6>::zeros();
    g.fixed_rows_mut::<3>(0).copy_from(&d);
    g.fixed_rows_mut::<3>(3).copy_from(&-d);
    let i = Matrix3::identity() * k_n_m;
    let mut h = SMatrix::<f64, 6, 6>::zeros();
    h.fixed_view_mut::<3, 3>(0, 0).copy_from(&i);
    h.fixed_view_mut::<3, 3>(3, 3).copy_from(&i);
    h.fixed_view_mut::<3, 3>(0, 3).copy_from(&-i);
    h.fixed_view_mut::<3, 3>(3, 0).copy_from(&-i);
    (g, h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::energy::fd;

    #[test]
    fn sewing_derivatives_match_finite_differences() {
        let x = SVector::<f64, 6>::from_column_slice(&[0.1, -0.2, 0.3, 0.05, 0.4, -0.1]);
        let split = |y: &SVector<f64, 6>| {
            (
                Vector3::new(y[0], y[1], y[2]),
                Vector3::new(y[3], y[4], y[5]),
            )
        };
        let (a, b) = split(&x);
        let (g, h) = gradient_hessian(500.0, &a, &b);
        fd::check_gradient(
            |y| {
                let (a, b) = split(y);
                energy(500.0, &a, &b)
            },
            &g,
            &x,
            1e-6,
            1e-6,
        );
        fd::check_hessian(
            |y| {
                let (a, b) = split(y);
                gradient_hessian(500.0, &a, &b).0
            },
            &h,
            &x,
            1e-6,
            1e-6,
        );
        fd::check_psd(&h);
    }
}
