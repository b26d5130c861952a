//! `clothsr lab train corrector --data DIR… -o MODEL`: trains the corrector on data sets made by
//! `clothsr lab dataset` (see [`clothsr::corrector::training`]).

use std::path::PathBuf;

use anyhow::Context;
use clothsr::corrector::data::Sequence;
use clothsr::corrector::training::{
    train, Progress, Summary, TrainSet, TrainingConfig, ValidationSet, VALIDATION_LOG,
};
use clothsr::corrector::CorrectorConfig;
use clothsr::data::coarse_simulation;
use indicatif::{ProgressBar, ProgressStyle};

/// Arguments of `train`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(Debug, clap::Subcommand)]
enum What {
    /// The GNN corrector (M_c → M_int).
    Corrector(Box<CorrectorArgs>),
    /// The ISR network of mesh super-resolution (M_int coordinate map → fine map).
    Isr(Box<IsrArgs>),
}

/// Arguments of `train isr`.
#[derive(Debug, clap::Args)]
pub struct IsrArgs {
    /// Data set directories (`clothsr lab dataset`); repeat for several sequences.
    #[arg(value_parser = crate::cli::values::input_dir, long, required = true)]
    data: Vec<PathBuf>,
    /// Output model directory (an interrupted run there with the same settings resumes).
    #[arg(value_parser = crate::cli::values::output_dir, short, long)]
    output: PathBuf,
    /// Train on frames 1..=N of each data set only (keep the rest for evaluation).
    #[arg(long)]
    frames: Option<usize>,
    /// Optimiser steps.
    #[arg(long, default_value_t = 3000)]
    steps: usize,
    /// Patches per step.
    #[arg(long, default_value_t = 8)]
    batch: usize,
    /// Patch side, pixels (a multiple of the window).
    #[arg(long, default_value_t = 32)]
    patch: usize,
    /// Learning rate at the first step.
    #[arg(value_parser = crate::cli::values::positive(1.0), long, default_value_t = 4e-4)]
    lr_start: f64,
    /// Learning rate at the last step (exponential decay).
    #[arg(value_parser = crate::cli::values::positive(1.0), long, default_value_t = 1e-5)]
    lr_end: f64,
    /// Weight of the gradient term of the loss (0: positions only).
    #[arg(value_parser = crate::cli::values::non_negative(crate::cli::values::MAX_FACTOR), long, default_value_t = 10.0)]
    beta: f64,
    /// Leave out the previous frame's output as an input (the ablation of §4.2).
    #[arg(long)]
    no_init: bool,
    /// Leave out the coarse map's local geometry (stretch, normal and curvature: nine input
    /// channels beyond the paper; measured to lower the error, see the sample models' README).
    #[arg(long)]
    no_geometry_input: bool,
    /// Condition the network on each panel's fabric (bending, density, stretch) and the
    /// coarse/fine ratio: four more input channels, read from the data sets' manifests.
    #[arg(long)]
    condition: bool,
    /// Feature channels.
    #[arg(long, default_value_t = 32)]
    embed_dim: usize,
    /// Swin layers per residual block, one number per block.
    #[arg(long, value_delimiter = ',', num_args = 1, default_value = "2,2")]
    depths: Vec<usize>,
    /// Attention heads.
    #[arg(long, default_value_t = 4)]
    heads: usize,
    /// Attention window side, pixels.
    #[arg(long, default_value_t = 8)]
    window: usize,
    /// Pixel-unshuffle factor: the Swin body works on s × s pixel blocks (s² times cheaper;
    /// 1: every pixel a token, as SwinIR). Patches must be multiples of window × s.
    #[arg(long, default_value_t = 1)]
    unshuffle: usize,
    /// σ of the Gaussian smoothing of the training initialisation, pixels.
    #[arg(value_parser = crate::cli::values::non_negative(1e3), long, default_value_t = 1.0)]
    init_blur_px: f64,
    /// Standard deviation of the noise added to the training initialisation, mm.
    #[arg(value_parser = crate::cli::values::non_negative(crate::cli::values::MAX_MM), long, default_value_t = 0.1)]
    init_noise_mm: f64,
    /// Pass the previous frame's output as it is, without moving it by the coarse motion.
    #[arg(long)]
    no_init_motion: bool,
    /// Phong tessellation blend of the coarse map (0: piecewise-linear, as the paper).
    #[arg(value_parser = crate::cli::values::within(0.0, 1.0), long, default_value_t = 0.5)]
    phong_alpha: f64,
    /// Most frames a sample is rolled out through the network before its loss (its
    /// initialisation is then the network's own output; 0: always the data's).
    #[arg(long, default_value_t = 3)]
    unroll_max: usize,
    /// Probability that a training sample's initialisation is the coarse map itself (as on a
    /// shot's first frame) instead of the previous frame's ground truth.
    #[arg(value_parser = crate::cli::values::within(0.0, 1.0), long, default_value_t = 0.1)]
    coarse_init_prob: f64,
    /// Random seed.
    #[arg(long, default_value_t = 7)]
    seed: u64,
}

/// Arguments of `train corrector`.
#[derive(Debug, clap::Args)]
pub struct CorrectorArgs {
    /// Data set directories (`clothsr lab dataset`); repeat for several sequences.
    #[arg(value_parser = crate::cli::values::input_dir, long, required = true)]
    data: Vec<PathBuf>,
    /// Output model directory (an interrupted run there with the same settings resumes).
    #[arg(value_parser = crate::cli::values::output_dir, short, long)]
    output: PathBuf,
    /// Train on frames 1..=N of each data set only (keep the rest for evaluation).
    #[arg(long)]
    frames: Option<usize>,
    /// Phase-1 optimiser steps.
    #[arg(long, default_value_t = 5000)]
    steps: usize,
    /// Samples per step.
    #[arg(long, default_value_t = 4)]
    batch: usize,
    /// Learning rate at the first step.
    #[arg(value_parser = crate::cli::values::positive(1.0), long, default_value_t = 1e-4)]
    lr_start: f64,
    /// Learning rate at the last phase-1 step (exponential decay).
    #[arg(value_parser = crate::cli::values::positive(1.0), long, default_value_t = 1e-6)]
    lr_end: f64,
    /// Training noise, as a multiple of the data's RMS per-step position correction (GNS
    /// style; off by default, as it measured worse on the three balls' drops:
    /// `docs/experiments/three_balls.md`).
    #[arg(value_parser = crate::cli::values::non_negative(crate::cli::values::MAX_FACTOR), long, default_value_t = 0.0)]
    noise_ratio: f64,
    /// Vertices per random sub-mesh patch (0: whole meshes).
    #[arg(long, default_value_t = 0)]
    patch_nodes: usize,
    /// Phase-2 window-rollout optimiser steps (0: skip phase 2).
    #[arg(long, default_value_t = 0)]
    rollout_iters: usize,
    /// Phase-2 window, steps.
    #[arg(long, default_value_t = 8)]
    window: usize,
    /// Phase-2 learning rate.
    #[arg(value_parser = crate::cli::values::non_negative(1.0), long, default_value_t = 1e-5)]
    rollout_lr: f64,
    /// Phase-2 target's pull-back time, steps: the target is the ground truth's velocity plus a
    /// pull towards its positions over this many steps (1: land on them in one step).
    #[arg(value_parser = crate::cli::values::positive(crate::cli::values::MAX_FACTOR), long, default_value_t = 1.0)]
    rollout_tau: f64,
    /// Stop phase 2 once the mean loss of the last 20 windows is below this (0: never).
    #[arg(value_parser = crate::cli::values::non_negative(crate::cli::values::MAX_FACTOR), long, default_value_t = 0.0)]
    rollout_stop_loss: f64,
    /// Latent width of every MLP.
    #[arg(long, default_value_t = 64)]
    latent: usize,
    /// Message-passing blocks.
    #[arg(long, default_value_t = 8)]
    mp_steps: usize,
    /// GATv2-style attention on the edge aggregation.
    #[arg(long)]
    attention: bool,
    /// The decoder: `node` (the paper's: a free correction per vertex) or `gated` (a learned
    /// share of the simulator step's velocity change taken back, per-vertex terms only near
    /// colliders).
    #[arg(long, default_value = "gated")]
    decoder: clothsr::corrector::model::Decoder,
    /// The gated decoder's tension limit at inference, saved with the model: the share of
    /// the step's velocity change taken back falls linearly to zero as the mean strain of a
    /// vertex's edges after the step rises from 0 to this (the fine cloth's wrinkles take up
    /// compression, not tension); 0: no limit.
    /// [default: 0.01, or the `--init` model's]
    #[arg(value_parser = crate::cli::values::non_negative(1.0), long)]
    tension_ramp: Option<f64>,
    /// The gated decoder's take-back scale at inference, saved with the model: the share of
    /// the step's velocity change taken back is multiplied by this, in (0, 1] (taking back
    /// most of it also takes back the cloth's restoring force, and the corrected cloth drifts).
    /// [default: 1, or the `--init` model's]
    #[arg(value_parser = crate::cli::values::positive(1.0), long)]
    take_back: Option<f64>,
    /// Low-pass filter on the correction at inference, saved with the model: this many rounds
    /// of mass-weighted averaging over each vertex and its mesh neighbours before it is applied
    /// (0: none; the one-step targets' local part is the coarse mesh's spring-back out of
    /// M_int, which the interleaved run does not have). [default: 0, or the `--init` model's]
    #[arg(long)]
    smoothing: Option<usize>,
    /// The gated decoder's lowest share, fixed when the network is made (not with `--init`):
    /// the learned share of the step's velocity change taken back lies in (m, 1); below 0
    /// the corrector may also amplify the step's response. [default: 0]
    #[arg(value_parser = crate::cli::values::within(-crate::cli::values::MAX_FACTOR, 1.0), long, allow_hyphen_values = true)]
    share_min: Option<f64>,
    /// Held-out data sets to select the network on (repeat for several; never a training
    /// set): at the end of each phase (with `--init`, the starting model too) and every
    /// `--validate-every` phase-2 windows the network is rolled out interleaved with the
    /// simulator on them, and the one closest to their ground truth is saved
    /// (`validation.csv` beside the model logs every validation).
    #[arg(value_parser = crate::cli::values::input_dir, long)]
    val_data: Vec<PathBuf>,
    /// Validate every this many phase-2 windows (with `--val-data`).
    #[arg(long, default_value_t = 100)]
    validate_every: usize,
    /// Roll out frames 1..=N of each validation set (default: all).
    #[arg(long)]
    val_frames: Option<usize>,
    /// Random seed.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    // The coarse model trained beside, saved with the model, which then runs with it
    // (unset: the `--init` model's, else the simulator's).
    #[command(flatten)]
    coarse: crate::cli::CoarseArgs,
    /// Start from this trained corrector (a model directory): its network sizes, decoder,
    /// inference settings, coarse membrane, weights and normalisation, instead of fresh
    /// weights (fine-tuning: more phase-2 windows with `--steps 0`, or new sequences).
    #[arg(value_parser = crate::cli::values::input_dir, long, value_name = "MODEL", conflicts_with_all = ["latent", "mp_steps", "attention", "decoder"])]
    init: Option<PathBuf>,
}

/// Runs `train`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.what {
        What::Corrector(a) => corrector(*a),
        What::Isr(a) => isr(*a),
    }
}

fn corrector(a: CorrectorArgs) -> anyhow::Result<()> {
    let cfg = training_config(&a)?;
    let validation = validation_sets(&a, &cfg)?;
    let mut sets = train_sets(&a, &cfg)?;
    let summary = train_with_progress(&cfg, &mut sets, &validation, &a.output)?;
    log_summary(&cfg, &summary, &a.output);
    Ok(())
}

/// The training settings the arguments give, checked.
fn training_config(a: &CorrectorArgs) -> anyhow::Result<TrainingConfig> {
    anyhow::ensure!(
        a.steps > 0 || a.rollout_iters > 0,
        "nothing to train: --steps and --rollout-iters are 0"
    );
    anyhow::ensure!(
        a.latent > 0 && a.mp_steps > 0,
        "--latent and --mp-steps must be at least 1"
    );
    // With --init, the network and the coarse membrane are the model's; inference settings
    // given here override its own.
    let init = init_config(a)?;
    let model = model_config(a, init.as_ref())?;
    let given = a.coarse.calibration();
    given.check_flags()?;
    let trained_beside = init.as_ref().map(|c| c.coarse).unwrap_or_default();
    let coarse = given.replacing(&trained_beside).unwrap_or(trained_beside);
    let cfg = TrainingConfig::new(model)
        .with_steps(a.steps)
        .with_batch(a.batch)
        .with_lr_start(a.lr_start)
        .with_lr_end(a.lr_end)
        .with_noise_ratio(a.noise_ratio)
        .with_patch_nodes(a.patch_nodes)
        .with_rollout_iters(a.rollout_iters)
        .with_window(a.window)
        .with_rollout_lr(a.rollout_lr)
        .with_rollout_stop_loss(a.rollout_stop_loss)
        .with_rollout_tau_steps(a.rollout_tau)
        .with_seed(a.seed)
        .with_coarse(coarse)
        .with_init_from(a.init.clone())
        .with_validate_every((!a.val_data.is_empty()).then_some(a.validate_every))
        .with_validation_frames(a.val_frames.filter(|_| !a.val_data.is_empty()));
    anyhow::ensure!(a.validate_every > 0, "--validate-every must be at least 1");
    Ok(cfg)
}

/// The training settings of the `--init` model, if any.
fn init_config(a: &CorrectorArgs) -> anyhow::Result<Option<TrainingConfig>> {
    let Some(dir) = &a.init else {
        return Ok(None);
    };
    let path = dir.join(clothsr::corrector::inference::CONFIG_FILE);
    let cfg = TrainingConfig::load(&path)
        .with_context(|| format!("{} is not a corrector to start from", dir.display()))?;
    Ok(Some(cfg))
}

/// The network: the `--init` model's or a new one, with the inference settings given.
fn model_config(
    a: &CorrectorArgs,
    init: Option<&TrainingConfig>,
) -> anyhow::Result<CorrectorConfig> {
    let mut model = match init {
        Some(old) => old.model.clone(),
        None => CorrectorConfig::new()
            .with_latent(a.latent)
            .with_steps(a.mp_steps)
            .with_attention(a.attention)
            .with_decoder(a.decoder),
    };
    if let Some(r) = a.tension_ramp {
        model.tension_ramp = r;
    }
    if let Some(k) = a.take_back {
        model.take_back = k;
    }
    if let Some(n) = a.smoothing {
        model.smoothing = n;
    }
    if let Some(m) = a.share_min {
        anyhow::ensure!(
            init.is_none(),
            "--share-min shapes a new network; it cannot change the --init model's"
        );
        model.share_min = m;
    }
    Ok(model)
}

/// The coarse simulation a data set was made with, with the coarse model trained beside.
fn prepared_simulation(
    cfg: &TrainingConfig,
    scene: &clothsr::scene::Scene,
    dir: &std::path::Path,
) -> anyhow::Result<clothsr::sim::driver::Simulation> {
    let mut sim = coarse_simulation(scene, dir, 1)?;
    cfg.prepare_coarse(&mut sim)?;
    Ok(sim)
}

/// The `--val-data` sets.
fn validation_sets(a: &CorrectorArgs, cfg: &TrainingConfig) -> anyhow::Result<Vec<ValidationSet>> {
    let mut validation = Vec::new();
    for dir in &a.val_data {
        let scene = data_scene(dir)?;
        let m = clothsr::data::read_manifest(dir)?;
        // One frame more than rolled out: the rollout starts at the first loaded frame.
        let frames = a.val_frames.map(|n| 1..=(n + 1).min(m.frames_done));
        let sim = prepared_simulation(cfg, &scene, dir)?;
        let seq = Sequence::load(dir, frames, &sim)?;
        validation.push(ValidationSet { seq, scene });
    }
    Ok(validation)
}

/// The `--data` sets, each with its simulator for phase 2.
fn train_sets(a: &CorrectorArgs, cfg: &TrainingConfig) -> anyhow::Result<Vec<TrainSet>> {
    let mut sets = Vec::new();
    for dir in &a.data {
        let m = clothsr::data::read_manifest(dir)?;
        let frames = a.frames.map(|n| 1..=n.min(m.frames_done));
        let scene = data_scene(dir)?;
        let sim = prepared_simulation(cfg, &scene, dir)?;
        let t0 = sim.state.t_s;
        let mut seq = Sequence::load(dir, frames, &sim)?;
        // M_c from this simulator, in a fresh instance (a simulator carries warm starts).
        let mut fresh = prepared_simulation(cfg, &scene, dir)?;
        seq.recompute_coarse(&mut fresh, t0)?;
        let sim = (a.rollout_iters > 0).then_some((sim, t0));
        tracing::info!(
            "{}: {} steps, {} coarse vertices, {} edges",
            dir.display(),
            seq.steps.len(),
            seq.graph.num_nodes,
            seq.graph.num_edges()
        );
        sets.push(TrainSet { seq, sim });
    }
    Ok(sets)
}

/// Trains, showing each phase's progress and mean recent loss (logged when there is no
/// terminal to draw a bar on).
fn train_with_progress(
    cfg: &TrainingConfig,
    sets: &mut [TrainSet],
    validation: &[ValidationSet],
    output: &std::path::Path,
) -> anyhow::Result<Summary> {
    let bar = ProgressBar::new(cfg.steps as u64);
    bar.set_style(
        ProgressStyle::with_template("phase {msg} {bar:30} {pos}/{len} {per_sec} eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut phase = 1;
    let mut recent = Vec::new();
    let summary = train(cfg, sets, validation, output, |p: &Progress| {
        if p.phase != phase {
            phase = p.phase;
            bar.set_length(p.total as u64);
            bar.reset();
            recent.clear();
        }
        recent.push(p.loss);
        if recent.len() > 50 {
            recent.remove(0);
        }
        let mean = recent.iter().sum::<f64>() / recent.len() as f64;
        bar.set_position(p.step as u64);
        bar.set_message(format!("{} loss {mean:.4}", p.phase));
        if bar.is_hidden() && p.step.is_multiple_of(250) {
            tracing::info!(
                "phase {} step {}/{}: loss {mean:.4}",
                p.phase,
                p.step,
                p.total
            );
        }
        std::ops::ControlFlow::Continue(())
    })?;
    bar.finish_and_clear();
    Ok(summary)
}

/// Logs what training did and, with validation, which network was kept.
fn log_summary(cfg: &TrainingConfig, summary: &Summary, output: &std::path::Path) {
    let phase1 = match (&cfg.init_from, cfg.steps) {
        (Some(init), 0) => format!("no phase 1 (started from {})", init.display()),
        _ => format!(
            "phase 1 loss {:.4} → {:.4}; noise σ {:.4} mm",
            summary.phase1_first_last.0,
            summary.phase1_first_last.1,
            summary.noise_std_m * 1e3
        ),
    };
    tracing::info!(
        "wrote {}: {phase1}; phase 2 ({} windows) {:.4} → {:.4}; {:.0} s",
        output.display(),
        summary.phase2_iters,
        summary.phase2_first_last.0,
        summary.phase2_first_last.1,
        summary.seconds
    );
    if let Some((mm, phase, step)) = summary.validation_best {
        let which = match (&cfg.init_from, phase, step) {
            (Some(init), 1, 0) => format!(
                "the starting model {} (no phase-2 network validated better)",
                init.display()
            ),
            _ => format!("the network of phase {phase} step {step}"),
        };
        tracing::info!(
            "kept {which}: {mm:.3} mm interleaved on the validation sets (all validations in {})",
            output.join(VALIDATION_LOG).display()
        );
    }
}

/// The scene a data set was made from (the corrector needs its colliders).
fn data_scene(dir: &std::path::Path) -> anyhow::Result<clothsr::scene::Scene> {
    let m = clothsr::data::read_manifest(dir)?;
    let source = m.source.as_ref().with_context(|| {
        format!(
            "{}: the corrector needs the data set's colliders, but this data set does not \
             record its scene files (made by an older clothsr)",
            dir.join("manifest.json").display()
        )
    })?;
    source
        .load()
        .with_context(|| format!("loading the scene of {}", dir.display()))
}

fn isr(a: IsrArgs) -> anyhow::Result<()> {
    use clothsr::msr::data::IsrSequence;
    use clothsr::msr::model::IsrConfig;
    use clothsr::msr::training::{self, IsrTrainingConfig};
    anyhow::ensure!(a.steps > 0, "nothing to train: --steps is 0");
    let first = clothsr::data::read_manifest(&a.data[0])?;
    let pixel_m = first.fine_edge_m;
    let model = IsrConfig::new()
        .with_embed_dim(a.embed_dim)
        .with_depths(a.depths.clone())
        .with_heads(a.heads)
        .with_window(a.window)
        .with_init_input(!a.no_init)
        .with_geometry_input(Some(!a.no_geometry_input))
        .with_unshuffle(Some(a.unshuffle))
        .with_condition_input(Some(a.condition));
    model
        .check()
        .map_err(|e| anyhow::anyhow!("ISR network: {e}"))?;
    let cfg = IsrTrainingConfig::new(model, pixel_m)
        .with_steps(a.steps)
        .with_batch(a.batch)
        .with_patch(a.patch)
        .with_lr_start(a.lr_start)
        .with_lr_end(a.lr_end)
        .with_beta(a.beta)
        .with_init_blur_px(a.init_blur_px)
        .with_init_noise_m(a.init_noise_mm * 1e-3)
        .with_init_motion(!a.no_init_motion)
        .with_unroll_max(a.unroll_max)
        .with_coarse_init_prob(a.coarse_init_prob)
        .with_phong_alpha(a.phong_alpha)
        .with_seed(a.seed);
    let mut seqs = Vec::new();
    for dir in &a.data {
        let m = clothsr::data::read_manifest(dir)?;
        let frames = a.frames.map(|n| 1..=n.min(m.frames_done));
        let seq = IsrSequence::load(dir, frames, pixel_m, cfg.phong_alpha, cfg.init_blur_px)?;
        tracing::info!(
            "{}: {} frames, {} panel maps ({}), {} fine vertices",
            dir.display(),
            seq.frames.len(),
            seq.grids.len(),
            seq.grids
                .iter()
                .map(|g| format!("{}×{}", g.shape().0, g.shape().1))
                .collect::<Vec<_>>()
                .join(", "),
            seq.fine_mesh.num_vertices()
        );
        seqs.push(seq);
    }
    let bar = ProgressBar::new(a.steps as u64);
    bar.set_style(
        ProgressStyle::with_template("ISR {msg} {bar:30} {pos}/{len} {per_sec} eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut recent = Vec::new();
    let summary = training::train(&cfg, &seqs, &a.output, |p: &training::Progress| {
        recent.push(p.loss);
        if recent.len() > 50 {
            recent.remove(0);
        }
        let mean = recent.iter().sum::<f64>() / recent.len() as f64;
        bar.set_position(p.step as u64);
        bar.set_message(format!("loss {mean:.4}"));
        if bar.is_hidden() && p.step.is_multiple_of(100) {
            tracing::info!("step {}/{}: loss {mean:.4}", p.step, p.total);
        }
        std::ops::ControlFlow::Continue(())
    })?;
    bar.finish_and_clear();
    tracing::info!(
        "wrote {}: loss {:.4} → {:.4}; {:.0} s",
        a.output.display(),
        summary.first_last.0,
        summary.first_last.1,
        summary.seconds
    );
    Ok(())
}
