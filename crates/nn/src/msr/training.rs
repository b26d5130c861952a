//! Training the ISR network (the paper's §3.2.2, §3.3.3, §3.3.4).
//!
//! * Samples are random `P × P` patches of the coordinate maps (random panel, frame, position,
//!   and a random mirror of material space along either axis, which leaves the cloth itself
//!   unchanged), kept when at least `min_mask_fraction` of their pixels lie on the pattern.
//! * The initialisation input is the ground-truth fine map of the previous frame smoothed with a
//!   Gaussian kernel (`init_blur_px`) plus N(0, `init_noise_m`²) noise (0.1 mm, §3.3.3); with
//!   probability `coarse_init_prob`, and always on a sequence's first frame, it is the coarse
//!   map itself (what inference uses on a shot's first frame). With `init_motion` the
//!   initialisation is first moved by the coarse map's change since that frame.
//! * Loss α·|I_f − I_gt| + β·|G_f − G_gt| over masked pixels (mean per value), with G the
//!   central differences of §3.2.1 along both map axes where a pixel and its four neighbours
//!   lie on the pattern. Both terms are in detail units (metres / `detail_m`) and the
//!   differences per pixel spacing (h = two pixels), so α and β weigh comparable quantities.
//! * **Unrolled initialisation** (beyond the paper): at inference the initialisation is the
//!   network's own previous output, not a smoothed ground truth, and a network trained only on
//!   the latter copies its own errors forward (fed its own previous output, its error grows
//!   well beyond what it makes fed the true previous frame). So each step draws r in
//!   0..=`unroll_max`, starts its patches r frames before the target from the data's
//!   initialisation and runs the network (no gradients) through those frames, feeding each
//!   output, moved by the coarse motion, forward as the next initialisation (the "pushforward"
//!   trick of neural PDE solvers, and the window rollout of the corrector's phase 2).
//! * Adam with an exponential learning-rate decay `lr_start → lr_end` over `steps`.
//!
//! The output directory holds `config.json` (these settings, the network's sizes, pixel size
//! and normalisation scale), `model.bpk`, `log.csv` (step, learning rate, loss, its two terms,
//! the loss of the coarse map and of the initialisation themselves on the same patches,
//! elapsed seconds) and, while training, `checkpoint/`, from which an interrupted run resumes.

use std::io::Write;
use std::ops::ControlFlow;
use std::path::Path;
use std::time::Instant;

use burn::config::Config;
use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use ndarray::{s, Array, Array2, Array3, Dimension};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use super::condition::{Condition, CONDITION_CHANNELS};
use super::data::IsrSequence;
use super::inference::{
    geometry_channels, patch_input, CONFIG_FILE, CURVATURE_STENCIL_PX, WEIGHTS_FILE,
};
use super::model::{IsrConfig, IsrNet};
use crate::common::{read_resume_point, write_json, write_training_checkpoint, ResumePoint};
use clothsr_geometry::error::{Error, Result};

/// How to train (saved as `config.json`, with the network's sizes).
#[derive(Config, Debug, PartialEq)]
pub struct IsrTrainingConfig {
    /// The network.
    pub model: IsrConfig,
    /// Pixel size of the coordinate maps, m (the fine mesh's edge length; taken from the data).
    pub pixel_m: f64,
    /// Patch side P, pixels (a multiple of the window).
    #[config(default = 32)]
    pub patch: usize,
    /// Phong tessellation blend of the coarse map (0: piecewise-linear rasterisation, as the
    /// paper; 0.5 halves the upsampled M_int's error on our drapes before any learning).
    #[config(default = 0.5)]
    pub phong_alpha: f64,
    /// Length that one normalised unit of the coarse shape input stands for, m.
    #[config(default = 0.01)]
    pub scale_m: f64,
    /// Length that one normalised unit of detail (initialisation and output, fine − coarse)
    /// stands for, m.
    #[config(default = 0.001)]
    pub detail_m: f64,
    /// Optimiser steps.
    #[config(default = 3000)]
    pub steps: usize,
    /// Patches per step.
    #[config(default = 8)]
    pub batch: usize,
    /// Learning rate at the first step.
    #[config(default = 4e-4)]
    pub lr_start: f64,
    /// Learning rate at the last step (exponential decay).
    #[config(default = 1e-5)]
    pub lr_end: f64,
    /// Weight α of the position term.
    #[config(default = 1.0)]
    pub alpha: f64,
    /// Weight β of the gradient term (§4.2.3: 10).
    #[config(default = 10.0)]
    pub beta: f64,
    /// σ of the Gaussian smoothing of the initialisation, pixels.
    #[config(default = 1.0)]
    pub init_blur_px: f64,
    /// Standard deviation of the noise added to the initialisation, m (§3.3.3: 0.1 mm).
    #[config(default = 1e-4)]
    pub init_noise_m: f64,
    /// Move the previous frame's fine map with the coarse motion before it enters the network:
    /// init = I_f^{t−1} + (I_c^t − I_c^{t−1}), so its detail sits where the coarse cloth is now
    /// (beyond the paper, which passes I_f^{t−1} as it is).
    #[config(default = true)]
    pub init_motion: bool,
    /// Probability that a sample's initialisation is the coarse map (a shot's first frame).
    #[config(default = 0.1)]
    pub coarse_init_prob: f64,
    /// Most frames a sample is rolled out through the network before its loss (uniform in
    /// 0..=`unroll_max` per step): the initialisation is then the network's own output, as at
    /// inference (0: always the data's).
    #[config(default = 3)]
    pub unroll_max: usize,
    /// Fewest pattern pixels a training patch may have, as a fraction of P².
    #[config(default = 0.25)]
    pub min_mask_fraction: f64,
    /// Checkpoint every this many steps.
    #[config(default = 250)]
    pub checkpoint_every: usize,
    /// Random seed.
    #[config(default = 7)]
    pub seed: u64,
    /// Start from the weights of this trained model (a directory with the same network;
    /// relative to the model's own directory) instead of random ones: fine-tuning. `None`:
    /// from scratch.
    pub fine_tune_from: Option<String>,
}

/// Progress, reported after each optimiser step.
#[derive(Debug, Clone, Copy)]
pub struct Progress {
    /// Steps done.
    pub step: usize,
    /// Steps in all.
    pub total: usize,
    /// Loss of the last step.
    pub loss: f64,
}

/// What training did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Summary {
    /// Mean loss over the first 50 steps run and the last 50.
    pub first_last: (f64, f64),
    /// Wall time, s.
    pub seconds: f64,
    /// Stopped by the progress callback before the end; resumable from the checkpoint.
    pub interrupted: bool,
}

#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
struct Position {
    done: usize,
}

const CHECKPOINT_DIR: &str = "checkpoint";

/// A batch on a device: inputs `[B, in, P, P]`, targets `[B, 3, P, P]`, the mask `[B, 1, P, P]`
/// and the gradient-validity mask `[B, 1, P − 2, P − 2]`, with the number of masked values of
/// each (for the means).
pub struct Batch {
    /// Normalised inputs.
    pub inputs: Tensor<4>,
    /// Normalised ground truth.
    pub targets: Tensor<4>,
    /// 1 on pattern pixels.
    pub mask: Tensor<4>,
    /// 1 where the central differences are valid.
    pub grad_mask: Tensor<4>,
    /// Σ mask · 3.
    pub mask_values: f32,
    /// Σ grad_mask · 6.
    pub grad_values: f32,
}

/// The ISR loss (see the module documentation): returns (total, position term, gradient term).
pub fn isr_loss(pred: Tensor<4>, b: &Batch, alpha: f64, beta: f64) -> (Tensor<1>, f64, f64) {
    let [n, _, p, q] = pred.dims();
    let diff = pred - b.targets.clone(); // [B, 3, P, P]
    let dist = (diff.clone().abs() * b.mask.clone()).sum() / b.mask_values.max(1.0);
    // Central differences of the difference (linear, so G_f − G_gt = G(I_f − I_gt)).
    let gu = (diff.clone().slice([0..n, 0..3, 2..p, 1..q - 1])
        - diff.clone().slice([0..n, 0..3, 0..p - 2, 1..q - 1]))
        * 0.5;
    let gv = (diff.clone().slice([0..n, 0..3, 1..p - 1, 2..q])
        - diff.slice([0..n, 0..3, 1..p - 1, 0..q - 2]))
        * 0.5;
    let cons = ((gu.abs() + gv.abs()) * b.grad_mask.clone()).sum() / b.grad_values.max(1.0);
    let d = f64::from(dist.clone().into_scalar::<f32>());
    let c = f64::from(cons.clone().into_scalar::<f32>());
    (dist * alpha + cons * beta, d, c)
}

/// `true` where a pixel and its four neighbours are on the pattern, cropped to (P − 2)².
pub fn gradient_mask(mask: &Array2<bool>) -> Array2<bool> {
    let (h, w) = mask.dim();
    Array2::from_shape_fn((h - 2, w - 2), |(i, j)| {
        let (i, j) = (i + 1, j + 1);
        mask[(i, j)] && mask[(i - 1, j)] && mask[(i + 1, j)] && mask[(i, j - 1)] && mask[(i, j + 1)]
    })
}

/// One training patch before normalisation, metres.
struct RawPatch {
    coarse: Array3<f32>,
    /// The coarse map's geometry channels (with `geometry_input`).
    geometry: Option<Array3<f32>>,
    /// The panel's condition channels (with `condition_input`).
    condition: Option<[f32; CONDITION_CHANNELS]>,
    init: Array3<f32>,
    fine: Array3<f32>,
    mask: Array2<bool>,
}

/// Checks a configuration against the data.
fn check(cfg: &IsrTrainingConfig, seqs: &[IsrSequence]) -> Result<()> {
    let bad = |m: String| Err(Error::Invalid(format!("ISR training configuration: {m}")));
    if let Err(e) = cfg.model.check() {
        return bad(e.to_string());
    }
    if seqs.is_empty() || seqs.iter().all(|s| s.frames.is_empty()) {
        return bad("no training data".into());
    }
    if cfg.patch < 4 || !cfg.patch.is_multiple_of(cfg.model.patch_multiple()) {
        return bad(format!(
            "the patch ({}) must be a multiple of the window ({}) times the unshuffle factor ({})",
            cfg.patch,
            cfg.model.window,
            cfg.model.unshuffle_factor()
        ));
    }
    if cfg.batch == 0 {
        return bad("batch must be at least 1".into());
    }
    let positive = [
        cfg.lr_start,
        cfg.lr_end,
        cfg.scale_m,
        cfg.detail_m,
        cfg.pixel_m,
    ];
    if positive.iter().any(|r| !(r.is_finite() && *r > 0.0)) {
        return bad("learning rates, scale_m, detail_m and pixel_m must be positive".into());
    }
    if !(cfg.phong_alpha.is_finite() && (0.0..=1.0).contains(&cfg.phong_alpha)) {
        return bad("phong_alpha must lie in [0, 1]".into());
    }
    if !(cfg.coarse_init_prob.is_finite() && (0.0..=1.0).contains(&cfg.coarse_init_prob)) {
        return bad("coarse_init_prob must lie in [0, 1]".into());
    }
    for s in seqs {
        if (s.grids[0].pixel_m - cfg.pixel_m).abs() > 1e-9 {
            return bad(format!(
                "{} is rasterised at {} m pixels, the configuration says {} m",
                s.dir.display(),
                s.grids[0].pixel_m,
                cfg.pixel_m
            ));
        }
        if cfg.model.condition() && s.conditions.is_none() {
            return bad(format!(
                "{} does not record its fabric's parameters, which the network takes",
                s.dir.display()
            ));
        }
    }
    Ok(())
}

/// Trains an ISR network on `seqs` into `out` (resuming from `out/checkpoint` when the
/// configuration there is the same); `progress` sees every optimiser step and may stop the run
/// (`ControlFlow::Break`): the position is then checkpointed and a later call with the same
/// arguments resumes.
pub fn train(
    cfg: &IsrTrainingConfig,
    seqs: &[IsrSequence],
    out: &Path,
    mut progress: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<Summary> {
    check(cfg, seqs)?;
    let resume = open_run(cfg, out)?;
    let resuming = resume.is_some();
    let device = crate::common::default_device()?.autodiff();
    let mut net = crate::common::init_network(&device, Some(cfg.seed), || cfg.model.init(&device));
    let mut optim = AdamConfig::new().init();
    let mut position = Position::default();
    if let Some(point) = resume {
        net = crate::common::load_weights(net, &point.weights)?;
        optim = optim
            .load(&point.optim)
            .map_err(|e| Error::bad_input(&point.optim, e.to_string()))?;
        position = point.position;
        tracing::info!("resuming at step {}", position.done);
    } else if let Some(from) = &cfg.fine_tune_from {
        net = start_from(net, &cfg.model, &out.join(from))?;
    }
    let mut log = LossLog::open(out, resuming)?;
    let t0 = Instant::now();
    let mut losses = Vec::new();
    let mut stopped = false;
    while position.done < cfg.steps {
        let step = position.done;
        // Each step's draws depend on the step alone: a run resumed from any checkpoint
        // trains exactly as one that never stopped.
        let mut rng = StdRng::seed_from_u64(cfg.seed ^ ((step as u64) << 20));
        let lr =
            cfg.lr_start * (cfg.lr_end / cfg.lr_start).powf(step as f64 / cfg.steps.max(1) as f64);
        let unroll = if cfg.model.init_input && cfg.unroll_max > 0 {
            rng.random_range(0..=cfg.unroll_max)
        } else {
            0
        };
        let batch = training_batch(cfg, seqs, &net, unroll, &device, &mut rng)?;
        let (loss, step_losses) = batch_losses(cfg, &net, &batch);
        let value = step_losses.loss;
        if !value.is_finite() {
            return Err(Error::Simulation(format!(
                "ISR training diverged at step {step} (loss {value})"
            )));
        }
        let grads = GradientsParams::from_grads(loss.backward(), &net);
        net = optim.step(lr, net, grads);
        position.done += 1;
        losses.push(value);
        log.add(&step_losses);
        if log.count == 25 || position.done == cfg.steps {
            log.flush(position.done, lr, t0)?;
        }
        let flow = progress(&Progress {
            step: position.done,
            total: cfg.steps,
            loss: value,
        });
        if position.done.is_multiple_of(cfg.checkpoint_every.max(1)) || flow.is_break() {
            checkpoint(out, &net, &optim, position)?;
        }
        if flow.is_break() {
            stopped = true;
            break;
        }
    }
    let k = 50.min(losses.len()).max(1);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let summary = Summary {
        first_last: (
            mean(&losses[..k.min(losses.len())]),
            mean(&losses[losses.len().saturating_sub(k)..]),
        ),
        seconds: t0.elapsed().as_secs_f64(),
        interrupted: stopped,
    };
    if stopped {
        return Ok(summary);
    }
    save_model(out, cfg, &net)?;
    crate::common::remove_checkpoint(&out.join(CHECKPOINT_DIR))?;
    Ok(summary)
}

/// Opens the run in `out`: the resume point there, if any (a new run writes its
/// configuration). Refuses an output holding a run with another configuration, or a
/// finished model.
fn open_run(cfg: &IsrTrainingConfig, out: &Path) -> Result<Option<ResumePoint<Position>>> {
    let dir = out.join(CHECKPOINT_DIR);
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(out, e))?;
    let config_path = out.join(CONFIG_FILE);
    let resume = read_resume_point(&dir)?;
    if resume.is_some() {
        let old = IsrTrainingConfig::load(&config_path)
            .map_err(|e| Error::bad_input(&config_path, e.to_string()))?;
        // A run saved before an optional input existed has `None`, which means off.
        let settled = |c: &IsrTrainingConfig| {
            let mut c = c.clone();
            c.model = c.model.settled();
            c
        };
        if settled(&old) != settled(cfg) {
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
    } else {
        write_json(&config_path, cfg)?;
    }
    Ok(resume)
}

/// `net` with the weights of the trained model in `dir`, whose network must be `model`.
fn start_from(net: IsrNet, model: &IsrConfig, dir: &Path) -> Result<IsrNet> {
    let path = dir.join(CONFIG_FILE);
    let theirs =
        IsrTrainingConfig::load(&path).map_err(|e| Error::bad_input(&path, e.to_string()))?;
    if theirs.model.settled() != model.settled() {
        return Err(Error::bad_input(
            &path,
            "its network differs from the one to fine-tune; it cannot be the start",
        ));
    }
    crate::common::load_weights(net, &dir.join(WEIGHTS_FILE))
}

/// One optimiser step's losses, as logged.
#[derive(Debug, Clone, Copy, Default)]
struct StepLosses {
    /// The loss.
    loss: f64,
    /// Its position term.
    position: f64,
    /// Its gradient term.
    gradient: f64,
    /// The loss of the coarse map itself as the prediction.
    coarse: f64,
    /// The loss of the initialisation as the prediction.
    init: f64,
}

/// The network's loss on `batch` (to differentiate) and the step's losses.
fn batch_losses(cfg: &IsrTrainingConfig, net: &IsrNet, batch: &Batch) -> (Tensor<1>, StepLosses) {
    let pred = net.forward(batch.inputs.clone());
    let (loss, d, c) = isr_loss(pred, batch, cfg.alpha, cfg.beta);
    // The same loss for the coarse map itself (the upsampled baseline: no detail), for
    // the log.
    let identity = batch.inputs.clone().narrow(1, 0, 3).zeros_like();
    let (base, _, _) = isr_loss(identity, batch, cfg.alpha, cfg.beta);
    let base = f64::from(base.into_scalar::<f32>());
    // And for the initialisation (the previous frame's map) as the prediction.
    let init_base = if cfg.model.init_input {
        let init = batch.inputs.clone().narrow(1, 3, 3).detach();
        f64::from(
            isr_loss(init, batch, cfg.alpha, cfg.beta)
                .0
                .into_scalar::<f32>(),
        )
    } else {
        base
    };
    let value = f64::from(loss.clone().into_scalar::<f32>());
    let losses = StepLosses {
        loss: value,
        position: d,
        gradient: c,
        coarse: base,
        init: init_base,
    };
    (loss, losses)
}

/// `log.csv`: the mean losses over every 25 steps.
struct LossLog {
    file: std::fs::File,
    path: std::path::PathBuf,
    /// Sums of the steps' losses since the last line.
    sum: StepLosses,
    /// Steps since the last line.
    count: usize,
}

impl LossLog {
    /// Opens (or, resuming, appends to) `out/log.csv`.
    fn open(out: &Path, resuming: bool) -> Result<LossLog> {
        let path = out.join("log.csv");
        let file = clothsr_io::open_log(
            &path,
            resuming,
            "step,lr,loss,position,gradient,coarse_loss,init_loss,seconds",
        )?;
        Ok(LossLog {
            file,
            path,
            sum: StepLosses::default(),
            count: 0,
        })
    }

    /// Adds a step's losses.
    fn add(&mut self, l: &StepLosses) {
        let s = &mut self.sum;
        *s = StepLosses {
            loss: s.loss + l.loss,
            position: s.position + l.position,
            gradient: s.gradient + l.gradient,
            coarse: s.coarse + l.coarse,
            init: s.init + l.init,
        };
        self.count += 1;
    }

    /// Writes the mean losses since the last line, at `done` steps, learning rate `lr`.
    fn flush(&mut self, done: usize, lr: f64, t0: Instant) -> Result<()> {
        let (s, k) = (self.sum, self.count as f64);
        writeln!(
            self.file,
            "{},{lr:.3e},{:.6},{:.6},{:.6},{:.6},{:.6},{:.1}",
            done,
            s.loss / k,
            s.position / k,
            s.gradient / k,
            s.coarse / k,
            s.init / k,
            t0.elapsed().as_secs_f64()
        )
        .map_err(|e| Error::io(&self.path, e))?;
        self.sum = StepLosses::default();
        self.count = 0;
        Ok(())
    }
}

/// Writes a model directory: `config.json` and `model.bpk` (each written whole, then renamed).
pub fn save_model(dir: &Path, cfg: &IsrTrainingConfig, net: &IsrNet) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    write_json(&dir.join(CONFIG_FILE), cfg)?;
    let weights = dir.join(WEIGHTS_FILE);
    let tmp = dir.join("model.bpk.tmp");
    net.valid()
        .save_file(&tmp)
        .map_err(|e| Error::Invalid(format!("{}: {e}", tmp.display())))?;
    std::fs::rename(&tmp, &weights).map_err(|e| Error::io(&weights, e))
}

fn checkpoint(
    out: &Path,
    net: &IsrNet,
    optim: &burn::optim::ModuleOptimizer,
    position: Position,
) -> Result<()> {
    write_training_checkpoint(&out.join(CHECKPOINT_DIR), &position, net, optim)
}

/// The rows (or columns) of a `p`-long window starting at `r0` (possibly negative) that lie
/// in `0..len`: (first index in the window, first index in the array, count).
fn overlap(r0: isize, p: usize, len: usize) -> (usize, usize, usize) {
    let start = r0.max(0);
    let end = (r0 + p as isize).min(len as isize);
    if end <= start {
        return (0, 0, 0);
    }
    (
        (start - r0) as usize,
        start as usize,
        (end - start) as usize,
    )
}

/// Crops `(C, H, W)` at `(r0, c0)` (possibly negative) to `p × p`, zero-padded past the border.
fn crop3(a: &Array3<f32>, r0: isize, c0: isize, p: usize) -> Array3<f32> {
    let (c, h, w) = a.dim();
    let ((oi, ai, ni), (oj, aj, nj)) = (overlap(r0, p, h), overlap(c0, p, w));
    let mut out = Array3::zeros((c, p, p));
    out.slice_mut(s![.., oi..oi + ni, oj..oj + nj])
        .assign(&a.slice(s![.., ai..ai + ni, aj..aj + nj]));
    out
}

fn crop2(a: &Array2<bool>, r0: isize, c0: isize, p: usize) -> Array2<bool> {
    let (h, w) = a.dim();
    let ((oi, ai, ni), (oj, aj, nj)) = (overlap(r0, p, h), overlap(c0, p, w));
    let mut out = Array2::from_elem((p, p), false);
    out.slice_mut(s![oi..oi + ni, oj..oj + nj])
        .assign(&a.slice(s![ai..ai + ni, aj..aj + nj]));
    out
}

/// The `(9, p, p)` geometry channels ([`geometry_channels`]) of the `p × p` crop at `origin`
/// of a whole coarse map `(3, H, W)` with its mask: computed on a crop with a margin of the
/// curvature stencil, so that they equal the whole map's (as at inference) on every pixel.
fn crop_geometry(
    map: &Array3<f32>,
    mask: &Array2<bool>,
    origin: (usize, usize),
    p: usize,
    pixel_m: f32,
) -> Array3<f32> {
    let m = CURVATURE_STENCIL_PX;
    let (r0, c0) = (
        origin.0 as isize - m as isize,
        origin.1 as isize - m as isize,
    );
    let wide = crop3(map, r0, c0, p + 2 * m);
    let wide_mask = crop2(mask, r0, c0, p + 2 * m);
    let g = geometry_channels(wide.view(), wide_mask.view(), pixel_m);
    g.slice(s![.., m..m + p, m..m + p]).to_owned()
}

/// A `(…, P, P)` array mirrored along its last two axes, rows (`flip[0]`) and columns
/// (`flip[1]`), in standard layout.
fn mirror<A: Clone, D: Dimension>(mut a: Array<A, D>, flip: [bool; 2]) -> Array<A, D> {
    let first = a.ndim() - 2;
    for (k, &f) in flip.iter().enumerate() {
        if f {
            a.invert_axis(ndarray::Axis(first + k));
        }
    }
    a.as_standard_layout().into_owned()
}

/// Geometry channels `(9, P, P)` of a patch as those of the patch mirrored along rows
/// (`flip[0]`) and columns (`flip[1]`): the pixels move, and a single mirror reverses one
/// material axis, which negates the angle's cosine (channel 2) and the normal (3–5); stretch
/// and curvature stay. So a mirrored training patch gets what [`geometry_channels`] gives for
/// the mirrored map, as inference would.
fn mirror_geometry(g: Array3<f32>, flip: [bool; 2]) -> Array3<f32> {
    let mut g = mirror(g, flip);
    if flip[0] != flip[1] {
        g.slice_mut(s![2..6, .., ..]).mapv_inplace(|v| -v);
    }
    g
}

/// Where a training patch comes from: sequence, frame (index into its loaded frames), panel
/// grid, top-left pixel and mirroring along rows and columns.
#[derive(Debug, Clone, Copy)]
struct Location {
    seq: usize,
    frame: usize,
    grid: usize,
    origin: (usize, usize),
    flip: [bool; 2],
}

impl Location {
    /// The condition channels of this location's panel (checked present by [`check`]).
    fn condition(&self, seqs: &[IsrSequence]) -> [f32; CONDITION_CHANNELS] {
        let seq = &seqs[self.seq];
        let panel = seq.grids[self.grid].panel as usize;
        seq.conditions
            .as_ref()
            .and_then(|c| c.get(panel))
            .map_or([0.0; CONDITION_CHANNELS], Condition::channels)
    }

    /// The `(3, P, P)` crop of `maps` (one frame's maps of this location's sequence).
    fn crop(&self, maps: &[Array3<f32>], p: usize) -> Array3<f32> {
        let (r0, c0) = (self.origin.0 as isize, self.origin.1 as isize);
        mirror(crop3(&maps[self.grid], r0, c0, p), self.flip)
    }

    /// The `(9, P, P)` geometry channels of the coarse map `maps` at this location
    /// ([`crop_geometry`]), mirrored like the maps ([`mirror_geometry`]).
    fn geometry(
        &self,
        seqs: &[IsrSequence],
        maps: &[Array3<f32>],
        p: usize,
        pixel_m: f32,
    ) -> Array3<f32> {
        let mask = &seqs[self.seq].grids[self.grid].mask;
        mirror_geometry(
            crop_geometry(&maps[self.grid], mask, self.origin, p, pixel_m),
            self.flip,
        )
    }

    fn mask(&self, seqs: &[IsrSequence], p: usize) -> Array2<bool> {
        let full = &seqs[self.seq].grids[self.grid].mask;
        let m = crop2(full, self.origin.0 as isize, self.origin.1 as isize, p);
        mirror(m, self.flip)
    }
}

/// A random patch location whose frame has at least `history` frames before it in its
/// sequence, preferring patches with at least `min_mask_fraction` pattern pixels.
fn sample_location(
    cfg: &IsrTrainingConfig,
    seqs: &[IsrSequence],
    history: usize,
    rng: &mut StdRng,
) -> Option<Location> {
    let p = cfg.patch;
    let counts: Vec<usize> = seqs
        .iter()
        .map(|s| s.frames.len().saturating_sub(history))
        .collect();
    let total: usize = counts.iter().sum();
    if total == 0 {
        return None;
    }
    let min_px = ((cfg.min_mask_fraction * (p * p) as f64) as usize).max(1);
    let mut best: Option<(usize, Location)> = None;
    for _attempt in 0..50 {
        let mut pick = rng.random_range(0..total);
        let seq = counts.iter().position(|&c| {
            if pick < c {
                true
            } else {
                pick -= c;
                false
            }
        })?;
        let s = &seqs[seq];
        let grid = rng.random_range(0..s.grids.len());
        let (h, w) = s.grids[grid].mask.dim();
        let loc = Location {
            seq,
            frame: pick + history,
            grid,
            origin: (
                rng.random_range(0..=h.saturating_sub(p)),
                rng.random_range(0..=w.saturating_sub(p)),
            ),
            flip: [rng.random_bool(0.5), rng.random_bool(0.5)],
        };
        let count = loc.mask(seqs, p).iter().filter(|&&m| m).count();
        if count >= min_px {
            return Some(loc);
        }
        if best.as_ref().is_none_or(|b| count > b.0) {
            best = Some((count, loc));
        }
    }
    best.map(|b| b.1)
}

/// The initialisation of `loc`'s patch at its sequence frame `frame` from the data: the coarse
/// map on a sequence's first frame and with probability `coarse_init_prob`, else the smoothed
/// ground truth of the frame before plus noise (moved by the coarse motion with
/// `init_motion`).
fn data_init(
    cfg: &IsrTrainingConfig,
    seqs: &[IsrSequence],
    loc: &Location,
    frame: usize,
    mask: &Array2<bool>,
    rng: &mut StdRng,
) -> Array3<f32> {
    let p = cfg.patch;
    let frames = &seqs[loc.seq].frames;
    let coarse = loc.crop(&frames[frame].coarse, p);
    if frame == 0 || rng.random_bool(cfg.coarse_init_prob.clamp(0.0, 1.0)) {
        return coarse;
    }
    let mut init = loc.crop(&frames[frame - 1].smoothed, p);
    if cfg.init_motion {
        init = init + &coarse - loc.crop(&frames[frame - 1].coarse, p);
    }
    if let Ok(n) = Normal::new(0.0, cfg.init_noise_m.max(0.0)) {
        for ((_, i, j), v) in init.indexed_iter_mut() {
            if mask[(i, j)] {
                *v += n.sample(rng) as f32;
            }
        }
    }
    init
}

/// One training batch. With `unroll` = r > 0 the initialisations are the network's own
/// outputs: each patch starts r frames earlier from the data's initialisation and the network
/// (without gradients) produces the frames up to the target's, each output moved by the coarse
/// motion into the next frame's initialisation, as at inference.
fn training_batch(
    cfg: &IsrTrainingConfig,
    seqs: &[IsrSequence],
    net: &IsrNet,
    unroll: usize,
    device: &Device,
    rng: &mut StdRng,
) -> Result<Batch> {
    let p = cfg.patch;
    let locs: Vec<Location> = (0..cfg.batch)
        .map(|_| sample_location(cfg, seqs, unroll, rng))
        .collect::<Option<Vec<_>>>()
        .ok_or_else(|| Error::Invalid("no training frames for the unroll length".into()))?;
    let masks: Vec<Array2<bool>> = locs.iter().map(|l| l.mask(seqs, p)).collect();
    let pixel_m = cfg.pixel_m as f32;
    let raw = |l: &Location, m: &Array2<bool>, frame: usize, init: Array3<f32>| RawPatch {
        coarse: l.crop(&seqs[l.seq].frames[frame].coarse, p),
        geometry: cfg
            .model
            .geometry()
            .then(|| l.geometry(seqs, &seqs[l.seq].frames[frame].coarse, p, pixel_m)),
        condition: cfg.model.condition().then(|| l.condition(seqs)),
        init,
        fine: l.crop(&seqs[l.seq].frames[frame].fine, p),
        mask: m.clone(),
    };
    let mut inits: Vec<Array3<f32>> = locs
        .iter()
        .zip(&masks)
        .map(|(l, m)| data_init(cfg, seqs, l, l.frame - unroll, m, rng))
        .collect();
    let detail = cfg.detail_m as f32;
    for back in (1..=unroll).rev() {
        let raws: Vec<RawPatch> = locs
            .iter()
            .zip(&masks)
            .zip(&inits)
            .map(|((l, m), init)| raw(l, m, l.frame - back, init.clone()))
            .collect();
        let b = batch_tensors(cfg, &raws, device);
        let out: Vec<f32> = net
            .forward(b.inputs)
            .detach()
            .into_data()
            .try_to_vec::<f32>()
            .map_err(|e| Error::Invalid(format!("ISR output: {e:?}")))?;
        for (n, (r, init)) in raws.iter().zip(inits.iter_mut()).enumerate() {
            let l = &locs[n];
            let out = &out[n * 3 * p * p..(n + 1) * 3 * p * p];
            let mut fine = r.coarse.clone();
            for ((c, i, j), v) in fine.indexed_iter_mut() {
                if r.mask[(i, j)] {
                    *v += out[(c * p + i) * p + j] * detail;
                }
            }
            if cfg.init_motion {
                let next = l.crop(&seqs[l.seq].frames[l.frame - back + 1].coarse, p);
                fine = fine + &next - &r.coarse;
            }
            *init = fine;
        }
    }
    let raws: Vec<RawPatch> = locs
        .iter()
        .zip(&masks)
        .zip(inits)
        .map(|((l, m), init)| raw(l, m, l.frame, init))
        .collect();
    Ok(batch_tensors(cfg, &raws, device))
}

/// Normalises and uploads raw patches.
fn batch_tensors(cfg: &IsrTrainingConfig, raws: &[RawPatch], device: &Device) -> Batch {
    let p = cfg.patch;
    let (scale, detail) = (cfg.scale_m as f32, cfg.detail_m as f32);
    let cin = cfg.model.in_channels();
    let (mut inputs, mut targets, mut mask, mut gmask) = (vec![], vec![], vec![], vec![]);
    let (mut mask_values, mut grad_values) = (0.0f32, 0.0f32);
    for r in raws {
        let init = cfg.model.init_input.then(|| r.init.view());
        let geometry = r.geometry.as_ref().map(|g| g.view());
        match patch_input(
            r.coarse.view(),
            init,
            r.mask.view(),
            scale,
            detail,
            geometry,
            r.condition.as_ref(),
        ) {
            Some(input) => {
                inputs.extend(input);
                for c in 0..3 {
                    for ((i, j), &m) in r.mask.indexed_iter() {
                        targets.push(if m {
                            (r.fine[(c, i, j)] - r.coarse[(c, i, j)]) / detail
                        } else {
                            0.0
                        });
                    }
                }
            }
            None => {
                inputs.extend(std::iter::repeat_n(0.0, cin * p * p));
                targets.extend(std::iter::repeat_n(0.0, 3 * p * p));
            }
        }
        for &m in &r.mask {
            mask.push(if m { 1.0f32 } else { 0.0 });
            mask_values += if m { 3.0 } else { 0.0 };
        }
        for &m in &gradient_mask(&r.mask) {
            gmask.push(if m { 1.0f32 } else { 0.0 });
            grad_values += if m { 6.0 } else { 0.0 };
        }
    }
    let b = raws.len();
    Batch {
        inputs: Tensor::from_data(TensorData::new(inputs, [b, cin, p, p]), device),
        targets: Tensor::from_data(TensorData::new(targets, [b, 3, p, p]), device),
        mask: Tensor::from_data(TensorData::new(mask, [b, 1, p, p]), device),
        grad_mask: Tensor::from_data(TensorData::new(gmask, [b, 1, p - 2, p - 2]), device),
        mask_values,
        grad_values,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mirrored_geometry_is_the_geometry_of_the_mirrored_map() {
        let (p, px) = (10usize, 0.0025f32);
        let map = Array3::from_shape_fn((3, p, p), |(c, i, j)| {
            let (u, v) = (i as f32 * px, j as f32 * px);
            [
                1.01 * u + 0.02 * v,
                v + 0.01 * (u * 80.0).sin(),
                0.01 * (u * 60.0 + v * 30.0).cos(),
            ][c]
        });
        let mask = Array2::from_shape_fn((p, p), |(i, j)| i + 2 * j > 3);
        let g = geometry_channels(map.view(), mask.view(), px);
        for flip in [[true, false], [false, true], [true, true], [false, false]] {
            let (mut m, mut k) = (map.clone(), mask.clone());
            for (axis, &f) in flip.iter().enumerate() {
                if f {
                    m.invert_axis(ndarray::Axis(axis + 1));
                    k.invert_axis(ndarray::Axis(axis));
                }
            }
            let direct = geometry_channels(
                m.as_standard_layout().view(),
                k.as_standard_layout().view(),
                px,
            );
            let mirrored = mirror_geometry(g.clone(), flip);
            for ((c, i, j), &v) in direct.indexed_iter() {
                let w = mirrored[(c, i, j)];
                assert!((v - w).abs() < 1e-4, "{flip:?} ({c}, {i}, {j}): {v} vs {w}");
            }
            if flip[0] != flip[1] {
                assert!(g.slice(s![3..6, .., ..]).iter().any(|v| v.abs() > 0.5));
            }
        }
    }

    #[test]
    fn geometry_of_a_crop_equals_the_whole_maps() {
        let (h, w, p, px) = (30usize, 26usize, 8usize, 0.0025f32);
        let map = Array3::from_shape_fn((3, h, w), |(c, i, j)| {
            let (u, v) = (i as f32 * px, j as f32 * px);
            [
                u + 0.01 * (v * 90.0).sin(),
                v,
                0.02 * (u * 70.0).cos() * (v * 40.0).sin(),
            ][c]
        });
        let mask = Array2::from_shape_fn((h, w), |(i, j)| i + j > 6 && !(i > 20 && j > 18));
        let whole = geometry_channels(map.view(), mask.view(), px);
        for origin in [(0, 0), (3, 5), (11, 9), (h - p, w - p), (25, 22)] {
            let crop = crop_geometry(&map, &mask, origin, p, px);
            for ((c, i, j), &v) in crop.indexed_iter() {
                let (a, b) = (origin.0 + i, origin.1 + j);
                let expect = if a < h && b < w {
                    whole[(c, a, b)]
                } else {
                    0.0
                };
                assert_eq!(v, expect, "origin {origin:?} ({c}, {i}, {j})");
            }
        }
    }
}
