//! The training configuration, saved as a model directory's `config.json`.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::corrector::model::CorrectorConfig;
use clothsr_geometry::error::{Error, Result};
use clothsr_sim::coarse::CoarseCalibration;
use clothsr_sim::driver::Simulation;

/// The form of a corrector's `config.json` this build reads and writes
/// ([`TrainingConfig::format_version`]). Files of another form are refused
/// ([`TrainingConfig::load`]) rather than read with guessed defaults.
pub const CORRECTOR_FORMAT_VERSION: u32 = 2;

/// How to train (saved as `config.json`, with the network's sizes, the inference settings and
/// the coarse model trained beside). A file holds every field; one of another
/// [`CORRECTOR_FORMAT_VERSION`], or with fields this build does not know, is refused.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainingConfig {
    /// The form of the file: [`CORRECTOR_FORMAT_VERSION`].
    pub format_version: u32,
    /// The network.
    pub model: CorrectorConfig,
    /// Phase-1 optimiser steps (the paper: 400K on a GPU).
    pub steps: usize,
    /// Samples (whole meshes or patches) per step.
    pub batch: usize,
    /// Learning rate at the first step.
    pub lr_start: f64,
    /// Learning rate at the last phase-1 step (exponential decay).
    pub lr_end: f64,
    /// Training-noise standard deviation as a multiple of the data's RMS per-step position
    /// correction h·|p̄| (0: no noise, the default: noise teaches the corrector to take back
    /// deviations in one step, which interleaved with the simulator feeds back).
    pub noise_ratio: f64,
    /// Vertices per random sub-mesh patch (0: whole meshes).
    pub patch_nodes: usize,
    /// Phase-2 (window rollout) optimiser steps; 0 skips phase 2.
    pub rollout_iters: usize,
    /// Phase-2 window ω, simulator steps.
    pub window: usize,
    /// Phase-2 learning rate.
    pub rollout_lr: f64,
    /// Phase-2 target's pull-back time τ, in simulator steps (1: the paper's target). The
    /// target is p̄ = Δv + (Δx − hΔv)/τ with Δx = x_int − x_c and Δv = v_int − v_c: the ground
    /// truth's velocity plus a pull towards its positions over τ steps. With τ = 1 it is Δx/h,
    /// which lands the step on M_int but leaves a drifted rollout's whole position gap in the
    /// velocity, to be overshot at the next step. From a ground-truth state (phase 1)
    /// Δx = hΔv and every τ gives the same target.
    pub rollout_tau_steps: f64,
    /// Phase 2 stops early once the mean window loss of the last 20 windows is below this
    /// (0: run all `rollout_iters`).
    pub rollout_stop_loss: f64,
    /// Checkpoint every this many optimiser steps.
    pub checkpoint_every: usize,
    /// Random seed.
    pub seed: u64,
    /// The coarse model (membrane compression and its knee, friction, wrinkle bending, bending,
    /// crease contacts) the corrector is trained beside, and so must run with
    /// ([`Self::prepare_coarse`]; unset settings: the simulator's own).
    pub coarse: CoarseCalibration,
    /// Validate every this many phase-2 windows, and at the end of each phase (a warm start's
    /// model before phase 2 too: [`Self::init_from`]), on the held-out
    /// [`super::ValidationSet`]s given to [`super::train`]: the interleaved rollout's mean
    /// distance to M_int over their frames; the network that was closest is the one saved
    /// (`None`: no validation, the last network is saved). Training losses are one step or
    /// one window long; a corrector is judged over hundreds of frames, where networks with
    /// the same losses can differ widely (`docs/experiments/`).
    pub validate_every: Option<usize>,
    /// Frames of each validation set rolled out (`None`: all loaded).
    pub validation_frames: Option<usize>,
    /// A trained corrector (model directory) whose weights and normalisation training starts
    /// from, instead of fresh weights and statistics fitted to the training data: fine-tuning,
    /// typically more phase-2 windows (`steps` 0) or new sequences (`None`: fresh weights).
    /// Its network must have [`Self::model`]'s sizes and decoder, and it must have been
    /// trained beside the same coarse model.
    pub init_from: Option<PathBuf>,
}

setters!(TrainingConfig {
    with_model: model: CorrectorConfig,
    with_steps: steps: usize,
    with_batch: batch: usize,
    with_lr_start: lr_start: f64,
    with_lr_end: lr_end: f64,
    with_noise_ratio: noise_ratio: f64,
    with_patch_nodes: patch_nodes: usize,
    with_rollout_iters: rollout_iters: usize,
    with_window: window: usize,
    with_rollout_lr: rollout_lr: f64,
    with_rollout_tau_steps: rollout_tau_steps: f64,
    with_rollout_stop_loss: rollout_stop_loss: f64,
    with_checkpoint_every: checkpoint_every: usize,
    with_seed: seed: u64,
    with_coarse: coarse: CoarseCalibration,
    with_validate_every: validate_every: Option<usize>,
    with_validation_frames: validation_frames: Option<usize>,
    with_init_from: init_from: Option<PathBuf>,
});

impl TrainingConfig {
    /// Training `model` with the default settings: 5,000 phase-1 steps of 4 samples, the
    /// learning rate 1e-4 → 1e-6, no noise, whole meshes, no phase 2 (8-step windows at 1e-5
    /// with τ = 1 once asked for), a checkpoint every 250 steps, seed 7, beside the
    /// simulator's own coarse model, no validation, fresh weights.
    pub fn new(model: CorrectorConfig) -> Self {
        TrainingConfig {
            format_version: CORRECTOR_FORMAT_VERSION,
            model,
            steps: 5000,
            batch: 4,
            lr_start: 1e-4,
            lr_end: 1e-6,
            noise_ratio: 0.0,
            patch_nodes: 0,
            rollout_iters: 0,
            window: 8,
            rollout_lr: 1e-5,
            rollout_tau_steps: 1.0,
            rollout_stop_loss: 0.0,
            checkpoint_every: 250,
            seed: 7,
            coarse: CoarseCalibration::default(),
            validate_every: None,
            validation_frames: None,
            init_from: None,
        }
    }

    /// The configuration in `path` (a model directory's `config.json`). A file of another
    /// form than this build's ([`CORRECTOR_FORMAT_VERSION`]) is refused, naming the file and
    /// how to make the model again.
    pub fn load(path: &Path) -> Result<TrainingConfig> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let value: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| Error::bad_input(path, format!("not a corrector configuration: {e}")))?;
        let version = value
            .get("format_version")
            .and_then(serde_json::Value::as_u64);
        if version != Some(u64::from(CORRECTOR_FORMAT_VERSION)) {
            let (found, by) = match version {
                Some(v) if v > u64::from(CORRECTOR_FORMAT_VERSION) => {
                    (format!("format_version {v}"), "a newer")
                }
                Some(v) => (format!("format_version {v}"), "an older"),
                None => ("no format_version".to_string(), "an older"),
            };
            return Err(Error::bad_input(
                path,
                format!(
                    "this corrector configuration has {found}, this clothsr reads \
                     {CORRECTOR_FORMAT_VERSION}: it was written by {by} clothsr. Make the \
                     model again with this one: a shipped model with its models folder's \
                     make.sh (tests/data/models/<folder>/make.sh), any other with \
                     'clothsr lab train corrector'"
                ),
            ));
        }
        serde_json::from_value(value)
            .map_err(|e| Error::bad_input(path, format!("not a corrector configuration: {e}")))
    }

    /// Sets up `sim` (a coarse simulation) as the corrector was trained with
    /// ([`CoarseCalibration::apply`] of [`Self::coarse`]).
    pub fn prepare_coarse(&self, sim: &mut Simulation) -> Result<()> {
        self.coarse.apply(sim)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, text: &str) -> PathBuf {
        let path = dir.join("config.json");
        std::fs::write(&path, text).expect("write");
        path
    }

    #[test]
    fn a_written_configuration_loads_as_it_was() {
        let dir = tempfile::tempdir().expect("tmp");
        let mut cfg = TrainingConfig::new(CorrectorConfig::new().with_take_back(0.5))
            .with_rollout_tau_steps(4.0)
            .with_validate_every(Some(10));
        cfg.coarse.friction = Some(2.5);
        let path = dir.path().join("config.json");
        crate::common::write_json(&path, &cfg).expect("write");
        assert_eq!(TrainingConfig::load(&path).expect("load"), cfg);
    }

    #[test]
    fn configurations_of_other_forms_are_refused_naming_the_file() {
        let dir = tempfile::tempdir().expect("tmp");
        let current =
            serde_json::to_value(TrainingConfig::new(CorrectorConfig::new())).expect("json");
        type Edit<'a> = &'a dyn Fn(&mut serde_json::Map<String, serde_json::Value>);
        let with = |f: Edit| {
            let mut v = current.clone();
            f(v.as_object_mut().expect("an object"));
            write(dir.path(), &v.to_string())
        };
        // Unversioned (written before the format had a version) and older: refused, saying so
        // and how to make the model again.
        let unversioned: Edit = &|m| drop(m.remove("format_version"));
        let older: Edit = &|m| drop(m.insert("format_version".into(), 1.into()));
        for (edit, found) in [
            (unversioned, "no format_version"),
            (older, "format_version 1"),
        ] {
            let path = with(edit);
            let e = TrainingConfig::load(&path).expect_err("old").to_string();
            assert!(
                e.contains(&path.display().to_string())
                    && e.contains(found)
                    && e.contains("an older clothsr")
                    && e.contains("make.sh"),
                "{e}"
            );
        }
        let newer = with(&|m| drop(m.insert("format_version".into(), 3.into())));
        let e = TrainingConfig::load(&newer).expect_err("newer").to_string();
        assert!(e.contains("a newer clothsr"), "{e}");
        // A field this build does not know, or one missing, is refused.
        let unknown = with(&|m| drop(m.insert("drift_share".into(), 0.5.into())));
        let e = TrainingConfig::load(&unknown)
            .expect_err("unknown")
            .to_string();
        assert!(
            e.contains("drift_share") && e.contains("config.json"),
            "{e}"
        );
        let missing = with(&|m| drop(m.remove("rollout_tau_steps")));
        let e = TrainingConfig::load(&missing)
            .expect_err("missing")
            .to_string();
        assert!(e.contains("rollout_tau_steps"), "{e}");
    }
}
