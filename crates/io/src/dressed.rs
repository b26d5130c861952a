//! A garment's dressed first frame kept in a file beside a run's output: a later run of the same
//! shot (more frames, other models, a rerun after a crash) starts from it instead of sewing the
//! garment again.

use std::path::{Path, PathBuf};

use crate::tensors::{TensorReader, TensorWriter};
use clothsr_geometry::error::Result;
use clothsr_sim::driver::{DressStats, Simulation};

/// Simulated seconds of sewing at most, of settling after it, and the seam gap sewing aims
/// for, m: how runs and data sets dress a garment ([`Simulation::dress`]).
pub const DRESSING: (f64, f64, f64) = (2.0, 0.3, 1e-3);

/// Where the dressed state of the run writing `output` is kept: `OUT.dressed.safetensors`
/// beside `OUT.usdc`.
pub fn dressed_path(output: &Path) -> PathBuf {
    output.with_extension("dressed.safetensors")
}

/// Dresses `sim` ([`Simulation::dress`] with [`DRESSING`]), or, when `cache` holds the dressed
/// state of the same simulation (the same mesh, fabric, solver and contact settings and first
/// frame of the colliders), restores it: positions at rest, seam rest lengths, welds. A new
/// dressing is written to `cache` (a failed write is only a warning). `None`: restored.
pub fn dress_or_restore(sim: &mut Simulation, cache: Option<&Path>) -> Result<Option<DressStats>> {
    let key = format!("{:016x}", fingerprint(sim));
    if let Some(path) = cache.filter(|p| p.exists()) {
        match restore(sim, path, &key) {
            Ok(true) => {
                tracing::info!("dressed: the dressed state kept in {}", path.display());
                return Ok(None);
            }
            Ok(false) => tracing::info!(
                "{}: dressed for another shot or other settings; dressing again",
                path.display()
            ),
            Err(e) => tracing::warn!("{e}; dressing again"),
        }
    }
    let (max_s, settle_s, gap_m) = DRESSING;
    let stats = sim.dress(max_s, settle_s, gap_m)?;
    if let Some(path) = cache {
        let n = sim.state.x.len();
        let x: Vec<f64> = sim.state.x.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
        let rest = sim.sim.seam_rest();
        let written = TensorWriter::new()
            .meta("clothsr_dressed", &key)
            .f64("x", &[n, 3], &x)
            .f64("seam_rest", &[rest.len()], rest)
            .write(path);
        if let Err(e) = written {
            tracing::warn!("the dressed state was not kept: {e}");
        }
    }
    Ok(Some(stats))
}

/// Sets `sim` to the dressed state in `path` when it was made with the fingerprint `key`.
fn restore(sim: &mut Simulation, path: &Path, key: &str) -> Result<bool> {
    let r = TensorReader::open(path)?;
    if r.meta("clothsr_dressed").as_deref() != Some(key) {
        return Ok(false);
    }
    let x = crate::data::unflat(&r.f64("x")?.1);
    if x.len() != sim.state.x.len() || x.iter().any(|p| !p.iter().all(|c| c.is_finite())) {
        return Ok(false);
    }
    sim.sim.set_seam_rest(&r.f64("seam_rest")?.1)?;
    sim.state.x = x;
    sim.state
        .v
        .iter_mut()
        .for_each(|v| *v = nalgebra::Vector3::zeros());
    // Welded seam pairs were saved on one point.
    sim.sim.weld_seams(&mut sim.state, 0.0);
    Ok(true)
}

/// FNV-1a over what dressing depends on: the mesh at rest, the parts' fabrics, the solver
/// settings, the colliders at the start and the pre-roll.
fn fingerprint(sim: &Simulation) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for b in bytes {
            h ^= u64::from(*b);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    // 2: seams that stall are pulled harder; 3: contact within panels while sewing; 4: outfits
    // dressed one garment at a time; 5: each layer of an outfit sewn in a simulation of its own.
    eat(b"clothsr dressed 5");
    let model = &sim.sim.model;
    for p in &sim.state.x {
        p.iter().for_each(|c| eat(&c.to_le_bytes()));
    }
    for t in &model.mesh.triangles {
        t.iter().for_each(|v| eat(&v.to_le_bytes()));
    }
    for s in &model.mesh.seam_pairs {
        s.iter().for_each(|v| eat(&v.to_le_bytes()));
    }
    for part in &model.parts {
        eat(format!("{:?}", part.fabric).as_bytes());
    }
    eat(format!("{:?}", sim.sim.params).as_bytes());
    eat(&sim.state.t_s.to_le_bytes());
    for points in sim.collider_points() {
        for p in points {
            p.iter().for_each(|c| eat(&c.to_le_bytes()));
        }
    }
    // A pre-roll dresses on the bodies as they were then.
    if sim.preroll_s > 0.0 {
        eat(&sim.preroll_s.to_le_bytes());
        let mut then = Vec::new();
        for c in &sim.colliders {
            c.positions_at(sim.state.t_s - sim.preroll_s, &mut then);
            then.iter()
                .for_each(|p| p.iter().for_each(|c| eat(&c.to_le_bytes())));
        }
    }
    h
}
