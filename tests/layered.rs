//! `clothsr run`'s override layer for a USD shot: composed over a real shot it replaces the
//! garment in place, in the shot's units, axis and time codes; value clips for long shots.

use std::path::Path;

use clothsr::eval::Animation;

#[path = "layered/shot.rs"]
mod shot;

#[test]
#[ignore = "heavy: dresses a skirt on the walking avatar (run by .ci/run)"]
fn the_layer_replaces_the_garment_of_a_z_up_centimetre_shot_in_place() {
    let dir = tempfile::tempdir().expect("tmp");
    let shot_file = shot::make(dir.path());
    let layer = dir.path().join("cloth.usda");
    shot::run(&shot_file, &layer, 2, &[]);
    let report = shot::check(&shot_file, &layer, 2);
    eprintln!("{report}");
    // clothsr's own reader composes the layer over its shot: the garment in metres, y up.
    let anim = Animation::read_usd(&layer).expect("the layer reads as its shot");
    assert_eq!(anim.time_codes, vec![0.0, 1.0, 2.0]);
    assert_eq!(anim.parts[0].0, "/Shot/Skirt");
}

fn sample() -> std::path::PathBuf {
    shot::root().join("samples/sheet_sphere.usda")
}

#[test]
fn value_clips_hold_the_frames_one_layer_holds() {
    let dir = tempfile::tempdir().expect("tmp");
    let one = dir.path().join("one.usda");
    let clipped = dir.path().join("clipped.usda");
    shot::run(&sample(), &one, 5, &["--clip-frames", "0"]);
    shot::run(&sample(), &clipped, 5, &["--clip-frames", "2"]);
    let clips: Vec<_> = std::fs::read_dir(dir.path().join("clipped.clips"))
        .expect("the clips folder")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    for f in [
        "clipped.0000.usdc",
        "clipped.0001.usdc",
        "clipped.0002.usdc",
        "static.usdc",
        "manifest.usda",
    ] {
        assert!(clips.iter().any(|c| c == f), "{f} missing: {clips:?}");
    }
    assert!(
        !clips.iter().any(|c| c.contains("clothsr-")),
        "temporary files left: {clips:?}"
    );
    let size = |p: &Path| std::fs::metadata(p).expect("file").len();
    assert!(
        size(&clipped) < 10_000 && size(&one) > 1_000_000,
        "the clipped layer stays small ({} bytes against {})",
        size(&clipped),
        size(&one)
    );
    let a = Animation::read_usd(&one).expect("one layer");
    let b = Animation::read_usd(&clipped).expect("clips");
    assert_eq!(a.time_codes, b.time_codes);
    assert_eq!(a.time_codes.len(), 6);
    assert_eq!(a.frames, b.frames, "the same points through the clips");
}

#[test]
fn standalone_output_keeps_the_colliders_and_garments_under_world() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("standalone.usdc");
    shot::run(&sample(), &out, 1, &["--layer", "off"]);
    let stage = clothsr::io::usd::read_usd(&out).expect("read");
    let paths: Vec<&str> = stage.meshes.iter().map(|m| m.path.as_str()).collect();
    assert_eq!(paths, ["/World/Garments/sheet", "/World/Colliders/sphere"]);
    // Layered (the default for USD input), the file holds the garment's override only.
    let layer = dir.path().join("layer.usda");
    shot::run(&sample(), &layer, 1, &[]);
    let text = std::fs::read_to_string(&layer).expect("text");
    assert!(
        text.contains("over Mesh \"sheet\"") && !text.contains("Colliders"),
        "{}",
        &text[..2000.min(text.len())]
    );
}
