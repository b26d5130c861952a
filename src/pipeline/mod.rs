//! The whole of the paper's Fig. 2 on a scene: per coarse step the simulator, then (when a model
//! is given) the corrector, whose output M_int the next step starts from (§3.1.3); per frame the
//! MSR module on M_int with the previous frame's fine output as initialisation (§3.2).
//!
//! The coarse simulation is set up as `clothsr lab dataset` set up the training data's: the same
//! mesher and solver settings, and by default the fine simulation's contact thickness d̂, so a
//! model sees at run time the kind of coarse mesh it was trained on.

use std::time::Instant;

use nalgebra::Vector3;

use crate::corrector::Corrector;
use crate::data::{coarse_contact_thickness, new_simulation};
use crate::error::{Error, Result};
use crate::garment::Fabric;
use crate::mesh::ClothMesh;
use crate::msr::inference::InitMaps;
use crate::msr::{condition, Isr, SuperResolver};
use crate::scene::Scene;
use crate::sim::collide::{push_out, Collider, PushOut};
use crate::sim::driver::Simulation;
use crate::sim::step::{SimState, SolverMode};

pub mod calibrate;
pub mod fit;
pub mod models;
mod run;
pub mod shot;
pub use crate::sim::coarse::{crease_label, CoarseCalibration};
use crate::transfer::Transfer;
pub use models::{choose_path, CorrectorChoice, ModelPath, ModelsManifest};
pub use run::{resume_path, run_to_files, Outputs, Preview, Progress, Report};

/// A run's settings: the shot's variation and how its coarse simulation is set up. One type
/// for every run: [`Options::default`] is what `clothsr run` and the Python package's `run`
/// take, `clothsr lab run` sets each field from a flag, and `fit` measures its held-out runs
/// under it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Coarse edge length, m (the paper: 20 mm).
    pub coarse_edge_m: f64,
    /// The coarse simulation's solver: [`SolverMode::Fast`] (one Newton step per time step
    /// when it is accepted, the paper's) or [`SolverMode::Converged`].
    pub coarse_solver: SolverMode,
    /// Cloth self-collision.
    pub self_collision: bool,
    /// Give the coarse simulation the fine one's contact thickness (as `clothsr lab dataset` does
    /// by default), for cloth without seams: garments keep the coarse mesh's own
    /// ([`crate::data::coarse_contact_thickness`]).
    pub match_contact_thickness: bool,
    /// Sew and settle garments with seams before the first frame (as `clothsr lab dataset` does).
    pub dress: bool,
    /// The coarse model's settings (unset: the corrector's, the one it was trained beside, else
    /// the simulator's own). A setting that differs from the corrector's is an error.
    pub coarse: CoarseCalibration,
    /// Push the fine output's vertices out of the colliders (to half the fine simulation's
    /// contact thickness; [`crate::sim::collide::push_out`]): the MSR module places them
    /// from the coarse surface, whose 20 mm chords and the network's wrinkles cut into a body
    /// the cloth wraps (the paper's §4.5 names the penetrations). Off, the network's output
    /// is written as it is.
    pub push_out: bool,
    /// The shot's variation (as `clothsr lab dataset` makes training sequences), applied to
    /// the scene as it is loaded ([`shot::run_shot`]; [`Pipeline::new`] takes the scene it is
    /// given).
    pub variation: crate::data::Variation,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            coarse_edge_m: crate::mesh::COARSE_EDGE_M,
            coarse_solver: SolverMode::Fast,
            self_collision: false,
            match_contact_thickness: true,
            dress: true,
            coarse: CoarseCalibration::default(),
            push_out: true,
            variation: crate::data::Variation::default(),
        }
    }
}

/// The options a run with the models folder `models` uses: with a corrector (`corrector`: its
/// directory) `given` as it is, else `given` filled from `models/coarse.json` where there is
/// one, which is returned too.
pub fn options_for_run(
    models: &std::path::Path,
    corrector: Option<&std::path::Path>,
    given: Options,
) -> Result<(Options, Option<CoarseCalibration>)> {
    if corrector.is_some() {
        return Ok((given, None));
    }
    Ok(match CoarseCalibration::load(models)? {
        Some(cal) => (given.filled_from(&cal), Some(cal)),
        None => (given, None),
    })
}

impl Options {
    /// Checks the settings before any work.
    pub fn check(&self) -> Result<()> {
        if !(self.coarse_edge_m.is_finite() && self.coarse_edge_m > 0.0) {
            return Err(Error::Usage(
                "the coarse edge length must be positive".into(),
            ));
        }
        if !matches!(self.coarse_solver, SolverMode::Fast | SolverMode::Converged) {
            return Err(Error::Usage(format!(
                "the coarse simulation runs in fast or converged mode, not {}",
                self.coarse_solver.name()
            )));
        }
        self.coarse.check_flags()
    }

    /// These options with each of their coarse settings that is unset taken from `cal`.
    pub fn filled_from(self, cal: &CoarseCalibration) -> Options {
        Options {
            coarse: self.coarse.or(cal),
            ..self
        }
    }
}

/// Seconds spent in each stage of the last frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FrameTimes {
    /// Coarse simulator steps.
    pub simulator_s: f64,
    /// Corrector calls.
    pub corrector_s: f64,
    /// Mesh super-resolution.
    pub msr_s: f64,
}

/// What the pipeline carries from one frame to the next (see [`Pipeline::resume_state`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ResumeState {
    /// The coarse state (M_int) at the end of the frame.
    pub coarse: SimState,
    /// The coarse simulator's seam rest lengths, m.
    pub seam_rest_m: Vec<f64>,
    /// The coarse simulator's collider detection margin, m.
    pub obstacle_margin_m: f64,
    /// The fine output of the frame.
    pub fine: Vec<Vector3<f64>>,
    /// The MSR module's initialisation for the next frame.
    pub previous_maps: Option<InitMaps>,
}

/// A scene running through the pipeline.
pub struct Pipeline<'a> {
    /// The coarse simulation; its state is M_int after each step when a corrector runs.
    pub coarse: Simulation,
    /// The fine mesh (all garments, in the coarse simulation's part order; positions are those
    /// of the last frame).
    pub fine: ClothMesh,
    /// The fine mesh's edge length (the ISR model's pixel), m.
    pub fine_edge_m: f64,
    /// Vertex range of each garment part in the fine mesh.
    pub fine_parts: Vec<std::ops::Range<usize>>,
    /// Each fine garment part on its own (name, mesh at rest, fabric), for writing.
    pub fine_part_meshes: Vec<(String, ClothMesh, Fabric)>,
    corrector: Option<Corrector>,
    sr: SuperResolver<'a>,
    /// The simulator's output M_c of the last step, before the corrector (empty when no
    /// corrector runs: M_c is then the state itself).
    pub simulated: Vec<Vector3<f64>>,
    upsampler: Option<Transfer>,
    /// Times of the last frame.
    pub times: FrameTimes,
    /// The clearance the fine output is pushed out of the colliders to, m (`None`: not pushed;
    /// [`Options::push_out`]).
    push_clearance_m: Option<f64>,
    /// What the push out of the colliders did to the last frame's fine output.
    pub pushed: PushOut,
}

impl<'a> Pipeline<'a> {
    /// Sets up `scene` with an ISR model and optionally a corrector model directory.
    pub fn new(
        scene: &Scene,
        isr: &'a Isr,
        corrector_dir: Option<&std::path::Path>,
        opts: Options,
    ) -> Result<Pipeline<'a>> {
        Pipeline::with_dress_cache(scene, isr, corrector_dir, opts, None)
    }

    /// As [`Pipeline::new`], dressing the garments from the dressed state kept in
    /// `dress_cache` when it was made for the same coarse simulation, else dressing them and
    /// keeping the state there ([`crate::io::dressed`]).
    pub fn with_dress_cache(
        scene: &Scene,
        isr: &'a Isr,
        corrector_dir: Option<&std::path::Path>,
        opts: Options,
        dress_cache: Option<&std::path::Path>,
    ) -> Result<Pipeline<'a>> {
        let fine_edge = isr.cfg.pixel_m;
        if opts.coarse_edge_m <= fine_edge {
            return Err(Error::Invalid(format!(
                "the coarse edge ({} mm) must be longer than the ISR model's pixel ({} mm)",
                opts.coarse_edge_m * 1e3,
                fine_edge * 1e3
            )));
        }
        // The fine mesh: meshed exactly as the training data's fine simulation (never stepped).
        let fine_sim = new_simulation(
            scene,
            fine_edge,
            opts.self_collision,
            opts.coarse_solver,
            None,
        )?;
        let dhat = coarse_contact_thickness(&fine_sim, opts.match_contact_thickness);
        let mut coarse = new_simulation(
            scene,
            opts.coarse_edge_m,
            opts.self_collision,
            opts.coarse_solver,
            dhat,
        )?;
        if opts.dress && !coarse.sim.model.mesh.seam_pairs.is_empty() {
            if let Some(d) = crate::io::dressed::dress_or_restore(&mut coarse, dress_cache)? {
                tracing::info!(
                    "dressed: {} sewing + {} settling steps, {} of {} seam pairs welded (from up \
                     to {:.1} mm apart), widest seam gap {:.1} mm, seams pulled up to {}× as hard",
                    d.sew_steps,
                    d.settle_steps,
                    d.welded_pairs,
                    coarse.sim.model.mesh.seam_pairs.len(),
                    d.welded_gap_m * 1e3,
                    d.seam_gap_m * 1e3,
                    1u32 << d.harder_pulls
                );
            }
            // The first frame starts the same whether dressed now or restored.
            coarse.sim.forget_history();
            coarse.sim.set_obstacle_margin_m(0.0);
        }
        let push_clearance_m = opts
            .push_out
            .then_some(0.5 * fine_sim.sim.params.collision.dhat_m);
        let fine = fine_sim.sim.model.mesh.clone();
        let fine_parts = fine_sim.sim.model.part_ranges();
        let model = &fine_sim.sim.model;
        let fine_part_meshes = (0..model.parts.len())
            .map(|i| {
                let p = &model.parts[i];
                (p.name.clone(), model.part_mesh(i), p.fabric.clone())
            })
            .collect();
        let corrector = corrector_dir
            .map(|d| Corrector::load(d, &coarse.sim.model.mesh))
            .transpose()?;
        opts.coarse.check()?;
        // After dressing: sewing is done with the full membrane.
        match &corrector {
            Some(c) => {
                if let Some(how) = opts.coarse.conflict_with(&c.training.coarse) {
                    return Err(Error::Invalid(format!(
                        "the corrector in {} was trained {how}",
                        c.dir.display()
                    )));
                }
                c.training.prepare_coarse(&mut coarse)?
            }
            None => opts.coarse.apply(&mut coarse)?,
        }
        let fabrics: Vec<_> = model.parts.iter().map(|p| p.fabric.clone()).collect();
        let conditions =
            condition::panel_conditions(&fine, &fabrics, coarse.edge_m, fine_sim.edge_m)?;
        let sr = SuperResolver::new(isr, &coarse.sim.model.mesh, &fine, &conditions)?;
        Ok(Pipeline {
            coarse,
            fine,
            fine_edge_m: fine_edge,
            fine_parts,
            fine_part_meshes,
            corrector,
            sr,
            simulated: Vec::new(),
            upsampler: None,
            times: FrameTimes::default(),
            push_clearance_m,
            pushed: PushOut::default(),
        })
    }

    /// The clearance the fine output is pushed out of the colliders to, m (`None`: not
    /// pushed; [`Options::push_out`]).
    pub fn push_clearance_m(&self) -> Option<f64> {
        self.push_clearance_m
    }

    /// Whether a corrector runs.
    pub fn has_corrector(&self) -> bool {
        self.corrector.is_some()
    }

    /// The fine mesh of the current state (the first frame, before any step: a new shot).
    pub fn super_resolve(&mut self) -> Result<&[Vector3<f64>]> {
        let t = Instant::now();
        let mut x = self.sr.frame(&self.coarse.state.x)?;
        if let Some(i) = x.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(Error::Simulation(format!(
                "super-resolution produced a non-finite fine vertex ({i})"
            )));
        }
        if let Some(clearance) = self.push_clearance_m {
            let points = self.coarse.collider_points();
            let bodies: Vec<Collider<'_>> = points
                .iter()
                .zip(&self.coarse.colliders)
                .map(|(p, c)| (p.as_slice(), c.triangles.as_slice()))
                .collect();
            self.pushed = push_out(&mut x, &bodies, clearance);
        }
        self.times.msr_s = t.elapsed().as_secs_f64();
        self.fine.positions = x;
        Ok(&self.fine.positions)
    }

    /// One output frame: the coarse steps, each followed by the corrector, then the MSR
    /// module. Returns the fine positions.
    pub fn advance_frame(&mut self) -> Result<&[Vector3<f64>]> {
        let (mut sim_s, mut cor_s) = (0.0, 0.0);
        let mut start_v = Vec::new();
        // A frame is where a run can resume: what steps cached starts afresh here, as it
        // does in a resumed run.
        self.coarse.sim.forget_history();
        for _ in 0..self.coarse.steps_per_frame {
            if self.corrector.is_some() {
                start_v.clone_from(&self.coarse.state.v);
            }
            let t = Instant::now();
            self.coarse.step()?;
            sim_s += t.elapsed().as_secs_f64();
            if let Some(c) = &self.corrector {
                self.simulated.clone_from(&self.coarse.state.x);
                let t = Instant::now();
                // Out of the simulation while `correct` reads its settings; put back either way
                // (a failed correction leaves it as it was).
                let mut state = std::mem::take(&mut self.coarse.state);
                let corrected = c.correct(&start_v, &mut state, &self.coarse);
                self.coarse.state = state;
                corrected?;
                cor_s += t.elapsed().as_secs_f64();
            }
        }
        self.times.simulator_s = sim_s;
        self.times.corrector_s = cor_s;
        self.super_resolve()
    }

    /// The coarse state (M_int) upsampled to the fine mesh by barycentric interpolation in
    /// material space: the baseline the paper compares with (no learned detail).
    pub fn upsampled(&mut self) -> Result<Vec<Vector3<f64>>> {
        if self.upsampler.is_none() {
            self.upsampler = Some(Transfer::new(&self.coarse.sim.model.mesh, &self.fine)?);
        }
        let t = self.upsampler.as_ref().ok_or_else(|| {
            Error::Invalid("the coarse-to-fine transfer could not be built".into())
        })?;
        Ok(t.upsample(&self.coarse.state.x))
    }

    /// Everything the next frame depends on: a resumed run restores it and continues exactly
    /// as an uninterrupted one would.
    pub fn resume_state(&self) -> ResumeState {
        ResumeState {
            coarse: self.coarse.state.clone(),
            seam_rest_m: self.coarse.sim.seam_rest().to_vec(),
            obstacle_margin_m: self.coarse.sim.obstacle_margin_m(),
            fine: self.fine.positions.clone(),
            previous_maps: self.sr.previous_maps(),
        }
    }

    /// Continues from a [`Pipeline::resume_state`] of the same scene and models.
    pub fn restore(&mut self, s: ResumeState) -> Result<()> {
        let (nc, nf) = (
            self.coarse.sim.model.num_vertices(),
            self.fine.num_vertices(),
        );
        if s.coarse.x.len() != nc || s.coarse.v.len() != nc || s.fine.len() != nf {
            return Err(Error::Invalid(format!(
                "the saved state has {} coarse and {} fine vertices, the scene {nc} and {nf}",
                s.coarse.x.len(),
                s.fine.len()
            )));
        }
        self.coarse.sim.set_seam_rest(&s.seam_rest_m)?;
        self.coarse.sim.set_obstacle_margin_m(s.obstacle_margin_m);
        match s.previous_maps {
            Some(maps) => self.sr.set_previous_maps(maps)?,
            None => self.sr.set_previous(&self.fine, &s.fine, &s.coarse.x)?,
        }
        self.coarse.state = s.coarse;
        self.fine.positions = s.fine;
        Ok(())
    }

    /// Positions of each fine garment part.
    pub fn fine_part_positions(&self) -> Vec<&[Vector3<f64>]> {
        self.fine_parts
            .iter()
            .map(|r| &self.fine.positions[r.clone()])
            .collect()
    }
}
