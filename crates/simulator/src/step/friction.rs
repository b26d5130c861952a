//! Coulomb friction against bodies as IPC's lagged dissipation potential.

use nalgebra::{Matrix3, Vector3};

use super::state::BodyMotion;
use super::Simulator;
use crate::collide::distance::segment_segment;
use crate::collide::repulsion::vertex_obstacle_jet;
use crate::collide::Contact;

/// Coulomb friction of one cloth vertex against a body as a dissipative potential in the
/// Newton system (lagged friction of IPC, Li et al. 2020): the normal force and the tangent
/// plane are those at the start of the step, the sliding is the vertex's tangential
/// displacement relative to the body surface under it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrictionPoint {
    /// Cloth vertex.
    pub v: u32,
    /// μ × normal force, N.
    pub mu_lambda_n: f64,
    /// Unit normal of the body face.
    pub n: Vector3<f64>,
    /// Where the vertex is without sliding: its start-of-step position moved with the body.
    pub anchor: Vector3<f64>,
    /// Sliding displacement below which friction is static-like (ε_v h), m.
    pub eps_m: f64,
}

impl FrictionPoint {
    /// Dissipation potential μλ f₀(‖u‖), u = (I − n nᵀ)(x − anchor), with IPC's C¹ mollifier
    /// f₀(y) = y²/ε − y³/(3ε²) + ε/3 below ε and y above; its gradient μλ f₁(y)/y u (the
    /// friction force, μλ in magnitude when sliding); and as Hessian μλ f₁(y)/y P, P = I − n nᵀ.
    /// The exact Hessian is μλ [f₁/y (P − ûûᵀ) + f₁′ ûûᵀ] (û = u/y): along the slide it has
    /// f₁′ ≤ f₁/y (0 when sliding), so this one is the exact one plus a PSD term, a stiffer
    /// model along the slide. With one Newton iteration a step (fast mode) the exact one let
    /// the step overshoot and the friction chatter: the corrector's tiny training set (a silk
    /// sheet on a ball) became noise that training could not lower, where with this one the
    /// loss fell. Converged Newton reaches the same minimiser.
    pub fn energy_gradient_hessian(&self, x: &Vector3<f64>) -> (f64, Vector3<f64>, Matrix3<f64>) {
        let (e, f1_over_y, _, u) = self.eval(x);
        let p = Matrix3::identity() - self.n * self.n.transpose();
        (
            e,
            u * (self.mu_lambda_n * f1_over_y),
            p * (self.mu_lambda_n * f1_over_y),
        )
    }

    /// The potential alone.
    pub fn energy(&self, x: &Vector3<f64>) -> f64 {
        self.eval(x).0
    }

    /// (μλ f₀(y), f₁(y)/y, f₁′(y), u).
    fn eval(&self, x: &Vector3<f64>) -> (f64, f64, f64, Vector3<f64>) {
        let r = x - self.anchor;
        let u = r - self.n * self.n.dot(&r);
        let y = u.norm();
        let eps = self.eps_m.max(f64::MIN_POSITIVE);
        let (f0, f1_over_y, df1) = if y >= eps {
            (y, 1.0 / y, 0.0)
        } else {
            (
                y * y / eps - y * y * y / (3.0 * eps * eps) + eps / 3.0,
                2.0 / eps - y / (eps * eps),
                2.0 / eps - 2.0 * y / (eps * eps),
            )
        };
        (self.mu_lambda_n * f0, f1_over_y, df1, u)
    }
}

/// Sliding speed below which friction holds like static friction (IPC's ε_v), m/s: cloth
/// under a tangential load smaller than μ N creeps at most this fast.
const FRICTION_EPS_M_S: f64 = 1e-3;

impl Simulator {
    /// The lagged friction of a step ([`FrictionPoint`]): one per free cloth vertex touching a
    /// body, all measured at the start of the step (cloth at `x_n`, bodies at their start
    /// positions): the normal force is the magnitude of the summed repulsion of its body
    /// contacts, ‖κ Σ (d̂ − d) ∇d‖, a crease contact's shared between its edge's two vertices
    /// by where along the edge it acts; the tangent plane and the body motion under the vertex
    /// are those of the face it is least deep under (nearest by |d|), or where it touches no
    /// face, of the first crease contact listed.
    pub(super) fn friction_points(
        &self,
        x_n: &[Vector3<f64>],
        contacts: &[Contact],
        motion: &BodyMotion<'_, '_>,
    ) -> Vec<FrictionPoint> {
        let mu = self.params.friction;
        if mu <= 0.0 {
            return Vec::new();
        }
        let p = &self.params.collision;
        struct Acc {
            d: f64,
            force: Vector3<f64>,
            n: Vector3<f64>,
            moved: Vector3<f64>,
        }
        let mut per: Vec<Option<Acc>> = (0..x_n.len()).map(|_| None).collect();
        for c in contacts {
            // A cloth edge against a crease: its repulsion, shared between the edge's two
            // vertices by where along the edge it acts, presses them against the crease (the
            // grip of an edge a sheet wraps over); a vertex with no face contact takes the
            // contact's direction as its normal and the crease's motion under it.
            if let Contact::EdgeObstacle { a, ends, .. } = c {
                let Some((e0, e1)) = motion.segment(ends) else {
                    continue;
                };
                let (i, j) = (a[0] as usize, a[1] as usize);
                let q = segment_segment(&x_n[i], &x_n[j], &e0[0], &e0[1]);
                if !(q.dist > 0.0 && q.dist < p.dhat_m) {
                    continue;
                }
                let on_cloth = x_n[i] + (x_n[j] - x_n[i]) * q.s;
                let on_crease = e0[0] + (e0[1] - e0[0]) * q.t;
                let Some(n) = (on_cloth - on_crease).try_normalize(1e-20) else {
                    continue;
                };
                let moved = (e1[0] - e0[0]) * (1.0 - q.t) + (e1[1] - e0[1]) * q.t;
                let force = p.kappa * (p.dhat_m - q.dist);
                for (k, w) in [(i, 1.0 - q.s), (j, q.s)] {
                    if !self.free[k] || w <= 0.0 {
                        continue;
                    }
                    let slot = per[k].get_or_insert(Acc {
                        d: f64::INFINITY,
                        force: Vector3::zeros(),
                        n,
                        moved,
                    });
                    slot.force += n * (force * w);
                }
                continue;
            }
            let Contact::VertexObstacle { v: i, face, .. } = c else {
                continue;
            };
            let (i, Some((t0, t1))) = (*i as usize, motion.triangle(face)) else {
                continue;
            };
            if !self.free[i] {
                continue;
            }
            // Distance and its gradient as the repulsion has them; the tangent plane is the
            // face's.
            let jet = vertex_obstacle_jet(&[x_n[i], t0[0], t0[1], t0[2]]);
            let d = jet.d;
            let Some(n) = (t0[1] - t0[0]).cross(&(t0[2] - t0[0])).try_normalize(1e-20) else {
                continue;
            };
            if d >= p.dhat_m {
                continue;
            }
            let push = jet.n * (p.kappa * (p.dhat_m - d));
            // p − q = Σ cᵢ xᵢ with c₀ = 1: the closest point's barycentric weights are −c₁..₃.
            let b = [-jet.coeffs[1], -jet.coeffs[2], -jet.coeffs[3]];
            let moved = (t1[0] - t0[0]) * b[0] + (t1[1] - t0[1]) * b[1] + (t1[2] - t0[2]) * b[2];
            let slot = per[i].get_or_insert(Acc {
                d: f64::INFINITY,
                force: Vector3::zeros(),
                n,
                moved,
            });
            slot.force += push;
            if d.abs() < slot.d.abs() {
                (slot.d, slot.n, slot.moved) = (d, n, moved);
            }
        }
        let eps_m = FRICTION_EPS_M_S * motion.dt_s * (motion.to - motion.from);
        per.iter()
            .enumerate()
            .filter_map(|(i, a)| {
                let a = a.as_ref()?;
                let force = a.force.norm();
                (force > 0.0).then(|| FrictionPoint {
                    v: i as u32,
                    mu_lambda_n: mu * force,
                    n: a.n,
                    anchor: x_n[i] + a.moved,
                    eps_m,
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::fd;
    use crate::step::ColliderFrame;
    use nalgebra::{SMatrix, SVector};

    fn point(eps_m: f64) -> FrictionPoint {
        FrictionPoint {
            v: 0,
            mu_lambda_n: 0.7,
            n: Vector3::new(0.2, 1.0, -0.3).normalize(),
            anchor: Vector3::new(0.01, -0.02, 0.005),
            eps_m,
        }
    }

    /// The friction potential's gradient matches finite differences where it is static-like
    /// (sliding below ε) and where it slides; its Hessian is the exact one (differences of the
    /// gradient) plus μλ (f₁/y − f₁′) ûûᵀ along the slide, and PSD; sliding, the force is μλ in
    /// the tangent plane against the slide.
    #[test]
    fn friction_derivatives_match_finite_differences() {
        let eps = 1e-3;
        let f = point(eps);
        let t1 = f.n.cross(&Vector3::x()).normalize();
        let t2 = f.n.cross(&t1);
        for slide in [0.3 * eps, 0.9 * eps, 4.0 * eps] {
            let x = f.anchor + (t1 * 0.8 + t2 * 0.6) * slide + f.n * 0.002;
            let to3 = |y: &SVector<f64, 3>| Vector3::new(y[0], y[1], y[2]);
            let x3 = SVector::<f64, 3>::from_column_slice(x.as_slice());
            let (_, g, h) = f.energy_gradient_hessian(&x);
            let g3 = SVector::<f64, 3>::from_column_slice(g.as_slice());
            fd::check_gradient(|y| f.energy(&to3(y)), &g3, &x3, 1e-7 * eps, 1e-6);
            fd::check_psd(&SMatrix::<f64, 3, 3>::from_column_slice(h.as_slice()));
            let (_, f1_over_y, df1, u) = f.eval(&x);
            let uhat = u.normalize();
            let extra = uhat * uhat.transpose() * (f.mu_lambda_n * (f1_over_y - df1));
            let exact = SMatrix::<f64, 3, 3>::from_column_slice((h - extra).as_slice());
            fd::check_hessian(
                |y| {
                    let g = f.energy_gradient_hessian(&to3(y)).1;
                    SVector::<f64, 3>::from_column_slice(g.as_slice())
                },
                &exact,
                &x3,
                1e-6 * eps,
                1e-5,
            );
            assert!(f1_over_y - df1 >= 0.0);
        }
        let x = f.anchor + t1 * (10.0 * eps) + f.n * 0.004;
        let g = f.energy_gradient_hessian(&x).1;
        assert!((g.norm() - f.mu_lambda_n).abs() < 1e-12);
        assert!(g.dot(&f.n).abs() < 1e-12 && g.dot(&t1) > 0.0);
        // At rest: 2μλ/ε across the whole tangent plane, nothing along the normal.
        let h = f.energy_gradient_hessian(&(f.anchor + f.n * 0.001)).2;
        assert!((t1.dot(&(h * t1)) - 2.0 * f.mu_lambda_n / eps).abs() < 1e-6 * h.norm());
        assert!((h * f.n).norm() < 1e-9 * h.norm());
    }

    /// A cloth edge across a crease of a moving box: the crease's repulsion grips the edge's
    /// two vertices, μ κ (d̂ − d) shared by where along the edge it acts (a quarter of the way:
    /// ¾ and ¼), normal to the crease's direction of contact, and they are anchored to the
    /// crease's own motion where the edge touches it (the box, second of two colliders, is
    /// stretched along the crease in the step: its far end moves 10 mm, the point touched, a
    /// quarter of the way along, 2.5 mm).
    #[test]
    fn a_crease_contact_grips_its_edges_vertices_moving_with_the_crease() {
        let scene = clothsr_geometry::scene::samples::sample("sheet_table").expect("sample");
        let sim = crate::driver::Simulation::new(&scene, 0.04, |_| {}).expect("setup");
        let s = &sim.sim;
        let p = s.params.collision;
        let mu = s.params.friction;
        assert!(mu > 0.0 && p.dhat_m < 0.01, "{mu} {}", p.dhat_m);
        let cube = clothsr_geometry::scene::Collider::cuboid(
            "box",
            Vector3::zeros(),
            Vector3::repeat(1.0),
        );
        let pts: Vec<Vector3<f64>> = cube.frames[0].iter().map(|p| p.cast::<f64>()).collect();
        let moved: Vec<Vector3<f64>> = pts
            .iter()
            .map(|q| q + Vector3::new(0.01 * q.x, 0.0, 0.0))
            .collect();
        let tris = cube.triangles;
        let far = clothsr_geometry::scene::Collider::cuboid(
            "far",
            Vector3::repeat(9.0),
            Vector3::repeat(10.0),
        );
        let far_pts: Vec<Vector3<f64>> = far.frames[0].iter().map(|p| p.cast::<f64>()).collect();
        // The crease y = z = 1 (along x); the closest point of the cloth edge a quarter of the
        // way from `a`, 0.3 d̂ out along (0, 1, 1)/√2; the edge runs along (0, 1, −1)/√2.
        let [a, b] = s.model.edges[0];
        let (a, b) = (a as usize, b as usize);
        let out = Vector3::new(0.0, 1.0, 1.0).normalize();
        let along = Vector3::new(0.0, 1.0, -1.0).normalize();
        let d = 0.3 * p.dhat_m;
        let c = Vector3::new(0.25, 1.0, 1.0) + out * d;
        let mut x_n = vec![Vector3::repeat(5.0); s.model.num_vertices()];
        x_n[a] = c - along * 0.025;
        x_n[b] = c + along * 0.075;
        let contacts = crate::collide::find_contacts(
            &x_n,
            &[],
            &[[a as u32, b as u32]],
            &[(&far_pts, &far.triangles), (&pts, &tris)],
            &p,
        );
        assert!(
            matches!(
                contacts[..],
                [Contact::EdgeObstacle {
                    ends: [1, _, _],
                    ..
                }]
            ),
            "{contacts:?}"
        );
        let frames = |q| {
            [
                ColliderFrame {
                    points: &far_pts,
                    triangles: &far.triangles,
                },
                ColliderFrame {
                    points: q,
                    triangles: &tris,
                },
            ]
        };
        let (start, end) = (frames(&pts), frames(&moved));
        let motion = BodyMotion {
            start: &start,
            end: &end,
            dt_s: 1.0 / 300.0,
            from: 0.0,
            to: 1.0,
        };
        let mut points = s.friction_points(&x_n, &contacts, &motion);
        points.sort_by_key(|f| f.v);
        assert_eq!(points.len(), 2, "{points:?}");
        let force = mu * p.kappa * (p.dhat_m - d);
        for f in &points {
            let w = if f.v as usize == a { 0.75 } else { 0.25 };
            assert!(
                (f.mu_lambda_n - force * w).abs() < 1e-9 * force,
                "vertex {}: {} against {}",
                f.v,
                f.mu_lambda_n,
                force * w
            );
            assert!((f.n - out).norm() < 1e-9, "{}", f.n);
            let want = x_n[f.v as usize] + Vector3::new(0.0025, 0.0, 0.0);
            assert!((f.anchor - want).norm() < 1e-12, "{} {want}", f.anchor);
        }
        // Without friction, no grip.
        let mut s = sim.sim;
        s.params.friction = 0.0;
        assert!(s.friction_points(&x_n, &contacts, &motion).is_empty());
    }
}
