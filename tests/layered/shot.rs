//! A studio-style shot for the layered-output tests (`tests/layered.rs`, `tests/dcc.rs`): z up,
//! centimetres, the walking avatar and a circle skirt meshed at 20 mm, referenced under one
//! transform (`make_shot.py`), and a run of it written as an override layer.

use std::path::{Path, PathBuf};
use std::process::Command;

pub fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The project venv's Python (usd-core), with the bridge importable.
pub fn python() -> Command {
    let mut c = Command::new(clothsr::io::python::venv_dir().join("bin/python"));
    c.env("PYTHONPATH", root().join("bridge"));
    c
}

fn ok(what: &str, out: std::process::Output) -> String {
    assert!(
        out.status.success(),
        "{what}: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Writes the shot in `dir`; returns its path.
pub fn make(dir: &Path) -> PathBuf {
    let mesh = dir.join("skirt_mesh.usdc");
    ok(
        "clothsr mesh",
        Command::new(env!("CARGO_BIN_EXE_clothsr"))
            .arg("mesh")
            .arg(
                root()
                    .join("tests/data/patterns/mh_skirt_circle/mh_skirt_circle_specification.json"),
            )
            .args(["--edge-mm", "20", "-o"])
            .arg(&mesh)
            .output()
            .expect("clothsr mesh"),
    );
    let shot = dir.join("shot.usda");
    ok(
        "make_shot.py",
        python()
            .arg(root().join("tests/layered/make_shot.py"))
            .arg(&shot)
            .arg(&mesh)
            .arg(root().join("tests/data/avatars/mh_walk_train.usda"))
            .output()
            .expect("python"),
    );
    shot
}

/// Runs `frames` frames of `shot` into `out` with `extra` arguments.
pub fn run(shot: &Path, out: &Path, frames: usize, extra: &[&str]) {
    ok(
        "clothsr run",
        Command::new(env!("CARGO_BIN_EXE_clothsr"))
            .arg("run")
            .arg(shot)
            .args(["--frames", &frames.to_string(), "-o"])
            .arg(out)
            .args(extra)
            .output()
            .expect("clothsr run"),
    );
}

/// Runs `check_layered.py` on the shot and its layer; returns its report.
#[allow(dead_code)]
pub fn check(shot: &Path, layer: &Path, frames: usize) -> String {
    ok(
        "check_layered.py",
        python()
            .arg(root().join("tests/layered/check_layered.py"))
            .arg(shot)
            .arg(layer)
            .arg(frames.to_string())
            .output()
            .expect("python"),
    )
}
