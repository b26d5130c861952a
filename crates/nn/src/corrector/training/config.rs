//! The training configuration.

use std::path::PathBuf;

use burn::config::Config;

use crate::corrector::model::CorrectorConfig;
use crate::error::Result;
use crate::sim::driver::Simulation;

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
    /// losses can differ widely (`docs/experiments/`). Optional so that older configs load.
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
    /// last weights: networks a few windows apart can differ widely in long-rollout error
    /// (`docs/experiments/`), and their mean is a smoother pick than any one of them. With
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
        self.coarse_calibration().friction_label()
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

    /// Records `cal` as the coarse model the corrector is trained beside.
    pub fn set_coarse_calibration(&mut self, cal: &crate::sim::coarse::CoarseCalibration) {
        self.coarse_compression = cal.compression;
        self.coarse_compression_knee = cal.compression_knee;
        self.coarse_friction = cal.friction;
        self.coarse_wrinkle_bending = cal.wrinkle_bending;
        self.coarse_bending = cal.bending;
        self.coarse_crease_contacts = cal.crease_contacts;
    }

    /// Sets up `sim` (a coarse simulation) as the corrector was trained with
    /// ([`crate::sim::coarse::CoarseCalibration::apply`] of [`Self::coarse_calibration`]).
    pub fn prepare_coarse(&self, sim: &mut Simulation) -> Result<()> {
        self.coarse_calibration().apply(sim)
    }
}
