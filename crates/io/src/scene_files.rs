//! Scenes from files and back: a GarmentCode pattern, an OBJ cloth mesh or a USD stage read
//! into a [`Scene`], collider files (OBJ, OBJ sequences, USD with UsdSkel) added to it, and a
//! scene written as a USD stage with clothsr's schema.

use std::path::Path;

use nalgebra::{Vector2, Vector3};

use crate::error::{Error, Result};
use crate::garment::{garmentcode, Fabric};
use crate::mesh::{cloth_from_corners, ClothMesh};
use crate::obj;
use crate::scene::{ClothPiece, Collider, Scene};
use crate::usd::{self, write_usd, MeshOut, SolverSettings, StageOut};

/// Reading a [`Scene`] from files and writing it to USD.
pub trait SceneFiles: Sized {
    /// Loads a scene from a GarmentCode JSON (one garment made of `fabric`), an OBJ (one cloth
    /// mesh with `vt`) or a USD stage (garments, cloth meshes, colliders, solver settings).
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
            _ => Err(Error::bad_input(
                path,
                "unknown file type (expected .json, .obj, .usd, .usda or .usdc)",
            )),
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

/// A cloth piece from an OBJ whose `vt` are material coordinates.
pub fn cloth_from_obj(path: &Path, fabric: Fabric) -> Result<ClothPiece> {
    let m = obj::read_obj(path)?;
    let uv = m.uv.as_ref().ok_or_else(|| {
        Error::bad_input(
            path,
            "no texture coordinates (vt): a cloth mesh needs them as material coordinates",
        )
    })?;
    let corners: Vec<u32> = m.triangles.iter().flatten().copied().collect();
    let corner_uv: Vec<Vector2<f64>> = corners.iter().map(|&v| uv[v as usize]).collect();
    // tobj split points at UV seams already; weld them back by position to find the seams.
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
    let corner_point: Vec<u32> = corners.iter().map(|&v| remap[v as usize]).collect();
    let (mesh, rescaled) =
        cloth_from_corners(&points, &corner_point, &corner_uv).map_err(|e| e.in_file(path))?;
    if let Some(s) = rescaled {
        tracing::warn!(
            "{}: texture coordinates are not in metres; scaled by {s:.4} to match the 3D area",
            path.display()
        );
    }
    Ok(ClothPiece {
        name: stem(path),
        mesh,
        fabric,
    })
}

fn cloth_from_usd_mesh(path: &Path, m: &usd::UsdMesh, fabric: Fabric) -> Result<ClothPiece> {
    let points: Vec<Vector3<f64>> = m.frames[0].iter().map(|p| p.cast::<f64>()).collect();
    let tris = m.triangles();
    let no_st = || {
        Error::bad_input(
            path,
            format!(
                "cloth mesh {} has no primvars:st (material coordinates)",
                m.path
            ),
        )
    };
    let mesh = match m.uv.as_ref().ok_or_else(no_st)? {
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
                _ => crate::mesh::connected_components(mesh.positions.len(), &mesh.triangles),
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
    /// mesh with `vt`) or a USD stage (garments, cloth meshes, colliders, solver settings).
    fn load(path: &Path, fabric: &Fabric) -> Result<Scene> {
        let mut scene = Scene::default();
        match FileKind::of(path)? {
            FileKind::GarmentCode => scene
                .garments
                .push(garmentcode::read(path, fabric.clone())?),
            FileKind::Obj => scene.cloths.push(cloth_from_obj(path, fabric.clone())?),
            FileKind::Usd => {
                let stage = usd::read_usd(path)?;
                scene.fps = stage.fps;
                scene.frame_start = stage.start.floor() as i64;
                scene.frame_end = stage.end.floor() as i64;
                if let Some(s) = stage.solver {
                    scene.gravity_m_s2 = s.gravity_m_s2;
                    scene.dt_s = s.dt_s;
                }
                scene.garments = stage.garments;
                for m in &stage.meshes {
                    match m.role {
                        usd::MeshRole::Cloth => {
                            let f = m
                                .fabric
                                .as_ref()
                                .map_or_else(|| fabric.clone(), |(f, _)| f.clone());
                            scene.cloths.push(cloth_from_usd_mesh(path, m, f)?);
                        }
                        _ => scene.colliders.push(collider_from_usd_mesh(m, stage.fps)),
                    }
                }
            }
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
