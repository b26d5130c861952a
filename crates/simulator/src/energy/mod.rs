//! Cloth energies of the incremental potential, each with its gradient and a positive
//! semi-definite (PSD) Hessian, per element on small fixed-size nalgebra types:
//! membrane (Baraff-Witkin), bending (Discrete Shells), sewing springs.

pub mod bending;
pub mod membrane;
pub mod sewing;

use nalgebra::{SMatrix, SVector};

/// 9-vector: three stacked 3D points (a triangle).
pub type Vec9 = SVector<f64, 9>;
/// 9 × 9 matrix.
pub type Mat9 = SMatrix<f64, 9, 9>;
/// 12-vector: four stacked 3D points (a hinge, a contact pair).
pub type Vec12 = SVector<f64, 12>;
/// 12 × 12 matrix.
pub type Mat12 = SMatrix<f64, 12, 12>;

/// The closest PSD matrix to a symmetric `m` (negative eigenvalues set to zero).
pub fn project_psd<const N: usize>(m: &SMatrix<f64, N, N>) -> SMatrix<f64, N, N> {
    let sym = (m + m.transpose()) * 0.5;
    if sym.cholesky().is_some() {
        return sym;
    }
    // Dynamic size keeps the generic bounds simple; this path only runs for indefinite blocks.
    let mut eig =
        nalgebra::SymmetricEigen::new(nalgebra::DMatrix::from_column_slice(N, N, sym.as_slice()));
    for v in eig.eigenvalues.iter_mut() {
        *v = v.max(0.0);
    }
    SMatrix::<f64, N, N>::from_column_slice(eig.recompose().as_slice())
}

/// Finite-difference checks shared by the energies' tests.
#[cfg(test)]
pub(crate) mod fd {
    use nalgebra::{SMatrix, SVector};

    /// Asserts `grad` matches central differences of `f` at `x` (relative to the gradient's
    /// magnitude, plus an absolute floor).
    pub fn check_gradient<const N: usize>(
        f: impl Fn(&SVector<f64, N>) -> f64,
        grad: &SVector<f64, N>,
        x: &SVector<f64, N>,
        h: f64,
        rel_tol: f64,
    ) {
        let mut num = SVector::<f64, N>::zeros();
        for i in 0..N {
            let (mut a, mut b) = (*x, *x);
            a[i] += h;
            b[i] -= h;
            num[i] = (f(&a) - f(&b)) / (2.0 * h);
        }
        let err = (num - grad).norm();
        let scale = grad.norm().max(num.norm()).max(1e-12);
        assert!(
            err <= rel_tol * scale + 1e-9,
            "gradient mismatch: |num - an| = {err:e}, |an| = {scale:e}\nnum {num}\nan {grad}"
        );
    }

    /// Asserts `hess` matches central differences of `grad` at `x`.
    pub fn check_hessian<const N: usize>(
        grad: impl Fn(&SVector<f64, N>) -> SVector<f64, N>,
        hess: &SMatrix<f64, N, N>,
        x: &SVector<f64, N>,
        h: f64,
        rel_tol: f64,
    ) {
        let mut num = SMatrix::<f64, N, N>::zeros();
        for i in 0..N {
            let (mut a, mut b) = (*x, *x);
            a[i] += h;
            b[i] -= h;
            num.set_column(i, &((grad(&a) - grad(&b)) / (2.0 * h)));
        }
        let err = (num - hess).norm();
        let scale = hess.norm().max(num.norm()).max(1e-12);
        assert!(
            err <= rel_tol * scale + 1e-9,
            "Hessian mismatch: |num - an| = {err:e}, |an| = {scale:e}"
        );
    }

    /// Asserts `m` is symmetric positive semi-definite (up to round-off).
    pub fn check_psd<const N: usize>(m: &SMatrix<f64, N, N>) {
        assert!(
            (m - m.transpose()).norm() <= 1e-9 * m.norm().max(1.0),
            "not symmetric"
        );
        let eig =
            nalgebra::SymmetricEigen::new(nalgebra::DMatrix::from_column_slice(N, N, m.as_slice()));
        let min = eig.eigenvalues.min();
        assert!(
            min >= -1e-9 * m.norm().max(1.0),
            "not PSD: smallest eigenvalue {min}"
        );
    }
}
