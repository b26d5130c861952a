//! `clothsr::data`: training data from a fine simulation, downsampled to M_int, with one
//! coarse step from each M_int (M_c); resumable.

mod common;

use clothsr::data::{read_frame_positions, read_manifest, Variation};
use clothsr::dataset::{fork, generate, Options};
use clothsr::io::tensors::TensorReader;
use clothsr::scene::Scene;
use nalgebra::Vector3;

fn scene() -> Scene {
    common::sheet_over_ball("cotton", 0.18)
}

fn opts(frames: usize) -> Options {
    Options {
        coarse_edge_m: 0.04,
        fine_edge_m: 0.015,
        frames,
        dress: true,
        self_collision: true,
        variation: Variation {
            garment_offset_m: [0.0, 0.01, 0.0],
            collider_offset_m: [0.0, 0.0, 0.0],
            ..Variation::default()
        },
        fast: false,
        fine_mode: clothsr::sim::step::SolverMode::Data,
        match_contact_thickness: false,
        source: None,
    }
}

#[test]
fn dataset_holds_int_and_coarse_steps_and_resumes_after_a_kill() {
    let dir = tempfile::tempdir().expect("tmp");
    let whole = dir.path().join("whole");
    let m = generate(&scene(), "test", &opts(3), &whole, |_| {}).expect("generate");
    assert_eq!(m.frames_done, 3);
    assert_eq!(read_manifest(&whole).expect("manifest"), m);
    let meshes = TensorReader::open(&whole.join("meshes.safetensors")).expect("meshes");
    let (shape, _) = meshes.f64("coarse_material").expect("material");
    assert_eq!(shape, vec![m.coarse_vertices, 2]);

    let f = read_frame_positions(&whole, 3).expect("frame 3");
    assert_eq!(f.int_x.0, vec![m.steps_per_frame, m.coarse_vertices, 3]);
    assert_eq!(f.fine_x.0, vec![m.fine_vertices, 3]);
    assert!(f.int_x.1.iter().chain(&f.coarse_x.1).all(|v| v.is_finite()));
    // M_c is one coarse step from the previous M_int: close to M_int, but not equal.
    let diff: Vec<f32> = f
        .int_x
        .1
        .iter()
        .zip(&f.coarse_x.1)
        .map(|(a, b)| (a - b).abs())
        .collect();
    let max = diff.iter().copied().fold(0.0, f32::max);
    assert!(max > 1e-7, "the coarse step changed nothing");
    assert!(max < 5e-3, "M_c is {max} m from M_int after one step");
    // The sheet fell between frames 1 and 3.
    let f1 = read_frame_positions(&whole, 1).expect("frame 1");
    let y = |v: &[f32]| v.iter().skip(1).step_by(3).sum::<f32>() / (v.len() / 3) as f32;
    assert!(y(&f.fine_x.1) < y(&f1.fine_x.1));

    // A run killed after frame 1 and started again continues where it stopped.
    let split = dir.path().join("split");
    generate(&scene(), "test", &opts(1), &split, |_| {}).expect("first part");
    let mut first = None;
    let resumed = generate(&scene(), "test", &opts(3), &split, |p| {
        first.get_or_insert(p.frames_done);
    })
    .expect("resume");
    assert_eq!(first, Some(1), "resumed after the finished frame");
    assert_eq!(resumed.frames_done, 3);
    let g = read_frame_positions(&split, 3).expect("frame 3");
    // Exactly: a resumed run is the run that was not stopped (the state, the seams' rest
    // lengths and both simulators' detection margins are saved with every frame).
    assert_eq!(g.fine_x.1, f.fine_x.1, "the resumed run differs");
    assert_eq!(g.int_x.1, f.int_x.1, "the resumed run's M_int differs");
    assert_eq!(g.coarse_x.1, f.coarse_x.1, "the resumed run's M_c differs");

    // Another scene in the same directory is refused, naming the manifest.
    let mut other = opts(3);
    other.variation.garment_offset_m = [0.0, 0.05, 0.0];
    let e = generate(&scene(), "test", &other, &split, |_| {})
        .expect_err("different data set")
        .to_string();
    assert!(e.contains("manifest.json"), "{e}");
}

#[test]
fn a_fork_continues_a_data_set_from_its_frame_moved_by_the_offset() {
    let dir = tempfile::tempdir().expect("tmp");
    let whole = dir.path().join("whole");
    generate(&scene(), "test", &opts(3), &whole, |_| {}).expect("generate");

    // Unmoved, a fork is the same simulation resumed: it lands where the original did.
    let same = dir.path().join("same");
    let m = fork(&whole, 1, Vector3::zeros(), &same).expect("fork");
    assert_eq!(m.frames_done, 1);
    assert_eq!(m.fork.as_ref().map(|f| f.frame), Some(1));
    generate(
        &scene(),
        &m.scene,
        &Options::of_manifest(&m, 3),
        &same,
        |_| {},
    )
    .expect("continue");
    let fine = |d: &std::path::Path, k| read_frame_positions(d, k).expect("frame").fine_x.1;
    let gap = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f32::max)
    };
    assert_eq!(fine(&same, 3), fine(&whole, 3));
    let manifest = read_manifest(&same).expect("manifest");
    assert_eq!(manifest.frames_done, 3);
    assert_eq!(
        manifest.fork, m.fork,
        "the continued data set still names its fork"
    );

    // Moved 3 mm sideways at the end of frame 1, frame 1 is shared and frame 3 is not.
    let moved = dir.path().join("moved");
    let m = fork(&whole, 1, Vector3::new(0.003, 0.0, 0.0), &moved).expect("fork");
    let r = TensorReader::open(&moved.join("frames/frame_00001.safetensors")).expect("frame 1");
    let o = TensorReader::open(&whole.join("frames/frame_00001.safetensors")).expect("frame 1");
    let (x, x0) = (
        r.f64("resume_fine_x").expect("x").1,
        o.f64("resume_fine_x").expect("x").1,
    );
    for (k, (a, b)) in x.iter().zip(&x0).enumerate() {
        let want = if k % 3 == 0 { 0.003 } else { 0.0 };
        assert!(
            (a - b - want).abs() < 1e-12,
            "component {k}: moved by {}",
            a - b
        );
    }
    generate(
        &scene(),
        &m.scene,
        &Options::of_manifest(&m, 3),
        &moved,
        |_| {},
    )
    .expect("continue");
    let g = gap(&fine(&moved, 3), &fine(&whole, 3));
    assert!(g > 1e-3, "3 mm at frame 1 left frame 3 {g} m away");

    // The same fork again is its data set (to resume); another fork there, or a frame not
    // yet simulated, is refused with the file named.
    assert_eq!(
        fork(&whole, 1, Vector3::new(0.003, 0.0, 0.0), &moved)
            .expect("again")
            .frames_done,
        3
    );
    let e = fork(&whole, 2, Vector3::zeros(), &moved)
        .expect_err("other fork")
        .to_string();
    assert!(
        e.contains("manifest.json") && e.contains("another data set"),
        "{e}"
    );
    let e = fork(&whole, 4, Vector3::zeros(), &dir.path().join("late"))
        .expect_err("frame 4")
        .to_string();
    assert!(e.contains("manifest.json") && e.contains("frame 4"), "{e}");
    assert!(
        !dir.path().join("late").exists(),
        "a refused fork left a directory"
    );
    // Into a directory holding something else, or a file, it is refused; into an empty one
    // it goes.
    let other = dir.path().join("other");
    std::fs::create_dir_all(&other).expect("mkdir");
    std::fs::write(other.join("notes.txt"), "mine").expect("write");
    let e = fork(&whole, 1, Vector3::zeros(), &other)
        .expect_err("occupied")
        .to_string();
    assert!(e.contains("other") && e.contains("not a data set"), "{e}");
    let file = dir.path().join("file");
    std::fs::write(&file, "mine").expect("write");
    let e = fork(&whole, 1, Vector3::zeros(), &file)
        .expect_err("a file")
        .to_string();
    assert!(e.contains("file"), "{e}");
    assert_eq!(std::fs::read_to_string(&file).expect("read"), "mine");
    let empty = dir.path().join("empty");
    std::fs::create_dir_all(&empty).expect("mkdir");
    fork(&whole, 2, Vector3::zeros(), &empty).expect("into an empty directory");
    assert_eq!(read_manifest(&empty).expect("manifest").frames_done, 2);
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .expect("list")
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains("fork-partial"))
        .collect();
    assert!(leftovers.is_empty(), "a fork left its temporary copy");

    // A resume state whose detection margin is not what the format says is refused, naming
    // the frame file, rather than taken for an older data set's missing one.
    let bad = dir.path().join("bad");
    let m = fork(&whole, 1, Vector3::zeros(), &bad).expect("fork");
    let frame1 = bad.join("frames/frame_00001.safetensors");
    let r = TensorReader::open(&frame1).expect("frame 1");
    let mut w = clothsr::io::tensors::TensorWriter::from_reader(&r).expect("copy");
    w.f32("resume_fine_margin", &[1], &[0.01]);
    w.write(&frame1).expect("write");
    let e = generate(
        &scene(),
        &m.scene,
        &Options::of_manifest(&m, 3),
        &bad,
        |_| {},
    )
    .expect_err("f32 margin")
    .to_string();
    assert!(
        e.contains("frame_00001") && e.contains("resume_fine_margin"),
        "{e}"
    );
}

#[test]
fn a_run_resumed_as_the_sheet_strikes_the_ball_continues_exactly() {
    // Stopped after frame 2, a few millimetres above the ball at 0.6 m/s: the detection
    // margins have grown with the fall (4 mm fine, 10 mm coarse, against 2.3 and 6 mm at
    // rest), and a resumed run that started from the smaller ones lands 0.26 mm elsewhere.
    let scene = common::sheet_over_ball("cotton", 0.17);
    // One whole step a step (fast mode): the data mode's sub-steps move a quarter as far
    // each, and its margins stay at rest through the fall.
    let opts = |frames| Options {
        variation: Variation::default(),
        fine_mode: clothsr::sim::step::SolverMode::Fast,
        ..opts(frames)
    };
    let dir = tempfile::tempdir().expect("tmp");
    let (whole, split) = (dir.path().join("whole"), dir.path().join("split"));
    generate(&scene, "test", &opts(4), &whole, |_| {}).expect("whole");
    let r = TensorReader::open(&whole.join("frames/frame_00002.safetensors")).expect("frame 2");
    let margin = r.f64("resume_fine_margin").expect("margin").1[0];
    assert!(
        margin > 0.003,
        "fine margin {margin} m: not the case this test is for"
    );
    generate(&scene, "test", &opts(2), &split, |_| {}).expect("first part");
    generate(&scene, "test", &opts(4), &split, |_| {}).expect("resume");
    for k in 3..=4 {
        let (a, b) = (
            read_frame_positions(&whole, k).expect("frame"),
            read_frame_positions(&split, k).expect("frame"),
        );
        assert_eq!(a.fine_x.1, b.fine_x.1, "frame {k}: the fine sheet differs");
        assert_eq!(a.coarse_x.1, b.coarse_x.1, "frame {k}: M_c differs");
    }
}

#[test]
fn a_data_set_made_before_the_data_mode_is_refused_with_a_reason() {
    let dir = tempfile::tempdir().expect("tmp");
    let data = dir.path().join("old");
    let m = generate(&scene(), "test", &opts(2), &data, |_| {}).expect("data set");
    assert_eq!(m.fine_solver, "data");
    assert_eq!(m.fine_unconverged, [0, 0]);
    m.check_reference(&data).expect("a data-mode data set");
    // The same data set as an older clothsr wrote it: no fine solver recorded.
    let path = data.join("manifest.json");
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).expect("read")).expect("json");
    json.as_object_mut().expect("object").remove("fine_solver");
    std::fs::write(&path, json.to_string()).expect("write");
    let old = read_manifest(&data).expect("still readable");
    for e in [
        old.check_reference(&data).expect_err("old").to_string(),
        fork(&data, 1, Vector3::zeros(), &dir.path().join("f"))
            .expect_err("fork")
            .to_string(),
    ] {
        assert!(
            e.contains("manifest.json") && e.contains("tight reference"),
            "{e}"
        );
    }
}
