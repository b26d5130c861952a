//! Bad input: a clear error naming the file and the element, a non-zero exit, no panic and no
//! output file.

use std::path::{Path, PathBuf};
use std::process::Command;

/// A valid two-panel GarmentCode pattern (cm) to break in various ways.
fn pattern(edit: impl FnOnce(&mut serde_json::Value)) -> String {
    let mut v = serde_json::json!({
        "pattern": {
            "panels": {
                "front": {
                    "translation": [0, 100, 15], "rotation": [0, 0, 0],
                    "vertices": [[-30, -50], [30, -50], [18, 0], [-18, 0]],
                    "edges": [
                        {"endpoints": [0, 1], "curvature": {"type": "quadratic", "params": [[0.5, -0.1]]}},
                        {"endpoints": [1, 2]},
                        {"endpoints": [2, 3], "curvature": {"type": "circle", "params": [60, 0, 1]}},
                        {"endpoints": [3, 0]}
                    ]
                },
                "back": {
                    "translation": [0, 100, -15], "rotation": [0, 180, 0],
                    "vertices": [[-30, -50], [30, -50], [18, 0], [-18, 0]],
                    "edges": [
                        {"endpoints": [0, 1]}, {"endpoints": [1, 2]}, {"endpoints": [2, 3]}, {"endpoints": [3, 0]}
                    ]
                }
            },
            "stitches": [
                [{"panel": "front", "edge": 1}, {"panel": "back", "edge": 3}],
                [{"panel": "front", "edge": 3}, {"panel": "back", "edge": 1}]
            ]
        },
        "properties": {"units_in_meter": 100, "curvature_coords": "relative"}
    });
    edit(&mut v);
    v.to_string()
}

struct Case {
    name: &'static str,
    file: &'static str,
    content: String,
    /// Words the error must contain besides the file name.
    expect: &'static [&'static str],
}

fn run_case(dir: &Path, case: &Case, command: &[&str]) {
    let input = dir.join(case.file);
    std::fs::write(&input, &case.content).expect("write input");
    let output = dir.join(format!("{}_out.usda", case.name));
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_clothsr"));
    cmd.args(command).arg(&input);
    if command[0] != "inspect" {
        cmd.arg("-o").arg(&output);
    }
    let out = cmd.output().expect("run clothsr");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{}: should fail", case.name);
    // 3: bad input (2 is bad usage, 4 a failure while running).
    assert_eq!(
        out.status.code(),
        Some(3),
        "{}: exit code (stderr: {stderr})",
        case.name
    );
    assert!(
        !stderr.contains("panicked"),
        "{}: panicked: {stderr}",
        case.name
    );
    assert!(
        stderr.contains(case.file),
        "{}: error does not name the file: {stderr}",
        case.name
    );
    for word in case.expect {
        assert!(
            stderr.contains(word),
            "{}: error lacks '{word}': {stderr}",
            case.name
        );
    }
    assert!(
        !output.exists(),
        "{}: partial output left behind",
        case.name
    );
    let leftovers: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("dir")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.to_string_lossy().contains("clothsr-tmp"))
        .collect();
    assert!(
        leftovers.is_empty(),
        "{}: temporary files left: {leftovers:?}",
        case.name
    );
}

#[test]
fn bad_patterns_fail_clearly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cases = vec![
        Case {
            name: "malformed_json",
            file: "broken.json",
            content: "{\"pattern\": {".into(),
            expect: &["malformed JSON"],
        },
        Case {
            name: "missing_units",
            file: "nounits.json",
            content: pattern(|v| {
                v["properties"]
                    .as_object_mut()
                    .map(|o| o.remove("units_in_meter"));
            }),
            expect: &["units_in_meter"],
        },
        Case {
            name: "unknown_units",
            file: "badunits.json",
            content: pattern(|v| v["properties"]["units_in_meter"] = serde_json::json!("inches")),
            expect: &["unknown units"],
        },
        Case {
            name: "self_intersecting",
            file: "bowtie.json",
            content: pattern(|v| {
                v["pattern"]["panels"]["back"]["vertices"] =
                    serde_json::json!([[-30, -50], [30, -50], [-18, 0], [18, 0]]);
            }),
            expect: &["panel 'back'", "self-intersects"],
        },
        Case {
            name: "zero_area",
            file: "flat.json",
            content: pattern(|v| {
                v["pattern"]["panels"]["back"]["vertices"] =
                    serde_json::json!([[-30, 0], [30, 0], [18, 0], [-18, 0]]);
            }),
            expect: &["panel 'back'"],
        },
        Case {
            name: "seam_length_mismatch",
            file: "seam.json",
            content: pattern(|v| {
                v["pattern"]["panels"]["back"]["vertices"] =
                    serde_json::json!([[-30, -50], [30, -50], [18, -45], [-18, -45]]);
            }),
            expect: &["seam 0", "ratio"],
        },
        Case {
            name: "unknown_stitch_panel",
            file: "stitch.json",
            content: pattern(|v| {
                v["pattern"]["stitches"][0][1]["panel"] = serde_json::json!("sleeve")
            }),
            expect: &["stitch 0", "unknown panel 'sleeve'"],
        },
        Case {
            name: "endpoint_out_of_range",
            file: "endpoint.json",
            content: pattern(|v| {
                v["pattern"]["panels"]["front"]["edges"][1]["endpoints"] = serde_json::json!([1, 9])
            }),
            expect: &["panel 'front' edge 1", "endpoint"],
        },
        Case {
            name: "unknown_curvature",
            file: "curve.json",
            content: pattern(|v| {
                v["pattern"]["panels"]["front"]["edges"][0]["curvature"]["type"] =
                    serde_json::json!("spline")
            }),
            expect: &["panel 'front' edge 0", "spline"],
        },
        Case {
            name: "non_numeric_vertex",
            file: "vertex.json",
            content: pattern(|v| {
                v["pattern"]["panels"]["front"]["vertices"][2] = serde_json::json!(["a", 0])
            }),
            expect: &["panel 'front' vertex 2"],
        },
    ];
    for case in &cases {
        run_case(dir.path(), case, &["convert"]);
        run_case(dir.path(), case, &["mesh"]);
        run_case(dir.path(), case, &["inspect"]);
    }
}

#[test]
fn bad_meshes_and_stages_fail_clearly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cases = vec![
        Case {
            name: "obj_nan",
            file: "nan.obj",
            content: "v nan 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n".into(),
            expect: &["not finite"],
        },
        Case {
            name: "obj_bad_index",
            file: "index.obj",
            content: "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n".into(),
            expect: &["OBJ"],
        },
        Case {
            // Without vt the mesh is flattened; a zero-area triangle cannot be.
            name: "obj_without_vt_unflattenable",
            file: "novt.obj",
            content: "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n".into(),
            expect: &["no texture coordinates", "cannot be flattened", "zero area"],
        },
        Case { name: "usd_garbage", file: "garbage.usda", content: "#usda 1.0\ndef Mesh \"M\" {{{ nonsense\n".into(), expect: &["cannot open as USD"] },
        Case {
            name: "usd_unknown_units",
            file: "nounits.usda",
            content: "#usda 1.0\n(\n upAxis = \"Y\"\n)\ndef Mesh \"M\" {\n int[] faceVertexCounts = [3]\n int[] faceVertexIndices = [0, 1, 2]\n point3f[] points = [(0,0,0), (1,0,0), (0,1,0)]\n}\n".into(),
            expect: &["metersPerUnit"],
        },
        Case {
            // Without primvars:st the mesh is flattened; a zero-area triangle cannot be.
            name: "usd_cloth_without_st_unflattenable",
            file: "nost.usda",
            content: "#usda 1.0\n(\n metersPerUnit = 1\n upAxis = \"Y\"\n)\ndef Mesh \"Cloth\" (prepend apiSchemas = [\"ClothsrGarmentAPI\"]) {\n int[] faceVertexCounts = [3]\n int[] faceVertexIndices = [0, 1, 2]\n point3f[] points = [(0,0,0), (1,0,0), (2,0,0)]\n}\n".into(),
            expect: &["/Cloth", "cannot be flattened"],
        },
        Case {
            name: "usd_face_index_out_of_range",
            file: "faces.usda",
            content: "#usda 1.0\n(\n metersPerUnit = 1\n)\ndef Mesh \"M\" {\n int[] faceVertexCounts = [3]\n int[] faceVertexIndices = [0, 1, 5]\n point3f[] points = [(0,0,0), (1,0,0), (0,1,0)]\n}\n".into(),
            expect: &["/M", "outside"],
        },
    ];
    for case in &cases {
        run_case(dir.path(), case, &["convert"]);
    }
}

#[test]
fn output_extension_is_checked_before_any_work() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("skirt.txt");
    let res = Command::new(env!("CARGO_BIN_EXE_clothsr"))
        .args(["mesh"])
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/skirt.usda"))
        .arg("-o")
        .arg(&out)
        .output()
        .expect("run");
    assert_eq!(res.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&res.stderr).contains("skirt.txt"));
    assert!(!out.exists());
}

#[test]
fn usd_validation_reports_real_problems() {
    // A stage without defaultPrim and metersPerUnit: usd-core's validators must flag it, so the
    // validation our writer relies on is known to bite.
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("bare.usda");
    std::fs::write(
        &path,
        "#usda 1.0\ndef Mesh \"M\" {\n point3f[] points = [(0,0,0)]\n}\n",
    )
    .expect("write");
    // The only test here that starts Python in this process, while the others spawn clothsr: the
    // bridge must not write the environment they hand to their children (a `putenv` during a
    // spawn gave one child a freed environment, EFAULT). numpy's two variables are set through
    // `std::env` first, so they may appear; nothing else may.
    let before: std::collections::BTreeMap<_, _> = std::env::vars_os().collect();
    let issues = clothsr::io::usd::validate_usd(&path).expect("validate");
    assert!(issues.iter().any(|i| i.0 == "error"), "{issues:?}");
    let after: std::collections::BTreeMap<_, _> = std::env::vars_os().collect();
    let changed: Vec<_> = after
        .iter()
        .filter(|(k, v)| before.get(*k) != Some(*v))
        .map(|(k, _)| k.to_string_lossy().into_owned())
        .filter(|k| !k.ends_with("BLAS_MAIN_FREE"))
        .collect();
    assert!(changed.is_empty(), "the bridge wrote {changed:?}");
    assert!(before.keys().all(|k| after.contains_key(k)));
}

#[test]
fn a_missing_file_is_named_once_with_its_reason() {
    let dir = tempfile::tempdir().expect("tempdir");
    let missing = dir.path().join("no_such_drop");
    let res = Command::new(env!("CARGO_BIN_EXE_clothsr"))
        .args(["lab", "rollout", "--model"])
        .arg(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/data/models/three_balls_lab/corrector"),
        )
        .arg("--data")
        .arg(&missing)
        .output()
        .expect("run");
    assert!(!res.status.success());
    let stderr = String::from_utf8_lossy(&res.stderr);
    assert!(stderr.contains("no_such_drop"), "{stderr}");
    assert_eq!(
        stderr.matches("No such file or directory").count(),
        1,
        "{stderr}"
    );
}

/// Hostile values of flags that once reached a command's code (one panicked: a
/// `--collider-offset` of two numbers) are refused when parsed: exit code 2, the flag named,
/// no panic, nothing written. The binary's own `hostile` test gives every flag of every
/// command such values in-process.
#[test]
fn hostile_flag_values_are_refused_by_name_not_a_panic() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/sheet_sphere.usda");
    let out = dir.path().join("out.usda");
    for (command, flag) in [
        (&["simulate"][..], "--collider-offset"),
        (&["simulate"][..], "--dt"),
        (&["simulate"][..], "--avatar"),
        (&["lab", "run"][..], "--heat-max-mm"),
        (&["lab", "run"][..], "--garment-offset"),
        (&["run"][..], "--models"),
    ] {
        for v in [
            "",
            "1,2",
            "-1",
            "nan,0,0",
            "1e400,0,0",
            "1,2,3,4",
            "nan",
            "1e308",
            "/nonexistent/x.usda",
        ] {
            let run = Command::new(env!("CARGO_BIN_EXE_clothsr"))
                .args(command)
                .arg(&scene)
                .args(["--frames", "1", "-o"])
                .arg(&out)
                .arg(format!("{flag}={v}"))
                .output()
                .expect("run clothsr");
            let stderr = String::from_utf8_lossy(&run.stderr);
            let case = format!("{command:?} {flag}={v}");
            assert_eq!(run.status.code(), Some(2), "{case}: {stderr}");
            assert!(stderr.contains(flag), "{case}: {stderr}");
            assert!(!stderr.contains("panicked"), "{case}: {stderr}");
            assert!(!out.exists(), "{case}");
        }
    }
}

/// A USD file that states no units is refused with the way on named, and read in the units
/// `--meters-per-unit` gives, which the run logs.
#[test]
fn units_a_file_does_not_state_are_given_on_the_command_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bad/usd/no_meters_per_unit.usda");
    let out = dir.path().join("scene.usda");
    let convert = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_clothsr"))
            .args(extra)
            .arg("convert")
            .arg(&file)
            .arg("-o")
            .arg(&out)
            .output()
            .expect("run clothsr")
    };
    let refused = convert(&[]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(3), "{stderr}");
    assert!(
        stderr.contains("no_meters_per_unit.usda") && stderr.contains("--meters-per-unit"),
        "{stderr}"
    );
    assert!(!out.exists());
    for bad in ["0", "-1", "nan", "x"] {
        let run = convert(&["--meters-per-unit", bad]);
        assert_eq!(run.status.code(), Some(2), "{bad}");
    }
    let done = convert(&["--meters-per-unit", "0.01"]);
    let stderr = String::from_utf8_lossy(&done.stderr);
    assert!(done.status.success(), "{stderr}");
    assert!(stderr.contains("taking 0.01 m per unit"), "{stderr}");
    // The sheet's corner at (-0.15, 0.5, -0.15) units is written in metres (text USD).
    let text = std::fs::read_to_string(&out).expect("read the converted scene");
    assert!(
        text.contains("metersPerUnit = 1") && text.contains("(-0.0015, 0.005, -0.0015)"),
        "{text}"
    );
}

#[test]
fn an_unknown_fabric_is_refused_naming_the_presets() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/sheet_sphere.usda");
    for command in ["simulate", "convert"] {
        let out = Command::new(env!("CARGO_BIN_EXE_clothsr"))
            .arg(command)
            .arg(&scene)
            .args(["--fabric", "kevlar", "-o"])
            .arg(dir.path().join("out.usda"))
            .output()
            .expect("run clothsr");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{command}: {stderr}");
        assert!(
            stderr.contains("unknown fabric 'kevlar' (known: silk, cotton, denim, leather)"),
            "{command}: {stderr}"
        );
        assert!(!dir.path().join("out.usda").exists(), "{command}");
    }
}
