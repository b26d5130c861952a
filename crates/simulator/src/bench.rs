//! The simulator's benchmark scene: a 1 m² cotton sheet dropped 2 cm above a sphere of radius
//! 0.3 m, dt 1/300 s, one step a frame (`clothsr lab bench sim`, and
//! `cargo run --release -p clothsr-sim --example bench` for the simulator alone). Newton 1.8's
//! side of the comparison (`tools/bench/newton_peer.py`) builds the same scene.

use std::time::Instant;

use nalgebra::Vector3;

use crate::driver::Simulation;
use crate::step::{PhaseTimes, SimParams};
use clothsr_geometry::error::Result;
use clothsr_geometry::garment::Fabric;
use clothsr_geometry::scene::samples::flat_sheet;
use clothsr_geometry::scene::{Collider, Scene};

/// Steps run before timing: they bring the sheet down onto the sphere.
pub const WARM_UP_STEPS: usize = 20;

/// The edge length that gives the bench's sheet about `verts` vertices, m (1 m² of pattern
/// holds about 2,950 vertices at 20 mm edges, scaling with 1/h²).
pub fn edge_for_vertices(verts: f64) -> f64 {
    clothsr_geometry::mesh::COARSE_EDGE_M * (2950.0 / verts).sqrt()
}

/// An approximate vertex count as the bench takes it: `3k`, `40k` or a plain number (`None`
/// when it is neither).
pub fn parse_vertices(s: &str) -> Option<f64> {
    let t = s.trim().to_ascii_lowercase();
    let (num, mult) = match t.strip_suffix('k') {
        Some(n) => (n, 1e3),
        None => (t.as_str(), 1.0),
    };
    num.parse::<f64>().ok().map(|n| n * mult)
}

/// The bench's scene with a sheet of about `verts` vertices, settings tuned by `tune`.
pub fn sheet_on_sphere(verts: f64, tune: impl FnOnce(&mut SimParams)) -> Result<Simulation> {
    let mut scene = Scene {
        garments: vec![flat_sheet(
            "sheet",
            1.0,
            1.0,
            Vector3::new(0.0, 0.32, 0.0),
            Fabric::preset("cotton").unwrap_or_default(),
        )],
        ..Scene::default()
    };
    scene
        .colliders
        .push(Collider::sphere("sphere", Vector3::zeros(), 0.3, 4));
    let mut sim = Simulation::new(&scene, edge_for_vertices(verts), tune)?;
    sim.steps_per_frame = 1;
    Ok(sim)
}

/// What timing a simulation's steps measured.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Timing {
    /// Cloth vertices.
    pub vertices: usize,
    /// Cloth triangles.
    pub triangles: usize,
    /// Wall time per step, ms.
    pub ms_per_step: f64,
    /// Newton iterations per step.
    pub newton_per_step: f64,
    /// Linear-solve iterations per Newton iteration.
    pub cg_per_newton: f64,
    /// Contacts at the last step.
    pub contacts: usize,
    /// Where the time went, per step, s.
    pub phases: PhaseTimes,
}

/// The phase columns' header, as [`phase_columns`] fills them.
pub fn phase_header() -> String {
    PhaseTimes::NAMES.map(|n| format!(" {n:>8}")).concat()
}

/// `phases`' times in ms, one column each under [`phase_header`].
pub fn phase_columns(phases: &PhaseTimes) -> String {
    phases
        .seconds()
        .map(|s| format!(" {:>8.2}", s * 1e3))
        .concat()
}

/// Runs `warm_up` steps of `sim`, then times `steps` more.
pub fn time_steps(sim: &mut Simulation, warm_up: usize, steps: usize) -> Result<Timing> {
    for _ in 0..warm_up {
        sim.advance_frame(|_| {})?;
    }
    let (mut newton, mut cg, mut contacts) = (0usize, 0usize, 0usize);
    let mut phases = PhaseTimes::default();
    let t = Instant::now();
    for _ in 0..steps {
        let f = sim.advance_frame(|_| {})?;
        newton += f.steps.newton_iters;
        cg += f.steps.cg_iters;
        contacts = f.steps.contacts;
        phases.add(&f.steps.times);
    }
    let per = 1.0 / steps.max(1) as f64;
    Ok(Timing {
        vertices: sim.sim.model.num_vertices(),
        triangles: sim.sim.model.mesh.triangles.len(),
        ms_per_step: t.elapsed().as_secs_f64() * 1e3 * per,
        newton_per_step: newton as f64 * per,
        cg_per_newton: cg as f64 / newton.max(1) as f64,
        contacts,
        phases: phases.scaled(per),
    })
}
