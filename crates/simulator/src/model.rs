//! Rest data of everything the simulator integrates: one concatenated cloth mesh made of one or
//! more garments, each with its fabric; lumped masses; membrane triangles, bending hinges, seams.

use std::ops::Range;

use nalgebra::Vector3;

use super::energy::bending::{self, Hinge};
use super::energy::membrane::{Membrane, MembraneStiffness};
use clothsr_geometry::error::{Error, Result};
use clothsr_geometry::garment::Fabric;
use clothsr_geometry::mesh::ClothMesh;

/// One garment inside the concatenated model.
#[derive(Debug, Clone)]
pub struct ClothPart {
    /// Name (for outputs).
    pub name: String,
    /// Fabric.
    pub fabric: Fabric,
    /// Its vertices in the model.
    pub vertices: Range<usize>,
    /// Its triangles in the model.
    pub triangles: Range<usize>,
}

/// The simulated cloth: all garments in one mesh, with per-element rest data.
#[derive(Debug, Clone)]
pub struct ClothModel {
    /// All garments' meshes, concatenated (material coordinates, rest positions, seams).
    pub mesh: ClothMesh,
    /// Where each garment lies in `mesh`.
    pub parts: Vec<ClothPart>,
    /// Lumped vertex masses, kg.
    pub mass_kg: Vec<f64>,
    /// Membrane elements (one per triangle).
    pub membranes: Vec<Membrane>,
    /// Stiffness of each membrane element.
    pub membrane_k: Vec<MembraneStiffness>,
    /// Bending hinges (interior edges of each panel).
    pub hinges: Vec<Hinge>,
    /// Rayleigh damping coefficient of each membrane element, s.
    pub membrane_damping_s: Vec<f64>,
    /// Rayleigh damping coefficient of each hinge, s.
    pub hinge_damping_s: Vec<f64>,
    /// Unique mesh edges.
    pub edges: Vec<[u32; 2]>,
    /// Bending stiffened where the membrane is compressed, once the cloth has settled
    /// ([`Self::set_wrinkle_bending`]; `None`: off), with each hinge's own weight.
    wrinkle_bending: Option<(WrinkleBending, Vec<f64>)>,
    /// Every hinge's weight relative to the fabric's, and the fabric's weights once a scale
    /// other than 1 was set ([`Self::set_bending_scale`]).
    bending_scale: (f64, Option<Vec<f64>>),
}

/// A coarse mesh's stand-in for the stiffness that a fine cloth's wrinkles add to its bending
/// (a corrugated sheet is stiffer than a flat one), for a cloth that has settled.
///
/// Before each step every hinge's weight is set to `w₀ (1 + gain · s · r)`, where `w₀` is its
/// own weight, `s = clamp(−ε / strain, 0, 1)` with `ε` the mean strain of the hinge's five
/// edges (negative when shortened: where the fine cloth would wrinkle) and
/// `r = clamp(1 − v̄ / settle_speed, 0, 1)` with `v̄` the cloth's mean vertex speed. The
/// weights are taken from the state at the start of the step and held through it (lagged,
/// like the simulator's friction), so every step's energy stays a fixed discrete shell.
///
/// Why the gate on speed: on the three-balls drop, stiffening during the impact moved the
/// coarse sheet's folds away from the fine sheet's (`docs/experiments/three_balls.md`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WrinkleBending {
    /// Extra bending stiffness where fully shortened, as a multiple of the fabric's (≥ 0).
    pub gain: f64,
    /// The shortening at which the extra stiffness is full (> 0).
    pub strain: f64,
    /// The cloth's mean speed at and above which nothing is added, m/s (> 0).
    pub settle_speed_m_s: f64,
}

impl WrinkleBending {
    /// The shortening at which the extra stiffness is full, by default (0.3 %; about what
    /// a settled fine sheet's coarse edges are shortened by on average).
    pub const DEFAULT_STRAIN: f64 = 0.003;
    /// The mean speed below which the extra stiffness comes in, by default, m/s.
    pub const DEFAULT_SETTLE_SPEED_M_S: f64 = 0.06;

    /// `gain` with the default strain and speed scales.
    pub fn with_gain(gain: f64) -> WrinkleBending {
        WrinkleBending {
            gain,
            strain: Self::DEFAULT_STRAIN,
            settle_speed_m_s: Self::DEFAULT_SETTLE_SPEED_M_S,
        }
    }

    /// A gain as the options take it: checked, and 0 as none.
    pub fn gain_option(gain: f64) -> Result<Option<f64>> {
        Self::with_gain(gain).check()?;
        Ok((gain != 0.0).then_some(gain))
    }

    /// Why these settings are unusable, if they are.
    pub fn check(&self) -> Result<()> {
        if !(self.gain >= 0.0 && self.gain.is_finite()) {
            return Err(Error::Invalid(format!(
                "the wrinkle bending gain must be finite and not negative, got {}",
                self.gain
            )));
        }
        if !(self.strain > 0.0 && self.strain.is_finite()) {
            return Err(Error::Invalid(format!(
                "the wrinkle bending strain must be > 0, got {}",
                self.strain
            )));
        }
        if !(self.settle_speed_m_s > 0.0 && self.settle_speed_m_s.is_finite()) {
            return Err(Error::Invalid(format!(
                "the wrinkle bending settle speed must be > 0, got {}",
                self.settle_speed_m_s
            )));
        }
        Ok(())
    }
}

impl ClothModel {
    /// Makes every membrane compression-soft: weft and warp stiffness times `factor` (in
    /// (0, 1]) where shortened ([`MembraneStiffness::compression`]), up to a shortening of
    /// `knee` (> 0) beyond which the full stiffness returns
    /// ([`MembraneStiffness::compression_knee`]; `None`: soft however short).
    pub fn set_membrane_compression(&mut self, factor: f64, knee: Option<f64>) -> Result<()> {
        if !(factor > 0.0 && factor <= 1.0) {
            return Err(Error::Invalid(format!(
                "membrane compression factor must be in (0, 1], got {factor}"
            )));
        }
        if let Some(s) = knee.filter(|s| !(*s > 0.0 && s.is_finite())) {
            return Err(Error::Invalid(format!(
                "membrane compression knee must be a shortening > 0, got {s}"
            )));
        }
        for k in &mut self.membrane_k {
            k.compression = factor;
            k.compression_knee = knee.unwrap_or(f64::INFINITY);
        }
        Ok(())
    }

    /// Builds the model from garments given as (name, mesh, fabric).
    pub fn new(pieces: &[(&str, &ClothMesh, &Fabric)]) -> Result<ClothModel> {
        if pieces.is_empty() {
            return Err(Error::Invalid(
                "nothing to simulate: the scene has no cloth".into(),
            ));
        }
        let mut mesh = ClothMesh::default();
        let mut parts = Vec::new();
        let (mut membranes, mut membrane_k, mut membrane_damping_s) =
            (Vec::new(), Vec::new(), Vec::new());
        let (mut hinges, mut hinge_damping_s) = (Vec::new(), Vec::new());
        for (name, m, fabric) in pieces {
            fabric.validate()?;
            m.validate()?;
            let v0 = mesh.positions.len() as u32;
            let t0 = mesh.triangles.len();
            let p0 = mesh.panel_names.len() as u32;
            mesh.positions.extend_from_slice(&m.positions);
            mesh.material.extend_from_slice(&m.material);
            mesh.triangles
                .extend(m.triangles.iter().map(|t| t.map(|v| v + v0)));
            mesh.panel_of_vertex
                .extend(m.panel_of_vertex.iter().map(|p| p + p0));
            mesh.panel_names
                .extend(m.panel_names.iter().map(|p| format!("{name}/{p}")));
            mesh.seam_pairs
                .extend(m.seam_pairs.iter().map(|p| p.map(|v| v + v0)));
            let k = MembraneStiffness::new(
                fabric.stretch_weft_n_m,
                fabric.stretch_warp_n_m,
                fabric.shear_n_m,
            );
            for (t, tri) in m.triangles.iter().enumerate() {
                let el = Membrane::new(*tri, &m.material).ok_or_else(|| {
                    Error::Invalid(format!(
                        "garment '{name}': triangle {t} is degenerate in material space"
                    ))
                })?;
                membranes.push(Membrane {
                    v: tri.map(|v| v + v0),
                    ..el
                });
                membrane_k.push(k);
                membrane_damping_s.push(fabric.damping_s);
            }
            for h in bending::hinges(&m.triangles, &m.material, fabric.bending_n_m) {
                hinges.push(Hinge {
                    v: h.v.map(|v| v + v0),
                    ..h
                });
                hinge_damping_s.push(fabric.damping_s);
            }
            parts.push(ClothPart {
                name: name.to_string(),
                fabric: (*fabric).clone(),
                vertices: v0 as usize..mesh.positions.len(),
                triangles: t0..mesh.triangles.len(),
            });
        }
        let mut mass_kg = vec![0.0; mesh.positions.len()];
        for part in &parts {
            for t in part.triangles.clone() {
                let m = membranes[t].area_m2 * part.fabric.areal_density_kg_m2 / 3.0;
                for v in membranes[t].v {
                    mass_kg[v as usize] += m;
                }
            }
        }
        if let Some(v) = mass_kg.iter().position(|m| m.is_nan() || *m <= 0.0) {
            return Err(Error::Invalid(format!(
                "vertex {v} belongs to no triangle (zero mass)"
            )));
        }
        let edges = mesh.edges();
        Ok(ClothModel {
            mesh,
            parts,
            mass_kg,
            membranes,
            membrane_k,
            hinges,
            membrane_damping_s,
            hinge_damping_s,
            edges,
            wrinkle_bending: None,
            bending_scale: (1.0, None),
        })
    }

    /// Sets every hinge's bending stiffness to `factor` (> 0) times the fabric's (1: the
    /// fabric's own; a coarse model's calibration, `clothsr lab calibrate`). With wrinkle bending on,
    /// the scaled weights become its own, which each step stiffens anew.
    pub fn set_bending_scale(&mut self, factor: f64) -> Result<()> {
        if !(factor > 0.0 && factor.is_finite()) {
            return Err(Error::Invalid(format!(
                "bending scale must be finite and > 0, got {factor}"
            )));
        }
        // Wrinkle bending off for the change puts the hinges back at their own weights.
        let wrinkles = self.wrinkle_bending();
        self.set_wrinkle_bending(None)?;
        let fabric = self
            .bending_scale
            .1
            .get_or_insert_with(|| self.hinges.iter().map(|h| h.weight).collect());
        for (h, w) in self.hinges.iter_mut().zip(fabric.iter()) {
            h.weight = w * factor;
        }
        self.bending_scale.0 = factor;
        self.set_wrinkle_bending(wrinkles)
    }

    /// Every hinge's weight relative to the fabric's ([`Self::set_bending_scale`]).
    pub fn bending_scale(&self) -> f64 {
        self.bending_scale.0
    }

    /// Turns on (or, with `None`, off) the wrinkles' bending stiffness ([`WrinkleBending`]);
    /// the hinges' present weights are the ones it scales, and turning it off restores them.
    pub fn set_wrinkle_bending(&mut self, wrinkles: Option<WrinkleBending>) -> Result<()> {
        if let Some(w) = &wrinkles {
            w.check()?;
        }
        let own = match self.wrinkle_bending.take() {
            Some((_, own)) => own,
            None => self.hinges.iter().map(|h| h.weight).collect(),
        };
        for (h, w) in self.hinges.iter_mut().zip(&own) {
            h.weight = *w;
        }
        self.wrinkle_bending = wrinkles.map(|w| (w, own));
        Ok(())
    }

    /// The wrinkles' bending stiffness in use ([`Self::set_wrinkle_bending`]).
    pub fn wrinkle_bending(&self) -> Option<WrinkleBending> {
        self.wrinkle_bending.as_ref().map(|(w, _)| *w)
    }

    /// Sets each hinge's weight for a step from positions `x` and velocities `v`
    /// ([`WrinkleBending`]); nothing when it is off.
    pub fn update_wrinkle_bending(&mut self, x: &[Vector3<f64>], v: &[Vector3<f64>]) {
        let Some((w, own)) = &self.wrinkle_bending else {
            return;
        };
        let mean_speed = v.iter().map(|v| v.norm()).sum::<f64>() / v.len().max(1) as f64;
        let settled = (1.0 - mean_speed / w.settle_speed_m_s).clamp(0.0, 1.0);
        let material = &self.mesh.material;
        let strain = |a: u32, b: u32| {
            let (a, b) = (a as usize, b as usize);
            let rest = (material[a] - material[b]).norm();
            if rest > 0.0 {
                (x[a] - x[b]).norm() / rest - 1.0
            } else {
                0.0
            }
        };
        for (h, own) in self.hinges.iter_mut().zip(own) {
            let [a, b, c, d] = h.v;
            let mean = if settled > 0.0 {
                (strain(a, b) + strain(a, c) + strain(b, c) + strain(a, d) + strain(b, d)) / 5.0
            } else {
                0.0
            };
            let shortened = (-mean / w.strain).clamp(0.0, 1.0);
            h.weight = own * (1.0 + w.gain * shortened * settled);
        }
    }

    /// The mesh of garment `part` alone (indices local to it).
    pub fn part_mesh(&self, part: usize) -> ClothMesh {
        let p = &self.parts[part];
        let (v0, v1) = (p.vertices.start as u32, p.vertices.end as u32);
        let m = &self.mesh;
        let p0 = m
            .panel_of_vertex
            .get(p.vertices.start)
            .copied()
            .unwrap_or(0);
        let panels: Vec<u32> = m.panel_of_vertex[p.vertices.clone()]
            .iter()
            .map(|x| x - p0)
            .collect();
        let num_panels = panels.iter().copied().max().map_or(0, |x| x + 1) as usize;
        ClothMesh {
            material: m.material[p.vertices.clone()].to_vec(),
            positions: m.positions[p.vertices.clone()].to_vec(),
            triangles: m.triangles[p.triangles.clone()]
                .iter()
                .map(|t| t.map(|v| v - v0))
                .collect(),
            panel_of_vertex: panels,
            panel_names: m.panel_names[p0 as usize..p0 as usize + num_panels].to_vec(),
            seam_pairs: m
                .seam_pairs
                .iter()
                .filter(|s| s[0] >= v0 && s[0] < v1)
                .map(|s| s.map(|v| v - v0))
                .collect(),
        }
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.mass_kg.len()
    }

    /// Total mass, kg.
    pub fn total_mass_kg(&self) -> f64 {
        self.mass_kg.iter().sum()
    }

    /// Smallest collision thickness of the garments' fabrics, m.
    pub fn min_thickness_m(&self) -> f64 {
        self.parts
            .iter()
            .map(|p| p.fabric.thickness_m)
            .fold(f64::INFINITY, f64::min)
    }

    /// Vertex pairs coupled by any element (for the sparse pattern).
    pub fn coupled_pairs(&self) -> Vec<(u32, u32)> {
        let mut pairs: Vec<(u32, u32)> = self.edges.iter().map(|e| (e[0], e[1])).collect();
        for h in &self.hinges {
            pairs.push((h.v[2], h.v[3]));
        }
        pairs.extend(self.mesh.seam_pairs.iter().map(|p| (p[0], p[1])));
        pairs
    }

    /// The vertex range of each part (garment or cloth piece), in order.
    pub fn part_ranges(&self) -> Vec<std::ops::Range<usize>> {
        self.parts.iter().map(|p| p.vertices.clone()).collect()
    }

    /// Elastic energy (membrane + bending) at positions `x`, joules.
    pub fn elastic_energy(&self, x: &[Vector3<f64>]) -> f64 {
        let mem = super::reduce::sum(self.membranes.len(), |k| {
            let m = &self.membranes[k];
            m.energy(&self.membrane_k[k], &m.v.map(|v| x[v as usize]))
        });
        let bend = super::reduce::sum(self.hinges.len(), |k| {
            let h = &self.hinges[k];
            bending::energy(h, &h.v.map(|v| x[v as usize]))
        });
        mem + bend
    }
}
