//! Fabric parameters and presets.
//!
//! Conventions: the material (pattern) u axis is the **weft** (cross grain) and the v axis the
//! **warp** (straight grain, along the panel's y), as GarmentCode lays panels out with the grain
//! vertical. Stiffnesses are per unit width (N/m) for membrane, N·m for bending.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

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

/// clothsr's fabric presets, by name (`silk`, `cotton`, `denim`, `leather`; parsed
/// case-insensitively).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum FabricPreset {
    /// Silk charmeuse.
    Silk,
    /// Cotton shirting.
    #[default]
    Cotton,
    /// Denim.
    Denim,
    /// Garment leather.
    Leather,
}

impl FabricPreset {
    /// Every preset, lightest first.
    pub const ALL: [FabricPreset; 4] = [Self::Silk, Self::Cotton, Self::Denim, Self::Leather];

    /// Its name, as parsed.
    pub fn name(self) -> &'static str {
        match self {
            Self::Silk => "silk",
            Self::Cotton => "cotton",
            Self::Denim => "denim",
            Self::Leather => "leather",
        }
    }

    /// The fabric.
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
    pub fn fabric(self) -> Fabric {
        let (density, warp, weft, shear, bending, thickness, damping) = match self {
            Self::Silk => (0.075, 800.0, 600.0, 40.0, 2.0e-6, 0.15e-3, 2.0e-4),
            Self::Cotton => (0.13, 2500.0, 1800.0, 100.0, 1.0e-5, 0.35e-3, 2.0e-4),
            Self::Denim => (0.42, 6000.0, 4500.0, 400.0, 7.0e-5, 0.8e-3, 3.0e-4),
            Self::Leather => (0.75, 9000.0, 8000.0, 2500.0, 5.0e-4, 1.1e-3, 5.0e-4),
        };
        Fabric {
            name: self.name().to_string(),
            areal_density_kg_m2: density,
            stretch_warp_n_m: warp,
            stretch_weft_n_m: weft,
            shear_n_m: shear,
            bending_n_m: bending,
            thickness_m: thickness,
            damping_s: damping,
        }
    }
}

impl std::fmt::Display for FabricPreset {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A fabric name that is no preset.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownFabric(pub String);

impl std::fmt::Display for UnknownFabric {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let known: Vec<&str> = FabricPreset::ALL.iter().map(|p| p.name()).collect();
        write!(
            f,
            "unknown fabric '{}' (known: {})",
            self.0,
            known.join(", ")
        )
    }
}

impl std::error::Error for UnknownFabric {}

impl std::str::FromStr for FabricPreset {
    type Err = UnknownFabric;

    fn from_str(s: &str) -> Result<Self, UnknownFabric> {
        FabricPreset::ALL
            .into_iter()
            .find(|p| p.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| UnknownFabric(s.to_string()))
    }
}

impl From<FabricPreset> for Fabric {
    fn from(p: FabricPreset) -> Fabric {
        p.fabric()
    }
}

impl Fabric {
    /// The preset named `name` ([`FabricPreset`]), case-insensitive.
    pub fn preset(name: &str) -> Option<Fabric> {
        name.parse::<FabricPreset>().ok().map(FabricPreset::fabric)
    }

    /// Checks every parameter is finite and positive (damping may be zero).
    pub fn validate(&self) -> Result<()> {
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
                return Err(Error::Invalid(format!(
                    "fabric '{}': {name} must be finite and > 0, got {v}",
                    self.name
                )));
            }
        }
        if !(self.damping_s.is_finite() && self.damping_s >= 0.0) {
            return Err(Error::Invalid(format!(
                "fabric '{}': damping must be finite and >= 0",
                self.name
            )));
        }
        Ok(())
    }
}

impl Default for Fabric {
    fn default() -> Self {
        FabricPreset::default().fabric()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_valid_and_ordered_by_weight() {
        let f: Vec<Fabric> = FabricPreset::ALL
            .iter()
            .map(|p| Fabric::preset(p.name()).expect("preset"))
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
        let err = "kevlar".parse::<FabricPreset>().expect_err("no preset");
        assert_eq!(
            err.to_string(),
            "unknown fabric 'kevlar' (known: silk, cotton, denim, leather)"
        );
        assert_eq!(" Denim".parse(), Ok(FabricPreset::Denim));
        assert_eq!(Fabric::default().name, "cotton");
    }
}
