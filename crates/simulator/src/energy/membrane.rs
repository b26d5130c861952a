//! Baraff-Witkin membrane (Baraff & Witkin 1998, "Large Steps in Cloth Simulation"):
//! anisotropic stretch along the weft (material u) and warp (material v), and in-plane shear.
//!
//! With the deformation gradient F = Ds·Dm⁻¹ (3×2) of a triangle with rest material coordinates
//! Dm = [u₁−u₀, u₂−u₀] and world edges Ds = [x₁−x₀, x₂−x₀], its columns w_u, w_v are how the
//! weft and warp directions are stretched. Per rest area A (m²):
//!
//! E = A · [½ k_weft (|w_u| − 1)² + ½ k_warp (|w_v| − 1)² + ½ k_shear (w_u·w_v)²]  (joules)
//!
//! with stiffnesses in N/m. A `compression` factor c ≤ 1 scales the weft and warp terms
//! where |w| < 1 (a compression-soft, tension-field-like membrane, ½ c k (|w| − 1)²): a coarse
//! mesh cannot buckle within its triangles as the cloth it stands for does, so at full
//! stiffness it resists, as membrane, shortening that the real cloth takes up in wrinkles
//! (the energy and its gradient stay continuous at |w| = 1; c = 1 is Baraff-Witkin's).
//! An optional compression knee s₀ gives the full stiffness back beyond a shortening of s₀
//! (|w| < 1 − s₀): with d = 1 − |w|, the term is ½ c k d² up to s₀ and
//! ½ c k s₀² + c k s₀ (d − s₀) + ½ k (d − s₀)² beyond, the cloth's wrinkles packing tight (C¹:
//! the force is continuous, its slope jumps from c k to k).
//! Gradients and Hessians are taken in the 6D space (w_u, w_v), then
//! mapped to the 9 vertex coordinates by the constant linear map w = B·x. The Hessian is made PSD
//! in that 6D space: the stretch terms analytically (the eigenvalue k(1 − 1/|w|) across the
//! stretch direction is clamped at zero under compression) and, when the shear coupling still
//! leaves it indefinite, by dropping that coupling (keeping the shear's Gauss-Newton part).

use nalgebra::{Matrix2, Matrix3, SMatrix, Vector2, Vector3};

use super::{Mat9, Vec9};

/// Rest data of one triangle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Membrane {
    /// Vertex indices.
    pub v: [u32; 3],
    /// Rest area in material space, m².
    pub area_m2: f64,
    /// Coefficients of x₀, x₁, x₂ in w_u (weft).
    pub cu: [f64; 3],
    /// Coefficients of x₀, x₁, x₂ in w_v (warp).
    pub cv: [f64; 3],
}

/// Membrane stiffnesses, N/m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MembraneStiffness {
    /// Stretch along the weft (material u).
    pub weft_n_m: f64,
    /// Stretch along the warp (material v).
    pub warp_n_m: f64,
    /// Shear.
    pub shear_n_m: f64,
    /// Factor on the weft and warp stiffnesses under compression (|w| < 1), in (0, 1].
    pub compression: f64,
    /// Shortening 1 − |w| beyond which the compression-soft stiffness gives way to the full
    /// one again (`f64::INFINITY`: never).
    pub compression_knee: f64,
}

impl MembraneStiffness {
    /// Full Baraff-Witkin stiffnesses: no compression softness.
    pub fn new(weft_n_m: f64, warp_n_m: f64, shear_n_m: f64) -> MembraneStiffness {
        MembraneStiffness {
            weft_n_m,
            warp_n_m,
            shear_n_m,
            compression: 1.0,
            compression_knee: f64::INFINITY,
        }
    }

    /// The stretch term of stiffness `k` per rest area at stretch ratio `l`: twice ψ(l), ψ',
    /// ψ'' (the stiffness along the stretch direction) and whether `l` is beyond the knee.
    /// Within the knee ψ = ½ k′ (l − 1)² with k′ = k·compression under compression (l < 1);
    /// beyond it (a shortening d = 1 − l > s₀ = `compression_knee`)
    /// ψ = ½ c k s₀² + c k s₀ (d − s₀) + ½ k (d − s₀)², whose ψ'' is `k`. The two forms are kept
    /// apart so that a membrane without a knee computes exactly what it did before the knee
    /// existed.
    fn stretch(&self, k: f64, l: f64) -> (f64, f64, f64, bool) {
        let (d, s0, c) = (1.0 - l, self.compression_knee, self.compression);
        if d > s0 {
            let e = d - s0;
            let psi = 0.5 * c * k * s0 * s0 + c * k * s0 * e + 0.5 * k * e * e;
            (2.0 * psi, -(c * k * s0 + k * e), k, true)
        } else {
            let kk = if l < 1.0 { k * c } else { k };
            (kk * (l - 1.0).powi(2), kk * (l - 1.0), kk, false)
        }
    }
}

impl Membrane {
    /// Rest data of triangle `v` from material coordinates; `None` if it is degenerate.
    pub fn new(v: [u32; 3], material: &[Vector2<f64>]) -> Option<Membrane> {
        let [u0, u1, u2] = v.map(|i| material[i as usize]);
        let dm = Matrix2::from_columns(&[u1 - u0, u2 - u0]);
        let area_m2 = 0.5 * dm.determinant().abs();
        let inv = dm.try_inverse().filter(|_| area_m2 > 1e-14)?;
        Some(Membrane {
            v,
            area_m2,
            cu: [-(inv[(0, 0)] + inv[(1, 0)]), inv[(0, 0)], inv[(1, 0)]],
            cv: [-(inv[(0, 1)] + inv[(1, 1)]), inv[(0, 1)], inv[(1, 1)]],
        })
    }

    /// (w_u, w_v): the columns of the deformation gradient.
    pub fn stretch_vectors(&self, x: &[Vector3<f64>; 3]) -> (Vector3<f64>, Vector3<f64>) {
        let wu = x[0] * self.cu[0] + x[1] * self.cu[1] + x[2] * self.cu[2];
        let wv = x[0] * self.cv[0] + x[1] * self.cv[1] + x[2] * self.cv[2];
        (wu, wv)
    }

    /// Energy, joules.
    pub fn energy(&self, k: &MembraneStiffness, x: &[Vector3<f64>; 3]) -> f64 {
        let (wu, wv) = self.stretch_vectors(x);
        let (lu, lv, s) = (wu.norm(), wv.norm(), wu.dot(&wv));
        let (eu, ev) = (k.stretch(k.weft_n_m, lu).0, k.stretch(k.warp_n_m, lv).0);
        self.area_m2 * 0.5 * (eu + ev + k.shear_n_m * s * s)
    }

    /// Energy, gradient in (w_u, w_v) and the 6×6 Hessian there; `psd` clamps the stretch
    /// terms' negative eigenvalues.
    fn w_space(
        &self,
        k: &MembraneStiffness,
        x: &[Vector3<f64>; 3],
        psd: bool,
        shear_coupling: bool,
    ) -> (f64, [Vector3<f64>; 2], SMatrix<f64, 6, 6>) {
        let a = self.area_m2;
        let (wu, wv) = self.stretch_vectors(x);
        let (lu, lv) = (wu.norm().max(1e-12), wv.norm().max(1e-12));
        let (nu, nv) = (wu / lu, wv / lv);
        let s = wu.dot(&wv);
        let (eu, du, ku, beyond_u) = k.stretch(k.weft_n_m, lu);
        let (ev, dv, kv, beyond_v) = k.stretch(k.warp_n_m, lv);
        let e = a * 0.5 * (eu + ev + k.shear_n_m * s * s);
        let gu = (nu * du + wv * (k.shear_n_m * s)) * a;
        let gv = (nv * dv + wu * (k.shear_n_m * s)) * a;
        // ∇²ψ(|w|) = ψ'' n nᵀ + (ψ' / |w|)(I − n nᵀ); the second is negative under compression.
        // Within the knee ψ' / |w| = k(1 − 1/|w|), written so.
        let stretch = |kk: f64, d1: f64, beyond: bool, n: &Vector3<f64>, l: f64| {
            let nn = n * n.transpose();
            let clamp = |p: f64| if psd { p.max(0.0) } else { p };
            if beyond {
                nn * kk + (Matrix3::identity() - nn) * clamp(d1 / l)
            } else {
                (nn + (Matrix3::identity() - nn) * clamp(1.0 - 1.0 / l)) * kk
            }
        };
        let huu = (stretch(ku, du, beyond_u, &nu, lu) + wv * wv.transpose() * k.shear_n_m) * a;
        let hvv = (stretch(kv, dv, beyond_v, &nv, lv) + wu * wu.transpose() * k.shear_n_m) * a;
        let coupling = if shear_coupling { s } else { 0.0 };
        let huv = (wv * wu.transpose() + Matrix3::identity() * coupling) * (k.shear_n_m * a);
        let mut h = SMatrix::<f64, 6, 6>::zeros();
        h.fixed_view_mut::<3, 3>(0, 0).copy_from(&huu);
        h.fixed_view_mut::<3, 3>(3, 3).copy_from(&hvv);
        h.fixed_view_mut::<3, 3>(0, 3).copy_from(&huv);
        h.fixed_view_mut::<3, 3>(3, 0).copy_from(&huv.transpose());
        (e, [gu, gv], h)
    }

    fn vertex_space(&self, g: [Vector3<f64>; 2], h: &SMatrix<f64, 6, 6>) -> (Vec9, Mat9) {
        let mut grad = Vec9::zeros();
        let mut hess = Mat9::zeros();
        let c = [self.cu, self.cv];
        for i in 0..3 {
            grad.fixed_rows_mut::<3>(3 * i)
                .copy_from(&(g[0] * c[0][i] + g[1] * c[1][i]));
            for j in 0..3 {
                let mut block = Matrix3::zeros();
                for (p, cp) in c.iter().enumerate() {
                    for (q, cq) in c.iter().enumerate() {
                        block += h.fixed_view::<3, 3>(3 * p, 3 * q) * (cp[i] * cq[j]);
                    }
                }
                hess.fixed_view_mut::<3, 3>(3 * i, 3 * j).copy_from(&block);
            }
        }
        (grad, hess)
    }

    /// Energy, gradient (9) and PSD Hessian (9×9). The stretch terms are clamped analytically;
    /// the shear coupling k_s·s·[[0, I], [I, 0]] is kept when the 6×6 block stays positive
    /// definite (one 6×6 Cholesky) and dropped otherwise, which leaves a sum of PSD terms (the
    /// shear's Gauss-Newton part k_s ∇C∇Cᵀ): no eigendecomposition on the hot path.
    pub fn energy_gradient_hessian(
        &self,
        k: &MembraneStiffness,
        x: &[Vector3<f64>; 3],
    ) -> (f64, Vec9, Mat9) {
        let (e, g, mut h) = self.w_space(k, x, true, true);
        if h.cholesky().is_none() {
            h = self.w_space(k, x, true, false).2;
        }
        let (grad, hess) = self.vertex_space(g, &h);
        (e, grad, hess)
    }

    /// Gradient (9) only.
    pub fn gradient(&self, k: &MembraneStiffness, x: &[Vector3<f64>; 3]) -> Vec9 {
        let (_, g, h) = self.w_space(k, x, false, true);
        self.vertex_space(g, &h).0
    }

    /// The exact (unfiltered) Hessian, for tests and analysis.
    pub fn hessian_exact(&self, k: &MembraneStiffness, x: &[Vector3<f64>; 3]) -> Mat9 {
        let (_, g, h) = self.w_space(k, x, false, true);
        self.vertex_space(g, &h).1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::fd;

    /// A small deterministic generator (no rand dependency in the library).
    pub(crate) struct Lcg(u64);
    impl Lcg {
        pub(crate) fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((self.0 >> 11) as f64) / ((1u64 << 53) as f64)
        }
    }

    fn setup(r: &mut Lcg) -> (Membrane, MembraneStiffness, Vec9) {
        let material = [
            Vector2::new(0.0, 0.0),
            Vector2::new(0.02 + 0.01 * r.next(), 0.003 * r.next()),
            Vector2::new(0.005 * r.next(), 0.02 + 0.01 * r.next()),
        ];
        let m = Membrane::new([0, 1, 2], &material).expect("triangle");
        // Every other triangle compression-soft.
        let k = MembraneStiffness {
            weft_n_m: 1800.0,
            warp_n_m: 2500.0,
            shear_n_m: 100.0,
            compression: if r.next() < 0.5 { 1.0 } else { 0.1 },
            compression_knee: if r.next() < 0.5 {
                f64::INFINITY
            } else {
                0.05 + 0.2 * r.next()
            },
        };
        // World: rotated, stretched or compressed, and sheared copy of the material triangle.
        let mut x = Vec9::zeros();
        let scale = 0.6 + 0.8 * r.next();
        for (i, u) in material.iter().enumerate() {
            let p = Vector3::new(u.x * scale, u.y, 0.0);
            let q = Vector3::new(
                p.x + 0.3 * p.y * r.next(),
                p.y * (0.7 + 0.6 * r.next()),
                0.01 * r.next(),
            );
            x.fixed_rows_mut::<3>(3 * i).copy_from(&q);
        }
        (m, k, x)
    }

    /// The right triangle with 20 mm legs along the weft and warp, and its membrane.
    fn right_triangle() -> ([Vector2<f64>; 3], Membrane) {
        let material = [
            Vector2::new(0.0, 0.0),
            Vector2::new(0.02, 0.0),
            Vector2::new(0.0, 0.02),
        ];
        let m = Membrane::new([0, 1, 2], &material).expect("triangle");
        (material, m)
    }

    fn pts(x: &Vec9) -> [Vector3<f64>; 3] {
        [0, 1, 2].map(|i| Vector3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2]))
    }

    #[test]
    fn gradient_and_hessian_match_finite_differences() {
        let mut r = Lcg(7);
        for _ in 0..30 {
            let (m, k, x) = setup(&mut r);
            let g = m.gradient(&k, &pts(&x));
            fd::check_gradient(|y| m.energy(&k, &pts(y)), &g, &x, 1e-7, 1e-5);
            let h = m.hessian_exact(&k, &pts(&x));
            fd::check_hessian(|y| m.gradient(&k, &pts(y)), &h, &x, 1e-7, 1e-5);
        }
    }

    #[test]
    fn filtered_hessian_is_psd_and_exact_when_stretched() {
        let mut r = Lcg(11);
        for _ in 0..30 {
            let (m, k, x) = setup(&mut r);
            let (e, g, h) = m.energy_gradient_hessian(&k, &pts(&x));
            fd::check_psd(&h);
            assert!((e - m.energy(&k, &pts(&x))).abs() < 1e-15);
            assert!((g - m.gradient(&k, &pts(&x))).norm() < 1e-9 * g.norm().max(1.0));
        }
        // Pure stretch along both axes, no shear: the exact Hessian is already PSD.
        let (_, m) = right_triangle();
        let k = MembraneStiffness::new(1000.0, 1500.0, 50.0);
        let x = [
            Vector3::zeros(),
            Vector3::new(0.022, 0.0, 0.0),
            Vector3::new(0.0, 0.021, 0.0),
        ];
        let (_, _, h) = m.energy_gradient_hessian(&k, &x);
        assert!((h - m.hessian_exact(&k, &x)).norm() < 1e-9 * h.norm());
    }

    #[test]
    fn compression_softness_scales_only_shortened_directions() {
        let (material, m) = right_triangle();
        let stiff = MembraneStiffness::new(1000.0, 1500.0, 50.0);
        let soft = MembraneStiffness {
            compression: 0.1,
            ..stiff
        };
        let scaled = |su: f64, sv: f64| material.map(|u| Vector3::new(su * u.x, sv * u.y, 0.0));
        // Weft shortened by 2 %, warp stretched by 1 %: only the weft term is scaled.
        let x = scaled(0.98, 1.01);
        let weft = 0.5 * 1000.0 * 0.02f64.powi(2) * m.area_m2;
        let warp = 0.5 * 1500.0 * 0.01f64.powi(2) * m.area_m2;
        assert!((m.energy(&stiff, &x) - (weft + warp)).abs() < 1e-12);
        assert!((m.energy(&soft, &x) - (0.1 * weft + warp)).abs() < 1e-12);
        // The gradient stays continuous through the rest length.
        for s in [1.0 - 1e-9, 1.0 + 1e-9] {
            assert!(m.gradient(&soft, &scaled(s, 1.0)).norm() < 1e-6);
        }
        let (_, _, h) = m.energy_gradient_hessian(&soft, &scaled(0.97, 0.99));
        fd::check_psd(&h);
    }

    #[test]
    fn compression_knee_gives_the_full_stiffness_back_beyond_it() {
        let (material, m) = right_triangle();
        let knee = MembraneStiffness {
            compression: 0.1,
            compression_knee: 0.2,
            ..MembraneStiffness::new(1000.0, 1500.0, 50.0)
        };
        let scaled = |su: f64| material.map(|u| Vector3::new(su * u.x, u.y, 0.0));
        let a = m.area_m2;
        // Up to the knee: the soft membrane's ½ c k d².
        let e = m.energy(&knee, &scaled(0.9));
        assert!((e - a * 0.5 * 0.1 * 1000.0 * 0.01).abs() < 1e-12, "{e}");
        // Beyond it: ½ c k s₀² + c k s₀ (d − s₀) + ½ k (d − s₀)², at d = 0.3.
        let e = m.energy(&knee, &scaled(0.7));
        let want = a * (0.5 * 100.0 * 0.04 + 100.0 * 0.2 * 0.1 + 0.5 * 1000.0 * 0.01);
        assert!((e - want).abs() < 1e-12, "{e} vs {want}");
        // The force is continuous through the knee; its slope jumps from c k to k.
        let f = |s: f64| m.gradient(&knee, &scaled(s))[3];
        let (below, above) = (f(0.8 + 1e-9), f(0.8 - 1e-9));
        assert!(
            (below - above).abs() < 1e-6 * below.abs(),
            "{below} vs {above}"
        );
        let slope = |s: f64| (f(s + 1e-6) - f(s - 1e-6)) / 2e-6;
        let (soft, stiff) = (slope(0.85), slope(0.75));
        assert!((stiff / soft - 10.0).abs() < 1e-4, "{soft} vs {stiff}");
        // Gradient and Hessian on both sides of the knee, by finite differences.
        for s in [0.85, 0.75, 0.6] {
            let x = Vec9::from_iterator(
                scaled(s)
                    .iter()
                    .zip([0.0, 0.002, -0.001])
                    .flat_map(|(p, dz)| [p.x, p.y + 0.1 * p.x, p.z + dz]),
            );
            let g = m.gradient(&knee, &pts(&x));
            fd::check_gradient(|y| m.energy(&knee, &pts(y)), &g, &x, 1e-7, 1e-5);
            let h = m.hessian_exact(&knee, &pts(&x));
            fd::check_hessian(|y| m.gradient(&knee, &pts(y)), &h, &x, 1e-7, 1e-5);
            fd::check_psd(&m.energy_gradient_hessian(&knee, &pts(&x)).2);
        }
    }

    #[test]
    fn rest_state_is_free_and_rigid_motion_costs_nothing() {
        let material = [
            Vector2::new(0.0, 0.0),
            Vector2::new(0.02, 0.001),
            Vector2::new(0.004, 0.018),
        ];
        let m = Membrane::new([0, 1, 2], &material).expect("triangle");
        let k = MembraneStiffness::new(1000.0, 1500.0, 50.0);
        let rot = nalgebra::Rotation3::from_euler_angles(0.3, -1.1, 0.7);
        let x = material.map(|u| rot * Vector3::new(u.x, u.y, 0.0) + Vector3::new(1.0, 2.0, 3.0));
        assert!(m.energy(&k, &x) < 1e-20);
        assert!(m.gradient(&k, &x).norm() < 1e-9);
        // Weft stretch costs k_weft, warp stretch k_warp.
        let stretch_u = material.map(|u| Vector3::new(1.1 * u.x, u.y, 0.0));
        let e_u = m.energy(&k, &stretch_u);
        let stretch_v = material.map(|u| Vector3::new(u.x, 1.1 * u.y, 0.0));
        let e_v = m.energy(&k, &stretch_v);
        assert!(e_v > e_u, "warp is stiffer: {e_v} vs {e_u}");
        assert!(Membrane::new(
            [0, 1, 2],
            &[
                Vector2::zeros(),
                Vector2::new(1.0, 0.0),
                Vector2::new(2.0, 0.0)
            ]
        )
        .is_none());
    }
}
