//! Training data sets made (the paper's §3.3.1): a fine simulation (2.5 mm) is the ground
//! truth M_f; every step is downsampled to the coarse mesh (20 mm) as M_int, the corrector's
//! target; and every M_int is advanced by one coarse simulator step to M_c, the simulator's
//! immediate error that the corrector learns to remove (§3.1.3). The format, and reading it,
//! are [`crate::data`]'s.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use crate::data::{
    coarse_contact_thickness, coarse_mode, flat32, flat64, frame_path, manifest_json,
    new_simulation, read_manifest, restore_welds, unflat, Fork, Manifest, SceneSource, Variation,
    FORMAT_VERSION,
};
use crate::error::{Error, Result};
use crate::io::tensors::{TensorReader, TensorWriter};
use crate::mesh::ClothMesh;
use crate::scene::Scene;
use crate::sim::driver::Simulation;
use crate::sim::step::SolverMode;
use crate::sim::SimState;
use crate::transfer::Transfer;

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

impl Options {
    /// The options that made the data set whose manifest is `m`, for `frames` frames:
    /// resuming it (or a [`fork`] of it) with these continues the same simulation.
    pub fn of_manifest(m: &Manifest, frames: usize) -> Options {
        Options {
            coarse_edge_m: m.coarse_edge_m,
            fine_edge_m: m.fine_edge_m,
            frames,
            dress: m.dressed,
            self_collision: m.self_collision,
            variation: m.variation,
            fast: m.fast,
            fine_mode: SolverMode::from_name(&m.fine_solver).unwrap_or(SolverMode::Data),
            source: m.source.clone(),
            match_contact_thickness: m.coarse_dhat_m.is_some(),
        }
    }
}

/// Progress of a run.
#[derive(Debug, Clone, Copy)]
pub struct Progress {
    /// Frames complete.
    pub frames_done: usize,
    /// Frames asked for.
    pub frames: usize,
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
        clothsr_io::write_atomic(&manifest_path, &manifest_json(&manifest, dir)?)?;
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
    let (max_s, settle_s, gap_m) = clothsr_io::dressed::DRESSING;
    let clock = std::time::Instant::now();
    let c = coarse.dress(max_s, settle_s, gap_m)?;
    let coarse_s = clock.elapsed().as_secs_f64();
    let x = transfer.upsample_phong(
        &coarse.state.x,
        &coarse.sim.model.mesh.triangles,
        DRESS_PHONG_ALPHA,
    );
    tracing::info!(
        "dressed the coarse mesh in {coarse_s:.1} s ({} sewing, {} worn to the start, {} \
         settling steps, seams {:.1} mm); dressing the fine mesh ({} vertices) from it",
        c.sew_steps,
        c.preroll_steps,
        c.settle_steps,
        c.seam_gap_m * 1e3,
        x.len()
    );
    closed("coarse", c.seam_gap_m)?;
    let clock = std::time::Instant::now();
    let f = fine.dress_from(
        x,
        coarse.weld_distance_m(),
        FINE_SEWING_S,
        FINE_SETTLING_S,
        gap_m,
    )?;
    tracing::info!(
        "dressed the fine mesh in {:.1} s ({} sewing, {} settling steps; {} sub-steps solved; \
         seams {:.1} mm)",
        clock.elapsed().as_secs_f64(),
        f.sew_steps,
        f.settle_steps,
        f.substeps,
        f.seam_gap_m * 1e3
    );
    closed("fine", f.seam_gap_m)
}

/// The widest seam gap a dressed garment may keep for a data set, m: an open garment is no
/// ground truth (a run only warns, as the garment is the user's).
const MAX_DRESSED_SEAM_GAP_M: f64 = 0.01;

/// Fails when dressing at `level` left a seam open by `gap_m`.
fn closed(level: &str, gap_m: f64) -> Result<()> {
    if gap_m > MAX_DRESSED_SEAM_GAP_M {
        return Err(Error::Simulation(format!(
            "dressing left a seam {:.1} mm open at the {level} level (the widest is named \
             above): a data set of an open garment is no ground truth",
            gap_m * 1e3
        )));
    }
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
    clothsr_io::write_atomic(&dir.join("manifest.json"), &manifest_json(manifest, dir)?)
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
/// [`Options::of_manifest`] then continues it from that moved state: the distance between the
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
        from: clothsr_io::absolute(src),
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
    clothsr_io::write_atomic(&tmp.join("manifest.json"), &manifest_json(&manifest, tmp)?)?;
    Ok(manifest)
}

/// At most this long the fine mesh sews, from the coarse dressing, s: seams the coarse mesh
/// could not close (zero ease at the hips holds them a few millimetres open) close at a
/// tenth of a millimetre per 0.1 s at 10 mm, and every step of a 100K-vertex skirt costs
/// seconds.
const FINE_SEWING_S: f64 = 0.1;

/// How long the fine mesh settles after its seams close, s. The coarse dressing did the
/// draping; from its shape the fine membrane relaxes within the first few steps, and past
/// them the fine mesh does not come to rest: a few percent of its vertices keep moving at a
/// fast-mode step's jitter where the cloth presses on the body, and the garment wanders as far
/// in any later stretch of settling as it settles in all of it. Every step costs seconds.
const FINE_SETTLING_S: f64 = 0.1;

/// Phong blend of the coarse dressed garment carried onto the fine mesh (¾, Phong
/// tessellation's usual choice).
const DRESS_PHONG_ALPHA: f64 = 0.75;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_dressing_that_leaves_a_seam_open_makes_no_data_set() {
        assert!(closed("coarse", 0.0).is_ok());
        assert!(closed("fine", 0.009).is_ok());
        let e = closed("coarse", 0.0992).expect_err("open");
        assert_eq!(e.kind(), crate::ErrorKind::Failure);
        assert!(
            e.to_string().contains("99.2 mm open at the coarse level"),
            "{e}"
        );
    }
}
