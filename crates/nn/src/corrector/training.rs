//! Training the corrector (the paper's §3.3.2, §3.3.4).
//!
//! * **Phase 1**, one-step supervision: L = |p − p̄| (normalised units, mean over vertices and
//!   components) with Adam and an exponential learning-rate decay from `lr_start` to `lr_end`
//!   over `steps`. GNS-style training noise (Sanchez-Gonzalez et al. 2020): M_c's positions are
//!   perturbed by δ ~ N(0, σ²), its velocities by δ/h (as if the step had ended there) and the
//!   target becomes the correction that still lands on M_int. Optional random overlapping
//!   sub-mesh patches (breadth-first balls of `patch_nodes` vertices; the loss skips each
//!   patch's two outer rings, whose neighbourhoods are cut).
//! * **Phase 2**, window rollout training (Kim et al. 2019): from a random ground-truth M_int
//!   roll out `window` steps of the real coarse simulator interleaved with the corrector; the
//!   loss is the mean over the window of |p_i − p̄_i|, with p̄_i = (x_int,i − x_c,i)/h the
//!   correction that brings the rollout back onto the ground truth. Gradients flow through the
//!   network at every step (the simulator's output is data).
//!
//! * Beyond the paper: a warm start from a trained corrector ([`TrainingConfig::init_from`]),
//!   an average of the phase-2 weights ([`TrainingConfig::average_from`]), phase-2 windows
//!   rolled out as at inference ([`TrainingConfig::rollout_as_inference`]) and phase 1
//!   distilling a trained corrector ([`TrainingConfig::distil_from`]).
//!
//! The output directory holds `config.json`, `normalisation.json`, `model.bpk`, `log.csv`
//! (phase, step, learning rate, loss, elapsed seconds) and, while training, `checkpoint/`
//! (weights, optimiser state, position), from which an interrupted run resumes.

use std::io::Write;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::config::Config;
use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use super::data::{vectors, Sequence};
use super::graph::{body_proximity, step_change, MeshGraph};
use super::inference::{
    features, load_net, read_json, take_back_weights, Corrector, CONFIG_FILE, NORMALISATION_FILE,
    WEIGHTS_FILE,
};
use super::model::{inverse_masses, CorrectorConfig, CorrectorNet, GraphTensors};
use super::normalise::{Normalisation, NormalisationBuilder};
use super::rollout::{interleaved_errors, interleaved_run};
use crate::common::{default_device, write_json};
use crate::data::flat32;
use crate::error::{Error, Result};
use crate::metrics::mean_distance_mm;
use crate::scene::Scene;
use crate::sim::coarse::{check_friction, crease_label};
use crate::sim::driver::Simulation;
use crate::sim::SimState;
use crate::sim::WrinkleBending;

/// How to train (saved as `config.json`, with the network's sizes).
#[derive(Config, Debug, PartialEq)]
pub struct TrainingConfig {
    /// The network.
    pub model: CorrectorConfig,
    /// Phase-1 optimiser steps (the paper: 400K on a GPU).
    #[config(default = 5000)]
    pub steps: usize,
    /// Samples (whole meshes or patches) per step.
    #[config(default = 4)]
    pub batch: usize,
    /// Learning rate at the first step.
    #[config(default = 1e-4)]
    pub lr_start: f64,
    /// Learning rate at the last phase-1 step (exponential decay).
    #[config(default = 1e-6)]
    pub lr_end: f64,
    /// Training-noise standard deviation as a multiple of the data's RMS per-step position
    /// correction h·|p̄| (0: no noise, the default: noise teaches the corrector to take back
    /// deviations in one step, which interleaved with the simulator feeds back).
    #[config(default = 0.0)]
    pub noise_ratio: f64,
    /// Vertices per random sub-mesh patch (0: whole meshes).
    #[config(default = 0)]
    pub patch_nodes: usize,
    /// Phase-2 (window rollout) optimiser steps; 0 skips phase 2.
    #[config(default = 0)]
    pub rollout_iters: usize,
    /// Phase-2 window ω, simulator steps.
    #[config(default = 8)]
    pub window: usize,
    /// Phase-2 learning rate.
    #[config(default = 1e-5)]
    pub rollout_lr: f64,
    /// Phase-2 target's pull-back time τ, in simulator steps (`None`: 1). The target is
    /// p̄ = Δv + (Δx − hΔv)/τ with Δx = x_int − x_c and Δv = v_int − v_c: the ground truth's
    /// velocity plus a pull towards its positions over τ steps. With τ = 1 it is Δx/h, which
    /// lands the step on M_int but leaves a drifted rollout's whole position gap in the
    /// velocity, to be overshot at the next step. From a ground-truth state (phase 1) Δx = hΔv
    /// and every τ gives the same target. Optional so that models saved before it load.
    pub rollout_tau_steps: Option<f64>,
    /// Phase-1 target horizon K, simulator steps (`None`: 1, the paper's one-step target
    /// v_int − v_c): the constant per-step correction that closes, over K uncorrected coarse
    /// steps from M_int, the gap to M_int K steps later
    /// ([`super::data::Sequence::recompute_coarse`]). The one-step target is mostly the
    /// coarse mesh's spring-back out of M_int's sub-coarse wrinkles; over K steps that is
    /// divided among K(K + 1)/2 and the coarse dynamics' own gap remains. Optional so that
    /// older configs load.
    pub target_steps: Option<usize>,
    /// Phase 2 stops early once the mean window loss of the last 20 windows is below this
    /// (0: run all `rollout_iters`).
    #[config(default = 0.0)]
    pub rollout_stop_loss: f64,
    /// Checkpoint every this many optimiser steps.
    #[config(default = 250)]
    pub checkpoint_every: usize,
    /// Random seed.
    #[config(default = 7)]
    pub seed: u64,
    /// The coarse simulator's membrane compression factor
    /// ([`crate::sim::ClothModel::set_membrane_compression`]) the corrector is trained with,
    /// and so must run with (`None`: 1, the full Baraff-Witkin membrane). Optional so that
    /// models saved before it load.
    pub coarse_compression: Option<f64>,
    /// The shortening beyond which that compression-soft coarse membrane is stiff again
    /// ([`crate::sim::ClothModel::set_membrane_compression`]; `None`: soft however short).
    /// Optional so that models saved before it load.
    pub coarse_compression_knee: Option<f64>,
    /// The coarse simulator's Coulomb friction coefficient against bodies the corrector is
    /// trained with, and so must run with (`None`: the simulator's,
    /// [`crate::sim::SimParams`]' default, the fine simulation's). On the three balls the
    /// coarse sheet comes closest to the fine one with several times the fine cloth's
    /// coefficient (`docs/experiments/three_balls.md`). Optional so that models saved
    /// before it load.
    pub coarse_friction: Option<f64>,
    /// The coarse simulator's wrinkle bending gain the corrector is trained beside, and so
    /// must run with ([`crate::sim::WrinkleBending::with_gain`]: extra bending stiffness where
    /// the coarse membrane is shortened, once the cloth has settled; `None`: off). Optional so
    /// that models saved before it load.
    pub coarse_wrinkle_bending: Option<f64>,
    /// The coarse hinges' bending stiffness as a factor of the fabric's the corrector is
    /// trained beside, and so must run with
    /// ([`crate::sim::model::ClothModel::set_bending_scale`]; `None`: 1). Optional so that
    /// models saved before it load.
    pub coarse_bending: Option<f64>,
    /// Whether the coarse simulation the corrector is trained beside has crease contacts
    /// ([`crate::sim::collide::CollisionDetector::crease_contacts`]; `None`: yes). Optional so
    /// that models saved before it load.
    pub coarse_crease_contacts: Option<bool>,
    /// Validate every this many phase-2 windows, and at the end of each phase (a warm start's
    /// model before phase 2 too: [`Self::init_from`]), on the held-out
    /// [`ValidationSet`]s given to [`train`]: the interleaved rollout's mean distance to M_int
    /// over their frames; the network that was closest is the one saved (`None`: no
    /// validation, the last network is saved). Training losses are one step or one window
    /// long; a corrector is judged over hundreds of frames, where networks with the same
    /// losses differ by 2× (the three-balls README). Optional so that older configs load.
    pub validate_every: Option<usize>,
    /// Frames of each validation set rolled out (`None`: all loaded).
    pub validation_frames: Option<usize>,
    /// A trained corrector (model directory) whose weights and normalisation training starts
    /// from, instead of fresh weights and statistics fitted to the training data: fine-tuning,
    /// typically more phase-2 windows (`steps` 0) or new sequences. Its network must have
    /// [`Self::model`]'s sizes and decoder, and it must have been trained beside the same
    /// coarse model (membrane, friction, wrinkle bending, bending, crease contacts). Optional
    /// so that older configs load.
    pub init_from: Option<PathBuf>,
    /// Phase-2 window after which the saved network is the running mean of the weights after
    /// every later window (stochastic weight averaging, Izmailov et al. 2018) instead of the
    /// last weights: networks a few windows apart differ by up to 2× in long-rollout error
    /// (the three-balls README), and their mean is a smoother pick than any one of them. With
    /// validation, the mean is what is validated. `None`: no averaging.
    pub average_from: Option<usize>,
    /// Phase 2 rolls the corrector out as it runs at inference: the gated decoder's take-back
    /// share scaled by the tension limit and the take-back scale
    /// ([`CorrectorConfig::tension_ramp`], [`CorrectorConfig::take_back`]), so that the window
    /// visits the states the interleaved run will visit and the loss is on the correction it
    /// will apply; the window advances with the correction smoothed as at inference
    /// ([`CorrectorConfig::smoothing`]; the loss stays on the network's own output, whose
    /// targets are not smooth). `None` / false: the raw network (phase 1 always trains it
    /// raw: its one-step targets hold the coarse mesh's spring-back out of M_int, which the
    /// limit would hide).
    pub rollout_as_inference: Option<bool>,
    /// Share of phase-2 windows that start from the interleaved run's own states instead of a
    /// ground-truth M_int (DAgger, Ross et al. 2011): the current network is rolled out as at
    /// inference over every training sequence from its first step (on a fresh copy of its
    /// coarse simulation), again after every [`Self::drift_refresh`] drift windows, and such
    /// a window starts from that run's state at a random step, its targets pulling back to
    /// the ground truth over [`Self::drift_tau_steps`]. Windows from M_int only visit states
    /// `window` steps from the ground truth, while the interleaved run at inference is
    /// 10–20 mm from it after a few frames on the skirt. `None`: every window starts from
    /// M_int. Optional so that older configs load.
    pub drift_share: Option<f64>,
    /// Drift windows between two interleaved runs of [`Self::drift_share`] (`None`: 50).
    pub drift_refresh: Option<usize>,
    /// Pull-back time τ, steps, of the windows that start from the interleaved run's states
    /// (`None`: 10): their gap to the ground truth is many steps' worth, and a one-step pull
    /// back would teach corrections of metres a second.
    pub drift_tau_steps: Option<f64>,
    /// A trained corrector (model directory), the teacher, whose outputs are phase 1's
    /// targets in place of the data's corrections (knowledge distillation, Hinton et al.
    /// 2015): the network learns the teacher's function on the training states, as a smaller
    /// and faster network where the teacher is too slow for the simulator's step. The
    /// student takes the teacher's normalisation (the targets are the teacher's outputs in
    /// its units), and must be trained beside the coarse model the teacher was (membrane,
    /// friction, wrinkle bending, bending, crease contacts). Phase 2 keeps the data's
    /// targets. `None`: the data's targets. Optional so that older configs load.
    pub distil_from: Option<PathBuf>,
}

/// Drift windows between two interleaved runs when [`TrainingConfig::drift_refresh`] is unset.
pub const DEFAULT_DRIFT_REFRESH: usize = 50;
/// Pull-back time of drift windows when [`TrainingConfig::drift_tau_steps`] is unset, steps.
pub const DEFAULT_DRIFT_TAU_STEPS: f64 = 10.0;

impl TrainingConfig {
    /// The coarse membrane's compression factor the corrector was trained beside
    /// ([`Self::coarse_compression`], 1 when unset).
    pub fn compression_factor(&self) -> f64 {
        self.coarse_compression.unwrap_or(1.0)
    }

    /// The coarse friction coefficient the corrector was trained beside, for reports: the
    /// number, or "the simulator's" when unset ([`Self::coarse_friction`]).
    pub fn friction_label(&self) -> String {
        self.coarse_friction
            .map_or_else(|| "the simulator's".to_string(), |mu| mu.to_string())
    }

    /// The coarse model the corrector was trained beside, as a calibration.
    pub fn coarse_calibration(&self) -> crate::sim::coarse::CoarseCalibration {
        crate::sim::coarse::CoarseCalibration {
            compression: self.coarse_compression,
            compression_knee: self.coarse_compression_knee,
            friction: self.coarse_friction,
            wrinkle_bending: self.coarse_wrinkle_bending,
            bending: self.coarse_bending,
            crease_contacts: self.coarse_crease_contacts,
        }
    }

    /// Sets up `sim` (a coarse simulation) as the corrector was trained with
    /// ([`crate::sim::coarse::CoarseCalibration::apply`] of [`Self::coarse_calibration`]).
    pub fn prepare_coarse(&self, sim: &mut Simulation) -> Result<()> {
        self.coarse_calibration().apply(sim)
    }
}

/// A training sequence and, for phase 2, the coarse simulation it was made with
/// ([`crate::data::coarse_simulation`]).
pub struct TrainSet {
    /// The sequence.
    pub seq: Sequence,
    /// The coarse simulator (phase 2 only) and its time at the data set's frame 0, s.
    pub sim: Option<(Simulation, f64)>,
}

/// A held-out sequence training selects its network on ([`TrainingConfig::validate_every`]):
/// it must not be one of the training sets.
pub struct ValidationSet {
    /// The sequence (loaded from its frame `first_frame`).
    pub seq: Sequence,
    /// The scene it was made from: every validation starts a fresh coarse simulation of it
    /// ([`crate::data::coarse_simulation`]; a simulator carries warm starts from step to step,
    /// and a network's score must not depend on what ran before).
    pub scene: Scene,
}

impl ValidationSet {
    /// Frames rolled out: all the loaded sequence holds, at most `limit`.
    fn frames(&self, limit: Option<usize>) -> usize {
        let s = self.seq.manifest.steps_per_frame.max(1);
        let loaded = self.seq.steps.len().saturating_sub(1) / s;
        limit.map_or(loaded, |l| l.min(loaded))
    }

    /// A short name for logs: the data set directory's last component.
    pub fn name(&self) -> String {
        self.seq.dir.file_name().map_or_else(
            || self.seq.dir.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        )
    }
}

/// Progress, reported after each optimiser step.
#[derive(Debug, Clone, Copy)]
pub struct Progress {
    /// 1 or 2.
    pub phase: u8,
    /// Steps done in this phase.
    pub step: usize,
    /// Steps in this phase.
    pub total: usize,
    /// Loss of the last step.
    pub loss: f64,
}

/// What training did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Summary {
    /// Mean phase-1 loss over the first 50 steps run and the last 50.
    pub phase1_first_last: (f64, f64),
    /// Mean phase-2 loss over the first 20 windows run and the last 20.
    pub phase2_first_last: (f64, f64),
    /// Phase-2 windows run.
    pub phase2_iters: usize,
    /// Wall time, s.
    pub seconds: f64,
    /// Training-noise standard deviation used, m.
    pub noise_std_m: f64,
    /// Stopped by the progress callback before the end; resumable from the checkpoint.
    pub interrupted: bool,
    /// With validation: the saved network's pooled interleaved error on the validation sets,
    /// mm, and where it was taken (phase, step or window).
    pub validation_best: Option<(f64, u8, usize)>,
    /// With validation: every validation's pooled error, (phase, step or window, mm; infinite
    /// where the rollout diverged).
    pub validations: Vec<(u8, usize, f64)>,
    /// Phase-2 networks whose mean weights were saved ([`TrainingConfig::average_from`]; 0:
    /// the last network's, or the best validated one's).
    pub averaged: usize,
    /// The interleaved runs made for drift windows ([`TrainingConfig::drift_share`]): the
    /// phase-2 window each was made at and its mean distance to M_int over the training
    /// sets' steps, mm.
    pub drift_runs: Vec<(usize, f64)>,
}

#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
struct Position {
    phase1_done: usize,
    phase2_done: usize,
    /// The best validation so far: pooled mm, phase, step (its weights are
    /// `checkpoint/best.bpk`).
    #[serde(default)]
    best: Option<(f64, u8, usize)>,
    /// The last validation point done (phase, step), so that a resumed run does not repeat it.
    #[serde(default)]
    validated: Option<(u8, usize)>,
    /// Phase-2 networks in the weight average when checkpointed ([`WeightAverage::count`];
    /// their mean is `checkpoint/average.bpk`).
    #[serde(default)]
    averaged: usize,
}

const CHECKPOINT_DIR: &str = "checkpoint";
/// The best validated network's weights in the checkpoint directory.
const BEST_FILE: &str = "best.bpk";
/// The running mean of the phase-2 weights in the checkpoint directory.
const AVERAGE_FILE: &str = "average.bpk";
/// The validation log in a model directory.
pub const VALIDATION_LOG: &str = "validation.csv";

/// One graph sample, raw (unnormalised) inputs and targets plus a loss mask.
struct Sample {
    graph: MeshGraph,
    nodes: Vec<f32>,
    edges: Vec<f32>,
    /// The step's velocity change beyond gravity, m/s, `[n, 3]`.
    step_change: Vec<f32>,
    targets: Vec<f32>,
    mask: Vec<f32>,
}

/// A batch of samples concatenated into one graph, normalised, on `device`.
fn batch_tensors(
    samples: &[Sample],
    norm: &Normalisation,
    device: &Device,
) -> (GraphTensors, Tensor<2>, Tensor<2>, f32) {
    let (mut nodes, mut edges, mut targets, mut mask) = (vec![], vec![], vec![], vec![]);
    let (mut senders, mut receivers, mut inv_mass) = (vec![], vec![], vec![]);
    let mut step_change = vec![];
    let mut offset = 0u32;
    for s in samples {
        inv_mass.extend(inverse_masses(&s.graph.mass));
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
        GraphTensors::new(
            nodes,
            edges,
            &senders,
            &receivers,
            inv_mass,
            step_change,
            device,
        ),
        Tensor::from_data(TensorData::new(targets, [n, 3]), device),
        Tensor::from_data(TensorData::new(mask, [n, 1]), device),
        weight,
    )
}

/// Masked L1 loss: Σ mask·|pred − target| / weight, `pred`/`target` `[N, 3]`, `mask` `[N, 1]`.
fn l1(pred: Tensor<2>, target: Tensor<2>, mask: Tensor<2>, weight: f32) -> Tensor<1> {
    ((pred - target).abs() * mask).sum() / weight
}

struct Trainer<'a> {
    cfg: &'a TrainingConfig,
    out: PathBuf,
    device: Device,
    net: CorrectorNet,
    optim: burn::optim::ModuleOptimizer,
    norm: Normalisation,
    noise_std_m: f64,
    position: Position,
    log: std::fs::File,
    t0: Instant,
    rng: StdRng,
    stopped: bool,
    /// The network of [`Position::best`].
    best: Option<CorrectorNet>,
    /// Every validation of this call, for the summary.
    validations: Vec<(u8, usize, f64)>,
    /// The running mean of the phase-2 weights ([`TrainingConfig::average_from`]), once begun.
    average: Option<WeightAverage>,
    /// Per training set, the last interleaved run's corrected states by sequence step (index
    /// 0: the first step's M_int; [`TrainingConfig::drift_share`]); empty until the first
    /// drift window.
    drift: Vec<Vec<SimState>>,
    /// Drift windows run since [`Self::drift`] was made.
    drift_used: usize,
    /// Per training set, its coarse simulation as it was before phase 2's first window: each
    /// interleaved run for drift windows starts from a copy, as a run at inference would.
    pristine: Vec<Option<Simulation>>,
    /// [`Summary::drift_runs`].
    drift_runs: Vec<(usize, f64)>,
    /// The network distilled ([`TrainingConfig::distil_from`]).
    teacher: Option<CorrectorNet>,
}

fn check(cfg: &TrainingConfig, sets: &[TrainSet], validation: &[ValidationSet]) -> Result<()> {
    let bad = |m: &str| Err(Error::Invalid(format!("training configuration: {m}")));
    if sets.is_empty() || sets.iter().all(|s| s.seq.steps.is_empty()) {
        return bad("no training data");
    }
    match (cfg.validate_every, validation.is_empty()) {
        (Some(0), _) => return bad("validate_every must be at least 1"),
        (Some(_), true) => return bad("validation asked for without validation data"),
        (None, false) => return bad("validation data given but validate_every not set"),
        _ => {}
    }
    if let Some(v) = validation
        .iter()
        .find(|v| v.frames(cfg.validation_frames) == 0)
    {
        return bad(&format!(
            "validation set {} has no whole frame to roll out",
            v.seq.dir.display()
        ));
    }
    let trained: Vec<PathBuf> = sets
        .iter()
        .filter_map(|s| s.seq.dir.canonicalize().ok())
        .collect();
    if let Some(v) = validation
        .iter()
        .find(|v| v.seq.dir.canonicalize().is_ok_and(|d| trained.contains(&d)))
    {
        return bad(&format!(
            "{} is both a training and a validation set",
            v.seq.dir.display()
        ));
    }
    if cfg.batch == 0 || cfg.window == 0 {
        return bad("batch and window must be at least 1");
    }
    let rates = [cfg.lr_start, cfg.lr_end, cfg.rollout_lr];
    if rates.iter().any(|r| !(r.is_finite() && *r > 0.0)) {
        return bad("learning rates must be positive");
    }
    if !(cfg.noise_ratio.is_finite() && cfg.noise_ratio >= 0.0) {
        return bad("noise_ratio must not be negative");
    }
    if let Err(e) = cfg.model.check() {
        return bad(&e);
    }
    if let Some(Err(e)) = cfg
        .coarse_wrinkle_bending
        .map(|g| WrinkleBending::with_gain(g).check())
    {
        return bad(&e);
    }
    if let Some(Err(e)) = cfg.coarse_friction.map(check_friction) {
        return bad(&format!("coarse: {e}"));
    }
    if cfg
        .coarse_bending
        .is_some_and(|b| !(b > 0.0 && b.is_finite()))
    {
        return bad("coarse_bending must be a factor > 0");
    }
    if cfg
        .rollout_tau_steps
        .is_some_and(|t| !(t >= 1.0 && t.is_finite()))
    {
        return bad("rollout_tau_steps must be at least 1");
    }
    if cfg.target_steps == Some(0) {
        return bad("target_steps must be at least 1");
    }
    if cfg.rollout_iters > 0
        && !sets
            .iter()
            .any(|s| s.sim.is_some() && s.seq.steps.len() > cfg.window)
    {
        return bad("phase 2 needs a coarse simulator and a sequence longer than the window");
    }
    if cfg
        .drift_share
        .is_some_and(|d| !(d.is_finite() && d > 0.0 && d <= 1.0))
    {
        return bad("drift_share must be in (0, 1]");
    }
    if cfg.drift_refresh == Some(0) {
        return bad("drift_refresh must be at least 1");
    }
    if cfg
        .drift_tau_steps
        .is_some_and(|t| !(t >= 1.0 && t.is_finite()))
    {
        return bad("drift_tau_steps must be at least 1");
    }
    if cfg.average_from.is_some_and(|k| k >= cfg.rollout_iters) {
        return bad("average_from must be below rollout_iters (weights are averaged in phase 2)");
    }
    Ok(())
}

/// The network, statistics and configuration of the trained corrector `cfg` starts from
/// ([`TrainingConfig::init_from`]), checked against `cfg`; `None` without one.
fn warm_start(
    cfg: &TrainingConfig,
    device: &Device,
) -> Result<Option<(CorrectorNet, Normalisation)>> {
    let Some(dir) = cfg.init_from.as_deref() else {
        return Ok(None);
    };
    let (net, norm, old) = load_net(dir, device)?;
    let config_path = dir.join(CONFIG_FILE);
    let (a, b) = (&old.model, &cfg.model);
    if (
        a.latent,
        a.hidden_layers,
        a.steps,
        a.attention,
        a.decoder_kind(),
    ) != (
        b.latent,
        b.hidden_layers,
        b.steps,
        b.attention,
        b.decoder_kind(),
    ) {
        return Err(Error::bad_input(
            &config_path,
            format!(
                "the network to start from has latent {}, {} hidden layers, {} blocks, \
                 attention {}, decoder {:?}; the training asks for {}, {}, {}, {}, {:?}",
                a.latent,
                a.hidden_layers,
                a.steps,
                a.attention,
                a.decoder_kind(),
                b.latent,
                b.hidden_layers,
                b.steps,
                b.attention,
                b.decoder_kind()
            ),
        ));
    }
    check_same_coarse(&old, cfg, &config_path, "the network to start from")?;
    Ok(Some((net, norm)))
}

/// Refuses (naming `config_path`) a trained corrector (`what`, configured as `old`) trained
/// beside another coarse model than `cfg` asks for.
fn check_same_coarse(
    old: &TrainingConfig,
    cfg: &TrainingConfig,
    config_path: &Path,
    what: &str,
) -> Result<()> {
    if old.coarse_friction != cfg.coarse_friction {
        return Err(Error::bad_input(
            config_path,
            format!(
                "{what} was trained beside a coarse friction coefficient \
                 of {:?}, the training asks for {:?} (None: the simulator's)",
                old.coarse_friction, cfg.coarse_friction
            ),
        ));
    }
    let (old_b, new_b) = (
        old.coarse_bending.unwrap_or(1.0),
        cfg.coarse_bending.unwrap_or(1.0),
    );
    if old_b != new_b {
        return Err(Error::bad_input(
            config_path,
            format!(
                "{what} was trained beside {old_b} times the fabric's \
                 bending stiffness, the training asks for {new_b}"
            ),
        ));
    }
    let (old_e, new_e) = (
        crease_label(old.coarse_crease_contacts),
        crease_label(cfg.coarse_crease_contacts),
    );
    if old_e != new_e {
        return Err(Error::bad_input(
            config_path,
            format!(
                "{what} was trained with crease contacts {old_e}, the \
                 training asks for {new_e}"
            ),
        ));
    }
    if old.coarse_wrinkle_bending != cfg.coarse_wrinkle_bending {
        return Err(Error::bad_input(
            config_path,
            format!(
                "{what} was trained beside a coarse wrinkle bending gain \
                 of {:?}, the training asks for {:?} (None: off)",
                old.coarse_wrinkle_bending, cfg.coarse_wrinkle_bending
            ),
        ));
    }
    if old.compression_factor() != cfg.compression_factor()
        || old.coarse_compression_knee != cfg.coarse_compression_knee
    {
        return Err(Error::bad_input(
            config_path,
            format!(
                "{what} was trained beside a coarse membrane with \
                 compression factor {} (knee {:?}), the training asks for {} (knee {:?})",
                old.compression_factor(),
                old.coarse_compression_knee,
                cfg.compression_factor(),
                cfg.coarse_compression_knee
            ),
        ));
    }
    Ok(())
}

/// The teacher network `cfg` distils ([`TrainingConfig::distil_from`]), without gradients,
/// and its statistics; `None` without one.
fn teacher(cfg: &TrainingConfig, device: &Device) -> Result<Option<(CorrectorNet, Normalisation)>> {
    let Some(dir) = cfg.distil_from.as_deref() else {
        return Ok(None);
    };
    let (net, norm, old) = load_net(dir, device)?;
    check_same_coarse(&old, cfg, &dir.join(CONFIG_FILE), "the teacher")?;
    Ok(Some((net.no_grad(), norm)))
}

/// A running mean of a network's float parameters (stochastic weight averaging), in the
/// order [`Module::visit`] gives them; each kept in f32, so that a mean saved to a checkpoint
/// and loaded again continues bit for bit.
#[derive(Default)]
struct WeightAverage {
    /// Networks averaged.
    count: usize,
    mean: Vec<Vec<f32>>,
}

/// Collects a module's float parameters ([`WeightAverage`]).
struct CollectFloats(Vec<Vec<f32>>);

impl ModuleVisitor for CollectFloats {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.0.push(param.val().into_data().iter::<f32>().collect());
    }
}

/// Replaces a module's float parameters by given values ([`WeightAverage`]).
struct ReplaceFloats<'a> {
    values: &'a [Vec<f32>],
    next: usize,
}

impl ModuleMapper for ReplaceFloats<'_> {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let Some(values) = self.values.get(self.next) else {
            return param;
        };
        self.next += 1;
        param.map(|t| {
            let (shape, device) = (t.shape(), t.device());
            Tensor::from_data(TensorData::new(values.clone(), shape), &device)
        })
    }
}

impl WeightAverage {
    /// The parameters of `net`.
    fn floats(net: &CorrectorNet) -> Vec<Vec<f32>> {
        let mut c = CollectFloats(Vec::new());
        net.visit(&mut c);
        c.0
    }

    /// A mean of the one network `net` (resuming: `count` networks whose mean it holds).
    fn of(net: &CorrectorNet, count: usize) -> Self {
        WeightAverage {
            count,
            mean: Self::floats(net),
        }
    }

    /// Adds `net` to the mean.
    fn add(&mut self, net: &CorrectorNet) {
        let w = Self::floats(net);
        self.count += 1;
        if self.count == 1 {
            self.mean = w;
            return;
        }
        let k = self.count as f64;
        for (m, w) in self.mean.iter_mut().zip(&w) {
            for (m, w) in m.iter_mut().zip(w) {
                *m = (f64::from(*m) + (f64::from(*w) - f64::from(*m)) / k) as f32;
            }
        }
    }

    /// `net` with the mean's parameters.
    fn apply(&self, net: CorrectorNet) -> CorrectorNet {
        net.map(&mut ReplaceFloats {
            values: &self.mean,
            next: 0,
        })
    }
}

/// Trains a corrector on `sets` into `out` (resuming from `out/checkpoint` when the
/// configuration there is the same); `progress` sees every optimiser step and may stop the
/// run (`ControlFlow::Break`): the position is then checkpointed and the summary says
/// `interrupted`, and a later call with the same arguments resumes.
pub fn train(
    cfg: &TrainingConfig,
    sets: &mut [TrainSet],
    validation: &[ValidationSet],
    out: &Path,
    mut progress: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<Summary> {
    check(cfg, sets, validation)?;
    // A run refused before it trained (an `--init` model it cannot start from) leaves no
    // folder it made behind.
    let made_out = !out.exists();
    std::fs::create_dir_all(out.join(CHECKPOINT_DIR)).map_err(|e| Error::io(out, e))?;
    let config_path = out.join(CONFIG_FILE);
    let state_path = out.join(CHECKPOINT_DIR).join("state.json");
    let mut position = Position::default();
    let resuming = state_path.exists();
    if resuming {
        let old = TrainingConfig::load(&config_path)
            .map_err(|e| Error::bad_input(&config_path, e.to_string()))?;
        if &old != cfg {
            return Err(Error::bad_input(
                &config_path,
                "a training run with another configuration is here; choose another output",
            ));
        }
        position = read_json(&state_path)?;
    } else if out.join(WEIGHTS_FILE).exists() {
        return Err(Error::bad_input(
            out.join(WEIGHTS_FILE),
            "a finished model is already here; choose another output",
        ));
    }
    let norm_path = out.join(NORMALISATION_FILE);
    let device = default_device()?.autodiff();
    device.seed(cfg.seed);
    // The models training starts from and distils, each checked against `cfg`. A run refused
    // here made nothing yet, so a folder it made goes again.
    let loaded = (|| {
        let start = if resuming {
            None
        } else {
            warm_start(cfg, &device)?
        };
        let teacher = teacher(cfg, &device)?;
        // The teacher's statistics are the student's: a warm start must share them.
        if let (Some((_, own)), Some((_, taught)), Some(dir)) = (&start, &teacher, &cfg.distil_from)
        {
            if own != taught {
                return Err(Error::bad_input(
                    dir.join(NORMALISATION_FILE),
                    "the teacher's normalisation is not the one of the network to start \
                     from (a student starts fresh or from a student of this teacher)",
                ));
            }
        }
        Ok((start, teacher))
    })();
    let (start, teacher) = match loaded {
        Ok(loaded) => loaded,
        Err(e) => {
            if made_out {
                // Best effort: the refusal is the error to report.
                let _ = std::fs::remove_dir_all(out);
            }
            return Err(e);
        }
    };
    let norm = if resuming {
        read_json(&norm_path)?
    } else {
        let norm = match (&start, &teacher) {
            (Some((_, norm)), _) | (None, Some((_, norm))) => norm.clone(),
            (None, None) => fit_normalisation(sets),
        };
        write_json(&norm_path, &norm)?;
        write_json(&config_path, cfg)?;
        norm
    };
    let rms: f64 = sets.iter().map(|s| s.seq.rms_correction_m()).sum::<f64>() / sets.len() as f64;
    let mut net = match start {
        Some((net, _)) => net,
        None => cfg.model.init(&device),
    };
    let mut optim = AdamConfig::new().init();
    let mut average = None;
    if resuming {
        let dir = out.join(CHECKPOINT_DIR);
        net = crate::common::load_weights(net, &dir.join(WEIGHTS_FILE))?;
        optim = optim
            .load(dir.join("optim.bpk"))
            .map_err(|e| Error::bad_input(dir.join("optim.bpk"), e.to_string()))?;
        if position.averaged > 0 {
            let avg =
                crate::common::load_weights(cfg.model.init(&device), &dir.join(AVERAGE_FILE))?;
            average = Some(WeightAverage::of(&avg, position.averaged));
        }
        tracing::info!(
            "resuming: phase 1 at step {}, phase 2 at window {}",
            position.phase1_done,
            position.phase2_done
        );
    }
    let log_path = out.join("log.csv");
    let log = crate::io::open_log(&log_path, resuming, "phase,step,lr,loss,seconds")?;
    let best = match position.best {
        Some(_) if resuming => Some(crate::common::load_weights(
            cfg.model.init(&device),
            &out.join(CHECKPOINT_DIR).join(BEST_FILE),
        )?),
        _ => None,
    };
    let mut t = Trainer {
        cfg,
        out: out.to_path_buf(),
        rng: StdRng::seed_from_u64(
            cfg.seed ^ (position.phase1_done as u64) << 20 ^ position.phase2_done as u64,
        ),
        device,
        net,
        optim,
        norm,
        noise_std_m: cfg.noise_ratio * rms,
        position,
        log,
        t0: Instant::now(),
        stopped: false,
        best,
        validations: Vec::new(),
        average,
        drift: Vec::new(),
        drift_used: 0,
        pristine: Vec::new(),
        drift_runs: Vec::new(),
        teacher: teacher.map(|(net, _)| net),
    };
    let mut summary = Summary {
        noise_std_m: t.noise_std_m,
        ..Summary::default()
    };
    summary.phase1_first_last = t.phase1(sets, &mut progress)?;
    // After phase 1, or before phase 2 of a warm start: a fine-tuned network is then kept
    // only where it validates better than the model it started from.
    let trained = cfg.steps > 0 || cfg.init_from.is_some();
    if !t.stopped && trained && t.position.phase2_done == 0 {
        t.validate(validation, 1, cfg.steps)?;
    }
    if !t.stopped {
        let (first_last, iters) = t.phase2(sets, validation, &mut progress)?;
        summary.phase2_first_last = first_last;
        summary.phase2_iters = iters;
    }
    summary.seconds = t.t0.elapsed().as_secs_f64();
    summary.validations = std::mem::take(&mut t.validations);
    summary.drift_runs = std::mem::take(&mut t.drift_runs);
    if t.stopped {
        summary.interrupted = true;
        return Ok(summary);
    }
    summary.validation_best = t.position.best;
    summary.averaged = t.average.as_ref().map_or(0, |a| a.count);
    let kept = match &t.best {
        Some(best) => best.clone(),
        None => t.kept_net(),
    };
    save_model(out, cfg, &t.norm, &kept)?;
    std::fs::remove_dir_all(out.join(CHECKPOINT_DIR)).map_err(|e| Error::io(out, e))?;
    Ok(summary)
}

/// Writes a model directory: `config.json`, `normalisation.json` and `model.bpk` (each
/// written whole, then renamed into place).
pub fn save_model(
    dir: &Path,
    cfg: &TrainingConfig,
    norm: &Normalisation,
    net: &CorrectorNet,
) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    write_json(&dir.join(NORMALISATION_FILE), norm)?;
    write_json(&dir.join(CONFIG_FILE), cfg)?;
    write_weights(net, &dir.join(WEIGHTS_FILE))
}

/// Writes `net`'s weights to `path` (burnpack), whole, then renamed into place.
fn write_weights(net: &CorrectorNet, path: &Path) -> Result<()> {
    let tmp = path.with_extension("bpk.tmp");
    net.valid()
        .save_file(&tmp)
        .map_err(|e| Error::Invalid(format!("{}: {e}", tmp.display())))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

/// Statistics of the clean (noise-free) inputs and targets of every step.
pub fn fit_normalisation(sets: &[TrainSet]) -> Normalisation {
    let mut b = NormalisationBuilder::default();
    for s in sets {
        for (i, st) in s.seq.steps.iter().enumerate() {
            let Some(dv) = &st.dv else { continue };
            let (x, v) = (vectors(&st.coarse_x), vectors(&st.coarse_v));
            let (mut nodes, mut edges) = (Vec::new(), Vec::new());
            s.seq
                .graph
                .node_features(&v, &vectors(dv), &st.body, &mut nodes);
            s.seq.graph.edge_features(&x, &v, &mut edges);
            let targets = s.seq.target(i);
            b.add(&nodes, &edges, &targets);
        }
    }
    b.build()
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn first_last(losses: &[f64], k: usize) -> (f64, f64) {
    (
        mean(&losses[..k.min(losses.len())]),
        mean(&losses[losses.len().saturating_sub(k)..]),
    )
}

impl Trainer<'_> {
    fn sample(&mut self, sets: &[TrainSet]) -> Sample {
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
        let x_int = vectors(st.target_x.as_deref().unwrap_or(&st.int_x));
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
        // p̄ = (x_int − x̃_c)/h (or towards the K-step target, `target_steps`); without noise
        // this is v_int − v_c.
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

    fn log(&mut self, phase: u8, step: usize, lr: f64, loss: f64) -> Result<()> {
        let path = self.out.join("log.csv");
        writeln!(
            self.log,
            "{phase},{step},{lr:.3e},{loss:.6},{:.1}",
            self.t0.elapsed().as_secs_f64()
        )
        .map_err(|e| Error::io(path, e))
    }

    fn checkpoint(&self) -> Result<()> {
        let dir = self.out.join(CHECKPOINT_DIR);
        let (w, o) = (dir.join("model.bpk.tmp"), dir.join("optim.bpk.tmp"));
        self.net
            .clone()
            .save_file(&w)
            .map_err(|e| Error::Invalid(format!("{}: {e}", w.display())))?;
        self.optim
            .save(&o)
            .map_err(|e| Error::Invalid(format!("{}: {e}", o.display())))?;
        std::fs::rename(&w, dir.join(WEIGHTS_FILE)).map_err(|e| Error::io(&w, e))?;
        std::fs::rename(&o, dir.join("optim.bpk")).map_err(|e| Error::io(&o, e))?;
        if let Some(avg) = &self.average {
            write_weights(&avg.apply(self.net.clone()), &dir.join(AVERAGE_FILE))?;
        }
        let position = Position {
            averaged: self.average.as_ref().map_or(0, |a| a.count),
            ..self.position
        };
        write_json(&dir.join("state.json"), &position)
    }

    /// The network training would save now: the weight average once begun, else the last.
    fn kept_net(&self) -> CorrectorNet {
        match &self.average {
            Some(avg) => avg.apply(self.net.clone()),
            None => self.net.clone(),
        }
    }

    /// Validation point (`phase`, `step`): rolls the current network out interleaved on every
    /// validation set, logs the pooled error and keeps the network when it is the best so
    /// far (then checkpoints, so that a resumed run keeps it). Nothing without validation
    /// sets, or when this point was done before a resume.
    fn validate(&mut self, validation: &[ValidationSet], phase: u8, step: usize) -> Result<()> {
        if validation.is_empty() || self.position.validated == Some((phase, step)) {
            return Ok(());
        }
        let t = Instant::now();
        let device = default_device()?;
        let kept = self.kept_net();
        let net = kept.valid();
        let (mut sum, mut frames, mut diverged) = (0.0, 0usize, false);
        let mut rows = Vec::new();
        for v in validation {
            let mut sim = crate::data::coarse_simulation(&v.scene, &v.seq.dir, v.seq.first_frame)?;
            self.cfg.prepare_coarse(&mut sim)?;
            let t0 = sim.state.t_s;
            let corrector = Corrector::new(
                net.clone(),
                self.norm.clone(),
                self.cfg.clone(),
                &v.seq.mesh,
                &self.out,
                &device,
            );
            let n = v.frames(self.cfg.validation_frames);
            let mm = match interleaved_errors(&v.seq, &mut sim, t0, &corrector, n)? {
                Some(e) => {
                    sum += e.iter().sum::<f64>();
                    frames += e.len();
                    mean(&e)
                }
                None => {
                    diverged = true;
                    f64::INFINITY
                }
            };
            rows.push(format!("{phase},{step},{},{n},{mm:.4}", v.name()));
        }
        let pooled = if diverged {
            f64::INFINITY
        } else {
            sum / frames.max(1) as f64
        };
        rows.push(format!("{phase},{step},pooled,{frames},{pooled:.4}"));
        let path = self.out.join(VALIDATION_LOG);
        let new_file = !path.exists();
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(|e| Error::io(&path, e))?;
        let header = new_file.then_some("phase,step,set,frames,interleaved_mm".to_string());
        for line in header.into_iter().chain(rows) {
            writeln!(f, "{line}").map_err(|e| Error::io(&path, e))?;
        }
        let better = self.position.best.is_none_or(|(b, _, _)| pooled < b);
        tracing::info!(
            "validation after phase {phase} step {step}: {pooled:.3} mm interleaved{} ({:.0} s)",
            if better { ", the best so far" } else { "" },
            t.elapsed().as_secs_f64()
        );
        if better && pooled.is_finite() {
            write_weights(&kept, &self.out.join(CHECKPOINT_DIR).join(BEST_FILE))?;
            self.best = Some(kept);
            self.position.best = Some((pooled, phase, step));
        }
        self.validations.push((phase, step, pooled));
        self.position.validated = Some((phase, step));
        self.checkpoint()
    }

    fn phase1(
        &mut self,
        sets: &[TrainSet],
        progress: &mut impl FnMut(&Progress) -> ControlFlow<()>,
    ) -> Result<(f64, f64)> {
        let cfg = self.cfg;
        let mut losses = Vec::new();
        let mut window = Vec::new();
        while self.position.phase1_done < cfg.steps {
            let step = self.position.phase1_done;
            let lr = cfg.lr_start
                * (cfg.lr_end / cfg.lr_start).powf(step as f64 / cfg.steps.max(1) as f64);
            let samples: Vec<Sample> = (0..cfg.batch).map(|_| self.sample(sets)).collect();
            let (g, target, mask, weight) = batch_tensors(&samples, &self.norm, &self.device);
            let target = match &self.teacher {
                Some(teacher) => teacher.forward(&g).detach(), // [N, 3]
                None => target,
            };
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

    /// Rolls the current network out as at inference over every training set with a coarse
    /// simulator ([`interleaved_run`], on a copy of its pristine simulation), keeping its
    /// corrected states for drift windows ([`TrainingConfig::drift_share`]); only when none
    /// were made yet or [`TrainingConfig::drift_refresh`] drift windows ran since. A run that
    /// diverged keeps its states up to a window before the divergence.
    fn refresh_drift(&mut self, sets: &[TrainSet]) -> Result<()> {
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

    fn phase2(
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
fn rollout_window(
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
    use crate::data::{coarse_simulation, generate, Options, Variation};
    use crate::scene::samples::flat_sheet;
    use crate::scene::Collider;
    use clothsr_geometry::garment::Fabric;

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
