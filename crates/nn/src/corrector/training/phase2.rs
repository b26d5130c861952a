//! Phase 2: window rollout training from ground-truth states.

use std::ops::ControlFlow;

use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};
use nalgebra::Vector3;
use rand::Rng;

use super::config::TrainingConfig;
use super::validation::ValidationSet;
use super::{first_last, mean, step_rng, Progress, TrainSet, Trainer};
use crate::corrector::data::vectors;
use crate::corrector::graph::{body_proximity, step_change};
use crate::corrector::inference::features;
use crate::corrector::model::{CorrectorNet, GraphTensors};
use crate::corrector::normalise::Normalisation;
use clothsr_geometry::error::{Error, Result};
use clothsr_io::data::flat32;

impl Trainer<'_> {
    pub(super) fn phase2(
        &mut self,
        sets: &mut [TrainSet],
        validation: &[ValidationSet],
        progress: &mut impl FnMut(&Progress) -> ControlFlow<()>,
    ) -> Result<((f64, f64), usize)> {
        let cfg = self.cfg;
        let usable: Vec<usize> = (0..sets.len())
            .filter(|&k| sets[k].sim.is_some() && sets[k].seq.steps.len() > cfg.window)
            .collect();
        let mut losses = Vec::new();
        while self.position.phase2_done < cfg.rollout_iters && !usable.is_empty() {
            self.rng = step_rng(cfg.seed, 2, self.position.phase2_done);
            let k = usable[self.rng.random_range(0..usable.len())];
            let set = &mut sets[k];
            let start = self.rng.random_range(0..set.seq.steps.len() - cfg.window);
            let value = rollout_window(
                &mut self.net,
                &mut self.optim,
                &self.norm,
                set,
                start,
                cfg,
                &self.device,
            )?;
            self.position.phase2_done += 1;
            losses.push(value);
            let it = self.position.phase2_done;
            if it.is_multiple_of(10) || it == cfg.rollout_iters {
                let recent = mean(&losses[losses.len().saturating_sub(10)..]);
                self.log(2, it, cfg.rollout_lr, recent)?;
            }
            if it.is_multiple_of(cfg.checkpoint_every.max(1).div_ceil(10)) {
                self.checkpoint()?;
            }
            if cfg
                .validate_every
                .is_some_and(|k| it.is_multiple_of(k.max(1)) || it == cfg.rollout_iters)
            {
                self.validate(validation, 2, it)?;
            }
            let flow = progress(&Progress {
                phase: 2,
                step: it,
                total: cfg.rollout_iters,
                loss: value,
            });
            if flow.is_break() {
                self.checkpoint()?;
                self.stopped = true;
                break;
            }
            if cfg.rollout_stop_loss > 0.0
                && losses.len() >= 20
                && mean(&losses[losses.len() - 20..]) < cfg.rollout_stop_loss
            {
                tracing::info!(
                    "phase 2: window loss below {} after {it} windows",
                    cfg.rollout_stop_loss
                );
                if cfg.validate_every.is_some() {
                    self.validate(validation, 2, it)?;
                }
                break;
            }
        }
        Ok((first_last(&losses, 20), losses.len()))
    }
}

/// The phase-2 target p̄ = Δv + (Δx − hΔv)/τ ([`TrainingConfig::rollout_tau_steps`]) per
/// vertex, from the ground truth (`x_gt`, `v_gt`) and the coarse step (`x_c`, `v_c`).
pub fn pull_back_target(
    x_gt: &[Vector3<f64>],
    v_gt: &[Vector3<f64>],
    x_c: &[Vector3<f64>],
    v_c: &[Vector3<f64>],
    h: f64,
    tau_steps: f64,
) -> Vec<Vector3<f64>> {
    x_gt.iter()
        .zip(v_gt)
        .zip(x_c.iter().zip(v_c))
        .map(|((xg, vg), (xc, vc))| {
            let dv = vg - vc;
            dv + (xg - xc - dv * h) / (tau_steps * h)
        })
        .collect()
}

/// One phase-2 update: rolls out `cfg.window` interleaved steps from the ground-truth M_int
/// at `set.seq.steps[start]`, and steps the optimiser on the mean window loss.
pub(super) fn rollout_window(
    net: &mut CorrectorNet,
    optim: &mut burn::optim::ModuleOptimizer,
    norm: &Normalisation,
    set: &mut TrainSet,
    start: usize,
    cfg: &TrainingConfig,
    device: &Device,
) -> Result<f64> {
    let (window, lr) = (cfg.window, cfg.rollout_lr);
    let seq = &set.seq;
    let Some((sim, t0)) = set.sim.as_mut() else {
        return Err(Error::Invalid("phase 2 needs a coarse simulator".into()));
    };
    // Each window steps as a new simulator started at its first state would: without the
    // caches, warm starts and adapted margin of the window before, so that a resumed training
    // rolls its windows out as one that never stopped.
    sim.sim.forget_history();
    let margin = sim.sim.params.detection_margin_m;
    sim.sim.set_obstacle_margin_m(margin);
    let h = seq.manifest.dt_s;
    let mut state = seq.int_state(start, *t0);
    let mut total: Option<Tensor<1>> = None;
    let n = seq.graph.num_nodes;
    for w in 1..=window {
        let (mut c, _) = sim.step_from(&state)?;
        let gt = &seq.steps[start + w];
        let target: Vec<f32> = flat32(&pull_back_target(
            &vectors(&gt.int_x),
            &vectors(&gt.int_v),
            &c.x,
            &c.v,
            h,
            cfg.rollout_tau_steps,
        ));
        let body = body_proximity(&c.x, &sim.colliders, c.t_s);
        let dv = step_change(&c.v, &state.v, sim.sim.params.gravity_m_s2 * h);
        let (nodes, edges) = features(&seq.graph, &c.x, &c.v, &dv, &body, norm);
        let mut step_change = flat32(&dv);
        norm.targets.apply(&mut step_change);
        let g = GraphTensors::of(&seq.graph, nodes, edges, step_change, device);
        let pred = net.forward(&g); // [n, 3], normalised
        let mut p: Vec<f32> = pred
            .clone()
            .into_data()
            .try_to_vec::<f32>()
            .map_err(|e| Error::Invalid(format!("corrector output: {e:?}")))?;
        norm.targets.invert(&mut p);
        let mut t = target;
        norm.targets.apply(&mut t);
        let target = Tensor::<2>::from_data(TensorData::new(t, [n, 3]), device);
        let loss = (pred - target).abs().mean();
        total = Some(match total {
            None => loss,
            Some(acc) => acc + loss,
        });
        let p = vectors(&p);
        for ((x, v), p) in c.x.iter_mut().zip(c.v.iter_mut()).zip(&p) {
            *v += p;
            *x += p * h;
        }
        state = c;
    }
    let Some(total) = total else {
        return Ok(0.0);
    };
    let loss = total / window as f32;
    let value = f64::from(loss.clone().into_scalar::<f32>());
    if !value.is_finite() {
        return Err(Error::Simulation(format!(
            "corrector rollout training diverged (loss {value})"
        )));
    }
    let grads = GradientsParams::from_grads(loss.backward(), &*net);
    *net = optim.step(lr, net.clone(), grads);
    Ok(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pull_back_target_lands_in_one_step_at_tau_one_and_shrinks_the_gap_by_one_over_tau() {
        let h = 1.0 / 300.0;
        let x_prev = [Vector3::new(0.1, 0.2, 0.3), Vector3::new(-0.4, 0.0, 0.25)];
        let v_gt = [Vector3::new(0.5, -1.0, 0.2), Vector3::new(0.0, 0.3, -0.7)];
        let v_c = [Vector3::new(0.45, -0.9, 0.1), Vector3::new(0.05, 0.2, -0.6)];
        let step = |v: &[Vector3<f64>; 2]| -> Vec<Vector3<f64>> {
            x_prev.iter().zip(v).map(|(x, v)| x + v * h).collect()
        };
        // From a ground-truth state (both steps start at x_prev) every τ gives Δv.
        let (x_gt, x_c) = (step(&v_gt), step(&v_c));
        for tau in [1.0, 4.0, 30.0] {
            let p = pull_back_target(&x_gt, &v_gt, &x_c, &v_c, h, tau);
            for i in 0..2 {
                assert!((p[i] - (v_gt[i] - v_c[i])).norm() < 1e-9, "τ {tau}");
            }
        }
        // A drifted coarse state: 2 mm off. τ = 1 lands on x_gt (p = Δx/h); τ = 4 keeps ¾ of
        // the gap left after matching the velocity, and the velocity is v_gt plus the pull.
        let drift = Vector3::new(0.002, 0.0, -0.001);
        let x_c: Vec<_> = x_c.iter().map(|x| x + drift).collect();
        let p1 = pull_back_target(&x_gt, &v_gt, &x_c, &v_c, h, 1.0);
        let p4 = pull_back_target(&x_gt, &v_gt, &x_c, &v_c, h, 4.0);
        for i in 0..2 {
            assert!((x_c[i] + p1[i] * h - x_gt[i]).norm() < 1e-12);
            let gap = x_c[i] + p4[i] * h - x_gt[i];
            assert!((gap - drift * 0.75).norm() < 1e-12);
            let v = v_c[i] + p4[i];
            assert!((v - (v_gt[i] - drift / (4.0 * h))).norm() < 1e-9);
        }
    }
}
