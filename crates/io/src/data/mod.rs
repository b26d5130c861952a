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

use crate::scene_files::SceneFiles;
use crate::tensors::TensorReader;
use clothsr_geometry::error::{Error, Result};
use clothsr_geometry::garment::Fabric;
use clothsr_geometry::mesh::ClothMesh;
use clothsr_geometry::scene::{root_motion, Scene};
use clothsr_sim::driver::Simulation;
use clothsr_sim::step::SolverMode;

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
        // dressed around empty space and fall. Those that are dressed are dressed at the
        // clip's start and worn through the motion up to the variation's first frame
        // (`Scene::preroll_s`): sewn mid-stride, a skirt's front panel met the forward leg.
        let mut g = Vector3::from(self.garment_offset_m);
        if self.clip_start_s != 0.0 {
            let t0 = scene.frame_start as f64 / scene.fps;
            g += root_motion(&scene.colliders, t0, t0 + self.clip_start_s);
            for c in &mut scene.colliders {
                c.times_s.iter_mut().for_each(|t| *t -= self.clip_start_s);
            }
            scene.preroll_s = self.clip_start_s.max(0.0);
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
    /// on the fine mesh from the coarse result: [`clothsr_sim::driver::Simulation::dress_from`]).
    pub dressed: bool,
    /// The clothsr revision that made it.
    pub git_revision: String,
    /// One Newton iteration per step when accepted ([`clothsr_sim::SimParams::newton_exact`]
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
    /// (`clothsr::dataset::Options::match_contact_thickness`), m; `None`: the coarse mesh's own default.
    #[serde(default)]
    pub coarse_dhat_m: Option<f64>,
    /// Set when this data set continues another from one of its frames (`clothsr::dataset::fork`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fork: Option<Fork>,
}

/// Where a forked data set branched off (`clothsr::dataset::fork`).
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
        let fabric = clothsr_geometry::garment::Fabric::preset(&self.fabric)
            .ok_or_else(|| Error::Usage(format!("unknown fabric preset '{}'", self.fabric)))?;
        let mut scene = Scene::load(&self.scene, &fabric)?;
        for c in self.colliders.iter().chain(&self.avatar) {
            scene.add_collider_file(c)?;
        }
        Ok(scene)
    }
}

/// The file of frame `k` in the data set `dir`.
pub fn frame_path(dir: &Path, k: usize) -> PathBuf {
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

/// Welds `sim`'s seams when the frame file `r` says they were (`key`; files written before
/// seams were welded have no such entry).
pub fn restore_welds(r: &TensorReader, key: &str, sim: &mut Simulation) -> Result<()> {
    if r.has(key) && r.scalar_f64(key)? > 0.5 {
        sim.sim.weld_seams(&mut sim.state, 0.0);
    }
    Ok(())
}

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

/// The coarse simulation a data set was made with: `scene` (as given to `clothsr::dataset::generate`, before
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
pub fn manifest_json(m: &Manifest, dir: &Path) -> Result<Vec<u8>> {
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
    use clothsr_geometry::garment::Fabric;
    use clothsr_geometry::mesh::{mesh_garment, MeshOptions};
    use clothsr_geometry::scene::samples::flat_sheet;

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
        let mut ball = clothsr_geometry::scene::Collider::sphere("b", Vector3::zeros(), 0.1, 1);
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
        let mut body = clothsr_geometry::scene::Collider::sphere("body", Vector3::zeros(), 0.1, 1);
        body.times_s = vec![0.0, 1.0];
        let moved = body.frames[0]
            .iter()
            .map(|p| p + nalgebra::Vector3::new(1.0f32, 0.2, 0.0))
            .collect();
        body.frames.push(moved);
        scene.colliders.push(body);
        scene
            .colliders
            .push(clothsr_geometry::scene::Collider::fixed(
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
        // Dressed at the clip's start, and worn from there.
        assert_eq!(scene.preroll_s, 0.5);
        // From the start of the clip nothing moves.
        let mut still = Scene {
            garments: vec![g.clone()],
            colliders: scene.colliders.clone(),
            ..Scene::default()
        };
        Variation::default().apply(&mut still);
        assert_eq!(still.garments[0].panels[0].placement, g.panels[0].placement);
        assert_eq!(still.preroll_s, 0.0);
    }
}
