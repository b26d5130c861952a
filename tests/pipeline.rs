//! `clothsr::pipeline` end to end on a tiny scene with a tiny ISR network: the fine USD has one
//! time sample per frame and passes usd-core's validators, the Rerun recording decodes and holds
//! every stage's meshes and timings, a stopped run resumes to exactly the uninterrupted result,
//! and `eval` measures the output against the upsampled baseline.

mod common;

use std::ops::ControlFlow;
use std::path::Path;

use clothsr::eval::{compare, summarise, Animation, Bodies, INSIDE_SEARCH_M};
use clothsr::io::usd::{read_usd, validate_usd, MeshRole};
use clothsr::io::SceneFiles;
use clothsr::msr::model::IsrConfig;
use clothsr::msr::training::IsrTrainingConfig;
use clothsr::msr::Isr;
use clothsr::nn::common::default_device;
use clothsr::pipeline::{
    resume_path, run_to_files, CoarseCalibration, Options, Outputs, Pipeline, Preview, Report,
};
use clothsr::scene::Scene;
use clothsr::sim::collide::{count_inside, max_penetration, push_out, PushOut};
use clothsr::viz::{paths, read_rrd, Recorder};
use nalgebra::Vector3;

const FINE_M: f64 = 0.01;

fn scene() -> Scene {
    common::sheet_over_ball("silk", 0.17)
}

/// An untrained tiny ISR network (its zero-initialised output layer returns the coarse map).
fn tiny_isr() -> Isr {
    let model = IsrConfig::new()
        .with_embed_dim(8)
        .with_depths(vec![2])
        .with_heads(2)
        .with_window(4);
    let cfg = IsrTrainingConfig::new(model, FINE_M).with_patch(16);
    let device = default_device().expect("device");
    let net = cfg.model.init(&device);
    Isr::from_net(cfg, net, device)
}

fn options() -> Options {
    Options {
        coarse_edge_m: 0.04,
        ..Options::default()
    }
}

fn outputs(dir: &Path, name: &str) -> Outputs {
    Outputs {
        fine: dir.join(format!("{name}.usdc")),
        coarse: Some(dir.join(format!("{name}_coarse.usdc"))),
        upsampled: Some(dir.join(format!("{name}_up.usdc"))),
        ascii: false,
        doc: "test".into(),
        resume: true,
        fingerprint: "tiny".into(),
        publish_every_s: 0.0,
        layer: None,
    }
}

fn run(
    isr: &Isr,
    out: &Outputs,
    frames: usize,
    stop_after: Option<usize>,
    rrd: Option<&Path>,
) -> Report {
    let scene = scene();
    let mut p = Pipeline::new(&scene, isr, None, options()).expect("pipeline");
    let rec = rrd.map(|r| Recorder::save("clothsr_test", r).expect("rrd"));
    let preview = rec.as_ref().map(|r| Preview {
        recorder: r,
        ground_truth: None,
        heat_max_m: 0.005,
    });
    let report = run_to_files(&mut p, &scene, frames, out, preview.as_ref(), |g| {
        if Some(g.frame) == stop_after {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    })
    .expect("run");
    if let Some(r) = rec {
        r.finish().expect("finish");
    }
    report
}

/// Without a corrector the coarse membrane's compression factor and knee are the options'
/// (1 and none when unset), and a factor outside (0, 1] or a knee ≤ 0 is refused.
#[test]
fn the_coarse_compression_option_sets_up_the_coarse_membrane() {
    let (scene, isr) = (scene(), tiny_isr());
    let factors = |o: Options| -> Vec<(f64, f64)> {
        let p = Pipeline::new(&scene, &isr, None, o).expect("pipeline");
        let k = &p.coarse.sim.model.membrane_k;
        assert!(!k.is_empty());
        k.iter()
            .map(|k| (k.compression, k.compression_knee))
            .collect()
    };
    assert!(factors(options())
        .iter()
        .all(|&c| c == (1.0, f64::INFINITY)));
    let soft = Options {
        coarse: CoarseCalibration {
            compression: Some(0.1),
            ..CoarseCalibration::default()
        },
        ..options()
    };
    assert!(factors(soft).iter().all(|&c| c == (0.1, f64::INFINITY)));
    let knee = Options {
        coarse: CoarseCalibration {
            compression: Some(0.1),
            compression_knee: Some(0.2),
            ..CoarseCalibration::default()
        },
        ..options()
    };
    assert!(factors(knee).iter().all(|&c| c == (0.1, 0.2)));
    for bad in [
        Options {
            coarse: CoarseCalibration {
                compression: Some(0.0),
                ..CoarseCalibration::default()
            },
            ..options()
        },
        Options {
            coarse: CoarseCalibration {
                compression: Some(0.1),
                compression_knee: Some(-0.2),
                ..CoarseCalibration::default()
            },
            ..options()
        },
    ] {
        assert!(Pipeline::new(&scene, &isr, None, bad).is_err());
    }
}

/// Without a corrector the coarse simulator's friction against bodies is the option's (the
/// simulator's when unset), and a negative or non-finite coefficient is refused.
#[test]
fn the_coarse_friction_option_sets_up_the_coarse_contact() {
    let (scene, isr) = (scene(), tiny_isr());
    let friction = |o: Options| {
        Pipeline::new(&scene, &isr, None, o)
            .map(|p| p.coarse.sim.params.friction)
            .map_err(|e| e.to_string())
    };
    let default = clothsr::sim::SimParams::for_edge(0.02).friction;
    assert_eq!(friction(options()), Ok(default));
    let grip = Options {
        coarse: CoarseCalibration {
            friction: Some(1.0),
            ..CoarseCalibration::default()
        },
        ..options()
    };
    assert_eq!(friction(grip), Ok(1.0));
    for bad in [-0.1, f64::NAN, f64::INFINITY] {
        let o = Options {
            coarse: CoarseCalibration {
                friction: Some(bad),
                ..CoarseCalibration::default()
            },
            ..options()
        };
        let e = friction(o).expect_err("a bad friction coefficient");
        assert!(e.contains("friction"), "{e}");
    }
}

/// Without a corrector the coarse simulator's wrinkle bending is the option's (off when unset
/// or 0), and a negative or non-finite gain is refused.
#[test]
fn the_coarse_wrinkle_bending_option_sets_up_the_coarse_hinges() {
    use clothsr::sim::WrinkleBending;
    let (scene, isr) = (scene(), tiny_isr());
    let wrinkles = |g: Option<f64>| {
        let o = Options {
            coarse: CoarseCalibration {
                wrinkle_bending: g,
                ..CoarseCalibration::default()
            },
            ..options()
        };
        Pipeline::new(&scene, &isr, None, o)
            .map(|p| p.coarse.sim.model.wrinkle_bending())
            .map_err(|e| e.to_string())
    };
    assert_eq!(wrinkles(None), Ok(None));
    assert_eq!(wrinkles(Some(0.0)), Ok(None));
    assert_eq!(
        wrinkles(Some(1.5)),
        Ok(Some(WrinkleBending::with_gain(1.5)))
    );
    for bad in [-0.5, f64::NAN, f64::INFINITY] {
        let e = wrinkles(Some(bad)).expect_err("a bad gain");
        assert!(e.contains("wrinkle bending gain"), "{e}");
    }
}

/// The fine output is pushed out of the colliders (`Options::push_out`, on by default): on
/// the sheet draped over the ball, the 40 mm coarse mesh's chords carried to the fine mesh
/// cut into the ball. Pushed, no fine vertex is inside it, and the output is the network's
/// moved only where a vertex was inside or nearer than the clearance; without, the same
/// frame has vertices inside.
#[test]
fn the_fine_output_is_pushed_out_of_the_colliders() {
    let (scene, isr) = (scene(), tiny_isr());
    let mut outs = Vec::new();
    for push_out in [false, true] {
        let opts = Options {
            push_out,
            ..options()
        };
        let mut p = Pipeline::new(&scene, &isr, None, opts).expect("pipeline");
        p.super_resolve().expect("frame 0");
        for _ in 0..8 {
            p.advance_frame().expect("frame");
        }
        let points = p.coarse.collider_points();
        let ball = [(
            points[0].as_slice(),
            p.coarse.colliders[0].triangles.as_slice(),
        )];
        let depth = max_penetration(&p.fine.positions, &ball);
        assert_eq!(p.push_clearance_m().is_some(), push_out);
        let clearance = p.push_clearance_m().unwrap_or_default();
        outs.push((
            p.fine.positions.clone(),
            depth,
            p.pushed,
            ball[0].0.to_vec(),
            clearance,
        ));
    }
    let [(raw, raw_depth, none, pts, _), (pushed, depth, stats, _, clearance)] = &outs[..] else {
        unreachable!()
    };
    assert_eq!(*none, PushOut::default());
    assert!(
        *raw_depth > 2e-4,
        "the chords cut {raw_depth} m into the ball"
    );
    assert_eq!(*depth, 0.0);
    assert!(
        stats.inside > 0 && (stats.max_depth_m - raw_depth).abs() < 1e-9,
        "{stats:?}"
    );
    // The pushed output is the raw one pushed out, and moved only where it was pushed.
    let mut again = raw.clone();
    let tris = &scene.colliders[0].triangles;
    assert!(*clearance > 1e-4 && *clearance < 1e-3, "{clearance}");
    assert_eq!(push_out(&mut again, &[(pts, tris)], *clearance), *stats);
    assert_eq!(&again, pushed);
    let moved = raw.iter().zip(pushed).filter(|(a, b)| a != b).count();
    assert_eq!(moved, stats.moved);
}

fn cloth_frames(path: &Path) -> Vec<Vec<Vector3<f32>>> {
    let stage = read_usd(path).expect("read");
    let cloth: Vec<_> = stage
        .meshes
        .into_iter()
        .filter(|m| m.role == MeshRole::Cloth)
        .collect();
    assert_eq!(cloth.len(), 1, "{}", path.display());
    cloth.into_iter().next().expect("cloth").frames
}

#[test]
fn a_run_writes_valid_usd_and_rerun_files_and_resumes_exactly() {
    let dir = tempfile::tempdir().expect("tmp");
    let isr = tiny_isr();
    let frames = 3;

    // Uninterrupted, with a recording. A temporary file that a killed writer left is removed.
    let rrd = dir.path().join("full.rrd");
    let full = outputs(dir.path(), "full");
    let stale = dir.path().join(".full.clothsr-tmp-2147483600.usdc");
    std::fs::write(&stale, b"left by a killed run").expect("write");
    let report = run(&isr, &full, frames, None, Some(&rrd));
    assert!(!report.stopped && report.frames_computed == frames);
    assert!(!resume_path(&full.fine).exists(), "resume point left");
    assert!(!stale.exists(), "stale temporary file left");
    for path in [
        &full.fine,
        full.coarse.as_ref().expect("coarse"),
        full.upsampled.as_ref().expect("up"),
    ] {
        let f = cloth_frames(path);
        assert_eq!(f.len(), frames + 1, "{}", path.display());
        assert!(f.iter().flatten().all(|p| p.iter().all(|c| c.is_finite())));
        let errors: Vec<_> = validate_usd(path)
            .expect("validate")
            .into_iter()
            .filter(|(severity, _, _)| severity == "error")
            .collect();
        assert!(errors.is_empty(), "{}: {errors:?}", path.display());
    }
    let fine = cloth_frames(&full.fine);
    // The sheet falls under gravity: the last frame is lower than the first.
    let mean_y = |f: &[Vector3<f32>]| f.iter().map(|p| p.y as f64).sum::<f64>() / f.len() as f64;
    assert!(mean_y(&fine[frames]) < mean_y(&fine[0]) - 1e-3);
    // The output carries the ball, and `eval` counts cloth inside it: none in the falling
    // sheet; sunk 5 cm, the vertices over the ball's top are, as the scene's ball says.
    let bodies = Bodies::read_usd(&full.fine).expect("bodies");
    assert!(!bodies.is_empty());
    let x: Vec<Vector3<f64>> = fine[frames].iter().map(|p| p.cast()).collect();
    assert_eq!(bodies.inside(&x, frames as f64).inside, 0);
    let sunk: Vec<Vector3<f64>> = x.iter().map(|p| p - Vector3::new(0.0, 0.05, 0.0)).collect();
    let got = bodies.inside(&sunk, frames as f64);
    let (n, depth) = (got.inside, got.max_depth_m);
    let ball = &scene().colliders[0];
    let mut points = Vec::new();
    ball.positions_at(0.0, &mut points);
    let want = count_inside(&sunk, &[(&points, &ball.triangles)], INSIDE_SEARCH_M);
    assert!(want.inside > 100, "{want:?}");
    assert!(n.abs_diff(want.inside) <= 2, "{n} against {want:?}");
    assert!(
        (depth - want.max_depth_m).abs() < 1e-5,
        "{depth} against {want:?}"
    );

    let summary = read_rrd(&rrd).expect("a valid recording");
    for entity in [
        paths::FINE.to_string(),
        paths::M_INT.to_string(),
        format!("{}/ball", paths::COLLIDERS),
        format!("{}/simulator_s", paths::TIMINGS),
        format!("{}/msr_s", paths::TIMINGS),
        paths::PUSHED_OUT.to_string(),
    ] {
        assert!(summary.entities.contains(&entity), "{entity}: {summary:?}");
    }
    assert!(std::fs::metadata(&rrd).expect("rrd").len() > 1000);

    // Stopped after frame 1, then called again: resumes after frame 1 and ends bit-identical.
    let part = outputs(dir.path(), "part");
    let stopped = run(&isr, &part, frames, Some(1), None);
    assert!(stopped.stopped);
    assert!(resume_path(&part.fine).exists());
    assert_eq!(cloth_frames(&part.fine).len(), 2);
    let resumed = run(&isr, &part, frames, None, None);
    assert_eq!(resumed.resumed_after, Some(1));
    assert_eq!(resumed.frames_computed, frames - 1);
    assert!(!resume_path(&part.fine).exists());
    assert_eq!(cloth_frames(&part.fine), fine);
    assert_eq!(
        cloth_frames(part.coarse.as_ref().expect("coarse")),
        cloth_frames(full.coarse.as_ref().expect("coarse"))
    );

    // A resume point written with other settings is ignored: the run starts over.
    let other = Outputs {
        fingerprint: "other".into(),
        ..outputs(dir.path(), "other")
    };
    run(&isr, &other, 2, Some(1), None);
    assert!(resume_path(&other.fine).exists());
    let again = run(
        &isr,
        &Outputs {
            fingerprint: "third".into(),
            ..other
        },
        2,
        None,
        None,
    );
    assert_eq!(again.resumed_after, None);

    // eval: the output against itself is exact; against the upsampled coarse mesh it differs
    // by the network's (zero) detail only through Phong tessellation, a few tenths of a mm.
    let gt = Animation::read_usd(&full.fine).expect("gt");
    let same = compare(
        &gt,
        &Animation::read_usd(&part.fine).expect("pred"),
        &part.fine,
    )
    .expect("compare");
    assert_eq!(same.len(), frames + 1);
    assert!(
        same.iter()
            .all(|m| m.mean_mm == 0.0 && m.max_mm == 0.0 && m.normal_deg < 1e-5),
        "{same:?}"
    );
    let up_path = full.upsampled.as_ref().expect("up");
    let up = compare(&gt, &Animation::read_usd(up_path).expect("up"), up_path).expect("compare");
    let s = summarise(&up);
    assert!(s.mean_mm > 0.0 && s.mean_mm < 5.0, "{s:?}");
    assert!(s.jitter_mm > 0.0 && s.gt_jitter_mm > 0.0, "{s:?}");
    // A file with other cloth is refused, naming it.
    let coarse_path = full.coarse.as_ref().expect("coarse");
    let err = compare(
        &gt,
        &Animation::read_usd(coarse_path).expect("coarse"),
        coarse_path,
    )
    .expect_err("different meshes");
    assert!(err.to_string().contains("do not match"), "{err}");
}

/// The models shipped for the samples (made by `clothsr fit`; the README's demo runs the
/// first) and the research models with a corrector still load with today's code and run the
/// whole pipeline (corrector included) on their sample scene: a frame of finite fine positions
/// on the 2.5 mm mesh they were trained for.
#[test]
fn shipped_sample_models_run_a_frame_of_their_scene() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    // (folder, scene, whether a corrector ships)
    for (models, scene, ships_corrector) in [
        (
            "samples/models/three_balls",
            "sheet_three_balls.usda",
            false,
        ),
        ("samples/models/table", "sheet_table.usda", false),
        (
            "tests/data/models/three_balls_lab",
            "sheet_three_balls.usda",
            true,
        ),
    ] {
        let models = root.join(models);
        let isr = Isr::load(&models.join("isr")).expect("the shipped ISR model loads");
        assert!((isr.cfg.pixel_m - 0.0025).abs() < 1e-12);
        let scene = clothsr::scene::Scene::load(
            &root.join("samples").join(scene),
            &clothsr::garment::Fabric::preset("cotton").expect("preset"),
        )
        .expect("scene");
        let corrector = models.join("corrector");
        assert_eq!(corrector.join("config.json").exists(), ships_corrector);
        let corrector = ships_corrector.then_some(corrector.as_path());
        if corrector.is_some() {
            // A coarse membrane or friction the corrector was not trained beside is refused.
            for (other, what) in [
                (
                    Options {
                        coarse: CoarseCalibration {
                            compression: Some(0.5),
                            ..CoarseCalibration::default()
                        },
                        ..Options::default()
                    },
                    "compression factor",
                ),
                (
                    Options {
                        coarse: CoarseCalibration {
                            friction: Some(0.9),
                            ..CoarseCalibration::default()
                        },
                        ..Options::default()
                    },
                    "friction",
                ),
                (
                    Options {
                        coarse: CoarseCalibration {
                            wrinkle_bending: Some(1.0),
                            ..CoarseCalibration::default()
                        },
                        ..Options::default()
                    },
                    "wrinkle bending",
                ),
                (
                    Options {
                        coarse: CoarseCalibration {
                            bending: Some(1.5),
                            ..CoarseCalibration::default()
                        },
                        ..Options::default()
                    },
                    "bending stiffness",
                ),
                (
                    Options {
                        coarse: CoarseCalibration {
                            crease_contacts: Some(false),
                            ..CoarseCalibration::default()
                        },
                        ..Options::default()
                    },
                    "crease contacts",
                ),
            ] {
                let err = Pipeline::new(&scene, &isr, corrector, other)
                    .err()
                    .expect(what);
                assert!(err.to_string().contains(what), "{err}");
            }
        }
        if corrector.is_some() {
            // A gain of 0 is no wrinkle bending, as the corrector was trained.
            let off = Options {
                coarse: CoarseCalibration {
                    wrinkle_bending: Some(0.0),
                    ..CoarseCalibration::default()
                },
                ..Options::default()
            };
            assert!(Pipeline::new(&scene, &isr, corrector, off).is_ok());
        }
        // Without a corrector, the folder's own coarse model (the one `clothsr fit` chose on
        // its training variations), as `clothsr run` and `clothsr bench` take it.
        let (opts, cal) =
            clothsr::pipeline::options_for_run(&models, corrector, Options::default())
                .expect("a valid coarse.json, if any");
        let mut p = Pipeline::new(&scene, &isr, corrector, opts).expect("set up");
        if !ships_corrector {
            let own = CoarseCalibration::load(&models)
                .expect("a valid coarse.json")
                .expect("fit leaves a coarse.json");
            assert_eq!(cal, Some(own));
            let k = &p.coarse.sim.model.membrane_k;
            let c = own.compression.unwrap_or(1.0);
            assert!(k.iter().all(|k| k.compression == c), "{:?}", k.first());
            if let Some(f) = own.friction {
                assert_eq!(p.coarse.sim.params.friction, f);
            }
        }
        if ships_corrector {
            // Without its corrector (`run --no-corrector`), the coarse model `clothsr
            // calibrate` chose on the three balls' training drops.
            let (opts, cal) = clothsr::pipeline::options_for_run(&models, None, Options::default())
                .expect("a valid coarse.json");
            let chosen = CoarseCalibration {
                compression: Some(0.01),
                friction: Some(2.5),
                wrinkle_bending: Some(1.0),
                ..CoarseCalibration::default()
            };
            assert_eq!(cal, Some(chosen));
            let alone = Pipeline::new(&scene, &isr, None, opts).expect("set up");
            assert_eq!(alone.coarse.sim.params.friction, 2.5);
            let k = &alone.coarse.sim.model.membrane_k;
            assert!(k.iter().all(|k| k.compression == 0.01), "{:?}", k.first());
        }
        assert_eq!(p.has_corrector(), ships_corrector);
        assert_eq!(p.fine.num_vertices(), 44_923, "{}", models.display());
        let first: Vec<Vector3<f64>> = p.super_resolve().expect("frame 0").to_vec();
        let x = p.advance_frame().expect("frame 1");
        assert!(x.iter().all(|q| q.iter().all(|c| c.is_finite())));
        // The sheet falls during its first frame (1/30 s): it moves, by millimetres, not
        // metres.
        let moved = x
            .iter()
            .zip(&first)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(
            moved > 1e-4 && moved < 0.05,
            "{}: {moved}",
            models.display()
        );
    }
}

/// A models folder's `coarse.json`: absent is none; fields fill only unset options; a bad
/// value or an unknown field is refused, naming the file.
#[test]
fn coarse_calibration_files_are_checked_and_fill_only_unset_options() {
    let dir = tempfile::tempdir().expect("tmp");
    assert_eq!(CoarseCalibration::load(dir.path()).expect("absent"), None);
    let file = dir.path().join(CoarseCalibration::FILE);
    std::fs::write(
        &file,
        r#"{"compression": 0.01, "friction": 2.5, "wrinkle_bending": 1, "bending": 1.5,
            "crease_contacts": false}"#,
    )
    .expect("write");
    let cal = CoarseCalibration::load(dir.path())
        .expect("valid")
        .expect("present");
    assert_eq!(
        cal.to_string(),
        "compression 0.01, friction 2.5, wrinkle bending 1, bending 1.5, no crease contacts"
    );
    let given = Options {
        coarse: CoarseCalibration {
            friction: Some(0.3),
            ..CoarseCalibration::default()
        },
        ..Options::default()
    };
    let filled = given.filled_from(&cal);
    assert_eq!(filled.coarse.compression, Some(0.01));
    assert_eq!(filled.coarse.compression_knee, None);
    assert_eq!(filled.coarse.friction, Some(0.3), "an option given wins");
    assert_eq!(filled.coarse.wrinkle_bending, Some(1.0));
    assert_eq!(filled.coarse.bending, Some(1.5));
    assert_eq!(filled.coarse.crease_contacts, Some(false));
    assert_eq!(filled.coarse_edge_m, given.coarse_edge_m);
    // As a run takes it: filled without a corrector, untouched beside one.
    let (run_opts, used) =
        clothsr::pipeline::options_for_run(dir.path(), None, given).expect("run");
    assert_eq!((run_opts, used), (filled, Some(cal)));
    let (run_opts, used) =
        clothsr::pipeline::options_for_run(dir.path(), Some(dir.path()), given).expect("run");
    assert_eq!((run_opts, used), (given, None));
    // A knee of 0 is none, in the file as in the options.
    std::fs::write(&file, r#"{"compression": 0.03, "compression_knee": 0}"#).expect("write");
    let cal = CoarseCalibration::load(dir.path())
        .expect("valid")
        .expect("present");
    assert_eq!(cal.compression_knee, Some(0.0));
    for (text, expected) in [
        (
            r#"{"compression": 2}"#,
            "compression must be in (0, 1], got 2",
        ),
        (
            r#"{"compression_knee": -1}"#,
            "compression_knee must be a shortening > 0",
        ),
        (
            r#"{"friction": -1}"#,
            "friction: the friction coefficient must be finite",
        ),
        (
            r#"{"wrinkle_bending": -1}"#,
            "wrinkle_bending: the wrinkle bending gain",
        ),
        (r#"{"bending": 0}"#, "bending must be a factor > 0, got 0"),
        (r#"{"compresion": 0.1}"#, "unknown field `compresion`"),
        ("0.03", "not a coarse calibration"),
    ] {
        std::fs::write(&file, text).expect("write");
        let err = CoarseCalibration::load(dir.path())
            .err()
            .unwrap_or_else(|| panic!("{text} accepted"))
            .to_string();
        assert!(
            err.contains(expected) && err.contains("coarse.json"),
            "{text}: {err}"
        );
    }
}

/// Issue 48: a models folder's `models.json` decides whether `run` uses the corrector
/// (`--corrector auto`); `on` needs a corrector; a bad manifest is refused, naming the file;
/// every shipped folder has a valid one.
#[test]
fn the_run_takes_the_better_validated_path_of_a_models_folder() {
    use clothsr::pipeline::{choose_path, CorrectorChoice, ModelPath, ModelsManifest};
    let dir = tempfile::tempdir().expect("tmp");
    let models = dir.path();
    let auto = |m: &Path| choose_path(m, CorrectorChoice::Auto).map(|(p, _)| p);
    // No corrector, no manifest: the coarse model alone; `on` is refused.
    assert_eq!(auto(models).expect("auto"), ModelPath::CoarseAlone);
    let err = choose_path(models, CorrectorChoice::On).expect_err("no corrector");
    assert!(err.to_string().contains("no corrector"), "{err}");
    // A corrector and no manifest: the corrector.
    std::fs::create_dir_all(models.join("corrector")).expect("mkdir");
    std::fs::write(models.join("corrector/config.json"), "{}").expect("write");
    assert_eq!(auto(models).expect("auto"), ModelPath::Corrector);
    // A manifest: its better path, and the reason names both figures.
    let manifest = |best: &str, corrector_mm: f64| {
        format!(
            r#"{{"format_version": 1, "scene": "s.usda", "held_out": "test", "protocol": "p",
                "paths": {{"corrector": {{"fine_error_mm": {corrector_mm}}},
                           "coarse_alone": {{"fine_error_mm": 3.85, "baseline_mm": 8.75}}}},
                "best": "{best}"}}"#
        )
    };
    let file = models.join(ModelsManifest::FILE);
    std::fs::write(&file, manifest("coarse_alone", 7.39)).expect("write");
    let (path, why) = choose_path(models, CorrectorChoice::Auto).expect("auto");
    assert_eq!(path, ModelPath::CoarseAlone);
    assert!(why.contains("3.85") && why.contains("7.39"), "{why}");
    assert_eq!(
        choose_path(models, CorrectorChoice::On).expect("on").0,
        ModelPath::Corrector
    );
    std::fs::write(&file, manifest("corrector", 2.0)).expect("write");
    assert_eq!(auto(models).expect("auto"), ModelPath::Corrector);
    assert_eq!(
        choose_path(models, CorrectorChoice::Off).expect("off").0,
        ModelPath::CoarseAlone
    );
    // Refused, naming the file: a best that is not a path, a negative figure, an unknown
    // path, another format version, a corrector's figures in a folder without one.
    for (text, says) in [
        (manifest("isr", 2.0), "unknown variant `isr`"),
        (manifest("corrector", -1.0), "finite"),
        (
            manifest("corrector", 2.0).replace("\"coarse_alone\"", "\"coarse\""),
            "unknown variant `coarse`",
        ),
        (
            manifest("corrector", 2.0).replace("\"format_version\": 1", "\"format_version\": 7"),
            "format_version 7",
        ),
    ] {
        std::fs::write(&file, text).expect("write");
        let err = auto(models).expect_err(says);
        let msg = err.to_string();
        assert!(msg.contains("models.json") && msg.contains(says), "{msg}");
    }
    std::fs::remove_dir_all(models.join("corrector")).expect("rm");
    std::fs::write(&file, manifest("coarse_alone", 2.0)).expect("write");
    assert!(auto(models)
        .expect_err("no corrector")
        .to_string()
        .contains("no corrector"));
    // The shipped folders' manifests are valid and their best path is what `run` takes.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for folder in [
        "samples/models/three_balls",
        "samples/models/table",
        "samples/models/skirt",
        "tests/data/models/three_balls_lab",
        "tests/data/models/skirt_lab",
    ] {
        let m = ModelsManifest::load(&root.join(folder))
            .expect("valid")
            .expect("every shipped folder has a models.json");
        assert_eq!(auto(&root.join(folder)).expect("auto"), m.best, "{folder}");
    }
}
