//! Round trips through real USD files written and read by usd-core (through the pyo3 bridge),
//! validated by usd-core's own validators; the UsdSkel avatar read as an animated collider.

use std::path::{Path, PathBuf};

use clothsr::garment::{garmentcode, Fabric};
use clothsr::io::usd::{read_usd, validate_usd, write_usd, MeshOut, MeshRole, StageOut, UvData};
use clothsr::io::SceneFiles;
use clothsr::mesh::{mesh_garment, MeshOptions};
use clothsr::scene::Scene;

fn fixture(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(rel)
}

fn assert_valid(path: &Path) {
    let issues = validate_usd(path).expect("validation runs");
    let errors: Vec<_> = issues.iter().filter(|i| i.0 == "error").collect();
    assert!(errors.is_empty(), "{}: {errors:?}", path.display());
}

#[test]
fn garmentcode_pattern_round_trips_through_usd_schema() {
    let dir = tempfile::tempdir().expect("tempdir");
    for rel in [
        "patterns/garmentcode_examples/js_mean_all_specification.json",
        "patterns/mh_skirt_circle/mh_skirt_circle_specification.json",
        "patterns/legacy_templates/basic_tee_jacket_hood.json",
    ] {
        let g = garmentcode::read(&fixture(rel), Fabric::preset("denim").expect("preset"))
            .expect("pattern");
        let scene = Scene {
            garments: vec![g.clone()],
            ..Scene::default()
        };
        let out = dir.path().join("pattern.usda");
        scene.write_usd(&out, true).expect("write");
        assert_valid(&out);
        let back = read_usd(&out).expect("read back");
        assert_eq!(back.garments.len(), 1);
        assert_eq!(
            back.garments[0], g,
            "{rel} differs after the USD round trip"
        );
        let text = std::fs::read_to_string(&out).expect("usda text");
        for expected in [
            "def ClothsrPanel",
            "\"ClothsrGarmentAPI\"",
            "int \"clothsr:schemaVersion\" = 1",
            "\"PhysicsSurfaceDeformableMaterialAPI\"",
            "rel material:binding:physics",
        ] {
            assert!(
                text.contains(expected),
                "{rel}: no {expected} in the written stage"
            );
        }
    }
}

#[test]
fn meshed_garment_writes_time_codes_and_st_and_reads_back() {
    let dir = tempfile::tempdir().expect("tempdir");
    let g = garmentcode::read(
        &fixture("patterns/mh_pencil_skirt/mh_pencil_skirt_specification.json"),
        Fabric::default(),
    )
    .expect("pattern");
    let mesh = mesh_garment(&g, &MeshOptions::with_edge(0.02)).expect("mesh");
    for ext in ["usdc", "usda", "usd"] {
        let out = dir.path().join(format!("skirt.{ext}"));
        let mut m = MeshOut::cloth(&g.name, &mesh, &g.fabric, 0.02);
        m.time_codes = Some(vec![0.0]);
        let stage = StageOut {
            over: None,
            fps: 30.0,
            start: 0.0,
            end: 0.0,
            meshes: vec![m],
            ..Default::default()
        };
        write_usd(&out, &stage).expect("write");
        assert_valid(&out);
        let back = read_usd(&out).expect("read back");
        assert_eq!(back.meters_per_unit, 1.0);
        assert_eq!(back.up_axis, "Y");
        let m = &back.meshes[0];
        assert_eq!(m.role, MeshRole::Cloth);
        assert_eq!(m.time_codes, vec![0.0]);
        assert_eq!(m.frames[0].len(), mesh.num_vertices());
        let Some(UvData::Vertex(uv)) = &m.uv else {
            panic!("st is per vertex")
        };
        let max_uv_err = uv
            .iter()
            .zip(&mesh.material)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(max_uv_err < 1e-6, "st differs by {max_uv_err} m");
        assert_eq!(m.seam_pairs.as_ref(), Some(&mesh.seam_pairs));
        let (fabric, edge) = m.fabric.clone().expect("fabric");
        assert_eq!((fabric, edge), (g.fabric.clone(), 0.02));
        // Read as a scene, the cloth comes back vertex for vertex.
        let scene = Scene::load(&out, &Fabric::default()).expect("scene");
        let cloth = &scene.cloths[0].mesh;
        assert_eq!(cloth.triangles, mesh.triangles);
        assert_eq!(cloth.panel_of_vertex, mesh.panel_of_vertex);
        let max_pos_err = cloth
            .positions
            .iter()
            .zip(&mesh.positions)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(
            max_pos_err < 1e-5,
            "positions differ by {max_pos_err} m (f32 storage)"
        );
    }
    // usdc by default: the binary crate format starts with "PXR-USDC".
    let head = std::fs::read(dir.path().join("skirt.usd")).expect("file");
    assert_eq!(&head[..8], b"PXR-USDC");
}

#[test]
fn usdskel_avatar_reads_as_animated_collider_matching_the_bake() {
    let skel = read_usd(&fixture("avatars/mh_walk_train.usda")).expect("avatar");
    assert_eq!((skel.fps, skel.start, skel.end), (30.0, 0.0, 180.0));
    assert_eq!(skel.meshes.len(), 1);
    let body = &skel.meshes[0];
    assert!(body.skinned);
    assert_eq!(body.role, MeshRole::Collider);
    assert_eq!(body.frames.len(), 181);
    assert_eq!(body.frames[0].len(), 13380);
    // The baked point cache holds every second frame of the first 2 s: pxr's skinning must
    // agree with it.
    let baked = read_usd(&fixture("avatars/mh_walk_train_baked_2s.usdc")).expect("baked");
    let b = &baked.meshes[0];
    assert_eq!(b.time_codes.len(), 31);
    let mut max_mm = 0.0f32;
    for (k, t) in b.time_codes.iter().enumerate() {
        let f = &body.frames[*t as usize];
        for (p, q) in f.iter().zip(&b.frames[k]) {
            max_mm = max_mm.max((p - q).norm() * 1e3);
        }
    }
    assert!(max_mm < 0.01, "skinned vs baked differ by {max_mm} mm");
    // The walk moves: the root travels forward along +z.
    let z = |f: &Vec<nalgebra::Vector3<f32>>| f.iter().map(|p| p.z).sum::<f32>() / f.len() as f32;
    assert!(z(&body.frames[180]) - z(&body.frames[0]) > 0.5);

    let mut scene = Scene::default();
    scene
        .add_collider_file(&fixture("avatars/mh_walk_train.usda"))
        .expect("collider");
    let c = &scene.colliders[0];
    assert!(c.is_animated());
    assert_eq!(c.frames.len(), 181);
    assert_eq!(scene.frame_end, 180);
    assert_eq!(c.triangles.len(), 2 * 13378);
    // Halfway between frames 10 and 11 the points are the average.
    let mut mid = Vec::new();
    c.positions_at(10.5 / 30.0, &mut mid);
    let expect = (c.frames[10][7].cast::<f64>() + c.frames[11][7].cast::<f64>()) * 0.5;
    assert!((mid[7] - expect).norm() < 1e-9);
}

#[test]
fn z_up_centimetre_stages_are_converted_to_y_up_metres() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("zup.usda");
    std::fs::write(
        &path,
        r#"#usda 1.0
(
    defaultPrim = "Root"
    metersPerUnit = 0.01
    upAxis = "Z"
)
def Xform "Root"
{
    def Mesh "Tri" (prepend apiSchemas = ["PhysicsCollisionAPI"])
    {
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
        point3f[] points = [(0, 0, 0), (100, 0, 0), (0, 0, 50)]
        double3 xformOp:translate = (0, 0, 10)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
}
"#,
    )
    .expect("write");
    let s = read_usd(&path).expect("read");
    let p = &s.meshes[0].frames[0];
    // (x, y, z) cm, z up -> (x, z, -y) m, y up; the translate lifts by 10 cm.
    let expect = [[0.0, 0.1, 0.0], [1.0, 0.1, 0.0], [0.0, 0.6, 0.0]];
    for (a, e) in p.iter().zip(expect) {
        assert!(
            (a - nalgebra::Vector3::new(e[0], e[1], e[2])).norm() < 1e-6,
            "{a:?} vs {e:?}"
        );
    }
    assert_eq!(s.meshes[0].role, MeshRole::Collider);
}

/// Several garments on one avatar: `convert` takes them all; a repeated name gets a suffix.
#[test]
fn convert_puts_several_garments_on_one_avatar() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("outfit.usda");
    let skirt = fixture("patterns/mh_pencil_skirt/mh_pencil_skirt_specification.json");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_clothsr"))
        .arg("convert")
        .arg(&skirt)
        .arg(fixture("patterns/mh_tshirt/mh_tshirt_specification.json"))
        .arg(&skirt)
        .arg("--avatar")
        .arg(fixture("avatars/mh_walk_train.usda"))
        .arg("-o")
        .arg(&out)
        .status()
        .expect("run clothsr");
    assert!(status.success());
    assert_valid(&out);
    let s = read_usd(&out).expect("read");
    let names: Vec<&str> = s.garments.iter().map(|g| g.name.as_str()).collect();
    assert_eq!(names.len(), 3, "{names:?}");
    assert_ne!(names[0], names[2], "{names:?}");
    assert!(names[2].starts_with(names[0]), "{names:?}");
    assert_eq!(
        s.meshes
            .iter()
            .filter(|m| m.role == MeshRole::Collider)
            .count(),
        1,
        "one avatar"
    );
}

#[test]
fn convert_writes_a_valid_scene_with_an_animated_avatar() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("skirt_on_avatar.usdc");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_clothsr"))
        .arg("convert")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/skirt.usda"))
        .arg("--avatar")
        .arg(fixture("avatars/mh_walk_train.usda"))
        .arg("-o")
        .arg(&out)
        .status()
        .expect("run clothsr");
    assert!(status.success());
    assert_valid(&out);
    let s = read_usd(&out).expect("read");
    assert_eq!(s.garments.len(), 1);
    assert_eq!(s.end, 180.0);
    let avatar = s
        .meshes
        .iter()
        .find(|m| m.role == MeshRole::Collider)
        .expect("avatar");
    assert_eq!(avatar.frames.len(), 181);
    assert!(s
        .solver
        .is_some_and(|x| (x.dt_s - 1.0 / 300.0).abs() < 1e-12));
}

/// Written with schema version 0's type names (`ClothGarmentAPI`, `ClothPanel`), which clothsr
/// still reads although USD no longer knows them as types.
#[test]
fn panel_placement_survives_units_axes_and_parent_transforms() {
    use clothsr::garment::Placement;
    use nalgebra::{Vector2, Vector3};
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("zup_pattern.usda");
    std::fs::write(
        &path,
        r#"#usda 1.0
(
    defaultPrim = "World"
    metersPerUnit = 0.01
    upAxis = "Z"
)
def Xform "World"
{
    double3 xformOp:translate = (5, 0, 0)
    uniform token[] xformOpOrder = ["xformOp:translate"]
    def Xform "Shirt" (prepend apiSchemas = ["ClothGarmentAPI"])
    {
        def ClothPanel "front"
        {
            double2[] clothsr:vertices = [(0, 0), (40, 0), (40, 60), (0, 60)]
            int2[] clothsr:edgeEndpoints = [(0, 1), (1, 2), (2, 3), (3, 0)]
            token[] clothsr:edgeCurveTypes = ["straight", "circle", "straight", "quadratic"]
            double4[] clothsr:edgeCurveParams = [(0, 0, 0, 0), (50, 0, 1, 0), (0, 0, 0, 0), (-5, 30, 0, 0)]
            double3 xformOp:translate = (10, 20, 30)
            double3 xformOp:rotateXYZ = (30, 40, 50)
            uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ"]
        }
    }
}
"#,
    )
    .expect("write");
    let s = read_usd(&path).expect("read");
    let g = &s.garments[0];
    let p = &g.panels[0];
    assert_eq!(p.vertices[2], Vector2::new(0.4, 0.6));
    // The arc radius scales with units, its flags do not.
    assert_eq!(
        p.edges[1].curve,
        clothsr::garment::Curve::Arc {
            radius_m: 0.5,
            large_arc: false,
            right: true
        }
    );
    // Expected: in stage units R·(u, v, 0) + t + parent, then cm -> m and z-up -> y-up.
    let stage_placement = Placement {
        translation_m: Vector3::new(15.0, 20.0, 30.0),
        rotation_xyz_deg: Vector3::new(30.0, 40.0, 50.0),
    };
    for uv in &p.vertices {
        let q = stage_placement.apply(uv * 100.0) * 0.01;
        let expect = Vector3::new(q.x, q.z, -q.y);
        let got = p.placement.apply(*uv);
        assert!((got - expect).norm() < 1e-9, "{got} vs {expect}");
    }
}

/// A cloth mesh described only in OpenUSD's deformable-physics names (as Newton reads them), in
/// centimetres and grams: its fabric comes from the bound physics material and the mesh's
/// thickness. With clothsr's own fabric authored beside a disagreeing material, clothsr's wins
/// and the reader says so.
#[test]
fn fabric_in_deformable_physics_names_is_read_and_clothsrs_wins() {
    let dir = tempfile::tempdir().expect("tempdir");
    let stage = |own: &str| {
        format!(
            r#"#usda 1.0
(
    metersPerUnit = 0.01
    kilogramsPerUnit = 0.001
    upAxis = "Y"
)
def Mesh "Cloth" (
    prepend apiSchemas = ["PhysicsSurfaceDeformableSimAPI", "MaterialBindingAPI"{api}]
)
{{
    int[] faceVertexCounts = [3, 3]
    int[] faceVertexIndices = [0, 1, 2, 1, 3, 2]
    point3f[] points = [(0, 0, 0), (100, 0, 0), (0, 0, 100), (100, 0, 100)]
    texCoord2f[] primvars:st = [(0, 0), (1, 0), (0, 1), (1, 1)] (interpolation = "vertex")
    float[] physics:thicknesses = [0.05]
    uniform token physics:thicknesses:elementType = "constant"
    rel material:binding:physics = </Fabric> (bindMaterialAs = "weakerThanDescendants")
    {own}
}}
def Material "Fabric" (
    prepend apiSchemas = ["PhysicsMaterialAPI", "PhysicsSurfaceDeformableMaterialAPI"]
)
{{
    float physics:density = 0.4
    float physics:surfaceStretchStiffness = 1000000
    float physics:surfaceShearStiffness = 40000
    float physics:surfaceBendStiffness = 30
}}
"#,
            api = if own.is_empty() {
                ""
            } else {
                ", \"ClothsrGarmentAPI\""
            },
        )
    };
    // Only the physics names: SI from centimetres and grams.
    let path = dir.path().join("physics_only.usda");
    std::fs::write(&path, stage("")).expect("write");
    let s = read_usd(&path).expect("read");
    let cloth = &s.meshes[0];
    assert_eq!(cloth.role, MeshRole::Cloth);
    let (f, _) = cloth.fabric.as_ref().expect("fabric");
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs();
    assert!(close(f.thickness_m, 5e-4), "thickness {}", f.thickness_m);
    // 0.4 g/cm³ = 400 kg/m³, times 0.5 mm.
    assert!(
        close(f.areal_density_kg_m2, 0.2),
        "areal density {}",
        f.areal_density_kg_m2
    );
    // 1e6 g/s² = 1000 N/m; 40000 g/s² = 40 N/m; 30 g·cm²/s² = 3e-6 N·m.
    assert!(close(f.stretch_warp_n_m, 1000.0) && close(f.stretch_weft_n_m, 1000.0));
    assert!(close(f.shear_n_m, 40.0), "shear {}", f.shear_n_m);
    assert!(close(f.bending_n_m, 3e-6), "bending {}", f.bending_n_m);
    assert_eq!(f.name, "Fabric");
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);

    // clothsr's own fabric beside it, disagreeing on bending: clothsr's wins, with a warning.
    let path = dir.path().join("both.usda");
    std::fs::write(
        &path,
        stage(
            "double clothsr:fabric:bending = 0.000005\n    double clothsr:fabric:thickness = 0.0005",
        ),
    )
    .expect("write");
    let s = read_usd(&path).expect("read");
    let (f, _) = s.meshes[0].fabric.as_ref().expect("fabric");
    assert!(close(f.bending_n_m, 5e-6), "bending {}", f.bending_n_m);
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(
        s.warnings[0].contains("both.usda") && s.warnings[0].contains("/Cloth"),
        "{}",
        s.warnings[0]
    );
}

/// The bridge registers the codeless schema itself (through `Plug.Registry`, never the process
/// environment): USD's validators do not flag prims of unknown types, so the files written
/// above would pass without it.
#[test]
fn the_bridge_registers_the_schema_without_the_environment() {
    use pyo3::types::PyAnyMethods;
    let before = std::env::var_os("PXR_PLUGINPATH_NAME");
    let registered = clothsr::io::python::with_bridge(|_py, m| {
        m.call_method0("schema_registered")?.extract::<bool>()
    })
    .expect("bridge");
    assert!(
        registered,
        "ClothsrPanel is unknown to USD's schema registry"
    );
    assert_eq!(std::env::var_os("PXR_PLUGINPATH_NAME"), before);
}

#[test]
fn a_catalogue_shot_writes_and_reads_back_with_its_moving_collider_and_mixed_fabric() {
    let dir = tempfile::tempdir().expect("tempdir");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_clothsr"))
        .args([
            "lab",
            "scenes",
            "strip-silk_cotton-cube-swing",
            "--frames",
            "12",
            "-o",
        ])
        .arg(dir.path())
        .status()
        .expect("run clothsr");
    assert!(status.success());
    let path = dir.path().join("strip-silk_cotton-cube-swing.usda");
    assert_valid(&path);
    let fabric = Fabric::preset("cotton").expect("cotton");
    let read = Scene::load(&path, &fabric).expect("load");
    let made = clothsr::scene::catalogue::scene("strip-silk_cotton-cube-swing", 12).expect("shot");
    let (silk, cotton) = (
        Fabric::preset("silk").expect("silk"),
        Fabric::preset("cotton").expect("cotton"),
    );
    let g = &read.garments[0];
    assert_eq!(g.fabric.name, "silk_cotton");
    let mid = (silk.bending_n_m * cotton.bending_n_m).sqrt();
    assert!((g.fabric.bending_n_m - mid).abs() < 1e-12 * mid.max(1.0));
    let cube = read
        .colliders
        .iter()
        .find(|c| c.name.contains("cube"))
        .expect("the cube");
    let want = &made.colliders[0];
    assert_eq!(cube.frames.len(), want.frames.len());
    assert!(cube.is_animated());
    for (a, b) in cube.frames.iter().zip(&want.frames) {
        for (p, q) in a.iter().zip(b) {
            assert!((p - q).norm() < 1e-6, "{p} vs {q}");
        }
    }
    for (a, b) in cube.times_s.iter().zip(&want.times_s) {
        assert!((a - b).abs() < 1e-9);
    }
}
