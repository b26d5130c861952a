//! A scene run through the pipeline into files: the fine garments as time-sampled USD, frame by
//! frame (optionally the coarse M_int and the upsampled coarse baseline beside them), a Rerun
//! recording, and a resume point so that a killed run continues from its last published frame.
//!
//! Every output is published atomically: USD files are checkpointed (a consistent file replaced
//! in one rename) every few seconds, and the resume point — the coarse state and the frame it
//! belongs to — is written after them, so it never names a frame a file lacks.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use nalgebra::Vector3;

use ndarray::Array3;

use super::{FrameTimes, Pipeline, ResumeState};
use crate::data::{flat64, unflat};
use crate::error::{Error, Result};
use crate::eval::{vertex_errors, Animation};
use crate::io::tensors::{TensorReader, TensorWriter};
use crate::io::usd::{AnimationWriter, MeshOut, OverLayer, SolverSettings, StageOut};
use crate::mesh::ClothMesh;
use crate::msr::inference::InitMaps;
use crate::scene::Scene;
use crate::sim::collide::PushOut;
use crate::sim::step::SimState;
use crate::viz::{colours, paths, Recorder};

/// Where and what a run writes.
#[derive(Debug, Clone, PartialEq)]
pub struct Outputs {
    /// The fine garments (and the colliders), one time sample per frame.
    pub fine: PathBuf,
    /// The coarse mesh the MSR module saw (M_int; M_c without a corrector).
    pub coarse: Option<PathBuf>,
    /// The coarse mesh upsampled to the fine one (the paper's baseline).
    pub upsampled: Option<PathBuf>,
    /// Text USD even for `.usd` files.
    pub ascii: bool,
    /// A short description stored in the files.
    pub doc: String,
    /// Continue an interrupted run whose resume point matches `fingerprint`.
    pub resume: bool,
    /// Identifies the run's settings (scene, models, options): a resume point with another
    /// fingerprint is ignored and the run starts over.
    pub fingerprint: String,
    /// Seconds between publishing the files and the resume point while running.
    pub publish_every_s: f64,
    /// Write the fine garments as an override layer for the USD shot they were read from
    /// ([`OverLayer`]) instead of a standalone stage: frames per value clip (0: one file).
    pub layer: Option<usize>,
}

/// How far a run is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// Frames done (0 = the first, rest frame).
    pub frame: usize,
    /// Frames to do.
    pub frames: usize,
    /// Stage times of the last frame.
    pub times: FrameTimes,
    /// What pushing the last frame's fine output out of the colliders did.
    pub pushed: PushOut,
    /// The frame a resumed run started after.
    pub resumed_after: Option<usize>,
}

/// What a run did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Report {
    /// Frames computed in this call (excluding the rest frame and resumed ones).
    pub frames_computed: usize,
    /// The frame a resumed run started after.
    pub resumed_after: Option<usize>,
    /// Summed stage times over the computed frames, s.
    pub totals: FrameTimes,
    /// Pushing the fine output out of the colliders, over the computed frames: vertices
    /// found inside and moved summed, the deepest found.
    pub pushed: PushOut,
    /// Wall time of the frame loop, s.
    pub wall_s: f64,
    /// The progress callback asked to stop: the files hold the frames so far (published, not
    /// validated) and the resume point lets the next call continue.
    pub stopped: bool,
}

/// What a run shows in Rerun.
pub struct Preview<'a> {
    /// The recording.
    pub recorder: &'a Recorder,
    /// A fine simulation of the same scene: the fine mesh is then coloured by its per-vertex
    /// distance to it (blue 0 → red `heat_max_m`), and the mean is plotted.
    pub ground_truth: Option<&'a Animation>,
    /// Distance shown in red, m.
    pub heat_max_m: f64,
}

/// The resume point beside `output`.
pub fn resume_path(output: &Path) -> PathBuf {
    let name = output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    output.with_file_name(format!(".{name}.clothsr-resume.safetensors"))
}

struct ResumePoint {
    frame: usize,
    state: ResumeState,
}

fn write_resume(path: &Path, fingerprint: &str, p: &ResumePoint) -> Result<()> {
    let s = &p.state;
    let (nc, nf) = (s.coarse.x.len(), s.fine.len());
    let mut w = TensorWriter::new();
    w.meta("fingerprint", fingerprint)
        .meta("frame", &p.frame.to_string())
        .f64("t_s", &[1], &[s.coarse.t_s])
        .f64("obstacle_margin_m", &[1], &[s.obstacle_margin_m])
        .f64("seam_rest_m", &[s.seam_rest_m.len()], &s.seam_rest_m)
        .f64("coarse_x", &[nc, 3], &flat64(&s.coarse.x))
        .f64("coarse_v", &[nc, 3], &flat64(&s.coarse.v))
        .f64("fine_x", &[nf, 3], &flat64(&s.fine));
    if let Some(maps) = &s.previous_maps {
        w.meta("maps", &maps.fine.len().to_string());
        for (k, (f, c)) in maps.fine.iter().zip(&maps.coarse).enumerate() {
            let shape = f.shape().to_vec();
            let fv: Vec<f32> = f.iter().copied().collect();
            let cv: Vec<f32> = c.iter().copied().collect();
            w.f32(&format!("prev_fine_{k}"), &shape, &fv).f32(
                &format!("prev_coarse_{k}"),
                &shape,
                &cv,
            );
        }
    }
    w.write(path)
}

fn one(path: &Path, v: Vec<f64>, name: &str) -> Result<f64> {
    v.first()
        .copied()
        .ok_or_else(|| Error::bad_input(path, format!("empty {name}")))
}

/// The resume point at `path` when it exists and was written with `fingerprint`.
fn read_resume(path: &Path, fingerprint: &str) -> Result<Option<ResumePoint>> {
    if !path.exists() {
        return Ok(None);
    }
    let r = TensorReader::open(path)?;
    if r.meta("fingerprint").as_deref() != Some(fingerprint) {
        tracing::info!(
            "{}: written by a run with other settings; starting over",
            path.display()
        );
        return Ok(None);
    }
    let frame = r
        .meta("frame")
        .and_then(|f| f.parse::<usize>().ok())
        .ok_or_else(|| Error::bad_input(path, "no frame number"))?;
    let map = |name: &str| -> Result<Array3<f32>> {
        let (shape, v) = r.f32(name)?;
        match shape[..] {
            [c, h, w] => Array3::from_shape_vec((c, h, w), v)
                .map_err(|e| Error::bad_input(path, format!("{name}: {e}"))),
            _ => Err(Error::bad_input(
                path,
                format!("{name}: not a (3, H, W) map"),
            )),
        }
    };
    let previous_maps = match r.meta("maps") {
        Some(n) => {
            let n: usize = n
                .parse()
                .map_err(|_| Error::bad_input(path, "bad map count"))?;
            let fine = (0..n)
                .map(|k| map(&format!("prev_fine_{k}")))
                .collect::<Result<Vec<_>>>()?;
            let coarse = (0..n)
                .map(|k| map(&format!("prev_coarse_{k}")))
                .collect::<Result<Vec<_>>>()?;
            Some(InitMaps { fine, coarse })
        }
        None => None,
    };
    Ok(Some(ResumePoint {
        frame,
        state: ResumeState {
            coarse: SimState {
                x: unflat(&r.f64("coarse_x")?.1),
                v: unflat(&r.f64("coarse_v")?.1),
                t_s: one(path, r.f64("t_s")?.1, "t_s")?,
            },
            seam_rest_m: r.f64("seam_rest_m")?.1,
            obstacle_margin_m: one(path, r.f64("obstacle_margin_m")?.1, "obstacle_margin_m")?,
            fine: unflat(&r.f64("fine_x")?.1),
            previous_maps,
        },
    }))
}

/// The USD writers of a run, all fed the same frames.
struct Writers {
    fine: (PathBuf, AnimationWriter),
    coarse: Option<(PathBuf, AnimationWriter)>,
    upsampled: Option<(PathBuf, AnimationWriter)>,
}

impl Writers {
    /// Opens the writers of `out` for `frames` frames of `p` on `scene`: new files, or with
    /// `resume_at` (a time in frames) the published ones continued after that frame.
    fn open(
        p: &Pipeline<'_>,
        scene: &Scene,
        frames: usize,
        out: &Outputs,
        resume_at: Option<f64>,
    ) -> Result<Writers> {
        let start = scene.frame_start as f64;
        let fine_edge = p.fine_edge_m;
        let stage = |meshes: Vec<MeshOut>, what: &str| {
            let mut meshes = meshes;
            for c in &scene.colliders {
                meshes.push(MeshOut::collider(c, scene.fps));
            }
            StageOut {
                fps: scene.fps,
                start,
                end: start + frames as f64,
                doc: Some(format!("{} ({what})", out.doc)),
                ascii: out.ascii,
                garments: Vec::new(),
                meshes,
                solver: Some(SolverSettings {
                    gravity_m_s2: scene.gravity_m_s2,
                    dt_s: p.coarse.sim.params.dt_s,
                }),
                over: None,
            }
        };
        let open = |path: &Path, st: &StageOut<'_>| -> Result<AnimationWriter> {
            match resume_at {
                Some(t) => AnimationWriter::resume(path, st, t),
                None => AnimationWriter::create(path, st),
            }
        };
        let mut fine_stage = stage(
            part_meshes(&p.fine_part_meshes, fine_edge),
            "fine garments M_f",
        );
        if let Some(clip_frames) = out.layer {
            fine_stage.over = Some(over_layer(scene, &fine_stage.meshes, clip_frames)?);
            fine_stage.meshes.retain(|m| m.animated);
            fine_stage.solver = None;
        }
        let mut writers = Writers {
            fine: (out.fine.clone(), open(&out.fine, &fine_stage)?),
            coarse: None,
            upsampled: None,
        };
        if let Some(path) = &out.coarse {
            let model = &p.coarse.sim.model;
            let coarse_part_meshes: Vec<_> = (0..model.parts.len())
                .map(|i| {
                    let q = &model.parts[i];
                    (q.name.clone(), model.part_mesh(i), q.fabric.clone())
                })
                .collect();
            let st = stage(
                part_meshes(&coarse_part_meshes, p.coarse.edge_m),
                "coarse M_int",
            );
            writers.coarse = Some((path.clone(), open(path, &st)?));
        }
        if let Some(path) = &out.upsampled {
            let st = stage(
                part_meshes(&p.fine_part_meshes, fine_edge),
                "coarse upsampled to the fine mesh",
            );
            writers.upsampled = Some((path.clone(), open(path, &st)?));
        }
        Ok(writers)
    }

    fn all(&mut self) -> impl Iterator<Item = &mut (PathBuf, AnimationWriter)> {
        std::iter::once(&mut self.fine)
            .chain(self.coarse.as_mut())
            .chain(self.upsampled.as_mut())
    }

    fn checkpoint(&mut self) -> Result<()> {
        for (_, w) in self.all() {
            w.checkpoint()?;
        }
        Ok(())
    }

    /// Writes `p`'s current state as frame `f` of a run starting at frame `start`, to every
    /// file.
    fn write_frame(&mut self, p: &mut Pipeline<'_>, start: f64, f: usize) -> Result<()> {
        let t = start + f as f64;
        self.fine.1.write_frame(t, &p.fine_part_positions())?;
        if let Some((_, cw)) = &mut self.coarse {
            cw.write_frame(t, &p.coarse.part_positions())?;
        }
        if self.upsampled.is_some() {
            let up = p.upsampled()?;
            if let Some((_, uw)) = &mut self.upsampled {
                uw.write_frame(t, &split(&up, &p.fine_parts))?;
            }
        }
        Ok(())
    }

    /// Finishes every file, logging what the writers warn about.
    fn finish(self) -> Result<()> {
        let Writers {
            fine,
            coarse,
            upsampled,
        } = self;
        for (path, w) in std::iter::once(fine).chain(coarse).chain(upsampled) {
            for warning in w.finish()? {
                tracing::warn!("{}: {warning}", path.display());
            }
        }
        Ok(())
    }
}

/// What a run shows in Rerun, frame by frame.
struct FrameLog<'a> {
    preview: Option<&'a Preview<'a>>,
    scene: &'a Scene,
    /// The scene's first frame.
    start: f64,
    /// The coarse mesh (its triangles).
    coarse_mesh: ClothMesh,
}

impl FrameLog<'_> {
    /// Logs the meshes' topologies and the still colliders.
    fn topology(&self, p: &Pipeline<'_>) -> Result<()> {
        let Some(r) = self.preview.map(|v| v.recorder) else {
            return Ok(());
        };
        let (scene, coarse_mesh) = (self.scene, &self.coarse_mesh);
        r.mesh_topology(paths::FINE, &p.fine.triangles, colours::FINE)?;
        r.mesh_topology(paths::M_INT, &coarse_mesh.triangles, colours::M_INT)?;
        if let Some(g) = self.preview.and_then(|v| v.ground_truth) {
            r.mesh_topology(paths::GROUND_TRUTH, &g.triangles, colours::GROUND_TRUTH)?;
        }
        if p.has_corrector() {
            r.mesh_topology(paths::COARSE, &coarse_mesh.triangles, colours::COARSE)?;
        }
        for c in scene.colliders.iter().filter(|c| !c.is_animated()) {
            let x: Vec<Vector3<f64>> = c.frames[0].iter().map(|q| q.cast()).collect();
            let entity = format!("{}/{}", paths::COLLIDERS, c.name);
            r.static_mesh(&entity, &c.triangles, &x, colours::COLLIDER)?;
        }
        for c in scene.colliders.iter().filter(|c| c.is_animated()) {
            let entity = format!("{}/{}", paths::COLLIDERS, c.name);
            r.mesh_topology(&entity, &c.triangles, colours::COLLIDER)?;
        }
        Ok(())
    }

    /// Logs frame `f` of `p`: positions (the fine mesh coloured by its distance to the ground
    /// truth when there is one), moving colliders and stage times.
    fn frame(&self, p: &mut Pipeline<'_>, f: usize) -> Result<()> {
        let Some(r) = self.preview.map(|v| v.recorder) else {
            return Ok(());
        };
        let (scene, coarse_mesh, start) = (self.scene, &self.coarse_mesh, self.start);
        let preview = self.preview;
        r.set_frame(start as i64 + f as i64);
        let t = start + f as f64;
        let gt = preview.and_then(|v| v.ground_truth.map(|g| (g, v.heat_max_m)));
        match gt.and_then(|(g, max)| Some((g.frame_at(t)?, g, max))) {
            Some((k, g, max_m)) if g.num_vertices() == p.fine.num_vertices() => {
                let e = vertex_errors(&g.frames[k], &p.fine.positions);
                r.mesh_heat_map(paths::FINE, &p.fine.triangles, &p.fine.positions, &e, max_m)?;
                r.mesh_positions(paths::GROUND_TRUTH, &g.triangles, &g.frames[k])?;
                let mean = e.iter().sum::<f64>() / e.len().max(1) as f64;
                r.scalar("error_mm/fine", mean * 1e3)?;
            }
            _ => r.mesh_positions(paths::FINE, &p.fine.triangles, &p.fine.positions)?,
        }
        r.mesh_positions(paths::M_INT, &coarse_mesh.triangles, &p.coarse.state.x)?;
        if p.has_corrector() && !p.simulated.is_empty() {
            r.mesh_positions(paths::COARSE, &coarse_mesh.triangles, &p.simulated)?;
        }
        let mut buf = Vec::new();
        for c in scene.colliders.iter().filter(|c| c.is_animated()) {
            c.positions_at(p.coarse.state.t_s, &mut buf);
            let entity = format!("{}/{}", paths::COLLIDERS, c.name);
            r.mesh_positions(&entity, &c.triangles, &buf)?;
        }
        if f > 0 {
            let t = p.times;
            r.scalar(&format!("{}/simulator_s", paths::TIMINGS), t.simulator_s)?;
            r.scalar(&format!("{}/corrector_s", paths::TIMINGS), t.corrector_s)?;
            r.scalar(&format!("{}/msr_s", paths::TIMINGS), t.msr_s)?;
            if p.push_clearance_m().is_some() {
                r.scalar(paths::PUSHED_OUT, p.pushed.inside as f64)?;
            }
        }
        Ok(())
    }
}

/// The override layer for the shot `scene` was read from, replacing `meshes` (the animated
/// ones: the garments), each at its prim.
fn over_layer(scene: &Scene, meshes: &[MeshOut], clip_frames: usize) -> Result<OverLayer> {
    let mut input: Option<&Path> = None;
    let mut prims = std::collections::BTreeMap::new();
    for m in meshes.iter().filter(|m| m.animated) {
        let source = scene.sources.get(&m.name).ok_or_else(|| {
            Error::Usage(format!(
                "garment '{}' was not read from a USD shot: a layered output overrides the \
                 shot's own prims (write a standalone stage instead)",
                m.name
            ))
        })?;
        match input {
            Some(file) if file != source.file => {
                return Err(Error::Usage(format!(
                    "garments come from {} and {}: a layered output overrides one shot",
                    file.display(),
                    source.file.display()
                )))
            }
            _ => input = Some(&source.file),
        }
        prims.insert(m.name.clone(), source.prim.clone());
    }
    let input = input.ok_or_else(|| Error::Invalid("no garment to write".into()))?;
    Ok(OverLayer {
        input: input.to_path_buf(),
        prims,
        clip_frames,
    })
}

fn part_meshes(parts: &[(String, ClothMesh, crate::garment::Fabric)], edge_m: f64) -> Vec<MeshOut> {
    parts
        .iter()
        .map(|(name, m, fabric)| {
            let mut out = MeshOut::cloth(name, m, fabric, edge_m);
            out.animated = true;
            out
        })
        .collect()
}

fn split<'x>(x: &'x [Vector3<f64>], parts: &[std::ops::Range<usize>]) -> Vec<&'x [Vector3<f64>]> {
    parts.iter().map(|r| &x[r.clone()]).collect()
}

/// Adds the last frame of `p` to the run's totals.
fn add_frame(totals: &mut FrameTimes, pushed: &mut PushOut, p: &Pipeline<'_>) {
    totals.simulator_s += p.times.simulator_s;
    totals.corrector_s += p.times.corrector_s;
    totals.msr_s += p.times.msr_s;
    *pushed = *pushed + p.pushed;
}

/// Runs `frames` frames of `p` (set up on `scene`) into `out`, shown in `preview` when given.
/// `progress` is called after every frame; returning `Break` stops the run after publishing
/// everything and a resume point. On failure every file keeps the frames published before it
/// and the resume point stays for the next call.
pub fn run_to_files(
    p: &mut Pipeline<'_>,
    scene: &Scene,
    frames: usize,
    out: &Outputs,
    preview: Option<&Preview<'_>>,
    mut progress: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<Report> {
    let start = scene.frame_start as f64;
    let resume_file = resume_path(&out.fine);
    let resumed = if out.resume {
        read_resume(&resume_file, &out.fingerprint)?.filter(|r| r.frame <= frames)
    } else {
        None
    };
    let coarse_mesh = p.coarse.sim.model.mesh.clone();
    let resume_at = resumed.as_ref().map(|r| start + r.frame as f64);
    let mut writers = Writers::open(p, scene, frames, out, resume_at)?;
    let log = FrameLog {
        preview,
        scene,
        start,
        coarse_mesh,
    };
    log.topology(p)?;

    let first = match resumed {
        Some(r) => {
            tracing::info!(
                "resuming {} after frame {} of {frames}",
                out.fine.display(),
                r.frame
            );
            let f = r.frame;
            p.restore(r.state)?;
            log.frame(p, f)?;
            f
        }
        None => {
            p.super_resolve()?;
            writers.write_frame(p, start, 0)?;
            log.frame(p, 0)?;
            0
        }
    };
    let _ = progress(&Progress {
        frame: first,
        frames,
        times: FrameTimes::default(),
        pushed: p.pushed,
        resumed_after: (first > 0).then_some(first),
    });
    let t0 = Instant::now();
    let mut last_publish = Instant::now();
    let mut totals = FrameTimes::default();
    let mut pushed = PushOut::default();
    let publish = |p: &Pipeline<'_>, w: &mut Writers, f: usize| -> Result<()> {
        w.checkpoint()?;
        write_resume(
            &resume_file,
            &out.fingerprint,
            &ResumePoint {
                frame: f,
                state: p.resume_state(),
            },
        )
    };
    for f in first + 1..=frames {
        if let Err(e) = p.advance_frame() {
            writers.checkpoint()?;
            return Err(e);
        }
        writers.write_frame(p, start, f)?;
        log.frame(p, f)?;
        add_frame(&mut totals, &mut pushed, p);
        let flow = progress(&Progress {
            frame: f,
            frames,
            times: p.times,
            pushed: p.pushed,
            resumed_after: (first > 0).then_some(first),
        });
        if flow.is_break() && f < frames {
            publish(p, &mut writers, f)?;
            return Ok(Report {
                frames_computed: f - first,
                resumed_after: (first > 0).then_some(first),
                totals,
                pushed,
                wall_s: t0.elapsed().as_secs_f64(),
                stopped: true,
            });
        }
        if last_publish.elapsed().as_secs_f64() >= out.publish_every_s && f < frames {
            publish(p, &mut writers, f)?;
            last_publish = Instant::now();
        }
    }
    writers.finish()?;
    if resume_file.exists() {
        std::fs::remove_file(&resume_file).map_err(|e| Error::io(&resume_file, e))?;
    }
    Ok(Report {
        frames_computed: frames - first,
        resumed_after: (first > 0).then_some(first),
        totals,
        pushed,
        wall_s: t0.elapsed().as_secs_f64(),
        stopped: false,
    })
}
