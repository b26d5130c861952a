//! Training and evaluation samples for the corrector, read from data sets made by
//! `clothsr::dataset::generate`: per simulator step, M_c (one coarse step from the previous M_int)
//! and M_int (the downsampled fine simulation). The target is the velocity correction
//! p̄ = v_int − v_c, which also moves M_c onto M_int: x_c + h·p̄ = x_int, since both came from
//! the same M_int by x = x₀ + h·v.

use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use super::graph::{body_proximity, step_change, MeshGraph};
use clothsr_geometry::error::{Error, Result};
use clothsr_geometry::mesh::ClothMesh;
use clothsr_io::data::{flat32, read_coarse_mesh, read_coarse_steps, read_manifest, Manifest};
use clothsr_sim::driver::Simulation;
use clothsr_sim::SimState;

/// One simulator step of a sequence: flattened (N·3) f32 arrays.
#[derive(Debug, Clone)]
pub struct Step {
    /// M_c positions, m.
    pub coarse_x: Vec<f32>,
    /// M_c velocities, m/s.
    pub coarse_v: Vec<f32>,
    /// M_int positions, m.
    pub int_x: Vec<f32>,
    /// M_int velocities, m/s.
    pub int_v: Vec<f32>,
    /// Body proximity of M_c's vertices ([`super::graph::body_proximity`]).
    pub body: Vec<f32>,
    /// The coarse step's velocity change beyond gravity ([`super::graph::step_change`]) from
    /// the previous step's M_int, m/s; `None` for a data set's very first step, whose start
    /// state is not stored.
    pub dv: Option<Vec<f32>>,
}

/// Δq = v_c − v_start − g·h of flattened arrays.
fn change(coarse_v: &[f32], start_v: &[f32], gravity_dt: Vector3<f64>) -> Vec<f32> {
    flat32(&step_change(
        &vectors(coarse_v),
        &vectors(start_v),
        gravity_dt,
    ))
}

/// A data set's coarse sequence in memory.
#[derive(Debug, Clone)]
pub struct Sequence {
    /// The data set directory.
    pub dir: PathBuf,
    /// Its manifest.
    pub manifest: Manifest,
    /// The coarse mesh (positions zero).
    pub mesh: ClothMesh,
    /// Its graph.
    pub graph: MeshGraph,
    /// First frame loaded (1-based); `steps[0]` is this frame's first step.
    pub first_frame: usize,
    /// Steps in order.
    pub steps: Vec<Step>,
}

/// Flattened f32 → vectors.
pub fn vectors(v: &[f32]) -> Vec<Vector3<f64>> {
    v.chunks_exact(3)
        .map(|c| Vector3::new(f64::from(c[0]), f64::from(c[1]), f64::from(c[2])))
        .collect()
}

impl Sequence {
    /// Loads frames `frames` (1-based, inclusive; `None`: all complete frames) of the data set
    /// in `dir`, with `sim`, the data set's coarse simulation
    /// ([`clothsr_io::data::coarse_simulation`], not yet stepped: its time is the data set's frame
    /// 0), for its colliders, time and gravity.
    pub fn load(
        dir: &Path,
        frames: Option<RangeInclusive<usize>>,
        sim: &Simulation,
    ) -> Result<Sequence> {
        let (colliders, t0_s) = (&sim.colliders, sim.state.t_s);
        let gravity_dt = sim.sim.params.gravity_m_s2 * sim.sim.params.dt_s;
        let manifest = read_manifest(dir)?;
        manifest.check_reference(dir)?;
        let frames = frames.unwrap_or(1..=manifest.frames_done);
        if frames.is_empty() || *frames.start() == 0 || *frames.end() > manifest.frames_done {
            return Err(Error::bad_input(
                dir.join("manifest.json"),
                format!(
                    "frames {}..={} asked for, the data set has 1..={}",
                    frames.start(),
                    frames.end(),
                    manifest.frames_done
                ),
            ));
        }
        let mesh = read_coarse_mesh(dir, &manifest)?;
        let graph = MeshGraph::new(&mesh);
        let (n3, s) = (3 * manifest.coarse_vertices, manifest.steps_per_frame);
        let mut steps = Vec::with_capacity(frames.clone().count() * s);
        // M_int's velocity before the first step loaded: the previous frame's last step.
        let mut start_v = if *frames.start() > 1 {
            let f = read_coarse_steps(dir, &manifest, frames.start() - 1)?;
            Some(f.int_v[(s - 1) * n3..s * n3].to_vec())
        } else {
            None
        };
        for k in frames.clone() {
            let f = read_coarse_steps(dir, &manifest, k)?;
            for i in 0..s {
                let r = i * n3..(i + 1) * n3;
                let coarse_x = f.coarse_x[r.clone()].to_vec();
                let coarse_v = f.coarse_v[r.clone()].to_vec();
                let t_s = t0_s + ((k - 1) * s + i + 1) as f64 * manifest.dt_s;
                let int_v = f.int_v[r.clone()].to_vec();
                steps.push(Step {
                    body: body_proximity(&vectors(&coarse_x), colliders, t_s),
                    dv: start_v.map(|v0| change(&coarse_v, &v0, gravity_dt)),
                    coarse_x,
                    coarse_v,
                    int_x: f.int_x[r].to_vec(),
                    int_v: int_v.clone(),
                });
                start_v = Some(int_v);
            }
        }
        Ok(Sequence {
            dir: dir.to_path_buf(),
            manifest,
            mesh,
            graph,
            first_frame: *frames.start(),
            steps,
        })
    }

    /// Replaces M_c of every step after the first with a step of `sim` (the data set's coarse
    /// simulation, [`clothsr_io::data::coarse_simulation`], whose time at the data set's frame 0 is
    /// `t0_s`, possibly set up otherwise) from the previous step's M_int, so that the
    /// corrector learns to correct the simulator it will run with rather than the one that
    /// made the data set. The first step's M_c (from the state before the sequence, which is
    /// not stored) stays as stored.
    pub fn recompute_coarse(&mut self, sim: &mut Simulation, t0_s: f64) -> Result<()> {
        let gravity_dt = sim.sim.params.gravity_m_s2 * sim.sim.params.dt_s;
        for i in 1..self.steps.len() {
            let state = self.int_state(i - 1, t0_s);
            let c = sim.step_from(&state)?.0;
            let dv = flat32(&step_change(&c.v, &state.v, gravity_dt));
            let st = &mut self.steps[i];
            st.body = body_proximity(&c.x, &sim.colliders, c.t_s);
            st.coarse_x = flat32(&c.x);
            st.coarse_v = flat32(&c.v);
            st.dv = Some(dv);
        }
        Ok(())
    }

    /// The per-step target velocity correction p̄ = v_int − v_c of `steps[i]`, flattened (the
    /// paper's one-step target, which also lands M_c on M_int: x_c + h·p̄ = x_int).
    pub fn target(&self, i: usize) -> Vec<f32> {
        let st = &self.steps[i];
        st.int_v
            .iter()
            .zip(&st.coarse_v)
            .map(|(a, b)| a - b)
            .collect()
    }

    /// The ground truth M_int at the end of `steps[i]` as a simulator state, with the coarse
    /// simulation's time there (`t0_s`: its time at the data set's frame 0).
    pub fn int_state(&self, i: usize, t0_s: f64) -> SimState {
        let st = &self.steps[i];
        SimState {
            x: vectors(&st.int_x),
            v: vectors(&st.int_v),
            t_s: t0_s + self.step_time_s(i),
        }
    }

    /// Simulated time at the end of `steps[i]`, s, relative to the data set's first frame.
    pub fn step_time_s(&self, i: usize) -> f64 {
        ((self.first_frame - 1) * self.manifest.steps_per_frame + i + 1) as f64 * self.manifest.dt_s
    }

    /// Root mean square of the per-step position correction h·|p̄| over all steps, m.
    pub fn rms_correction_m(&self) -> f64 {
        let h = self.manifest.dt_s;
        let (mut sum, mut count) = (0.0, 0usize);
        for s in &self.steps {
            for (a, b) in s.int_v.iter().zip(&s.coarse_v) {
                sum += (f64::from(a - b) * h).powi(2);
                count += 1;
            }
        }
        (3.0 * sum / count.max(1) as f64).sqrt()
    }
}
