//! Discrete Shells bending (Grinspun, Hirani, Desbrun & Schröder 2003, "Discrete Shells",
//! SCA 2003), with its exact gradient and exact Hessian and two PSD variants of the latter.
//!
//! # Energy
//!
//! Every interior edge `e` of the mesh, shared by two triangles, is a *hinge* with four vertices
//! `x0, x1` (the shared edge), `x2` (opposite vertex of the first triangle) and `x3` (opposite
//! vertex of the second). Its energy is
//!
//! ```text
//! E = w · (θ − θ̄)²,      w = k_b · 3‖ē‖² / (Ā1 + Ā2)
//! ```
//!
//! with `θ` the signed dihedral angle, `θ̄` its rest value, `k_b` the bending stiffness (N·m) and
//! `ē`, `Ā1`, `Ā2` the rest edge length and triangle areas (Grinspun et al. 2003, eq. 3:
//! `‖ē‖ / h̄_e` with `h̄_e = (Ā1 + Ā2) / (3‖ē‖)`).
//!
//! # Angle
//!
//! With `e = x1 − x0`, `a = x2 − x0`, `b = x3 − x0` and the (area-weighted, unnormalised) face
//! normals `n1 = e × a`, `n2 = b × e` (the first triangle is `(x0, x1, x2)`, the second
//! `(x1, x0, x3)`, both counter-clockwise seen from their normal side):
//!
//! ```text
//! θ = atan2( ‖e‖ · det[e, a, b],  n1 · n2 )          (∈ (−π, π], 0 when flat)
//! ```
//!
//! This is exact, since `n1 × n2 = −det[e, a, b] · e`, so `‖e‖ det[e, a, b] = ‖n1‖‖n2‖ sin θ` and
//! `n1 · n2 = ‖n1‖‖n2‖ cos θ`; atan2 of the two keeps full accuracy both near 0 and near ±π
//! (unlike acos of the normalised dot product). Because `det[e, a, b] = n1 · (x3 − x0) =
//! n2 · (x2 − x0)`, `θ > 0` exactly when each wing tip lies on the front (normal) side of the other
//! triangle, i.e. the surface folds towards its normals.
//!
//! # Derivatives
//!
//! The gradient is the classical closed form (Bridson, Marino & Fedkiw 2003; Tamstorf &
//! Grinspun 2013, "Discrete bending forces and their Jacobians", eq. 9–12):
//!
//! ```text
//! ∂θ/∂x2 = ‖e‖ n1 / ‖n1‖²,   ∂θ/∂x3 = ‖e‖ n2 / ‖n2‖²,
//! ∂θ/∂x0 = −(1 − t1) ∂θ/∂x2 − (1 − t2) ∂θ/∂x3,   ∂θ/∂x1 = −t1 ∂θ/∂x2 − t2 ∂θ/∂x3,
//! t1 = a·e / ‖e‖²,  t2 = b·e / ‖e‖².
//! ```
//!
//! Both gradient and Hessian are computed here by differentiating the atan2 form directly (a
//! derivation equivalent to Tamstorf & Grinspun's closed forms): with `X = n1·n2` (a quartic
//! polynomial of `e, a, b`), `Y = ‖e‖ det[e, a, b]`, `r = √(X² + Y²) = ‖n1‖‖n2‖`, `c = X/r = cos θ`,
//! `s = Y/r = sin θ`, `X' = ∇X / r`, `Y' = ∇Y / r`:
//!
//! ```text
//! ∇θ  = c Y' − s X'
//! ∇²θ = (c ∇²Y − s ∇²X) / r + (s² − c²)(Y' X'ᵀ + X' Y'ᵀ) + 2 s c (X' X'ᵀ − Y' Y'ᵀ)
//! ```
//!
//! in the 9 variables `(e, a, b)`; the polynomial Hessians `∇²X`, `∇²det` are written out block by
//! block, and the results are lifted to the 12 vertex coordinates through `x0 ↦ −(e + a + b)`.
//! Then `∇E = 2w(θ − θ̄)∇θ` and `∇²E = 2w(∇θ∇θᵀ + (θ − θ̄)∇²θ)`. The second term is
//! indefinite, hence [`BendingHessian`].
//!
//! A hinge with a (numerically) zero-area triangle contributes nothing (zero energy, gradient and
//! Hessian) instead of NaN; see [`DEGENERATE_REL_AREA`].

use std::collections::HashMap;
use std::f64::consts::PI;

use nalgebra::{Matrix3, Vector2, Vector3};

use super::{project_psd, Mat12, Mat9, Vec12, Vec9};

/// A hinge triangle is degenerate (the hinge then contributes nothing) when twice its area,
/// `‖n‖`, is at most this fraction of its longest squared edge length, i.e. roughly when the
/// sine of its smallest angle is below 1e-12.
pub const DEGENERATE_REL_AREA: f64 = 1e-12;

/// One hinge: an interior edge shared by two triangles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hinge {
    /// [x0, x1] = the shared edge, x2 = opposite vertex of the first triangle, x3 = opposite vertex of the second.
    pub v: [u32; 4],
    /// Rest dihedral angle (radians); 0 for a flat pattern.
    pub rest_angle: f64,
    /// k_b · 3‖ē‖² / (Ā1 + Ā2) with rest (material-space) edge length ē and triangle areas Ā, in joules.
    pub weight: f64,
}

/// How the Hessian is made PSD.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BendingHessian {
    /// 2w ∇θ∇θᵀ only (drops the indefinite (θ−θ̄)∇²θ term): PSD by construction, cheap.
    #[default]
    GaussNewton,
    /// the exact Hessian projected to PSD by eigenvalue clamping (project_psd).
    Projected,
}

/// All hinges of a mesh (every edge shared by exactly two triangles), rest angle 0 (flat pattern), weights from material-space (2D, metres) rest geometry. Triangles are counter-clockwise in material space. Order the hinge vertices so the dihedral angle is 0 when flat and its sign consistent (positive when the mesh folds one way).
///
/// For each interior edge, `[x0, x1]` is the edge in the direction it has in the first triangle
/// (in triangle order) that contains it, so the first triangle is `(x0, x1, x2)` and the second
/// `(x1, x0, x3)`, both counter-clockwise. With this order [`dihedral_angle`] is positive when
/// the surface folds towards the side its (counter-clockwise) normals face.
///
/// `bending_n_m` is the bending stiffness `k_b` (N·m = J); the weight is
/// `k_b · 3‖ē‖² / (Ā1 + Ā2)` (Grinspun et al. 2003). Hinges come out in the order their edges
/// first appear in `triangles`. Skipped: boundary and non-manifold edges (not exactly two
/// triangles), pairs whose shared edge has the same direction in both triangles (inconsistent
/// orientation) and pairs with zero total rest area.
///
/// # Panics
///
/// If a triangle indexes past the end of `material`.
pub fn hinges(triangles: &[[u32; 3]], material: &[Vector2<f64>], bending_n_m: f64) -> Vec<Hinge> {
    /// Uses of one undirected edge: how many triangles, and (from, to, opposite) of the first two.
    struct EdgeUse {
        count: u32,
        first: [u32; 3],
        second: [u32; 3],
    }
    let mut uses: HashMap<(u32, u32), EdgeUse> = HashMap::with_capacity(triangles.len() * 2);
    let mut order: Vec<(u32, u32)> = Vec::with_capacity(triangles.len() * 2);
    for t in triangles {
        for k in 0..3 {
            let (p, q, r) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            let key = (p.min(q), p.max(q));
            let entry = uses.entry(key).or_insert_with(|| {
                order.push(key);
                EdgeUse {
                    count: 0,
                    first: [p, q, r],
                    second: [p, q, r],
                }
            });
            if entry.count == 1 {
                entry.second = [p, q, r];
            }
            entry.count += 1;
        }
    }

    let cross2 = |u: Vector2<f64>, v: Vector2<f64>| u.x * v.y - u.y * v.x;
    let mut out = Vec::with_capacity(order.len());
    for key in order {
        let Some(u) = uses.get(&key) else { continue };
        if u.count != 2 {
            continue;
        }
        let [p, q, r] = u.first;
        let [p2, q2, s] = u.second;
        if p2 != q || q2 != p {
            continue; // inconsistently oriented pair
        }
        let (mp, mq) = (material[p as usize], material[q as usize]);
        let (mr, ms) = (material[r as usize], material[s as usize]);
        let edge_len2_m2 = (mq - mp).norm_squared();
        let area1_m2 = 0.5 * cross2(mq - mp, mr - mp).abs();
        let area2_m2 = 0.5 * cross2(mp - mq, ms - mq).abs();
        let area_sum_m2 = area1_m2 + area2_m2;
        if area_sum_m2 <= 0.0 {
            continue;
        }
        out.push(Hinge {
            v: [p, q, r, s],
            rest_angle: 0.0,
            weight: bending_n_m * 3.0 * edge_len2_m2 / area_sum_m2,
        });
    }
    out
}

/// Shared per-hinge quantities (edge frame relative to x0).
struct Geometry {
    /// e = x1 − x0.
    e: Vector3<f64>,
    /// a = x2 − x0.
    a: Vector3<f64>,
    /// b = x3 − x0.
    b: Vector3<f64>,
    /// ‖e‖.
    len_e: f64,
    /// det[e, a, b] = n1 · b.
    det: f64,
    /// X = n1 · n2 (= r cos θ).
    cos_part: f64,
    /// Y = ‖e‖ det[e, a, b] (= r sin θ).
    sin_part: f64,
}

impl Geometry {
    /// `None` when either triangle is degenerate (see [`DEGENERATE_REL_AREA`]).
    fn new(x: &[Vector3<f64>; 4]) -> Option<Self> {
        let e = x[1] - x[0];
        let a = x[2] - x[0];
        let b = x[3] - x[0];
        let n1 = e.cross(&a);
        let n2 = b.cross(&e);
        let e2 = e.norm_squared();
        let scale1 = e2.max(a.norm_squared()).max((a - e).norm_squared());
        let scale2 = e2.max(b.norm_squared()).max((b - e).norm_squared());
        // `<=` so that NaN input propagates instead of being silently zeroed.
        if n1.norm() <= DEGENERATE_REL_AREA * scale1 || n2.norm() <= DEGENERATE_REL_AREA * scale2 {
            return None;
        }
        let len_e = e2.sqrt();
        let det = n1.dot(&b);
        Some(Self {
            e,
            a,
            b,
            len_e,
            det,
            cos_part: n1.dot(&n2),
            sin_part: len_e * det,
        })
    }

    /// θ ∈ (−π, π].
    fn angle(&self) -> f64 {
        let t = self.sin_part.atan2(self.cos_part);
        if t <= -PI {
            PI
        } else {
            t
        }
    }
}

/// First-order quantities in the 9 variables (e, a, b), shared by gradient and Hessian.
struct FirstOrder {
    theta: f64,
    /// cos θ.
    c: f64,
    /// sin θ.
    s: f64,
    /// r = ‖n1‖‖n2‖.
    r: f64,
    /// ∇X / r.
    gx: Vec9,
    /// ∇Y / r.
    gy: Vec9,
    /// ∇det.
    gdet: Vec9,
    /// ∇θ.
    gtheta: Vec9,
}

impl FirstOrder {
    fn new(g: &Geometry) -> Self {
        let (e, a, b) = (&g.e, &g.a, &g.b);
        let (ea, eb, ab, ee) = (e.dot(a), e.dot(b), a.dot(b), e.dot(e));
        let r = g.cos_part.hypot(g.sin_part);
        let (c, s) = (g.cos_part / r, g.sin_part / r);

        // X = (e·a)(e·b) − (e·e)(a·b).
        let mut gx = Vec9::zeros();
        gx.fixed_rows_mut::<3>(0)
            .copy_from(&(a * eb + b * ea - e * (2.0 * ab)));
        gx.fixed_rows_mut::<3>(3).copy_from(&(e * eb - b * ee));
        gx.fixed_rows_mut::<3>(6).copy_from(&(e * ea - a * ee));

        // det = e·(a×b): ∇ = (a×b, b×e, e×a).
        let mut gdet = Vec9::zeros();
        gdet.fixed_rows_mut::<3>(0).copy_from(&a.cross(b));
        gdet.fixed_rows_mut::<3>(3).copy_from(&b.cross(e));
        gdet.fixed_rows_mut::<3>(6).copy_from(&e.cross(a));

        // Y = ‖e‖ det: ∇Y = det ∇‖e‖ + ‖e‖ ∇det, ∇‖e‖ = (ê, 0, 0).
        let mut gy = gdet * g.len_e;
        let mut gy_e = gy.fixed_rows_mut::<3>(0);
        gy_e += e * (g.det / g.len_e);

        let gx = gx / r;
        let gy = gy / r;
        let gtheta = gy * c - gx * s;
        Self {
            theta: g.angle(),
            c,
            s,
            r,
            gx,
            gy,
            gdet,
            gtheta,
        }
    }

    /// ∇²θ in (e, a, b).
    fn hessian9(&self, g: &Geometry) -> Mat9 {
        let (e, a, b) = (&g.e, &g.a, &g.b);
        let (ea, eb, ab, ee) = (e.dot(a), e.dot(b), a.dot(b), e.dot(e));
        let id = Matrix3::<f64>::identity();

        // ∇²X, block (row, col) over (e, a, b).
        let mut hx = Mat9::zeros();
        let hx_ee = a * b.transpose() + b * a.transpose() - id * (2.0 * ab);
        let hx_ea = id * eb + b * e.transpose() - e * b.transpose() * 2.0;
        let hx_eb = id * ea + a * e.transpose() - e * a.transpose() * 2.0;
        let hx_ab = e * e.transpose() - id * ee;
        hx.fixed_view_mut::<3, 3>(0, 0).copy_from(&hx_ee);
        hx.fixed_view_mut::<3, 3>(0, 3).copy_from(&hx_ea);
        hx.fixed_view_mut::<3, 3>(3, 0)
            .copy_from(&hx_ea.transpose());
        hx.fixed_view_mut::<3, 3>(0, 6).copy_from(&hx_eb);
        hx.fixed_view_mut::<3, 3>(6, 0)
            .copy_from(&hx_eb.transpose());
        hx.fixed_view_mut::<3, 3>(3, 6).copy_from(&hx_ab);
        hx.fixed_view_mut::<3, 3>(6, 3)
            .copy_from(&hx_ab.transpose());

        // ∇²det: ∂(a×b)/∂a = −[b]×, ∂(a×b)/∂b = [a]×, ∂(b×e)/∂b = −[e]×.
        let mut hdet = Mat9::zeros();
        let hd_ea = -b.cross_matrix();
        let hd_eb = a.cross_matrix();
        let hd_ab = -e.cross_matrix();
        hdet.fixed_view_mut::<3, 3>(0, 3).copy_from(&hd_ea);
        hdet.fixed_view_mut::<3, 3>(3, 0)
            .copy_from(&hd_ea.transpose());
        hdet.fixed_view_mut::<3, 3>(0, 6).copy_from(&hd_eb);
        hdet.fixed_view_mut::<3, 3>(6, 0)
            .copy_from(&hd_eb.transpose());
        hdet.fixed_view_mut::<3, 3>(3, 6).copy_from(&hd_ab);
        hdet.fixed_view_mut::<3, 3>(6, 3)
            .copy_from(&hd_ab.transpose());

        // ∇²Y = det ∇²‖e‖ + ∇‖e‖ ∇detᵀ + ∇det ∇‖e‖ᵀ + ‖e‖ ∇²det, ∇²‖e‖ = (I − êêᵀ)/‖e‖.
        let e_hat = e / g.len_e;
        let mut grad_len = Vec9::zeros();
        grad_len.fixed_rows_mut::<3>(0).copy_from(&e_hat);
        let mut hy =
            hdet * g.len_e + grad_len * self.gdet.transpose() + self.gdet * grad_len.transpose();
        let mut hy_ee = hy.fixed_view_mut::<3, 3>(0, 0);
        hy_ee += (id - e_hat * e_hat.transpose()) * (g.det / g.len_e);

        let (c, s) = (self.c, self.s);
        let (gx, gy) = (&self.gx, &self.gy);
        (hy * c - hx * s) / self.r
            + (gy * gx.transpose() + gx * gy.transpose()) * (s * s - c * c)
            + (gx * gx.transpose() - gy * gy.transpose()) * (2.0 * s * c)
    }
}

/// Lifts a gradient in (e, a, b) = (x1 − x0, x2 − x0, x3 − x0) to (x0, x1, x2, x3).
fn lift_gradient(g9: &Vec9) -> Vec12 {
    let mut g = Vec12::zeros();
    let g0 = -(g9.fixed_rows::<3>(0) + g9.fixed_rows::<3>(3) + g9.fixed_rows::<3>(6));
    g.fixed_rows_mut::<3>(0).copy_from(&g0);
    g.fixed_rows_mut::<9>(3).copy_from(g9);
    g
}

/// Lifts a symmetric Hessian in (e, a, b) to (x0, x1, x2, x3): `Mᵀ H M` with x0 ↦ −(e + a + b).
fn lift_hessian(h9: &Mat9) -> Mat12 {
    let mut h = Mat12::zeros();
    h.fixed_view_mut::<9, 9>(3, 3).copy_from(h9);
    let mut h00 = Matrix3::<f64>::zeros();
    for j in 0..3 {
        let col = h9.fixed_view::<3, 3>(0, 3 * j)
            + h9.fixed_view::<3, 3>(3, 3 * j)
            + h9.fixed_view::<3, 3>(6, 3 * j);
        let blk = -col;
        h.fixed_view_mut::<3, 3>(0, 3 * (j + 1)).copy_from(&blk);
        h.fixed_view_mut::<3, 3>(3 * (j + 1), 0)
            .copy_from(&blk.transpose());
        h00 -= blk;
    }
    let h00 = (h00 + h00.transpose()) * 0.5;
    h.fixed_view_mut::<3, 3>(0, 0).copy_from(&h00);
    h
}

/// Signed dihedral angle (radians, 0 = flat) of the four points, in (-π, π].
///
/// `θ = atan2(‖e‖ det[e, a, b], n1 · n2)` (see the module docs); positive when each wing tip lies
/// on the front side of the other triangle (`n1 = (x1 − x0) × (x2 − x0)`). 0 for a degenerate
/// hinge.
pub fn dihedral_angle(x: &[Vector3<f64>; 4]) -> f64 {
    Geometry::new(x).map_or(0.0, |g| g.angle())
}

/// ∇θ (12, stacked x0..x3) with θ; `None` for a degenerate hinge.
///
/// Equals the closed form of Tamstorf & Grinspun 2013: `∂θ/∂x2 = ‖e‖ n1/‖n1‖²`,
/// `∂θ/∂x3 = ‖e‖ n2/‖n2‖²`, `∂θ/∂x0`, `∂θ/∂x1` by translation and rotation invariance.
pub fn dihedral_angle_gradient(x: &[Vector3<f64>; 4]) -> Option<(f64, Vec12)> {
    let g = Geometry::new(x)?;
    let f = FirstOrder::new(&g);
    Some((f.theta, lift_gradient(&f.gtheta)))
}

/// θ, ∇θ and the exact ∇²θ; `None` for a degenerate hinge.
fn angle_derivatives(x: &[Vector3<f64>; 4]) -> Option<(f64, Vec12, Mat12)> {
    let g = Geometry::new(x)?;
    let f = FirstOrder::new(&g);
    let h9 = f.hessian9(&g);
    Some((f.theta, lift_gradient(&f.gtheta), lift_hessian(&h9)))
}

/// E = weight · (θ − θ̄)².
///
/// No wrapping of `θ − θ̄`: θ ∈ (−π, π] is the physical range (crossing ±π means the two faces
/// pass through each other), so for θ̄ ≠ 0 the energy jumps there. 0 for a degenerate hinge.
pub fn energy(h: &Hinge, x: &[Vector3<f64>; 4]) -> f64 {
    match Geometry::new(x) {
        Some(g) => {
            let d = g.angle() - h.rest_angle;
            h.weight * d * d
        }
        None => 0.0,
    }
}

/// ∂E/∂x (12, stacked x0..x3).
///
/// `∇E = 2w(θ − θ̄)∇θ`; zero for a degenerate hinge.
pub fn gradient(h: &Hinge, x: &[Vector3<f64>; 4]) -> Vec12 {
    match dihedral_angle_gradient(x) {
        Some((theta, g)) => g * (2.0 * h.weight * (theta - h.rest_angle)),
        None => Vec12::zeros(),
    }
}

/// Exact ∂²E/∂x² (not PSD-filtered).
///
/// `∇²E = 2w(∇θ∇θᵀ + (θ − θ̄)∇²θ)`; zero for a degenerate hinge.
pub fn hessian(h: &Hinge, x: &[Vector3<f64>; 4]) -> Mat12 {
    match angle_derivatives(x) {
        Some((theta, g, hth)) => {
            let w2 = 2.0 * h.weight;
            (g * g.transpose() + hth * (theta - h.rest_angle)) * w2
        }
        None => Mat12::zeros(),
    }
}

/// Energy, gradient and PSD Hessian in one pass (the solver's hot path: avoid recomputing shared quantities; no heap allocation in GaussNewton mode).
///
/// `GaussNewton` gives `2w∇θ∇θᵀ` and never forms `∇²θ`; `Projected` gives
/// `project_psd(2w(∇θ∇θᵀ + (θ − θ̄)∇²θ))` (which allocates when the matrix is indefinite).
/// All zero for a degenerate hinge.
pub fn energy_gradient_hessian(
    h: &Hinge,
    x: &[Vector3<f64>; 4],
    mode: BendingHessian,
) -> (f64, Vec12, Mat12) {
    let Some(geo) = Geometry::new(x) else {
        return (0.0, Vec12::zeros(), Mat12::zeros());
    };
    let f = FirstOrder::new(&geo);
    let d = f.theta - h.rest_angle;
    let w2 = 2.0 * h.weight;
    let g = lift_gradient(&f.gtheta);
    let e = h.weight * d * d;
    let grad = g * (w2 * d);
    let hess = match mode {
        BendingHessian::GaussNewton => {
            let mut hess = Mat12::zeros();
            hess.ger(w2, &g, &g, 0.0);
            hess
        }
        BendingHessian::Projected => {
            let hth = lift_hessian(&f.hessian9(&geo));
            project_psd(&((g * g.transpose() + hth * d) * w2))
        }
    };
    (e, grad, hess)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::fd::{check_gradient, check_hessian, check_psd};
    use nalgebra::{Quaternion, UnitQuaternion};
    use std::panic::{catch_unwind, AssertUnwindSafe};

    /// Tiny seeded LCG (Knuth's MMIX constants).
    struct Lcg(u64);

    impl Lcg {
        fn next_f64(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }

        fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * self.next_f64()
        }

        fn vec3(&mut self, half: f64) -> Vector3<f64> {
            Vector3::new(
                self.range(-half, half),
                self.range(-half, half),
                self.range(-half, half),
            )
        }

        fn rotation(&mut self) -> UnitQuaternion<f64> {
            UnitQuaternion::new_normalize(Quaternion::new(
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
            ))
        }
    }

    fn pack(x: &[Vector3<f64>; 4]) -> Vec12 {
        let mut q = Vec12::zeros();
        for (i, p) in x.iter().enumerate() {
            q.fixed_rows_mut::<3>(3 * i).copy_from(p);
        }
        q
    }

    fn unpack(q: &Vec12) -> [Vector3<f64>; 4] {
        std::array::from_fn(|i| q.fixed_rows::<3>(3 * i).into_owned())
    }

    /// A random non-degenerate hinge folded by `fold` radians (the expected dihedral angle),
    /// placed by a random rigid motion. Wing tips may project outside the edge (obtuse angles).
    fn folded(rng: &mut Lcg, fold: f64) -> [Vector3<f64>; 4] {
        let len = rng.range(0.5, 1.5);
        let (t1, t2) = (rng.range(-0.3, 1.3), rng.range(-0.3, 1.3));
        let (h1, h2) = (rng.range(0.3, 1.2), rng.range(0.3, 1.2));
        let local = [
            Vector3::zeros(),
            Vector3::new(len, 0.0, 0.0),
            Vector3::new(t1 * len, h1, 0.0),
            Vector3::new(t2 * len, -h2 * fold.cos(), h2 * fold.sin()),
        ];
        let rot = rng.rotation();
        let shift = rng.vec3(2.0);
        local.map(|p| rot * p + shift)
    }

    /// Fold angles of the test cases: flat, tiny, moderate, ±150°, ±160°.
    const FOLDS: [f64; 12] = [
        0.0,
        1e-3,
        -0.3,
        0.7,
        -1.2,
        1.6,
        -2.2,
        2.5,
        150.0 * PI / 180.0,
        -150.0 * PI / 180.0,
        160.0 * PI / 180.0,
        -160.0 * PI / 180.0,
    ];

    /// 24 random cases (two per fold angle), a third of them with rest angle 0.
    fn cases() -> Vec<(Hinge, [Vector3<f64>; 4], f64)> {
        let mut rng = Lcg(0x5eed_b3d1);
        (0..24)
            .map(|i| {
                let fold = FOLDS[i % FOLDS.len()];
                let rest_angle = if i % 3 == 0 {
                    0.0
                } else {
                    rng.range(-0.4, 0.4)
                };
                let h = Hinge {
                    v: [0, 1, 2, 3],
                    rest_angle,
                    weight: rng.range(0.5, 3.0),
                };
                (h, folded(&mut rng, fold), fold)
            })
            .collect()
    }

    fn wrapped_diff(a: f64, b: f64) -> f64 {
        let d = (a - b).rem_euclid(2.0 * PI);
        d.min(2.0 * PI - d)
    }

    #[test]
    fn angle_matches_construction_including_near_pi() {
        let mut rng = Lcg(7);
        let extra = [3.1, -3.1, PI - 1e-6, -(PI - 1e-6), 1e-8, -1e-8, PI];
        for &fold in FOLDS.iter().chain(extra.iter()) {
            for _ in 0..4 {
                let x = folded(&mut rng, fold);
                let theta = dihedral_angle(&x);
                assert!(theta > -PI && theta <= PI);
                assert!(
                    wrapped_diff(theta, fold) < 1e-10,
                    "fold {fold}: got {theta}"
                );
            }
        }
    }

    #[test]
    fn gradient_matches_finite_differences() {
        for (h, x, _) in cases() {
            let q = pack(&x);
            check_gradient(
                |q: &Vec12| energy(&h, &unpack(q)),
                &gradient(&h, &x),
                &q,
                1e-6,
                1e-5,
            );
        }
    }

    #[test]
    fn hessian_matches_finite_differences() {
        for (h, x, _) in cases() {
            let q = pack(&x);
            check_hessian(
                |q: &Vec12| gradient(&h, &unpack(q)),
                &hessian(&h, &x),
                &q,
                1e-6,
                1e-5,
            );
        }
    }

    #[test]
    fn angle_gradient_matches_classical_closed_form() {
        for (_, x, _) in cases() {
            let Some((_, g)) = dihedral_angle_gradient(&x) else {
                panic!("non-degenerate case reported degenerate")
            };
            let e = x[1] - x[0];
            let (a, b) = (x[2] - x[0], x[3] - x[0]);
            let (n1, n2) = (e.cross(&a), b.cross(&e));
            let g2 = n1 * (e.norm() / n1.norm_squared());
            let g3 = n2 * (e.norm() / n2.norm_squared());
            let (t1, t2) = (a.dot(&e) / e.norm_squared(), b.dot(&e) / e.norm_squared());
            let g0 = -g2 * (1.0 - t1) - g3 * (1.0 - t2);
            let g1 = -g2 * t1 - g3 * t2;
            let expected = pack(&[g0, g1, g2, g3]);
            assert!(
                (g - expected).norm() <= 1e-10 * expected.norm(),
                "{g} vs {expected}"
            );
        }
    }

    #[test]
    fn combined_pass_agrees_and_is_psd() {
        let mut indefinite = 0;
        for (h, x, _) in cases() {
            let e = energy(&h, &x);
            let g = gradient(&h, &x);
            let hx = hessian(&h, &x);
            let (_, g_theta) = dihedral_angle_gradient(&x).unwrap_or_default();
            let gn = g_theta * g_theta.transpose() * (2.0 * h.weight);
            let projected = project_psd(&hx);
            let scale = hx.norm().max(1.0);
            for (mode, expected) in [
                (BendingHessian::GaussNewton, gn),
                (BendingHessian::Projected, projected),
            ] {
                let (e2, g2, h2) = energy_gradient_hessian(&h, &x, mode);
                assert!((e2 - e).abs() <= 1e-12 * e.abs().max(1e-300));
                assert!((g2 - g).norm() <= 1e-12 * g.norm().max(1e-300));
                assert!((h2 - expected).norm() <= 1e-10 * scale, "{mode:?}");
                check_psd(&h2);
            }
            let eig = nalgebra::SymmetricEigen::new(hx).eigenvalues.min();
            if eig < -1e-6 * scale {
                indefinite += 1;
            }
        }
        // The exact Hessian really is indefinite away from rest, so the filtering matters.
        assert!(indefinite >= 10, "only {indefinite} indefinite cases");
    }

    #[test]
    fn projected_equals_exact_when_already_psd() {
        // At θ = θ̄ the indefinite term vanishes: the exact Hessian is 2w∇θ∇θᵀ, PSD.
        for (mut h, x, _) in cases() {
            h.rest_angle = dihedral_angle(&x);
            let exact = hessian(&h, &x);
            check_psd(&exact);
            let (e, g, p) = energy_gradient_hessian(&h, &x, BendingHessian::Projected);
            assert_eq!(e, 0.0);
            assert_eq!(g, Vec12::zeros());
            assert!((p - exact).norm() <= 1e-10 * exact.norm());
        }
    }

    #[test]
    fn flat_hinge_has_zero_energy_and_gradient() {
        let mut rng = Lcg(11);
        let h = Hinge {
            v: [0, 1, 2, 3],
            rest_angle: 0.0,
            weight: 2.0,
        };
        // Exactly planar (z = 0): exactly zero.
        let x = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.3, 0.8, 0.0),
            Vector3::new(0.6, -0.7, 0.0),
        ];
        assert_eq!(dihedral_angle(&x), 0.0);
        assert_eq!(energy(&h, &x), 0.0);
        assert_eq!(gradient(&h, &x), Vec12::zeros());
        // Flat but rigidly placed: zero up to round-off.
        for _ in 0..10 {
            let x = folded(&mut rng, 0.0);
            assert!(dihedral_angle(&x).abs() < 1e-12);
            assert!(energy(&h, &x) < 1e-24);
            assert!(gradient(&h, &x).norm() < 1e-11);
        }
    }

    #[test]
    fn rigid_motion_invariance_and_mirror_sign() {
        let mut rng = Lcg(13);
        for (h, x, _) in cases() {
            let rot = rng.rotation();
            let shift = rng.vec3(5.0);
            let y = x.map(|p| rot * p + shift);
            let (tx, ty) = (dihedral_angle(&x), dihedral_angle(&y));
            assert!((tx - ty).abs() < 1e-10, "{tx} vs {ty}");
            let (ex, ey) = (energy(&h, &x), energy(&h, &y));
            assert!((ex - ey).abs() <= 1e-9 * ex.max(1.0));
            // The gradient rotates with the hinge.
            let (gx, gy) = (gradient(&h, &x), gradient(&h, &y));
            let gx_rot = pack(&unpack(&gx).map(|v| rot * v));
            assert!(
                (gx_rot - gy).norm() <= 1e-9 * gx.norm().max(1.0),
                "{} vs {}",
                gx.norm(),
                (gx_rot - gy).norm()
            );
            // A reflection flips the angle.
            let mirrored = x.map(|p| Vector3::new(p.x, p.y, -p.z));
            let tm = dihedral_angle(&mirrored);
            assert!((tm + tx).abs() < 1e-10, "{tx} mirrored to {tm}");
        }
    }

    #[test]
    fn degenerate_triangle_gives_zero_not_nan() {
        let h = Hinge {
            v: [0, 1, 2, 3],
            rest_angle: 0.3,
            weight: 1.0,
        };
        let collinear = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.5, 0.0, 0.0),
            Vector3::new(0.5, -1.0, 0.2),
        ];
        let collapsed = [Vector3::new(1.0, 2.0, 3.0); 4];
        for x in [collinear, collapsed] {
            assert_eq!(dihedral_angle(&x), 0.0);
            assert_eq!(energy(&h, &x), 0.0);
            assert_eq!(gradient(&h, &x), Vec12::zeros());
            assert_eq!(hessian(&h, &x), Mat12::zeros());
            for mode in [BendingHessian::GaussNewton, BendingHessian::Projected] {
                let (e, g, m) = energy_gradient_hessian(&h, &x, mode);
                assert_eq!((e, g, m), (0.0, Vec12::zeros(), Mat12::zeros()));
            }
        }
    }

    #[test]
    fn finite_difference_checks_can_fail() {
        let (h, x, _) = cases()[4];
        let q = pack(&x);
        // A gradient missing the x0 block must be caught.
        let mut wrong = gradient(&h, &x);
        wrong.fixed_rows_mut::<3>(0).fill(0.0);
        let r = catch_unwind(AssertUnwindSafe(|| {
            check_gradient(|q: &Vec12| energy(&h, &unpack(q)), &wrong, &q, 1e-6, 1e-5)
        }));
        assert!(r.is_err(), "corrupted gradient passed");
        // The Gauss-Newton matrix is not the exact Hessian away from rest.
        let (_, _, gn) = energy_gradient_hessian(&h, &x, BendingHessian::GaussNewton);
        let r = catch_unwind(AssertUnwindSafe(|| {
            check_hessian(|q: &Vec12| gradient(&h, &unpack(q)), &gn, &q, 1e-6, 1e-5)
        }));
        assert!(r.is_err(), "Gauss-Newton passed as exact Hessian");
    }

    /// 2×2 squares of side `s`, 3×3 vertices, each square split along its (i,j)–(i+1,j+1) diagonal.
    fn grid(s: f64) -> (Vec<[u32; 3]>, Vec<Vector2<f64>>) {
        let idx = |i: u32, j: u32| j * 3 + i;
        let mut tris = Vec::new();
        for j in 0..2 {
            for i in 0..2 {
                let (v00, v10) = (idx(i, j), idx(i + 1, j));
                let (v01, v11) = (idx(i, j + 1), idx(i + 1, j + 1));
                tris.push([v00, v10, v11]);
                tris.push([v00, v11, v01]);
            }
        }
        let material = (0..9)
            .map(|k| Vector2::new(f64::from(k % 3) * s, f64::from(k / 3) * s))
            .collect();
        (tris, material)
    }

    fn corners(x: &[Vector3<f64>], h: &Hinge) -> [Vector3<f64>; 4] {
        h.v.map(|i| x[i as usize])
    }

    #[test]
    fn hinges_of_grid() {
        let (s, kb) = (0.1, 2e-3);
        let (tris, material) = grid(s);
        let hs = hinges(&tris, &material, kb);
        // 16 edges, 8 on the boundary.
        assert_eq!(hs.len(), 8);
        let is_ccw_triangle = |p: u32, q: u32, r: u32| {
            tris.iter()
                .any(|t| (0..3).any(|k| [t[k], t[(k + 1) % 3], t[(k + 2) % 3]] == [p, q, r]))
        };
        let (mut diagonal, mut axis) = (0, 0);
        for h in &hs {
            let [x0, x1, x2, x3] = h.v;
            assert!(
                is_ccw_triangle(x0, x1, x2) && is_ccw_triangle(x1, x0, x3),
                "{h:?}"
            );
            assert_eq!(h.rest_angle, 0.0);
            assert!(h.weight > 0.0);
            // Diagonal: 3·2s²/s² = 6 k_b; axis-aligned: 3·s²/s² = 3 k_b.
            if (h.weight - 6.0 * kb).abs() < 1e-12 {
                diagonal += 1;
            } else {
                assert!((h.weight - 3.0 * kb).abs() < 1e-12, "{h:?}");
                axis += 1;
            }
        }
        assert_eq!((diagonal, axis), (4, 4));

        // Rest positions (flat, also rigidly moved): zero energy and gradient.
        let mut rng = Lcg(17);
        let rot = rng.rotation();
        let shift = rng.vec3(1.0);
        let flat: Vec<Vector3<f64>> = material
            .iter()
            .map(|m| Vector3::new(m.x, m.y, 0.0))
            .collect();
        let moved: Vec<Vector3<f64>> = flat.iter().map(|p| rot * p + shift).collect();
        for h in &hs {
            assert_eq!(energy(h, &corners(&flat, h)), 0.0);
            assert_eq!(gradient(h, &corners(&flat, h)), Vec12::zeros());
            assert!(energy(h, &corners(&moved, h)) < 1e-24);
        }

        // Folding the right column about the line x = s: both hinges on the fold line get the
        // same angle, +φ when folding towards the normals (+z), −φ the other way; others stay 0.
        for phi in [0.9_f64, -0.9, 2.6, -2.6] {
            let bent: Vec<Vector3<f64>> = flat
                .iter()
                .map(|p| {
                    if p.x > s + 1e-9 {
                        let d = p.x - s;
                        Vector3::new(s + d * phi.cos(), p.y, d * phi.sin())
                    } else {
                        *p
                    }
                })
                .collect();
            let mut on_fold = 0;
            for h in &hs {
                let theta = dihedral_angle(&corners(&bent, h));
                let [a, b] = [material[h.v[0] as usize], material[h.v[1] as usize]];
                if (a.x - s).abs() < 1e-9 && (b.x - s).abs() < 1e-9 {
                    on_fold += 1;
                    assert!((theta - phi).abs() < 1e-12, "{theta} vs {phi}");
                } else {
                    assert!(theta.abs() < 1e-12, "{theta}");
                }
            }
            assert_eq!(on_fold, 2);
        }
    }
}
