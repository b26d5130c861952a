//! A models folder and the path `clothsr run` takes through it.
//!
//! A folder holds the ISR network (`isr/`), optionally a corrector (`corrector/`) and a coarse
//! model (`coarse.json`, used when no corrector runs), and its manifest `models.json`
//! ([`ModelsManifest`], read in `clothsr-io`): the held-out figures each path through the
//! folder was validated with (the corrector interleaved with the coarse simulation, or the
//! coarse model alone) and which of them was better. By default ([`CorrectorChoice::Auto`]) a
//! run takes the better one. Where the generic models are is found here too.

use std::path::{Path, PathBuf};

pub use crate::io::models::{
    has_corrector, CorrectorChoice, ModelPath, ModelsManifest, PathFigures,
};

use crate::error::{Error, Result};

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
pub fn find_generic_models() -> Result<PathBuf> {
    let candidates = generic_models_candidates();
    candidates
        .iter()
        .find(|d| d.join("isr").join("config.json").is_file())
        .cloned()
        .ok_or_else(|| {
            let looked: Vec<String> = candidates.iter().map(|d| d.display().to_string()).collect();
            Error::Usage(format!(
                "no --models given and no generic models found (looked in {}); pass --models DIR \
                 or set {MODELS_ENV}",
                looked.join(", ")
            ))
        })
}

/// The path a run takes through the folder `models`, and why, in words.
pub fn choose_path(models: &Path, choice: CorrectorChoice) -> Result<(ModelPath, String)> {
    let manifest = ModelsManifest::load(models)?;
    let corrector = has_corrector(models);
    let figures = |p: ModelPath| -> String {
        match manifest.as_ref().and_then(|m| m.paths.get(&p)) {
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
                let best = m.best;
                let other = match best {
                    ModelPath::Corrector => ModelPath::CoarseAlone,
                    ModelPath::CoarseAlone => ModelPath::Corrector,
                };
                let against = m
                    .paths
                    .get(&other)
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
