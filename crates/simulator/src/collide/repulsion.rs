//! Unilateral quadratic repulsion between a point and a triangle or between two edges, with
//! exact first and second derivatives of the distance in each closest-feature case.
//!
//! # Energy
//!
//! For a contact with distance d (metres), thickness d̂ and stiffness κ (N/m):
//!
//! E(d) = ½ κ (d̂ − d)²  for d < d̂,  0 otherwise,
//!
//! ∇E = −κ (d̂ − d) ∇d,   ∇²E = κ ∇d ∇dᵀ − κ (d̂ − d) ∇²d.
//!
//! E is C¹ at d = d̂ (value and gradient vanish), which is what a Newton solver with line search
//! needs; d may be negative (signed obstacle distance), the force then keeps growing linearly.
//!
//! # Distance and its gradient
//!
//! The four points x₀..x₃ of a contact are (vertex, triangle) or (edge a, edge b). The distance is
//! d = |Σ cᵢ xᵢ| where Σ cᵢ xᵢ = p − q is the vector between the closest points (the coefficients
//! cᵢ are 1 and minus the barycentric coordinates, or (1−s, s, −(1−t), −t) for edges). Because
//! the closest points minimise the distance over the features, the derivative of the closest
//! point parameters drops out (Danskin's / the envelope theorem), so with n = (p − q)/d
//!
//! ∂d/∂xᵢ = cᵢ n,
//!
//! exactly, in every closest-feature case. [`DistanceJet`] stores (d, c, n).
//!
//! # Second derivative
//!
//! ∇²d depends on the closest-feature case, as in IPC (Li et al., "Incremental Potential
//! Contact", SIGGRAPH 2020, §4 and its supplement): point–point d = |xᵢ − xⱼ|, point–line
//! d = |(xᵢ − xⱼ) × (xₖ − xⱼ)| / |xₖ − xⱼ|, point–plane d = ±(x₀ − x₁)·N/|N| with
//! N = (x₂ − x₁) × (x₃ − x₁), line–line d = ±(x₀ − x₂)·N/|N| with N = (x₁ − x₀) × (x₃ − x₂).
//! These closed forms are differentiated twice with forward-mode second-order dual numbers
//! (value, 12-gradient, 12×12 Hessian), which is exact to round-off. The case is fixed by the
//! closest features at the current positions.
//!
//! # PSD Hessian: Gauss-Newton by default
//!
//! [`HessianKind::GaussNewton`] (the default) drops the curvature term: H = κ ∇d ∇dᵀ =
//! κ (c cᵀ) ⊗ (n nᵀ), PSD by construction, a single 12×12 outer product, and bounded as d → 0
//! (the exact ∇²d grows like 1/d for unsigned distances). It is also what eigenvalue clamping of
//! the exact Hessian gives in the point–point case (the dropped term −κ(d̂ − d)(I − nnᵀ)/d is
//! negative semi-definite there) and what clamping the cloth vertex's 3×3 block gives for a
//! cloth vertex against a fixed obstacle face (d is affine in the vertex in the face case; in the
//! edge and vertex cases the dropped block −κ(d̂ − d)∇²d is negative semi-definite and
//! orthogonal to n). [`HessianKind::ProjectedExact`]
//! (eigenvalue-clamped exact Hessian, [`project_psd`]) and [`HessianKind::Exact`] are available
//! for comparison and for the tests.
//!
//! # Obstacles: signed distance
//!
//! For a cloth vertex against a collider face (counter-clockwise seen from outside, outward
//! normal n = (b − a) × (c − a) / |…|), [`obstacle_eval`] uses the signed plane distance
//! d = n·(p − a) when p projects inside the face (so a vertex that slipped inside still gets
//! pushed out along +n, with ∂d/∂p = n and ∂d/∂(a, b, c) = −λ n for the projection's
//! barycentric λ), and the unsigned closest-point distance otherwise.

use nalgebra::Vector3;

use super::distance::{point_triangle, segment_segment, PointTriangle, TriangleFeature};
use crate::energy::{project_psd, Mat12, Vec12};

/// Which closed form of the distance holds at the current positions (local point indices 0..4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DistanceCase {
    /// d = |xᵢ − xⱼ|.
    PointPoint(usize, usize),
    /// Distance from xᵢ to the line through xⱼ, xₖ.
    PointLine(usize, usize, usize),
    /// d = sign·(x₀ − x₁)·N/|N|, N = (x₂ − x₁) × (x₃ − x₁); sign = +1 for the signed obstacle
    /// distance, the side of x₀ for the unsigned one.
    PointPlane {
        /// +1 or −1.
        sign: f64,
    },
    /// d = sign·(x₀ − x₂)·N/|N|, N = (x₁ − x₀) × (x₃ − x₂) (both closest points interior).
    LineLine {
        /// +1 or −1 (the side of edge 0), so that d ≥ 0.
        sign: f64,
    },
}

/// A distance with its exact gradient ∂d/∂xᵢ = `coeffs[i]`·`n`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DistanceJet {
    /// The distance (signed for obstacle faces), metres.
    pub d: f64,
    /// Coefficients cᵢ with p − q = Σ cᵢ xᵢ.
    pub coeffs: [f64; 4],
    /// Unit direction of increasing d (from the closest point q towards p).
    pub n: Vector3<f64>,
    /// Closed form for the second derivative.
    pub case: DistanceCase,
}

impl DistanceJet {
    /// ∇d as a 12-vector (x₀, x₁, x₂, x₃ stacked).
    pub fn gradient(&self) -> Vec12 {
        let mut g = Vec12::zeros();
        for i in 0..4 {
            g.fixed_rows_mut::<3>(3 * i)
                .copy_from(&(self.n * self.coeffs[i]));
        }
        g
    }

    /// Exact ∇²d (12×12) of this case's closed form at `x`; zero where it is undefined
    /// (d = 0 for unsigned distances, degenerate lines or planes).
    pub fn hessian(&self, x: &[Vector3<f64>; 4]) -> Mat12 {
        let p: [[Dual; 3]; 4] =
            std::array::from_fn(|k| std::array::from_fn(|a| Dual::var(x[k][a], 3 * k + a)));
        let d = match self.case {
            DistanceCase::PointPoint(i, j) => {
                let r = sub3(&p[i], &p[j]);
                dot3(&r, &r).sqrt()
            }
            DistanceCase::PointLine(i, j, k) => {
                let u = sub3(&p[i], &p[j]);
                let e = sub3(&p[k], &p[j]);
                let c = cross3(&u, &e);
                dot3(&c, &c).mul(&dot3(&e, &e).recip()).sqrt()
            }
            DistanceCase::PointPlane { sign } => {
                let n = cross3(&sub3(&p[2], &p[1]), &sub3(&p[3], &p[1]));
                dot3(&sub3(&p[0], &p[1]), &n)
                    .mul(&dot3(&n, &n).sqrt().recip())
                    .scale(sign)
            }
            DistanceCase::LineLine { sign } => {
                let n = cross3(&sub3(&p[1], &p[0]), &sub3(&p[3], &p[2]));
                dot3(&sub3(&p[0], &p[2]), &n)
                    .mul(&dot3(&n, &n).sqrt().recip())
                    .scale(sign)
            }
        };
        if d.h.iter().all(|v| v.is_finite()) {
            d.h
        } else {
            Mat12::zeros()
        }
    }
}

/// Some unit vector orthogonal to `v` (or +z for v = 0).
fn any_orthogonal(v: &Vector3<f64>) -> Vector3<f64> {
    let t = if v.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    v.cross(&t).try_normalize(0.0).unwrap_or_else(Vector3::z)
}

/// Builds the jet for p − q = `r` with a fallback direction for r = 0.
fn jet_from(
    r: Vector3<f64>,
    coeffs: [f64; 4],
    fallback: Vector3<f64>,
    case: DistanceCase,
) -> DistanceJet {
    let d = r.norm();
    let n = if d > 1e-300 { r / d } else { fallback };
    DistanceJet { d, coeffs, n, case }
}

/// Unsigned distance between point x₀ and triangle (x₁, x₂, x₃), with its closest-feature case.
pub fn vertex_triangle_jet(x: &[Vector3<f64>; 4]) -> DistanceJet {
    let pt = point_triangle(&x[0], &x[1], &x[2], &x[3]);
    vertex_triangle_jet_from(x, &pt)
}

fn vertex_triangle_jet_from(x: &[Vector3<f64>; 4], pt: &PointTriangle) -> DistanceJet {
    let b = pt.bary;
    let q = x[1] * b[0] + x[2] * b[1] + x[3] * b[2];
    let r = x[0] - q;
    let nrm = (x[2] - x[1]).cross(&(x[3] - x[1]));
    let case = match pt.feature {
        TriangleFeature::Vertex(i) => DistanceCase::PointPoint(0, i + 1),
        TriangleFeature::Edge(i, j) => DistanceCase::PointLine(0, i + 1, j + 1),
        TriangleFeature::Face => DistanceCase::PointPlane {
            sign: if r.dot(&nrm) < 0.0 { -1.0 } else { 1.0 },
        },
    };
    let fallback = nrm.try_normalize(0.0).unwrap_or_else(Vector3::z);
    jet_from(r, [1.0, -b[0], -b[1], -b[2]], fallback, case)
}

/// Unsigned distance between edge (x₀, x₁) and edge (x₂, x₃), with its closest-feature case.
pub fn edge_edge_jet(x: &[Vector3<f64>; 4]) -> DistanceJet {
    let ss = segment_segment(&x[0], &x[1], &x[2], &x[3]);
    let (s, t) = (ss.s, ss.t);
    let r = (x[0] + (x[1] - x[0]) * s) - (x[2] + (x[3] - x[2]) * t);
    let ea = x[1] - x[0];
    let nrm = ea.cross(&(x[3] - x[2]));
    let end_a = s == 0.0 || s == 1.0;
    let end_b = t == 0.0 || t == 1.0;
    let ia = if s == 0.0 { 0 } else { 1 };
    let ib = if t == 0.0 { 2 } else { 3 };
    let case = match (end_a, end_b) {
        (true, true) => DistanceCase::PointPoint(ia, ib),
        (true, false) => DistanceCase::PointLine(ia, 2, 3),
        (false, true) => DistanceCase::PointLine(ib, 0, 1),
        (false, false) => DistanceCase::LineLine {
            sign: if r.dot(&nrm) < 0.0 { -1.0 } else { 1.0 },
        },
    };
    let fallback = nrm
        .try_normalize(0.0)
        .unwrap_or_else(|| any_orthogonal(&ea));
    jet_from(r, [1.0 - s, s, t - 1.0, -t], fallback, case)
}

/// A cloth vertex against an obstacle face: everything needed to decide and evaluate contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObstacleEval {
    /// Unsigned closest point on the face.
    pub closest: PointTriangle,
    /// Outward unit normal (b − a) × (c − a)/|…|; `None` for a degenerate face.
    pub normal: Option<Vector3<f64>>,
    /// Signed distance n·(p − a) to the face's plane (0 for a degenerate face).
    pub signed_plane: f64,
    /// Barycentric coordinates of p's projection onto the plane.
    pub proj_bary: [f64; 3],
    /// Whether the projection lies in the (closed) face.
    pub projects_inside: bool,
}

impl ObstacleEval {
    /// The contact distance: signed plane distance if p projects inside the face, else the
    /// unsigned closest-point distance.
    pub fn distance(&self) -> f64 {
        if self.projects_inside {
            self.signed_plane
        } else {
            self.closest.dist
        }
    }
}

/// Evaluates point `p` against the obstacle face `abc` (counter-clockwise seen from outside).
pub fn obstacle_eval(
    p: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> ObstacleEval {
    obstacle_eval_with(p, a, b, c, point_triangle(p, a, b, c))
}

/// The normal (b − a) × (c − a) of triangle a, b, c, not normalised, and its squared length;
/// `None` for a sliver (squared length below 1e-14 times the longest edge's fourth power, or
/// not a number), whose normal is noise.
pub fn face_normal(
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> Option<(Vector3<f64>, f64)> {
    let nrm = (b - a).cross(&(c - a));
    let n2 = nrm.norm_squared();
    let emax = (b - a)
        .norm_squared()
        .max((c - a).norm_squared())
        .max((c - b).norm_squared());
    let sliver = n2.is_nan() || n2 <= 1e-14 * emax * emax;
    (!sliver).then_some((nrm, n2))
}

/// As [`obstacle_eval`], given the already computed `closest = point_triangle(p, a, b, c)`.
pub fn obstacle_eval_with(
    p: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
    closest: PointTriangle,
) -> ObstacleEval {
    let Some((nrm, n2)) = face_normal(a, b, c) else {
        return ObstacleEval {
            closest,
            normal: None,
            signed_plane: 0.0,
            proj_bary: closest.bary,
            projects_inside: false,
        };
    };
    // Signed sub-areas (invariant to moving p along the normal).
    let la = nrm.dot(&(b - p).cross(&(c - p))) / n2;
    let lb = nrm.dot(&(c - p).cross(&(a - p))) / n2;
    let lc = 1.0 - la - lb;
    let n = nrm / n2.sqrt();
    ObstacleEval {
        closest,
        normal: Some(n),
        signed_plane: n.dot(&(p - a)),
        proj_bary: [la, lb, lc],
        projects_inside: la >= 0.0 && lb >= 0.0 && lc >= 0.0,
    }
}

/// Distance of vertex x₀ to obstacle face (x₁, x₂, x₃): signed if x₀ projects inside the face,
/// unsigned otherwise (see [`ObstacleEval::distance`]).
pub fn vertex_obstacle_jet(x: &[Vector3<f64>; 4]) -> DistanceJet {
    let e = obstacle_eval(&x[0], &x[1], &x[2], &x[3]);
    match e.normal {
        Some(n) if e.projects_inside => {
            let l = e.proj_bary;
            DistanceJet {
                d: e.signed_plane,
                coeffs: [1.0, -l[0], -l[1], -l[2]],
                n,
                case: DistanceCase::PointPlane { sign: 1.0 },
            }
        }
        _ => vertex_triangle_jet_from(x, &e.closest),
    }
}

/// Which Hessian [`penalty`] returns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum HessianKind {
    /// κ ∇d ∇dᵀ: PSD, cheap, bounded as d → 0 (the default; see the module docs).
    #[default]
    GaussNewton,
    /// The exact Hessian with negative eigenvalues clamped to zero.
    ProjectedExact,
    /// The exact Hessian κ ∇d ∇dᵀ − κ (d̂ − d) ∇²d (indefinite in general).
    Exact,
}

/// E(d) = ½ κ (d̂ − d)² for d < d̂, else 0.
pub fn penalty_energy(d: f64, dhat: f64, kappa: f64) -> f64 {
    if d < dhat {
        0.5 * kappa * (dhat - d) * (dhat - d)
    } else {
        0.0
    }
}

/// Energy, gradient and Hessian (of `kind`) of the quadratic repulsion for `jet` at points `x`.
/// All zero when d ≥ d̂.
pub fn penalty(
    x: &[Vector3<f64>; 4],
    jet: &DistanceJet,
    dhat: f64,
    kappa: f64,
    kind: HessianKind,
) -> (f64, Vec12, Mat12) {
    let d = jet.d;
    if d >= dhat || !d.is_finite() {
        return (0.0, Vec12::zeros(), Mat12::zeros());
    }
    let gap = dhat - d;
    let gd = jet.gradient();
    let gn = gd * gd.transpose() * kappa;
    let h = match kind {
        HessianKind::GaussNewton => gn,
        HessianKind::Exact => gn - jet.hessian(x) * (kappa * gap),
        HessianKind::ProjectedExact => project_psd(&(gn - jet.hessian(x) * (kappa * gap))),
    };
    (0.5 * kappa * gap * gap, gd * (-kappa * gap), h)
}

// ---------------------------------------------------------------------------------------------
// Second-order forward-mode dual numbers over the 12 contact coordinates.

/// A scalar with its gradient and Hessian w.r.t. the 12 coordinates.
#[derive(Clone)]
struct Dual {
    v: f64,
    g: Vec12,
    h: Mat12,
}

impl Dual {
    fn var(v: f64, i: usize) -> Dual {
        let mut g = Vec12::zeros();
        g[i] = 1.0;
        Dual {
            v,
            g,
            h: Mat12::zeros(),
        }
    }

    fn add(&self, o: &Dual) -> Dual {
        Dual {
            v: self.v + o.v,
            g: self.g + o.g,
            h: self.h + o.h,
        }
    }

    fn sub(&self, o: &Dual) -> Dual {
        Dual {
            v: self.v - o.v,
            g: self.g - o.g,
            h: self.h - o.h,
        }
    }

    fn scale(&self, k: f64) -> Dual {
        Dual {
            v: self.v * k,
            g: self.g * k,
            h: self.h * k,
        }
    }

    /// (ab)'' = a''b + ab'' + a'b'ᵀ + b'a'ᵀ.
    fn mul(&self, o: &Dual) -> Dual {
        let cross = self.g * o.g.transpose();
        Dual {
            v: self.v * o.v,
            g: self.g * o.v + o.g * self.v,
            h: self.h * o.v + o.h * self.v + cross + cross.transpose(),
        }
    }

    /// (1/b)' = −b'/b², (1/b)'' = −b''/b² + 2 b'b'ᵀ/b³.
    fn recip(&self) -> Dual {
        let b = self.v;
        Dual {
            v: 1.0 / b,
            g: self.g * (-1.0 / (b * b)),
            h: self.h * (-1.0 / (b * b)) + self.g * self.g.transpose() * (2.0 / (b * b * b)),
        }
    }

    /// (√a)' = a'/(2√a), (√a)'' = a''/(2√a) − a'a'ᵀ/(4 a^{3/2}).
    fn sqrt(&self) -> Dual {
        let s = self.v.sqrt();
        Dual {
            v: s,
            g: self.g * (0.5 / s),
            h: self.h * (0.5 / s) - self.g * self.g.transpose() * (0.25 / (s * s * s)),
        }
    }
}

fn sub3(a: &[Dual; 3], b: &[Dual; 3]) -> [Dual; 3] {
    std::array::from_fn(|k| a[k].sub(&b[k]))
}

fn dot3(a: &[Dual; 3], b: &[Dual; 3]) -> Dual {
    a[0].mul(&b[0]).add(&a[1].mul(&b[1])).add(&a[2].mul(&b[2]))
}

fn cross3(a: &[Dual; 3], b: &[Dual; 3]) -> [Dual; 3] {
    [
        a[1].mul(&b[2]).sub(&a[2].mul(&b[1])),
        a[2].mul(&b[0]).sub(&a[0].mul(&b[2])),
        a[0].mul(&b[1]).sub(&a[1].mul(&b[0])),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::collide::distance::tests::Lcg;
    use crate::energy::fd::{check_gradient, check_hessian, check_psd};
    use std::collections::HashMap;

    fn to_pts(v: &Vec12) -> [Vector3<f64>; 4] {
        std::array::from_fn(|k| Vector3::new(v[3 * k], v[3 * k + 1], v[3 * k + 2]))
    }

    fn to_vec(x: &[Vector3<f64>; 4]) -> Vec12 {
        Vec12::from_fn(|i, _| x[i / 3][i % 3])
    }

    /// A label for the closest-feature case that ignores the unsigned sign.
    fn label(j: &DistanceJet) -> String {
        match j.case {
            DistanceCase::PointPlane { .. } => "PointPlane".into(),
            DistanceCase::LineLine { .. } => "LineLine".into(),
            c => format!("{c:?}"),
        }
    }

    /// Whether the case (and sign) stays the same under ±1e-4 perturbations of every coordinate.
    fn stable(x: &[Vector3<f64>; 4], jet: fn(&[Vector3<f64>; 4]) -> DistanceJet) -> bool {
        let c0 = jet(x).case;
        let v = to_vec(x);
        (0..12).all(|i| {
            [-1e-4, 1e-4].iter().all(|&h| {
                let mut w = v;
                w[i] += h;
                jet(&to_pts(&w)).case == c0
            })
        })
    }

    /// FD-checks energy, gradient and exact Hessian, and PSD of the PSD variants, at `x`.
    fn check_all(
        x: &[Vector3<f64>; 4],
        jet: fn(&[Vector3<f64>; 4]) -> DistanceJet,
        dhat: f64,
        kappa: f64,
    ) {
        let e = |v: &Vec12| {
            let p = to_pts(v);
            penalty(&p, &jet(&p), dhat, kappa, HessianKind::GaussNewton).0
        };
        let g = |v: &Vec12| {
            let p = to_pts(v);
            penalty(&p, &jet(&p), dhat, kappa, HessianKind::GaussNewton).1
        };
        let j = jet(x);
        let v = to_vec(x);
        // The distance gradient alone, against differences of d.
        check_gradient(|w| jet(&to_pts(w)).d, &j.gradient(), &v, 1e-6, 1e-6);
        let (en, gr, gn) = penalty(x, &j, dhat, kappa, HessianKind::GaussNewton);
        assert!((en - 0.5 * kappa * (dhat - j.d).powi(2)).abs() < 1e-12 * en.max(1.0));
        assert!((en - e(&v)).abs() < 1e-14);
        check_gradient(e, &gr, &v, 1e-6, 1e-6);
        let (_, _, ex) = penalty(x, &j, dhat, kappa, HessianKind::Exact);
        check_hessian(g, &ex, &v, 1e-6, 1e-5);
        check_psd(&gn);
        let (_, _, pe) = penalty(x, &j, dhat, kappa, HessianKind::ProjectedExact);
        check_psd(&pe);
    }

    /// Samples random configurations and FD-checks a few of each closest-feature case.
    fn sweep(
        seed: u64,
        jet: fn(&[Vector3<f64>; 4]) -> DistanceJet,
        sample: impl Fn(&mut Lcg) -> [Vector3<f64>; 4],
        expect: &[&str],
    ) {
        let (dhat, kappa) = (4.0, 7.0);
        let mut rng = Lcg(seed);
        let mut count: HashMap<String, usize> = HashMap::new();
        for _ in 0..20000 {
            let x = sample(&mut rng);
            let j = jet(&x);
            if !(j.d > 0.05 && j.d < dhat - 0.05 && stable(&x, jet)) {
                continue;
            }
            let l = label(&j);
            let c = count.entry(l).or_insert(0);
            if *c >= 4 {
                continue;
            }
            *c += 1;
            check_all(&x, jet, dhat, kappa);
            let have = |k: &str| -> usize {
                count
                    .iter()
                    .filter(|(c, _)| c.starts_with(k))
                    .map(|(_, n)| n)
                    .sum()
            };
            if expect.iter().all(|k| have(k) >= 3) {
                break;
            }
        }
        for k in expect {
            assert!(
                count.keys().any(|c| c.starts_with(k)),
                "case {k} never sampled: {count:?}"
            );
        }
    }

    #[test]
    fn vertex_triangle_derivatives_in_every_region() {
        sweep(
            21,
            vertex_triangle_jet,
            |r| [r.v3(2.0), r.v3(1.0), r.v3(1.0), r.v3(1.0)],
            &[
                "PointPlane",
                "PointLine(0, 1, 2)",
                "PointLine(0, 1, 3)",
                "PointLine(0, 2, 3)",
                "PointPoint(0, 1)",
                "PointPoint(0, 2)",
                "PointPoint(0, 3)",
            ],
        );
    }

    #[test]
    fn edge_edge_derivatives_in_every_region() {
        sweep(
            22,
            edge_edge_jet,
            |r| [r.v3(1.0), r.v3(1.0), r.v3(1.0), r.v3(1.0)],
            &[
                "LineLine",
                "PointLine(0, 2, 3)",
                "PointLine(1, 2, 3)",
                "PointLine(2, 0, 1)",
                "PointLine(3, 0, 1)",
                "PointPoint(0, 2)",
                "PointPoint(1, 3)",
            ],
        );
    }

    #[test]
    fn obstacle_derivatives_signed_and_unsigned() {
        // Signed face case on both sides, and the unsigned cases outside the prism.
        sweep(
            23,
            vertex_obstacle_jet,
            |r| [r.v3(2.0), r.v3(1.0), r.v3(1.0), r.v3(1.0)],
            &["PointPlane", "PointLine", "PointPoint"],
        );
        // Explicitly below the face (negative d), which the sweep above skips (d > 0.05).
        let mut rng = Lcg(24);
        let mut below = 0;
        for _ in 0..2000 {
            let x = [rng.v3(1.0), rng.v3(1.0), rng.v3(1.0), rng.v3(1.0)];
            let j = vertex_obstacle_jet(&x);
            if j.d < -0.05 && stable(&x, vertex_obstacle_jet) {
                assert_eq!(j.case, DistanceCase::PointPlane { sign: 1.0 });
                check_all(&x, vertex_obstacle_jet, 0.1, 7.0);
                below += 1;
                if below == 5 {
                    break;
                }
            }
        }
        assert_eq!(below, 5);
    }

    #[test]
    fn zero_beyond_dhat() {
        let x = [
            Vector3::new(0.2, 0.2, 0.5),
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
        ];
        for jet in [vertex_triangle_jet, vertex_obstacle_jet] {
            let j = jet(&x);
            assert!((j.d - 0.5).abs() < 1e-15);
            for kind in [
                HessianKind::GaussNewton,
                HessianKind::Exact,
                HessianKind::ProjectedExact,
            ] {
                let (e, g, h) = penalty(&x, &j, 0.5, 10.0, kind);
                assert_eq!((e, g.norm(), h.norm()), (0.0, 0.0, 0.0));
                let (e, g, h) = penalty(&x, &j, 0.5 + 1e-3, 10.0, kind);
                assert!(e > 0.0 && g.norm() > 0.0 && h.norm() > 0.0);
            }
        }
        assert_eq!(penalty_energy(0.5, 0.5, 10.0), 0.0);
        assert!((penalty_energy(0.25, 0.5, 10.0) - 0.3125).abs() < 1e-15);
    }

    #[test]
    fn obstacle_pushes_penetrating_vertex_out_along_normal() {
        // Counter-clockwise seen from +z: outward normal +z.
        let tri = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
        ];
        let dhat = 0.01;
        for z in [0.005, 0.0, -0.003, -0.02] {
            let x = [Vector3::new(0.25, 0.3, z), tri[0], tri[1], tri[2]];
            let j = vertex_obstacle_jet(&x);
            assert!((j.d - z).abs() < 1e-15, "signed distance {} vs {z}", j.d);
            let (e, g, h) = penalty(&x, &j, dhat, 100.0, HessianKind::GaussNewton);
            assert!(e > 0.0);
            let force = -g.fixed_rows::<3>(0).into_owned();
            assert!(force.z > 0.0 && force.x.abs() < 1e-15 && force.y.abs() < 1e-15);
            assert!((force.z - 100.0 * (dhat - z)).abs() < 1e-12);
            check_psd(&h);
        }
        // The unsigned self distance does not flip: below the face it pushes further down.
        let x = [Vector3::new(0.25, 0.3, -0.003), tri[0], tri[1], tri[2]];
        let j = vertex_triangle_jet(&x);
        assert!((j.d - 0.003).abs() < 1e-15 && j.n.z < 0.0);
        // Outside the prism, the obstacle distance is the unsigned one.
        let x = [Vector3::new(-0.1, -0.1, -0.001), tri[0], tri[1], tri[2]];
        let j = vertex_obstacle_jet(&x);
        assert!((j.d - (0.02f64 + 1e-6).sqrt()).abs() < 1e-15);
    }

    #[test]
    fn obstacle_eval_projection_and_prism() {
        let mut rng = Lcg(25);
        let mut inside = 0;
        for _ in 0..2000 {
            let [p, a, b, c] = [rng.v3(1.5), rng.v3(1.0), rng.v3(1.0), rng.v3(1.0)];
            let e = obstacle_eval(&p, &a, &b, &c);
            let n = e.normal.expect("random triangles are not degenerate");
            let l = e.proj_bary;
            assert!((l.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            // The projection q = Σ λ x lies in the plane with p − q along the normal.
            let q = a * l[0] + b * l[1] + c * l[2];
            assert!(((p - q) - n * e.signed_plane).norm() < 1e-12);
            assert!((n.dot(&(b - a)).abs() + n.dot(&(c - a)).abs()) < 1e-12);
            assert!((b - a).cross(&(c - a)).dot(&n) > 0.0);
            // Inside the prism iff the closest point is in the face interior (away from ties).
            if l.iter().all(|v| v.abs() > 1e-9) {
                let face = e.closest.feature == TriangleFeature::Face;
                assert_eq!(e.projects_inside, face, "{l:?} {:?}", e.closest.feature);
                inside += face as usize;
                let want = if face { e.signed_plane } else { e.closest.dist };
                assert_eq!(e.distance(), want);
                assert_eq!(vertex_obstacle_jet(&[p, a, b, c]).d, want);
            }
        }
        assert!(inside > 100);
    }

    #[test]
    fn dual_numbers_on_a_known_function() {
        // f = sqrt(x0² + x1²)/x2 at (3, 4, 2).
        let a = Dual::var(3.0, 0);
        let b = Dual::var(4.0, 1);
        let c = Dual::var(2.0, 2);
        let f = a.mul(&a).add(&b.mul(&b)).sqrt().mul(&c.recip());
        assert!((f.v - 2.5).abs() < 1e-15);
        assert!((f.g[0] - 0.3).abs() < 1e-15 && (f.g[1] - 0.4).abs() < 1e-15);
        assert!((f.g[2] + 1.25).abs() < 1e-15);
        // ∂²f/∂x0² = (1/x2)·x1²/r³ = 0.5·16/125.
        assert!((f.h[(0, 0)] - 0.5 * 16.0 / 125.0).abs() < 1e-15);
        // ∂²f/∂x2² = 2r/x2³ = 10/8.
        assert!((f.h[(2, 2)] - 1.25).abs() < 1e-15);
    }
}
