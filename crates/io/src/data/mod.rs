//! Training data (the paper's §3.3.1): a fine simulation (2.5 mm) is the ground truth M_f;
//! every step is downsampled to the coarse mesh (20 mm) as M_int, the corrector's target; and
//! every M_int is advanced by one coarse simulator step to M_c, the simulator's immediate error
//! that the corrector learns to remove (§3.1.3).
//!
//! # Format (a directory)
//! * `manifest.json`: [`Manifest`] — scene, variation, resolutions, dt, counts, git revision,
//!   `frames_done`; rewritten atomically after every frame.
//! * `meshes.safetensors`: for `coarse` and `fine`: `{r}_material` (N, 2) f64 metres,
//!   `{r}_triangles` (T, 3) u32, `{r}_panel` (N) u32, `{r}_seams` (S, 2) u32; panel names in
//!   the manifest. Coordinate maps are made from these on the fly (the ISR network's `msr` module).
//! * `frames/frame_NNNNN.safetensors`, one per output frame k = 1.. (steps (k−1)·s+1 ..= k·s):
//!   `int_x`, `int_v`, `coarse_x`, `coarse_v` (s, Nc, 3) f32 — M_int and M_c per step;
//!   `fine_x`, `fine_v` (Nf, 3) f32 — M_f at the frame's end; and, to resume (bit for bit
//!   on the test scenes; a garment touching many body faces resumes within round-off, most
//!   likely because the contact detector's rebuilt trees change the order of sums),
//!   `resume_fine_x`, `resume_fine_v` (Nf, 3) f64, `resume_fine_seam_rest`,
//!   `resume_coarse_seam_rest` f64, `resume_fine_margin`, `resume_coarse_margin` (1) f64 (the
//!   simulators' detection margins; absent in data sets made before they were kept).
//!
//! A killed run continues from its last complete frame (frame files are written whole, then
//! the manifest). All files are readable with `safetensors.numpy.load_file`.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::garment::Fabric;
use crate::mesh::ClothMesh;
use crate::scene::Scene;
use crate::scene_files::SceneFiles;
use crate::sim::driver::Simulation;
use crate::sim::step::SolverMode;
use crate::sim::SimState;
use crate::tensors::{TensorReader, TensorWriter};
use crate::transfer::Transfer;

/// Version of the on-disk format.
pub const FORMAT_VERSION: u32 = 1;

/// How one training sequence differs from the scene as loaded.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Variation {
    /// Garments (patterns and meshes) moved by this, m.
    pub garment_offset_m: [f64; 3],
    /// Colliders moved by this, m.
    pub collider_offset_m: [f64; 3],
    /// Garments turned about the vertical (y) axis through the origin, degrees.
    #[serde(default)]
    pub garment_yaw_deg: f64,
    /// Animated colliders start this far into their clip, s (another stretch of the motion).
    #[serde(default)]
    pub clip_start_s: f64,
}

impl Variation {
    /// Applies the variation to `scene`.
    pub fn apply(&self, scene: &mut Scene) {
        if self.garment_yaw_deg != 0.0 {
            let r = nalgebra::Rotation3::from_axis_angle(
                &Vector3::y_axis(),
                self.garment_yaw_deg.to_radians(),
            );
            for garment in &mut scene.garments {
                for p in &mut garment.panels {
                    let d = p.placement.rotation_xyz_deg.map(f64::to_radians);
                    // R = Rz·Ry·Rx is nalgebra's from_euler_angles(roll = x, pitch = y, yaw = z).
                    let old = nalgebra::Rotation3::from_euler_angles(d.x, d.y, d.z);
                    let (x, y, z) = (r * old).euler_angles();
                    p.placement.rotation_xyz_deg = Vector3::new(x, y, z).map(f64::to_degrees);
                    p.placement.translation_m = r * p.placement.translation_m;
                }
            }
            for c in &mut scene.cloths {
                c.mesh.positions.iter_mut().for_each(|p| *p = r * *p);
            }
        }
        // Garments are placed around the animated bodies as they are at the clip's start (a
        // GarmentCode pattern around the rest pose): started later in the clip, they go where
        // the bodies have walked to (the horizontal move of their centroid), or they are
        // dressed around empty space and fall.
        let mut g = Vector3::from(self.garment_offset_m);
        if self.clip_start_s != 0.0 {
            g += root_motion(&scene.colliders, self.clip_start_s);
            for c in &mut scene.colliders {
                c.times_s.iter_mut().for_each(|t| *t -= self.clip_start_s);
            }
        }
        for garment in &mut scene.garments {
            for p in &mut garment.panels {
                p.placement.translation_m += g;
            }
        }
        for c in &mut scene.cloths {
            c.mesh.positions.iter_mut().for_each(|p| *p += g);
        }
        let o = Vector3::from(self.collider_offset_m);
        if o != Vector3::zeros() {
            scene.colliders = std::mem::take(&mut scene.colliders)
                .into_iter()
                .map(|c| c.transformed(1.0, o))
                .collect();
        }
    }
}

/// The horizontal (x, z) move of the animated colliders' point centroid from their clip's
/// start to `t_s` into it, m (zero without animated colliders).
fn root_motion(colliders: &[crate::scene::Collider], t_s: f64) -> Vector3<f64> {
    let (mut start, mut then, mut n) = (Vector3::zeros(), Vector3::zeros(), 0usize);
    let mut buf = Vec::new();
    for c in colliders.iter().filter(|c| c.is_animated()) {
        let t0 = c.times_s.first().copied().unwrap_or(0.0);
        c.positions_at(t0, &mut buf);
        start += buf.iter().sum::<Vector3<f64>>();
        c.positions_at(t0 + t_s, &mut buf);
        then += buf.iter().sum::<Vector3<f64>>();
        n += buf.len();
    }
    if n == 0 {
        return Vector3::zeros();
    }
    let d = (then - start) / n as f64;
    Vector3::new(d.x, 0.0, d.z)
}

/// What a data set holds (`manifest.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// [`FORMAT_VERSION`].
    pub format_version: u32,
    /// The scene file, as given.
    pub scene: String,
    /// Applied to the scene.
    pub variation: Variation,
    /// Requested coarse / fine edge lengths, m.
    pub coarse_edge_m: f64,
    /// Requested fine edge length, m.
    pub fine_edge_m: f64,
    /// Mean edge of the meshes actually made, m.
    pub coarse_mean_edge_m: f64,
    /// Mean fine edge, m.
    pub fine_mean_edge_m: f64,
    /// Time step, s.
    pub dt_s: f64,
    /// Steps per output frame.
    pub steps_per_frame: usize,
    /// Output frames per second.
    pub fps: f64,
    /// Frames asked for.
    pub frames_requested: usize,
    /// Frames complete on disk.
    pub frames_done: usize,
    /// Coarse / fine vertex and triangle counts.
    pub coarse_vertices: usize,
    /// Fine vertices.
    pub fine_vertices: usize,
    /// Coarse triangles.
    pub coarse_triangles: usize,
    /// Fine triangles.
    pub fine_triangles: usize,
    /// Panel names (index = panel id in `meshes.safetensors`), the same at both resolutions.
    pub panels: Vec<String>,
    /// Fabric preset names per garment part.
    pub fabrics: Vec<String>,
    /// The fabric of each garment part, with its parameters (what the ISR is conditioned on);
    /// empty in data sets made before it was recorded.
    #[serde(default)]
    pub fabric_values: Vec<Fabric>,
    /// Whether garments were sewn and settled before frame 0 (at the coarse resolution, then
    /// on the fine mesh from the coarse result: [`crate::sim::driver::Simulation::dress_from`]).
    pub dressed: bool,
    /// The clothsr revision that made it.
    pub git_revision: String,
    /// One Newton iteration per step when accepted ([`crate::sim::SimParams::newton_exact`]
    /// off), for both resolutions; the corrector must run beside the same solver.
    #[serde(default)]
    pub fast: bool,
    /// The fine simulation's solver mode ([`SolverMode::name`]): `data` for data sets checked
    /// against a tight reference (`clothsr lab converge`); empty in data sets made before,
    /// whose fine simulation ran in the mode `fast` names, off the converged solution on
    /// stiff fabrics. Training and calibration refuse those ([`Manifest::check_reference`]).
    #[serde(default)]
    pub fine_solver: String,
    /// The fine simulation's linear solves taken at their iteration cap (at a step's last
    /// halving) and sub-steps taken with Newton's iterations run out, over the frames done.
    #[serde(default)]
    pub fine_unconverged: [usize; 2],
    /// Cloth self-collision at both resolutions.
    #[serde(default = "yes")]
    pub self_collision: bool,
    /// The files the scene was loaded from, when it came from files: training reloads it to
    /// run the coarse simulator (rollouts).
    #[serde(default)]
    pub source: Option<SceneSource>,
    /// Contact thickness d̂ of the coarse simulation when it was set to the fine one's
    /// ([`Options::match_contact_thickness`]), m; `None`: the coarse mesh's own default.
    #[serde(default)]
    pub coarse_dhat_m: Option<f64>,
    /// Set when this data set continues another from one of its frames ([`fork`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fork: Option<Fork>,
}

/// Where a forked data set branched off ([`fork`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Fork {
    /// The data set it continues (in the file: relative to the fork's folder).
    pub from: PathBuf,
    /// Its last frame shared with `from`: frames 1..=frame are copies.
    pub frame: usize,
    /// The fine garment state at the end of `frame` moved by this before the simulation went on, m.
    pub offset_m: [f64; 3],
}

impl Manifest {
    /// Fails unless the fine simulation ran in a mode checked against a tight reference
    /// ([`SolverMode::Data`] or [`SolverMode::Tight`]): data sets made before learned the
    /// fast solver's error on stiff fabrics, and neither training nor calibration takes them.
    pub fn check_reference(&self, dir: &Path) -> Result<()> {
        match SolverMode::from_name(&self.fine_solver) {
            Some(SolverMode::Data | SolverMode::Tight) => Ok(()),
            _ => Err(Error::bad_input(
                dir.join("manifest.json"),
                "made before the fine simulation was checked against a tight reference (its \
                 fine steps ran in fast mode, off the converged solution on stiff fabrics); \
                 make it again with `clothsr lab dataset` or `clothsr fit`",
            )),
        }
    }

    /// The same manifest with `f` applied to every file it names (its source, its fork's).
    fn map_paths(mut self, f: impl Fn(&Path) -> PathBuf) -> Manifest {
        self.source = self.source.map(|s| s.map_paths(&f));
        if let Some(fork) = &mut self.fork {
            fork.from = f(&fork.from);
        }
        self
    }

    /// The [`generate`] options that made this data set, for `frames` frames: resuming it
    /// (or a [`fork`] of it) with these continues the same simulation.
    pub fn options(&self, frames: usize) -> Options {
        Options {
            coarse_edge_m: self.coarse_edge_m,
            fine_edge_m: self.fine_edge_m,
            frames,
            dress: self.dressed,
            self_collision: self.self_collision,
            variation: self.variation,
            fast: self.fast,
            fine_mode: SolverMode::from_name(&self.fine_solver).unwrap_or(SolverMode::Data),
            source: self.source.clone(),
            match_contact_thickness: self.coarse_dhat_m.is_some(),
        }
    }
}

fn yes() -> bool {
    true
}

/// Where a data set's scene came from, so that tools can load it again.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneSource {
    /// The scene file (USD, GarmentCode JSON, OBJ): absolute in memory, relative to the
    /// folder of the file that records it on disk ([`crate::relative_to`]).
    pub scene: PathBuf,
    /// Extra collider files.
    pub colliders: Vec<PathBuf>,
    /// The avatar file.
    pub avatar: Option<PathBuf>,
    /// Fabric preset for garments without one.
    pub fabric: String,
}

impl SceneSource {
    /// The same files named by absolute paths ([`crate::absolute`]).
    pub fn absolute(&self) -> SceneSource {
        self.map_paths(crate::absolute)
    }

    /// The same files with `f` applied to each path.
    pub fn map_paths(&self, f: impl Fn(&Path) -> PathBuf) -> SceneSource {
        SceneSource {
            scene: f(&self.scene),
            colliders: self.colliders.iter().map(|c| f(c)).collect(),
            avatar: self.avatar.as_deref().map(&f),
            fabric: self.fabric.clone(),
        }
    }

    /// Loads the scene as the data set saw it before its variation.
    pub fn load(&self) -> Result<Scene> {
        let fabric = crate::garment::Fabric::preset(&self.fabric)
            .ok_or_else(|| Error::Usage(format!("unknown fabric preset '{}'", self.fabric)))?;
        let mut scene = Scene::load(&self.scene, &fabric)?;
        for c in self.colliders.iter().chain(&self.avatar) {
            scene.add_collider_file(c)?;
        }
        Ok(scene)
    }
}

/// Options of [`generate`].
#[derive(Debug, Clone)]
pub struct Options {
    /// Coarse edge, m (20 mm).
    pub coarse_edge_m: f64,
    /// Fine edge, m (2.5 mm).
    pub fine_edge_m: f64,
    /// Output frames.
    pub frames: usize,
    /// Sew and settle before frame 0 when the garments have seams.
    pub dress: bool,
    /// Cloth self-collision.
    pub self_collision: bool,
    /// Scene variation.
    pub variation: Variation,
    /// The coarse simulation in fast mode (see [`Manifest::fast`]).
    pub fast: bool,
    /// The fine simulation's solver mode ([`SolverMode::Data`] for training data).
    pub fine_mode: SolverMode,
    /// The scene's files, recorded in the manifest when given.
    pub source: Option<SceneSource>,
    /// Give the coarse simulation the fine one's contact thickness d̂ (the simulator's default
    /// scales d̂ with the edge length: 3 mm at 20 mm against 0.75 mm at 5 mm). A thickness is
    /// a property of the cloth, not of its mesh; with the default, the coarse cloth rests a
    /// few millimetres further from every body than the fine one and the corrector has to
    /// pull it back through the repulsion at every step. Garments with seams keep the coarse
    /// mesh's own ([`coarse_contact_thickness`]).
    pub match_contact_thickness: bool,
}

/// Progress of a run.
#[derive(Debug, Clone, Copy)]
pub struct Progress {
    /// Frames complete.
    pub frames_done: usize,
    /// Frames asked for.
    pub frames: usize,
}

fn frame_path(dir: &Path, k: usize) -> PathBuf {
    dir.join("frames").join(format!("frame_{k:05}.safetensors"))
}

/// Vectors as a flat (N·3) f32 array, for tensor files and networks.
pub fn flat32(x: &[Vector3<f64>]) -> Vec<f32> {
    x.iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect()
}

/// Positions as a flat (N·3) array, for tensor files.
pub fn flat64(x: &[Vector3<f64>]) -> Vec<f64> {
    x.iter().flat_map(|p| [p.x, p.y, p.z]).collect()
}

/// The inverse of [`flat64`].
pub fn unflat(v: &[f64]) -> Vec<Vector3<f64>> {
    v.chunks_exact(3)
        .map(|c| Vector3::new(c[0], c[1], c[2]))
        .collect()
}

fn write_meshes(path: &Path, coarse: &ClothMesh, fine: &ClothMesh) -> Result<()> {
    let mut w = TensorWriter::new();
    for (r, m) in [("coarse", coarse), ("fine", fine)] {
        let mat: Vec<f64> = m.material.iter().flat_map(|p| [p.x, p.y]).collect();
        w.f64(&format!("{r}_material"), &[m.num_vertices(), 2], &mat);
        w.u32(
            &format!("{r}_triangles"),
            &[m.triangles.len(), 3],
            m.triangles.as_flattened(),
        );
        w.u32(
            &format!("{r}_panel"),
            &[m.num_vertices()],
            &m.panel_of_vertex,
        );
        w.u32(
            &format!("{r}_seams"),
            &[m.seam_pairs.len(), 2],
            m.seam_pairs.as_flattened(),
        );
    }
    w.write(path)
}

/// Generates (or resumes) a data set in `dir` for `scene` (loaded from `scene_name`).
pub fn generate(
    scene: &Scene,
    scene_name: &str,
    opts: &Options,
    dir: &Path,
    mut progress: impl FnMut(Progress),
) -> Result<Manifest> {
    let mut scene = scene.clone();
    opts.variation.apply(&mut scene);
    let self_collision = opts.self_collision;
    let mut fine = new_simulation(
        &scene,
        opts.fine_edge_m,
        self_collision,
        opts.fine_mode,
        None,
    )?;
    let coarse_dhat_m = coarse_contact_thickness(&fine, opts.match_contact_thickness);
    let mut coarse = new_simulation(
        &scene,
        opts.coarse_edge_m,
        self_collision,
        coarse_mode(opts.fast),
        coarse_dhat_m,
    )?;
    let (cm, fm) = (&coarse.sim.model.mesh, &fine.sim.model.mesh);
    if cm.panel_names != fm.panel_names {
        return Err(Error::Invalid(
            "the coarse and fine meshes have different panels".into(),
        ));
    }
    let transfer = Transfer::new(cm, fm)?;
    let mut manifest = new_manifest(scene_name, opts, &coarse, &fine, coarse_dhat_m);
    let manifest_path = dir.join("manifest.json");
    std::fs::create_dir_all(dir.join("frames")).map_err(|e| Error::io(dir, e))?;
    let start_frame = resume_point(dir, &mut manifest)?;
    if start_frame > 0 {
        restore(dir, start_frame, &mut fine, &mut coarse)?;
    } else {
        start_new(dir, &manifest, &transfer, &mut fine, &mut coarse)?;
    }
    manifest.frames_done = start_frame;
    progress(Progress {
        frames_done: start_frame,
        frames: opts.frames,
    });
    let mut prev_int = downsample(&transfer, &fine.state);
    for k in start_frame + 1..=opts.frames {
        // Every frame is a resume point: what the steps cached (hierarchies, clearances,
        // factors) starts afresh here, as it does after a resume, so that a resumed data set
        // is bit-identical to one made without the stop.
        fine.sim.forget_history();
        coarse.sim.forget_history();
        let (buf, unconverged) = simulate_frame(&mut fine, &mut coarse, &transfer, &mut prev_int)?;
        if unconverged != [0, 0] {
            tracing::warn!(
                "frame {k}: the fine simulation took {} linear solves at their cap and {} \
                 sub-steps with Newton unconverged, at its smallest time step",
                unconverged[0],
                unconverged[1]
            );
        }
        manifest.fine_unconverged[0] += unconverged[0];
        manifest.fine_unconverged[1] += unconverged[1];
        write_frame(&frame_path(dir, k), &buf, &fine, &coarse)?;
        manifest.frames_done = k;
        crate::write_atomic(&manifest_path, &manifest_json(&manifest, dir)?)?;
        progress(Progress {
            frames_done: k,
            frames: opts.frames,
        });
    }
    Ok(manifest)
}

/// The manifest of a data set made with `opts` before any frame is done.
fn new_manifest(
    scene_name: &str,
    opts: &Options,
    coarse: &Simulation,
    fine: &Simulation,
    coarse_dhat_m: Option<f64>,
) -> Manifest {
    let (cm, fm) = (&coarse.sim.model.mesh, &fine.sim.model.mesh);
    Manifest {
        format_version: FORMAT_VERSION,
        scene: scene_name.to_string(),
        variation: opts.variation,
        coarse_edge_m: opts.coarse_edge_m,
        fine_edge_m: opts.fine_edge_m,
        coarse_mean_edge_m: coarse.edge_m,
        fine_mean_edge_m: fine.edge_m,
        dt_s: fine.sim.params.dt_s,
        steps_per_frame: fine.steps_per_frame,
        fps: fine.fps,
        frames_requested: opts.frames,
        frames_done: 0,
        coarse_vertices: cm.num_vertices(),
        fine_vertices: fm.num_vertices(),
        coarse_triangles: cm.triangles.len(),
        fine_triangles: fm.triangles.len(),
        panels: fm.panel_names.clone(),
        fabrics: fine
            .sim
            .model
            .parts
            .iter()
            .map(|p| p.fabric.name.clone())
            .collect(),
        fabric_values: fine
            .sim
            .model
            .parts
            .iter()
            .map(|p| p.fabric.clone())
            .collect(),
        dressed: opts.dress && !fm.seam_pairs.is_empty(),
        git_revision: env!("CLOTHSR_GIT_REVISION").to_string(),
        fast: opts.fast,
        fine_solver: opts.fine_mode.name().to_string(),
        fine_unconverged: [0, 0],
        self_collision: opts.self_collision,
        source: opts.source.clone(),
        coarse_dhat_m,
        fork: None,
    }
}

/// The frame a run in `dir` starts after: 0 for a new data set, or the frames done of the
/// compatible run on disk (its fork record then carries over to `manifest`).
fn resume_point(dir: &Path, manifest: &mut Manifest) -> Result<usize> {
    // Resume when a compatible run is on disk.
    let manifest_path = dir.join("manifest.json");
    if !manifest_path.exists() {
        return Ok(0);
    }
    let old = read_manifest(dir)?;
    let same = Manifest {
        frames_done: old.frames_done,
        frames_requested: old.frames_requested,
        git_revision: old.git_revision.clone(),
        fork: old.fork.clone(),
        fine_unconverged: old.fine_unconverged,
        // Recorded since; a run made before still resumes.
        fabric_values: if old.fabric_values.is_empty() {
            Vec::new()
        } else {
            manifest.fabric_values.clone()
        },
        ..manifest.clone()
    };
    // As stored: a value read back from JSON may differ from the one computed in its last bit
    // (serde_json's default parser), and a manifest copied from a read one (a fork's) carries
    // that; once more through JSON both are the same.
    let as_stored = |m: &Manifest| -> Option<serde_json::Value> {
        serde_json::from_str(&serde_json::to_string(m).ok()?).ok()
    };
    if as_stored(&same) != as_stored(&old) {
        return Err(Error::bad_input(
            &manifest_path,
            "a different data set is already here (scene, variation, resolutions or meshes \
             differ); choose another directory",
        ));
    }
    manifest.fork = old.fork;
    manifest.fine_unconverged = old.fine_unconverged;
    Ok(old.frames_done)
}

/// M_int of a fine state: downsampled to the coarse mesh.
fn downsample(transfer: &Transfer, s: &SimState) -> SimState {
    SimState {
        x: transfer.downsample(&s.x),
        v: transfer.downsample(&s.v),
        t_s: s.t_s,
    }
}

/// Dresses the garments as data sets do: at the coarse resolution (rolled, sewn, draped), then
/// carried onto the fine mesh (Phong-tessellated, so that it bulges with the body instead of
/// cutting chords into it) where it sews its last millimetres and drapes again. The fine mesh
/// dressed from its flat pattern was very slow, its steps halved under the move limits while
/// the seams were open. `transfer` goes from `coarse`'s mesh to `fine`'s.
pub fn dress_fine_from_coarse(
    coarse: &mut Simulation,
    fine: &mut Simulation,
    transfer: &Transfer,
) -> Result<()> {
    let (max_s, settle_s, gap_m) = crate::dressed::DRESSING;
    let c = coarse.dress(max_s, settle_s, gap_m)?;
    let x = transfer.upsample_phong(
        &coarse.state.x,
        &coarse.sim.model.mesh.triangles,
        DRESS_PHONG_ALPHA,
    );
    tracing::info!(
        "dressed the coarse mesh ({} sewing, {} settling steps, seams {:.1} mm); dressing \
         the fine mesh ({} vertices) from it",
        c.sew_steps,
        c.settle_steps,
        c.seam_gap_m * 1e3,
        x.len()
    );
    let f = fine.dress_from(x, FINE_SEWING_S, 0.3, 1e-3)?;
    tracing::info!(
        "dressed the fine mesh ({} sewing, {} settling steps, seams {:.1} mm)",
        f.sew_steps,
        f.settle_steps,
        f.seam_gap_m * 1e3
    );
    Ok(())
}

/// Restores both simulations to the end of frame `start_frame` from its frame file in `dir`.
fn restore(
    dir: &Path,
    start_frame: usize,
    fine: &mut Simulation,
    coarse: &mut Simulation,
) -> Result<()> {
    let path = frame_path(dir, start_frame);
    let r = TensorReader::open(&path)?;
    let x = unflat(&r.f64("resume_fine_x")?.1);
    let v = unflat(&r.f64("resume_fine_v")?.1);
    if x.len() != fine.sim.model.mesh.num_vertices() || v.len() != x.len() {
        return Err(Error::bad_input(
            &path,
            "resume state has the wrong vertex count",
        ));
    }
    fine.state.x = x;
    fine.state.v = v;
    fine.state.t_s += (start_frame * fine.steps_per_frame) as f64 * fine.sim.params.dt_s;
    fine.sim.set_seam_rest(&r.f64("resume_fine_seam_rest")?.1)?;
    coarse
        .sim
        .set_seam_rest(&r.f64("resume_coarse_seam_rest")?.1)?;
    restore_welds(&r, "resume_fine_welded", fine)?;
    restore_welds(&r, "resume_coarse_welded", coarse)?;
    // The detection margins follow the last step's largest move, and a step's Newton
    // displacement is bounded by them: a run resumed without them takes a different first
    // step (millimetres on a walking skirt).
    if r.has("resume_fine_margin") || r.has("resume_coarse_margin") {
        fine.sim
            .set_obstacle_margin_m(r.scalar_f64("resume_fine_margin")?);
        coarse
            .sim
            .set_obstacle_margin_m(r.scalar_f64("resume_coarse_margin")?);
    } else {
        tracing::warn!(
            "{}: no detection margins (written by an older clothsr); the run continues \
             from its state but not exactly as it would have",
            path.display()
        );
    }
    Ok(())
}

/// Starts a new data set in `dir`: dresses the garments when the manifest says so, starts the
/// coarse seams no longer than the downsampled fine ones, and writes the meshes and the
/// manifest.
fn start_new(
    dir: &Path,
    manifest: &Manifest,
    transfer: &Transfer,
    fine: &mut Simulation,
    coarse: &mut Simulation,
) -> Result<()> {
    if manifest.dressed {
        dress_fine_from_coarse(coarse, fine, transfer)?;
    }
    let rest: Vec<f64> = {
        let int = downsample(transfer, &fine.state);
        coarse
            .sim
            .model
            .mesh
            .seam_pairs
            .iter()
            .zip(coarse.sim.seam_rest())
            .map(|(p, r)| r.min((int.x[p[0] as usize] - int.x[p[1] as usize]).norm()))
            .collect()
    };
    coarse.sim.set_seam_rest(&rest)?;
    write_meshes(
        &dir.join("meshes.safetensors"),
        &coarse.sim.model.mesh,
        &fine.sim.model.mesh,
    )?;
    crate::write_atomic(&dir.join("manifest.json"), &manifest_json(manifest, dir)?)
}

/// The steps of one output frame: the fine simulation's, each downsampled to M_int, and the
/// coarse step from the previous M_int (`prev_int`, updated) to M_c; as `int_x`, `int_v`,
/// `coarse_x`, `coarse_v`.
fn simulate_frame(
    fine: &mut Simulation,
    coarse: &mut Simulation,
    transfer: &Transfer,
    prev_int: &mut SimState,
) -> Result<([Vec<f32>; 4], [usize; 2])> {
    let (nc, s) = (coarse.sim.model.num_vertices(), fine.steps_per_frame);
    let mut buf: [Vec<f32>; 4] = std::array::from_fn(|_| Vec::with_capacity(s * nc * 3));
    let mut unconverged = [0, 0];
    for _ in 0..s {
        let st = fine.step()?;
        unconverged[0] += st.capped_solves;
        unconverged[1] += st.unconverged_steps;
        let int = downsample(transfer, &fine.state);
        let (c, _) = coarse.step_from(prev_int)?;
        buf[0].extend(flat32(&int.x));
        buf[1].extend(flat32(&int.v));
        buf[2].extend(flat32(&c.x));
        buf[3].extend(flat32(&c.v));
        *prev_int = int;
    }
    Ok((buf, unconverged))
}

/// 1 when `sim`'s seams are welded, else 0 (a frame file's `resume_*_welded`).
fn welded(sim: &Simulation) -> f64 {
    f64::from(u8::from(sim.sim.welded()))
}

/// Welds `sim`'s seams when the frame file `r` says they were (`key`; files written before
/// seams were welded have no such entry).
fn restore_welds(r: &TensorReader, key: &str, sim: &mut Simulation) -> Result<()> {
    if r.has(key) && r.scalar_f64(key)? > 0.5 {
        sim.sim.weld_seams(&mut sim.state, 0.0);
    }
    Ok(())
}

/// Writes a frame file: the frame's steps `buf` ([`simulate_frame`]), the fine state at its
/// end and what a resume needs.
fn write_frame(
    path: &Path,
    buf: &[Vec<f32>; 4],
    fine: &Simulation,
    coarse: &Simulation,
) -> Result<()> {
    let (nc, s) = (coarse.sim.model.num_vertices(), fine.steps_per_frame);
    let nf = fine.state.x.len();
    let mut w = TensorWriter::new();
    for (name, data) in ["int_x", "int_v", "coarse_x", "coarse_v"].iter().zip(buf) {
        w.f32(name, &[s, nc, 3], data);
    }
    w.f32("fine_x", &[nf, 3], &flat32(&fine.state.x))
        .f32("fine_v", &[nf, 3], &flat32(&fine.state.v))
        .f64("resume_fine_x", &[nf, 3], &flat64(&fine.state.x))
        .f64("resume_fine_v", &[nf, 3], &flat64(&fine.state.v))
        .f64(
            "resume_fine_seam_rest",
            &[fine.sim.seam_rest().len()],
            fine.sim.seam_rest(),
        )
        .f64(
            "resume_coarse_seam_rest",
            &[coarse.sim.seam_rest().len()],
            coarse.sim.seam_rest(),
        )
        .f64("resume_fine_welded", &[1], &[welded(fine)])
        .f64("resume_coarse_welded", &[1], &[welded(coarse)])
        .f64("resume_fine_margin", &[1], &[fine.sim.obstacle_margin_m()])
        .f64(
            "resume_coarse_margin",
            &[1],
            &[coarse.sim.obstacle_margin_m()],
        );
    w.write(path)
}

/// Forks the data set in `src` at its frame `frame`: writes `dst` holding copies of frames
/// 1..=`frame`, with the fine garment's state at the end of `frame` (the one a resume starts
/// from) moved by `offset_m`, and a manifest that records the fork. [`generate`] with
/// [`Manifest::options`] then continues it from that moved state: the distance between the
/// two data sets' later frames is how far a change of `offset_m` carries, the ground truth's
/// own predictability floor (`clothsr lab rollout --floor`).
///
/// The copy is made beside `dst` and renamed into place, so a killed or failed fork leaves no
/// data set. Forking again into a `dst` that already holds the same fork returns its manifest
/// (its frames beyond `frame` are kept, for resuming). A fork of a fork records only the last
/// fork.
pub fn fork(src: &Path, frame: usize, offset_m: Vector3<f64>, dst: &Path) -> Result<Manifest> {
    let source = read_manifest(src)?;
    // A fork continues the fine simulation in the source's mode: one made before the data
    // mode cannot be continued as it was made.
    source.check_reference(src)?;
    let src_manifest = src.join("manifest.json");
    if frame == 0 || frame > source.frames_done {
        return Err(Error::bad_input(
            &src_manifest,
            format!(
                "cannot fork at frame {frame}: frames 1..={} are done",
                source.frames_done
            ),
        ));
    }
    if !offset_m.iter().all(|v| v.is_finite()) {
        return Err(Error::Invalid(format!(
            "the fork offset {offset_m:?} is not finite"
        )));
    }
    let record = Fork {
        from: crate::absolute(src),
        frame,
        offset_m: offset_m.into(),
    };
    let dst_manifest = dst.join("manifest.json");
    if dst_manifest.exists() {
        let old = read_manifest(dst)?;
        if old.fork.as_ref() == Some(&record) {
            return Ok(old);
        }
        return Err(Error::bad_input(
            &dst_manifest,
            format!(
                "another data set is already here, not {} forked at frame {frame} by {:?} m; \
                 choose another directory",
                src.display(),
                record.offset_m
            ),
        ));
    }
    if dst.exists() {
        let empty = std::fs::read_dir(dst)
            .map_err(|e| Error::io(dst, e))?
            .next()
            .is_none();
        if !empty {
            return Err(Error::bad_input(
                dst,
                "exists and is not a data set; choose another directory",
            ));
        }
    }
    let name = dst
        .file_name()
        .ok_or_else(|| Error::bad_input(dst, "not a directory name"))?;
    let parent = match dst.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let tmp = parent.join(format!(".{}.fork-partial", name.to_string_lossy()));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(|e| Error::io(&tmp, e))?;
    }
    let made = fork_into(src, frame, offset_m, source, record, &tmp).and_then(|m| {
        if dst.exists() {
            std::fs::remove_dir(dst).map_err(|e| Error::io(dst, e))?;
        }
        std::fs::rename(&tmp, dst).map_err(|e| Error::io(dst, e))?;
        Ok(m)
    });
    if made.is_err() {
        // Best effort: the error that matters is the one returned.
        let _ = std::fs::remove_dir_all(&tmp);
    }
    made
}

/// [`fork`]'s copy into `tmp`.
fn fork_into(
    src: &Path,
    frame: usize,
    offset_m: Vector3<f64>,
    source: Manifest,
    record: Fork,
    tmp: &Path,
) -> Result<Manifest> {
    std::fs::create_dir_all(tmp.join("frames")).map_err(|e| Error::io(tmp, e))?;
    let copy = |from: PathBuf, to: PathBuf| -> Result<()> {
        std::fs::copy(&from, &to).map_err(|e| {
            Error::Invalid(format!(
                "copying {} to {}: {e}",
                from.display(),
                to.display()
            ))
        })?;
        Ok(())
    };
    copy(
        src.join("meshes.safetensors"),
        tmp.join("meshes.safetensors"),
    )?;
    for k in 1..frame {
        copy(frame_path(src, k), frame_path(tmp, k))?;
    }
    let last = frame_path(src, frame);
    let r = TensorReader::open(&last)?;
    let mut w = TensorWriter::from_reader(&r)?;
    let (shape, mut x) = r.f64("resume_fine_x")?;
    for p in x.chunks_exact_mut(3) {
        p.iter_mut().zip(offset_m.iter()).for_each(|(a, o)| *a += o);
    }
    w.f64("resume_fine_x", &shape, &x);
    w.write(&frame_path(tmp, frame))?;
    let manifest = Manifest {
        frames_done: frame,
        frames_requested: frame,
        fork: Some(record),
        ..source
    };
    crate::write_atomic(&tmp.join("manifest.json"), &manifest_json(&manifest, tmp)?)?;
    Ok(manifest)
}

/// At most this long the fine mesh sews, from the coarse dressing, s: seams the coarse mesh
/// could not close (zero ease at the hips holds them a few millimetres open) close at a
/// tenth of a millimetre per 0.1 s at 10 mm, and every step of a 100K-vertex skirt costs
/// seconds.
const FINE_SEWING_S: f64 = 0.1;

/// Phong blend of the coarse dressed garment carried onto the fine mesh (¾, Phong
/// tessellation's usual choice).
const DRESS_PHONG_ALPHA: f64 = 0.75;

/// The coarse simulation's solver mode: fast (the pipeline's) or converged.
pub fn coarse_mode(fast: bool) -> SolverMode {
    if fast {
        SolverMode::Fast
    } else {
        SolverMode::Converged
    }
}

/// The contact thickness of the coarse simulation beside the fine simulation `fine`, m
/// (`None`: the coarse mesh's own, 15 % of its edge): the fine one's when `matched`, so
/// that the levels rest at the same distance from a body, except for garments with seams.
/// A garment wraps a body curved at the scale of the coarse edge (arms, legs, the sides of
/// the torso), and the fine mesh made from the coarse one lies on its triangles' chords and
/// dips between its vertices: at the fine thickness a T-shirt on the walking avatar put 8 %
/// of its fine vertices inside the body, at its own under 0.1 %
/// (`docs/experiments/garments.md`). Sheets on props keep the matched thickness, which
/// brings the resolution ladder together (`docs/experiments/reference.md`).
pub fn coarse_contact_thickness(fine: &Simulation, matched: bool) -> Option<f64> {
    (matched && fine.sim.model.mesh.seam_pairs.is_empty())
        .then_some(fine.sim.params.collision.dhat_m)
}

/// A simulation of `scene` at `edge_m` with the data tool's solver settings: self-collision
/// on or off, a solver mode, and optionally a contact thickness d̂ (also the detection
/// margin).
pub fn new_simulation(
    scene: &Scene,
    edge_m: f64,
    self_collision: bool,
    mode: SolverMode,
    dhat_m: Option<f64>,
) -> Result<Simulation> {
    Simulation::new(scene, edge_m, |p| {
        p.collision.self_collision = self_collision;
        mode.apply(p);
        if let Some(d) = dhat_m {
            p.collision.dhat_m = d;
            p.detection_margin_m = d;
        }
    })
}

/// The coarse simulation a data set was made with: `scene` (as given to [`generate`], before
/// the variation) with the manifest's variation, resolution and solver settings. Fails when
/// the coarse mesh it makes differs from the one stored in `dir`. Seam rest lengths are those
/// stored with frame `frame` (0: as meshed).
pub fn coarse_simulation(scene: &Scene, dir: &Path, frame: usize) -> Result<Simulation> {
    let m = read_manifest(dir)?;
    let mut scene = scene.clone();
    m.variation.apply(&mut scene);
    let mut sim = new_simulation(
        &scene,
        m.coarse_edge_m,
        m.self_collision,
        coarse_mode(m.fast),
        m.coarse_dhat_m,
    )?;
    let meshes_path = dir.join("meshes.safetensors");
    let r = TensorReader::open(&meshes_path)?;
    let (_, material) = r.f64("coarse_material")?;
    let mesh = &sim.sim.model.mesh;
    let same = material.len() == 2 * mesh.num_vertices()
        && material
            .chunks_exact(2)
            .zip(&mesh.material)
            .all(|(a, b)| (a[0] - b.x).abs() < 1e-9 && (a[1] - b.y).abs() < 1e-9);
    if !same {
        return Err(Error::bad_input(
            &meshes_path,
            "the scene meshes to a different coarse mesh than the one stored here",
        ));
    }
    if frame > 0 {
        let r = TensorReader::open(&frame_path(dir, frame))?;
        sim.sim
            .set_seam_rest(&r.f64("resume_coarse_seam_rest")?.1)?;
        restore_welds(&r, "resume_coarse_welded", &mut sim)?;
    }
    Ok(sim)
}

/// `m` as `dir/manifest.json` holds it: the files it names relative to `dir`.
fn manifest_json(m: &Manifest, dir: &Path) -> Result<Vec<u8>> {
    let m = m.clone().map_paths(|p| crate::relative_to(p, dir));
    serde_json::to_vec_pretty(&m).map_err(|e| Error::Invalid(format!("manifest: {e}")))
}

/// A data set's manifest, the files it names resolved (relative ones are from `dir`).
pub fn read_manifest(dir: &Path) -> Result<Manifest> {
    let p = dir.join("manifest.json");
    let text = std::fs::read_to_string(&p).map_err(|e| Error::io(&p, e))?;
    let m: Manifest =
        serde_json::from_str(&text).map_err(|e| Error::bad_input(&p, e.to_string()))?;
    Ok(m.map_paths(|p| crate::resolve_against(p, dir)))
}

/// One frame's arrays: (int_x, coarse_x) as (steps, Nc, 3) and fine_x as (Nf, 3), f32.
pub fn read_frame_positions(dir: &Path, k: usize) -> Result<FramePositions> {
    let r = TensorReader::open(&frame_path(dir, k))?;
    Ok(FramePositions {
        int_x: r.f32("int_x")?,
        coarse_x: r.f32("coarse_x")?,
        fine_x: r.f32("fine_x")?,
    })
}

/// The coarse mesh stored in a data set (positions are zero: the frames hold them), with the
/// panel names of its manifest.
pub fn read_coarse_mesh(dir: &Path, manifest: &Manifest) -> Result<ClothMesh> {
    read_mesh(dir, manifest, "coarse", manifest.coarse_vertices)
}

/// The fine mesh stored in a data set (positions zero), as [`read_coarse_mesh`].
pub fn read_fine_mesh(dir: &Path, manifest: &Manifest) -> Result<ClothMesh> {
    read_mesh(dir, manifest, "fine", manifest.fine_vertices)
}

fn read_mesh(dir: &Path, manifest: &Manifest, which: &str, expected: usize) -> Result<ClothMesh> {
    let path = dir.join("meshes.safetensors");
    mesh_of_tensors(
        &TensorReader::open(&path)?,
        &path,
        manifest,
        which,
        expected,
    )
}

/// The `which` (`coarse` or `fine`) mesh of a data set's `meshes.safetensors` read as `r` from
/// `path`, checked to have `expected` vertices and to be a valid mesh.
pub fn mesh_of_tensors(
    r: &TensorReader,
    path: &Path,
    manifest: &Manifest,
    which: &str,
    expected: usize,
) -> Result<ClothMesh> {
    let path = path.to_path_buf();
    let (_, material) = r.f64(&format!("{which}_material"))?;
    let (_, triangles) = r.u32(&format!("{which}_triangles"))?;
    let (_, panel_of_vertex) = r.u32(&format!("{which}_panel"))?;
    let (_, seams) = r.u32(&format!("{which}_seams"))?;
    let n = material.len() / 2;
    let mesh = ClothMesh {
        material: material
            .chunks_exact(2)
            .map(|c| nalgebra::Vector2::new(c[0], c[1]))
            .collect(),
        positions: vec![Vector3::zeros(); n],
        triangles: triangles
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect(),
        panel_of_vertex,
        panel_names: manifest.panels.clone(),
        seam_pairs: seams.chunks_exact(2).map(|c| [c[0], c[1]]).collect(),
    };
    if n != expected {
        return Err(Error::bad_input(
            &path,
            format!("{n} {which} vertices, the manifest says {expected}"),
        ));
    }
    mesh.validate().map_err(|e| e.in_file(&path))?;
    Ok(mesh)
}

/// One frame's coarse arrays, each (steps, Nc, 3) f32 flattened: M_int and M_c per step.
#[derive(Debug, Clone)]
pub struct CoarseSteps {
    /// M_int positions.
    pub int_x: Vec<f32>,
    /// M_int velocities.
    pub int_v: Vec<f32>,
    /// M_c positions.
    pub coarse_x: Vec<f32>,
    /// M_c velocities.
    pub coarse_v: Vec<f32>,
}

/// Reads frame `k`'s coarse arrays, checking their shapes against the manifest and that every
/// value is finite.
pub fn read_coarse_steps(dir: &Path, manifest: &Manifest, k: usize) -> Result<CoarseSteps> {
    let path = frame_path(dir, k);
    let r = TensorReader::open(&path)?;
    let want = vec![manifest.steps_per_frame, manifest.coarse_vertices, 3];
    let get = |name: &str| -> Result<Vec<f32>> {
        let (shape, v) = r.f32(name)?;
        if shape != want {
            return Err(Error::bad_input(
                &path,
                format!("'{name}' has shape {shape:?}, expected {want:?}"),
            ));
        }
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(Error::bad_input(
                &path,
                format!("'{name}' holds a non-finite value at {i}"),
            ));
        }
        Ok(v)
    };
    Ok(CoarseSteps {
        int_x: get("int_x")?,
        int_v: get("int_v")?,
        coarse_x: get("coarse_x")?,
        coarse_v: get("coarse_v")?,
    })
}

/// Positions stored for one frame, with their shapes.
#[derive(Debug, Clone)]
pub struct FramePositions {
    /// M_int per step.
    pub int_x: (Vec<usize>, Vec<f32>),
    /// M_c per step.
    pub coarse_x: (Vec<usize>, Vec<f32>),
    /// M_f at the frame's end.
    pub fine_x: (Vec<usize>, Vec<f32>),
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::garment::Fabric;
    use crate::mesh::{mesh_garment, MeshOptions};
    use crate::scene::samples::flat_sheet;

    #[test]
    fn yaw_turns_garments_about_the_vertical_and_clip_start_shifts_colliders() {
        let mut g = flat_sheet(
            "s",
            0.2,
            0.1,
            Vector3::new(0.3, 1.0, 0.0),
            Fabric::default(),
        );
        g.panels[0].placement.rotation_xyz_deg = Vector3::new(-90.0, 20.0, 10.0);
        let mut scene = Scene {
            garments: vec![g.clone()],
            ..Scene::default()
        };
        let mut ball = crate::scene::Collider::sphere("b", Vector3::zeros(), 0.1, 1);
        ball.times_s = vec![0.0, 1.0];
        ball.frames.push(ball.frames[0].clone());
        scene.colliders.push(ball);
        let v = Variation {
            garment_yaw_deg: 90.0,
            clip_start_s: 0.5,
            ..Variation::default()
        };
        v.apply(&mut scene);
        let before = mesh_garment(&g, &MeshOptions::with_edge(0.05)).expect("mesh");
        let after = mesh_garment(&scene.garments[0], &MeshOptions::with_edge(0.05)).expect("mesh");
        let r = nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), 90f64.to_radians());
        for (a, b) in after.positions.iter().zip(&before.positions) {
            assert!((a - r * b).norm() < 1e-9, "{a:?} vs {:?}", r * b);
        }
        assert_eq!(scene.colliders[0].times_s, vec![-0.5, 0.5]);
    }

    #[test]
    fn a_later_clip_start_carries_garments_along_with_the_walking_bodies() {
        let g = flat_sheet(
            "s",
            0.2,
            0.1,
            Vector3::new(0.3, 1.0, 0.0),
            Fabric::default(),
        );
        let mut scene = Scene {
            garments: vec![g.clone()],
            ..Scene::default()
        };
        // A body walking 1 m along x and rising 0.2 m in its 1 s clip, and a static floor
        // (which must not hold the centroid back).
        let mut body = crate::scene::Collider::sphere("body", Vector3::zeros(), 0.1, 1);
        body.times_s = vec![0.0, 1.0];
        let moved = body.frames[0]
            .iter()
            .map(|p| p + nalgebra::Vector3::new(1.0f32, 0.2, 0.0))
            .collect();
        body.frames.push(moved);
        scene.colliders.push(body);
        scene.colliders.push(crate::scene::Collider::fixed(
            "floor",
            vec![Vector3::zeros(), Vector3::x(), Vector3::z()],
            vec![[0, 1, 2]],
        ));
        let v = Variation {
            clip_start_s: 0.5,
            garment_offset_m: [0.0, 0.0, 0.25],
            ..Variation::default()
        };
        v.apply(&mut scene);
        let before = mesh_garment(&g, &MeshOptions::with_edge(0.05)).expect("mesh");
        let after = mesh_garment(&scene.garments[0], &MeshOptions::with_edge(0.05)).expect("mesh");
        // Half the walk along x (not the rise), plus the offset asked for.
        for (a, b) in after.positions.iter().zip(&before.positions) {
            let d = a - b;
            assert!((d - Vector3::new(0.5, 0.0, 0.25)).norm() < 1e-6, "{d:?}");
        }
        // From the start of the clip nothing moves.
        let mut still = Scene {
            garments: vec![g.clone()],
            colliders: scene.colliders.clone(),
            ..Scene::default()
        };
        Variation::default().apply(&mut still);
        assert_eq!(still.garments[0].panels[0].placement, g.panels[0].placement);
    }
}
