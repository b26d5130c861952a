//! The damping potential's rows: gradients of the elastic conditions at the start of a step.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::friction::FrictionPoint;
use super::potential::{gather3, gather4};
use super::Simulator;
use crate::energy::bending;
use crate::energy::{Vec12, Vec9};

/// Gradients of the elastic conditions at the start of a step, for the damping potential.
#[derive(Debug, Clone, Default)]
pub(super) struct DampingRows {
    /// Per triangle: ∇C of weft, warp, shear and their coefficients β k A.
    pub(super) mem: Vec<([Vec9; 3], [f64; 3])>,
    /// Per hinge: ∇θ and β · 2w.
    pub(super) hinge: Vec<(Vec12, f64)>,
    /// Friction against bodies, lagged at the start of the step.
    pub(super) friction: Vec<FrictionPoint>,
}

impl Simulator {
    pub(super) fn damping_rows(&self, x: &[Vector3<f64>]) -> DampingRows {
        let m = &self.model;
        let mem = m
            .membranes
            .par_iter()
            .zip(m.membrane_k.par_iter().zip(m.membrane_damping_s.par_iter()))
            .map(|(el, (k, beta))| {
                let p = gather3(x, el.v);
                let (wu, wv) = el.stretch_vectors(&p);
                let (nu, nv) = (wu / wu.norm().max(1e-12), wv / wv.norm().max(1e-12));
                let mut rows = [Vec9::zeros(); 3];
                for i in 0..3 {
                    rows[0]
                        .fixed_rows_mut::<3>(3 * i)
                        .copy_from(&(nu * el.cu[i]));
                    rows[1]
                        .fixed_rows_mut::<3>(3 * i)
                        .copy_from(&(nv * el.cv[i]));
                    rows[2]
                        .fixed_rows_mut::<3>(3 * i)
                        .copy_from(&(wv * el.cu[i] + wu * el.cv[i]));
                }
                let c = beta * el.area_m2;
                (rows, [c * k.weft_n_m, c * k.warp_n_m, c * k.shear_n_m])
            })
            .collect();
        let hinge = m
            .hinges
            .par_iter()
            .zip(m.hinge_damping_s.par_iter())
            .map(|(hg, beta)| {
                let p = gather4(x, hg.v);
                let grad =
                    bending::dihedral_angle_gradient(&p).map_or_else(Vec12::zeros, |(_, g)| g);
                (grad, beta * 2.0 * hg.weight)
            })
            .collect();
        DampingRows {
            mem,
            hinge,
            friction: Vec::new(),
        }
    }
}
