//! Pictures of USD outputs: the repository's headless renderer (`tools/render.py`: Blender as a
//! Python module, Cycles on the CPU) run in the Python that has Blender's `bpy`
//! (`CLOTHSR_BPY_PYTHON`, else the repository's `.venv-bpy`, which `bash .ci/setup` makes).

use std::path::{Path, PathBuf};
use std::process::Command;

use clothsr_geometry::error::{Error, Result};

use crate::python::repo_root;

/// Where the camera looks from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum View {
    /// The avatar's front.
    Front,
    /// 35° round from the front.
    ThreeQuarter,
    /// The side.
    Side,
    /// The back.
    Back,
}

impl View {
    /// The renderer's name for it (also in its images' names).
    pub fn name(self) -> &'static str {
        match self {
            View::Front => "front",
            View::ThreeQuarter => "three-quarter",
            View::Side => "side",
            View::Back => "back",
        }
    }
}

/// How [`side_by_side`] renders.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderSettings {
    /// Camera.
    pub view: View,
    /// Image size of each input's panel, pixels.
    pub size: (u32, u32),
    /// Cycles samples per pixel (denoised).
    pub samples: u32,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            view: View::ThreeQuarter,
            size: (320, 400),
            samples: 16,
        }
    }
}

/// The Python with Blender's `bpy` and the renderer script, or why they are not there.
pub fn renderer() -> std::result::Result<(PathBuf, PathBuf), String> {
    let root = repo_root();
    // The reasons name no path: a fit's report, which is committed, quotes them.
    let python = std::env::var_os("CLOTHSR_BPY_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join(".venv-bpy/bin/python"));
    let script = root.join("tools/render.py");
    if !python.is_file() {
        tracing::debug!("no Python with bpy at {}", python.display());
        return Err(
            "no Python with Blender's bpy: set CLOTHSR_BPY_PYTHON, or run `bash \
                    .ci/setup` in the clothsr repository for its .venv-bpy"
                .into(),
        );
    }
    if !script.is_file() {
        tracing::debug!("no renderer at {}", script.display());
        return Err(
            "no renderer (tools/render.py): set CLOTHSR_ROOT to the clothsr repository".into(),
        );
    }
    Ok((python, script))
}

/// Renders the USD files `inputs` (`(label, file)`, each with its garments and colliders) side
/// by side at each of `frames` (time codes), through one camera, into `out_dir` as
/// `{name}_f{frame}.png`; returns the images' paths. The single images stay in a temporary
/// folder; the pictures are published only when all were made, each whole (written beside,
/// then renamed).
pub fn side_by_side(
    inputs: &[(&str, &Path)],
    frames: &[i64],
    settings: &RenderSettings,
    out_dir: &Path,
    name: &str,
) -> Result<Vec<PathBuf>> {
    let (python, script) = renderer().map_err(Error::Invalid)?;
    if inputs.len() < 2 || frames.is_empty() {
        return Err(Error::Invalid(format!(
            "side by side needs two inputs or more and a frame ({} inputs, {} frames)",
            inputs.len(),
            frames.len()
        )));
    }
    if let Some((label, _)) = inputs.iter().find(|(l, _)| l.contains(',')) {
        return Err(Error::Invalid(format!(
            "label '{label}': the renderer takes labels without commas"
        )));
    }
    let tmp = tempfile::tempdir().map_err(|e| Error::io(out_dir, e))?;
    // The renderer names a side-by-side image after its inputs' file stems: they are linked
    // (or copied) under known names.
    let mut named = Vec::new();
    for (k, (_, file)) in inputs.iter().enumerate() {
        let ext = file.extension().and_then(|e| e.to_str()).unwrap_or("usdc");
        let link = tmp.path().join(format!("in{k}.{ext}"));
        if std::fs::hard_link(file, &link).is_err() {
            std::fs::copy(file, &link).map_err(|e| Error::io(file, e))?;
        }
        named.push(link);
    }
    let labels: Vec<&str> = inputs.iter().map(|(l, _)| *l).collect();
    let frame_list: Vec<String> = frames.iter().map(i64::to_string).collect();
    let out = Command::new(&python)
        .arg(&script)
        .args(&named)
        .args(["--side-by-side", "--labels", &labels.join(",")])
        .args(["--frames", &frame_list.join(",")])
        .args(["--view", settings.view.name()])
        .args([
            "--size",
            &format!("{}x{}", settings.size.0, settings.size.1),
        ])
        .args(["--samples", &settings.samples.to_string(), "--fit", "all"])
        .arg("-o")
        .arg(tmp.path())
        .output()
        .map_err(|e| Error::io(&python, e))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let tail: Vec<&str> = err.lines().rev().take(6).collect();
        return Err(Error::Invalid(format!(
            "the renderer ({}) failed: {}",
            script.display(),
            tail.into_iter().rev().collect::<Vec<_>>().join(" / ")
        )));
    }
    let joined = (0..inputs.len())
        .map(|k| format!("in{k}"))
        .collect::<Vec<_>>()
        .join("_vs_");
    let mut made = Vec::new();
    for f in frames {
        let image = tmp
            .path()
            .join(format!("{joined}_f{f}_{}.png", settings.view.name()));
        made.push((
            out_dir.join(format!("{name}_f{f}.png")),
            std::fs::read(&image).map_err(|e| Error::io(&image, e))?,
        ));
    }
    let mut written = Vec::new();
    for (dest, bytes) in made {
        crate::write_atomic(&dest, &bytes)?;
        written.push(dest);
    }
    Ok(written)
}
