//! The coarse model: the settings of the 20 mm simulation that the learned stages run beside
//! (membrane compression and its knee, friction, wrinkle bending, bending stiffness, crease
//! contacts), as a models folder's `coarse.json` and a corrector's training configuration
//! record them.

use crate::driver::Simulation;
use clothsr_geometry::error::{Error, Result};

/// The coarse model's settings, each optional (unset: the simulator's own). A models folder's
/// `coarse.json` holds the calibration its figures were measured with for runs without a
/// corrector, since the best coarse model differs from scene to scene; a corrector carries the
/// one it was trained beside. `{"compression": 0.03}` sets the membrane's compression factor
/// alone; likewise `compression_knee`, `friction`, `wrinkle_bending` (0: off), `bending` and
/// `crease_contacts`. On the command line the same settings are the `--coarse-*` options;
/// [`CoarseCalibration::apply`] sets a simulation up with them.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct CoarseCalibration {
    /// The coarse membrane's stiffness under compression, as a factor in (0, 1] of its stretch
    /// stiffness: below 1 the coarse mesh gives way to the shortening the fine cloth takes up
    /// in wrinkles.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compression: Option<f64>,
    /// The shortening (1 − stretch ratio, > 0) beyond which the compression-soft coarse
    /// membrane is stiff again, as the fine cloth's wrinkles pack tight (0: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compression_knee: Option<f64>,
    /// The coarse simulation's Coulomb friction coefficient against bodies, ≥ 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub friction: Option<f64>,
    /// The wrinkle bending gain: extra bending stiffness where the coarse membrane is
    /// shortened, up to this multiple of the fabric's, fading in as the cloth's mean speed
    /// falls from 6 cm/s to rest (0: off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wrinkle_bending: Option<f64>,
    /// The coarse hinges' bending stiffness as a factor of the fabric's, > 0 (1: the
    /// fabric's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bending: Option<f64>,
    /// Whether coarse cloth edges meet the colliders' sharp edges, `on` or `off`; off, a 20 mm
    /// edge may cut a table's corner as the downsampled fine cloth's do.
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
        Self::parse(&text, &path).map(Some)
    }

    /// The settings in `coarse.json` text (errors name `path`), checked.
    pub fn parse(text: &str, path: &std::path::Path) -> Result<CoarseCalibration> {
        let cal: CoarseCalibration = serde_json::from_str(text)
            .map_err(|e| Error::bad_input(path, format!("not a coarse calibration: {e}")))?;
        cal.check().map_err(|e| e.in_file(path))?;
        Ok(cal)
    }

    /// Why these settings are unusable, if they are, naming the setting as `coarse.json` does.
    pub fn check(&self) -> Result<()> {
        match self.problem() {
            Some((key, why)) => Err(Error::Invalid(format!("{key}{why}"))),
            None => Ok(()),
        }
    }

    /// Why these settings are unusable, if they are, naming the command-line option.
    pub fn check_flags(&self) -> Result<()> {
        match self.problem() {
            Some((key, why)) => Err(Error::Usage(format!(
                "--coarse-{}{why}",
                key.replace('_', "-")
            ))),
            None => Ok(()),
        }
    }

    /// The first unusable setting: its name and what is wrong.
    fn problem(&self) -> Option<(&'static str, String)> {
        if let Some(c) = self.compression.filter(|c| !(*c > 0.0 && *c <= 1.0)) {
            return Some(("compression", format!(" must be in (0, 1], got {c}")));
        }
        if let Some(k) = self
            .compression_knee
            .filter(|k| !(*k >= 0.0 && k.is_finite()))
        {
            return Some((
                "compression_knee",
                format!(" must be a shortening > 0 (0: none), got {k}"),
            ));
        }
        if let Some(Err(m)) = self.friction.map(check_friction) {
            return Some(("friction", format!(": {m}")));
        }
        if let Some(Err(m)) = self.wrinkle_bending.map(crate::WrinkleBending::gain_option) {
            return Some(("wrinkle_bending", format!(": {m}")));
        }
        if let Some(b) = self.bending.filter(|b| !(*b > 0.0 && b.is_finite())) {
            return Some(("bending", format!(" must be a factor > 0, got {b}")));
        }
        None
    }

    /// These settings where set, else `base`'s.
    pub fn or(&self, base: &CoarseCalibration) -> CoarseCalibration {
        CoarseCalibration {
            compression: self.compression.or(base.compression),
            compression_knee: self.compression_knee.or(base.compression_knee),
            friction: self.friction.or(base.friction),
            wrinkle_bending: self.wrinkle_bending.or(base.wrinkle_bending),
            bending: self.bending.or(base.bending),
            crease_contacts: self.crease_contacts.or(base.crease_contacts),
        }
    }

    /// The same model with each setting that is the simulator's own unset (a compression or a
    /// bending factor of 1, a knee or a wrinkle bending gain of 0, crease contacts on), as
    /// configurations record them; `None` where a setting is unusable.
    pub fn normalised(&self) -> Option<CoarseCalibration> {
        self.check().ok()?;
        Some(CoarseCalibration {
            compression: self.compression.filter(|&c| c != 1.0),
            compression_knee: self.compression_knee.filter(|&k| k != 0.0),
            friction: self.friction,
            wrinkle_bending: self.wrinkle_bending.filter(|&g| g != 0.0),
            bending: self.bending.filter(|&b| b != 1.0),
            crease_contacts: self.crease_contacts.filter(|&on| !on),
        })
    }

    /// The friction coefficient for reports: the number, or "the simulator's" when unset.
    pub fn friction_label(&self) -> String {
        self.friction
            .map_or_else(|| "the simulator's".to_string(), |mu| mu.to_string())
    }

    /// `base` with each setting given here in place of its own, normalised (a setting given as
    /// the simulator's own, such as a compression factor of 1, unsets it); `None` where a given
    /// setting is unusable.
    pub fn replacing(&self, base: &CoarseCalibration) -> Option<CoarseCalibration> {
        let n = self.normalised()?;
        fn pick<T>(given: &Option<T>, normalised: Option<T>, base: Option<T>) -> Option<T> {
            if given.is_some() {
                normalised
            } else {
                base
            }
        }
        Some(CoarseCalibration {
            compression: pick(&self.compression, n.compression, base.compression),
            compression_knee: pick(
                &self.compression_knee,
                n.compression_knee,
                base.compression_knee,
            ),
            friction: pick(&self.friction, n.friction, base.friction),
            wrinkle_bending: pick(
                &self.wrinkle_bending,
                n.wrinkle_bending,
                base.wrinkle_bending,
            ),
            bending: pick(&self.bending, n.bending, base.bending),
            crease_contacts: pick(
                &self.crease_contacts,
                n.crease_contacts,
                base.crease_contacts,
            ),
        })
    }

    /// Where the settings given here differ from the model a corrector was `trained` beside:
    /// how, completing "the corrector was trained …". Unset settings here agree with anything.
    pub fn conflict_with(&self, trained: &CoarseCalibration) -> Option<String> {
        let given = self.normalised().unwrap_or(*self);
        let trained_factor = trained.compression.unwrap_or(1.0);
        if let Some(f) = self.compression.filter(|&f| f != trained_factor) {
            return Some(format!(
                "beside a coarse membrane compression factor of {trained_factor}, not {f}"
            ));
        }
        if self.compression_knee.is_some() && trained.compression_knee != given.compression_knee {
            return Some(format!(
                "beside a coarse membrane compression knee of {:?}, not {:?}",
                trained.compression_knee, self.compression_knee
            ));
        }
        if self.friction.is_some() && trained.friction != self.friction {
            return Some(format!(
                "beside a coarse friction coefficient of {}, not {:?}",
                trained.friction_label(),
                self.friction
            ));
        }
        if self.wrinkle_bending.is_some()
            && trained.wrinkle_bending.filter(|&g| g != 0.0) != given.wrinkle_bending
        {
            return Some(format!(
                "beside a coarse wrinkle bending gain of {:?}, not {:?}",
                trained.wrinkle_bending, self.wrinkle_bending
            ));
        }
        let trained_bending = trained.bending.unwrap_or(1.0);
        if let Some(b) = self.bending.filter(|&b| b != trained_bending) {
            return Some(format!(
                "beside {trained_bending} times the fabric's bending stiffness, not {b} times it"
            ));
        }
        let trained_creases = trained.crease_contacts.unwrap_or(true);
        if let Some(on) = self.crease_contacts.filter(|&on| on != trained_creases) {
            return Some(format!(
                "with crease contacts {}, not {}",
                crease_label(Some(trained_creases)),
                crease_label(Some(on))
            ));
        }
        None
    }

    /// Sets a coarse simulation's model to this calibration (unset fields: the simulator's own
    /// model), but for an unset friction, which leaves the simulation's as it is (a fresh
    /// simulation's: the scene's).
    pub fn apply(&self, sim: &mut Simulation) -> Result<()> {
        self.check()?;
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
pub fn check_friction(mu: f64) -> Result<()> {
    if mu.is_finite() && mu >= 0.0 {
        Ok(())
    } else {
        Err(Error::Invalid(format!(
            "the friction coefficient must be finite and not negative, got {mu}"
        )))
    }
}

/// Sets a coarse simulation's Coulomb friction coefficient against bodies
/// ([`check_friction`]).
pub fn set_friction(sim: &mut Simulation, mu: f64) -> Result<()> {
    check_friction(mu)?;
    sim.sim.params.friction = mu;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cal(compression: Option<f64>, bending: Option<f64>) -> CoarseCalibration {
        CoarseCalibration {
            compression,
            bending,
            ..CoarseCalibration::default()
        }
    }

    #[test]
    fn problems_name_the_setting_as_the_file_or_the_option_does() {
        let bad = cal(Some(2.0), None);
        assert_eq!(
            bad.check().unwrap_err().to_string(),
            "compression must be in (0, 1], got 2"
        );
        assert_eq!(
            bad.check_flags().unwrap_err().to_string(),
            "--coarse-compression must be in (0, 1], got 2"
        );
        let knee = CoarseCalibration {
            compression_knee: Some(-1.0),
            ..CoarseCalibration::default()
        };
        assert!(knee
            .check_flags()
            .unwrap_err()
            .to_string()
            .starts_with("--coarse-compression-knee must be"));
        let gain = CoarseCalibration {
            wrinkle_bending: Some(-1.0),
            ..CoarseCalibration::default()
        };
        assert!(gain
            .check_flags()
            .unwrap_err()
            .to_string()
            .starts_with("--coarse-wrinkle-bending: the wrinkle bending gain"));
        assert!(cal(Some(0.5), Some(2.0)).check_flags().is_ok());
    }

    #[test]
    fn given_settings_replace_the_base_normalised() {
        let base = CoarseCalibration {
            compression: Some(0.1),
            friction: Some(2.5),
            crease_contacts: Some(false),
            ..CoarseCalibration::default()
        };
        // A factor of 1 given is the simulator's own: unset; what is not given stays.
        let given = CoarseCalibration {
            compression: Some(1.0),
            bending: Some(1.5),
            crease_contacts: Some(true),
            ..CoarseCalibration::default()
        };
        let got = given.replacing(&base).expect("usable");
        assert_eq!(
            got,
            CoarseCalibration {
                compression: None,
                friction: Some(2.5),
                bending: Some(1.5),
                crease_contacts: None,
                ..CoarseCalibration::default()
            }
        );
        assert_eq!(cal(Some(0.0), None).replacing(&base), None);
        // `or` keeps given values as they are.
        assert_eq!(given.or(&base).compression, Some(1.0));
        assert_eq!(given.or(&base).friction, Some(2.5));
    }

    #[test]
    fn only_given_settings_that_differ_from_the_trained_model_conflict() {
        let trained = CoarseCalibration {
            compression: Some(0.1),
            wrinkle_bending: Some(1.0),
            ..CoarseCalibration::default()
        };
        assert_eq!(CoarseCalibration::default().conflict_with(&trained), None);
        assert_eq!(cal(Some(0.1), Some(1.0)).conflict_with(&trained), None);
        let how = cal(Some(0.5), None)
            .conflict_with(&trained)
            .expect("differs");
        assert!(how.contains("compression factor of 0.1, not 0.5"), "{how}");
        let how = cal(None, Some(2.0))
            .conflict_with(&trained)
            .expect("differs");
        assert!(how.contains("bending stiffness"), "{how}");
        let off = CoarseCalibration {
            wrinkle_bending: Some(0.0),
            ..CoarseCalibration::default()
        };
        assert!(off
            .conflict_with(&trained)
            .expect("differs")
            .contains("wrinkle"));
        let creases = CoarseCalibration {
            crease_contacts: Some(false),
            ..CoarseCalibration::default()
        };
        assert_eq!(
            creases.conflict_with(&trained).as_deref(),
            Some("with crease contacts on, not off")
        );
    }
}
