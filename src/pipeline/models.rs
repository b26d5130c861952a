//! A models folder and the path `clothsr run` takes through it.
//!
//! A folder holds the ISR network (`isr/`), optionally a corrector (`corrector/`) and a coarse
//! model (`coarse.json`, used when no corrector runs), and its manifest `models.json`
//! ([`ModelsManifest`]): the held-out figures each path through the folder was validated with
//! (the corrector interleaved with the coarse simulation, or the coarse model alone) and which
//! of them was better. By default ([`CorrectorChoice::Auto`]) a run takes the better one.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Whether a run uses the models folder's corrector.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
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

/// A path through a models folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
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

    fn from_key(key: &str) -> Option<Self> {
        [Self::Corrector, Self::CoarseAlone]
            .into_iter()
            .find(|p| p.key() == key)
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
    /// Figures per path, by [`ModelPath::key`].
    pub paths: BTreeMap<String, PathFigures>,
    /// The key of the better path.
    pub best: String,
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
        let m: ModelsManifest = serde_json::from_str(&text)
            .map_err(|e| Error::bad_input(&path, format!("not a models manifest: {e}")))?;
        m.check(models)
            .map_err(|msg| Error::bad_input(&path, msg))?;
        Ok(Some(m))
    }

    /// Why this manifest does not describe the folder `models`, if it does not.
    fn check(&self, models: &Path) -> std::result::Result<(), String> {
        if self.format_version != Self::FORMAT_VERSION {
            return Err(format!(
                "format_version {} (this build reads {})",
                self.format_version,
                Self::FORMAT_VERSION
            ));
        }
        for (key, f) in &self.paths {
            let path = ModelPath::from_key(key).ok_or_else(|| {
                format!("paths.{key}: unknown path (known: corrector, coarse_alone)")
            })?;
            let ok = |x: f64| x.is_finite() && x >= 0.0;
            if !ok(f.fine_error_mm) || f.baseline_mm.is_some_and(|b| !ok(b)) {
                return Err(format!("paths.{key}: figures must be finite and ≥ 0"));
            }
            if path == ModelPath::Corrector && !has_corrector(models) {
                return Err("paths.corrector: the folder has no corrector/".into());
            }
        }
        if !self.paths.contains_key(&self.best) {
            return Err(format!("best: '{}' is not one of its paths", self.best));
        }
        Ok(())
    }

    /// The path it validated as better.
    pub fn best(&self) -> ModelPath {
        ModelPath::from_key(&self.best).unwrap_or(ModelPath::CoarseAlone)
    }
}

/// Environment variable naming the generic models folder.
pub const MODELS_ENV: &str = "CLOTHSR_MODELS";

/// Where the generic models may be, in order: `$CLOTHSR_MODELS`; `models/generic` beside the
/// executable, or in `../share/clothsr/` from it (an installed tree); the source tree the
/// program was built from.
pub fn generic_models_candidates() -> Vec<PathBuf> {
    let mut out = Vec::new();
    if let Some(dir) = std::env::var_os(MODELS_ENV) {
        out.push(PathBuf::from(dir));
    }
    if let Some(exe_dir) = std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().map(Path::to_path_buf))
    {
        out.push(exe_dir.join("models/generic"));
        out.push(exe_dir.join("../share/clothsr/models/generic"));
    }
    out.push(Path::new(env!("CARGO_MANIFEST_DIR")).join("models/generic"));
    out
}

/// The first of [`generic_models_candidates`] that holds an ISR model; otherwise an error
/// listing where it looked.
pub fn find_generic_models() -> std::result::Result<PathBuf, String> {
    let candidates = generic_models_candidates();
    candidates
        .iter()
        .find(|d| d.join("isr").join("config.json").is_file())
        .cloned()
        .ok_or_else(|| {
            let looked: Vec<String> = candidates.iter().map(|d| d.display().to_string()).collect();
            format!(
                "no --models given and no generic models found (looked in {}); pass --models DIR \
                 or set {MODELS_ENV}",
                looked.join(", ")
            )
        })
}

/// Whether the folder `models` has a corrector.
pub fn has_corrector(models: &Path) -> bool {
    models.join("corrector").join("config.json").exists()
}

/// The path a run takes through the folder `models`, and why, in words.
pub fn choose_path(models: &Path, choice: CorrectorChoice) -> Result<(ModelPath, String)> {
    let manifest = ModelsManifest::load(models)?;
    let corrector = has_corrector(models);
    let figures = |p: ModelPath| -> String {
        match manifest.as_ref().and_then(|m| m.paths.get(p.key())) {
            Some(f) => format!(
                "; validated at {:.2} mm from the fine simulation on {}",
                f.fine_error_mm,
                manifest.as_ref().map_or("", |m| m.held_out.as_str())
            ),
            None => String::new(),
        }
    };
    Ok(match (choice, corrector) {
        (CorrectorChoice::Off, _) => (
            ModelPath::CoarseAlone,
            format!("--corrector off{}", figures(ModelPath::CoarseAlone)),
        ),
        (CorrectorChoice::On, false) => {
            return Err(Error::bad_input(
                models,
                "--corrector on, but the folder has no corrector (corrector/config.json)",
            ))
        }
        (CorrectorChoice::Auto, false) => (
            ModelPath::CoarseAlone,
            format!(
                "the folder has no corrector{}",
                figures(ModelPath::CoarseAlone)
            ),
        ),
        (CorrectorChoice::On, true) => (
            ModelPath::Corrector,
            format!("--corrector on{}", figures(ModelPath::Corrector)),
        ),
        (CorrectorChoice::Auto, true) => match &manifest {
            None => (
                ModelPath::Corrector,
                format!("the folder has a corrector and no {}", ModelsManifest::FILE),
            ),
            Some(m) => {
                let best = m.best();
                let other = match best {
                    ModelPath::Corrector => ModelPath::CoarseAlone,
                    ModelPath::CoarseAlone => ModelPath::Corrector,
                };
                let against = m
                    .paths
                    .get(other.key())
                    .map(|f| format!(", against {:.2} mm for {other}", f.fine_error_mm))
                    .unwrap_or_default();
                (
                    best,
                    format!("the better validated path{}{against}", figures(best)),
                )
            }
        },
    })
}
