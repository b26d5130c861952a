//! Validation: held-out sequences training selects its network on.

use std::io::Write;
use std::time::Instant;

use burn::module::Module;

use super::checkpoint::{write_weights, BEST_FILE, CHECKPOINT_DIR, VALIDATION_LOG};
use super::{mean, Trainer};
use crate::common::default_device;
use crate::corrector::data::Sequence;
use crate::corrector::inference::Corrector;
use crate::corrector::rollout::interleaved_errors;
use clothsr_geometry::error::{Error, Result};
use clothsr_geometry::scene::Scene;

/// A held-out sequence training selects its network on ([`TrainingConfig::validate_every`]):
/// it must not be one of the training sets.
pub struct ValidationSet {
    /// The sequence (loaded from its frame `first_frame`).
    pub seq: Sequence,
    /// The scene it was made from: every validation starts a fresh coarse simulation of it
    /// ([`clothsr_io::data::coarse_simulation`]; a simulator carries warm starts from step to step,
    /// and a network's score must not depend on what ran before).
    pub scene: Scene,
}

impl ValidationSet {
    /// Frames rolled out: all the loaded sequence holds, at most `limit`.
    pub(super) fn frames(&self, limit: Option<usize>) -> usize {
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

impl Trainer<'_> {
    /// Validation point (`phase`, `step`): rolls the current network out interleaved on every
    /// validation set, logs the pooled error and keeps the network when it is the best so
    /// far (then checkpoints, so that a resumed run keeps it). Nothing without validation
    /// sets, or when this point was done before a resume.
    pub(super) fn validate(
        &mut self,
        validation: &[ValidationSet],
        phase: u8,
        step: usize,
    ) -> Result<()> {
        if validation.is_empty() || self.position.validated == Some((phase, step)) {
            return Ok(());
        }
        let t = Instant::now();
        let device = default_device()?;
        let kept = self.net.clone();
        let net = kept.valid();
        let (mut sum, mut frames, mut diverged) = (0.0, 0usize, false);
        let mut rows = Vec::new();
        for v in validation {
            let mut sim =
                clothsr_io::data::coarse_simulation(&v.scene, &v.seq.dir, v.seq.first_frame)?;
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
}
