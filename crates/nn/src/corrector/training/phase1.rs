//! Phase 1: one-step supervision on graph samples, with training noise and patches.

use std::ops::ControlFlow;

use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};
use nalgebra::Vector3;
use rand::Rng;
use rand_distr::{Distribution, Normal};

use super::{first_last, mean, step_rng, Progress, TrainSet, Trainer};
use crate::corrector::data::vectors;
use crate::corrector::graph::MeshGraph;
use crate::corrector::model::GraphTensors;
use crate::corrector::normalise::Normalisation;
use clothsr_geometry::error::{Error, Result};
use clothsr_io::data::flat32;

/// One graph sample, raw (unnormalised) inputs and targets plus a loss mask.
pub(super) struct Sample {
    pub(super) graph: MeshGraph,
    pub(super) nodes: Vec<f32>,
    pub(super) edges: Vec<f32>,
    /// The step's velocity change beyond gravity, m/s, `[n, 3]`.
    pub(super) step_change: Vec<f32>,
    pub(super) targets: Vec<f32>,
    pub(super) mask: Vec<f32>,
}

/// A batch of samples concatenated into one graph, normalised, on `device`.
pub(super) fn batch_tensors(
    samples: &[Sample],
    norm: &Normalisation,
    device: &Device,
) -> (GraphTensors, Tensor<2>, Tensor<2>, f32) {
    let (mut nodes, mut edges, mut targets, mut mask) = (vec![], vec![], vec![], vec![]);
    let (mut senders, mut receivers) = (vec![], vec![]);
    let mut step_change = vec![];
    let mut offset = 0u32;
    for s in samples {
        step_change.extend_from_slice(&s.step_change);
        nodes.extend_from_slice(&s.nodes);
        edges.extend_from_slice(&s.edges);
        targets.extend_from_slice(&s.targets);
        mask.extend_from_slice(&s.mask);
        senders.extend(s.graph.senders.iter().map(|i| i + offset));
        receivers.extend(s.graph.receivers.iter().map(|i| i + offset));
        offset += s.graph.num_nodes as u32;
    }
    norm.nodes.apply(&mut nodes);
    norm.edges.apply(&mut edges);
    norm.targets.apply(&mut targets);
    norm.targets.apply(&mut step_change);
    let n = offset as usize;
    let weight: f32 = mask.iter().sum::<f32>().max(1.0) * 3.0;
    (
        GraphTensors::new(nodes, edges, &senders, &receivers, step_change, device),
        Tensor::from_data(TensorData::new(targets, [n, 3]), device),
        Tensor::from_data(TensorData::new(mask, [n, 1]), device),
        weight,
    )
}

/// Masked L1 loss: Σ mask·|pred − target| / weight, `pred`/`target` `[N, 3]`, `mask` `[N, 1]`.
pub(super) fn l1(pred: Tensor<2>, target: Tensor<2>, mask: Tensor<2>, weight: f32) -> Tensor<1> {
    ((pred - target).abs() * mask).sum() / weight
}

impl Trainer<'_> {
    pub(super) fn sample(&mut self, sets: &[TrainSet]) -> Sample {
        let total: usize = sets.iter().map(|s| s.seq.steps.len()).sum();
        let mut pick = self.rng.random_range(0..total);
        let set = sets
            .iter()
            .find(|s| {
                if pick < s.seq.steps.len() {
                    true
                } else {
                    pick -= s.seq.steps.len();
                    false
                }
            })
            .unwrap_or(&sets[0]);
        let seq = &set.seq;
        let mut k = pick.min(seq.steps.len() - 1);
        // Only a data set's very first step has no Δq (its start is not stored): take the next.
        if seq.steps[k].dv.is_none() && k + 1 < seq.steps.len() {
            k += 1;
        }
        let st = &seq.steps[k];
        let h = seq.manifest.dt_s;
        let mut x = vectors(&st.coarse_x);
        let mut v = vectors(&st.coarse_v);
        let mut dv = st
            .dv
            .as_deref()
            .map_or_else(|| vec![Vector3::zeros(); x.len()], vectors);
        let x_int = vectors(&st.int_x);
        if self.noise_std_m > 0.0 {
            if let Ok(normal) = Normal::new(0.0, self.noise_std_m) {
                for ((x, v), dv) in x.iter_mut().zip(v.iter_mut()).zip(dv.iter_mut()) {
                    let d = Vector3::from_fn(|_, _| normal.sample(&mut self.rng));
                    *x += d;
                    *v += d / h;
                    *dv += d / h;
                }
            }
        }
        // p̄ = (x_int − x̃_c)/h; without noise this is v_int − v_c.
        let targets: Vec<Vector3<f64>> = x_int.iter().zip(&x).map(|(a, b)| (a - b) / h).collect();
        let n = seq.graph.num_nodes;
        let (graph, nodes_idx, mask) = if self.cfg.patch_nodes > 0 && self.cfg.patch_nodes < n {
            let centre = self.rng.random_range(0..n) as u32;
            let ball = seq.graph.ball(centre, usize::MAX, self.cfg.patch_nodes);
            let rim = ball.last().map_or(0, |b| b.1);
            let idx: Vec<u32> = ball.iter().map(|b| b.0).collect();
            let mask = ball
                .iter()
                .map(|b| if b.1 + 2 <= rim { 1.0 } else { 0.0 })
                .collect();
            (seq.graph.subgraph(&idx), idx, mask)
        } else {
            (seq.graph.clone(), (0..n as u32).collect(), vec![1.0; n])
        };
        let take = |a: &[Vector3<f64>]| -> Vec<Vector3<f64>> {
            nodes_idx.iter().map(|&i| a[i as usize]).collect()
        };
        let (xs, vs, dvs, ts) = (take(&x), take(&v), take(&dv), take(&targets));
        let body: Vec<f32> = nodes_idx.iter().map(|&i| st.body[i as usize]).collect();
        let (mut nodes, mut edges) = (Vec::new(), Vec::new());
        graph.node_features(&vs, &dvs, &body, &mut nodes);
        graph.edge_features(&xs, &vs, &mut edges);
        Sample {
            graph,
            nodes,
            edges,
            step_change: flat32(&dvs),
            targets: flat32(&ts),
            mask,
        }
    }

    pub(super) fn phase1(
        &mut self,
        sets: &[TrainSet],
        progress: &mut impl FnMut(&Progress) -> ControlFlow<()>,
    ) -> Result<(f64, f64)> {
        let cfg = self.cfg;
        let mut losses = Vec::new();
        let mut window = Vec::new();
        while self.position.phase1_done < cfg.steps {
            let step = self.position.phase1_done;
            self.rng = step_rng(cfg.seed, 1, step);
            let lr = cfg.lr_start
                * (cfg.lr_end / cfg.lr_start).powf(step as f64 / cfg.steps.max(1) as f64);
            let samples: Vec<Sample> = (0..cfg.batch).map(|_| self.sample(sets)).collect();
            let (g, target, mask, weight) = batch_tensors(&samples, &self.norm, &self.device);
            let pred = self.net.forward(&g);
            let loss = l1(pred, target, mask, weight);
            let value = f64::from(loss.clone().into_scalar::<f32>());
            if !value.is_finite() {
                return Err(Error::Simulation(format!(
                    "corrector training diverged at phase-1 step {step} (loss {value})"
                )));
            }
            let grads = GradientsParams::from_grads(loss.backward(), &self.net);
            self.net = self.optim.step(lr, self.net.clone(), grads);
            self.position.phase1_done += 1;
            losses.push(value);
            window.push(value);
            if window.len() == 25 || self.position.phase1_done == cfg.steps {
                self.log(1, self.position.phase1_done, lr, mean(&window))?;
                window.clear();
            }
            if self
                .position
                .phase1_done
                .is_multiple_of(cfg.checkpoint_every.max(1))
            {
                self.checkpoint()?;
            }
            let flow = progress(&Progress {
                phase: 1,
                step: self.position.phase1_done,
                total: cfg.steps,
                loss: value,
            });
            if flow.is_break() {
                self.checkpoint()?;
                self.stopped = true;
                break;
            }
        }
        Ok(first_last(&losses, 50))
    }
}
