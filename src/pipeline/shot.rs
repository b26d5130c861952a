//! One shot through the whole pipeline into files: what `clothsr run` and the Python package's
//! `clothsr.run` do. [`RunModels`] loads a models folder once (several shots can share it);
//! [`run_shot`] loads a shot, sets the pipeline up and runs it into its [`ShotFiles`].

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use super::{
    choose_path, options_for_run, run_to_files, CoarseCalibration, CorrectorChoice, ModelPath,
    Options, Outputs, Pipeline, Preview, Progress, Report,
};
use crate::data::SceneSource;
use crate::error::{Error, Result};
use crate::eval::Animation;
use crate::msr::Isr;
use crate::viz::Recorder;

/// A models folder loaded for runs: the ISR network, the path taken through the folder and the
/// pipeline options it gives.
pub struct RunModels {
    /// The folder.
    pub dir: PathBuf,
    /// The MSR module's network.
    pub isr: Isr,
    /// The corrector's folder, when the path taken has one.
    pub corrector: Option<PathBuf>,
    /// The pipeline's options under the settings given.
    pub opts: Options,
    /// Why this path (with the held-out figures it was validated with), in words.
    pub why: String,
    /// The folder's coarse calibration, when the options took it.
    pub calibration: Option<CoarseCalibration>,
}

impl RunModels {
    /// Loads the folder `dir` (`isr/` required; `corrector/`, `coarse.json` and
    /// `models.json` optional) for runs under `given`, taking the path `choice` asks for.
    pub fn load(dir: &Path, choice: CorrectorChoice, given: Options) -> Result<RunModels> {
        given.check()?;
        let isr_dir = dir.join("isr");
        if !isr_dir.join("config.json").exists() {
            return Err(Error::bad_input(
                dir,
                format!(
                    "no ISR model here (expected {}; train one with 'clothsr lab train isr')",
                    isr_dir.join("config.json").display()
                ),
            ));
        }
        let isr = Isr::load(&isr_dir)?;
        let (path, why) = choose_path(dir, choice)?;
        let corrector = (path == ModelPath::Corrector).then(|| dir.join("corrector"));
        let (opts, calibration) = options_for_run(dir, corrector.as_deref(), given)?;
        Ok(RunModels {
            dir: dir.to_path_buf(),
            isr,
            corrector,
            opts,
            why: format!("{path} ({why})"),
            calibration,
        })
    }
}

/// How a run writes the fine garments: `auto`, `on` (a layer) or `off` (a standalone stage).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum OutputKind {
    /// An override layer for a USD shot, a standalone stage for other inputs.
    #[default]
    Auto,
    /// An override layer for the USD shot ([`crate::io::usd::OverLayer`]): sublayered over
    /// the shot, it replaces each garment with its fine animated mesh at the garment's prim.
    #[value(name = "on")]
    Layer,
    /// A standalone stage: the fine garments under `/World/Garments`, the colliders under
    /// `/World/Colliders`, in metres with y up.
    #[value(name = "off")]
    Standalone,
}

impl std::str::FromStr for OutputKind {
    type Err = String;
    /// The names the command line takes.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        <Self as clap::ValueEnum>::from_str(s.trim(), false)
            .map_err(|_| format!("layer '{s}': expected auto, on or off"))
    }
}

/// Frames per value clip of a layered output unless asked otherwise.
pub const DEFAULT_CLIP_FRAMES: usize = 100;

/// Where one shot's run writes, and what it shows.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ShotFiles {
    /// The fine garments, one time sample per frame (USD).
    pub output: PathBuf,
    /// Also the coarse mesh the MSR module saw (M_int, or M_c without corrector).
    pub coarse: Option<PathBuf>,
    /// Also the coarse mesh upsampled to the fine one (the baseline without learned detail).
    pub upsampled: Option<PathBuf>,
    /// A Rerun recording to save.
    pub rrd: Option<PathBuf>,
    /// Stream live to a Rerun viewer instead.
    pub spawn: bool,
    /// A fine simulation of the same shot (USD, or a `clothsr lab dataset` directory) that the
    /// Rerun preview colours the fine mesh against.
    pub ground_truth: Option<PathBuf>,
    /// Text USD even for a `.usd` file.
    pub ascii: bool,
    /// Start over even when an interrupted run with the same settings left a resume point.
    pub restart: bool,
    /// An override layer or a standalone stage.
    pub kind: OutputKind,
    /// A layered output's frames per value clip (0: every frame in the layer).
    pub clip_frames: usize,
    /// Seconds between publishing the files and the resume point while running (`None`: every
    /// [`DEFAULT_PUBLISH_EVERY_S`]).
    pub publish_every_s: Option<f64>,
    /// Distance shown red in the ground-truth heat map of the Rerun preview, m (`None`:
    /// [`DEFAULT_HEAT_MAX_M`]).
    pub heat_max_m: Option<f64>,
}

/// Distance shown red in the Rerun preview's ground-truth heat map unless asked otherwise, m.
pub const DEFAULT_HEAT_MAX_M: f64 = 5e-3;

/// Seconds between publishing a run's files and resume point unless asked otherwise.
pub const DEFAULT_PUBLISH_EVERY_S: f64 = 10.0;

/// What [`run_shot`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShotReport {
    /// The frame loop's report.
    pub run: Report,
    /// Coarse and fine vertex counts.
    pub coarse_vertices: usize,
    /// Fine vertices.
    pub fine_vertices: usize,
}

/// An absolute path (recorded in the resume fingerprint).
fn absolute(p: &Path) -> Result<PathBuf> {
    std::path::absolute(p).map_err(|e| Error::io(p, e))
}

/// Runs `frames` frames (default: the shot's range) of the shot `source` with `models` (under
/// their options) into `files`, calling `progress` after every frame (`Break` stops after
/// publishing the frames so far and a resume point). An interrupted run with the same settings
/// resumes from its last published frame unless `files.restart`.
pub fn run_shot(
    models: &RunModels,
    source: &SceneSource,
    files: &ShotFiles,
    frames: Option<usize>,
    progress: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<ShotReport> {
    for extra in [&files.coarse, &files.upsampled].into_iter().flatten() {
        crate::io::usd::check_extension(extra)?;
    }
    crate::io::usd::check_extension(&files.output)?;
    if files
        .publish_every_s
        .is_some_and(|s| !(s.is_finite() && s >= 0.0))
    {
        return Err(Error::Usage(
            "the publishing interval must be a number of seconds >= 0".into(),
        ));
    }
    if files
        .heat_max_m
        .is_some_and(|h| !(h.is_finite() && h > 0.0))
    {
        return Err(Error::Usage(
            "the heat map's maximum distance must be positive".into(),
        ));
    }
    if files.ground_truth.is_some() && files.rrd.is_none() && !files.spawn {
        return Err(Error::Usage(
            "a ground truth colours the Rerun preview: save or stream one with it".into(),
        ));
    }
    let mut scene = source.load()?;
    models.opts.variation.apply(&mut scene);
    let frames = frames.unwrap_or((scene.frame_end - scene.frame_start).max(0) as usize);
    if frames == 0 {
        return Err(Error::bad_input(
            &source.scene,
            "nothing to run: the scene's frame range is empty (give a number of frames)",
        ));
    }
    let t_setup = std::time::Instant::now();
    let mut p = Pipeline::with_dress_cache(
        &scene,
        &models.isr,
        models.corrector.as_deref(),
        models.opts,
        Some(&crate::io::dressed::dressed_path(&files.output)),
    )?;
    tracing::info!(
        "{}: coarse {} vertices, fine {} vertices ({} mm pixels), corrector {}; set up in {:.1} s",
        source.scene.display(),
        p.coarse.sim.model.num_vertices(),
        p.fine.num_vertices(),
        models.isr.cfg.pixel_m * 1e3,
        if p.has_corrector() { "on" } else { "off" },
        t_setup.elapsed().as_secs_f64()
    );
    let rec = match (&files.rrd, files.spawn) {
        (Some(path), _) => Some(Recorder::save("clothsr", path)?),
        (None, true) => Some(Recorder::spawn("clothsr")?),
        (None, false) => None,
    };
    let gt = ground_truth(
        files.ground_truth.as_deref(),
        scene.frame_start as f64,
        &p,
        &models.isr,
    )?;
    let preview = rec.as_ref().map(|r| Preview {
        recorder: r,
        ground_truth: gt.as_ref(),
        heat_max_m: files.heat_max_m.unwrap_or(DEFAULT_HEAT_MAX_M),
    });
    let layer = match files.kind {
        OutputKind::Standalone => false,
        OutputKind::Layer => true,
        OutputKind::Auto => {
            crate::io::FileKind::of(&source.scene)? == crate::io::FileKind::Usd
                && !scene.sources.is_empty()
        }
    };
    // Everything that shapes the output: a resume point made with other settings is ignored.
    let fingerprint = format!(
        "scene={} models={} corrector={} frames={frames} opts={:?} \
         colliders={:?} avatar={:?} fabric={} layer={:?}",
        absolute(&source.scene)?.display(),
        absolute(&models.dir)?.display(),
        p.has_corrector(),
        models.opts,
        source.colliders,
        source.avatar,
        source.fabric,
        layer.then_some(files.clip_frames)
    );
    let outputs = Outputs {
        fine: files.output.clone(),
        coarse: files.coarse.clone(),
        upsampled: files.upsampled.clone(),
        ascii: files.ascii,
        doc: format!(
            "clothsr run {} with models {} (corrector {})",
            source.scene.display(),
            models.dir.display(),
            if p.has_corrector() { "on" } else { "off" }
        ),
        resume: !files.restart,
        fingerprint,
        publish_every_s: files.publish_every_s.unwrap_or(DEFAULT_PUBLISH_EVERY_S),
        layer: layer.then_some(files.clip_frames),
    };
    let report = run_to_files(&mut p, &scene, frames, &outputs, preview.as_ref(), progress)?;
    if let Some(r) = rec {
        if let Some(path) = r.finish()? {
            tracing::info!("wrote {}", path.display());
        }
    }
    Ok(ShotReport {
        run: report,
        coarse_vertices: p.coarse.sim.model.num_vertices(),
        fine_vertices: p.fine.num_vertices(),
    })
}

/// The ground truth `path` (a USD file, or a data set's fine frames from time code `start`),
/// checked to be the fine mesh of this run.
fn ground_truth(
    path: Option<&Path>,
    start: f64,
    p: &Pipeline<'_>,
    isr: &Isr,
) -> Result<Option<Animation>> {
    let Some(path) = path else {
        return Ok(None);
    };
    let gt = Animation::read(path, start)?;
    if gt.num_vertices() != p.fine.num_vertices() || gt.triangles != p.fine.triangles {
        return Err(Error::bad_input(
            path,
            format!(
                "not the fine mesh of this run ({} vertices against {}): simulate it at the ISR \
                 model's pixel size ({} mm)",
                gt.num_vertices(),
                p.fine.num_vertices(),
                isr.cfg.pixel_m * 1e3
            ),
        ));
    }
    Ok(Some(gt))
}

/// What happened to one shot of a run or a batch, as `clothsr run --json` reports it (and the
/// Ray batch, one line per shot).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ShotSummary {
    /// The shot.
    pub scene: PathBuf,
    /// Its output.
    pub output: PathBuf,
    /// Whether it went through.
    pub status: Status,
    /// Frames computed in this call.
    pub frames_computed: usize,
    /// The frame a resumed run started after.
    pub resumed_after: Option<usize>,
    /// Wall time of the shot, s.
    pub wall_s: f64,
    /// Why it failed.
    pub error: Option<ErrorSummary>,
}

/// An error in a summary: its kind (`usage`, `input`, `failure`) and its message.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ErrorSummary {
    /// Its kind: `usage`, `input` or `failure` in JSON.
    pub kind: crate::ErrorKind,
    /// The message, with its causes.
    pub message: String,
}

/// Where a shot's output goes in a batch's output folder: `out_dir/<the scene's stem>.usdc`
/// (`None` for a path with no file name).
pub fn shot_output(scene: &Path, out_dir: &Path) -> Option<PathBuf> {
    let stem = scene.file_stem()?.to_string_lossy();
    Some(out_dir.join(format!("{stem}.usdc")))
}

/// Whether a shot, or a whole run, went through: `ok` or `failed` in JSON.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Done.
    Ok,
    /// Failed (the summary's error says why).
    Failed,
}

/// What a run or a batch did, as `clothsr run --json` prints it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunSummary {
    /// Failed when any shot (or the run before any shot) failed.
    pub status: Status,
    /// The exit code: 0, or the code of the most severe failure ([`crate::ErrorKind::exit_code`]).
    pub exit_code: i32,
    /// An error before any shot ran (bad usage, a models folder that does not load).
    pub error: Option<ErrorSummary>,
    /// Each shot, in order.
    pub shots: Vec<ShotSummary>,
}

impl RunSummary {
    /// The summary of `shots`, with `error` before any shot when there was one.
    pub fn of(shots: Vec<ShotSummary>, error: Option<(crate::ErrorKind, String)>) -> RunSummary {
        let mut kinds: Vec<crate::ErrorKind> = shots
            .iter()
            .filter_map(|s| s.error.as_ref().map(|e| e.kind))
            .collect();
        kinds.extend(error.as_ref().map(|(k, _)| *k));
        let exit_code = kinds.iter().map(|k| k.exit_code()).max().unwrap_or(0);
        RunSummary {
            status: if exit_code == 0 {
                Status::Ok
            } else {
                Status::Failed
            },
            exit_code,
            error: error.map(|(kind, message)| ErrorSummary { kind, message }),
            shots,
        }
    }
}
