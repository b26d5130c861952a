//! A models folder's files that are not networks: its manifest `models.json`
//! ([`ModelsManifest`]: the held-out figures each path through the folder was validated with,
//! and which was better) and the choice of path a run makes. The networks (`isr/`,
//! `corrector/`) are read by `clothsr-nn`; `coarse.json` by `clothsr-sim`.

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use clothsr_geometry::error::{Error, Result};

/// Whether a run uses the models folder's corrector: `auto`, `on` or `off`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum CorrectorChoice {
    /// The path the folder's manifest validated as better; the corrector where a folder
    /// without a manifest has one.
    #[default]
    Auto,
    /// The corrector, which the folder must have.
    On,
    /// The coarse model alone.
    Off,
}

impl FromStr for CorrectorChoice {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.trim() {
            "auto" => Ok(Self::Auto),
            "on" => Ok(Self::On),
            "off" => Ok(Self::Off),
            t => Err(format!("{t}: 'auto', 'on' or 'off'")),
        }
    }
}

/// A path through a models folder; in `models.json`, `corrector` or `coarse_alone`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ModelPath {
    /// The corrector interleaved with the coarse simulation (the paper's Fig. 2).
    Corrector,
    /// The coarse model alone (the folder's `coarse.json`, else the simulator's own).
    CoarseAlone,
}

impl ModelPath {
    /// Its key in [`ModelsManifest::paths`].
    pub fn key(self) -> &'static str {
        match self {
            Self::Corrector => "corrector",
            Self::CoarseAlone => "coarse_alone",
        }
    }
}

impl fmt::Display for ModelPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Corrector => "the corrector interleaved with the coarse simulation",
            Self::CoarseAlone => "the coarse model alone",
        })
    }
}

/// The held-out figures of one path through a folder.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PathFigures {
    /// The whole pipeline's fine output against the fine simulation, mean over frames and
    /// starts, mm.
    pub fine_error_mm: f64,
    /// The upsampled coarse simulation of the simulator's own model on the same protocol, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub baseline_mm: Option<f64>,
}

/// A models folder's manifest, `models.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelsManifest {
    /// [`ModelsManifest::FORMAT_VERSION`].
    pub format_version: u32,
    /// The scene the models were made for.
    pub scene: String,
    /// The held-out data the figures were measured on.
    pub held_out: String,
    /// What was measured, and with which command.
    pub protocol: String,
    /// Figures per path.
    pub paths: BTreeMap<ModelPath, PathFigures>,
    /// The better path.
    pub best: ModelPath,
}

impl ModelsManifest {
    /// Its file name in a models folder.
    pub const FILE: &'static str = "models.json";
    /// The format this build reads and writes.
    pub const FORMAT_VERSION: u32 = 1;

    /// The manifest of the folder `models`, checked; `None` where it has none.
    pub fn load(models: &Path) -> Result<Option<ModelsManifest>> {
        let path = models.join(Self::FILE);
        if !path.exists() {
            return Ok(None);
        }
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        Self::parse(&text, &path, has_corrector(models)).map(Some)
    }

    /// The manifest in `models.json` text (errors name `path`), checked against a folder that
    /// has a corrector or not.
    pub fn parse(text: &str, path: &Path, corrector: bool) -> Result<ModelsManifest> {
        let not =
            |e: serde_json::Error| Error::bad_input(path, format!("not a models manifest: {e}"));
        // The version first: another version's fields may not parse as this one's.
        let value: serde_json::Value = serde_json::from_str(text).map_err(not)?;
        let version = value
            .get("format_version")
            .and_then(serde_json::Value::as_u64);
        if version != Some(u64::from(Self::FORMAT_VERSION)) {
            return Err(Error::bad_input(
                path,
                format!(
                    "format_version {} (this build reads {})",
                    version.map_or("missing".to_string(), |v| v.to_string()),
                    Self::FORMAT_VERSION
                ),
            ));
        }
        let m: ModelsManifest = serde_json::from_value(value).map_err(not)?;
        m.check(corrector).map_err(|e| e.in_file(path))?;
        Ok(m)
    }

    /// Why this manifest does not describe a folder that has a corrector (`corrector`) or
    /// not, if it does not.
    fn check(&self, corrector: bool) -> Result<()> {
        for (&path, f) in &self.paths {
            let key = path.key();
            let ok = |x: f64| x.is_finite() && x >= 0.0;
            if !ok(f.fine_error_mm) || f.baseline_mm.is_some_and(|b| !ok(b)) {
                return Err(Error::Invalid(format!(
                    "paths.{key}: figures must be finite and ≥ 0"
                )));
            }
            if path == ModelPath::Corrector && !corrector {
                return Err(Error::Invalid(
                    "paths.corrector: the folder has no corrector/".into(),
                ));
            }
        }
        if !self.paths.contains_key(&self.best) {
            return Err(Error::Invalid(format!(
                "best: '{}' is not one of its paths",
                self.best.key()
            )));
        }
        Ok(())
    }
}

/// Whether the folder `models` has a corrector.
pub fn has_corrector(models: &Path) -> bool {
    models.join("corrector").join("config.json").exists()
}
