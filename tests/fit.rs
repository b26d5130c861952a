//! `clothsr fit`: a deterministic plan, tasks run in order, resumed after a stop with the
//! same result, a held-out report (on the sample sheet at 40 mm / 10 mm, a few frames).

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use clothsr::data::SceneSource;
use clothsr::pipeline::fit::{self, FitOptions, Plan, Quality, Role, TaskKind};

/// The sample sheet's scene, in folder `root` (a copy of it is made there).
fn shot(root: &Path) -> SceneSource {
    let scene = root.join("sheet_sphere.usda");
    if !scene.exists() {
        std::fs::create_dir_all(root).expect("mkdir");
        let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/sheet_sphere.usda");
        std::fs::copy(sample, &scene).expect("copy the sample");
    }
    SceneSource {
        scene,
        colliders: Vec::new(),
        avatar: None,
        fabric: "cotton".into(),
    }
}

fn options() -> FitOptions {
    FitOptions {
        quality: Quality::Preview,
        coarse_edge_m: 0.04,
        fine_edge_m: 0.01,
        frames: Some(3),
        isr_steps: Some(20),
        generic_isr: None,
    }
}

fn plan(root: &Path) -> Plan {
    let scene = shot(root).load().expect("scene");
    Plan::new(shot(root), &scene, &options()).expect("plan")
}

/// Every text file under `dir` that names `needle`.
fn naming(dir: &Path, needle: &str) -> Vec<PathBuf> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir).expect("read_dir") {
        let path = entry.expect("entry").path();
        if path.is_dir() {
            found.extend(naming(&path, needle));
        } else if std::fs::read_to_string(&path).is_ok_and(|t| t.contains(needle)) {
            found.push(path);
        }
    }
    found
}

fn read(path: PathBuf) -> Vec<u8> {
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn a_fit_plans_deterministically_resumes_after_stops_and_reports() {
    let tmp = tempfile::tempdir().expect("tmp");
    let repo = tmp.path().join("repo");
    let p = plan(&repo);
    assert_eq!(p, plan(&repo));
    let json = serde_json::to_string(&p).expect("json");
    assert_eq!(serde_json::from_str::<Plan>(&json).expect("parse"), p);
    assert_eq!(p.of_role(Role::Train).count(), 2);
    assert_eq!(p.of_role(Role::HeldOut).count(), 1);
    // Each task comes after those it needs; a data set per variation.
    for (k, t) in p.tasks.iter().enumerate() {
        for a in &t.after {
            assert!(
                p.tasks[..k].iter().any(|u| &u.id == a),
                "{} before {a}",
                t.id
            );
        }
    }
    let datasets = p
        .tasks
        .iter()
        .filter(|t| matches!(t.kind, TaskKind::Dataset { .. }))
        .count();
    assert_eq!(datasets, p.variations.len());

    let (a, b) = (repo.join("a"), repo.join("b"));
    assert!(fit::run(&p, &a, |_| ControlFlow::Continue(())).expect("fit"));
    // Stopped before the second data set, then in the middle of the ISR training.
    let stop_at = |what: &'static str| {
        move |f: &fit::FitProgress| {
            if f.message.starts_with(what) {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        }
    };
    assert!(!fit::run(&p, &b, stop_at("data_train_1: started")).expect("fit"));
    assert!(b.join("tasks/data_train_0.done").exists());
    assert!(!b.join("tasks/data_train_1.done").exists());
    // Another process running that task: a second fit there is refused, naming it.
    {
        let held = std::fs::File::create(b.join("tasks/data_train_1.lock")).expect("lock file");
        held.lock().expect("lock");
        let err = fit::run(&p, &b, |_| ControlFlow::Continue(())).expect_err("refused");
        assert!(
            err.to_string().contains("'data_train_1'")
                && err.to_string().contains("another process"),
            "{err}"
        );
    }
    assert!(!fit::run(&p, &b, stop_at("train_isr: step 10/")).expect("fit"));
    assert!(b.join("isr/checkpoint").exists());
    assert!(!b.join("tasks/train_isr.done").exists());
    assert!(fit::run(&p, &b, |_| ControlFlow::Continue(())).expect("fit"));
    // The simulations and the calibration are the same to the bit. The network's training is
    // not, even without a stop (the CPU backend's threaded sums): its held-out error is.
    for file in [
        "plan.json",
        "coarse.json",
        "data/train_1/frames/frame_00003.safetensors",
        "data/held_out_0/frames/frame_00003.safetensors",
    ] {
        assert!(read(a.join(file)) == read(b.join(file)), "{file} differs");
    }
    let mean_isr = |dir: &Path| {
        let csv = String::from_utf8(read(dir.join("held_out.csv"))).expect("utf-8");
        let v: Vec<f64> = csv
            .lines()
            .skip(1)
            .filter_map(|l| l.split(',').nth(2)?.parse().ok())
            .collect();
        assert_eq!(v.len(), 3, "{csv}");
        v.iter().sum::<f64>() / v.len() as f64
    };
    let (ea, eb) = (mean_isr(&a), mean_isr(&b));
    assert!(
        ea.is_finite() && (ea - eb).abs() <= 0.02 * ea,
        "{ea} vs {eb} mm"
    );
    let report = String::from_utf8(read(a.join("report.md"))).expect("utf-8");
    assert!(report.contains("| held_out_0 |"), "{report}");
    // Pictures of the held-out variation's first, middle and last frames, the fine simulation
    // beside the fit's models, where Blender is installed (`bash .ci/setup` makes .venv-bpy).
    if clothsr::io::render::renderer().is_ok() {
        let pictures: Vec<&str> = report
            .lines()
            .filter_map(|l| l.strip_prefix("![held_out_0 ")?.split("](").nth(1))
            .map(|l| l.trim_end_matches(')'))
            .collect();
        assert_eq!(pictures.len(), 3, "{report}");
        for p in pictures {
            let png = read(a.join(p));
            assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "{p}");
            let size =
                |at: usize| u32::from_be_bytes([png[at], png[at + 1], png[at + 2], png[at + 3]]);
            // Two panels of 320 × 400 pixels side by side, under their labels.
            assert!(
                size(16) >= 2 * 320 && size(20) >= 400 && size(16) < 3 * 320,
                "{p}: {} × {}",
                size(16),
                size(20)
            );
        }
    } else {
        assert!(report.contains("held_out_0: no pictures"), "{report}");
    }
    assert!(!a.join("isr/checkpoint").exists());
    // A finished fit leaves no lock files.
    let locks = std::fs::read_dir(a.join("tasks"))
        .expect("tasks")
        .filter(|e| {
            e.as_ref()
                .is_ok_and(|e| e.path().extension().is_some_and(|x| x == "lock"))
        })
        .count();
    assert_eq!(locks, 0);
    // The folder's manifest: the whole pipeline held out, beside the paper's baseline, which
    // the held-out variation's own coarse and fine simulations do not match exactly.
    let m = clothsr::pipeline::ModelsManifest::load(&a)
        .expect("models.json")
        .expect("written");
    let f = m.paths[&clothsr::pipeline::ModelPath::CoarseAlone];
    let base = f.baseline_mm.expect("baseline");
    assert!(f.fine_error_mm > 0.0 && base > 0.0, "{f:?}");
    assert!(
        f.fine_error_mm < 10.0 * base && base < 10.0 * f.fine_error_mm,
        "{f:?}"
    );
    assert!(m.held_out.contains("held_out_0"), "{}", m.held_out);
    // The held-out variation's twin (its predictability floor) resumed its source's fork.
    assert!(a.join("data/held_out_0_twin/manifest.json").exists());
    assert!(report.contains("fit's / floor"), "{report}");
    // The pipeline against the twin, per frame: by the triangle inequality (per vertex, so
    // for the mean too) it differs from the pipeline against the fine simulation by at most
    // the two fine simulations' distance.
    let gt = clothsr::eval::Animation::read_dataset(&a.join("data/held_out_0"), 0.0).expect("gt");
    let twin =
        clothsr::eval::Animation::read_dataset(&a.join("data/held_out_0_twin"), 0.0).expect("twin");
    let csv = String::from_utf8(read(a.join("held_out.csv"))).expect("utf-8");
    let (mut rows, mut apart) = (0, 0);
    for (k, line) in csv.lines().skip(1).enumerate() {
        let v: Vec<f64> = line
            .split(',')
            .skip(4)
            .map(|x| x.parse().expect("a number"))
            .collect();
        let &[fit, base, to_twin] = v.as_slice() else {
            panic!("{line}");
        };
        let floor = clothsr::metrics::mean_distance_mm(&gt.frames[k], &twin.frames[k]);
        assert!(fit > 0.0 && base > 0.0 && to_twin > 0.0, "{line}");
        // The CSV's four decimals.
        assert!(
            (fit - to_twin).abs() <= floor + 2e-4,
            "{line}: floor {floor} mm"
        );
        // Measured against the twin, not the fine simulation again.
        if floor > 1e-3 && (fit - to_twin).abs() > 1e-4 {
            apart += 1;
        }
        rows += 1;
    }
    assert_eq!(rows, 3);
    assert!(apart > 0, "{csv}");
    // The mean distance to the two is at least half the floor: the report's last column.
    let row = report
        .lines()
        .find(|l| l.starts_with("| held_out_0 |") && l.split('|').count() == 10)
        .unwrap_or_else(|| panic!("{report}"));
    let both: f64 = row
        .split('|')
        .nth(8)
        .expect("column")
        .trim()
        .parse()
        .expect("a number");
    assert!(both >= 0.99, "{row}");
    assert!(report.contains("fit's to the twin"), "{report}");
    // Another plan is not mixed into a fit's folder.
    let other = Plan::new(
        shot(&repo),
        &shot(&repo).load().expect("scene"),
        &FitOptions {
            quality: Quality::Final,
            ..options()
        },
    )
    .expect("plan");
    let err = fit::run(&other, &a, |_| ControlFlow::Continue(())).expect_err("refused");
    assert!(err.to_string().contains("plan.json"), "{err}");

    // The folder names what it was made from relative to itself: moved with the shot (a
    // repository cloned elsewhere), its plan and data sets still find it, and the fit is done.
    let root = tmp.path().to_string_lossy().into_owned();
    assert_eq!(naming(&a, &root), Vec::<PathBuf>::new());
    let moved = tmp.path().join("moved");
    std::fs::rename(&repo, &moved).expect("move");
    let scene = moved.join("sheet_sphere.usda");
    let again = Plan::load(&moved.join("a")).expect("plan");
    assert_eq!(again.shot.scene, scene);
    assert_eq!(
        again,
        Plan {
            shot: shot(&moved),
            ..p
        }
    );
    let m = clothsr::data::read_manifest(&moved.join("a/data/held_out_0_twin")).expect("read");
    assert_eq!(m.source.expect("source").scene, scene);
    let fork = m.fork.expect("a fork");
    assert_eq!(fork.from, moved.join("a/data/held_out_0"));
    let mut ran = Vec::new();
    let done = fit::run(&again, &moved.join("a"), |f| {
        ran.push(f.message.clone());
        ControlFlow::Continue(())
    })
    .expect("fit");
    assert!(done && ran == ["done"], "{ran:?}");
}
