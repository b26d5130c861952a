//! Fabric parameters and presets.
//!
//! Conventions: the material (pattern) u axis is the **weft** (cross grain) and the v axis the
//! **warp** (straight grain, along the panel's y), as GarmentCode lays panels out with the grain
//! vertical. Stiffnesses are per unit width (N/m) for membrane, N·m for bending.

use serde::{Deserialize, Serialize};

/// Physical parameters of one fabric.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Fabric {
    /// Preset or user name.
    pub name: String,
    /// Mass per area, kg/m².
    pub areal_density_kg_m2: f64,
    /// Baraff-Witkin stretch stiffness along the warp (material v), N/m.
    pub stretch_warp_n_m: f64,
    /// Baraff-Witkin stretch stiffness along the weft (material u), N/m.
    pub stretch_weft_n_m: f64,
    /// Baraff-Witkin in-plane shear stiffness, N/m.
    pub shear_n_m: f64,
    /// Discrete-shell bending stiffness, N·m.
    pub bending_n_m: f64,
    /// Thickness, m (also the default collision thickness).
    pub thickness_m: f64,
    /// Rayleigh stiffness-proportional damping coefficient, s.
    pub damping_s: f64,
}

/// Names accepted by [`Fabric::preset`].
pub const PRESET_NAMES: [&str; 4] = ["silk", "cotton", "denim", "leather"];

impl Fabric {
    /// A named preset (`silk`, `cotton`, `denim`, `leather`), case-insensitive.
    ///
    /// Sources for the numbers:
    /// - Areal densities are the middle of the usual trade weights: silk charmeuse 60–90 g/m²,
    ///   cotton shirting/poplin 110–150 g/m², denim 11–14 oz/yd² (373–475 g/m²), garment leather
    ///   0.9–1.2 mm at ≈ 0.7 g/cm³.
    /// - Bending stiffness comes from Kawabata KES-FB2 bending rigidity B (gf·cm²/cm, where
    ///   1 gf·cm²/cm = 9.81·10⁻⁵ N·m) as reported for these fabric classes (Kawabata & Niwa 1989,
    ///   "Fabric performance in clothing and clothing manufacture", J. Text. Inst. 80(1)):
    ///   silk ≈ 0.02, shirting cotton ≈ 0.1, denim ≈ 0.7, leather ≈ 5.
    /// - Stretch and shear stiffness are the initial slopes of KES-FB1 tensile / shear curves
    ///   scaled to N/m (warp stiffer than weft for wovens; leather near-isotropic), capped so that
    ///   implicit Euler at dt = 1/300 s stays well conditioned, as in Wang et al. 2011,
    ///   "Data-driven elastic models for cloth" (ACM TOG 30(4)), whose measured fabrics span
    ///   10²–10⁴ N/m.
    pub fn preset(name: &str) -> Option<Fabric> {
        let lower = name.to_ascii_lowercase();
        let (density, warp, weft, shear, bending, thickness, damping) = match lower.as_str() {
            "silk" => (0.075, 800.0, 600.0, 40.0, 2.0e-6, 0.15e-3, 2.0e-4),
            "cotton" => (0.13, 2500.0, 1800.0, 100.0, 1.0e-5, 0.35e-3, 2.0e-4),
            "denim" => (0.42, 6000.0, 4500.0, 400.0, 7.0e-5, 0.8e-3, 3.0e-4),
            "leather" => (0.75, 9000.0, 8000.0, 2500.0, 5.0e-4, 1.1e-3, 5.0e-4),
            _ => return None,
        };
        Some(Fabric {
            name: lower,
            areal_density_kg_m2: density,
            stretch_warp_n_m: warp,
            stretch_weft_n_m: weft,
            shear_n_m: shear,
            bending_n_m: bending,
            thickness_m: thickness,
            damping_s: damping,
        })
    }

    /// Checks every parameter is finite and positive (damping may be zero).
    pub fn validate(&self) -> Result<(), String> {
        let fields = [
            ("arealDensity", self.areal_density_kg_m2),
            ("stretchWarp", self.stretch_warp_n_m),
            ("stretchWeft", self.stretch_weft_n_m),
            ("shear", self.shear_n_m),
            ("bending", self.bending_n_m),
            ("thickness", self.thickness_m),
        ];
        for (name, v) in fields {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!(
                    "fabric '{}': {name} must be finite and > 0, got {v}",
                    self.name
                ));
            }
        }
        if !(self.damping_s.is_finite() && self.damping_s >= 0.0) {
            return Err(format!(
                "fabric '{}': damping must be finite and >= 0",
                self.name
            ));
        }
        Ok(())
    }
}

impl Default for Fabric {
    fn default() -> Self {
        // "cotton" is always a valid preset name.
        Fabric::preset("cotton").unwrap_or(Fabric {
            name: "cotton".into(),
            areal_density_kg_m2: 0.13,
            stretch_warp_n_m: 2500.0,
            stretch_weft_n_m: 1800.0,
            shear_n_m: 100.0,
            bending_n_m: 1.0e-5,
            thickness_m: 0.35e-3,
            damping_s: 2.0e-4,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_valid_and_ordered_by_weight() {
        let f: Vec<Fabric> = PRESET_NAMES
            .iter()
            .map(|n| Fabric::preset(n).expect("preset"))
            .collect();
        for x in &f {
            x.validate().expect("valid preset");
        }
        for w in f.windows(2) {
            assert!(w[0].areal_density_kg_m2 < w[1].areal_density_kg_m2);
            assert!(w[0].bending_n_m < w[1].bending_n_m);
        }
        assert!(Fabric::preset("SILK").is_some());
        assert!(Fabric::preset("kevlar").is_none());
    }
}
