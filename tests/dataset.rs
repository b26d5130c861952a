//! `clothsr::data`: training data from a fine simulation, downsampled to M_int, with one
//! coarse step from each M_int (M_c); resumable.

mod common;

use clothsr::data::{generate, read_frame_positions, read_manifest, Options, Variation};
use clothsr::io::tensors::TensorReader;
use clothsr::scene::Scene;

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
    let err = g
        .fine_x
        .1
        .iter()
        .zip(&f.fine_x.1)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    assert!(err < 1e-4, "resumed run differs by {err} m");

    // Another scene in the same directory is refused, naming the manifest.
    let mut other = opts(3);
    other.variation.garment_offset_m = [0.0, 0.05, 0.0];
    let e = generate(&scene(), "test", &other, &split, |_| {})
        .expect_err("different data set")
        .to_string();
    assert!(e.contains("manifest.json"), "{e}");
}
