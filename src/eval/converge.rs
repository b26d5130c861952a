//! The convergence harness behind `clothsr lab converge`: a shot simulated in several solver
//! modes and at several resolutions, each run measured frame by frame against a tight
//! reference of the fine discretisation. A simulation is evidence only once it agrees with the
//! same simulation solved tighter; this says how far each mode is from that, what it costs,
//! and whether the reference itself has converged (the same reference at a smaller time step)
//! or the shot is chaotic (the reference's twin, started a fraction of a millimetre away).

use std::path::{Path, PathBuf};
use std::time::Instant;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::io::tensors::{TensorReader, TensorWriter};
use crate::mesh::ClothMesh;
use crate::scene::Scene;
use crate::sim::driver::Simulation;
use crate::sim::step::SolverMode;
use crate::transfer::Transfer;

/// A solver mode and how many times finer than the scene's its time step is: `tight/8` is
/// [`SolverMode::Tight`] at an eighth of the scene's step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ModeSpec {
    /// The solver mode.
    pub mode: SolverMode,
    /// The scene's time step is divided by this (sub-steps on top of the mode's own).
    pub dt_divisor: u32,
}

impl ModeSpec {
    /// `MODE` or `MODE/N` with MODE one of [`SolverMode::name`]'s names and N ≥ 1.
    pub fn parse(s: &str) -> Result<ModeSpec> {
        let (name, div) = match s.split_once('/') {
            Some((n, d)) => (n, Some(d)),
            None => (s, None),
        };
        let mode = SolverMode::from_name(name).ok_or_else(|| {
            let names: Vec<&str> = SolverMode::ALL.iter().map(|m| m.name()).collect();
            Error::Usage(format!(
                "'{s}': unknown solver mode '{name}' (known: {}; add /N to divide the time step by N)",
                names.join(", ")
            ))
        })?;
        let dt_divisor = match div {
            None => 1,
            Some(d) => match d.parse::<u32>() {
                Ok(n) if (1..=64).contains(&n) => n,
                _ => {
                    return Err(Error::Usage(format!(
                        "'{s}': the time-step divisor must be a whole number from 1 to 64"
                    )))
                }
            },
        };
        Ok(ModeSpec { mode, dt_divisor })
    }
}

impl std::fmt::Display for ModeSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.dt_divisor == 1 {
            write!(f, "{}", self.mode)
        } else {
            write!(f, "{}/{}", self.mode, self.dt_divisor)
        }
    }
}

/// What names a run without self-collision, after `sep` (nothing for a run with it).
fn self_collision_tag(self_collision: bool, sep: &str) -> String {
    if self_collision {
        String::new()
    } else {
        format!("{sep}no-self-collision")
    }
}

/// One simulation of the harness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunSpec {
    /// Target edge length of the cloth mesh, m.
    pub edge_m: f64,
    /// Solver settings.
    pub mode: ModeSpec,
    /// The garment's start moved up by this, m (a twin; 0 for none).
    pub twin_offset_m: f64,
    /// Contact thickness d̂ (and detection margin), m; `None`: the mesh's own default (15 %
    /// of its edge).
    pub dhat_m: Option<f64>,
    /// Cloth self-collision (`lab dataset --self-collision off` and `run` simulate without it).
    pub self_collision: bool,
}

impl RunSpec {
    /// A readable label: `2.5mm data`, `2.5mm tight/4 twin`.
    pub fn label(&self) -> String {
        let twin = if self.twin_offset_m != 0.0 {
            " twin"
        } else {
            ""
        };
        let mm = (self.edge_m * 1e4).round() / 10.0;
        let dhat = self.dhat_m.map_or(String::new(), |d| {
            format!(" dhat{}mm", (d * 1e5).round() / 100.0)
        });
        let sc = self_collision_tag(self.self_collision, " ");
        format!("{mm}mm {}{twin}{dhat}{sc}", self.mode)
    }

    /// The label as a file name.
    fn file_stem(&self) -> String {
        self.label().replace([' ', '/'], "_")
    }
}

/// What the harness runs on one shot.
#[derive(Debug, Clone)]
pub struct Plan {
    /// Output frames.
    pub frames: usize,
    /// The fine resolution, m.
    pub fine_edge_m: f64,
    /// The reference: the fine mesh in this mode.
    pub reference: ModeSpec,
    /// The reference solved tighter still, to show it has converged (`None`: not run).
    pub check: Option<ModeSpec>,
    /// The modes measured at the fine resolution.
    pub modes: Vec<ModeSpec>,
    /// The reference's twin, its start moved up by this, m (`None`: no twin).
    pub twin_offset_m: Option<f64>,
    /// Coarser resolutions measured against the fine reference, m.
    pub ladder_m: Vec<f64>,
    /// The mode of the ladder's runs.
    pub ladder_mode: ModeSpec,
    /// The ladder's runs also with the fine mesh's contact thickness (as the pipeline's coarse
    /// simulation runs), beside their own.
    pub ladder_matched_thickness: bool,
    /// Every run with cloth self-collision.
    pub self_collision: bool,
}

impl Plan {
    /// Every run, the reference first.
    pub fn runs(&self) -> Vec<RunSpec> {
        let fine = |mode| RunSpec {
            edge_m: self.fine_edge_m,
            mode,
            twin_offset_m: 0.0,
            dhat_m: None,
            self_collision: self.self_collision,
        };
        let mut runs = vec![fine(self.reference)];
        runs.extend(self.check.map(fine));
        if let Some(o) = self.twin_offset_m {
            runs.push(RunSpec {
                twin_offset_m: o,
                ..fine(self.reference)
            });
        }
        runs.extend(self.modes.iter().map(|&m| fine(m)));
        for &e in &self.ladder_m {
            let level = RunSpec {
                edge_m: e,
                ..fine(self.ladder_mode)
            };
            runs.push(level);
            if self.ladder_matched_thickness {
                runs.push(RunSpec {
                    dhat_m: Some(fine_dhat_m(self.fine_edge_m)),
                    ..level
                });
            }
        }
        let mut seen = Vec::new();
        runs.retain(|r| {
            let dup = seen.contains(r);
            seen.push(*r);
            !dup
        });
        runs
    }
}

/// One frame of a run: the solver's work and its distance to the reference.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    /// Newton iterations.
    pub newton_iters: usize,
    /// Linear-solve iterations.
    pub cg_iters: usize,
    /// Linear solves taken at their iteration cap above tolerance.
    pub capped_solves: usize,
    /// Sub-steps taken with Newton's iterations run out.
    pub unconverged_steps: usize,
    /// Sub-steps solved (halvings included).
    pub substeps: usize,
    /// Wall time of the frame, s.
    pub wall_s: f64,
}

/// A finished run: its positions per frame (frame 0, the start, first) and its records.
#[derive(Debug, Clone)]
pub struct RunResult {
    /// What ran.
    pub spec: RunSpec,
    /// Its cloth mesh (material coordinates, triangles, panels).
    pub mesh: ClothMesh,
    /// Positions at frames 0..=frames, m.
    pub x: Vec<Vec<Vector3<f64>>>,
    /// Frames 1..=frames.
    pub frames: Vec<FrameRecord>,
}

impl RunResult {
    /// Total wall time of its frames, s.
    pub fn wall_s(&self) -> f64 {
        self.frames.iter().map(|f| f.wall_s).sum()
    }

    /// Totals of its frames' records.
    pub fn totals(&self) -> FrameRecord {
        self.frames
            .iter()
            .fold(FrameRecord::default(), |a, f| FrameRecord {
                newton_iters: a.newton_iters + f.newton_iters,
                cg_iters: a.cg_iters + f.cg_iters,
                capped_solves: a.capped_solves + f.capped_solves,
                unconverged_steps: a.unconverged_steps + f.unconverged_steps,
                substeps: a.substeps + f.substeps,
                wall_s: a.wall_s + f.wall_s,
            })
    }
}

/// A run's distance to the reference: per frame 1..=frames, mean and max over its vertices, m.
#[derive(Debug, Clone, PartialEq)]
pub struct Distance {
    /// Mean over vertices, per frame.
    pub mean_m: Vec<f64>,
    /// Max over vertices, per frame.
    pub max_m: Vec<f64>,
}

impl Distance {
    /// The mean of the per-frame means, m.
    pub fn mean_m(&self) -> f64 {
        self.mean_m.iter().sum::<f64>() / self.mean_m.len().max(1) as f64
    }

    /// The largest per-vertex distance over all frames, m.
    pub fn max_m(&self) -> f64 {
        self.max_m.iter().copied().fold(0.0, f64::max)
    }
}

/// The default contact thickness of a mesh of target edge `edge_m` (its mean edge is about
/// 5 % longer), m.
fn fine_dhat_m(edge_m: f64) -> f64 {
    crate::sim::step::SimParams::for_edge(1.05 * edge_m)
        .collision
        .dhat_m
}

/// The simulation of `scene` at `spec`'s resolution and solver settings.
pub fn simulation(scene: &Scene, spec: &RunSpec) -> Result<Simulation> {
    let (mode, dhat, self_collision) = (spec.mode, spec.dhat_m, spec.self_collision);
    Simulation::new(scene, spec.edge_m, |p| {
        mode.mode.apply(p);
        p.substeps *= mode.dt_divisor;
        p.collision.self_collision = self_collision;
        if let Some(d) = dhat {
            p.collision.dhat_m = d;
            p.detection_margin_m = d;
        }
    })
}

/// The start of every run at one resolution: dressed (when the garments have seams) once, in
/// data mode, and reused by every mode with the same self-collision setting.
fn start_state(
    scene: &Scene,
    edge_m: f64,
    self_collision: bool,
    dir: &Path,
    coarse_edge_m: f64,
) -> Result<(Vec<Vector3<f64>>, Vec<f64>)> {
    let spec = RunSpec {
        edge_m,
        mode: ModeSpec {
            mode: SolverMode::Data,
            dt_divisor: 1,
        },
        twin_offset_m: 0.0,
        dhat_m: None,
        self_collision,
    };
    let mut sim = simulation(scene, &spec)?;
    if sim.sim.model.mesh.seam_pairs.is_empty() {
        return Ok((sim.state.x.clone(), sim.sim.seam_rest().to_vec()));
    }
    let path = dir.join(format!(
        "start_{}mm{}.safetensors",
        (edge_m * 1e4).round() / 10.0,
        self_collision_tag(self_collision, "_")
    ));
    if path.exists() {
        let r = TensorReader::open(&path)?;
        return Ok((
            crate::data::unflat(&r.f64("x")?.1),
            r.f64("seam_rest")?.1.to_vec(),
        ));
    }
    if edge_m >= coarse_edge_m {
        let (max_s, settle_s, gap_m) = crate::io::dressed::DRESSING;
        sim.dress(max_s, settle_s, gap_m)?;
    } else {
        let mut coarse = simulation(
            scene,
            &RunSpec {
                edge_m: coarse_edge_m,
                ..spec
            },
        )?;
        let t = Transfer::new(&coarse.sim.model.mesh, &sim.sim.model.mesh)?;
        crate::dataset::dress_fine_from_coarse(&mut coarse, &mut sim, &t)?;
    }
    let mut w = TensorWriter::new();
    w.f64(
        "x",
        &[sim.state.x.len(), 3],
        &crate::data::flat64(&sim.state.x),
    )
    .f64(
        "seam_rest",
        &[sim.sim.seam_rest().len()],
        sim.sim.seam_rest(),
    );
    w.write(&path)?;
    Ok((sim.state.x.clone(), sim.sim.seam_rest().to_vec()))
}

/// Runs `spec` on `scene` for `frames` frames, or reads it from `dir` when a run of the same
/// spec with at least as many frames is there; a stopped run goes on from its last frame (the
/// file is rewritten after every frame, with the state to resume from). `progress` sees each
/// frame's index and record.
pub fn run(
    scene: &Scene,
    spec: &RunSpec,
    frames: usize,
    dir: &Path,
    coarse_edge_m: f64,
    mut progress: impl FnMut(&RunSpec, usize, &FrameRecord),
) -> Result<RunResult> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let path = dir.join(format!("{}.safetensors", spec.file_stem()));
    let mut sim = simulation(scene, spec)?;
    let mesh = sim.sim.model.mesh.clone();
    let stored = read_run(&path, mesh.num_vertices())?;
    let (mut x, mut records) = match stored {
        Some(s) if s.records.len() >= frames => {
            let mut x = s.x;
            let mut records = s.records;
            x.truncate(frames + 1);
            records.truncate(frames);
            return Ok(RunResult {
                spec: *spec,
                mesh,
                x,
                frames: records,
            });
        }
        Some(Stored {
            x,
            records,
            resume: Some(r),
        }) => {
            let last = x.last().cloned().unwrap_or_default();
            sim.state.x = last;
            sim.state.v = r.v;
            sim.state.t_s = r.t_s;
            sim.sim.set_seam_rest(&r.seam_rest)?;
            sim.sim.set_obstacle_margin_m(r.margin_m);
            tracing::info!("{}: resuming after frame {}", spec.label(), records.len());
            (x, records)
        }
        _ => {
            let (x0, rest) =
                start_state(scene, spec.edge_m, spec.self_collision, dir, coarse_edge_m)?;
            sim.state.x = x0;
            sim.state.v.iter_mut().for_each(|v| *v = Vector3::zeros());
            sim.sim.set_seam_rest(&rest)?;
            if spec.twin_offset_m != 0.0 {
                let up = Vector3::new(0.0, spec.twin_offset_m, 0.0);
                sim.state.x.iter_mut().for_each(|p| *p += up);
            }
            (vec![sim.state.x.clone()], Vec::with_capacity(frames))
        }
    };
    // Dressed garments run with their seams welded, as dressing leaves them.
    if !mesh.seam_pairs.is_empty() {
        sim.sim.weld_seams(&mut sim.state, 0.0);
    }
    for f in records.len() + 1..=frames {
        // Every frame is a resume point: what the steps cached starts afresh, as after a
        // resume, so that a resumed run is the one made without the stop.
        sim.sim.forget_history();
        let t = Instant::now();
        let stats = sim
            .advance_frame(|_| {})
            .map_err(|e| Error::Simulation(format!("{}, frame {f}: {e}", spec.label())))?;
        let rec = FrameRecord {
            newton_iters: stats.steps.newton_iters,
            cg_iters: stats.steps.cg_iters,
            capped_solves: stats.steps.capped_solves,
            unconverged_steps: stats.steps.unconverged_steps,
            substeps: stats.steps.substeps,
            wall_s: t.elapsed().as_secs_f64(),
        };
        progress(spec, f, &rec);
        records.push(rec);
        x.push(sim.state.x.clone());
        write_run(&path, spec, &x, &records, &sim)?;
    }
    Ok(RunResult {
        spec: *spec,
        mesh,
        x,
        frames: records,
    })
}

/// What a run's file holds: positions from frame 0, records from frame 1, and the state to go
/// on from.
struct Stored {
    x: Vec<Vec<Vector3<f64>>>,
    records: Vec<FrameRecord>,
    resume: Option<Resume>,
}

/// The simulation's state at the end of a run's last frame, besides its positions.
struct Resume {
    v: Vec<Vector3<f64>>,
    t_s: f64,
    seam_rest: Vec<f64>,
    margin_m: f64,
}

fn write_run(
    path: &Path,
    spec: &RunSpec,
    x: &[Vec<Vector3<f64>>],
    records: &[FrameRecord],
    sim: &Simulation,
) -> Result<()> {
    let n = sim.state.x.len();
    let flat: Vec<f64> = x.iter().flat_map(|f| crate::data::flat64(f)).collect();
    let records = serde_json::to_string(records)
        .map_err(|e| Error::Invalid(format!("{}: {e}", path.display())))?;
    let rest = sim.sim.seam_rest();
    let mut w = TensorWriter::new();
    w.f64("x", &[x.len(), n, 3], &flat)
        .f64("resume_v", &[n, 3], &crate::data::flat64(&sim.state.v))
        .f64("resume_t", &[1], &[sim.state.t_s])
        .f64("resume_seam_rest", &[rest.len()], rest)
        .f64("resume_margin", &[1], &[sim.sim.obstacle_margin_m()])
        .meta("records", &records)
        .meta("label", &spec.label());
    w.write(path)
}

/// The run stored at `path` for a mesh of `n` vertices, if there is one.
fn read_run(path: &Path, n: usize) -> Result<Option<Stored>> {
    if !path.exists() {
        return Ok(None);
    }
    let r = TensorReader::open(path)?;
    let (shape, x) = r.f64("x")?;
    let records: Vec<FrameRecord> = r
        .meta("records")
        .and_then(|s| serde_json::from_str(&s).ok())
        .unwrap_or_default();
    if shape.len() != 3 || shape[1] != n || shape[2] != 3 || shape[0] != records.len() + 1 {
        tracing::info!(
            "{}: another run's result (its mesh or frames differ); running again",
            path.display()
        );
        return Ok(None);
    }
    let resume = if r.has("resume_v") {
        Some(Resume {
            v: crate::data::unflat(&r.f64("resume_v")?.1),
            t_s: r.scalar_f64("resume_t")?,
            seam_rest: r.f64("resume_seam_rest")?.1,
            margin_m: r.scalar_f64("resume_margin")?,
        })
    } else {
        None
    };
    Ok(Some(Stored {
        x: x.chunks_exact(3 * n).map(crate::data::unflat).collect(),
        records,
        resume,
    }))
}

/// `run`'s distance to `reference`, frame by frame; a run on another mesh is compared at its
/// own vertices with the reference surface at the same material point.
pub fn distance(run: &RunResult, reference: &RunResult) -> Result<Distance> {
    let same_mesh = run.mesh.num_vertices() == reference.mesh.num_vertices()
        && run.mesh.triangles == reference.mesh.triangles;
    let transfer = if same_mesh {
        None
    } else {
        Some(Transfer::new(&run.mesh, &reference.mesh)?)
    };
    let mut d = Distance {
        mean_m: Vec::new(),
        max_m: Vec::new(),
    };
    for (a, b) in run.x.iter().zip(&reference.x).skip(1) {
        let b = match &transfer {
            Some(t) => std::borrow::Cow::Owned(t.downsample(b)),
            None => std::borrow::Cow::Borrowed(b),
        };
        let e: Vec<f64> = a
            .iter()
            .zip(b.iter())
            .map(|(p, q)| (p - q).norm())
            .collect();
        d.mean_m.push(e.iter().sum::<f64>() / e.len().max(1) as f64);
        d.max_m.push(e.iter().copied().fold(0.0, f64::max));
    }
    Ok(d)
}

/// The harness's result on one shot: every run with its distance to the reference.
#[derive(Debug, Clone)]
pub struct Report {
    /// The shot's name.
    pub shot: String,
    /// The runs, the reference first, each with its distance to the reference.
    pub runs: Vec<(RunResult, Distance)>,
}

/// Runs `plan` on `scene` (named `shot`), keeping each finished run in `dir` (a later call
/// with the same plan reads them back: the harness resumes run by run).
pub fn converge(
    scene: &Scene,
    shot: &str,
    plan: &Plan,
    dir: &Path,
    coarse_edge_m: f64,
    mut progress: impl FnMut(&RunSpec, usize, &FrameRecord),
) -> Result<Report> {
    let specs = plan.runs();
    let mut results = Vec::with_capacity(specs.len());
    for spec in &specs {
        results.push(run(
            scene,
            spec,
            plan.frames,
            dir,
            coarse_edge_m,
            &mut progress,
        )?);
    }
    let reference = results[0].clone();
    let runs = results
        .into_iter()
        .map(|r| {
            let d = distance(&r, &reference)?;
            Ok((r, d))
        })
        .collect::<Result<Vec<_>>>()?;
    let report = Report {
        shot: shot.to_string(),
        runs,
    };
    crate::io::write_atomic(&dir.join("frames.csv"), report.csv().as_bytes())?;
    Ok(report)
}

impl Report {
    /// One row per run and frame.
    pub fn csv(&self) -> String {
        let mut s = String::from(
            "shot,run,vertices,frame,mean_mm,max_mm,newton,cg,capped_solves,unconverged_steps,substeps,wall_s\n",
        );
        for (r, d) in &self.runs {
            for (k, f) in r.frames.iter().enumerate() {
                s.push_str(&format!(
                    "{},{},{},{},{:.4},{:.4},{},{},{},{},{},{:.3}\n",
                    self.shot,
                    r.spec.label(),
                    r.mesh.num_vertices(),
                    k + 1,
                    d.mean_m[k] * 1e3,
                    d.max_m[k] * 1e3,
                    f.newton_iters,
                    f.cg_iters,
                    f.capped_solves,
                    f.unconverged_steps,
                    f.substeps,
                    f.wall_s
                ));
            }
        }
        s
    }

    /// A Markdown table: per run its distance to the reference (mean over frames, worst
    /// frame's mean, max), solver work and wall time, as a ratio to `time_base`'s (a mode at
    /// the fine resolution, e.g. fast).
    pub fn table(&self, time_base: Option<ModeSpec>) -> String {
        let base_s = time_base.and_then(|b| {
            self.runs
                .iter()
                .find(|(r, _)| {
                    r.spec.mode == b
                        && r.spec.twin_offset_m == 0.0
                        && r.spec.edge_m == self.runs[0].0.spec.edge_m
                })
                .map(|(r, _)| r.wall_s())
        });
        let mut s = format!(
            "**{}** (reference: {})\n\n| run | vertices | mean mm | worst frame mean mm | max mm | newton/frame | cg/newton | capped solves | unconverged | substeps | wall s | × {} |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
            self.shot,
            self.runs[0].0.spec.label(),
            time_base.map_or("-".to_string(), |b| b.to_string()),
        );
        for (r, d) in &self.runs {
            let t = r.totals();
            let frames = r.frames.len().max(1) as f64;
            let worst = d.mean_m.iter().copied().fold(0.0, f64::max);
            s.push_str(&format!(
                "| {} | {} | {:.2} | {:.2} | {:.2} | {:.1} | {:.1} | {} | {} | {} | {:.1} | {} |\n",
                r.spec.label(),
                r.mesh.num_vertices(),
                d.mean_m() * 1e3,
                worst * 1e3,
                d.max_m() * 1e3,
                t.newton_iters as f64 / frames,
                t.cg_iters as f64 / t.newton_iters.max(1) as f64,
                t.capped_solves,
                t.unconverged_steps,
                t.substeps,
                r.wall_s(),
                base_s.map_or("-".into(), |b| format!("{:.2}", r.wall_s() / b)),
            ));
        }
        s
    }
}

/// Where the harness keeps a shot's runs under `root`.
pub fn shot_dir(root: &Path, shot: &str) -> PathBuf {
    root.join(shot.replace(['/', '\\', ' '], "_"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mode_specs_parse_and_print_back() {
        for s in ["fast", "data", "converged/4", "tight/8"] {
            assert_eq!(
                ModeSpec::parse(s).map(|m| m.to_string()).ok(),
                Some(s.into())
            );
        }
        for bad in ["", "quick", "tight/0", "tight/x", "tight/65", "data/"] {
            assert!(ModeSpec::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_plan_runs_the_reference_first_and_each_run_once() {
        let tight = ModeSpec::parse("tight/4").ok();
        let plan = Plan {
            frames: 3,
            fine_edge_m: 2.5e-3,
            reference: tight.unwrap_or(ModeSpec {
                mode: SolverMode::Tight,
                dt_divisor: 4,
            }),
            check: None,
            modes: vec![
                ModeSpec {
                    mode: SolverMode::Data,
                    dt_divisor: 1,
                },
                ModeSpec {
                    mode: SolverMode::Tight,
                    dt_divisor: 4,
                },
            ],
            twin_offset_m: Some(1e-4),
            ladder_m: vec![0.02],
            ladder_mode: ModeSpec {
                mode: SolverMode::Data,
                dt_divisor: 1,
            },
            ladder_matched_thickness: true,
            self_collision: true,
        };
        let labels: Vec<String> = plan.runs().iter().map(|r| r.label()).collect();
        assert_eq!(
            labels,
            [
                "2.5mm tight/4",
                "2.5mm tight/4 twin",
                "2.5mm data",
                "20mm data",
                "20mm data dhat0.39mm"
            ]
        );
        // Runs without self-collision are other runs: their files are not the ones above.
        let off = Plan {
            self_collision: false,
            ..plan
        };
        let stems: Vec<String> = off.runs().iter().map(|r| r.file_stem()).collect();
        assert_eq!(stems[0], "2.5mm_tight_4_no-self-collision");
        assert!(off.runs().iter().all(|r| !r.self_collision));
        assert!(stems
            .iter()
            .zip(&labels)
            .all(|(s, l)| *s != l.replace([' ', '/'], "_")));
    }
}
