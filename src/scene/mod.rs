//! A scene: garments (sewing patterns or meshes with material coordinates), colliders (static or
//! animated triangle meshes: avatars, balls, tables), gravity, time step, frame rate and range.

use std::path::Path;

use nalgebra::{Vector2, Vector3};

use crate::error::{Error, Result};
use crate::garment::{garmentcode, Fabric, Garment};
use crate::io::{obj, usd};
use crate::mesh::{cloth_from_corners, ClothMesh};

pub mod samples;

/// Default simulation time step (the paper's 1/300 s).
pub const DEFAULT_DT_S: f64 = 1.0 / 300.0;
/// Default output frame rate.
pub const DEFAULT_FPS: f64 = 30.0;

/// A garment already meshed (from OBJ or USD), with its fabric.
#[derive(Debug, Clone)]
pub struct ClothPiece {
    /// Name.
    pub name: String,
    /// Mesh with material coordinates.
    pub mesh: ClothMesh,
    /// Fabric.
    pub fabric: Fabric,
}

/// A collision body: fixed triangles, points at one or more times (linearly interpolated).
#[derive(Debug, Clone, PartialEq)]
pub struct Collider {
    /// Name.
    pub name: String,
    /// Triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Time of each frame, seconds (one entry for a static body).
    pub times_s: Vec<f64>,
    /// Points per frame, metres, y up.
    pub frames: Vec<Vec<Vector3<f32>>>,
}

impl Collider {
    /// A static collider.
    pub fn fixed(name: &str, positions: Vec<Vector3<f64>>, triangles: Vec<[u32; 3]>) -> Self {
        Collider {
            name: name.into(),
            triangles,
            times_s: vec![0.0],
            frames: vec![positions.iter().map(|p| p.cast::<f32>()).collect()],
        }
    }

    /// Number of points.
    pub fn num_points(&self) -> usize {
        self.frames.first().map_or(0, Vec::len)
    }

    /// Whether the points move.
    pub fn is_animated(&self) -> bool {
        self.frames.len() > 1
    }

    /// Points at time `t_s`, linearly interpolated between frames and held outside their range.
    pub fn positions_at(&self, t_s: f64, out: &mut Vec<Vector3<f64>>) {
        out.clear();
        let k = self.times_s.partition_point(|&t| t <= t_s);
        let (i, j, w) = if k == 0 {
            (0, 0, 0.0)
        } else if k >= self.times_s.len() {
            (k - 1, k - 1, 0.0)
        } else {
            let (t0, t1) = (self.times_s[k - 1], self.times_s[k]);
            (k - 1, k, (t_s - t0) / (t1 - t0))
        };
        out.extend(
            self.frames[i]
                .iter()
                .zip(&self.frames[j])
                .map(|(a, b)| a.cast::<f64>() * (1.0 - w) + b.cast::<f64>() * w),
        );
    }

    /// Scales the collider about the origin by `scale`, then moves it by `offset_m`.
    pub fn transformed(mut self, scale: f64, offset_m: Vector3<f64>) -> Self {
        let off = offset_m.cast::<f32>();
        for frame in &mut self.frames {
            for p in frame.iter_mut() {
                *p = *p * scale as f32 + off;
            }
        }
        self
    }

    /// An icosphere of `radius` around `centre` (`subdivisions` = 3 gives 642 points).
    pub fn sphere(name: &str, centre: Vector3<f64>, radius: f64, subdivisions: usize) -> Self {
        let t = (1.0 + 5f64.sqrt()) / 2.0;
        let mut pts: Vec<Vector3<f64>> = [
            (-1.0, t, 0.0),
            (1.0, t, 0.0),
            (-1.0, -t, 0.0),
            (1.0, -t, 0.0),
            (0.0, -1.0, t),
            (0.0, 1.0, t),
            (0.0, -1.0, -t),
            (0.0, 1.0, -t),
            (t, 0.0, -1.0),
            (t, 0.0, 1.0),
            (-t, 0.0, -1.0),
            (-t, 0.0, 1.0),
        ]
        .iter()
        .map(|&(x, y, z)| Vector3::new(x, y, z).normalize())
        .collect();
        let mut tris: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..subdivisions {
            let mut mid = std::collections::HashMap::new();
            let mut next = Vec::with_capacity(tris.len() * 4);
            let mut midpoint = |a: u32, b: u32, pts: &mut Vec<Vector3<f64>>| {
                *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    pts.push(((pts[a as usize] + pts[b as usize]) * 0.5).normalize());
                    (pts.len() - 1) as u32
                })
            };
            for [a, b, c] in tris {
                let ab = midpoint(a, b, &mut pts);
                let bc = midpoint(b, c, &mut pts);
                let ca = midpoint(c, a, &mut pts);
                next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            tris = next;
        }
        let pts = pts.into_iter().map(|p| centre + p * radius).collect();
        Collider::fixed(name, pts, tris)
    }

    /// An axis-aligned box from `min` to `max` (12 triangles, outward facing).
    pub fn cuboid(name: &str, min: Vector3<f64>, max: Vector3<f64>) -> Self {
        let pts = (0..8)
            .map(|i| {
                Vector3::new(
                    if i & 1 == 0 { min.x } else { max.x },
                    if i & 2 == 0 { min.y } else { max.y },
                    if i & 4 == 0 { min.z } else { max.z },
                )
            })
            .collect();
        let tris = vec![
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ];
        Collider::fixed(name, pts, tris)
    }
}

/// Everything one simulation needs.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Garments given as sewing patterns (meshed at the resolution a stage asks for).
    pub garments: Vec<Garment>,
    /// Garments given as meshes.
    pub cloths: Vec<ClothPiece>,
    /// Collision bodies.
    pub colliders: Vec<Collider>,
    /// Gravity, m/s².
    pub gravity_m_s2: Vector3<f64>,
    /// Simulation time step, s.
    pub dt_s: f64,
    /// Output frames per second.
    pub fps: f64,
    /// First output frame.
    pub frame_start: i64,
    /// Last output frame.
    pub frame_end: i64,
}

impl Default for Scene {
    fn default() -> Self {
        Scene {
            garments: Vec::new(),
            cloths: Vec::new(),
            colliders: Vec::new(),
            gravity_m_s2: Vector3::new(0.0, -9.81, 0.0),
            dt_s: DEFAULT_DT_S,
            fps: DEFAULT_FPS,
            frame_start: 0,
            frame_end: 0,
        }
    }
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

impl Scene {
    /// Loads a scene from a GarmentCode JSON (one garment made of `fabric`), an OBJ (one cloth
    /// mesh with `vt`) or a USD stage (garments, cloth meshes, colliders, solver settings).
    pub fn load(path: &Path, fabric: &Fabric) -> Result<Scene> {
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
    pub fn add_collider_file(&mut self, path: &Path) -> Result<()> {
        self.add_collider_file_transformed(path, 1.0, Vector3::zeros())
    }

    /// As [`Scene::add_collider_file`], scaling the file's points by `scale` (units to metres)
    /// and moving them by `offset_m`.
    pub fn add_collider_file_transformed(
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
        self.add_collider_file_raw(path)?;
        for c in &mut self.colliders[first..] {
            *c = std::mem::replace(c, Collider::fixed("", Vec::new(), Vec::new()))
                .transformed(scale, offset_m);
        }
        Ok(())
    }

    fn add_collider_file_raw(&mut self, path: &Path) -> Result<()> {
        let text = path.to_string_lossy();
        if text.contains('%') || text.contains('#') {
            let (triangles, frames) = obj::read_obj_sequence(path)?;
            self.colliders.push(Collider {
                name: stem(path).replace(['%', '#'], ""),
                triangles,
                times_s: (0..frames.len()).map(|k| k as f64 / self.fps).collect(),
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
                self.colliders
                    .push(Collider::fixed(&stem(path), m.positions, m.triangles));
            }
            FileKind::Usd => {
                let stage = usd::read_usd(path)?;
                if stage.meshes.is_empty() {
                    return Err(Error::bad_input(path, "no mesh to collide with"));
                }
                for m in &stage.meshes {
                    self.colliders.push(collider_from_usd_mesh(m, stage.fps));
                }
                let last = stage
                    .meshes
                    .iter()
                    .filter_map(|m| m.time_codes.last())
                    .fold(0.0f64, |a, &b| a.max(b));
                self.frame_end = self.frame_end.max(last.floor() as i64);
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
}

fn collider_from_usd_mesh(m: &usd::UsdMesh, fps: f64) -> Collider {
    Collider {
        name: m.name.clone(),
        triangles: m.triangles(),
        times_s: m.time_codes.iter().map(|t| t / fps).collect(),
        frames: m.frames.clone(),
    }
}
