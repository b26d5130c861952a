//! clothsr's USD output read in a real DCC: Blender (PyPI `bpy`, Blender as a Python module)
//! imports it, steps to each frame, and its evaluated meshes match what pxr reads.
//!
//! Blender runs in its own Python (`.venv-bpy`, made by `.ci/setup`; or `$CLOTHSR_BPY_PYTHON`):
//! it carries its own USD libraries, which must not meet usd-core's in one process. Where that
//! Python is missing, or `bpy` could not load on this machine (`.ci/setup` writes why to
//! `.venv-bpy/UNAVAILABLE`), the test says so and skips; `CLOTHSR_REQUIRE_BPY=1` makes that a
//! failure.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use clothsr::io::usd::{read_usd, UsdMesh};
use serde::Deserialize;

#[path = "layered/shot.rs"]
mod shot;

/// The largest distance allowed between Blender's and pxr's points, m (1e-3 mm).
const TOLERANCE_M: f64 = 1e-6;

#[derive(Deserialize)]
struct BlenderMeshes {
    blender: String,
    /// Object name -> frame -> points (y up, metres).
    meshes: BTreeMap<String, BTreeMap<String, Vec<[f64; 3]>>>,
}

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The Python with `bpy`, or why there is none.
fn blender_python() -> Result<PathBuf, String> {
    if let Some(p) = std::env::var_os("CLOTHSR_BPY_PYTHON") {
        return Ok(PathBuf::from(p));
    }
    let venv = root().join(".venv-bpy");
    if let Ok(why) = std::fs::read_to_string(venv.join("UNAVAILABLE")) {
        return Err(format!("bpy does not load on this machine: {}", why.trim()));
    }
    let python = venv.join("bin/python");
    if python.exists() {
        Ok(python)
    } else {
        Err(format!(
            "no {} (run `bash .ci/setup`, or set CLOTHSR_BPY_PYTHON)",
            python.display()
        ))
    }
}

/// The Python with `bpy`, or `None` after saying why the test skips.
fn blender_or_skip() -> Option<PathBuf> {
    match blender_python() {
        Ok(p) => Some(p),
        Err(why) => {
            assert!(
                std::env::var_os("CLOTHSR_REQUIRE_BPY").is_none(),
                "CLOTHSR_REQUIRE_BPY is set but {why}"
            );
            eprintln!("skipped: {why}");
            None
        }
    }
}

/// Imports `file` into Blender and reads every mesh object's evaluated points at `times`.
fn blender_read(python: &Path, file: &Path, times: &[String], dir: &Path) -> BlenderMeshes {
    let json = dir.join("blender.json");
    let res = Command::new(python)
        .arg(root().join("tests/dcc/blender_read.py"))
        .arg(file)
        .arg(&json)
        .args(times)
        .current_dir(dir)
        .output()
        .expect("start Blender's Python");
    assert!(
        res.status.success(),
        "Blender failed: {}",
        String::from_utf8_lossy(&res.stderr)
    );
    let got: BlenderMeshes =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json")).expect("parse");
    eprintln!("Blender {}", got.blender);
    got
}

/// Compares pxr's mesh `m` with Blender's object of its name at `times`; returns the frames
/// compared.
fn compare(m: &UsdMesh, got: &BlenderMeshes, times: &[String]) -> usize {
    let b = got
        .meshes
        .get(&m.name)
        .unwrap_or_else(|| panic!("Blender has no object {} ({:?})", m.name, got.meshes.keys()));
    let mut compared = 0;
    for (k, frame) in m.frames.iter().enumerate() {
        // A static mesh has one frame in pxr: compare it at every time.
        let ts: Vec<&String> = if m.frames.len() == 1 {
            times.iter().collect()
        } else {
            vec![&times[k]]
        };
        for t in ts {
            let pts = &b[t];
            assert_eq!(pts.len(), frame.len(), "{} at {t}: vertex count", m.name);
            let worst = pts
                .iter()
                .zip(frame)
                .map(|(p, q)| {
                    (0..3)
                        .map(|c| (p[c] - f64::from(q[c])).abs())
                        .fold(0.0f64, f64::max)
                })
                .fold(0.0f64, f64::max);
            assert!(
                worst <= TOLERANCE_M,
                "{} at {t}: Blender's points are {worst:e} m from pxr's",
                m.name
            );
            compared += 1;
        }
    }
    compared
}

fn time_strings(m: &UsdMesh) -> Vec<String> {
    m.time_codes
        .iter()
        .map(|t| format!("{}", t.round() as i64))
        .collect()
}

#[test]
#[ignore = "heavy: starts Blender (run by .ci/run)"]
fn blender_reads_the_fine_output_as_pxr_does() {
    let Some(python) = blender_or_skip() else {
        return;
    };
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("table.usdc");
    let frames = 3;
    let run = Command::new(env!("CARGO_BIN_EXE_clothsr"))
        .arg("run")
        .arg(root().join("samples/sheet_table.usda"))
        .arg("--models")
        .arg(root().join("samples/models/table"))
        .args(["--layer", "off", "--frames", &frames.to_string(), "-o"])
        .arg(&out)
        .output()
        .expect("run");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let stage = read_usd(&out).expect("pxr reads the output");
    let cloth = stage
        .meshes
        .iter()
        .find(|m| m.frames.len() == frames + 1)
        .expect("an animated fine garment");
    let times = time_strings(cloth);
    let got = blender_read(&python, &out, &times, dir.path());
    let compared: usize = stage.meshes.iter().map(|m| compare(m, &got, &times)).sum();
    assert!(compared > frames, "compared {compared} frames");
}

/// The layered output composed over a z-up, centimetre shot, as the run writes it: Blender
/// places the fine skirt where pxr does (Blender's own unit and axis conversion included).
#[test]
#[ignore = "heavy: dresses a skirt on the walking avatar and starts Blender (run by .ci/run)"]
fn blender_reads_the_layered_shot_as_pxr_does() {
    let Some(python) = blender_or_skip() else {
        return;
    };
    let dir = tempfile::tempdir().expect("tmp");
    let shot_file = shot::make(dir.path());
    let layer = dir.path().join("cloth.usda");
    let frames = 2;
    shot::run(&shot_file, &layer, frames, &[]);
    // The composed shot the run writes beside its layer, as a TD opens it.
    let composed = clothsr::io::usd::composed_path(&layer);
    let stage = read_usd(&composed).expect("pxr reads the composed shot");
    let skirt = stage
        .meshes
        .iter()
        .find(|m| m.path == "/Shot/Skirt")
        .expect("the skirt at its own path");
    assert_eq!(skirt.frames.len(), frames + 1);
    let times = time_strings(skirt);
    let got = blender_read(&python, &composed, &times, dir.path());
    assert_eq!(compare(skirt, &got, &times), frames + 1);
}
