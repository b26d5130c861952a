//! Running a [`Scene`] through the simulator frame by frame: garments meshed at the requested
//! edge length, colliders interpolated at every step, output written as time-sampled USD.

use nalgebra::Vector3;

use super::arrange::{wrap_panels_around_body, WrapOptions};
use super::collide::bvh::Aabb;
use super::collide::{push_out, Collider as BodyMesh, PushOut};
use super::model::ClothModel;
use super::step::{
    ColliderFrame, PhaseTimes, Pin, PinTarget, SimParams, SimState, Simulator, SolverMode,
    StepStats, MAX_OBSTACLE_MARGIN_M,
};
use clothsr_geometry::error::{Error, Result};
use clothsr_geometry::garment::Fabric;
use clothsr_geometry::mesh::{mesh_garment, remesh, ClothMesh, MeshOptions};
use clothsr_geometry::scene::{root_motion, ClothPiece, Collider, Scene};

/// Moves the vertices of `x` inside `colliders` (at `points`, one list per collider), or
/// nearer one than `clearance_m`, out to that distance ([`push_out`]).
fn push_out_of(
    colliders: &[Collider],
    points: &[Vec<Vector3<f64>>],
    x: &mut [Vector3<f64>],
    clearance_m: f64,
) -> PushOut {
    let bodies: Vec<BodyMesh<'_>> = points
        .iter()
        .zip(colliders)
        .map(|(p, c)| (p.as_slice(), c.triangles.as_slice()))
        .collect();
    push_out(x, &bodies, clearance_m)
}

/// The colliders' triangles with their points `points` (one point list per collider).
fn collider_frames<'a>(
    colliders: &'a [Collider],
    points: &'a [Vec<Vector3<f64>>],
) -> Vec<ColliderFrame<'a>> {
    colliders
        .iter()
        .zip(points)
        .map(|(c, p)| ColliderFrame {
            points: p,
            triangles: &c.triangles,
        })
        .collect()
}

/// Sets which cloth–cloth contacts the simulator detects. Without self-collision, the
/// garments of an outfit (two or more) still meet each other, so that no layer passes
/// through another, and while `sewing` from the flat pattern each panel meets itself (a
/// dresser's panels do not pass through themselves). `active`: the garments taking part
/// (the others are parked while layers are dressed one by one); all when `None`.
fn cloth_contacts(sim: &mut Simulator, sewing: bool, active: Option<Vec<bool>>) {
    let outfit = sim.model.parts.len() > 1;
    let pairs = (sewing || outfit || active.is_some()).then_some((sewing, outfit, active));
    sim.set_cloth_pairs(pairs);
}

/// Rolls the panels of `garments` (positions `x` of `mesh`) that face the body around it and
/// `bodies` ([`wrap_panels_around_body`]) and says which, as `stage`.
fn roll_panels(
    mesh: &ClothMesh,
    x: &mut [Vector3<f64>],
    garments: &[std::ops::Range<usize>],
    bodies: &[ColliderFrame<'_>],
    stage: &str,
) -> Vec<crate::arrange::WrappedPanel> {
    let wrapped = wrap_panels_around_body(mesh, garments, x, bodies, &WrapOptions::default());
    for w in &wrapped {
        tracing::info!(
            "{stage}: panel '{}' rolled around the body (radius {:.0} mm, {:.0}°)",
            mesh.panel_names[w.panel],
            w.radius_m * 1e3,
            w.span_deg
        );
    }
    wrapped
}

/// A scene ready to simulate (a clone carries the simulator's warm starts and caches, so a
/// clone made before any step runs as a fresh simulation would).
#[derive(Clone)]
pub struct Simulation {
    /// The simulator.
    pub sim: Simulator,
    /// Current state.
    pub state: SimState,
    /// Collision bodies.
    pub colliders: Vec<Collider>,
    /// Steps per output frame.
    pub steps_per_frame: usize,
    /// Output frames per second.
    pub fps: f64,
    /// Mean edge length of the cloth mesh, m.
    pub edge_m: f64,
    /// Garments are dressed this long before the start ([`Scene::preroll_s`]), s.
    pub preroll_s: f64,
    buffers: [Vec<Vec<Vector3<f64>>>; 2],
}

/// What one frame cost.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FrameStats {
    /// Sum over the frame's steps.
    pub steps: StepStats,
    /// Steps run.
    pub step_count: usize,
    /// Deepest penetration over the frame, m.
    pub max_penetration_m: f64,
}

/// Sewing stops when the widest seam gap has not closed by 1 % for this long, s.
const SEWING_STALL_S: f64 = 0.2;

/// Seam pairs are welded within this many contact thicknesses; sewing stops on a stall only
/// within it (a garment's widest gap may pause for a while as panels slide around a body).
const WELD_MAX_DHAT: f64 = 3.0;

/// Sub-steps of the first settling step of a garment dressed from a coarser mesh's dressing
/// ([`Simulation::dress_from`]): carried from the coarse shape, the fine membrane relaxes by a
/// millimetre or more in that step, and at the full step the move limits held it back until
/// the step failed and was halved, again and again; taken in sub-steps from the start, each
/// has less to move and none fails.
pub const CARRIED_FIRST_SUBSTEPS: u32 = 8;

/// Relative tolerance of the linear solves of a garment dressed from a coarser mesh's dressing
/// ([`Simulation::dress_from`]: its seams arrive closed, and it mostly settles), looser than
/// fast mode's. A fine mesh's settling is set-up, judged by its seams, its contact and its
/// rest, not by its path, and its solves are most of its time. Not used for sewing from the
/// flat pattern, whose seams close later with looser solves.
pub const CARRIED_CG_REL_TOL: f64 = 1e-2;

/// How often sewing pulls harder on seams that stopped closing short of welding distance
/// (each time doubling the seam springs' stiffness and how far they may stretch).
const SEWING_PULL_DOUBLINGS: u32 = 4;

/// How far beyond the box around an outfit's layer, when its sewing starts, the garments
/// under it are kept in the simulation that sews it ([`Simulation::sew_layer_alone`]), m.
/// Sewn without gravity, a garment is drawn in around the body, not out of that box.
const LAYER_REACH_M: f64 = 0.1;

/// What dressing did ([`Simulation::dress`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DressStats {
    /// Steps run with gravity off while the seams closed.
    pub sew_steps: usize,
    /// Steps run settling under gravity.
    pub settle_steps: usize,
    /// Panels rolled around the body before sewing ([`super::arrange`]).
    pub wrapped_panels: usize,
    /// Widest seam gap before sewing (after rolling), m.
    pub initial_seam_gap_m: f64,
    /// Widest seam gap at the end, m.
    pub seam_gap_m: f64,
    /// Deepest collider penetration in the last settling step, m.
    pub max_penetration_m: f64,
    /// Widest gap of the seam pairs welded when sewing stopped, m (what welding closed;
    /// [`Simulator::weld_seams`](super::step::Simulator::weld_seams)).
    pub welded_gap_m: f64,
    /// Seam pairs welded (the others, still open, stay on their sewing springs).
    pub welded_pairs: usize,
    /// Steps run wearing the garment through the bodies' motion from where it was dressed to
    /// the start ([`Scene::preroll_s`]).
    pub preroll_steps: usize,
    /// Times sewing doubled the seams' pull after their widest gap stopped closing short of
    /// welding distance.
    pub harder_pulls: u32,
    /// Layers of an outfit sewn in a simulation of their own, with only the garments under
    /// them within reach (the others sewn in the whole outfit's).
    pub layers_alone: usize,
    /// Newton iterations over every dressing step (sewing, settling, pre-roll).
    pub newton_iters: usize,
    /// (Sub-)steps solved over every dressing step, halvings included: one a step where
    /// none was halved or sub-stepped.
    pub substeps: usize,
    /// Where dressing's time went, summed over its steps.
    pub times: PhaseTimes,
}

impl DressStats {
    /// Counts one dressing step's iterations and time.
    fn count(&mut self, stats: &StepStats) {
        self.newton_iters += stats.newton_iters;
        self.substeps += stats.substeps;
        self.times.add(&stats.times);
    }

    /// Adds another stage's counts to these.
    fn count_all(&mut self, other: &DressStats) {
        self.newton_iters += other.newton_iters;
        self.substeps += other.substeps;
        self.times.add(&other.times);
    }
}

/// A mesh garment's mesh at `edge_m`: remeshed chart by chart like a pattern
/// ([`remesh`]), or, when a chart cannot be an outline (a hole, a
/// boundary that touches itself), as it is, with a warning.
pub fn remeshed(cloth: &ClothPiece, edge_m: f64) -> ClothMesh {
    match remesh(&cloth.mesh, &MeshOptions::with_edge(edge_m)) {
        Ok(m) => m,
        Err(e) => {
            tracing::warn!(
                "garment '{}': kept at its own resolution, not remeshed at {:.1} mm: {e}",
                cloth.name,
                edge_m * 1e3
            );
            cloth.mesh.clone()
        }
    }
}

impl Simulation {
    /// Meshes the scene's garments at `edge_m` (patterns meshed, mesh garments remeshed chart by
    /// chart, see [`remeshed`]) and sets up
    /// the simulator with the scene's gravity and time step; `tune` may change the defaults.
    pub fn new(
        scene: &Scene,
        edge_m: f64,
        tune: impl FnOnce(&mut SimParams),
    ) -> Result<Simulation> {
        let mut meshed: Vec<(String, ClothMesh, Fabric)> = Vec::new();
        for g in &scene.garments {
            meshed.push((
                g.name.clone(),
                mesh_garment(g, &MeshOptions::with_edge(edge_m))?,
                g.fabric.clone(),
            ));
        }
        for c in &scene.cloths {
            meshed.push((c.name.clone(), remeshed(c, edge_m), c.fabric.clone()));
        }
        let pieces: Vec<(&str, &ClothMesh, &Fabric)> =
            meshed.iter().map(|(n, m, f)| (n.as_str(), m, f)).collect();
        let model = ClothModel::new(&pieces)?;
        let mean_edge = model.mesh.stats().mean_edge_m;
        let mut params = SimParams::for_edge(mean_edge);
        params.dt_s = scene.dt_s;
        params.gravity_m_s2 = scene.gravity_m_s2;
        tune(&mut params);
        if !(params.dt_s > 0.0 && params.dt_s.is_finite()) {
            return Err(Error::Invalid(format!(
                "time step must be positive, got {}",
                params.dt_s
            )));
        }
        if !(scene.preroll_s >= 0.0 && scene.preroll_s.is_finite()) {
            return Err(Error::Invalid(format!(
                "the pre-roll must be zero or more seconds, got {}",
                scene.preroll_s
            )));
        }
        let steps_per_frame = ((1.0 / scene.fps) / params.dt_s).round().max(1.0) as usize;
        let sim = Simulator::new(model, params);
        let mut state = sim.initial_state();
        state.t_s = scene.frame_start as f64 / scene.fps;
        let mut out = Simulation {
            sim,
            state,
            colliders: scene.colliders.clone(),
            steps_per_frame,
            fps: scene.fps,
            edge_m: mean_edge,
            preroll_s: scene.preroll_s,
            buffers: [Vec::new(), Vec::new()],
        };
        cloth_contacts(&mut out.sim, false, None);
        // Garments with seams are dressed (`dress`), which places them around the body.
        if out.sim.model.mesh.seam_pairs.is_empty() {
            out.start_outside_bodies();
        }
        Ok(out)
    }

    /// Moves the cloth out of the bodies it starts in (a garment placed slightly into the
    /// avatar): every vertex inside a body, or nearer one than half the contact thickness, to
    /// that distance from its surface. Cloth that starts with no vertex inside any body is
    /// left as it is. Vertices deeper than [`crate::collide::OBSTACLE_SEARCH_M`] are not found.
    pub fn start_outside_bodies(&mut self) -> PushOut {
        let points = self.collider_points();
        let mut x = self.state.x.clone();
        let clearance = 0.5 * self.sim.params.collision.dhat_m;
        let pushed = push_out_of(&self.colliders, &points, &mut x, clearance);
        if pushed.inside > 0 {
            tracing::info!(
                "{} cloth vertices started inside a body (deepest {:.1} mm): moved out to {:.2} mm \
                 from its surface",
                pushed.inside,
                pushed.max_depth_m * 1e3,
                clearance * 1e3
            );
            self.state.x = x;
        }
        pushed
    }

    /// One step of `dt` from `state` (at `state.t_s`) with the colliders interpolated over it;
    /// `self.state` is untouched. The coarse side of data generation steps from M_int with it.
    pub fn step_from(&mut self, state: &SimState) -> Result<(SimState, StepStats)> {
        let dt = self.sim.params.dt_s;
        let t0 = state.t_s;
        for (k, buf) in self.buffers.iter_mut().enumerate() {
            buf.resize(self.colliders.len(), Vec::new());
            for (c, out) in self.colliders.iter().zip(buf.iter_mut()) {
                c.positions_at(t0 + k as f64 * dt, out);
            }
        }
        let start = collider_frames(&self.colliders, &self.buffers[0]);
        let end = collider_frames(&self.colliders, &self.buffers[1]);
        let (mut next, stats) = self.sim.step(state, &start, &end)?;
        next.t_s = t0 + dt;
        Ok((next, stats))
    }

    /// Advances `self.state` by one step.
    pub fn step(&mut self) -> Result<StepStats> {
        let state = std::mem::replace(
            &mut self.state,
            SimState {
                x: Vec::new(),
                v: Vec::new(),
                t_s: 0.0,
            },
        );
        match self.step_from(&state) {
            Ok((next, stats)) => {
                self.state = next;
                Ok(stats)
            }
            Err(e) => {
                self.state = state;
                Err(e)
            }
        }
    }

    /// Runs one output frame (`steps_per_frame` steps); `on_step` sees each step's stats.
    pub fn advance_frame(&mut self, mut on_step: impl FnMut(&StepStats)) -> Result<FrameStats> {
        let mut frame = FrameStats::default();
        for _ in 0..self.steps_per_frame {
            let stats = self.step()?;
            on_step(&stats);
            frame.step_count += 1;
            frame.max_penetration_m = frame.max_penetration_m.max(stats.max_penetration_m);
            frame.steps.newton_iters += stats.newton_iters;
            frame.steps.cg_iters += stats.cg_iters;
            frame.steps.contacts = stats.contacts;
            frame.steps.substeps += stats.substeps;
            frame.steps.capped_solves += stats.capped_solves;
            frame.steps.unconverged_steps += stats.unconverged_steps;
            frame.steps.energy_j = stats.energy_j;
            frame.steps.times.add(&stats.times);
        }
        Ok(frame)
    }

    /// Dresses the garments before the animation, as a tailor would: flat panels that face the
    /// body are first rolled around it ([`super::arrange`]), then, with the colliders held at
    /// the first frame and gravity off, the seams close (GarmentCode places panels flat around
    /// the body, up to tens of centimetres apart; under gravity they would fall before the
    /// seams close), then `settle_s` of draping under gravity, still on the first frame's
    /// colliders. The state's time goes back to the start, with zero velocity. Stops sewing
    /// once every seam pair is within `gap_m` or after `max_s` of simulated time.
    ///
    /// With a pre-roll ([`Self::preroll_s`]) the garments are dressed that long before the
    /// start instead, on the bodies as they were then and moved back with their walk
    /// ([`root_motion`]); they are then worn through the bodies' motion up to the start
    /// (gravity, friction, the run's contact settings) and settle `settle_s` there. Dressing
    /// runs in fast mode whatever the solver's mode (it is set-up, not the trajectory).
    pub fn dress(&mut self, max_s: f64, settle_s: f64, gap_m: f64) -> Result<DressStats> {
        let out = self.in_fast_mode(|sim| sim.dress_with_preroll(max_s, settle_s, gap_m))?;
        log_dressing_work(&out);
        Ok(out)
    }

    /// Runs `f` with the simulator's solver in fast mode, then puts its settings back.
    /// Dressing is set-up, not part of the trajectory: it runs in fast mode in every
    /// solver mode (four strict sub-steps a step cost a fine mesh minutes of settling), so a
    /// garment is dressed the same way for every mode.
    fn in_fast_mode<T>(&mut self, f: impl FnOnce(&mut Self) -> Result<T>) -> Result<T> {
        let params = self.sim.params.clone();
        SolverMode::Fast.apply(&mut self.sim.params);
        let out = f(self);
        self.sim.params = params;
        out
    }

    /// [`Self::dress`]'s work (pre-roll included) with the solver's settings as they are.
    fn dress_with_preroll(&mut self, max_s: f64, settle_s: f64, gap_m: f64) -> Result<DressStats> {
        if self.preroll_s <= 0.0 {
            return self.dress_here(max_s, settle_s, gap_m);
        }
        let t_start = self.state.t_s;
        let t_dress = t_start - self.preroll_s;
        let back = root_motion(&self.colliders, t_dress, t_start);
        self.state.x.iter_mut().for_each(|p| *p -= back);
        self.state.t_s = t_dress;
        let mut out = self.dress_here(max_s, settle_s, gap_m)?;
        let steps = (self.preroll_s / self.sim.params.dt_s).round() as usize;
        for _ in 0..steps {
            let stats = self.step()?;
            out.count(&stats);
        }
        tracing::info!(
            "dressing: worn through {:.2} s of the bodies' motion to the start ({steps} steps)",
            self.preroll_s
        );
        self.state.t_s = t_start;
        let held = self.collider_points();
        let settled =
            self.sew_and_settle(&held, DressStats::default(), 0.0, settle_s, gap_m, true)?;
        out.preroll_steps = steps;
        out.count_all(&settled);
        out.settle_steps += settled.settle_steps;
        out.seam_gap_m = settled.seam_gap_m;
        out.max_penetration_m = settled.max_penetration_m;
        Ok(out)
    }

    /// [`Self::dress`] at the state's time, without a pre-roll.
    fn dress_here(&mut self, max_s: f64, settle_s: f64, gap_m: f64) -> Result<DressStats> {
        let held = self.collider_points();
        let garments = self.sim.model.part_ranges();
        if garments.len() > 1 && !self.sim.model.mesh.seam_pairs.is_empty() {
            return self.dress_in_layers(&held, &garments, max_s, settle_s, gap_m);
        }
        let frames = collider_frames(&self.colliders, &held);
        let mut out = DressStats::default();
        let wrapped = roll_panels(
            &self.sim.model.mesh,
            &mut self.state.x,
            &garments,
            &frames,
            "dressing",
        );
        out.wrapped_panels = wrapped.len();
        if !wrapped.is_empty() {
            // Seams start at rest at their new length (they shrink from there as they close):
            // rest lengths kept from the flat placement would push the rolled panels apart.
            self.seams_at_rest_where_they_are()?;
        }
        self.sew_and_settle(&held, out, max_s, settle_s, gap_m, true)
    }

    /// Dresses an outfit as a dresser would, from the inside out, the garments in the scene's
    /// order (the first innermost): each is rolled around the body and the garments already
    /// on it, and sewn with those held where they are and the later ones parked (held flat,
    /// touching nothing); then every seam is welded and all settle together, each garment in
    /// contact with the others. Sewn at once, the panels of two garments overlap around the
    /// body and the seams drag them through each other.
    fn dress_in_layers(
        &mut self,
        held: &[Vec<Vector3<f64>>],
        garments: &[std::ops::Range<usize>],
        max_s: f64,
        settle_s: f64,
        gap_m: f64,
    ) -> Result<DressStats> {
        let pins = self.sim.pins().to_vec();
        let t_start = self.state.t_s;
        let layered: Result<DressStats> = (|| {
            let mut out = DressStats::default();
            for (k, g) in garments.iter().enumerate() {
                let frames = collider_frames(&self.colliders, held);
                // The garments already on are a body this one is rolled around.
                let inner_x = self.state.x.clone();
                let inner: Vec<[u32; 3]> = self
                    .sim
                    .model
                    .mesh
                    .triangles
                    .iter()
                    .filter(|t| (t[0] as usize) < g.start)
                    .copied()
                    .collect();
                let mut bodies = frames.clone();
                if !inner.is_empty() {
                    bodies.push(ColliderFrame {
                        points: &inner_x,
                        triangles: &inner,
                    });
                }
                let stage = format!("dressing layer {}", k + 1);
                let wrapped = roll_panels(
                    &self.sim.model.mesh,
                    &mut self.state.x,
                    std::slice::from_ref(g),
                    &bodies,
                    &stage,
                );
                out.wrapped_panels += wrapped.len();
                self.seams_at_rest_where_they_are()?;
                let sewn = match self.sew_layer_alone(held, garments, k, max_s, gap_m)? {
                    Some(sewn) => {
                        out.layers_alone += 1;
                        sewn
                    }
                    None => {
                        // Every other garment is held where it is, in the whole outfit's
                        // simulation.
                        let mut layer_pins = pins.clone();
                        let pinned: std::collections::HashSet<u32> =
                            pins.iter().map(|p| p.v).collect();
                        for v in (0..self.state.x.len()).filter(|v| !g.contains(v)) {
                            if !pinned.contains(&(v as u32)) {
                                layer_pins.push(Pin {
                                    v: v as u32,
                                    target: PinTarget::Fixed(self.state.x[v]),
                                });
                            }
                        }
                        self.sim.set_pins(layer_pins);
                        let active = (0..garments.len()).map(|j| j <= k).collect();
                        let sewn = self.sew_layer(held, max_s, gap_m, active)?;
                        self.sim.set_pins(pins.clone());
                        sewn
                    }
                };
                tracing::info!(
                    "dressing layer {}: sewn in {} steps, widest seam gap {:.1} mm",
                    k + 1,
                    sewn.sew_steps,
                    sewn.seam_gap_m * 1e3
                );
                out.sew_steps += sewn.sew_steps;
                out.count_all(&sewn);
                out.harder_pulls += sewn.harder_pulls;
                out.initial_seam_gap_m = out.initial_seam_gap_m.max(sewn.initial_seam_gap_m);
                self.state.t_s = t_start;
            }
            self.sim.set_pins(pins.clone());
            let settled =
                self.sew_and_settle(held, DressStats::default(), 0.0, settle_s, gap_m, true)?;
            out.settle_steps = settled.settle_steps;
            out.count_all(&settled);
            out.seam_gap_m = settled.seam_gap_m;
            out.max_penetration_m = settled.max_penetration_m;
            out.welded_pairs = settled.welded_pairs;
            out.welded_gap_m = settled.welded_gap_m;
            Ok(out)
        })();
        self.sim.set_pins(pins);
        cloth_contacts(&mut self.sim, false, None);
        layered
    }

    /// Sews layer `k` of an outfit ([`Self::dress_in_layers`]) in a simulation of its own:
    /// garment `k`, and of the garments under it only the triangles whose boxes come within
    /// [`LAYER_REACH_M`] of the box around it, held where they are; the later garments
    /// (parked) left out. In the whole outfit's simulation the held garments took part in every
    /// detection, assembly and linear solve of the layer's Newton iterations though only their
    /// contact with it mattered. Its positions and seam rest lengths are then written back.
    /// `None` (nothing changed) when the sewn garment ends within contact reach of the box's
    /// walls where cloth was left out beyond them, or when its simulation fails: the caller
    /// sews it in the whole outfit instead.
    fn sew_layer_alone(
        &mut self,
        held: &[Vec<Vector3<f64>>],
        garments: &[std::ops::Range<usize>],
        k: usize,
        max_s: f64,
        gap_m: f64,
    ) -> Result<Option<DressStats>> {
        let g = garments[k].clone();
        let model = &self.sim.model;
        let x = &self.state.x;
        let reach = Aabb::from_points(&x[g.clone()]).inflate(LAYER_REACH_M);
        // A triangle is kept when its box meets the layer's: every one left out lies wholly
        // outside it.
        let meets = |t: &[u32; 3]| reach.overlaps(&Aabb::from_points(t.map(|v| &x[v as usize])));
        // The garments under it, cropped to the box, then the garment itself; `map`: each
        // vertex's index in the outfit.
        let mut meshes: Vec<(String, ClothMesh, Fabric)> = Vec::new();
        let mut map: Vec<usize> = Vec::new();
        let mut held_seams: Vec<usize> = Vec::new();
        let mut dropped = false;
        let mut local = vec![u32::MAX; x.len()];
        for part in &model.parts[..k] {
            let all = &model.mesh.triangles[part.triangles.clone()];
            let tris: Vec<[u32; 3]> = all.iter().filter(|t| meets(t)).copied().collect();
            dropped |= tris.len() < all.len();
            if tris.is_empty() {
                continue;
            }
            let mut verts: Vec<usize> = Vec::new();
            let tris: Vec<[u32; 3]> = tris
                .iter()
                .map(|t| {
                    t.map(|v| {
                        if local[v as usize] == u32::MAX {
                            local[v as usize] = verts.len() as u32;
                            verts.push(v as usize);
                        }
                        local[v as usize]
                    })
                })
                .collect();
            // Its seams between kept vertices (with self-collision, the cloth on either side
            // of a seam is not a contact).
            let seams: Vec<usize> = (0..model.mesh.seam_pairs.len())
                .filter(|&p| {
                    let [a, b] = model.mesh.seam_pairs[p].map(|v| v as usize);
                    part.vertices.contains(&a) && local[a] != u32::MAX && local[b] != u32::MAX
                })
                .collect();
            let mesh = ClothMesh {
                material: verts.iter().map(|&v| model.mesh.material[v]).collect(),
                positions: verts.iter().map(|&v| x[v]).collect(),
                triangles: tris,
                panel_of_vertex: verts
                    .iter()
                    .map(|&v| model.mesh.panel_of_vertex[v])
                    .collect(),
                panel_names: model.mesh.panel_names.clone(),
                seam_pairs: seams
                    .iter()
                    .map(|&p| model.mesh.seam_pairs[p].map(|v| local[v as usize]))
                    .collect(),
            };
            held_seams.extend(seams);
            meshes.push((part.name.clone(), mesh, part.fabric.clone()));
            map.extend(verts);
        }
        let held_count = map.len();
        let own = ClothMesh {
            positions: x[g.clone()].to_vec(),
            ..model.part_mesh(k)
        };
        meshes.push((
            model.parts[k].name.clone(),
            own,
            model.parts[k].fabric.clone(),
        ));
        map.extend(g.clone());
        let own_seams: Vec<usize> = (0..model.mesh.seam_pairs.len())
            .filter(|&p| g.contains(&(model.mesh.seam_pairs[p][0] as usize)))
            .collect();
        let pieces: Vec<(&str, &ClothMesh, &Fabric)> =
            meshes.iter().map(|(n, m, f)| (n.as_str(), m, f)).collect();
        let layer_model = match ClothModel::new(&pieces) {
            Ok(m) => m,
            Err(e) => {
                tracing::warn!("dressing layer {}: not sewn alone ({e})", k + 1);
                return Ok(None);
            }
        };
        let mut sim = Simulator::new(layer_model, self.sim.params.clone());
        let mut index = vec![u32::MAX; x.len()];
        for (s, &v) in map.iter().enumerate() {
            index[v] = s as u32;
        }
        let mut layer_pins: Vec<Pin> = (0..held_count)
            .map(|s| Pin {
                v: s as u32,
                target: PinTarget::Fixed(x[map[s]]),
            })
            .collect();
        // The scene's own pins on the garment.
        layer_pins.extend(
            self.sim
                .pins()
                .iter()
                .filter(|p| g.contains(&(p.v as usize)))
                .map(|p| Pin {
                    v: index[p.v as usize],
                    ..*p
                }),
        );
        sim.set_pins(layer_pins);
        let rest: Vec<f64> = held_seams
            .iter()
            .chain(&own_seams)
            .map(|&p| self.sim.seam_rest()[p])
            .collect();
        sim.set_seam_rest(&rest)?;
        let mut layer = Simulation {
            sim,
            state: SimState {
                x: map.iter().map(|&v| x[v]).collect(),
                v: vec![Vector3::zeros(); map.len()],
                t_s: self.state.t_s,
            },
            colliders: self.colliders.clone(),
            steps_per_frame: self.steps_per_frame,
            fps: self.fps,
            edge_m: self.edge_m,
            preroll_s: 0.0,
            buffers: [Vec::new(), Vec::new()],
        };
        let parts = layer.sim.model.parts.len();
        let sewn = match layer.sew_layer(held, max_s, gap_m, vec![true; parts]) {
            Ok(sewn) => sewn,
            Err(e) => {
                tracing::warn!("dressing layer {}: sewing it alone failed ({e})", k + 1);
                return Ok(None);
            }
        };
        if dropped {
            // Within reach of the box's walls, it may have met cloth left out beyond them:
            // sewing's contact thickness (the mesh's own) and the largest margin contacts are
            // looked for within.
            let p = &self.sim.params;
            let thickness = SimParams::for_edge(self.edge_m)
                .collision
                .dhat_m
                .max(p.collision.dhat_m);
            let wall =
                2.0 * thickness + p.detection_margin_m.max(thickness) + MAX_OBSTACLE_MARGIN_M;
            let within = reach.inflate(-wall);
            let inside = layer.state.x[held_count..]
                .iter()
                .all(|q| within.distance_sq(q) == 0.0);
            if !inside {
                tracing::info!(
                    "dressing layer {}: the garment came near cloth left out of its sewing; \
                     sewing it again beside the whole outfit",
                    k + 1
                );
                return Ok(None);
            }
        }
        for (s, &v) in map.iter().enumerate().skip(held_count) {
            self.state.x[v] = layer.state.x[s];
        }
        self.state.v.iter_mut().for_each(|v| *v = Vector3::zeros());
        let mut all = self.sim.seam_rest().to_vec();
        let layer_rest = &layer.sim.seam_rest()[held_seams.len()..];
        for (&p, &r) in own_seams.iter().zip(layer_rest) {
            all[p] = r;
        }
        self.sim.set_seam_rest(&all)?;
        Ok(Some(sewn))
    }

    /// How far apart dressing's sewing leaves seam pairs that it then welds, m: a few of the
    /// mesh's own contact thicknesses (or the run's, where thicker).
    pub fn weld_distance_m(&self) -> f64 {
        let own_dhat = SimParams::for_edge(self.edge_m).collision.dhat_m;
        WELD_MAX_DHAT * own_dhat.max(self.sim.params.collision.dhat_m)
    }

    /// Dresses the garments from positions `x` where the garment is already nearly sewn and
    /// draped (a coarser simulation's dressed state carried onto this mesh): no rolling;
    /// seams within `weld_m` are welded at once (the coarser mesh's
    /// [`Self::weld_distance_m`]: it closed them), the others start at rest where they are
    /// and close to within `gap_m` (at most `max_s` of
    /// simulated time, gravity off), then `settle_s` of draping, as in [`Self::dress`], its
    /// first step in sub-steps (the membrane relaxing from the coarser shape). A fine
    /// mesh dressed from its flat pattern spends most of its time on seams tens of
    /// centimetres open, where the move limits hold every vertex back and steps are halved;
    /// from a coarse dressing it only settles the detail the coarse mesh could not hold, at
    /// the run's move limits (its seams are closed: nothing flings the cloth, and at half its
    /// thin contact thickness an iteration the first steps were halved for minutes while the
    /// fine membrane relaxed from the coarse shape).
    pub fn dress_from(
        &mut self,
        x: Vec<Vector3<f64>>,
        weld_m: f64,
        max_s: f64,
        settle_s: f64,
        gap_m: f64,
    ) -> Result<DressStats> {
        if x.len() != self.state.x.len() || x.iter().any(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(Error::Invalid(format!(
                "dressing from {} positions (finite ones needed), the garments have {} vertices",
                x.len(),
                self.state.x.len()
            )));
        }
        self.state.x = x;
        self.state.v.iter_mut().for_each(|v| *v = Vector3::zeros());
        // Seams the coarser dressing closed are welded as they arrive: left on their springs
        // while the fine membrane relaxes from the coarse shape, the corners where several
        // panels meet (a hood's nape) were pulled apart and never closed again, and between
        // the coarse vertices the two sides' patches bow apart by a millimetre or two, which
        // springs do not close where a shoulder holds the seam.
        let carried = self.sim.weld_seams(&mut self.state, weld_m);
        let held = self.collider_points();
        if carried.pairs > 0 {
            // A welded point halfway across a gap may lie in the body.
            let clearance = 0.5 * self.sim.params.collision.dhat_m;
            push_out_of(&self.colliders, &held, &mut self.state.x, clearance);
        }
        self.seams_at_rest_where_they_are()?;
        let mut out = self.in_fast_mode(|sim| {
            sim.sim.params.cg_rel_tol = CARRIED_CG_REL_TOL;
            sim.sew_and_settle(&held, DressStats::default(), max_s, settle_s, gap_m, false)
        })?;
        out.welded_pairs += carried.pairs;
        out.welded_gap_m = out.welded_gap_m.max(carried.widest_gap_m);
        log_dressing_work(&out);
        Ok(out)
    }

    /// The colliders' points at the state's time (dressing holds them there).
    pub fn collider_points(&self) -> Vec<Vec<Vector3<f64>>> {
        let mut held: Vec<Vec<Vector3<f64>>> = vec![Vec::new(); self.colliders.len()];
        for (c, out) in self.colliders.iter().zip(held.iter_mut()) {
            c.positions_at(self.state.t_s, out);
        }
        held
    }

    /// Sets every seam's rest length to its present gap.
    fn seams_at_rest_where_they_are(&mut self) -> Result<()> {
        let gaps: Vec<f64> = self
            .sim
            .model
            .mesh
            .seam_pairs
            .iter()
            .map(|p| (self.state.x[p[0] as usize] - self.state.x[p[1] as usize]).norm())
            .collect();
        self.sim.set_seam_rest(&gaps)
    }

    /// Dressing's sewing (gravity and friction off, slow moves when `slow`) and settling on the
    /// colliders held at `held`; the state's time goes back to where it was, with zero
    /// velocity.
    fn sew_and_settle(
        &mut self,
        held: &[Vec<Vector3<f64>>],
        out: DressStats,
        max_s: f64,
        settle_s: f64,
        gap_m: f64,
        slow: bool,
    ) -> Result<DressStats> {
        self.sew_then(held, out, max_s, settle_s, gap_m, slow, None)
    }

    /// Sews one layer of an outfit ([`Self::dress_in_layers`]): the garments `active` only
    /// (the others take part in no cloth–cloth contact), no welding, no settling.
    fn sew_layer(
        &mut self,
        held: &[Vec<Vector3<f64>>],
        max_s: f64,
        gap_m: f64,
        active: Vec<bool>,
    ) -> Result<DressStats> {
        let out = DressStats::default();
        self.sew_then(held, out, max_s, 0.0, gap_m, true, Some(active))
    }

    /// [`Self::sew_and_settle`]; with `layer` (the garments taking part), it only sews.
    #[allow(clippy::too_many_arguments)]
    fn sew_then(
        &mut self,
        held: &[Vec<Vector3<f64>>],
        mut out: DressStats,
        max_s: f64,
        settle_s: f64,
        gap_m: f64,
        slow: bool,
        layer: Option<Vec<bool>>,
    ) -> Result<DressStats> {
        let finish = layer.is_none();
        let t_start = self.state.t_s;
        let gravity = self.sim.params.gravity_m_s2;
        let dt = self.sim.params.dt_s;
        let frames = collider_frames(&self.colliders, held);
        out.initial_seam_gap_m = self.sim.max_seam_gap_m(&self.state.x);
        let max_steps = (max_s / dt).ceil() as usize;
        self.sim.params.gravity_m_s2 = Vector3::zeros();
        // Panels slide around the body as their seams pull them closed: without friction, as
        // a dresser smooths cloth into place (with it the hem of a pencil skirt stuck on the
        // legs, 105 mm open).
        let friction = std::mem::replace(&mut self.sim.params.friction, 0.0);
        // A dresser moves cloth slowly: through sewing and settling, no vertex moves more
        // than ½ d̂ per Newton iteration (as every vertex did before the contact margin adapted
        // to the cloth's speed). Uncapped, seam springs pulled tight fling the light panels
        // together and they crumple.
        let move_cap = self.sim.params.move_cap_m;
        let capped = |dhat: f64| {
            if slow {
                move_cap.min(0.5 * dhat)
            } else {
                move_cap
            }
        };
        // Dressing works at the mesh's own contact thickness even when the run's is thinner
        // (a coarse mesh given the fine one's): each iteration's moves are capped at half of
        // it, and at a fine mesh's thickness a coarse garment took minutes to close its seams.
        // The run's thickness comes back for a last settling, where the cloth comes down
        // the rest of the way onto the body.
        let run_contact = (
            self.sim.params.collision.dhat_m,
            self.sim.params.detection_margin_m,
        );
        let own_dhat = SimParams::for_edge(self.edge_m)
            .collision
            .dhat_m
            .max(run_contact.0);
        let thicker = own_dhat > run_contact.0;
        self.sim.params.collision.dhat_m = own_dhat;
        self.sim.params.detection_margin_m = run_contact.1.max(own_dhat);
        self.sim.params.move_cap_m = capped(own_dhat);
        // Sewing ends once every seam is within `gap_m`, or within the contact thickness
        // (where a body between the two sides, an armpit, holds them that far apart), or
        // when the widest gap, within a few thicknesses, has stopped closing; then the seams
        // are welded, those within a few thicknesses.
        let weld_gap = gap_m.max(own_dhat);
        let weld_max = self.weld_distance_m();
        let stall_steps = ((SEWING_STALL_S / dt).ceil() as usize).max(1);
        let mut progress = (f64::INFINITY, 0usize);
        // A seam that stops closing further out is held by the cloth around it (a hood's
        // corner pulled round the nape against its own stiffness): the springs then pull
        // harder, as a tailor would, a few times over.
        let pull = (
            self.sim.params.sew_stiffness_n_m,
            self.sim.params.sew_max_stretch_m,
        );
        let mut doublings = 0u32;
        let mut before_pulling = None;
        // Sewn without cloth–cloth contact, a strap's panel folded through itself on its way
        // over the shoulder and closed folded onto the chest. A dresser's panels do not pass
        // through themselves: while sewing from the flat pattern, contact within each panel is
        // on (between panels of one garment it stays as the run has it: the legs of a jumpsuit
        // hooked on each other at the crotch with it).
        cloth_contacts(&mut self.sim, slow, layer);
        let sewing: Result<()> = (|| {
            while out.sew_steps < max_steps {
                out.seam_gap_m = self.sim.max_seam_gap_m(&self.state.x);
                if out.seam_gap_m <= weld_gap {
                    break;
                }
                if out.seam_gap_m < 0.99 * progress.0 {
                    progress = (out.seam_gap_m, out.sew_steps);
                } else if out.sew_steps - progress.1 >= stall_steps {
                    if out.seam_gap_m <= weld_max {
                        tracing::info!(
                            "dressing: the widest seam gap stopped closing at {:.1} mm",
                            out.seam_gap_m * 1e3
                        );
                        break;
                    }
                    if doublings < SEWING_PULL_DOUBLINGS {
                        before_pulling = Some((
                            self.state.clone(),
                            self.sim.seam_rest().to_vec(),
                            self.sim.obstacle_margin_m(),
                        ));
                        doublings += 1;
                        self.sim.params.sew_stiffness_n_m *= 2.0;
                        self.sim.params.sew_max_stretch_m *= 2.0;
                        progress = (out.seam_gap_m, out.sew_steps);
                        tracing::info!(
                            "dressing: the widest seam gap stopped closing at {:.1} mm; \
                             pulling the seams {}× as hard",
                            out.seam_gap_m * 1e3,
                            1 << doublings
                        );
                    }
                }
                let (next, st) = match self.sim.step(&self.state, &frames, &frames) {
                    Ok(step) => step,
                    // Pulled harder, cloth pressed between its own layers can leave the
                    // solver no way down: sewing stops where it was before the last doubling.
                    Err(e) => match before_pulling.take() {
                        Some((state, rest, margin)) => {
                            tracing::warn!(
                                "dressing: pulling the seams harder failed ({e}); \
                                 going on from where they stalled"
                            );
                            self.state = state;
                            self.sim.set_seam_rest(&rest)?;
                            self.sim.set_obstacle_margin_m(margin);
                            doublings -= 1;
                            out.seam_gap_m = self.sim.max_seam_gap_m(&self.state.x);
                            break;
                        }
                        None => return Err(e),
                    },
                };
                self.state = next;
                out.sew_steps += 1;
                out.count(&st);
                if out.sew_steps.is_multiple_of(30) {
                    tracing::info!(
                        "dressing: sewing step {}: widest seam gap {:.1} mm, newton {}, cg {}, contacts {}, penetration {:.2} mm",
                        out.sew_steps,
                        out.seam_gap_m * 1e3,
                        st.newton_iters,
                        st.cg_iters,
                        st.contacts,
                        st.max_penetration_m * 1e3
                    );
                }
            }
            Ok(())
        })();
        cloth_contacts(&mut self.sim, false, None);
        self.sim.params.gravity_m_s2 = gravity;
        self.sim.params.friction = friction;
        (
            self.sim.params.sew_stiffness_n_m,
            self.sim.params.sew_max_stretch_m,
        ) = pull;
        out.harder_pulls = doublings;
        if !finish {
            self.sim.params.move_cap_m = move_cap;
            self.sim.params.collision.dhat_m = run_contact.0;
            self.sim.params.detection_margin_m = run_contact.1;
            sewing?;
            out.seam_gap_m = self.sim.max_seam_gap_m(&self.state.x);
            self.state.t_s = t_start;
            self.state.v.iter_mut().for_each(|v| *v = Vector3::zeros());
            return Ok(out);
        }
        if sewing.is_ok() {
            let welded = self.sim.weld_seams(&mut self.state, weld_max);
            (out.welded_pairs, out.welded_gap_m) = (welded.pairs, welded.widest_gap_m);
            // A welded point halfway across a gap may lie in the body.
            let clearance = 0.5 * self.sim.params.collision.dhat_m;
            push_out_of(&self.colliders, held, &mut self.state.x, clearance);
        }
        let settle_steps = (settle_s / dt).ceil() as usize;
        let phases = if thicker { 2 } else { 1 };
        let settled = sewing.and_then(|()| {
            for k in 0..phases * settle_steps {
                if k == settle_steps {
                    self.sim.params.collision.dhat_m = run_contact.0;
                    self.sim.params.detection_margin_m = run_contact.1;
                    self.sim.params.move_cap_m = capped(run_contact.0);
                }
                // Only a garment carried from a coarser mesh's dressing is dressed at the
                // run's move limits (not `slow`): its first step relaxes the membrane from the
                // coarser shape.
                let substeps = self.sim.params.substeps;
                if k == 0 && !slow {
                    self.sim.params.substeps = substeps * CARRIED_FIRST_SUBSTEPS;
                }
                let stepped = self.sim.step(&self.state, &frames, &frames);
                self.sim.params.substeps = substeps;
                let (next, stats) = stepped?;
                self.state = next;
                out.settle_steps += 1;
                out.count(&stats);
                out.max_penetration_m = stats.max_penetration_m;
                // A fine mesh settles for minutes (its moves are capped at half its thin
                // contact margin an iteration): say where it is, as sewing does.
                if out.settle_steps.is_multiple_of(30) {
                    let speed = self.state.v.iter().map(|v| v.norm()).fold(0.0, f64::max);
                    tracing::info!(
                        "dressing: settling step {}/{}: fastest vertex {:.0} mm/s, newton {}, cg {}, contacts {}, penetration {:.2} mm",
                        out.settle_steps,
                        phases * settle_steps,
                        speed * 1e3,
                        stats.newton_iters,
                        stats.cg_iters,
                        stats.contacts,
                        stats.max_penetration_m * 1e3
                    );
                }
            }
            Ok(())
        });
        self.sim.params.move_cap_m = move_cap;
        self.sim.params.collision.dhat_m = run_contact.0;
        self.sim.params.detection_margin_m = run_contact.1;
        settled?;
        out.seam_gap_m = self.sim.max_seam_gap_m(&self.state.x);
        if out.seam_gap_m > gap_m {
            self.log_widest_seam();
        }
        self.state.t_s = t_start;
        self.state.v.iter_mut().for_each(|v| *v = Vector3::zeros());
        Ok(out)
    }

    /// Says where the widest seam gap is (which panels, where): what a user needs to see why
    /// a garment did not close.
    fn log_widest_seam(&self) {
        let mesh = &self.sim.model.mesh;
        let x = &self.state.x;
        let widest = mesh.seam_pairs.iter().max_by(|p, q| {
            let gap = |s: &&[u32; 2]| (x[s[0] as usize] - x[s[1] as usize]).norm();
            gap(p).total_cmp(&gap(q))
        });
        if let Some([a, b]) = widest {
            let (a, b) = (*a as usize, *b as usize);
            let name = |v: usize| &mesh.panel_names[mesh.panel_of_vertex[v] as usize];
            let mid = (x[a] + x[b]) * 0.5;
            tracing::warn!(
                "dressing: widest seam gap {:.1} mm, between '{}' and '{}' at ({:.3}, {:.3}, {:.3}) m",
                (x[a] - x[b]).norm() * 1e3,
                name(a),
                name(b),
                mid.x,
                mid.y,
                mid.z
            );
        }
    }

    /// Positions of each garment part, in the order of `sim.model.parts`.
    pub fn part_positions(&self) -> Vec<&[Vector3<f64>]> {
        self.sim
            .model
            .parts
            .iter()
            .map(|p| &self.state.x[p.vertices.clone()])
            .collect()
    }

    /// Kinetic energy, J.
    pub fn kinetic_energy_j(&self) -> f64 {
        self.state
            .v
            .iter()
            .zip(&self.sim.model.mass_kg)
            .map(|(v, m)| 0.5 * m * v.norm_squared())
            .sum()
    }
}

/// Logs a dressing's Newton iterations, its steps and where their time went.
fn log_dressing_work(out: &DressStats) {
    let phases = PhaseTimes::NAMES
        .iter()
        .zip(out.times.seconds())
        .map(|(name, s)| format!("{name} {s:.1} s"))
        .collect::<Vec<_>>()
        .join(", ");
    tracing::info!(
        "dressing: {} Newton iterations over {} steps; {phases}",
        out.newton_iters,
        out.sew_steps + out.settle_steps + out.preroll_steps
    );
}
