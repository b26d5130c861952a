//! The generic models (`models/generic`, the default of `run`) on what they never saw: a
//! held-out shot (an unseen garment on an unseen fabric), and a garment mesh without texture
//! coordinates.

use std::path::{Path, PathBuf};
use std::process::Command;

use clothsr::io::usd::{read_usd, MeshRole};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The binary, with the generic models found the default way (no `$CLOTHSR_MODELS`).
fn clothsr() -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_clothsr"));
    cmd.env_remove("CLOTHSR_MODELS");
    cmd
}

/// Runs `run` with no `--models` and checks the output: made with the generic models, every
/// frame of every fine garment finite, `frames` + 1 time samples.
fn run_generic(scene: &Path, extra: &[&str], frames: usize) -> Vec<usize> {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("fine.usda");
    let res = clothsr()
        .arg("run")
        .arg(scene)
        .args(extra)
        .args(["--frames", &frames.to_string(), "-o"])
        .arg(&out)
        .output()
        .expect("run");
    assert!(
        res.status.success(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
    let text = std::fs::read_to_string(&out).expect("output");
    let generic = root().join("models/generic");
    assert!(
        text.contains(&format!("with models {}", generic.display())),
        "the output was not made with the generic models"
    );
    let stage = read_usd(&out).expect("read the output");
    let cloth: Vec<_> = stage
        .meshes
        .iter()
        .filter(|m| m.role == MeshRole::Cloth)
        .collect();
    assert!(!cloth.is_empty(), "no fine garment in the output");
    for m in &cloth {
        assert_eq!(m.frames.len(), frames + 1, "{}", m.path);
        assert!(
            m.frames
                .iter()
                .flatten()
                .all(|p| p.iter().all(|c| c.is_finite())),
            "{}: non-finite points",
            m.path
        );
    }
    cloth.iter().map(|m| m.frames[0].len()).collect()
}

/// A held-out shot of `clothsr lab scenes` (the disc, a garment and a fabric no generic model
/// was trained on), run with no `--models`: lifted to the fine resolution.
#[test]
fn run_without_models_lifts_an_unseen_garment_with_the_generic_models() {
    let dir = tempfile::tempdir().expect("tmp");
    let res = clothsr()
        .args(["lab", "scenes", "--set", "held-out", "--frames", "2", "-o"])
        .arg(dir.path())
        .output()
        .expect("scenes");
    assert!(res.status.success());
    let disc: PathBuf = String::from_utf8_lossy(&res.stdout)
        .lines()
        .map(PathBuf::from)
        .find(|p| p.to_string_lossy().contains("disc-"))
        .expect("the held-out disc shot");
    let fine = run_generic(&disc, &[], 2);
    // The disc of radius 0.27 m at 2.5 mm: about 36K vertices (20 mm: about 700).
    assert!(fine[0] > 20_000, "{} fine vertices", fine[0]);
}

/// A garment mesh modelled in 3D, as OBJ with no texture coordinates: a sheet bent over a
/// cylinder, 20 mm quads. `run` flattens it, remeshes its chart at 20 mm and 2.5 mm like a
/// pattern panel, and runs on it with the generic models.
#[test]
fn run_without_models_works_on_an_obj_garment_without_uvs() {
    let dir = tempfile::tempdir().expect("tmp");
    let obj = dir.path().join("bent_sheet.obj");
    let (nu, nv) = (16, 16);
    let mut text = String::new();
    for j in 0..=nv {
        for i in 0..=nu {
            // A 0.32 m × 0.32 m sheet bent over a cylinder of radius 0.25 m, 0.4 m up.
            let angle = (i as f64 / nu as f64 - 0.5) * 0.32 / 0.25;
            let (x, y) = (0.25 * angle.sin(), 0.4 + 0.25 * angle.cos() - 0.25);
            let z = (j as f64 / nv as f64 - 0.5) * 0.32;
            text.push_str(&format!("v {x:.5} {y:.5} {z:.5}\n"));
        }
    }
    let v = |i: usize, j: usize| j * (nu + 1) + i + 1;
    for j in 0..nv {
        for i in 0..nu {
            text.push_str(&format!(
                "f {} {} {}\n",
                v(i, j),
                v(i + 1, j),
                v(i + 1, j + 1)
            ));
            text.push_str(&format!(
                "f {} {} {}\n",
                v(i, j),
                v(i + 1, j + 1),
                v(i, j + 1)
            ));
        }
    }
    std::fs::write(&obj, text).expect("write obj");
    let fine = run_generic(&obj, &["--fabric", "silk"], 2);
    // 0.1 m² at 2.5 mm: about 16K vertices (the OBJ has 289).
    assert!(
        (12_000..20_000).contains(&fine[0]),
        "{} fine vertices",
        fine[0]
    );
}
