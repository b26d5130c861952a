//! Faults: a run killed with SIGKILL at random points resumes to the output an uninterrupted run
//! writes, bit for bit; a full disk (RLIMIT_FSIZE) during a write is a clear error that leaves
//! the previous output intact.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// `lab run` of the sphere sample for `frames` frames into `out`, publishing every frame.
fn run_command(out: &Path, frames: usize) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_clothsr"));
    c.args(["lab", "run"])
        .arg(root().join("samples/sheet_sphere.usda"))
        .args([
            "--layer",
            "off",
            "--publish-every-s",
            "0",
            "--frames",
            &frames.to_string(),
            "-o",
        ])
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    c
}

/// The fine points of every frame of a run's output, as pxr reads them.
fn frames(path: &Path) -> Vec<Vec<nalgebra::Vector3<f32>>> {
    let stage = clothsr::io::usd::read_usd(path).expect("read the output");
    let cloth = stage
        .meshes
        .iter()
        .find(|m| m.role == clothsr::io::usd::MeshRole::Cloth)
        .expect("the fine garment");
    cloth.frames.clone()
}

#[test]
#[ignore = "heavy: ten killed runs (run by .ci/run)"]
fn a_run_killed_ten_times_resumes_to_the_uninterrupted_output() {
    let dir = tempfile::tempdir().expect("tmp");
    let frames_n = 30;
    let straight: PathBuf = dir.path().join("straight.usdc");
    let t0 = Instant::now();
    assert!(run_command(&straight, frames_n)
        .status()
        .expect("run")
        .success());
    let full = t0.elapsed();
    let killed = dir.path().join("killed.usdc");
    let expected = frames(&straight);
    // Ten kills at points spread over a run (a fixed pseudo-random sequence). A run that ends
    // before its kill closes a chain of killed and resumed runs: its output must be the
    // uninterrupted one, bit for bit.
    let mut seed = 0x2545_f491_u64;
    let (mut kills, mut resumed_kills, mut chains) = (0, 0, 0);
    while kills < 10 {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        let at = full.mul_f64(0.2 + 0.5 * (seed % 1000) as f64 / 1000.0);
        let resuming = killed.exists();
        let mut child = run_command(&killed, frames_n).spawn().expect("spawn");
        std::thread::sleep(at);
        if let Some(status) = child.try_wait().expect("wait") {
            assert!(status.success(), "a resumed run failed");
            assert_eq!(
                frames(&killed),
                expected,
                "chain {chains}: resumed output differs"
            );
            std::fs::remove_file(&killed).expect("start a new chain");
            chains += 1;
            continue;
        }
        child.kill().expect("SIGKILL");
        child.wait().expect("reap");
        kills += 1;
        resumed_kills += usize::from(resuming);
    }
    let status = run_command(&killed, frames_n).status().expect("finish");
    assert!(status.success());
    assert_eq!(
        frames(&killed),
        expected,
        "the last chain's resumed output differs"
    );
    chains += 1;
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .expect("dir")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains("clothsr-") || n.ends_with(".resume"))
        .collect();
    assert!(leftovers.is_empty(), "left behind: {leftovers:?}");
    eprintln!(
        "10 kills in {chains} chains, each resumed bit-identical; {resumed_kills} kills hit a \
         resumed run"
    );
    assert!(
        resumed_kills >= 3,
        "too few kills hit a resumed run: {resumed_kills}"
    );
}

#[test]
fn a_full_disk_is_a_clear_error_and_keeps_the_previous_output() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("out.usdc");
    assert!(run_command(&out, 1).status().expect("run").success());
    let before = std::fs::read(&out).expect("the first output");
    // Files may not grow past 64 KB: the next write fails with EFBIG (SIGXFSZ ignored).
    let res = Command::new("bash")
        .arg("-c")
        .arg("trap '' XFSZ; ulimit -f 64; exec \"$@\"")
        .arg("bash")
        .arg(env!("CARGO_BIN_EXE_clothsr"))
        .args(["lab", "run"])
        .arg(root().join("samples/sheet_sphere.usda"))
        .args(["--layer", "off", "--frames", "2", "--restart", "-o"])
        .arg(&out)
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&res.stderr);
    assert_eq!(res.status.code(), Some(4), "a failure while running: {err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains("out.usdc"), "the error names the file: {err}");
    assert_eq!(
        std::fs::read(&out).expect("still there"),
        before,
        "the previous output changed"
    );
}
