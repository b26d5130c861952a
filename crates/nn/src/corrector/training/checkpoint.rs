//! Checkpoints, the weight average and the saved model.

use std::path::Path;

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::tensor::{Tensor, TensorData};
use serde::{Deserialize, Serialize};

use super::config::TrainingConfig;
use super::Trainer;
use crate::common::write_json;
use crate::corrector::inference::{CONFIG_FILE, NORMALISATION_FILE, WEIGHTS_FILE};
use crate::corrector::model::CorrectorNet;
use crate::corrector::normalise::Normalisation;
use crate::error::{Error, Result};

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
    /// Phase-2 networks in the weight average when checkpointed ([`WeightAverage::count`];
    /// their mean is `checkpoint/average.bpk`).
    #[serde(default)]
    pub(super) averaged: usize,
}

pub(super) const CHECKPOINT_DIR: &str = "checkpoint";
/// The best validated network's weights in the checkpoint directory.
pub(super) const BEST_FILE: &str = "best.bpk";
/// The running mean of the phase-2 weights in the checkpoint directory.
pub(super) const AVERAGE_FILE: &str = "average.bpk";
/// The validation log in a model directory.
pub const VALIDATION_LOG: &str = "validation.csv";

/// A running mean of a network's float parameters (stochastic weight averaging), in the
/// order [`Module::visit`] gives them; each kept in f32, so that a mean saved to a checkpoint
/// and loaded again continues bit for bit.
#[derive(Default)]
pub(super) struct WeightAverage {
    /// Networks averaged.
    pub(super) count: usize,
    pub(super) mean: Vec<Vec<f32>>,
}

/// Collects a module's float parameters ([`WeightAverage`]).
pub(super) struct CollectFloats(Vec<Vec<f32>>);

impl ModuleVisitor for CollectFloats {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.0.push(param.val().into_data().iter::<f32>().collect());
    }
}

/// Replaces a module's float parameters by given values ([`WeightAverage`]).
pub(super) struct ReplaceFloats<'a> {
    pub(super) values: &'a [Vec<f32>],
    pub(super) next: usize,
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
    pub(super) fn floats(net: &CorrectorNet) -> Vec<Vec<f32>> {
        let mut c = CollectFloats(Vec::new());
        net.visit(&mut c);
        c.0
    }

    /// A mean of the one network `net` (resuming: `count` networks whose mean it holds).
    pub(super) fn of(net: &CorrectorNet, count: usize) -> Self {
        WeightAverage {
            count,
            mean: Self::floats(net),
        }
    }

    /// Adds `net` to the mean.
    pub(super) fn add(&mut self, net: &CorrectorNet) {
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
    pub(super) fn apply(&self, net: CorrectorNet) -> CorrectorNet {
        net.map(&mut ReplaceFloats {
            values: &self.mean,
            next: 0,
        })
    }
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
pub(super) fn write_weights(net: &CorrectorNet, path: &Path) -> Result<()> {
    let tmp = path.with_extension("bpk.tmp");
    net.valid()
        .save_file(&tmp)
        .map_err(|e| Error::Invalid(format!("{}: {e}", tmp.display())))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

impl Trainer<'_> {
    pub(super) fn checkpoint(&self) -> Result<()> {
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
    pub(super) fn kept_net(&self) -> CorrectorNet {
        match &self.average {
            Some(avg) => avg.apply(self.net.clone()),
            None => self.net.clone(),
        }
    }
}
