//! The incremental potential and its assembly into gradient and Hessian.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use super::damping::DampingRows;
use super::Simulator;
use crate::collide::Contact;
use crate::energy::bending;
use crate::energy::{sewing, Mat12, Vec12, Vec9};
use crate::reduce;
use crate::scatter::for_each_vertex;

pub(super) fn gather3(x: &[Vector3<f64>], v: [u32; 3]) -> [Vector3<f64>; 3] {
    v.map(|i| x[i as usize])
}

pub(super) fn gather4(x: &[Vector3<f64>], v: [u32; 4]) -> [Vector3<f64>; 4] {
    v.map(|i| x[i as usize])
}

fn stack<const N: usize, const M: usize>(p: &[Vector3<f64>; N]) -> nalgebra::SVector<f64, M> {
    let mut out = nalgebra::SVector::<f64, M>::zeros();
    for (i, q) in p.iter().enumerate() {
        out.fixed_rows_mut::<3>(3 * i).copy_from(q);
    }
    out
}

impl Simulator {
    /// Total incremental potential at `x` with a fixed contact set.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn potential(
        &self,
        x: &[Vector3<f64>],
        x_n: &[Vector3<f64>],
        x_tilde: &[Vector3<f64>],
        h: f64,
        damping: &DampingRows,
        contacts: &[Contact],
    ) -> f64 {
        let m = &self.model;
        let air = self.params.air_damping_per_s * h;
        // Every sum in fixed chunks (reduce::sum): the Armijo test compares these energies,
        // and their bits must not depend on the thread count.
        let inertia: f64 = reduce::sum(x.len(), |i| {
            0.5 * m.mass_kg[i]
                * ((x[i] - x_tilde[i]).norm_squared() + air * (x[i] - x_n[i]).norm_squared())
        }) / (h * h);
        let elastic = m.elastic_energy(x);
        let damp_mem: f64 = reduce::sum(m.membranes.len(), |k| {
            let (el, (rows, c)) = (&m.membranes[k], &damping.mem[k]);
            let d: Vec9 = stack(&gather3(x, el.v)) - stack::<3, 9>(&gather3(x_n, el.v));
            (0..3).map(|q| c[q] * rows[q].dot(&d).powi(2)).sum::<f64>()
        });
        let damp_hinge: f64 = reduce::sum(m.hinges.len(), |k| {
            let (hg, (row, c)) = (&m.hinges[k], &damping.hinge[k]);
            let d: Vec12 = stack(&gather4(x, hg.v)) - stack::<4, 12>(&gather4(x_n, hg.v));
            c * row.dot(&d).powi(2)
        });
        let sew: f64 = m
            .mesh
            .seam_pairs
            .iter()
            .enumerate()
            .map(|(k, p)| {
                sewing::energy(
                    self.params.sew_stiffness_n_m,
                    self.seam_rest_m(k),
                    &x[p[0] as usize],
                    &x[p[1] as usize],
                )
            })
            .sum();
        let contact: f64 = reduce::sum(contacts.len(), |k| {
            contacts[k].energy(x, &self.params.collision)
        });
        let friction: f64 = reduce::sum(damping.friction.len(), |k| {
            let f = &damping.friction[k];
            f.energy(&x[f.v as usize])
        });
        inertia + elastic + (damp_mem + damp_hinge) / (2.0 * h) + sew + contact + friction
    }

    /// Assembles gradient and Hessian at `x`; returns the potential.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn assemble(
        &mut self,
        x: &[Vector3<f64>],
        x_n: &[Vector3<f64>],
        x_tilde: &[Vector3<f64>],
        h: f64,
        damping: &DampingRows,
        contacts: &[Contact],
    ) -> f64 {
        let inv_h2 = 1.0 / (h * h);
        let mode = self.params.bending_hessian;
        let model = &self.model;
        let contact_local: Vec<(f64, Vec12, Mat12)> = contacts
            .par_iter()
            .map(|c| c.energy_gradient_hessian(x, &self.params.collision))
            .collect();

        self.matrix.clear();
        // Inertia plus air damping ½ (α/h) m ‖x − xₙ‖² = ½ h⁻² (αh) m ‖x − xₙ‖².
        let air = self.params.air_damping_per_s * h;
        let mut energy = for_each_vertex(&mut self.matrix, &mut self.grad, |i, g, d| {
            let m = model.mass_kg[i];
            let (a, b) = (x[i] - x_tilde[i], x[i] - x_n[i]);
            *g = (a + b * air) * (m * inv_h2);
            *d += Matrix3::identity() * (m * inv_h2 * (1.0 + air));
            0.5 * m * inv_h2 * (a.norm_squared() + air * b.norm_squared())
        });
        // Elements by colour: those of one colour share no vertex, so their blocks are disjoint.
        energy += self.mem_set.add(&mut self.matrix, &mut self.grad, |k| {
            let el = &model.membranes[k];
            let (rows, c) = &damping.mem[k];
            let p = gather3(x, el.v);
            let (mut e, mut g, mut hm) = el.energy_gradient_hessian(&model.membrane_k[k], &p);
            let d: Vec9 = stack(&p) - stack::<3, 9>(&gather3(x_n, el.v));
            for q in 0..3 {
                let s = rows[q].dot(&d);
                e += c[q] * s * s / (2.0 * h);
                g.axpy(c[q] * s / h, &rows[q], 1.0);
                hm.ger(c[q] / h, &rows[q], &rows[q], 1.0);
            }
            (e, g, hm)
        });
        energy += self.hinge_set.add(&mut self.matrix, &mut self.grad, |k| {
            let hg = &model.hinges[k];
            let (row, c) = &damping.hinge[k];
            let p = gather4(x, hg.v);
            let (mut e, mut g, mut hm) = bending::energy_gradient_hessian(hg, &p, mode);
            let d: Vec12 = stack(&p) - stack::<4, 12>(&gather4(x_n, hg.v));
            let s = row.dot(&d);
            e += c * s * s / (2.0 * h);
            g.axpy(c * s / h, row, 1.0);
            hm.ger(c / h, row, row, 1.0);
            (e, g, hm)
        });
        let k_sew = self.params.sew_stiffness_n_m;
        for (k, p) in model.mesh.seam_pairs.iter().enumerate() {
            let (i, j) = (p[0], p[1]);
            let rest = self.seam_rest_m(k);
            energy += sewing::energy(k_sew, rest, &x[i as usize], &x[j as usize]);
            let (g, hm) = sewing::gradient_hessian(k_sew, rest, &x[i as usize], &x[j as usize]);
            self.grad[i as usize] += g.fixed_rows::<3>(0);
            self.grad[j as usize] += g.fixed_rows::<3>(3);
            for (a, va) in [i, j].iter().enumerate() {
                for (b, vb) in [i, j].iter().enumerate() {
                    self.matrix
                        .add(*va, *vb, &hm.fixed_view::<3, 3>(3 * a, 3 * b).into_owned());
                }
            }
        }
        for (c, (e, g, hm)) in contacts.iter().zip(&contact_local) {
            // Candidates beyond d̂ (found within the detection margin) add nothing.
            if *e == 0.0 && g.iter().all(|v| *v == 0.0) {
                continue;
            }
            energy += e;
            let dofs = c.cloth_dofs();
            for (a, va) in dofs.iter().enumerate() {
                let Some(va) = va else { continue };
                self.grad[*va as usize] += g.fixed_rows::<3>(3 * a);
                for (b, vb) in dofs.iter().enumerate() {
                    if let Some(vb) = vb {
                        self.matrix.add(
                            *va,
                            *vb,
                            &hm.fixed_view::<3, 3>(3 * a, 3 * b).into_owned(),
                        );
                    }
                }
            }
        }
        for f in &damping.friction {
            let i = f.v as usize;
            let (e, g, hm) = f.energy_gradient_hessian(&x[i]);
            energy += e;
            self.grad[i] += g;
            self.matrix.add(f.v, f.v, &hm);
        }
        self.fold_welds();
        for (gi, f) in self.grad.iter_mut().zip(&self.free) {
            if !f {
                *gi = Vector3::zeros();
            }
        }
        energy
    }

    /// Rest length of seam pair `k` in the step being solved.
    fn seam_rest_m(&self, k: usize) -> f64 {
        self.seam_rest_step_m[k]
    }
}
