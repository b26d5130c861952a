//! The command line on real files: `inspect` and `mesh` on every fixture pattern, the samples.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;

fn clothsr() -> Command {
    Command::new(env!("CARGO_BIN_EXE_clothsr"))
}

fn patterns() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/patterns");
    let mut out = Vec::new();
    for dir in [
        "garmentcode_examples",
        "legacy_templates",
        "mh_skirt_circle",
        "mh_pencil_skirt",
        "mh_tshirt",
    ] {
        for e in std::fs::read_dir(root.join(dir)).expect("dir") {
            let p = e.expect("entry").path();
            if p.extension().is_some_and(|x| x == "json") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

#[test]
fn inspect_and_mesh_work_on_every_fixture_pattern() {
    let dir = tempfile::tempdir().expect("tempdir");
    let all = patterns();
    assert!(all.len() >= 29);
    for p in &all {
        let out = clothsr()
            .arg("inspect")
            .arg("--no-mesh")
            .arg(p)
            .output()
            .expect("run");
        assert!(
            out.status.success(),
            "inspect {}: {}",
            p.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains("panel") && text.contains("seam"), "{text}");
        let usd = dir.path().join("m.usdc");
        let out = clothsr()
            .arg("mesh")
            .arg(p)
            .args(["--edge-mm", "20", "-o"])
            .arg(&usd)
            .output()
            .expect("run");
        assert!(
            out.status.success(),
            "mesh {}: {}",
            p.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(usd.exists());
    }
}

#[test]
fn inspect_reports_vertex_counts_and_avatar_frames() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = clothsr()
        .arg("inspect")
        .arg(root.join("samples/skirt.usda"))
        .output()
        .expect("run");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    assert!(
        text.contains("at   20 mm") && text.contains("at  2.5 mm"),
        "{text}"
    );
    let out = clothsr()
        .arg("inspect")
        .arg(root.join("tests/data/avatars/mh_walk_train.usda"))
        .output()
        .expect("run");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("UsdSkel skinned") && text.contains("181 frames, time codes 0..180"),
        "{text}"
    );
}

#[test]
fn committed_samples_are_what_the_generator_writes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let status = clothsr()
        .args(["lab", "samples", "-o"])
        .arg(dir.path())
        .status()
        .expect("run");
    assert!(status.success());
    for name in clothsr::scene::samples::SAMPLE_NAMES {
        let fresh =
            std::fs::read_to_string(dir.path().join(format!("{name}.usda"))).expect("fresh");
        let committed = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("samples/{name}.usda")),
        )
        .expect("committed sample");
        assert!(
            fresh == committed,
            "samples/{name}.usda is stale: run `clothsr lab samples -o samples`"
        );
    }
}

#[test]
fn a_missing_python_environment_says_what_to_run() {
    let out = clothsr()
        .env("CLOTHSR_VENV", "/nonexistent/venv")
        .arg("inspect")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/skirt.usda"))
        .output()
        .expect("run");
    // A broken installation is a failure while running (4), not the input's fault.
    assert_eq!(out.status.code(), Some(4));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bash .ci/setup") && err.contains("/nonexistent/venv"),
        "{err}"
    );
}

/// `dataset` → `train corrector` (both phases, the second reloading the scene the manifest
/// names) → `rollout` → `train isr` → `sr` → `run` with both models, on a coarse sample;
/// offsets with minus signs parse.
#[test]
fn dataset_train_rollout_sr_and_run_chain_on_a_sample() {
    let dir = tempfile::tempdir().expect("tempdir");
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/sheet_sphere.usda");
    let (data, model, csv) = (
        dir.path().join("data"),
        dir.path().join("model"),
        dir.path().join("rollout.csv"),
    );
    let run = |args: Vec<OsString>| {
        let out = clothsr().args(&args).output().expect("run");
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).to_string()
    };
    run(vec![
        "lab".into(),
        "dataset".into(),
        sample.clone().into(),
        "--coarse-mm".into(),
        "80".into(),
        "--fine-mm".into(),
        "40".into(),
        "--frames".into(),
        "3".into(),
        "--fast".into(),
        "--self-collision".into(),
        "off".into(),
        "--garment-offset".into(),
        "-0.01,-0.005,0.01".into(),
        "-o".into(),
        data.clone().into(),
    ]);
    let manifest = std::fs::read_to_string(data.join("manifest.json")).expect("manifest");
    assert!(manifest.contains("-0.005") && manifest.contains("\"fast\": true"));
    // calibrate: two membranes and two grips (the simulator's own among them) run alone from
    // the data set's M_int; the table lists all four best first, the CSV each, and the best
    // is written as a models folder's coarse.json.
    let (cal_json, cal_csv) = (
        dir.path().join("cal_models/coarse.json"),
        dir.path().join("cal.csv"),
    );
    let calibrate = |extra: &[&str]| {
        let mut args: Vec<OsString> = vec![
            "lab".into(),
            "calibrate".into(),
            "--data".into(),
            data.clone().into(),
            "-o".into(),
            cal_json.clone().into(),
            "--csv".into(),
            cal_csv.clone().into(),
            "--wrinkle-bending".into(),
            "0".into(),
        ];
        args.extend(extra.iter().map(OsString::from));
        clothsr().args(&args).output().expect("run")
    };
    let bad = calibrate(&["--compression", "1,1.5"]);
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && err.contains("compression"),
        "{err}"
    );
    let bad = calibrate(&["--friction", "scene,grippy"]);
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success() && err.contains("grippy"), "{err}");
    let bad = calibrate(&["--bending", "0"]);
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        bad.status.code() == Some(2) && err.contains("'0'") && err.contains("--bending"),
        "{err}"
    );
    assert!(!cal_json.exists() && !cal_csv.exists());
    // A CSV that could not be written is refused before any run.
    let under_a_file = data.join("manifest.json").join("cal.csv");
    let bad = clothsr()
        .arg("lab")
        .arg("calibrate")
        .arg("--data")
        .arg(&data)
        .arg("-o")
        .arg(&cal_json)
        .arg("--csv")
        .arg(&under_a_file)
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success() && err.contains("is a file"), "{err}");
    assert!(!cal_json.exists());
    let out = calibrate(&[
        "--compression",
        "1,0.05",
        "--friction",
        "scene,2",
        "--frames",
        "2",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rows: Vec<Vec<f64>> = std::fs::read_to_string(&cal_csv)
        .expect("calibration csv")
        .lines()
        .skip(1)
        .map(|l| {
            l.split(',')
                .map(|c| match c {
                    "scene" => -1.0,
                    "on" => 1.0,
                    "off" => 0.0,
                    _ => c.parse().expect("number"),
                })
                .collect()
        })
        .collect();
    assert_eq!(rows.len(), 4, "{stdout}");
    // Best first; the simulator's own model is 1.00× itself.
    // Columns: compression, knee, friction, gain, bending, crease contacts (on: 1), pooled mm,
    // ratio to own, per set.
    assert!(rows.iter().all(|r| r.len() == 9), "{rows:?}");
    assert!(rows.windows(2).all(|w| w[0][6] <= w[1][6]), "{rows:?}");
    let own = rows
        .iter()
        .find(|r| r[0] == 1.0 && r[2] == -1.0)
        .expect("own");
    assert!((own[7] - 1.0).abs() < 1e-12 && own[6] > 0.0, "{own:?}");
    assert!(
        rows.iter()
            .all(|r| r[1] == 0.0 && r[4] == 1.0 && r[5] == 1.0),
        "{rows:?}"
    );
    let chosen: clothsr::pipeline::CoarseCalibration =
        serde_json::from_str(&std::fs::read_to_string(&cal_json).expect("coarse.json"))
            .expect("a calibration");
    assert_eq!(chosen.compression.unwrap_or(1.0), rows[0][0]);
    assert_eq!(chosen.friction.unwrap_or(-1.0), rows[0][2]);
    assert!(stdout.contains("chosen:"), "{stdout}");
    run(vec![
        "lab".into(),
        "train".into(),
        "corrector".into(),
        "--data".into(),
        data.clone().into(),
        "-o".into(),
        model.clone().into(),
        "--steps".into(),
        "5".into(),
        "--batch".into(),
        "1".into(),
        "--latent".into(),
        "8".into(),
        "--mp-steps".into(),
        "1".into(),
        "--rollout-iters".into(),
        "2".into(),
        "--window".into(),
        "2".into(),
    ]);
    assert!(model.join("model.bpk").exists());
    // Fine-tuned from it: two more phase-2 windows; the network's sizes come from the model,
    // and asking for others is refused.
    let tuned = dir.path().join("tuned");
    let tune = |extra: &[&str]| {
        let mut args: Vec<OsString> = vec![
            "lab".into(),
            "train".into(),
            "corrector".into(),
            "--data".into(),
            data.clone().into(),
            "-o".into(),
            tuned.clone().into(),
            "--init".into(),
            model.clone().into(),
            "--steps".into(),
            "0".into(),
            "--rollout-iters".into(),
            "2".into(),
            "--window".into(),
            "2".into(),
        ];
        args.extend(extra.iter().map(OsString::from));
        clothsr().args(&args).output().expect("run")
    };
    let refused = tune(&["--latent", "16"]);
    assert_eq!(refused.status.code(), Some(2));
    assert!(!tuned.exists());
    // So is a negative wrinkle bending gain, naming the option, before anything is written.
    let refused = tune(&["--coarse-wrinkle-bending=-1"]);
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        refused.status.code() == Some(2)
            && err.contains("'-1'")
            && err.contains("--coarse-wrinkle-bending"),
        "{err}"
    );
    assert!(!tuned.exists());
    // The coarse model must be the one the network was trained beside: with crease contacts
    // and the fabric's bending.
    for (other, why) in [
        (
            ["--coarse-crease-contacts", "off"],
            "trained with crease contacts on, the training asks for off",
        ),
        (
            ["--coarse-bending", "0.5"],
            "trained beside 1 times the fabric's bending stiffness, the training asks for 0.5",
        ),
    ] {
        let out = tune(&other);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(why), "{err}");
        assert!(!tuned.exists());
    }
    let out = tune(&["--coarse-bending", "0"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.code() == Some(2) && err.contains("'0'") && err.contains("--coarse-bending"),
        "{err}"
    );
    // A wrinkle bending gain of 0 is none, as the model was trained.
    let out = tune(&["--coarse-wrinkle-bending", "0"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let config = std::fs::read_to_string(tuned.join("config.json")).expect("config");
    assert!(
        config.contains("\"format_version\": 2")
            && config.contains("\"latent\": 8")
            && config.contains("\"init_from\"")
            && config.contains("\"coarse\": {}"),
        "{config}"
    );
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(log.contains("no phase 1 (started from"), "{log}");
    // `clothsr rollout` of the model on the data set, with these arguments after.
    let rollout = |args: Vec<OsString>| {
        let mut all: Vec<OsString> = vec![
            "lab".into(),
            "rollout".into(),
            "--model".into(),
            model.clone().into(),
            "--data".into(),
            data.clone().into(),
        ];
        all.extend(args);
        run(all)
    };
    // A CSV's rows after its header, as numbers.
    let csv_rows = |csv: &Path| -> Vec<Vec<f64>> {
        std::fs::read_to_string(csv)
            .expect("csv")
            .lines()
            .skip(1)
            .map(|l| l.split(',').filter_map(|w| w.parse().ok()).collect())
            .collect()
    };
    let report = rollout(vec![
        "--frames".into(),
        "2".into(),
        "--csv".into(),
        csv.clone().into(),
    ]);
    assert!(report.contains("mean error, interleaved"), "{report}");
    assert_eq!(
        std::fs::read_to_string(&csv).expect("csv").lines().count(),
        3
    );
    assert!(
        report.contains("coarse membrane compression 1, friction the simulator's ("),
        "{report}"
    );
    // The simulation alone's mean edge strain in frame 2 (the sheet on the sphere), from a
    // rollout's CSV, %.
    let strain = |csv: &Path| -> f64 {
        let rows = csv_rows(csv);
        rows.get(1)
            .and_then(|r| r.get(7).copied())
            .unwrap_or_else(|| panic!("no sim-alone strain in {rows:?}"))
    };
    let stiff = strain(&csv);
    // The corrector beside another coarse membrane than its training's, and a factor out of
    // range refused with the flag named.
    let report = rollout(vec![
        "--frames".into(),
        "2".into(),
        "--coarse-compression".into(),
        "0.25".into(),
        "--csv".into(),
        csv.clone().into(),
    ]);
    assert!(
        report.contains("coarse membrane compression 0.25, friction the simulator's ("),
        "{report}"
    );
    // The factor reaches the simulator: the simulation alone's edges shorten more under the
    // softer membrane.
    let soft = strain(&csv);
    assert!(
        soft < stiff - 0.005,
        "sim alone mean strain {stiff} % at factor 1 and {soft} % at 0.25"
    );
    // `clothsr rollout` with these arguments refused: its error output.
    let rollout_refused = |args: &[&str]| -> String {
        let out = clothsr()
            .arg("lab")
            .arg("rollout")
            .args(args)
            .arg("--model")
            .arg(&model)
            .arg("--data")
            .arg(&data)
            .output()
            .expect("run");
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let err = rollout_refused(&["--frames", "1", "--coarse-compression", "0"]);
    assert!(
        err.contains("'0'") && err.contains("--coarse-compression"),
        "{err}"
    );
    // Short horizons: two one-frame rollouts from the ground truth (frames 1 and 2), averaged
    // per frame after the start, beside the factor in use; the factor reaches the simulators
    // here too (the simulation alone's error differs from the paper's membrane's).
    let horizon = |factor: &str, csv: &Path| -> (String, Vec<f64>) {
        let report = rollout(vec![
            "--frames".into(),
            "2".into(),
            "--horizon".into(),
            "1".into(),
            "--every".into(),
            "1".into(),
            "--coarse-compression".into(),
            factor.into(),
            "--csv".into(),
            csv.into(),
        ]);
        let rows = csv_rows(csv);
        assert!(rows.len() == 1 && rows[0].len() == 4, "{rows:?}");
        (report, rows[0].clone())
    };
    let (report, soft) = horizon("0.5", &dir.path().join("horizon_soft.csv"));
    assert!(
        report.contains("2 rollouts of 1 frames, from frames 1..=2")
            && report.contains("coarse membrane compression 0.5, friction the simulator's ("),
        "{report}"
    );
    assert!(
        report
            .lines()
            .any(|l| l.trim_start().starts_with("1 ") && l.ends_with('×')),
        "no row for frame 1 in {report}"
    );
    // Columns: frames after start, sim alone mm, interleaved mm, their ratio.
    assert!(
        soft[1] > 0.0 && (soft[2] / soft[1] / soft[3] - 1.0).abs() < 0.01,
        "{soft:?}"
    );
    let (report, stiff) = horizon("1", &dir.path().join("horizon_stiff.csv"));
    assert!(
        report.contains("coarse membrane compression 1, friction the simulator's ("),
        "{report}"
    );
    assert!(
        (soft[1] - stiff[1]).abs() > 1e-3,
        "sim alone {} mm at factor 0.5 and {} mm at 1",
        soft[1],
        stiff[1]
    );
    // The friction in use is reported beside the membrane, and so is the wrinkle bending
    // gain, when on; a negative gain is refused, naming the option.
    for (option, value, setup) in [
        (
            "--coarse-friction",
            "0.6",
            "coarse membrane compression 1, friction 0.6 (all three variants)",
        ),
        (
            "--coarse-wrinkle-bending",
            "1.5",
            "coarse membrane compression 1, friction the simulator's, wrinkle bending 1.5 (all \
             three variants)",
        ),
    ] {
        let report = rollout(vec![
            "--frames".into(),
            "1".into(),
            option.into(),
            value.into(),
        ]);
        assert!(report.contains(setup), "{report}");
    }
    let err = rollout_refused(&["--frames", "1", "--coarse-wrinkle-bending=-1"]);
    assert!(
        err.contains("'-1'") && err.contains("--coarse-wrinkle-bending"),
        "{err}"
    );

    // Jitter: the rollout again from the start moved 0.1 mm sideways, pooled with the
    // nominal one; the moved run is 0.1 mm from the ground truth at the end of frame 1.
    let jitter_csv = dir.path().join("jitter.csv");
    let report = rollout(vec![
        "--frames".into(),
        "1".into(),
        "--jitter".into(),
        "1".into(),
        "--csv".into(),
        jitter_csv.clone().into(),
    ]);
    assert!(
        report.contains("start moved 0.1 mm along (+1.000, +0.000, +0.000)")
            && report.contains("pooled over 2 runs, 2 frames")
            && report.contains("range over runs"),
        "{report}"
    );
    let text = std::fs::read_to_string(&jitter_csv).expect("csv");
    let errors = |tag: &str| -> Vec<f64> {
        text.lines()
            .find(|l| l.contains(tag))
            .map(|l| {
                l.split(',')
                    .skip(2)
                    .filter_map(|w| w.parse().ok())
                    .collect()
            })
            .unwrap_or_else(|| panic!("no run '{tag}' in {text}"))
    };
    let (nominal, moved) = (errors("data,1,"), errors("@1,1,"));
    // The coarse steps of 1/300 s fall behind the fine sub-steps (implicit Euler's lag, about
    // g·h·t/2, vertical); the start moved 0.1 mm sideways adds to that at right angles.
    for k in 0..2 {
        let expected = nominal[k].hypot(0.1);
        assert!(
            (moved[k] - expected).abs() < 0.01 && nominal[k] < 1.0,
            "column {k}: the moved start's error {} against {expected} from the nominal {}\n{text}",
            moved[k],
            nominal[k]
        );
    }

    // The data set forked at frame 1 with the sheet moved 1 mm, and the distance between the
    // two ground truths reported beside the rollout as its predictability floor.
    let forked = dir.path().join("forked");
    run(vec![
        "lab".into(),
        "fork".into(),
        data.clone().into(),
        "--frame".into(),
        "1".into(),
        "--offset".into(),
        "0,0.001,0".into(),
        "-o".into(),
        forked.clone().into(),
    ]);
    let manifest = std::fs::read_to_string(forked.join("manifest.json")).expect("manifest");
    assert!(
        manifest.contains("\"fork\"") && manifest.contains("\"frames_done\": 3"),
        "{manifest}"
    );
    let report = rollout(vec![
        "--frames".into(),
        "2".into(),
        "--floor".into(),
        forked.clone().into(),
    ]);
    let floor: f64 = report
        .lines()
        .find_map(|l| l.strip_prefix("predictability floor"))
        .and_then(|l| l.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no floor in {report}"));
    // Frame 1 is shared; the sheet moved 1 mm at its end is about that far away in frame 2.
    assert!(floor > 0.1 && floor < 5.0, "floor {floor} mm");

    // The ISR network on the same data, evaluated by `sr`.
    let isr = dir.path().join("models").join("isr");
    run(vec![
        "lab".into(),
        "train".into(),
        "isr".into(),
        "--data".into(),
        data.clone().into(),
        "-o".into(),
        isr.clone().into(),
        "--steps".into(),
        "3".into(),
        "--batch".into(),
        "2".into(),
        "--patch".into(),
        "16".into(),
        "--embed-dim".into(),
        "8".into(),
        "--depths".into(),
        "2".into(),
        "--heads".into(),
        "2".into(),
        "--window".into(),
        "4".into(),
    ]);
    // The geometry channels are on by default.
    let config = std::fs::read_to_string(isr.join("config.json")).expect("config");
    assert!(config.contains("\"geometry_input\": true"), "{config}");
    let report = run(vec![
        "lab".into(),
        "sr".into(),
        "--model".into(),
        isr.clone().into(),
        "--data".into(),
        data.clone().into(),
        "--csv".into(),
        csv.clone().into(),
    ]);
    assert!(report.contains("mean error, SR"), "{report}");
    assert_eq!(
        std::fs::read_to_string(&csv).expect("csv").lines().count(),
        4
    );

    // `run`: the whole pipeline with both models, to a USD file with one time sample per
    // frame plus the first.
    copy_dir(&model, &dir.path().join("models").join("corrector"));
    let usd = dir.path().join("fine.usdc");
    run(vec![
        "lab".into(),
        "run".into(),
        sample.clone().into(),
        "--models".into(),
        dir.path().join("models").into(),
        "--coarse-mm".into(),
        "80".into(),
        "--frames".into(),
        "2".into(),
        "-o".into(),
        usd.clone().into(),
    ]);
    let stage = clothsr::io::usd::read_usd(&usd).expect("read the output");
    let cloth: Vec<_> = stage
        .meshes
        .iter()
        .filter(|m| m.role == clothsr::io::usd::MeshRole::Cloth)
        .collect();
    assert_eq!(cloth.len(), 1);
    assert_eq!(cloth[0].frames.len(), 3);
    assert!(cloth[0]
        .frames
        .iter()
        .flatten()
        .all(|p| p.iter().all(|c| c.is_finite())));
    let (_, fabric_edge) = cloth[0].fabric.clone().expect("fabric");
    assert!((fabric_edge - 0.04).abs() < 1e-9, "{fabric_edge}");

    // `run` again with a Rerun recording and the upsampled baseline, then `eval` against a
    // fine simulation of the same scene: table, CSV, PNG plot and heat-map recording.
    let (rrd, up, gt) = (
        dir.path().join("run.rrd"),
        dir.path().join("up.usdc"),
        dir.path().join("gt.usdc"),
    );
    run(vec![
        "simulate".into(),
        sample.clone().into(),
        "--edge-mm".into(),
        "40".into(),
        "--fast".into(),
        "--self-collision".into(),
        "off".into(),
        "--frames".into(),
        "2".into(),
        "-o".into(),
        gt.clone().into(),
    ]);
    run(vec![
        "lab".into(),
        "run".into(),
        sample.clone().into(),
        "--models".into(),
        dir.path().join("models").into(),
        "--coarse-mm".into(),
        "80".into(),
        "--frames".into(),
        "2".into(),
        "-o".into(),
        usd.clone().into(),
        "--gt".into(),
        gt.clone().into(),
        "--rrd".into(),
        rrd.clone().into(),
        "--upsampled-out".into(),
        up.clone().into(),
    ]);
    let rec = clothsr::viz::read_rrd(&rrd).expect("a valid recording");
    for entity in [
        "world/fine",
        "world/coarse/m_int",
        "world/coarse/m_c",
        "timings/corrector_s",
    ] {
        assert!(rec.entities.contains(entity), "{entity}: {rec:?}");
    }
    let (eval_csv, png, eval_rrd) = (
        dir.path().join("eval.csv"),
        dir.path().join("eval.png"),
        dir.path().join("eval.rrd"),
    );
    let table = run(vec![
        "eval".into(),
        "--gt".into(),
        gt.clone().into(),
        "--pred".into(),
        usd.clone().into(),
        "--baseline".into(),
        format!("upsampled={}", up.display()).into(),
        "--csv".into(),
        eval_csv.clone().into(),
        "--plot".into(),
        png.clone().into(),
        "--rrd".into(),
        eval_rrd.clone().into(),
    ]);
    assert!(table.contains("prediction / upsampled"), "{table}");
    // Header plus (prediction, upsampled) × 3 frames.
    let rows = std::fs::read_to_string(&eval_csv).expect("csv");
    assert_eq!(rows.lines().count(), 7, "{rows}");
    assert!(rows.lines().skip(1).all(|l| l
        .split(',')
        .nth(2)
        .and_then(|v| v.parse::<f64>().ok())
        .is_some_and(f64::is_finite)));
    let png_bytes = std::fs::read(&png).expect("png");
    assert!(png_bytes.starts_with(b"\x89PNG"), "not a PNG");
    let rec = clothsr::viz::read_rrd(&eval_rrd).expect("a valid recording");
    assert!(rec.entities.contains("world/prediction"), "{rec:?}");
    assert!(rec.entities.contains("world/upsampled"), "{rec:?}");
    // Without a ground truth, the prediction alone is checked.
    let check = run(vec!["eval".into(), "--pred".into(), usd.clone().into()]);
    assert!(check.contains("frames: 3"), "{check}");
    assert!(check.contains("points not finite: 0"), "{check}");
    assert!(
        check.contains("inside the bodies: 0 frames with any"),
        "{check}"
    );
    assert!(
        check.contains("largest move of a vertex in one frame"),
        "{check}"
    );
    // The data set as the ground truth and its fork as its twin: the fork's distance from
    // it, the predictability floor, is about the 1 mm it was moved by at the end of frame 1.
    let table = run(vec![
        "eval".into(),
        "--gt".into(),
        data.clone().into(),
        "--pred".into(),
        usd.clone().into(),
        "--baseline".into(),
        format!("upsampled={}", up.display()).into(),
        "--floor".into(),
        forked.clone().into(),
    ]);
    // Column `k` (0: frames, 1: mean mm) of the table's row for a series.
    let cell = |row: &str, k: usize| -> f64 {
        table
            .lines()
            .find_map(|l| l.strip_prefix(row))
            .and_then(|l| l.split_whitespace().nth(k))
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no {row}row in {table}"))
    };
    let floor_mm = cell("floor ", 1);
    assert!(
        floor_mm > 0.1 && floor_mm < 5.0,
        "floor {floor_mm} mm: {table}"
    );
    assert!(table.contains("prediction / floor"), "{table}");
    // Over the prediction's frames only (the fork has one more).
    assert_eq!(cell("floor ", 0), cell("prediction ", 0), "{table}");
    // Cloth through cloth, of the ground truth beside every series, over the same frames.
    let (_, through) = table
        .split_once("cloth through cloth")
        .unwrap_or_else(|| panic!("no cloth through cloth in {table}"));
    for row in ["ground truth ", "prediction ", "upsampled ", "floor "] {
        let cells: Vec<f64> = through
            .lines()
            .find_map(|l| l.strip_prefix(row))
            .map(|l| {
                l.split_whitespace()
                    .filter_map(|v| v.parse().ok())
                    .collect()
            })
            .unwrap_or_default();
        assert_eq!(cells.len(), 4, "{row}in {through}");
        assert_eq!(cells[0], cell("prediction ", 0), "{row}in {through}");
        assert!(
            cells[1] >= cells[2] && cells[1].is_finite(),
            "{row}in {through}"
        );
    }
    // Half the floor is the least any prediction averages over the two ground truths; the
    // prediction's two errors average above it, and the bound is set beside the baseline.
    let number_after = |prefix: &str| -> f64 {
        table
            .lines()
            .find_map(|l| l.split_once(prefix))
            .and_then(|(_, rest)| rest.split_whitespace().next())
            .and_then(|v| v.trim_end_matches(['×', ',', ';']).parse().ok())
            .unwrap_or_else(|| panic!("no {prefix:?} in {table}"))
    };
    let least = number_after("least possible over both: ");
    assert!(
        (number_after("ground truths apart: ") - floor_mm).abs() < 2e-3,
        "{table}"
    );
    assert!((least - 0.5 * floor_mm).abs() < 2e-3, "{table}");
    let both = number_after("mean over both: ");
    assert!(both >= least, "{table}");
    assert!(
        (both - 0.5 * (number_after("against the twin: ") + cell("prediction ", 1))).abs() < 2e-3,
        "{table}"
    );
    assert!(
        number_after("prediction over both / least: ") >= 1.0,
        "{table}"
    );
    let upsampled = cell("upsampled ", 1);
    assert!(
        (number_after("least / upsampled: ") - least / upsampled).abs() < 2e-3,
        "{table}"
    );
    // Without the corrector `run` takes the models folder's coarse.json; a bad one is refused
    // before anything is written, naming the file.
    let calibration = dir.path().join("models").join("coarse.json");
    std::fs::write(&calibration, r#"{"compression": 2}"#).expect("write");
    // `clothsr run` on the sample with these arguments, refused before writing: its exit
    // code and error output.
    let refused = dir.path().join("refused.usdc");
    let run_refused = |args: &[&str]| -> (Option<i32>, String) {
        let out = clothsr()
            .arg("lab")
            .arg("run")
            .arg(&sample)
            .arg("--models")
            .arg(dir.path().join("models"))
            .args(args)
            .arg("-o")
            .arg(&refused)
            .output()
            .expect("run");
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(!out.status.success(), "{err}");
        assert!(!refused.exists());
        (out.status.code(), err)
    };
    let (code, err) = run_refused(&["--coarse-mm", "80", "--frames", "1", "--corrector", "off"]);
    // The models folder's file is bad input (3).
    assert_eq!(code, Some(3), "{err}");
    assert!(
        err.contains("coarse.json") && err.contains("compression must be in (0, 1], got 2"),
        "{err}"
    );
    std::fs::remove_file(&calibration).expect("remove");
    // A negative knee is refused at once, naming the option (0 is none).
    let (_, err) = run_refused(&["--frames", "1", "--coarse-compression-knee=-1"]);
    assert!(
        err.contains("'-1'") && err.contains("--coarse-compression-knee"),
        "{err}"
    );
    // A missing prediction is refused as the command line's error, naming the file.
    let out = clothsr()
        .args(["eval", "--gt"])
        .arg(&gt)
        .arg("--pred")
        .arg(dir.path().join("fine.usdc").with_file_name("missing.usdc"))
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.usdc"));

    // A directory that is not a model: bad input (3), the directory named.
    let out = clothsr()
        .args(["lab", "rollout", "--model"])
        .arg(&data)
        .arg("--data")
        .arg(&data)
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(3));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("not a corrector model directory"), "{err}");
}

/// `inspect` on a mesh without texture coordinates reports how it was flattened.
#[test]
fn inspect_reports_the_flattening_of_a_mesh_without_uvs() {
    let bunny = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/colliders/bunny.obj");
    let out = clothsr().arg("inspect").arg(&bunny).output().expect("run");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("texture coordinates: no"), "{text}");
    // The number printed after `label`.
    let after = |label: &str| -> f64 {
        text.split(label)
            .nth(1)
            .and_then(|t| t.split_whitespace().next())
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("no '{label}' reported: {text}"))
    };
    let charts = after("flattened into ") as usize;
    assert!(charts >= 2, "{text}");
    assert!(
        text.contains(&format!("as cloth: {charts} panels")),
        "{text}"
    );
    // Each chart is remeshed like a pattern panel: the bunny, in its own units read as metres,
    // covers about 219 m², some 2.5K vertices a square metre at 20 mm (a pattern meshes so);
    // at 2.5 mm it would be millions, which the remeshing refuses, naming the units.
    let area = after("material area ");
    let remeshed: Vec<f64> = text
        .lines()
        .filter(|l| l.contains("remeshed in"))
        .filter_map(|l| l.split(':').nth(1)?.split_whitespace().next()?.parse().ok())
        .collect();
    assert_eq!(remeshed.len(), 1, "{text}");
    let per_m2 = remeshed[0] / area;
    assert!(
        (1_800.0..3_700.0).contains(&per_m2),
        "{per_m2} a m²: {text}"
    );
    assert!(
        text.contains("at  2.5 mm: not remeshed") && text.contains("check the mesh's units"),
        "{text}"
    );
}

/// Without `--models`, `run` takes the generic models: `$CLOTHSR_MODELS` first.
#[test]
fn run_without_models_takes_the_folder_clothsr_models_names() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("fine.usda");
    let models = root.join("samples/models/three_balls");
    let run = clothsr()
        .env("CLOTHSR_MODELS", &models)
        .arg("run")
        .arg(root.join("samples/sheet_three_balls.usda"))
        .args(["--frames", "1", "-o"])
        .arg(&out)
        .output()
        .expect("run");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let text = std::fs::read_to_string(&out).expect("output");
    assert!(
        text.contains(&format!("with models {}", models.display())),
        "the output does not name the models it was made with"
    );
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for e in std::fs::read_dir(from).expect("read_dir") {
        let e = e.expect("entry");
        if e.path().is_file() {
            std::fs::copy(e.path(), to.join(e.file_name())).expect("copy");
        }
    }
}

/// Issue 48: `clothsr --help` lists the user's commands and `lab`, the research tools answer
/// under `clothsr lab`, and `run --help` shows a short, grouped set of flags.
#[test]
fn help_lists_the_users_commands_and_the_lab_holds_the_research_tools() {
    let help = |args: &[&str]| {
        let out = clothsr().args(args).arg("--help").output().expect("run");
        assert!(out.status.success(), "{args:?}");
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let commands = |text: &str| -> Vec<String> {
        text.split("Commands:")
            .nth(1)
            .and_then(|t| t.split("Options:").next())
            .unwrap_or_default()
            .lines()
            .filter_map(|l| l.split_whitespace().next().map(String::from))
            .collect()
    };
    let top = help(&[]);
    assert_eq!(
        commands(&top),
        ["run", "fit", "eval", "inspect", "convert", "mesh", "simulate", "lab", "help"],
        "{top}"
    );
    let lab = help(&["lab"]);
    for c in [
        "dataset",
        "fork",
        "train",
        "rollout",
        "calibrate",
        "sr",
        "run",
        "bench",
        "samples",
    ] {
        assert!(commands(&lab).iter().any(|x| x == c), "{c}: {lab}");
    }
    let run = help(&["run"]);
    let flags = run
        .lines()
        .filter(|l| l.trim_start().starts_with('-'))
        .count();
    assert!(flags <= 19, "{flags} flags: {run}");
    for heading in ["Input:", "Output:", "Models:", "Preview:"] {
        assert!(run.contains(heading), "{heading} {run}");
    }
    assert!(!run.contains("--coarse-compression"), "{run}");
    assert!(help(&["lab", "run"]).contains("--coarse-compression"));
    // The research tools are not user commands any more.
    let out = clothsr().args(["train", "--help"]).output().expect("run");
    assert!(!out.status.success());
}

/// A batch goes on past a failing shot, exits with the failure's code (3: bad input) and says
/// what each shot did in the `--json` summary.
#[test]
fn a_batch_goes_on_past_a_bad_shot_and_summarises_it_in_json() {
    let dir = tempfile::tempdir().expect("tempdir");
    let bad = dir.path().join("broken.usda");
    std::fs::write(&bad, "#usda 1.0\ndef Mesh \"cloth\" {\n").expect("write");
    let good = Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/sheet_sphere.usda");
    let out = clothsr()
        .arg("run")
        .arg(&bad)
        .arg(&good)
        .args(["--frames", "1", "--json", "--out-dir"])
        .arg(dir.path())
        .output()
        .expect("run");
    assert_eq!(
        out.status.code(),
        Some(3),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    use clothsr::pipeline::shot::Status;
    // The JSON's words, as a farm's script reads them.
    let text = String::from_utf8_lossy(&out.stdout);
    for word in [
        r#""status":"failed""#,
        r#""status":"ok""#,
        r#""kind":"input""#,
    ] {
        assert!(text.contains(word), "{word} in {text}");
    }
    let summary: clothsr::pipeline::shot::RunSummary =
        serde_json::from_slice(&out.stdout).expect("one JSON summary on stdout");
    assert_eq!((summary.status, summary.exit_code), (Status::Failed, 3));
    assert_eq!(summary.shots.len(), 2);
    let (first, second) = (&summary.shots[0], &summary.shots[1]);
    assert_eq!(first.status, Status::Failed);
    let error = first.error.as_ref().expect("the first shot's error");
    assert_eq!(error.kind, clothsr::ErrorKind::Input);
    assert!(error.message.contains("broken.usda"), "{}", error.message);
    assert!(!dir.path().join("broken.usdc").exists());
    assert_eq!((second.status, second.frames_computed), (Status::Ok, 1));
    assert!(dir.path().join("sheet_sphere.usdc").exists());
    // Bad usage before any shot: exit code 2, and the summary says so.
    let out = clothsr()
        .arg("run")
        .arg(&good)
        .args(["--json", "--frames", "1", "-o"])
        .arg(dir.path().join("out.txt"))
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2));
    let summary: clothsr::pipeline::shot::RunSummary =
        serde_json::from_slice(&out.stdout).expect("JSON");
    assert_eq!(
        summary.error.expect("an error").kind,
        clothsr::ErrorKind::Usage
    );
}

/// A garment is dressed once per shot: a later run of it starts from the dressed state kept
/// beside the output, and makes the same animation as the run that dressed it.
#[test]
fn a_rerun_starts_from_the_dressed_state_kept_beside_the_output() {
    use clothsr::io::usd::{read_usd, MeshRole};
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("skirt.usdc");
    let run = |pattern: &str, out: &Path, extra: &[&str]| {
        let r = clothsr()
            .arg("run")
            .arg(
                root.join("tests/data/patterns/legacy_templates")
                    .join(pattern),
            )
            .arg("--models")
            .arg(root.join("models/generic"))
            .args(["--frames", "2", "-o"])
            .arg(out)
            .args(extra)
            .output()
            .expect("run");
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        let log = String::from_utf8_lossy(&r.stderr).into_owned();
        let s = read_usd(out).expect("read");
        let cloth = s
            .meshes
            .into_iter()
            .find(|m| m.role == MeshRole::Cloth)
            .expect("cloth");
        (log, cloth.frames)
    };
    let two = "skirts_skirt_2_panels.json";
    let (first, dressed_now) = run(two, &out, &[]);
    let kept = clothsr::io::dressed::dressed_path(&out);
    assert!(kept.exists(), "no dressed state beside the output");
    assert!(!first.contains("dressed state kept in"), "{first}");
    let (second, restored) = run(two, &out, &["--restart"]);
    assert!(second.contains("dressed state kept in"), "{second}");
    assert_eq!(
        dressed_now, restored,
        "another animation from the kept dressing"
    );
    // Kept for another garment, it is not taken: that one is dressed anew.
    let other = dir.path().join("other.usdc");
    std::fs::copy(&kept, clothsr::io::dressed::dressed_path(&other)).expect("copy");
    let (log, _) = run("skirts_skirt_4_panels.json", &other, &[]);
    assert!(log.contains("dressing again"), "{log}");
}
