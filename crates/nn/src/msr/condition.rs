//! What the ISR network is told beyond the coordinate maps (beyond the paper, whose §4.4.3
//! names a fabric-blind network as a limitation): the fabric of each panel and the ratio of the
//! coarse to the fine edge length. A stiff fabric folds in few wide waves, a soft one in many
//! narrow ones; a coarser mesh leaves more of the detail to the network.

use clothsr_geometry::garment::Fabric;

use clothsr_geometry::error::{Error, Result};
use clothsr_geometry::mesh::ClothMesh;
use clothsr_geometry::scene::catalogue;
use clothsr_io::data::Manifest;

/// Input channels the condition adds ([`Condition::channels`]).
pub const CONDITION_CHANNELS: usize = 4;

/// The fabric and resolutions one panel is super-resolved with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Condition {
    /// Discrete-shell bending stiffness, N·m.
    pub bending_n_m: f64,
    /// Mass per area, kg/m².
    pub areal_density_kg_m2: f64,
    /// Mean of the warp and weft stretch stiffnesses, N/m.
    pub stretch_n_m: f64,
    /// Coarse edge length over the fine one.
    pub ratio: f64,
}

impl Condition {
    /// `fabric` at coarse and fine edge lengths `coarse_edge_m`, `fine_edge_m`.
    pub fn new(fabric: &Fabric, coarse_edge_m: f64, fine_edge_m: f64) -> Condition {
        Condition {
            bending_n_m: fabric.bending_n_m,
            areal_density_kg_m2: fabric.areal_density_kg_m2,
            stretch_n_m: 0.5 * (fabric.stretch_warp_n_m + fabric.stretch_weft_n_m),
            ratio: coarse_edge_m / fine_edge_m,
        }
    }

    /// The network's input: each quantity's logarithm relative to cotton at a ratio of 8, so
    /// the presets span about ±2 units.
    pub fn channels(&self) -> [f32; CONDITION_CHANNELS] {
        let log = |v: f64, reference: f64| (v / reference).max(1e-30).log10() as f32;
        [
            log(self.bending_n_m, 1e-5),
            log(self.areal_density_kg_m2, 0.13),
            log(self.stretch_n_m, 2150.0),
            (self.ratio / 8.0).max(1e-30).log2() as f32,
        ]
    }

    /// Checks every quantity is finite and positive.
    pub fn check(&self) -> Result<()> {
        let ok = [
            self.bending_n_m,
            self.areal_density_kg_m2,
            self.stretch_n_m,
            self.ratio,
        ]
        .iter()
        .all(|v| v.is_finite() && *v > 0.0);
        if ok {
            Ok(())
        } else {
            Err(Error::Invalid(format!(
                "the ISR condition must be finite and positive, got {self:?}"
            )))
        }
    }
}

/// Each panel's part in a mesh whose panels are named `part/panel` (parts in order of first
/// appearance; a mesh of one garment may have no prefix).
pub fn part_of_panel(mesh: &ClothMesh) -> Vec<usize> {
    let mut parts: Vec<&str> = Vec::new();
    mesh.panel_names
        .iter()
        .map(|name| {
            let part = name.split_once('/').map_or("", |(p, _)| p);
            match parts.iter().position(|p| *p == part) {
                Some(k) => k,
                None => {
                    parts.push(part);
                    parts.len() - 1
                }
            }
        })
        .collect()
}

/// Each panel's condition for per-part `fabrics`.
pub fn panel_conditions(
    mesh: &ClothMesh,
    fabrics: &[Fabric],
    coarse_edge_m: f64,
    fine_edge_m: f64,
) -> Result<Vec<Condition>> {
    part_of_panel(mesh)
        .into_iter()
        .map(|k| {
            let fabric = fabrics.get(k).or(fabrics.last()).ok_or_else(|| {
                Error::Invalid("no fabric to condition the ISR network on".into())
            })?;
            let c = Condition::new(fabric, coarse_edge_m, fine_edge_m);
            c.check()?;
            Ok(c)
        })
        .collect()
}

/// Each panel's condition in a data set: its recorded fabrics, or for data sets made before
/// they were recorded, the fabrics its names stand for (presets and the catalogue's mixes).
pub fn data_conditions(manifest: &Manifest, fine_mesh: &ClothMesh) -> Result<Vec<Condition>> {
    let fabrics: Vec<Fabric> = if manifest.fabric_values.is_empty() {
        manifest
            .fabrics
            .iter()
            .map(|name| {
                catalogue::fabric_named(name).ok_or_else(|| {
                    Error::Invalid(format!(
                        "the data set's fabric '{name}' has no recorded parameters"
                    ))
                })
            })
            .collect::<Result<_>>()?
    } else {
        manifest.fabric_values.clone()
    };
    panel_conditions(
        fine_mesh,
        &fabrics,
        manifest.coarse_mean_edge_m,
        manifest.fine_mean_edge_m,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cotton_at_a_ratio_of_eight_is_the_origin_and_presets_are_ordered() {
        let cotton = Fabric::preset("cotton").expect("cotton");
        let c = Condition::new(&cotton, 0.02, 0.0025).channels();
        for (k, v) in c.iter().enumerate() {
            if k < 2 {
                assert!(v.abs() < 1e-6, "channel {k}: {v}");
            }
        }
        // Mean stretch of cotton (2500, 1800) is 2150 N/m.
        assert!(c[2].abs() < 1e-6);
        assert!(c[3].abs() < 1e-6);
        let mut last = f32::MIN;
        for name in ["silk", "cotton", "denim", "leather"] {
            let f = Fabric::preset(name).expect("preset");
            let b = Condition::new(&f, 0.02, 0.0025).channels()[0];
            assert!(b > last, "{name}: bending channel {b} not above {last}");
            assert!(b.abs() < 2.0);
            last = b;
        }
        let half = Condition::new(&cotton, 0.02, 0.005).channels()[3];
        assert!((half + 1.0).abs() < 1e-6);
    }

    #[test]
    fn panels_take_their_parts_fabric() {
        let mesh = ClothMesh {
            panel_names: vec!["a/front".into(), "a/back".into(), "b/sheet".into()],
            ..ClothMesh::default()
        };
        assert_eq!(part_of_panel(&mesh), vec![0, 0, 1]);
        let f = [
            Fabric::preset("silk").expect("silk"),
            Fabric::preset("denim").expect("denim"),
        ];
        let c = panel_conditions(&mesh, &f, 0.02, 0.0025).expect("conditions");
        assert_eq!(c[0], c[1]);
        assert_eq!(c[2].bending_n_m, f[1].bending_n_m);
        assert!(panel_conditions(&mesh, &[], 0.02, 0.0025).is_err());
    }
}
