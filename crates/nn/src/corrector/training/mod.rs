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
//! * Beyond the paper: phase 2's pull-back time ([`TrainingConfig::rollout_tau_steps`]), a
//!   warm start from a trained corrector ([`TrainingConfig::init_from`]) and the choice of the
//!   network by its interleaved rollout on held-out sequences
//!   ([`TrainingConfig::validate_every`]).
//!
//! The output directory holds `config.json`, `normalisation.json`, `model.bpk`, `log.csv`
//! (phase, step, learning rate, loss, elapsed seconds) and, while training, `checkpoint/`
//! (weights, optimiser state, position), from which an interrupted run resumes.

mod checkpoint;
mod config;
mod phase1;
mod phase2;
mod start;
mod validation;

pub use checkpoint::{save_model, VALIDATION_LOG};
pub use config::{TrainingConfig, CORRECTOR_FORMAT_VERSION};
pub use phase2::pull_back_target;
pub use validation::ValidationSet;

use std::io::Write;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::optim::AdamConfig;
use burn::tensor::Device;
use rand::rngs::StdRng;
use rand::SeedableRng;

use super::data::{vectors, Sequence};
use super::inference::{read_json, CONFIG_FILE, NORMALISATION_FILE, WEIGHTS_FILE};
use super::model::CorrectorNet;
use super::normalise::{Normalisation, NormalisationBuilder};
use crate::common::{default_device, init_network, read_resume_point, write_json, ResumePoint};
use checkpoint::{Position, BEST_FILE, CHECKPOINT_DIR};
use clothsr_geometry::error::{Error, Result};
use clothsr_sim::driver::Simulation;
use start::warm_start;

/// A training sequence and, for phase 2, the coarse simulation it was made with
/// ([`clothsr_io::data::coarse_simulation`]).
pub struct TrainSet {
    /// The sequence.
    pub seq: Sequence,
    /// The coarse simulator (phase 2 only) and its time at the data set's frame 0, s.
    pub sim: Option<(Simulation, f64)>,
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
    if cfg.format_version != CORRECTOR_FORMAT_VERSION {
        return bad(&format!(
            "format_version {} (this clothsr writes {CORRECTOR_FORMAT_VERSION})",
            cfg.format_version
        ));
    }
    if let Err(e) = cfg.model.check() {
        return bad(&e.to_string());
    }
    if let Err(e) = cfg.coarse.check() {
        return bad(&format!("coarse: {e}"));
    }
    let tau = cfg.rollout_tau_steps;
    if !(tau >= 1.0 && tau.is_finite()) {
        return bad("rollout_tau_steps must be at least 1");
    }
    if cfg.rollout_iters > 0
        && !sets
            .iter()
            .any(|s| s.sim.is_some() && s.seq.steps.len() > cfg.window)
    {
        return bad("phase 2 needs a coarse simulator and a sequence longer than the window");
    }
    Ok(())
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
    let resume = open_run(cfg, out)?;
    let resuming = resume.is_some();
    let position = resume.as_ref().map(|r| r.position).unwrap_or_default();
    let norm_path = out.join(NORMALISATION_FILE);
    let device = default_device()?.autodiff();
    let start = match starting_model(cfg, &device, resuming) {
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
        let norm = match &start {
            Some((_, norm)) => norm.clone(),
            None => fit_normalisation(sets),
        };
        write_json(&norm_path, &norm)?;
        write_json(&out.join(CONFIG_FILE), cfg)?;
        norm
    };
    let rms: f64 = sets.iter().map(|s| s.seq.rms_correction_m()).sum::<f64>() / sets.len() as f64;
    let net = match start {
        Some((net, _)) => net,
        None => init_network(&device, Some(cfg.seed), || cfg.model.init(&device)),
    };
    let (net, optim) = if let Some(point) = &resume {
        resume_weights(net, point)?
    } else {
        (net, AdamConfig::new().init())
    };
    let log_path = out.join("log.csv");
    let log = clothsr_io::open_log(&log_path, resuming, "phase,step,lr,loss,seconds")?;
    let best = match position.best {
        Some(_) if resuming => Some(crate::common::load_network(
            &device,
            &out.join(CHECKPOINT_DIR).join(BEST_FILE),
            || cfg.model.init(&device),
        )?),
        _ => None,
    };
    let mut t = Trainer {
        cfg,
        out: out.to_path_buf(),
        rng: step_rng(cfg.seed, 1, position.phase1_done),
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
    };
    t.run(sets, validation, &mut progress)
}

/// The random draws of step `step` of `phase` (its samples, noise and windows): they depend
/// on the step alone, so that a run resumed from any checkpoint draws as one that never
/// stopped.
fn step_rng(seed: u64, phase: u8, step: usize) -> StdRng {
    StdRng::seed_from_u64(seed ^ (u64::from(phase) << 56) ^ ((step as u64) << 20))
}

/// Opens the run in `out`: the resume point there, if any. Refuses an output holding a run
/// with another configuration, or a finished model.
fn open_run(cfg: &TrainingConfig, out: &Path) -> Result<Option<ResumePoint<Position>>> {
    let dir = out.join(CHECKPOINT_DIR);
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(out, e))?;
    let config_path = out.join(CONFIG_FILE);
    let resume = read_resume_point(&dir)?;
    if resume.is_some() {
        let old = TrainingConfig::load(&config_path)?;
        if &old != cfg {
            return Err(Error::bad_input(
                &config_path,
                "a training run with another configuration is here; choose another output",
            ));
        }
    } else if out.join(WEIGHTS_FILE).exists() {
        return Err(Error::bad_input(
            out.join(WEIGHTS_FILE),
            "a finished model is already here; choose another output",
        ));
    }
    Ok(resume)
}

/// The model training starts from (none when `resuming`), checked against `cfg`, and its
/// normalisation. A run refused here made nothing yet, so a folder it made goes again.
fn starting_model(
    cfg: &TrainingConfig,
    device: &Device,
    resuming: bool,
) -> Result<Option<(CorrectorNet, Normalisation)>> {
    if resuming {
        Ok(None)
    } else {
        warm_start(cfg, device)
    }
}

/// The checkpointed network and optimiser state of a resumed run.
fn resume_weights(
    net: CorrectorNet,
    point: &ResumePoint<Position>,
) -> Result<(CorrectorNet, burn::optim::ModuleOptimizer)> {
    let net = crate::common::load_weights(net, &point.weights)?;
    let optim = AdamConfig::new()
        .init()
        .load(&point.optim)
        .map_err(|e| Error::bad_input(&point.optim, e.to_string()))?;
    tracing::info!(
        "resuming: phase 1 at step {}, phase 2 at window {}",
        point.position.phase1_done,
        point.position.phase2_done
    );
    Ok((net, optim))
}

impl Trainer<'_> {
    /// Runs both phases with their validations, then saves the kept network and removes the
    /// checkpoint (unless stopped).
    fn run(
        &mut self,
        sets: &mut [TrainSet],
        validation: &[ValidationSet],
        progress: &mut impl FnMut(&Progress) -> ControlFlow<()>,
    ) -> Result<Summary> {
        let (cfg, out) = (self.cfg, self.out.clone());
        let mut summary = Summary {
            noise_std_m: self.noise_std_m,
            ..Summary::default()
        };
        summary.phase1_first_last = self.phase1(sets, progress)?;
        // After phase 1, or before phase 2 of a warm start: a fine-tuned network is then kept
        // only where it validates better than the model it started from.
        let trained = cfg.steps > 0 || cfg.init_from.is_some();
        if !self.stopped && trained && self.position.phase2_done == 0 {
            self.validate(validation, 1, cfg.steps)?;
        }
        if !self.stopped {
            let (first_last, iters) = self.phase2(sets, validation, progress)?;
            summary.phase2_first_last = first_last;
            summary.phase2_iters = iters;
        }
        summary.seconds = self.t0.elapsed().as_secs_f64();
        summary.validations = std::mem::take(&mut self.validations);
        if self.stopped {
            summary.interrupted = true;
            return Ok(summary);
        }
        summary.validation_best = self.position.best;
        let kept = match &self.best {
            Some(best) => best.clone(),
            None => self.net.clone(),
        };
        save_model(&out, cfg, &self.norm, &kept)?;
        crate::common::remove_checkpoint(&out.join(CHECKPOINT_DIR))?;
        Ok(summary)
    }
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
    fn log(&mut self, phase: u8, step: usize, lr: f64, loss: f64) -> Result<()> {
        let path = self.out.join("log.csv");
        writeln!(
            self.log,
            "{phase},{step},{lr:.3e},{loss:.6},{:.1}",
            self.t0.elapsed().as_secs_f64()
        )
        .map_err(|e| Error::io(path, e))
    }
}
