//! Scenes from files and back: a GarmentCode pattern, an OBJ cloth mesh or a USD stage read
//! into a [`Scene`], collider files (OBJ, OBJ sequences, USD with UsdSkel) added to it, and a
//! scene written as a USD stage with clothsr's schema.

use std::path::Path;

use nalgebra::{Vector2, Vector3};

use crate::obj;
use crate::usd::{self, write_usd, MeshOut, SolverSettings, StageOut};
use clothsr_geometry::error::{Error, Result};
use clothsr_geometry::garment::{garmentcode, Fabric};
use clothsr_geometry::mesh::{cloth_from_corners, flatten, ClothMesh, FlattenOptions, Flattening};
use clothsr_geometry::scene::{ClothPiece, Collider, PrimSource, Scene};

/// Reading a [`Scene`] from files and writing it to USD.
pub trait SceneFiles: Sized {
    /// Loads a scene from a GarmentCode JSON (one garment made of `fabric`), an OBJ (one cloth
    /// mesh, flattened when it has no `vt`) or a USD stage (garments, cloth meshes, colliders,
    /// solver settings).
    fn load(path: &Path, fabric: &Fabric) -> Result<Self>;
    /// Adds a collider file: OBJ, OBJ sequence (`%04d` / `####`, frames at the scene's fps) or
    /// USD (every mesh of the stage, skinned where UsdSkel).
    fn add_collider_file(&mut self, path: &Path) -> Result<()>;
    /// As [`SceneFiles::add_collider_file`], scaling the file's points by `scale` (units to
    /// metres) and moving them by `offset_m`.
    fn add_collider_file_transformed(
        &mut self,
        path: &Path,
        scale: f64,
        offset_m: Vector3<f64>,
    ) -> Result<()>;
    /// Writes the scene as a USD stage with clothsr's schema (atomically, validated); returns
    /// the validators' warnings.
    fn write_usd(&self, path: &Path, ascii: bool) -> Result<Vec<String>>;
}

/// Kinds of input file, from the extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileKind {
    /// GarmentCode JSON.
    GarmentCode,
    /// Wavefront OBJ.
    Obj,
    /// USD (usd, usda, usdc).
    Usd,
}

impl FileKind {
    /// The kind of `path`, or an error naming it.
    pub fn of(path: &Path) -> Result<FileKind> {
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref()
        {
            Some("json") => Ok(FileKind::GarmentCode),
            Some("obj") => Ok(FileKind::Obj),
            Some("usd" | "usda" | "usdc") => Ok(FileKind::Usd),
            _ => Err(Error::Usage(format!(
                "{}: unknown file type (expected .json, .obj, .usd, .usda or .usdc)",
                path.display()
            ))),
        }
    }
}

fn stem(path: &Path) -> String {
    path.file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("mesh")
        .trim_end_matches("_specification")
        .to_string()
}

/// A cloth piece from an OBJ: its `vt` are the material coordinates, or, without `vt`, the mesh
/// is flattened into charts (see [`flatten`]) that become its panels.
pub fn cloth_from_obj(path: &Path, fabric: Fabric) -> Result<ClothPiece> {
    obj_cloth(path, fabric).map(|(cloth, _)| cloth)
}

/// As [`cloth_from_obj`], with the flattening it made (charts and distortion, for reports);
/// `None` when the OBJ has `vt`.
pub fn obj_cloth(path: &Path, fabric: Fabric) -> Result<(ClothPiece, Option<Flattening>)> {
    cloth_of_obj_mesh(path, obj::read_obj(path)?, fabric)
}

/// The cloth piece of the OBJ mesh `m` read from `path`, as [`obj_cloth`] makes it.
pub fn cloth_of_obj_mesh(
    path: &Path,
    m: obj::ObjMesh,
    fabric: Fabric,
) -> Result<(ClothPiece, Option<Flattening>)> {
    let (points, corner_point) = welded(&m);
    let piece = |mesh| ClothPiece {
        name: stem(path),
        mesh,
        fabric,
    };
    let Some(uv) = m.uv.as_ref() else {
        let (mesh, f) = flattened_cloth(path, "the mesh", &points, &corner_point)?;
        return Ok((piece(mesh), Some(f)));
    };
    let corner_uv: Vec<Vector2<f64>> = m
        .triangles
        .iter()
        .flatten()
        .map(|&v| uv[v as usize])
        .collect();
    let (mesh, rescaled) =
        cloth_from_corners(&points, &corner_point, &corner_uv).map_err(|e| e.in_file(path))?;
    if let Some(s) = rescaled {
        tracing::warn!(
            "{}: texture coordinates are not in metres; UV charts scaled to their 3D areas (layout by {s:.4})",
            path.display()
        );
    }
    Ok((piece(mesh), None))
}

/// The points of an OBJ mesh welded by position (tobj splits them at UV and normal seams), and
/// the welded point of every face corner.
fn welded(m: &obj::ObjMesh) -> (Vec<Vector3<f64>>, Vec<u32>) {
    let mut welded: std::collections::HashMap<[u64; 3], u32> = std::collections::HashMap::new();
    let mut points = Vec::new();
    let remap: Vec<u32> = m
        .positions
        .iter()
        .map(|p| {
            *welded
                .entry([p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
                .or_insert_with(|| {
                    points.push(*p);
                    (points.len() - 1) as u32
                })
        })
        .collect();
    let corner_point = m
        .triangles
        .iter()
        .flatten()
        .map(|&v| remap[v as usize])
        .collect();
    (points, corner_point)
}

/// Flattens the triangles given by `corner_point` (see [`flatten`]), the error naming `what`
/// in `path`.
fn flattening(
    path: &Path,
    what: &str,
    points: &[Vector3<f64>],
    corner_point: &[u32],
) -> Result<Flattening> {
    let triangles: Vec<[u32; 3]> = corner_point
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    flatten(points, &triangles, &FlattenOptions::default()).map_err(|e| {
        Error::bad_input(
            path,
            format!("{what} has no texture coordinates and cannot be flattened: {e}"),
        )
    })
}

/// A cloth mesh for a triangle mesh without texture coordinates (`what` names it in `path`):
/// flattened into charts whose coordinates become material coordinates (in the points' units,
/// metres), and points on chart boundaries sewn; with the flattening.
fn flattened_cloth(
    path: &Path,
    what: &str,
    points: &[Vector3<f64>],
    corner_point: &[u32],
) -> Result<(ClothMesh, Flattening)> {
    let f = flattening(path, what, points, corner_point)?;
    let d = f.distortion;
    tracing::info!(
        "{}: {what} has no texture coordinates; flattened into {} chart(s), area distortion \
         mean {:.2}% max {:.2}%, angle distortion mean {:.2}° max {:.2}°{}",
        path.display(),
        f.charts,
        100.0 * d.area_mean,
        100.0 * d.area_max,
        d.angle_mean_deg,
        d.angle_max_deg,
        if d.flipped > 0 {
            format!(", {} flipped triangle(s)", d.flipped)
        } else {
            String::new()
        }
    );
    let (mesh, _) =
        cloth_from_corners(points, corner_point, &f.corner_uv).map_err(|e| e.in_file(path))?;
    Ok((mesh, f))
}

fn cloth_from_usd_mesh(path: &Path, m: &usd::UsdMesh, fabric: Fabric) -> Result<ClothPiece> {
    let points: Vec<Vector3<f64>> = m.frames[0].iter().map(|p| p.cast::<f64>()).collect();
    let tris = m.triangles();
    let Some(uv) = m.uv.as_ref() else {
        let corner_point: Vec<u32> = tris.iter().flatten().copied().collect();
        let what = format!("cloth mesh {}", m.path);
        let (mesh, _) = flattened_cloth(path, &what, &points, &corner_point)?;
        return Ok(ClothPiece {
            name: m.name.clone(),
            mesh,
            fabric,
        });
    };
    let mesh = match uv {
        // Per-point material coordinates: the points are the vertices, as clothsr writes them.
        usd::UvData::Vertex(uv) => {
            let mut mesh = ClothMesh {
                material: uv.clone(),
                positions: points,
                triangles: tris,
                ..Default::default()
            };
            for t in &mut mesh.triangles {
                let [a, b, c] = t.map(|v| mesh.material[v as usize]);
                if (b - a).perp(&(c - a)) < 0.0 {
                    t.swap(1, 2);
                }
            }
            mesh.seam_pairs = m.seam_pairs.clone().unwrap_or_default();
            mesh.panel_of_vertex = match &m.panel_ids {
                Some(ids) if ids.len() == mesh.positions.len() => ids.clone(),
                _ => clothsr_geometry::mesh::connected_components(
                    mesh.positions.len(),
                    &mesh.triangles,
                ),
            };
            let panels = mesh
                .panel_of_vertex
                .iter()
                .copied()
                .max()
                .map_or(0, |x| x + 1);
            mesh.panel_names = (0..panels).map(|i| format!("panel_{i}")).collect();
            mesh.validate().map_err(|e| e.in_file(path))?;
            mesh
        }
        // Per-corner coordinates: split points along UV seams and sew them back.
        usd::UvData::Corner(uv) => {
            let mut corner_uv = Vec::with_capacity(3 * tris.len());
            let mut k = 0usize;
            for &c in &m.face_counts {
                for j in 1..c as usize - 1 {
                    corner_uv.extend([uv[k], uv[k + j], uv[k + j + 1]]);
                }
                k += c as usize;
            }
            let corner_point: Vec<u32> = tris.iter().flatten().copied().collect();
            cloth_from_corners(&points, &corner_point, &corner_uv)
                .map_err(|e| e.in_file(path))?
                .0
        }
    };
    Ok(ClothPiece {
        name: m.name.clone(),
        mesh,
        fabric,
    })
}

impl SceneFiles for Scene {
    /// Loads a scene from a GarmentCode JSON (one garment made of `fabric`), an OBJ (one cloth
    /// mesh, flattened when it has no `vt`) or a USD stage (garments, cloth meshes, colliders,
    /// solver settings).
    fn load(path: &Path, fabric: &Fabric) -> Result<Scene> {
        let mut scene = Scene::default();
        match FileKind::of(path)? {
            FileKind::GarmentCode => scene
                .garments
                .push(garmentcode::read(path, fabric.clone())?),
            FileKind::Obj => scene.cloths.push(cloth_from_obj(path, fabric.clone())?),
            FileKind::Usd => scene = scene_of_usd(path, usd::read_usd(path)?, fabric)?,
        }
        Ok(scene)
    }

    /// Adds a collider file: OBJ, OBJ sequence (`%04d` / `####`, frames at the scene's fps) or
    /// USD (every mesh of the stage, skinned where UsdSkel).
    fn add_collider_file(&mut self, path: &Path) -> Result<()> {
        self.add_collider_file_transformed(path, 1.0, Vector3::zeros())
    }

    /// As [`Scene::add_collider_file`], scaling the file's points by `scale` (units to metres)
    /// and moving them by `offset_m`.
    fn add_collider_file_transformed(
        &mut self,
        path: &Path,
        scale: f64,
        offset_m: Vector3<f64>,
    ) -> Result<()> {
        if !(scale.is_finite() && scale > 0.0 && offset_m.iter().all(|c| c.is_finite())) {
            return Err(Error::bad_input(
                path,
                format!("collider scale {scale} / offset must be finite and positive"),
            ));
        }
        let first = self.colliders.len();
        add_collider_file_raw(self, path)?;
        for c in &mut self.colliders[first..] {
            *c = std::mem::replace(c, Collider::fixed("", Vec::new(), Vec::new()))
                .transformed(scale, offset_m);
        }
        Ok(())
    }

    /// Writes the scene as a USD stage with clothsr's schema (atomically, validated); returns
    /// the validators' warnings.
    fn write_usd(&self, path: &Path, ascii: bool) -> Result<Vec<String>> {
        let mut meshes: Vec<MeshOut> = self
            .cloths
            .iter()
            .map(|c| MeshOut::cloth(&c.name, &c.mesh, &c.fabric, 0.0))
            .collect();
        meshes.extend(
            self.colliders
                .iter()
                .map(|c| MeshOut::collider(c, self.fps)),
        );
        let out = StageOut {
            over: None,
            fps: self.fps,
            start: self.frame_start as f64,
            end: self.frame_end as f64,
            doc: Some("clothsr scene".into()),
            ascii,
            garments: self.garments.iter().collect(),
            meshes,
            solver: Some(SolverSettings {
                gravity_m_s2: self.gravity_m_s2,
                dt_s: self.dt_s,
            }),
        };
        write_usd(path, &out)
    }
}

fn add_collider_file_raw(scene: &mut Scene, path: &Path) -> Result<()> {
    let text = path.to_string_lossy();
    if text.contains('%') || text.contains('#') {
        let (triangles, frames) = obj::read_obj_sequence(path)?;
        scene.colliders.push(Collider {
            name: stem(path).replace(['%', '#'], ""),
            triangles,
            times_s: (0..frames.len()).map(|k| k as f64 / scene.fps).collect(),
            frames: frames
                .iter()
                .map(|f| f.iter().map(|p| p.cast::<f32>()).collect())
                .collect(),
        });
        return Ok(());
    }
    match FileKind::of(path)? {
        FileKind::Obj => {
            let m = obj::read_obj(path)?;
            scene
                .colliders
                .push(Collider::fixed(&stem(path), m.positions, m.triangles));
        }
        FileKind::Usd => {
            let stage = usd::read_usd(path)?;
            if stage.meshes.is_empty() {
                return Err(Error::bad_input(path, "no mesh to collide with"));
            }
            for m in &stage.meshes {
                scene.colliders.push(collider_from_usd_mesh(m, stage.fps));
            }
            let last = stage
                .meshes
                .iter()
                .filter_map(|m| m.time_codes.last())
                .fold(0.0f64, |a, &b| a.max(b));
            scene.frame_end = scene.frame_end.max(last.floor() as i64);
        }
        FileKind::GarmentCode => {
            return Err(Error::bad_input(
                path,
                "a sewing pattern cannot be a collider",
            ))
        }
    }
    Ok(())
}

fn collider_from_usd_mesh(m: &usd::UsdMesh, fps: f64) -> Collider {
    Collider {
        name: m.name.clone(),
        triangles: m.triangles(),
        times_s: m.time_codes.iter().map(|t| t / fps).collect(),
        frames: m.frames.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fmt::Write as _;

    /// Largest relative difference between material and 3D edge lengths of a cloth mesh.
    fn edge_error(mesh: &ClothMesh) -> f64 {
        mesh.edges()
            .iter()
            .map(|&[a, b]| {
                let l3 = (mesh.positions[a as usize] - mesh.positions[b as usize]).norm();
                let l2 = (mesh.material[a as usize] - mesh.material[b as usize]).norm();
                (l2 / l3 - 1.0).abs()
            })
            .fold(0.0, f64::max)
    }

    /// An open tube (a sleeve) of quads, 0.1 m in radius and 0.4 m long, as OBJ text without
    /// `vt`; its rim is squeezed into an ellipse so that it is not a perfect cylinder.
    fn sleeve_obj() -> String {
        let (around, along) = (24, 12);
        let mut text = String::new();
        for j in 0..=along {
            let y = 0.4 * j as f64 / along as f64;
            for i in 0..around {
                let a = std::f64::consts::TAU * i as f64 / around as f64;
                let rx = 0.1 * (1.0 + 0.2 * y);
                writeln!(text, "v {} {} {}", rx * a.cos(), y, 0.1 * a.sin()).expect("fmt");
            }
        }
        let id = |i: usize, j: usize| j * around + i % around + 1;
        for j in 0..along {
            for i in 0..around {
                let q = [id(i, j), id(i, j + 1), id(i + 1, j + 1), id(i + 1, j)];
                writeln!(text, "f {} {} {} {}", q[0], q[1], q[2], q[3]).expect("fmt");
            }
        }
        text
    }

    #[test]
    fn obj_without_vt_is_flattened_into_material_coordinates() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("sleeve.obj");
        std::fs::write(&path, sleeve_obj()).expect("write");
        let scene = Scene::load(&path, &Fabric::default()).expect("load");
        let mesh = &scene.cloths[0].mesh;
        mesh.validate().expect("valid");
        assert_eq!(mesh.triangles.len(), 2 * 24 * 12);
        // The closed tube must be cut: points along the cut are sewn back.
        assert!(!mesh.seam_pairs.is_empty());
        for [a, b] in &mesh.seam_pairs {
            assert_eq!(mesh.positions[*a as usize], mesh.positions[*b as usize]);
        }
        let err = edge_error(mesh);
        eprintln!(
            "sleeve: {} panels, worst edge length error {err:.2e}",
            mesh.panel_names.len()
        );
        assert!(err < 1e-3, "edge lengths off by {err}");
        let area3: f64 = mesh
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
                0.5 * (b - a).cross(&(c - a)).norm()
            })
            .sum();
        let area2: f64 = (0..mesh.triangles.len())
            .map(|t| mesh.material_area(t))
            .sum();
        assert!((area2 / area3 - 1.0).abs() < 1e-9);
    }

    #[test]
    fn usd_cloth_without_st_is_flattened() {
        // A 1 m × 0.5 m panel folded by 90° (a crease: two charts), in centimetres.
        let (nx, ny) = (10, 5);
        let mut points = Vec::new();
        for j in 0..=ny {
            for i in 0..=nx {
                let (x, y) = (100.0 * i as f64 / nx as f64, 50.0 * j as f64 / ny as f64);
                let p = if x <= 40.0 {
                    (x, y, 0.0)
                } else {
                    (40.0, y, x - 40.0)
                };
                points.push(format!("({}, {}, {})", p.0, p.1, p.2));
            }
        }
        let mut indices = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                let v = |i: usize, j: usize| (j * (nx + 1) + i).to_string();
                indices.extend([v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)]);
            }
        }
        let usda = format!(
            "#usda 1.0\n(\n metersPerUnit = 0.01\n upAxis = \"Y\"\n)\n\
             def Mesh \"Cloth\" (prepend apiSchemas = [\"ClothsrGarmentAPI\"]) {{\n\
             int[] faceVertexCounts = [{}]\n int[] faceVertexIndices = [{}]\n\
             point3f[] points = [{}]\n}}\n",
            vec!["4"; nx * ny].join(", "),
            indices.join(", "),
            points.join(", ")
        );
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("folded.usda");
        std::fs::write(&path, usda).expect("write");
        let scene = Scene::load(&path, &Fabric::default()).expect("load");
        let mesh = &scene.cloths[0].mesh;
        assert_eq!(mesh.panel_names.len(), 2, "the fold is a crease");
        assert_eq!(mesh.seam_pairs.len(), ny + 1, "sewn along the fold");
        let err = edge_error(mesh);
        assert!(err < 1e-5, "edge lengths off by {err}");
        let area: f64 = (0..mesh.triangles.len())
            .map(|t| mesh.material_area(t))
            .sum();
        assert!((area - 0.5).abs() < 1e-5, "{area} m²");
    }

    #[test]
    fn scanned_bunny_without_vt_flattens_into_discs() {
        // A closed scanned surface (the Stanford bunny, low resolution) loaded as a cloth: it
        // must be cut, split where it is curved, and give a valid mesh with no flipped triangle.
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/colliders/bunny.obj");
        let (cloth, f) = obj_cloth(&path, Fabric::default()).expect("flatten");
        let f = f.expect("the bunny has no vt");
        let d = f.distortion;
        eprintln!("bunny: {} charts, {d:?}", f.charts);
        assert_eq!(d.flipped, 0);
        assert!(d.area_mean < 0.05, "{d:?}");
        cloth.mesh.validate().expect("valid");
        assert_eq!(cloth.mesh.panel_names.len(), f.charts);
    }

    #[test]
    fn obj_that_cannot_be_flattened_is_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("line.obj");
        std::fs::write(&path, "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n").expect("write");
        let err = Scene::load(&path, &Fabric::default())
            .expect_err("zero area")
            .to_string();
        assert!(
            err.contains("line.obj") && err.contains("cannot be flattened"),
            "{err}"
        );
    }

    #[test]
    fn usd_cloth_that_cannot_be_flattened_is_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("line.usda");
        std::fs::write(
            &path,
            "#usda 1.0\n(\n metersPerUnit = 1\n upAxis = \"Y\"\n)\n\
             def Mesh \"Cloth\" (prepend apiSchemas = [\"ClothsrGarmentAPI\"]) {\n\
             int[] faceVertexCounts = [3]\n int[] faceVertexIndices = [0, 1, 2]\n\
             point3f[] points = [(0,0,0), (1,0,0), (2,0,0)]\n}\n",
        )
        .expect("write");
        let err = Scene::load(&path, &Fabric::default())
            .expect_err("zero area")
            .to_string();
        for part in ["line.usda", "/Cloth", "no texture coordinates", "zero area"] {
            assert!(err.contains(part), "{part}: {err}");
        }
    }
}

/// The scene of the stage read from `path` (as the bridge hands it over): its garments, cloth
/// meshes (made of `fabric` where they name none) and colliders, frame range and solver.
pub fn scene_of_usd(
    path: &Path,
    stage: usd::UsdStage<usd::UsdMesh>,
    fabric: &Fabric,
) -> Result<Scene> {
    stage.check(path)?;
    let mut scene = Scene {
        fps: stage.fps,
        frame_start: stage.start.floor() as i64,
        frame_end: stage.end.floor() as i64,
        ..Scene::default()
    };
    if let Some(s) = stage.solver {
        scene.gravity_m_s2 = s.gravity_m_s2;
        scene.dt_s = s.dt_s;
    }
    let source = |prim: &str| PrimSource {
        file: path.to_path_buf(),
        prim: prim.to_string(),
    };
    for (g, prim) in stage.garments.iter().zip(&stage.garment_paths) {
        scene.sources.insert(g.name.clone(), source(prim));
    }
    scene.garments = stage.garments;
    for m in &stage.meshes {
        m.check(path)?;
        match m.role {
            usd::MeshRole::Cloth => {
                let f = m
                    .fabric
                    .as_ref()
                    .map_or_else(|| fabric.clone(), |(f, _)| f.clone());
                let cloth = cloth_from_usd_mesh(path, m, f).map_err(|e| match e {
                    // Name the prim where the mesh checks did not.
                    Error::BadInput { path, message } if !message.contains(&m.path) => {
                        Error::BadInput {
                            path,
                            message: format!("mesh {}: {message}", m.path),
                        }
                    }
                    other => other,
                })?;
                scene.sources.insert(cloth.name.clone(), source(&m.path));
                scene.cloths.push(cloth);
            }
            _ => scene.colliders.push(collider_from_usd_mesh(m, stage.fps)),
        }
    }
    Ok(scene)
}

/// What [`convert`] makes a scene of.
#[derive(Debug, Clone, PartialEq)]
pub struct Convert {
    /// GarmentCode JSON, OBJ cloth meshes or USD scenes: their garments go into one scene (a
    /// repeated name gets a suffix); the first sets the frame rate and range.
    pub inputs: Vec<std::path::PathBuf>,
    /// Colliders (OBJ, OBJ sequence, USD) and then the avatar.
    pub colliders: Vec<std::path::PathBuf>,
    /// Fabric for patterns and meshes without one.
    pub fabric: Fabric,
    /// Frames per second of the scene (OBJ sequences are read at this rate).
    pub fps: Option<f64>,
    /// Frames to simulate from the first (default: to the end of the colliders' animation).
    pub frames: Option<i64>,
}

/// The scene `c` describes.
pub fn convert(c: &Convert) -> Result<Scene> {
    let (first, rest) = c
        .inputs
        .split_first()
        .ok_or_else(|| Error::Usage("nothing to convert: give at least one input".into()))?;
    let mut scene = Scene::load(first, &c.fabric)?;
    for input in rest {
        scene.merge(Scene::load(input, &c.fabric)?);
    }
    if let Some(fps) = c.fps {
        if !(fps.is_finite() && fps > 0.0) {
            return Err(Error::Usage(format!(
                "frames per second must be positive, got {fps}"
            )));
        }
        scene.fps = fps;
    }
    for path in &c.colliders {
        scene.add_collider_file(path)?;
    }
    if let Some(n) = c.frames {
        if n < 0 {
            return Err(Error::Usage(format!(
                "the number of frames must be >= 0, got {n}"
            )));
        }
        scene.frame_end = scene.frame_start + n;
    }
    Ok(scene)
}
