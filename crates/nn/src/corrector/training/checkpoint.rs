//! Checkpoints and the saved model.

use std::path::Path;

use burn::module::Module;
use serde::{Deserialize, Serialize};

use super::config::TrainingConfig;
use super::Trainer;
use crate::common::{write_json, write_training_checkpoint};
use crate::corrector::inference::{CONFIG_FILE, NORMALISATION_FILE, WEIGHTS_FILE};
use crate::corrector::model::CorrectorNet;
use crate::corrector::normalise::Normalisation;
use clothsr_geometry::error::{Error, Result};

#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub(super) struct Position {
    pub(super) phase1_done: usize,
    pub(super) phase2_done: usize,
    /// The best validation so far: pooled mm, phase, step (its weights are
    /// `checkpoint/best.bpk`).
    #[serde(default)]
    pub(super) best: Option<(f64, u8, usize)>,
    /// The last validation point done (phase, step), so that a resumed run does not repeat it.
    #[serde(default)]
    pub(super) validated: Option<(u8, usize)>,
}

pub(super) const CHECKPOINT_DIR: &str = "checkpoint";
/// The best validated network's weights in the checkpoint directory.
pub(super) const BEST_FILE: &str = "best.bpk";
/// The validation log in a model directory.
pub const VALIDATION_LOG: &str = "validation.csv";

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
pub(super) fn write_weights(net: &CorrectorNet, path: &Path) -> Result<()> {
    let tmp = path.with_extension("bpk.tmp");
    net.valid()
        .save_file(&tmp)
        .map_err(|e| Error::Invalid(format!("{}: {e}", tmp.display())))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

impl Trainer<'_> {
    pub(super) fn checkpoint(&self) -> Result<()> {
        write_training_checkpoint(
            &self.out.join(CHECKPOINT_DIR),
            &self.position,
            &self.net,
            &self.optim,
        )
    }
}
