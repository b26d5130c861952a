//! The coarse model: the settings of the 20 mm simulation that the learned stages run beside
//! (membrane compression and its knee, friction, wrinkle bending, bending stiffness, crease
//! contacts), as a models folder's `coarse.json` and a corrector's training configuration
//! record them.

use crate::driver::Simulation;
use crate::error::{Error, Result};

/// The coarse model's settings, each optional (unset: the simulator's own). A models folder's
/// `coarse.json` holds the calibration its figures were measured with for runs without a
/// corrector, since the best coarse model differs from scene to scene; a corrector carries the
/// one it was trained beside. `{"compression": 0.03}` sets the membrane's compression factor
/// alone; likewise `compression_knee`, `friction`, `wrinkle_bending` (0: off), `bending` and
/// `crease_contacts`. [`CoarseCalibration::apply`] sets a simulation up with them.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct CoarseCalibration {
    /// The membrane's stiffness under compression as a factor of its stretch stiffness
    /// ([`crate::model::ClothModel::set_membrane_compression`]), in (0, 1].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compression: Option<f64>,
    /// The shortening beyond which the compression-soft membrane is stiff again, > 0 (0: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compression_knee: Option<f64>,
    /// The Coulomb friction coefficient against bodies, ≥ 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub friction: Option<f64>,
    /// The wrinkle bending gain ([`crate::WrinkleBending::with_gain`]), ≥ 0 (0: off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wrinkle_bending: Option<f64>,
    /// The hinges' bending stiffness as a factor of the fabric's, > 0 (1: the fabric's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bending: Option<f64>,
    /// Whether cloth edges meet the colliders' sharp edges
    /// ([`crate::collide::CollisionDetector::crease_contacts`]; `false`: coarse edges may cut
    /// colliders' creases).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crease_contacts: Option<bool>,
}

/// A crease-contacts setting as `on` or `off` (`None`: on, the simulator's).
pub fn crease_label(setting: Option<bool>) -> &'static str {
    if setting.unwrap_or(true) {
        "on"
    } else {
        "off"
    }
}

impl CoarseCalibration {
    /// Its file name in a models folder.
    pub const FILE: &'static str = "coarse.json";

    /// The calibration in `models/coarse.json`, checked; `None` where there is no such file.
    pub fn load(models: &std::path::Path) -> Result<Option<CoarseCalibration>> {
        let path = models.join(Self::FILE);
        if !path.exists() {
            return Ok(None);
        }
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        let cal: CoarseCalibration = serde_json::from_str(&text)
            .map_err(|e| Error::bad_input(&path, format!("not a coarse calibration: {e}")))?;
        cal.check().map_err(|m| Error::bad_input(&path, m))?;
        Ok(Some(cal))
    }

    /// Why these settings are unusable, if they are.
    pub fn check(&self) -> std::result::Result<(), String> {
        if let Some(c) = self.compression {
            if !(c > 0.0 && c <= 1.0) {
                return Err(format!("compression must be in (0, 1], got {c}"));
            }
        }
        if let Some(k) = self.compression_knee {
            if !(k >= 0.0 && k.is_finite()) {
                return Err(format!(
                    "compression_knee must be a shortening > 0 (0: none), got {k}"
                ));
            }
        }
        if let Some(mu) = self.friction {
            check_friction(mu).map_err(|m| format!("friction: {m}"))?;
        }
        if let Some(g) = self.wrinkle_bending {
            crate::WrinkleBending::gain_option(g).map_err(|m| format!("wrinkle_bending: {m}"))?;
        }
        if let Some(b) = self.bending {
            if !(b > 0.0 && b.is_finite()) {
                return Err(format!("bending must be a factor > 0, got {b}"));
            }
        }
        Ok(())
    }

    /// Sets a coarse simulation's model to this calibration (unset fields: the simulator's own
    /// model), but for an unset friction, which leaves the simulation's as it is (a fresh
    /// simulation's: the scene's).
    pub fn apply(&self, sim: &mut Simulation) -> Result<()> {
        self.check().map_err(Error::Invalid)?;
        let knee = self.compression_knee.filter(|&k| k != 0.0);
        sim.sim
            .model
            .set_membrane_compression(self.compression.unwrap_or(1.0), knee)?;
        if let Some(mu) = self.friction {
            set_friction(sim, mu)?;
        }
        sim.sim
            .model
            .set_bending_scale(self.bending.unwrap_or(1.0))?;
        sim.sim.detector_mut().crease_contacts = self.crease_contacts.unwrap_or(true);
        let gain = self.wrinkle_bending.filter(|&g| g != 0.0);
        sim.sim
            .model
            .set_wrinkle_bending(gain.map(crate::WrinkleBending::with_gain))
    }
}

impl std::fmt::Display for CoarseCalibration {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let parts: Vec<String> = [
            ("compression", self.compression),
            ("compression knee", self.compression_knee),
            ("friction", self.friction),
            ("wrinkle bending", self.wrinkle_bending),
            ("bending", self.bending),
        ]
        .iter()
        .filter_map(|(name, v)| v.map(|v| format!("{name} {v}")))
        .chain((self.crease_contacts == Some(false)).then(|| "no crease contacts".to_string()))
        .collect();
        if parts.is_empty() {
            f.write_str("the simulator's")
        } else {
            f.write_str(&parts.join(", "))
        }
    }
}

/// Why `mu` is no Coulomb friction coefficient (it must be finite and not negative).
pub fn check_friction(mu: f64) -> std::result::Result<(), String> {
    if mu.is_finite() && mu >= 0.0 {
        Ok(())
    } else {
        Err(format!(
            "the friction coefficient must be finite and not negative, got {mu}"
        ))
    }
}

/// Sets a coarse simulation's Coulomb friction coefficient against bodies
/// ([`check_friction`]).
pub fn set_friction(sim: &mut Simulation, mu: f64) -> Result<()> {
    check_friction(mu).map_err(Error::Invalid)?;
    sim.sim.params.friction = mu;
    Ok(())
}
