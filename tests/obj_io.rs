//! OBJ input: cloth meshes whose `vt` are material coordinates, colliders, numbered sequences.

use std::fmt::Write as _;
use std::path::Path;

use clothsr::garment::Fabric;
use clothsr::io::scene_files::cloth_from_obj;
use clothsr::io::SceneFiles;
use clothsr::mesh::{mesh_garment, MeshOptions};
use clothsr::scene::samples::skirt;
use clothsr::scene::Scene;

/// Writes `mesh` as OBJ with `vt` = material coordinates, welding seam pairs into one `v` so the
/// file looks like a DCC export (one position, several texture coordinates along seams).
fn write_obj(path: &Path, mesh: &clothsr::mesh::ClothMesh) {
    let n = mesh.num_vertices();
    let mut rep: Vec<usize> = (0..n).collect();
    fn find(rep: &mut [usize], mut x: usize) -> usize {
        while rep[x] != x {
            x = rep[x];
        }
        x
    }
    for [a, b] in &mesh.seam_pairs {
        let (ra, rb) = (find(&mut rep, *a as usize), find(&mut rep, *b as usize));
        rep[ra.max(rb)] = ra.min(rb);
    }
    let mut text = String::new();
    for p in &mesh.positions {
        writeln!(text, "v {} {} {}", p.x, p.y, p.z).expect("fmt");
    }
    for uv in &mesh.material {
        writeln!(text, "vt {} {}", uv.x, uv.y).expect("fmt");
    }
    for t in &mesh.triangles {
        let c: Vec<String> = t
            .iter()
            .map(|&v| format!("{}/{}", find(&mut rep, v as usize) + 1, v + 1))
            .collect();
        writeln!(text, "f {}", c.join(" ")).expect("fmt");
    }
    std::fs::write(path, text).expect("write obj");
}

#[test]
fn obj_cloth_with_vt_keeps_material_space_and_finds_seams() {
    let dir = tempfile::tempdir().expect("tempdir");
    let g = skirt(Fabric::default());
    let mesh = mesh_garment(&g, &MeshOptions::with_edge(0.03)).expect("mesh");
    let path = dir.path().join("skirt.obj");
    write_obj(&path, &mesh);
    let cloth = cloth_from_obj(&path, Fabric::default()).expect("read");
    let (a, b) = (cloth.mesh.stats(), mesh.stats());
    assert_eq!(a.vertices, b.vertices);
    assert_eq!(a.triangles, b.triangles);
    // tobj reads single precision.
    assert!((a.area_m2 - b.area_m2).abs() < 1e-5 * b.area_m2);
    assert_eq!(
        cloth.mesh.panel_names.len(),
        2,
        "two panels from two UV islands"
    );
    // Every seam pair of the pattern mesh is found again from the welded positions.
    assert_eq!(cloth.mesh.seam_pairs.len(), mesh.seam_pairs.len());
    for [p, q] in &cloth.mesh.seam_pairs {
        let d = (cloth.mesh.positions[*p as usize] - cloth.mesh.positions[*q as usize]).norm();
        assert!(d < 1e-12);
    }
}

#[test]
fn obj_in_texture_space_is_rescaled_to_metres() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("quad.obj");
    // A 2 m × 2 m quad with UVs in [0, 1].
    std::fs::write(
        &path,
        "v 0 0 0\nv 2 0 0\nv 2 0 2\nv 0 0 2\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n",
    )
    .expect("write");
    let cloth = cloth_from_obj(&path, Fabric::default()).expect("read");
    assert!((cloth.mesh.stats().area_m2 - 4.0).abs() < 1e-9);
}

#[test]
fn obj_sequence_is_an_animated_collider() {
    let dir = tempfile::tempdir().expect("tempdir");
    for k in 1..=4 {
        let y = 0.1 * k as f64;
        std::fs::write(
            dir.path().join(format!("frame_{k:04}.obj")),
            format!("v 0 {y} 0\nv 1 {y} 0\nv 0 {y} 1\nf 1 2 3\n"),
        )
        .expect("write");
    }
    let mut scene = Scene::default();
    scene
        .add_collider_file(&dir.path().join("frame_%04d.obj"))
        .expect("sequence");
    let c = &scene.colliders[0];
    assert_eq!(c.frames.len(), 4);
    assert_eq!(c.times_s, vec![0.0, 1.0 / 30.0, 2.0 / 30.0, 3.0 / 30.0]);
    let mut p = Vec::new();
    c.positions_at(0.5 / 30.0, &mut p);
    assert!((p[0].y - 0.15).abs() < 1e-6);
    // A frame with other topology is refused, naming the file.
    std::fs::write(
        dir.path().join("frame_0005.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 0 1\nv 1 0 1\nf 1 2 3\nf 2 4 3\n",
    )
    .expect("write");
    let err = scene
        .add_collider_file(&dir.path().join("frame_####.obj"))
        .expect_err("topology");
    assert!(err.to_string().contains("frame_0005.obj"), "{err}");
}

#[test]
fn bunny_obj_is_a_static_collider() {
    let mut scene = Scene::default();
    scene
        .add_collider_file(
            &Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/colliders/bunny.obj"),
        )
        .expect("bunny");
    let c = &scene.colliders[0];
    assert!(!c.is_animated());
    assert!(c.triangles.len() > 1000);
}
