//! Phase 2: window rollout training, from ground-truth or drift states.

use std::ops::ControlFlow;
use std::time::Instant;

use burn::module::Module;
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};
use nalgebra::Vector3;
use rand::Rng;

use super::checkpoint::WeightAverage;
use super::config::{TrainingConfig, DEFAULT_DRIFT_REFRESH, DEFAULT_DRIFT_TAU_STEPS};
use super::validation::ValidationSet;
use super::{first_last, mean, Progress, TrainSet, Trainer};
use crate::common::default_device;
use crate::corrector::data::vectors;
use crate::corrector::graph::{body_proximity, step_change};
use crate::corrector::inference::{features, take_back_weights, Corrector};
use crate::corrector::model::{CorrectorNet, GraphTensors};
use crate::corrector::normalise::Normalisation;
use crate::corrector::rollout::interleaved_run;
use crate::data::flat32;
use crate::error::{Error, Result};
use crate::metrics::mean_distance_mm;
use crate::sim::SimState;

impl Trainer<'_> {
    /// Rolls the current network out as at inference over every training set with a coarse
    /// simulator ([`interleaved_run`], on a copy of its pristine simulation), keeping its
    /// corrected states for drift windows ([`TrainingConfig::drift_share`]); only when none
    /// were made yet or [`TrainingConfig::drift_refresh`] drift windows ran since. A run that
    /// diverged keeps its states up to a window before the divergence.
    pub(super) fn refresh_drift(&mut self, sets: &[TrainSet]) -> Result<()> {
        let every = self.cfg.drift_refresh.unwrap_or(DEFAULT_DRIFT_REFRESH);
        if !self.drift.is_empty() && self.drift_used < every {
            return Ok(());
        }
        let done = self.position.phase2_done;
        let t = Instant::now();
        let device = default_device()?;
        let net = self.net.valid();
        let mut drift = Vec::with_capacity(sets.len());
        let (mut figures, mut total_gap, mut steps) = (Vec::new(), 0.0, 0usize);
        for (set, pristine) in sets.iter().zip(&self.pristine) {
            let seq = &set.seq;
            let usable = pristine.as_ref().filter(|_| !seq.steps.is_empty());
            let (Some((_, t0)), Some(pristine)) = (&set.sim, usable) else {
                drift.push(Vec::new());
                continue;
            };
            let mut sim = pristine.clone();
            let corrector = Corrector::new(
                net.clone(),
                self.norm.clone(),
                self.cfg.clone(),
                &seq.mesh,
                &self.out,
                &device,
            );
            let mut states = vec![seq.int_state(0, *t0)];
            let mut gap = 0.0;
            let whole = interleaved_run(seq, &mut sim, *t0, &corrector, usize::MAX, |i, state| {
                gap += mean_distance_mm(&state.x, &vectors(&seq.steps[i].int_x));
                states.push(state.clone());
            })?;
            let run = states.len() - 1;
            figures.push(format!(
                "{run} steps{}, {:.2} mm from M_int on average",
                if whole { "" } else { " (diverged there)" },
                gap / run.max(1) as f64
            ));
            total_gap += gap;
            steps += run;
            if !whole {
                // The states just before a divergence would start windows that diverge.
                states.truncate(states.len().saturating_sub(self.cfg.window).max(1));
            }
            drift.push(states);
        }
        self.drift_runs
            .push((done, total_gap / steps.max(1) as f64));
        tracing::info!(
            "phase 2 window {done}: interleaved runs for drift windows: {} ({:.0} s)",
            figures.join("; "),
            t.elapsed().as_secs_f64()
        );
        self.drift = drift;
        self.drift_used = 0;
        Ok(())
    }

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
        if cfg.drift_share.is_some() {
            self.pristine = sets
                .iter()
                .map(|s| s.sim.as_ref().map(|(sim, _)| sim.clone()))
                .collect();
        }
        let mut losses = Vec::new();
        while self.position.phase2_done < cfg.rollout_iters && !usable.is_empty() {
            let k = usable[self.rng.random_range(0..usable.len())];
            // Only a drift run draws this number: runs without it keep their windows.
            let drift = cfg
                .drift_share
                .is_some_and(|share| self.rng.random::<f64>() < share);
            if drift {
                self.refresh_drift(sets)?;
            }
            let set = &mut sets[k];
            // The last step a drift window can start at: step 0 is the ground truth itself, a
            // diverged run offers the steps before it, and the window must end in the data.
            let last = (self.drift.get(k).map_or(0, Vec::len).saturating_sub(1))
                .min(set.seq.steps.len() - 1 - cfg.window);
            let (start, from) = match drift {
                true if last >= 1 => {
                    self.drift_used += 1;
                    let start = self.rng.random_range(1..=last);
                    let tau = cfg.drift_tau_steps.unwrap_or(DEFAULT_DRIFT_TAU_STEPS);
                    (start, Some((&self.drift[k][start], tau)))
                }
                _ => (
                    self.rng.random_range(0..set.seq.steps.len() - cfg.window),
                    None,
                ),
            };
            let value = rollout_window(
                &mut self.net,
                &mut self.optim,
                &self.norm,
                set,
                start,
                from,
                cfg,
                &self.device,
            )?;
            self.position.phase2_done += 1;
            losses.push(value);
            let it = self.position.phase2_done;
            if cfg.average_from.is_some_and(|k| it > k) {
                self.average
                    .get_or_insert_with(WeightAverage::default)
                    .add(&self.net);
            }
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
/// at `set.seq.steps[start]`, or from `from`'s state at that step with its pull-back time
/// (a drift window: [`TrainingConfig::drift_share`]), and steps the optimiser on the mean
/// window loss.
#[allow(clippy::too_many_arguments)]
pub(super) fn rollout_window(
    net: &mut CorrectorNet,
    optim: &mut burn::optim::ModuleOptimizer,
    norm: &Normalisation,
    set: &mut TrainSet,
    start: usize,
    from: Option<(&SimState, f64)>,
    cfg: &TrainingConfig,
    device: &Device,
) -> Result<f64> {
    let (window, lr) = (cfg.window, cfg.rollout_lr);
    let seq = &set.seq;
    let Some((sim, t0)) = set.sim.as_mut() else {
        return Err(Error::Invalid("phase 2 needs a coarse simulator".into()));
    };
    let h = seq.manifest.dt_s;
    let (mut state, tau_steps) = match from {
        Some((state, tau)) => (state.clone(), tau),
        None => (
            seq.int_state(start, *t0),
            cfg.rollout_tau_steps.unwrap_or(1.0),
        ),
    };
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
            tau_steps,
        ));
        let body = body_proximity(&c.x, &sim.colliders, c.t_s);
        let dv = step_change(&c.v, &state.v, sim.sim.params.gravity_m_s2 * h);
        let (nodes, edges) = features(&seq.graph, &c.x, &c.v, &dv, &body, norm);
        let mut step_change = flat32(&dv);
        norm.targets.apply(&mut step_change);
        let gate = cfg
            .rollout_as_inference
            .unwrap_or(false)
            .then(|| take_back_weights(&cfg.model, &seq.graph, &c.x))
            .flatten();
        let g = GraphTensors::of(&seq.graph, nodes, edges, step_change, device).with_tension(gate);
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
        let mut p = vectors(&p);
        if cfg.rollout_as_inference.unwrap_or(false) {
            seq.graph.smooth(&mut p, cfg.model.smoothing.unwrap_or(0));
        }
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
    use crate::common::default_device;
    use crate::corrector::data::Sequence;
    use crate::corrector::training::fit_normalisation;
    use crate::corrector::CorrectorConfig;
    use crate::data::{coarse_simulation, generate, Options, Variation};
    use crate::scene::samples::flat_sheet;
    use crate::scene::Collider;
    use crate::scene::Scene;
    use burn::optim::AdamConfig;
    use clothsr_geometry::garment::Fabric;
    use std::path::Path;

    /// A one-frame data set of a silk sheet dropped on a ball (40 mm / 15 mm) and its
    /// training set with a fresh coarse simulation.
    fn tiny_set(dir: &Path) -> TrainSet {
        let mut scene = Scene {
            garments: vec![flat_sheet(
                "sheet",
                0.3,
                0.3,
                Vector3::new(0.0, 0.17, 0.0),
                Fabric::preset("silk").expect("preset"),
            )],
            ..Scene::default()
        };
        scene
            .colliders
            .push(Collider::sphere("ball", Vector3::zeros(), 0.15, 3));
        if !dir.join("manifest.json").exists() {
            let opts = Options {
                coarse_edge_m: 0.04,
                fine_edge_m: 0.015,
                frames: 1,
                dress: false,
                self_collision: false,
                variation: Variation::default(),
                fast: true,
                match_contact_thickness: true,
                source: None,
            };
            generate(&scene, "test", &opts, dir, |_| {}).expect("generate");
        }
        let sim = coarse_simulation(&scene, dir, 1).expect("coarse simulation");
        let t0 = sim.state.t_s;
        let seq = Sequence::load(dir, None, &sim).expect("load");
        TrainSet {
            seq,
            sim: Some((sim, t0)),
        }
    }

    #[test]
    fn a_drift_window_from_the_ground_truth_is_a_ground_truth_window_and_its_state_counts() {
        let dir = tempfile::tempdir().expect("tmp");
        let cfg = TrainingConfig::new(CorrectorConfig::new().with_latent(8).with_steps(1))
            .with_window(3)
            .with_rollout_lr(1e-3);
        let norm = fit_normalisation(&[tiny_set(dir.path())]);
        let device = default_device().expect("device").autodiff();
        device.seed(3);
        let net = cfg.model.init(&device);
        let start = 2;
        // One window from a fresh simulation and optimiser, with the same initial network.
        let window = |from: Option<(&SimState, f64)>| -> f64 {
            let mut set = tiny_set(dir.path());
            let mut optim = AdamConfig::new().init();
            rollout_window(
                &mut net.clone(),
                &mut optim,
                &norm,
                &mut set,
                start,
                from,
                &cfg,
                &device,
            )
            .expect("window")
        };
        let set = tiny_set(dir.path());
        let t0 = set.sim.as_ref().map_or(0.0, |s| s.1);
        let gt = set.seq.int_state(start, t0);
        let plain = window(None);
        assert!(plain.is_finite() && plain > 0.0, "{plain}");
        // The ground truth's own state with τ = 1 is the ground-truth window.
        assert_eq!(window(Some((&gt, 1.0))), plain);
        // A state 1 mm off it starts another window, and τ reaches the targets.
        let mut off = gt.clone();
        for x in &mut off.x {
            x.x += 1e-3;
        }
        let drifted = window(Some((&off, 1.0)));
        assert!((drifted - plain).abs() > 1e-3 * plain, "{drifted} {plain}");
        let slow = window(Some((&off, 10.0)));
        assert!((slow - drifted).abs() > 1e-3 * drifted, "{slow} {drifted}");
    }

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
