//! `clothsr fit`: the best models for one garment and shot.
//!
//! A fit first writes a deterministic plan ([`Plan`], `plan.json`): the variations of the shot
//! to simulate (the shot as given, turned, moved and started later in its motion), each a
//! data set task, then the tasks that need them: the coarse model calibrated on the training
//! variations, the ISR network trained on them (fine-tuned from the generic one where it
//! fits), and the held-out measurement written to `report.md`. Tasks are independent units
//! (what a cluster fans out); each one done is recorded in `tasks/`, so a fit killed at any
//! point and run again goes on where it stopped, with the same result.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::calibrate::{best, score, CalibrationSet, Grid, Scored};
use super::CoarseCalibration;
use crate::data::{SceneSource, Variation};
use crate::dataset::{generate, Options};
use crate::error::{Error, Result};
use crate::eval::FrameMetrics;
use crate::io::write_atomic;
use crate::msr::data::IsrSequence;
use crate::msr::eval::evaluate;
use crate::msr::model::IsrConfig;
use crate::msr::training::{train, IsrTrainingConfig};
use crate::msr::Isr;

/// Version of `plan.json`.
pub const PLAN_VERSION: u32 = 2;
/// The plan's file in a fit's folder.
pub const PLAN_FILE: &str = "plan.json";

/// How much a fit simulates and trains.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Quality {
    /// Two training variations and one held out, 30 frames each.
    Preview,
    /// Five training variations and two held out, 90 frames each.
    Final,
}

impl FromStr for Quality {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "preview" => Ok(Quality::Preview),
            "final" => Ok(Quality::Final),
            _ => Err(format!("quality '{s}': expected preview or final")),
        }
    }
}

/// Whether a variation trains or measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// Trained and calibrated on.
    Train,
    /// Only measured on.
    HeldOut,
}

/// One variation of the shot and the data set made of it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlannedVariation {
    /// Its name, also its data set's folder under `data/`.
    pub id: String,
    /// Training or held out.
    pub role: Role,
    /// How the shot is varied.
    pub variation: Variation,
}

/// What a task does.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum TaskKind {
    /// The fine and coarse simulation of one variation (`data/<variation>`).
    Dataset {
        /// The variation's id.
        variation: String,
    },
    /// The held-out variation's fine simulation again from its first frame with the garment
    /// moved 0.1 mm (`data/<variation>_twin`): the shot's predictability floor, which no
    /// prediction is expected to beat.
    Twin {
        /// The variation's id.
        variation: String,
    },
    /// The coarse model calibrated over the training data sets (`coarse.json`).
    Calibrate,
    /// The ISR network trained on the training data sets (`isr/`).
    TrainIsr,
    /// The models measured on the held-out data sets (`report.md`).
    Evaluate,
}

/// One unit of work and the tasks it needs done first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Task {
    /// Unique id; a finished task leaves `tasks/<id>.done`.
    pub id: String,
    /// What it does.
    #[serde(flatten)]
    pub kind: TaskKind,
    /// Ids of the tasks it needs.
    pub after: Vec<String>,
}

/// Everything a fit does, decided before it starts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// [`PLAN_VERSION`].
    pub format_version: u32,
    /// The shot's files.
    pub shot: SceneSource,
    /// Its size.
    pub quality: Quality,
    /// Coarse and fine edge lengths, m.
    pub coarse_edge_m: f64,
    /// Fine edge length, m (the ISR network's pixel).
    pub fine_edge_m: f64,
    /// Frames of every variation.
    pub frames: usize,
    /// Coarse steps in fast mode and no self-collision at either resolution, as the shipped
    /// models' data (the fine simulations always run in data mode).
    pub fast: bool,
    /// The ISR model fine-tuned from (`None`: trained from scratch).
    pub fine_tune_from: Option<PathBuf>,
    /// Optimiser steps of the ISR training.
    pub isr_steps: usize,
    /// The variations.
    pub variations: Vec<PlannedVariation>,
    /// The tasks, in an order that runs each after those it needs.
    pub tasks: Vec<Task>,
}

/// What a fit is asked for, beyond the shot.
#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    /// Its size.
    pub quality: Quality,
    /// Coarse edge length, m.
    pub coarse_edge_m: f64,
    /// Fine edge length, m.
    pub fine_edge_m: f64,
    /// Frames of each variation (`None`: the quality's).
    pub frames: Option<usize>,
    /// ISR optimiser steps (`None`: the quality's).
    pub isr_steps: Option<usize>,
    /// A trained ISR model to fine-tune (the generic one), used when its pixel is the fine
    /// edge.
    pub generic_isr: Option<PathBuf>,
}

/// (yaw °, garment offset m, clip start s) of the training and held-out variations.
type Turn = (f64, [f64; 3], f64);
const PREVIEW_TRAIN: [Turn; 2] = [(0.0, [0.0; 3], 0.0), (20.0, [0.01, 0.0, -0.01], 0.5)];
const PREVIEW_HELD_OUT: [Turn; 1] = [(-15.0, [-0.01, 0.0, 0.015], 0.25)];
const FINAL_TRAIN: [Turn; 5] = [
    (0.0, [0.0; 3], 0.0),
    (20.0, [0.01, 0.0, -0.01], 0.5),
    (-25.0, [-0.015, 0.0, 0.01], 1.0),
    (40.0, [0.02, 0.0, 0.02], 1.5),
    (-40.0, [-0.02, 0.0, -0.015], 2.0),
];
const FINAL_HELD_OUT: [Turn; 2] = [
    (-15.0, [-0.01, 0.0, 0.015], 0.25),
    (30.0, [0.015, 0.0, -0.02], 1.25),
];

impl Plan {
    /// The plan for `shot` (whose scene is `scene`: an animated collider makes the variations
    /// start later in its motion, move the garment half as far and turn it a quarter as far).
    pub fn new(shot: SceneSource, scene: &crate::scene::Scene, opts: &FitOptions) -> Result<Plan> {
        let ok = |v: f64| v.is_finite() && v > 0.0;
        if !ok(opts.coarse_edge_m)
            || !ok(opts.fine_edge_m)
            || opts.coarse_edge_m <= opts.fine_edge_m
        {
            return Err(Error::Invalid(format!(
                "the coarse edge ({} m) must be longer than the fine one ({} m)",
                opts.coarse_edge_m, opts.fine_edge_m
            )));
        }
        let animated = scene.colliders.iter().any(|c| c.is_animated());
        let (train_turns, held_turns, frames, steps): (&[Turn], &[Turn], usize, usize) =
            match opts.quality {
                Quality::Preview => (&PREVIEW_TRAIN, &PREVIEW_HELD_OUT, 30, 2000),
                Quality::Final => (&FINAL_TRAIN, &FINAL_HELD_OUT, 90, 8000),
            };
        // A garment on a moving body is worn as it was made: its variations come from the
        // motion (another stretch of the clip) and it is moved and turned less. Turned 20°, a
        // pencil skirt's side seams lay across the thighs and its dressing caught on one.
        let variation = |&(yaw, off, clip): &Turn| Variation {
            garment_offset_m: off.map(|o| if animated { 0.5 * o } else { o }),
            collider_offset_m: [0.0; 3],
            garment_yaw_deg: if animated { 0.25 * yaw } else { yaw },
            clip_start_s: if animated { clip } else { 0.0 },
        };
        let mut variations = Vec::new();
        for (k, t) in train_turns.iter().enumerate() {
            variations.push(PlannedVariation {
                id: format!("train_{k}"),
                role: Role::Train,
                variation: variation(t),
            });
        }
        for (k, t) in held_turns.iter().enumerate() {
            variations.push(PlannedVariation {
                id: format!("held_out_{k}"),
                role: Role::HeldOut,
                variation: variation(t),
            });
        }
        let fine_tune_from = opts.generic_isr.clone().filter(|dir| {
            Isr::load(dir).is_ok_and(|isr| (isr.cfg.pixel_m - opts.fine_edge_m).abs() < 1e-9)
        });
        let frames = opts.frames.unwrap_or(frames).max(2);
        let isr_steps = opts.isr_steps.unwrap_or(if fine_tune_from.is_some() {
            steps / 2
        } else {
            steps
        });
        Ok(Plan {
            format_version: PLAN_VERSION,
            shot,
            quality: opts.quality,
            coarse_edge_m: opts.coarse_edge_m,
            fine_edge_m: opts.fine_edge_m,
            frames,
            fast: true,
            fine_tune_from,
            isr_steps,
            tasks: tasks(&variations),
            variations,
        })
    }

    /// The same plan naming its files from folder `base`, as `base/plan.json` holds it.
    fn relative_to(&self, base: &Path) -> Plan {
        self.map_paths(|p| crate::io::relative_to(p, base))
    }

    /// The same plan with `f` applied to every file it names.
    fn map_paths(&self, f: impl Fn(&Path) -> PathBuf) -> Plan {
        Plan {
            shot: self.shot.map_paths(&f),
            fine_tune_from: self.fine_tune_from.as_deref().map(&f),
            ..self.clone()
        }
    }

    /// The plan a fit wrote in `dir` ([`save_plan`]), its files resolved.
    pub fn load(dir: &Path) -> Result<Plan> {
        let path = dir.join(PLAN_FILE);
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        let plan = serde_json::from_str::<Plan>(&text)
            .map_err(|e| Error::bad_input(&path, e.to_string()))?
            .map_paths(|p| crate::io::resolve_against(p, dir));
        if plan.format_version != PLAN_VERSION {
            return Err(Error::bad_input(
                &path,
                format!(
                    "plan format {} (this clothsr reads {PLAN_VERSION})",
                    plan.format_version
                ),
            ));
        }
        Ok(plan)
    }

    /// The variations of `role`.
    pub fn of_role(&self, role: Role) -> impl Iterator<Item = &PlannedVariation> {
        self.variations.iter().filter(move |v| v.role == role)
    }
}

/// The tasks of a plan with these variations.
fn tasks(variations: &[PlannedVariation]) -> Vec<Task> {
    let data_id = |v: &PlannedVariation| format!("data_{}", v.id);
    let mut out: Vec<Task> = variations
        .iter()
        .map(|v| Task {
            id: data_id(v),
            kind: TaskKind::Dataset {
                variation: v.id.clone(),
            },
            after: Vec::new(),
        })
        .collect();
    let training: Vec<String> = variations
        .iter()
        .filter(|v| v.role == Role::Train)
        .map(data_id)
        .collect();
    out.push(Task {
        id: "calibrate".into(),
        kind: TaskKind::Calibrate,
        after: training.clone(),
    });
    out.push(Task {
        id: "train_isr".into(),
        kind: TaskKind::TrainIsr,
        after: training,
    });
    let mut all: Vec<String> = variations
        .iter()
        .filter(|v| v.role == Role::HeldOut)
        .map(data_id)
        .collect();
    // The floor of the first held-out variation.
    if let Some(v) = variations.iter().find(|v| v.role == Role::HeldOut) {
        out.push(Task {
            id: format!("twin_{}", v.id),
            kind: TaskKind::Twin {
                variation: v.id.clone(),
            },
            after: vec![data_id(v)],
        });
        all.push(format!("twin_{}", v.id));
    }
    all.extend(["calibrate".to_string(), "train_isr".to_string()]);
    out.push(Task {
        id: "evaluate".into(),
        kind: TaskKind::Evaluate,
        after: all,
    });
    out
}

/// Where a fit is, for progress.
#[derive(Debug, Clone)]
pub struct FitProgress {
    /// Tasks done.
    pub done: usize,
    /// Tasks in the plan.
    pub total: usize,
    /// The task now running, and what it reports.
    pub message: String,
}

/// Runs `plan` in `dir` (where `plan.json` is written first; a plan already there must be the
/// same), skipping tasks already done. `progress` sees each task start and its steps; a
/// `Break` stops the fit at the next point it can resume from (before the next task, or at a
/// training step). Returns whether every task is done.
pub fn run(
    plan: &Plan,
    dir: &Path,
    mut progress: impl FnMut(&FitProgress) -> ControlFlow<()>,
) -> Result<bool> {
    std::fs::create_dir_all(dir.join("tasks")).map_err(|e| Error::io(dir, e))?;
    save_plan(plan, dir)?;
    for k in 0..plan.tasks.len() {
        if !run_marked(plan, dir, k, &mut progress)? {
            return Ok(false);
        }
    }
    let total = plan.tasks.len();
    let _ = progress(&FitProgress {
        done: total,
        total,
        message: "done".into(),
    });
    Ok(true)
}

/// Runs the one task `id` of `plan` in `dir`, whose tasks it needs must be done (by this or
/// another process: a cluster runs a fit's independent tasks on several machines over one
/// shared folder); a task already done is skipped. Returns whether it is done.
pub fn run_one(
    plan: &Plan,
    dir: &Path,
    id: &str,
    mut progress: impl FnMut(&FitProgress) -> ControlFlow<()>,
) -> Result<bool> {
    std::fs::create_dir_all(dir.join("tasks")).map_err(|e| Error::io(dir, e))?;
    save_plan(plan, dir)?;
    let (k, task) = plan
        .tasks
        .iter()
        .enumerate()
        .find(|(_, t)| t.id == id)
        .ok_or_else(|| Error::Usage(format!("the plan in {} has no task '{id}'", dir.display())))?;
    if let Some(missing) = task.after.iter().find(|a| !done_marker(dir, a).exists()) {
        return Err(Error::Usage(format!(
            "task '{id}' needs task '{missing}' done first"
        )));
    }
    run_marked(plan, dir, k, &mut progress)
}

/// The file a finished task leaves.
fn done_marker(dir: &Path, id: &str) -> PathBuf {
    dir.join("tasks").join(format!("{id}.done"))
}

/// Runs task `k` unless its marker says it is done, reporting its progress, and leaves the
/// marker when it ends. Returns whether it is done.
fn run_marked(
    plan: &Plan,
    dir: &Path,
    k: usize,
    progress: &mut impl FnMut(&FitProgress) -> ControlFlow<()>,
) -> Result<bool> {
    let task = &plan.tasks[k];
    let marker = done_marker(dir, &task.id);
    if marker.exists() {
        return Ok(true);
    }
    // One process a task: a second fit in the same folder (or a task run twice on a cluster)
    // is refused while the first runs it, rather than both writing the same files.
    let lock_path = dir.join("tasks").join(format!("{}.lock", task.id));
    let lock = std::fs::File::create(&lock_path).map_err(|e| Error::io(&lock_path, e))?;
    match lock.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            return Err(Error::Usage(format!(
                "task '{}' of the fit in {} is running in another process; wait for it, or \
                 stop it first",
                task.id,
                dir.display()
            )))
        }
        Err(std::fs::TryLockError::Error(e)) => return Err(Error::io(&lock_path, e)),
    }
    if marker.exists() {
        return Ok(true);
    }
    let total = plan.tasks.len();
    let mut report = |message: String| {
        progress(&FitProgress {
            done: k,
            total,
            message: format!("{}: {message}", task.id),
        })
    };
    if report("started".into()).is_break() || !run_task(plan, dir, task, &mut report)? {
        return Ok(false);
    }
    write_atomic(&marker, b"done\n")?;
    // Best effort: a process that opened it meanwhile finds the marker once it holds it.
    let _ = std::fs::remove_file(&lock_path);
    Ok(true)
}

/// Writes `plan` to `dir/plan.json` (its files named from `dir`, so that the folder can move
/// with what it was made from), or checks that the plan already there is the same.
pub fn save_plan(plan: &Plan, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let path = dir.join(PLAN_FILE);
    let text = serde_json::to_string_pretty(&plan.relative_to(dir))
        .map_err(|e| Error::Invalid(e.to_string()))?;
    if path.exists() {
        let old = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        if old.trim_end() != text.trim_end() {
            return Err(Error::bad_input(
                &path,
                "another fit's plan is here (other shot, quality or options); choose another \
                 folder",
            ));
        }
        return Ok(());
    }
    write_atomic(&path, (text + "\n").as_bytes())
}

fn data_dir(dir: &Path, variation: &str) -> PathBuf {
    dir.join("data").join(variation)
}

fn twin_dir(dir: &Path, variation: &str) -> PathBuf {
    dir.join("data").join(format!("{variation}_twin"))
}

/// Reports a task's progress; `Break` asks it to stop.
type Report<'a> = dyn FnMut(String) -> ControlFlow<()> + 'a;

/// Runs one task; false when it stopped before its end.
fn run_task(plan: &Plan, dir: &Path, task: &Task, report: &mut Report) -> Result<bool> {
    match &task.kind {
        TaskKind::Dataset { variation } => {
            let v = plan
                .variations
                .iter()
                .find(|v| &v.id == variation)
                .ok_or_else(|| Error::Invalid(format!("the plan has no variation {variation}")))?;
            let scene = plan.shot.load()?;
            let opts = Options {
                coarse_edge_m: plan.coarse_edge_m,
                fine_edge_m: plan.fine_edge_m,
                frames: plan.frames,
                dress: true,
                self_collision: !plan.fast,
                variation: v.variation,
                fast: plan.fast,
                source: Some(plan.shot.clone()),
                fine_mode: crate::sim::step::SolverMode::Data,
                match_contact_thickness: true,
            };
            let data = data_dir(dir, variation);
            let name = crate::io::relative_to(&plan.shot.scene, &data);
            generate(&scene, &name.display().to_string(), &opts, &data, |p| {
                let _ = report(format!("frame {}/{}", p.frames_done, p.frames));
            })?;
            Ok(true)
        }
        TaskKind::Twin { variation } => {
            let scene = plan.shot.load()?;
            let data = data_dir(dir, variation);
            let m = crate::dataset::fork(
                &data,
                1,
                nalgebra::Vector3::new(1e-4, 0.0, 0.0),
                &twin_dir(dir, variation),
            )?;
            generate(
                &scene,
                &m.scene,
                &Options::of_manifest(&m, plan.frames),
                &twin_dir(dir, variation),
                |p| {
                    let _ = report(format!("frame {}/{}", p.frames_done, p.frames));
                },
            )?;
            Ok(true)
        }
        TaskKind::Calibrate => calibrate(plan, dir, report).map(|()| true),
        TaskKind::TrainIsr => train_isr(plan, dir, report),
        TaskKind::Evaluate => evaluate_held_out(plan, dir, report).map(|()| true),
    }
}

fn calibration_sets(plan: &Plan, dir: &Path, role: Role) -> Result<Vec<CalibrationSet>> {
    let scene = plan.shot.load()?;
    plan.of_role(role)
        .map(|v| CalibrationSet::load(scene.clone(), &data_dir(dir, &v.id), None))
        .collect()
}

/// The calibration grid of a fit: the default one.
fn calibrate(plan: &Plan, dir: &Path, report: &mut Report) -> Result<()> {
    let sets = calibration_sets(plan, dir, Role::Train)?;
    let candidates = Grid::default().candidates()?;
    let _ = report(format!("{} candidates", candidates.len()));
    let scored = score(&sets, &candidates, &[], || {})?;
    let i = best(&scored)
        .ok_or_else(|| Error::Simulation("the simulator failed on every candidate".into()))?;
    let json = serde_json::to_string_pretty(&scored[i].calibration)
        .map_err(|e| Error::Invalid(e.to_string()))?;
    write_atomic(&dir.join(CoarseCalibration::FILE), (json + "\n").as_bytes())
}

/// The ISR recipe of the shipped models: geometry channels and the fabric as inputs, no
/// initialisation input, the Swin body on 4 × 4 pixel blocks.
fn isr_config(plan: &Plan, dir: &Path) -> Result<IsrTrainingConfig> {
    if let Some(from) = &plan.fine_tune_from {
        let generic = Isr::load(from)?;
        return Ok(generic
            .cfg
            .clone()
            .with_steps(plan.isr_steps)
            .with_lr_start(1e-4)
            .with_lr_end(1e-5)
            .with_fine_tune_from(Some(
                crate::io::relative_to(from, &dir.join("isr"))
                    .display()
                    .to_string(),
            )));
    }
    let model = IsrConfig::new()
        .with_depths(vec![2, 2, 2])
        .with_init_input(false)
        .with_geometry_input(Some(true))
        .with_unshuffle(Some(4))
        .with_condition_input(Some(true));
    Ok(IsrTrainingConfig::new(model, plan.fine_edge_m).with_steps(plan.isr_steps))
}

fn train_isr(plan: &Plan, dir: &Path, report: &mut Report) -> Result<bool> {
    let cfg = isr_config(plan, dir)?;
    let seqs = plan
        .of_role(Role::Train)
        .map(|v| {
            IsrSequence::load(
                &data_dir(dir, &v.id),
                None,
                cfg.pixel_m,
                cfg.phong_alpha,
                cfg.init_blur_px,
            )
        })
        .collect::<Result<Vec<_>>>()?;
    let summary = train(&cfg, &seqs, &dir.join("isr"), |p| {
        report(format!("step {}/{}: loss {:.4}", p.step, p.total, p.loss))
    })?;
    if summary.interrupted {
        return Ok(false);
    }
    let _ = std::fs::remove_dir_all(dir.join("isr").join("checkpoint"));
    Ok(true)
}

/// The held-out figures of one variation.
#[derive(Debug, Clone)]
struct HeldOut {
    id: String,
    /// Coarse simulation alone against M_int, mean over frames, mm: the simulator's own model
    /// and the calibrated one.
    coarse_own_mm: f64,
    coarse_calibrated_mm: f64,
    /// The ISR on M_int against the fine simulation, and M_int upsampled, mean over frames, mm.
    isr_mm: f64,
    upsampled_mm: f64,
    /// The bend-angle distributions' distance to the fine simulation's, of the ISR's meshes and
    /// of M_int upsampled, mean over frames, degrees.
    isr_bend_w1_deg: f64,
    upsampled_bend_w1_deg: f64,
    /// Per frame: (ISR, upsampled) mm.
    per_frame: Vec<(f64, f64)>,
    /// The whole pipeline with the fit's models (the calibrated coarse model and the ISR)
    /// against the fine simulation, and the simulator's own coarse model upsampled from the
    /// same start (the paper's baseline), per frame, mm.
    run_per_frame: Vec<(f64, f64)>,
    /// The same pipeline against the twin's fine simulation, per frame, mm (empty without a
    /// twin): a shot that forks (a large floor) may follow the twin's road.
    twin_per_frame: Vec<f64>,
    /// The predictability floor, where measured ([`HeldOutRun::floor_mm`]).
    floor_mm: Option<f64>,
    /// Pictures of its frames ([`HeldOutRun::pictures`]).
    pictures: std::result::Result<Vec<PathBuf>, String>,
}

impl HeldOut {
    /// Mean over frames of the whole pipeline and of the baseline, mm.
    fn run_means_mm(&self) -> (f64, f64) {
        let n = self.run_per_frame.len().max(1) as f64;
        (
            self.run_per_frame.iter().map(|p| p.0).sum::<f64>() / n,
            self.run_per_frame.iter().map(|p| p.1).sum::<f64>() / n,
        )
    }

    /// Against the twin, mean over frames, and the mean over the two fine simulations as a
    /// share of the least any prediction from their shared start can average there (half
    /// the floor, by the triangle inequality); `None` without a twin or a floor.
    fn twin_means(&self) -> Option<(f64, f64)> {
        let floor = self.floor_mm.filter(|&f| f > 0.0)?;
        let twin = self.twin_per_frame.iter().sum::<f64>() / self.twin_per_frame.len() as f64;
        Some((twin, (self.run_means_mm().0 + twin) / floor))
    }
}

/// What the whole pipeline gave on a held-out variation, per frame, mm.
struct HeldOutRun {
    /// The pipeline and the baseline against the variation's fine simulation.
    against_gt: Vec<(f64, f64)>,
    /// The pipeline against the twin's fine simulation (empty without a twin).
    against_twin: Vec<f64>,
    /// The predictability floor: the mean distance between the variation's fine simulation
    /// and its twin's over the same frames (the shared first frame is zero, as `clothsr eval
    /// --floor` counts it); `None` without a twin.
    floor_mm: Option<f64>,
    /// Pictures of the fine simulation beside the fit's models, or why there are none.
    pictures: std::result::Result<Vec<PathBuf>, String>,
}

/// The whole pipeline on held-out variation `v` with the fit's ISR and coarse model `cal`,
/// beside the simulator's own coarse model upsampled, against the variation's fine simulation
/// and its twin's, if it has one.
fn run_held_out(
    plan: &Plan,
    dir: &Path,
    v: &PlannedVariation,
    isr: &Isr,
    cal: &CoarseCalibration,
) -> Result<HeldOutRun> {
    let data = data_dir(dir, &v.id);
    let gt = crate::eval::Animation::read_dataset(&data, 0.0)?;
    let twin_data = twin_dir(dir, &v.id);
    let twin = if twin_data.join("manifest.json").exists() {
        Some(crate::eval::Animation::read_dataset(&twin_data, 0.0)?)
    } else {
        None
    };
    let opts = |coarse: CoarseCalibration| super::Options {
        coarse_edge_m: plan.coarse_edge_m,
        coarse_solver: crate::data::coarse_mode(plan.fast),
        self_collision: !plan.fast,
        match_contact_thickness: true,
        dress: true,
        coarse,
        push_out: true,
        variation: v.variation,
    };
    let mut scene = plan.shot.load()?;
    opts(*cal).variation.apply(&mut scene);
    let mut run = super::Pipeline::new(&scene, isr, None, opts(*cal))?;
    let mut paper = super::Pipeline::new(&scene, isr, None, opts(CoarseCalibration::default()))?;
    if run.fine.num_vertices() != gt.num_vertices() {
        return Err(Error::bad_input(
            &data,
            format!(
                "its fine mesh has {} vertices, the run's {}",
                gt.num_vertices(),
                run.fine.num_vertices()
            ),
        ));
    }
    run.super_resolve()?;
    let mut out = Vec::with_capacity(gt.frames.len());
    let mut pred = crate::eval::Animation {
        parts: gt.parts.clone(),
        triangles: gt.triangles.clone(),
        time_codes: gt.time_codes.clone(),
        frames: Vec::with_capacity(gt.frames.len()),
    };
    for truth in &gt.frames {
        let fine = run.advance_frame()?;
        let own = crate::metrics::mean_distance_mm(truth, fine);
        pred.frames.push(fine.to_vec());
        for _ in 0..paper.coarse.steps_per_frame {
            paper.coarse.step()?;
        }
        out.push((
            own,
            crate::metrics::mean_distance_mm(truth, &paper.upsampled()?),
        ));
    }
    // The floor over the same frames as the pipeline's figures, or none.
    let (to_twin, floor_mm) = match &twin {
        Some(twin) => {
            let frames = crate::eval::floor_frames(&gt, twin, &twin_data, &pred, &data)?;
            let to_twin: Vec<f64> = frames.iter().map(|f| f.against_twin_mm).collect();
            let floor =
                (frames.len() == out.len()).then(|| crate::eval::FloorBound::of(&frames).floor_mm);
            (to_twin, floor)
        }
        None => (Vec::new(), None),
    };
    let pictures = render_held_out(dir, &v.id, &scene, &gt, &pred);
    Ok(HeldOutRun {
        against_gt: out,
        against_twin: to_twin,
        floor_mm,
        pictures,
    })
}

/// Renders the held-out variation `id`'s first, middle and last frames: its fine simulation
/// beside the fit's models, with the scene's bodies (`{id}_f{frame}.png` in the fit's folder,
/// [`crate::io::render`]); the images, or why there are none (no Blender here).
fn render_held_out(
    dir: &Path,
    id: &str,
    scene: &crate::scene::Scene,
    gt: &crate::eval::Animation,
    pred: &crate::eval::Animation,
) -> std::result::Result<Vec<PathBuf>, String> {
    use crate::io::usd::{MeshOut, StageOut};
    if let Err(why) = crate::io::render::renderer() {
        tracing::warn!("{id}: no pictures of the held-out frames: {why}");
        return Err(why);
    }
    // What went wrong is logged; the report, which is committed, says only that it did.
    let failed = |what: &str, e: Error| {
        tracing::warn!("{id}: no pictures of the held-out frames: {what}: {e}");
        format!("{what} failed; the fit's log says why")
    };
    let n = gt.frames.len().min(pred.frames.len());
    if n == 0 {
        return Err("no frames".into());
    }
    let mut picks = vec![0, n / 2, n - 1];
    picks.dedup();
    // Frame k of a data set ends at the scene's time code start + k + 1, where the bodies'
    // samples are.
    let frame = |k: usize| scene.frame_start + k as i64 + 1;
    let code = |k: usize| frame(k) as f64;
    let tmp = tempfile::tempdir().map_err(|e| failed("a temporary folder", Error::io(dir, e)))?;
    let write = |anim: &crate::eval::Animation, name: &str| -> Result<PathBuf> {
        let mut meshes = vec![MeshOut {
            name: "garment".into(),
            group: "Garments".into(),
            triangles: anim.triangles.clone(),
            frames: picks
                .iter()
                .map(|&k| anim.frames[k].iter().map(|p| p.cast::<f32>()).collect())
                .collect(),
            time_codes: Some(picks.iter().map(|&k| code(k)).collect()),
            ..Default::default()
        }];
        meshes.extend(
            scene
                .colliders
                .iter()
                .map(|c| MeshOut::collider(c, scene.fps)),
        );
        let path = tmp.path().join(format!("{name}.usdc"));
        crate::io::usd::write_usd(
            &path,
            &StageOut {
                fps: scene.fps,
                start: code(0),
                end: code(n - 1),
                meshes,
                ..Default::default()
            },
        )?;
        Ok(path)
    };
    let files = write(gt, "fine").and_then(|a| Ok((a, write(pred, "fit")?)));
    let (fine, fit) = files.map_err(|e| failed("writing the frames", e))?;
    let frames: Vec<i64> = picks.iter().map(|&k| frame(k)).collect();
    // Pictures of an earlier evaluation (other frames) go.
    let earlier = format!("{id}_f");
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.starts_with(&earlier) && name.ends_with(".png") {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
    crate::io::render::side_by_side(
        &[("fine simulation", &fine), ("fit's models", &fit)],
        &frames,
        &crate::io::render::RenderSettings::default(),
        dir,
        id,
    )
    .map_err(|e| failed("rendering", e))
}

fn evaluate_held_out(plan: &Plan, dir: &Path, report: &mut Report) -> Result<()> {
    let chosen = CoarseCalibration::load(dir)?.ok_or_else(|| {
        Error::Invalid(format!(
            "{}: the calibration task left no coarse model",
            dir.join(CoarseCalibration::FILE).display()
        ))
    })?;
    let sets = calibration_sets(plan, dir, Role::HeldOut)?;
    let coarse: Vec<Scored> = score(&sets, &[Default::default(), chosen], &[], || {})?;
    let isr = Isr::load(&dir.join("isr"))?;
    let mut rows = Vec::new();
    for (k, v) in plan.of_role(Role::HeldOut).enumerate() {
        let _ = report(format!("measuring {}", v.id));
        let data = data_dir(dir, &v.id);
        let seq = IsrSequence::load(&data, None, isr.cfg.pixel_m, isr.cfg.phong_alpha, 0.0)?;
        let e = evaluate(&seq, &isr, false, |_, _| ControlFlow::Continue(()))?;
        let per_frame: Vec<(f64, f64)> =
            e.frames.iter().map(|f| (f.sr_mm, f.upsampled_mm)).collect();
        let _ = report(format!("running the pipeline on {}", v.id));
        let run = run_held_out(plan, dir, v, &isr, &chosen)?;
        let n = per_frame.len().max(1) as f64;
        rows.push(HeldOut {
            id: v.id.clone(),
            coarse_own_mm: coarse[0].run_means_mm[k]
                .first()
                .copied()
                .unwrap_or(f64::NAN),
            coarse_calibrated_mm: coarse[1].run_means_mm[k]
                .first()
                .copied()
                .unwrap_or(f64::NAN),
            isr_mm: per_frame.iter().map(|p| p.0).sum::<f64>() / n,
            upsampled_mm: per_frame.iter().map(|p| p.1).sum::<f64>() / n,
            isr_bend_w1_deg: e.mean_bend_w1_deg().0,
            upsampled_bend_w1_deg: e.mean_bend_w1_deg().1,
            per_frame,
            run_per_frame: run.against_gt,
            twin_per_frame: run.against_twin,
            floor_mm: run.floor_mm,
            pictures: run.pictures,
        });
    }
    write_atomic(&dir.join("held_out.csv"), csv(&rows).as_bytes())?;
    let series: Vec<(String, Vec<FrameMetrics>)> = rows
        .iter()
        .flat_map(|r| {
            let metrics = |pick: fn(&(f64, f64)) -> f64| {
                r.run_per_frame
                    .iter()
                    .enumerate()
                    .map(|(k, p)| FrameMetrics {
                        time_code: (k + 1) as f64,
                        mean_mm: pick(p),
                        max_mm: pick(p),
                        std_mm: 0.0,
                        normal_deg: 0.0,
                        jitter_mm: None,
                        gt_jitter_mm: None,
                        bend_w1_deg: 0.0,
                        bend_mean_deg: 0.0,
                        gt_bend_mean_deg: 0.0,
                    })
                    .collect()
            };
            [
                (format!("fit's models {}", r.id), metrics(|p| p.0)),
                (
                    format!("simulator's coarse model upsampled {}", r.id),
                    metrics(|p| p.1),
                ),
            ]
        })
        .collect();
    let plotted = crate::eval::plot(
        &dir.join("held_out.png"),
        &series,
        "held-out error over time",
    )
    .map_err(|e| tracing::warn!("no plot: {e}"))
    .is_ok();
    let text = report_text(&plan.relative_to(dir), &chosen, &rows, plotted);
    write_atomic(&dir.join("report.md"), text.as_bytes())?;
    write_manifest(plan, dir, &rows)
}

fn round3(x: f64) -> f64 {
    (x * 1e3).round() / 1e3
}

/// The fit's `models.json`: the whole pipeline's held-out figures, which `clothsr run` reports
/// and chooses its path by.
fn write_manifest(plan: &Plan, dir: &Path, rows: &[HeldOut]) -> Result<()> {
    let n = rows.len().max(1) as f64;
    let mean =
        |pick: fn((f64, f64)) -> f64| rows.iter().map(|r| pick(r.run_means_mm())).sum::<f64>() / n;
    let ids: Vec<&str> = rows.iter().map(|r| r.id.as_str()).collect();
    let manifest = super::ModelsManifest {
        format_version: super::ModelsManifest::FORMAT_VERSION,
        scene: crate::io::relative_to(&plan.shot.scene, dir)
            .display()
            .to_string(),
        held_out: format!("data/{{{}}}", ids.join(",")),
        protocol: format!(
            "`clothsr fit`: the whole pipeline with these models on each held-out variation, \
             {} frames, against its fine simulation, mean over frames and variations; baseline: \
             the simulator's own coarse model, upsampled, from the same starts. report.md",
            plan.frames
        ),
        paths: [(
            super::ModelPath::CoarseAlone,
            super::models::PathFigures {
                fine_error_mm: round3(mean(|p| p.0)),
                baseline_mm: Some(round3(mean(|p| p.1))),
            },
        )]
        .into(),
        best: super::ModelPath::CoarseAlone,
    };
    let json =
        serde_json::to_string_pretty(&manifest).map_err(|e| Error::Invalid(e.to_string()))?;
    write_atomic(
        &dir.join(super::ModelsManifest::FILE),
        (json + "\n").as_bytes(),
    )
}

fn report_text(plan: &Plan, chosen: &CoarseCalibration, rows: &[HeldOut], plotted: bool) -> String {
    let mut s = format!(
        "# Fit of {}\n\nQuality {:?}: {} training and {} held-out variations of {} frames, \
         {:.1} mm coarse / {:.1} mm fine; the ISR network {}.\n\n\
         Coarse model chosen on the training variations: {chosen}.\n\n\
         ## The whole pipeline, held out\n\n\
         `clothsr run` with these models on each held-out variation against its fine \
         simulation, beside the simulator's own coarse model upsampled (the paper's baseline), \
         mean over frames.\n\n\
         | variation | fit's models (mm) | simulator's coarse model upsampled (mm) | ratio | floor (mm) | fit's / floor | fit's to the twin (mm) | mean to both / half the floor |\n\
         |---|---|---|---|---|---|---|---|\n{}\n\
         The floor: the distance between the variation's fine simulation and its twin from a \
         start 0.1 mm away, which no prediction is expected to beat. Where a shot forks (a \
         large floor), the twin may take another road than the fine simulation, and the fit's \
         models against the twin say which road they follow. Their mean distance to the two \
         is at least half the floor (the triangle inequality); the last column is it as a \
         share of that.\n\n\
         ## The stages, held out\n\n\
         | variation | coarse alone, simulator's model (mm to M_int) | calibrated | ISR on M_int (mm to the fine simulation) | M_int upsampled | ISR / upsampled | bend angles, ISR (W1 °) | upsampled |\n\
         |---|---|---|---|---|---|---|---|\n",
        plan.shot.scene.display(),
        plan.quality,
        plan.of_role(Role::Train).count(),
        plan.of_role(Role::HeldOut).count(),
        plan.frames,
        plan.coarse_edge_m * 1e3,
        plan.fine_edge_m * 1e3,
        match &plan.fine_tune_from {
            Some(d) => format!("fine-tuned from {}", d.display()),
            None => "trained from scratch".into(),
        },
        rows.iter()
            .map(|r| {
                let (run, base) = r.run_means_mm();
                let (floor, share) = match r.floor_mm {
                    Some(f) => (format!("{f:.2}"), format!("{:.2}", run / f)),
                    None => ("".into(), "".into()),
                };
                let (twin, both) = match r.twin_means() {
                    Some((t, b)) => (format!("{t:.2}"), format!("{b:.2}")),
                    None => ("".into(), "".into()),
                };
                format!(
                    "| {} | {run:.2} | {base:.2} | {:.2} | {floor} | {share} | {twin} | {both} |\n",
                    r.id,
                    run / base
                )
            })
            .collect::<String>()
    );
    for r in rows {
        s += &format!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |\n",
            r.id,
            r.coarse_own_mm,
            r.coarse_calibrated_mm,
            r.isr_mm,
            r.upsampled_mm,
            r.isr_mm / r.upsampled_mm,
            r.isr_bend_w1_deg,
            r.upsampled_bend_w1_deg
        );
    }
    s += "\nBend angles: the distance (1-Wasserstein, degrees) between the distribution of the \
          angles between neighbouring triangles and the fine simulation's: the folds and \
          wrinkles in kind, wherever they lie.\n\nPer-frame errors: `held_out.csv`.\n";
    if plotted {
        s += "\n![Error over time](held_out.png)\n";
    }
    s += "\n## Pictures, held out\n\nThe fine simulation (left) and the fit's models (right) \
          at the first, middle and last frames, through one camera.\n";
    for r in rows {
        match &r.pictures {
            Ok(files) => {
                s += &format!("\n{}:\n\n", r.id);
                for f in files {
                    let name = f
                        .file_name()
                        .map(|n| n.to_string_lossy())
                        .unwrap_or_default();
                    s += &format!("![{} {name}]({name})\n", r.id);
                }
            }
            Err(why) => s += &format!("\n{}: no pictures ({why}).\n", r.id),
        }
    }
    s
}

/// Per frame: the ISR on M_int and M_int upsampled (against the fine simulation), the whole
/// pipeline and the baseline, and the pipeline against the twin (empty without one), mm.
fn csv(rows: &[HeldOut]) -> String {
    let mut s =
        String::from("variation,frame,isr_mm,upsampled_mm,fit_mm,baseline_mm,fit_to_twin_mm\n");
    for r in rows {
        for (k, (a, b)) in r.per_frame.iter().enumerate() {
            let (fit, base) = r
                .run_per_frame
                .get(k)
                .map_or((String::new(), String::new()), |(f, b)| {
                    (format!("{f:.4}"), format!("{b:.4}"))
                });
            let twin = r
                .twin_per_frame
                .get(k)
                .map_or(String::new(), |t| format!("{t:.4}"));
            s += &format!("{},{},{a:.4},{b:.4},{fit},{base},{twin}\n", r.id, k + 1);
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options(quality: Quality) -> FitOptions {
        FitOptions {
            quality,
            coarse_edge_m: 0.02,
            fine_edge_m: 0.0025,
            frames: None,
            isr_steps: None,
            generic_isr: None,
        }
    }

    fn plan(quality: Quality) -> Plan {
        let scene = crate::scene::samples::sample("sheet_sphere").expect("a sample");
        let shot = SceneSource {
            scene: PathBuf::from("/shots/sheet_sphere.usda"),
            colliders: Vec::new(),
            avatar: None,
            fabric: "cotton".into(),
        };
        Plan::new(shot, &scene, &options(quality)).expect("a plan")
    }

    #[test]
    fn every_task_comes_after_what_it_needs_and_evaluate_after_all() {
        for quality in [Quality::Preview, Quality::Final] {
            let plan = plan(quality);
            let (train, held) = match quality {
                Quality::Preview => (2, 1),
                Quality::Final => (5, 2),
            };
            assert_eq!(plan.of_role(Role::Train).count(), train);
            assert_eq!(plan.of_role(Role::HeldOut).count(), held);
            // A data set per variation, calibration, training, one twin, the evaluation.
            assert_eq!(plan.tasks.len(), train + held + 4);
            let mut done = std::collections::HashSet::new();
            for t in &plan.tasks {
                for a in &t.after {
                    assert!(done.contains(a.as_str()), "{} runs before {a}", t.id);
                }
                assert!(done.insert(t.id.as_str()), "{} twice", t.id);
            }
            let last = plan.tasks.last().expect("tasks");
            assert_eq!(last.kind, TaskKind::Evaluate);
            assert_eq!(last.after.len(), plan.tasks.len() - 1 - train);
            // Calibration and training never see a held-out variation.
            for t in &plan.tasks {
                if matches!(t.kind, TaskKind::Calibrate | TaskKind::TrainIsr) {
                    assert_eq!(t.after.len(), train);
                    assert!(t.after.iter().all(|a| a.starts_with("data_train_")));
                }
            }
        }
    }

    #[test]
    fn a_plan_round_trips_through_its_folder_with_relative_files() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut plan = plan(Quality::Preview);
        plan.shot.scene = dir.path().join("shots/sheet_sphere.usda");
        save_plan(&plan, dir.path()).expect("save");
        let text = std::fs::read_to_string(dir.path().join(PLAN_FILE)).expect("read");
        assert!(!text.contains(&dir.path().display().to_string()), "{text}");
        assert_eq!(Plan::load(dir.path()).expect("load"), plan);
        let moved = tempfile::tempdir().expect("tempdir");
        std::fs::copy(dir.path().join(PLAN_FILE), moved.path().join(PLAN_FILE)).expect("copy");
        let there = Plan::load(moved.path()).expect("load");
        assert_eq!(
            there.shot.scene,
            moved.path().join("shots/sheet_sphere.usda")
        );
    }

    #[test]
    fn a_plan_needs_a_coarse_edge_longer_than_the_fine_one() {
        let scene = crate::scene::samples::sample("sheet_sphere").expect("a sample");
        let shot = plan(Quality::Preview).shot;
        for (coarse, fine) in [
            (0.0025, 0.0025),
            (0.001, 0.0025),
            (f64::NAN, 0.0025),
            (0.02, 0.0),
        ] {
            let opts = FitOptions {
                coarse_edge_m: coarse,
                fine_edge_m: fine,
                ..options(Quality::Preview)
            };
            assert!(
                Plan::new(shot.clone(), &scene, &opts).is_err(),
                "{coarse} {fine}"
            );
        }
        assert_eq!("final".parse::<Quality>(), Ok(Quality::Final));
        assert!("fast".parse::<Quality>().is_err());
    }

    #[test]
    fn the_twin_share_is_of_half_the_floor() {
        let row = HeldOut {
            id: "held_out_0".into(),
            coarse_own_mm: 0.0,
            coarse_calibrated_mm: 0.0,
            isr_mm: 0.0,
            upsampled_mm: 0.0,
            isr_bend_w1_deg: 0.0,
            upsampled_bend_w1_deg: 0.0,
            per_frame: Vec::new(),
            run_per_frame: vec![(2.0, 4.0), (4.0, 8.0)],
            twin_per_frame: vec![1.0, 3.0],
            floor_mm: Some(4.0),
            pictures: Err("no renderer".into()),
        };
        assert_eq!(row.run_means_mm(), (3.0, 6.0));
        // Against the twin 2 mm; (3 + 2) / 4: no prediction can average below 1 (= 4 / 4).
        assert_eq!(row.twin_means(), Some((2.0, 1.25)));
        let no_floor = HeldOut {
            floor_mm: Some(0.0),
            ..row
        };
        assert_eq!(no_floor.twin_means(), None);
    }
}
