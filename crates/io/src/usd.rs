//! USD through usd-core: the Rust side of the bridge. Arrays cross as whole numpy buffers; the
//! Python side (`bridge/clothsr_usd`) does all `pxr` work and hands back plain arrays in metres,
//! y up, world space.

use std::path::{Path, PathBuf};

use nalgebra::{Vector2, Vector3};
use numpy::{IntoPyArray, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use super::python::with_bridge;
use clothsr_geometry::error::{Error, Result};
use clothsr_geometry::garment::{
    Curve, EdgeRef, Fabric, Garment, Panel, PanelEdge, Placement, Seam,
};

/// What a mesh in a USD stage is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshRole {
    /// A garment meshed with material coordinates (`ClothsrGarmentAPI`, or a surface
    /// deformable of OpenUSD's physics proposal).
    Cloth,
    /// A collision body (skinned avatar or `PhysicsCollisionAPI`).
    Collider,
    /// Anything else.
    Other,
}

/// Texture coordinates of a USD mesh.
#[derive(Debug, Clone, PartialEq)]
pub enum UvData {
    /// One per point.
    Vertex(Vec<Vector2<f64>>),
    /// One per face corner (faceVarying).
    Corner(Vec<Vector2<f64>>),
}

/// A mesh read from USD: topology and every frame of its points (world, metres, y up).
#[derive(Debug, Clone)]
pub struct UsdMesh {
    /// Prim path.
    pub path: String,
    /// Prim name.
    pub name: String,
    /// What it is for.
    pub role: MeshRole,
    /// Skinned by UsdSkel.
    pub skinned: bool,
    /// Vertices per face.
    pub face_counts: Vec<u32>,
    /// Point indices, face after face.
    pub face_indices: Vec<u32>,
    /// Time codes of the frames.
    pub time_codes: Vec<f64>,
    /// Points per frame.
    pub frames: Vec<Vec<Vector3<f32>>>,
    /// `primvars:st`, if any.
    pub uv: Option<UvData>,
    /// `primvars:clothsr:panelId`, if any.
    pub panel_ids: Option<Vec<u32>>,
    /// `clothsr:seamPairs`, if any.
    pub seam_pairs: Option<Vec<[u32; 2]>>,
    /// Fabric and meshing edge length of cloth meshes.
    pub fabric: Option<(Fabric, f64)>,
}

/// The farthest a point may lie from the origin, m: beyond, a garment or body is a units or
/// export mistake that would only explode the simulation.
pub const MAX_COORDINATE_M: f32 = 1e5;

impl UsdMesh {
    /// Triangles by fan-splitting each polygon ([`UsdMesh::check`] first: faces past the
    /// indices, or of fewer than three points, are skipped).
    pub fn triangles(&self) -> Vec<[u32; 3]> {
        let mut out = Vec::with_capacity(self.face_indices.len());
        let rest = self.frames.first();
        let mut k = 0usize;
        for &c in &self.face_counts {
            let Some(f) = self.face_indices.get(k..k + c as usize) else {
                break;
            };
            k += c as usize;
            // Polygons by ear clipping in their plane; a fan where that finds none.
            if f.len() > 3 {
                let corners: Option<Vec<Vector3<f64>>> = rest.and_then(|r| {
                    f.iter()
                        .map(|&i| r.get(i as usize).map(|p| p.cast::<f64>()))
                        .collect()
                });
                if let Some(tris) = corners
                    .as_deref()
                    .and_then(clothsr_geometry::mesh::triangulate_polygon)
                {
                    out.extend(tris.iter().map(|t| t.map(|j| f[j])));
                    continue;
                }
            }
            for j in 1..f.len().saturating_sub(1) {
                out.push([f[0], f[j], f[j + 1]]);
            }
        }
        out
    }

    /// Why this mesh, read from `file`, cannot be used, if it cannot: the topology, the frames
    /// and the per-point and per-corner arrays must agree, the points be finite and the
    /// frames' times be finite and increasing.
    pub fn check(&self, file: &Path) -> Result<()> {
        let bad = |what: String| {
            Err(Error::bad_input(
                file,
                format!("mesh {}: {what}", self.path),
            ))
        };
        let n = self.frames.first().map_or(0, Vec::len);
        if n == 0 || self.face_counts.is_empty() {
            return bad("no points or no faces".into());
        }
        if let Some(c) = self.face_counts.iter().position(|&c| c < 3) {
            return bad(format!(
                "face {c} has {} points (3 or more needed)",
                self.face_counts[c]
            ));
        }
        let corners: u64 = self.face_counts.iter().map(|&c| u64::from(c)).sum();
        if corners != self.face_indices.len() as u64 {
            return bad(format!(
                "faceVertexCounts add up to {corners} corners but faceVertexIndices has {}",
                self.face_indices.len()
            ));
        }
        let mut k = 0usize;
        let mut seen = std::collections::HashMap::new();
        // Cloth faces must each be a piece of cloth (a body's stray faces are harmless).
        let faces = if self.role == MeshRole::Cloth {
            self.face_counts.as_slice()
        } else {
            &[]
        };
        for (face, &c) in faces.iter().enumerate() {
            let f = &self.face_indices[k..k + c as usize];
            k += c as usize;
            let mut sorted = f.to_vec();
            sorted.sort_unstable();
            if sorted.windows(2).any(|w| w[0] == w[1]) {
                return bad(format!(
                    "face {face} ({f:?}) repeats a point: it has no area"
                ));
            }
            if let Some(first) = seen.insert(sorted, face) {
                return bad(format!("face {face} repeats face {first}"));
            }
        }
        if let Some(i) = self.face_indices.iter().position(|&i| i as usize >= n) {
            return bad(format!(
                "faceVertexIndices[{i}] = {} is past its {n} points",
                self.face_indices[i]
            ));
        }
        if self.time_codes.len() != self.frames.len()
            && !(self.time_codes.is_empty() && self.frames.len() == 1)
        {
            return bad(format!(
                "{} frames of points for {} time codes",
                self.frames.len(),
                self.time_codes.len()
            ));
        }
        if !self.time_codes.iter().all(|t| t.is_finite())
            || self.time_codes.windows(2).any(|w| w[1] <= w[0])
        {
            return bad("time codes are not finite and increasing".into());
        }
        for (k, f) in self.frames.iter().enumerate() {
            if f.len() != n {
                return bad(format!(
                    "frame {k} has {} points where the first has {n}: the topology changes over time",
                    f.len()
                ));
            }
            if let Some(i) = f.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
                return bad(format!("point {i} of frame {k} is not finite"));
            }
            if let Some(i) = f.iter().position(|p| p.amax() > MAX_COORDINATE_M) {
                return bad(format!(
                    "point {i} of frame {k} lies {:.3e} m from the origin (more than \
                     {MAX_COORDINATE_M:.0e} m): check the stage's units",
                    f[i].amax()
                ));
            }
        }
        match &self.uv {
            Some(UvData::Vertex(uv)) if uv.len() != n => {
                return bad(format!(
                    "primvars:st has {} values for {n} points",
                    uv.len()
                ))
            }
            Some(UvData::Corner(uv)) if uv.len() != self.face_indices.len() => {
                return bad(format!(
                    "primvars:st has {} values for {} face corners",
                    uv.len(),
                    self.face_indices.len()
                ))
            }
            Some(UvData::Vertex(uv) | UvData::Corner(uv))
                if !uv.iter().all(|c| c.iter().all(|x| x.is_finite())) =>
            {
                return bad("primvars:st has values that are not finite".into())
            }
            _ => {}
        }
        if let Some(ids) = &self.panel_ids {
            if ids.len() != n {
                return bad(format!(
                    "primvars:clothsr:panelId has {} values for {n} points",
                    ids.len()
                ));
            }
        }
        if let Some(pairs) = &self.seam_pairs {
            if let Some(p) = pairs.iter().find(|p| p.iter().any(|&i| i as usize >= n)) {
                return bad(format!(
                    "clothsr:seamPairs pair {p:?} is past its {n} points"
                ));
            }
        }
        Ok(())
    }
}

impl UsdStage<UsdMesh> {
    /// Why this stage, read from `file`, cannot be used, if it cannot: its timing, and each
    /// mesh ([`UsdMesh::check`]).
    pub fn check(&self, file: &Path) -> Result<()> {
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return Err(Error::bad_input(
                file,
                format!("timeCodesPerSecond = {} is not a positive number", self.fps),
            ));
        }
        let frame = |t: f64| t.is_finite() && t.abs() < 1e9;
        if !(frame(self.start) && frame(self.end) && self.end >= self.start) {
            return Err(Error::bad_input(
                file,
                format!(
                    "time codes {}..{} are not a finite range",
                    self.start, self.end
                ),
            ));
        }
        self.meshes.iter().try_for_each(|m| m.check(file))
    }
}

/// Summary of a mesh without its animation (for `inspect`).
#[derive(Debug, Clone)]
pub struct UsdMeshInfo {
    /// Prim path.
    pub path: String,
    /// What it is for.
    pub role: MeshRole,
    /// Skinned by UsdSkel.
    pub skinned: bool,
    /// Point count.
    pub num_points: usize,
    /// Face count.
    pub num_faces: usize,
    /// Time codes with data.
    pub time_codes: Vec<f64>,
}

/// Simulation settings stored on the stage's PhysicsScene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverSettings {
    /// Gravity, m/s², y up.
    pub gravity_m_s2: Vector3<f64>,
    /// Time step, s.
    pub dt_s: f64,
}

/// A whole stage: timing, meshes, pattern garments, solver settings.
#[derive(Debug, Clone)]
pub struct UsdStage<M> {
    /// Time codes per second.
    pub fps: f64,
    /// First time code.
    pub start: f64,
    /// Last time code.
    pub end: f64,
    /// The stage's metersPerUnit (data are converted to metres already).
    pub meters_per_unit: f64,
    /// The stage's up axis (data are converted to y up already).
    pub up_axis: String,
    /// Meshes.
    pub meshes: Vec<M>,
    /// Garments given as sewing patterns.
    pub garments: Vec<Garment>,
    /// Each garment's prim path.
    pub garment_paths: Vec<String>,
    /// PhysicsScene settings, if any.
    pub solver: Option<SolverSettings>,
    /// What the reader noticed but could go on from (a garment whose physics material
    /// disagrees with its clothsr fabric), each naming the file and the prim.
    pub warnings: Vec<String>,
}

fn array<'py, T: numpy::Element + Copy>(obj: &Bound<'py, PyAny>) -> PyResult<(Vec<T>, Vec<usize>)> {
    let arr: PyReadonlyArrayDyn<'py, T> = obj.extract()?;
    let shape = arr.shape().to_vec();
    Ok((arr.as_array().iter().copied().collect(), shape))
}

fn opt_array<'py, T: numpy::Element + Copy>(
    d: &Bound<'py, PyDict>,
    key: &str,
) -> PyResult<Option<(Vec<T>, Vec<usize>)>> {
    match d.get_item(key)? {
        Some(v) if !v.is_none() => Ok(Some(array::<T>(&v)?)),
        _ => Ok(None),
    }
}

fn item<'py>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<Bound<'py, PyAny>> {
    d.get_item(key)?.ok_or_else(|| {
        pyo3::exceptions::PyKeyError::new_err(format!("bridge result lacks '{key}'"))
    })
}

fn role(s: &str) -> MeshRole {
    match s {
        "cloth" => MeshRole::Cloth,
        "collider" => MeshRole::Collider,
        _ => MeshRole::Other,
    }
}

fn fabric_from(d: &Bound<'_, PyDict>) -> PyResult<(Fabric, f64)> {
    let f = |k: &str| -> PyResult<f64> { item(d, k)?.extract() };
    Ok((
        Fabric {
            name: item(d, "name")?.extract()?,
            areal_density_kg_m2: f("areal_density_kg_m2")?,
            stretch_warp_n_m: f("stretch_warp_n_m")?,
            stretch_weft_n_m: f("stretch_weft_n_m")?,
            shear_n_m: f("shear_n_m")?,
            bending_n_m: f("bending_n_m")?,
            thickness_m: f("thickness_m")?,
            damping_s: f("damping_s")?,
        },
        f("edge_length_m")?,
    ))
}

fn fabric_to<'py>(py: Python<'py>, fabric: &Fabric, edge_m: f64) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("name", &fabric.name)?;
    d.set_item("areal_density_kg_m2", fabric.areal_density_kg_m2)?;
    d.set_item("stretch_warp_n_m", fabric.stretch_warp_n_m)?;
    d.set_item("stretch_weft_n_m", fabric.stretch_weft_n_m)?;
    d.set_item("shear_n_m", fabric.shear_n_m)?;
    d.set_item("bending_n_m", fabric.bending_n_m)?;
    d.set_item("thickness_m", fabric.thickness_m)?;
    d.set_item("damping_s", fabric.damping_s)?;
    d.set_item("edge_length_m", edge_m)?;
    Ok(d)
}

fn to_np<'py, T: numpy::Element>(
    py: Python<'py>,
    v: Vec<T>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyArrayDyn<T>>> {
    v.into_pyarray(py).reshape(shape)
}

fn garment_from(
    g: &Bound<'_, PyDict>,
    path: &Path,
) -> PyResult<std::result::Result<Garment, Error>> {
    let name: String = item(g, "name")?.extract()?;
    let (fabric, _) = fabric_from(&item(g, "fabric")?.cast_into::<PyDict>()?)?;
    let mut panels = Vec::new();
    for p in item(g, "panels")?.cast_into::<PyList>()?.iter() {
        let p = p.cast_into::<PyDict>()?;
        let (verts, _) = array::<f64>(&item(&p, "vertices")?)?;
        let (ends, _) = array::<i32>(&item(&p, "edge_endpoints")?)?;
        let types: Vec<String> = item(&p, "curve_types")?.extract()?;
        let (params, _) = array::<f64>(&item(&p, "curve_params")?)?;
        let (t, _) = array::<f64>(&item(&p, "translation")?)?;
        let (r, _) = array::<f64>(&item(&p, "rotation")?)?;
        let pname: String = item(&p, "name")?.extract()?;
        let mut edges = Vec::new();
        for (k, ty) in types.iter().enumerate() {
            let prm = [
                params[4 * k],
                params[4 * k + 1],
                params[4 * k + 2],
                params[4 * k + 3],
            ];
            let Some(curve) = Curve::from_type_params(ty, prm) else {
                return Ok(Err(Error::bad_input(
                    path,
                    format!("garment '{name}' panel '{pname}' edge {k}: unknown curve type '{ty}'"),
                )));
            };
            let (s, e) = (ends[2 * k], ends[2 * k + 1]);
            if s < 0 || e < 0 {
                return Ok(Err(Error::bad_input(
                    path,
                    format!("garment '{name}' panel '{pname}' edge {k}: negative vertex index"),
                )));
            }
            edges.push(PanelEdge {
                start: s as usize,
                end: e as usize,
                curve,
            });
        }
        panels.push(Panel {
            name: pname,
            vertices: verts
                .chunks_exact(2)
                .map(|c| Vector2::new(c[0], c[1]))
                .collect(),
            edges,
            placement: Placement {
                translation_m: Vector3::new(t[0], t[1], t[2]),
                rotation_xyz_deg: Vector3::new(r[0], r[1], r[2]),
            },
        });
    }
    let mut seams = Vec::new();
    for s in item(g, "seams")?.cast_into::<PyList>()?.iter() {
        let s = s.cast_into::<PyDict>()?;
        let u = |k: &str| -> PyResult<usize> { item(&s, k)?.extract() };
        seams.push(Seam {
            a: EdgeRef {
                panel: u("panel_a")?,
                edge: u("edge_a")?,
            },
            b: EdgeRef {
                panel: u("panel_b")?,
                edge: u("edge_b")?,
            },
            reversed: item(&s, "reversed")?.extract()?,
        });
    }
    let garment = Garment {
        name,
        panels,
        seams,
        fabric,
    };
    Ok(garment
        .validate()
        .map(|_| garment.clone())
        .map_err(|e| e.in_file(path)))
}

fn garment_to<'py>(py: Python<'py>, g: &Garment) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("name", &g.name)?;
    d.set_item("fabric", fabric_to(py, &g.fabric, 0.0)?)?;
    let panels = PyList::empty(py);
    for p in &g.panels {
        let pd = PyDict::new(py);
        pd.set_item("name", &p.name)?;
        let verts: Vec<f64> = p.vertices.iter().flat_map(|v| [v.x, v.y]).collect();
        pd.set_item("vertices", to_np(py, verts, &[p.vertices.len(), 2])?)?;
        let ends: Vec<i32> = p
            .edges
            .iter()
            .flat_map(|e| [e.start as i32, e.end as i32])
            .collect();
        pd.set_item("edge_endpoints", to_np(py, ends, &[p.edges.len(), 2])?)?;
        let types: Vec<&str> = p.edges.iter().map(|e| e.curve.type_name()).collect();
        pd.set_item("curve_types", types)?;
        let params: Vec<f64> = p.edges.iter().flat_map(|e| e.curve.params()).collect();
        pd.set_item("curve_params", to_np(py, params, &[p.edges.len(), 4])?)?;
        pd.set_item("translation", p.placement.translation_m.as_slice().to_vec())?;
        pd.set_item("rotation", p.placement.rotation_xyz_deg.as_slice().to_vec())?;
        panels.append(pd)?;
    }
    d.set_item("panels", panels)?;
    let seams = PyList::empty(py);
    for s in &g.seams {
        let sd = PyDict::new(py);
        sd.set_item("panel_a", s.a.panel)?;
        sd.set_item("edge_a", s.a.edge)?;
        sd.set_item("panel_b", s.b.panel)?;
        sd.set_item("edge_b", s.b.edge)?;
        sd.set_item("reversed", s.reversed)?;
        seams.append(sd)?;
    }
    d.set_item("seams", seams)?;
    Ok(d)
}

fn stage_common<M>(
    d: &Bound<'_, PyDict>,
    path: &Path,
    meshes: Vec<M>,
) -> PyResult<std::result::Result<UsdStage<M>, Error>> {
    let mut garments = Vec::new();
    let mut garment_paths = Vec::new();
    for g in item(d, "garments")?.cast_into::<PyList>()?.iter() {
        let g = g.cast_into::<PyDict>()?;
        garment_paths.push(item(&g, "path")?.extract()?);
        match garment_from(&g, path)? {
            Ok(g) => garments.push(g),
            Err(e) => return Ok(Err(e)),
        }
    }
    let solver = match d.get_item("solver")? {
        Some(s) if !s.is_none() => {
            let s = s.cast_into::<PyDict>()?;
            let (g, _) = array::<f64>(&item(&s, "gravity")?)?;
            Some(SolverSettings {
                gravity_m_s2: Vector3::new(g[0], g[1], g[2]),
                dt_s: item(&s, "dt")?.extract()?,
            })
        }
        _ => None,
    };
    let warnings: Vec<String> = match d.get_item("warnings")? {
        Some(w) if !w.is_none() => w.extract()?,
        _ => Vec::new(),
    };
    for w in &warnings {
        tracing::warn!("{w}");
    }
    Ok(Ok(UsdStage {
        fps: item(d, "fps")?.extract()?,
        start: item(d, "start")?.extract()?,
        end: item(d, "end")?.extract()?,
        meters_per_unit: item(d, "meters_per_unit")?.extract()?,
        up_axis: item(d, "up_axis")?.extract()?,
        meshes,
        garments,
        garment_paths,
        solver,
        warnings,
    }))
}

fn path_str(path: &Path) -> Result<String> {
    if !path.exists() {
        return Err(Error::bad_input(path, "no such file"));
    }
    Ok(path.to_string_lossy().into_owned())
}

/// Takes `meters_per_unit` for every USD file read or layered over from now on in this
/// process that does not state its units (`metersPerUnit`); `None` (the default) refuses
/// such files. Reading one logs the value taken.
pub fn assume_meters_per_unit(meters_per_unit: Option<f64>) -> Result<()> {
    if let Some(m) = meters_per_unit {
        if !(m.is_finite() && m > 0.0) {
            return Err(Error::Usage(format!(
                "{m} metres per unit: expected a positive number"
            )));
        }
    }
    with_bridge(|_py, m| {
        m.call_method1("assume_meters_per_unit", (meters_per_unit,))?;
        Ok(())
    })
}

/// Reads metadata, mesh summaries and garments of a USD file without loading animation.
pub fn inspect_usd(path: &Path) -> Result<UsdStage<UsdMeshInfo>> {
    let p = path_str(path)?;
    with_bridge(|_py, m| {
        let d = m
            .call_method1("inspect_stage", (p.as_str(),))?
            .cast_into::<PyDict>()?;
        let mut meshes = Vec::new();
        for md in item(&d, "meshes")?.cast_into::<PyList>()?.iter() {
            let md = md.cast_into::<PyDict>()?;
            let (times, _) = array::<f64>(&item(&md, "times")?)?;
            meshes.push(UsdMeshInfo {
                path: item(&md, "path")?.extract()?,
                role: role(&item(&md, "role")?.extract::<String>()?),
                skinned: item(&md, "skinned")?.extract()?,
                num_points: item(&md, "num_points")?.extract()?,
                num_faces: item(&md, "num_faces")?.extract()?,
                time_codes: times,
            });
        }
        stage_common(&d, path, meshes)
    })?
}

/// Reads a USD file whole: meshes with every frame (skinned by pxr where UsdSkel), garments and
/// solver settings, in metres with y up.
pub fn read_usd(path: &Path) -> Result<UsdStage<UsdMesh>> {
    let p = path_str(path)?;
    let stage = with_bridge(|_py, m| {
        let d = m
            .call_method1("read_stage", (p.as_str(),))?
            .cast_into::<PyDict>()?;
        let mut meshes = Vec::new();
        for md in item(&d, "meshes")?.cast_into::<PyList>()?.iter() {
            let md = md.cast_into::<PyDict>()?;
            let (counts, _) = array::<i32>(&item(&md, "counts")?)?;
            let (indices, _) = array::<i32>(&item(&md, "indices")?)?;
            let (times, _) = array::<f64>(&item(&md, "times")?)?;
            let (frames, shape) = array::<f32>(&item(&md, "frames")?)?;
            let n = shape[1];
            let frames = frames
                .chunks_exact(3 * n.max(1))
                .map(|f| {
                    f.chunks_exact(3)
                        .map(|c| Vector3::new(c[0], c[1], c[2]))
                        .collect()
                })
                .collect();
            let uv = match opt_array::<f64>(&md, "st")? {
                None => None,
                Some((v, _)) => {
                    let pts = v
                        .chunks_exact(2)
                        .map(|c| Vector2::new(c[0], c[1]))
                        .collect();
                    let interp: String = item(&md, "st_interp")?.extract()?;
                    Some(if interp == "faceVarying" {
                        UvData::Corner(pts)
                    } else {
                        UvData::Vertex(pts)
                    })
                }
            };
            let fabric = match md.get_item("fabric")? {
                Some(f) if !f.is_none() => Some(fabric_from(&f.cast_into::<PyDict>()?)?),
                _ => None,
            };
            meshes.push(UsdMesh {
                path: item(&md, "path")?.extract()?,
                name: item(&md, "name")?.extract()?,
                role: role(&item(&md, "role")?.extract::<String>()?),
                skinned: item(&md, "skinned")?.extract()?,
                face_counts: counts.iter().map(|&c| c as u32).collect(),
                face_indices: indices.iter().map(|&c| c as u32).collect(),
                time_codes: times,
                frames,
                uv,
                panel_ids: opt_array::<i32>(&md, "panel_ids")?
                    .map(|(v, _)| v.iter().map(|&x| x as u32).collect()),
                seam_pairs: opt_array::<i32>(&md, "seam_pairs")?.map(|(v, _)| {
                    v.chunks_exact(2)
                        .map(|c| [c[0] as u32, c[1] as u32])
                        .collect()
                }),
                fabric,
            });
        }
        stage_common(&d, path, meshes)
    })??;
    stage.check(path)?;
    Ok(stage)
}

/// A mesh to write: topology, frames (one frame = static points), optional cloth data.
#[derive(Debug, Clone, Default)]
pub struct MeshOut {
    /// Prim name (made a valid identifier).
    pub name: String,
    /// Scope under `/World` (`Garments`, `Colliders`, ...).
    pub group: String,
    /// Triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Points per frame.
    pub frames: Vec<Vec<Vector3<f32>>>,
    /// Time code of each frame; `None` writes a single static frame.
    pub time_codes: Option<Vec<f64>>,
    /// Per-point `primvars:st` (material coordinates, metres).
    pub uv: Option<Vec<Vector2<f64>>>,
    /// Per-point panel id.
    pub panel_ids: Option<Vec<u32>>,
    /// Sewing pairs.
    pub seam_pairs: Option<Vec<[u32; 2]>>,
    /// Fabric and edge length (marks the mesh as a garment).
    pub fabric: Option<(Fabric, f64)>,
    /// Apply `PhysicsCollisionAPI`.
    pub collider: bool,
    /// Points are time-sampled later by an [`AnimationWriter`].
    pub animated: bool,
    /// Prim documentation.
    pub doc: Option<String>,
}

/// Everything [`write_usd`] writes.
#[derive(Debug, Clone, Default)]
pub struct StageOut<'a> {
    /// Time codes per second.
    pub fps: f64,
    /// First time code.
    pub start: f64,
    /// Last time code.
    pub end: f64,
    /// Layer documentation.
    pub doc: Option<String>,
    /// Write text (usda) even for a `.usd` file.
    pub ascii: bool,
    /// Pattern garments.
    pub garments: Vec<&'a Garment>,
    /// Meshes.
    pub meshes: Vec<MeshOut>,
    /// Solver settings.
    pub solver: Option<SolverSettings>,
    /// Write an override layer for the stage the garments were read from instead of a
    /// standalone stage.
    pub over: Option<OverLayer>,
}

/// An override layer for a USD shot (`clothsr run --layer`): sublayered over the shot, it
/// replaces each garment with its animated mesh at the garment's own prim path, in the
/// shot's units, up axis and time codes; nothing else of the shot is copied.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct OverLayer {
    /// The shot.
    pub input: PathBuf,
    /// Each animated mesh's prim in the shot, by mesh name.
    pub prims: std::collections::BTreeMap<String, String>,
    /// Frames per value clip: longer animations go to one file per clip of this many frames
    /// (beside the layer, in `<name>.clips/`), stitched by the layer; 0 keeps every frame in
    /// the layer.
    pub clip_frames: usize,
}

/// The shot composed with the override layer at `layer`, which a layered run writes beside
/// it: `NAME.composed.usda` (the bridge's `composed_path`).
pub fn composed_path(layer: &Path) -> PathBuf {
    let stem = layer.file_stem().unwrap_or_default().to_string_lossy();
    layer.with_file_name(format!("{stem}.composed.usda"))
}

/// Checks that `path` names a USD file clothsr can write (.usd, .usda, .usdc).
pub fn check_extension(path: &Path) -> Result<()> {
    match path.extension().and_then(|e| e.to_str()) {
        Some("usd" | "usda" | "usdc") => Ok(()),
        _ => Err(Error::Usage(format!(
            "{}: the output must end in .usd, .usda or .usdc",
            path.display()
        ))),
    }
}

fn stage_spec<'py>(py: Python<'py>, out: &StageOut<'_>) -> PyResult<Bound<'py, PyDict>> {
    let spec = PyDict::new(py);
    spec.set_item("fps", out.fps)?;
    spec.set_item("start", out.start)?;
    spec.set_item("end", out.end)?;
    spec.set_item("ascii", out.ascii)?;
    if let Some(doc) = &out.doc {
        spec.set_item("doc", doc)?;
    }
    let garments = PyList::empty(py);
    for g in &out.garments {
        garments.append(garment_to(py, g)?)?;
    }
    spec.set_item("garments", garments)?;
    let meshes = PyList::empty(py);
    for m in &out.meshes {
        let md = PyDict::new(py);
        md.set_item("name", &m.name)?;
        md.set_item("group", &m.group)?;
        md.set_item(
            "counts",
            to_np(py, vec![3i32; m.triangles.len()], &[m.triangles.len()])?,
        )?;
        let idx: Vec<i32> = m.triangles.iter().flatten().map(|&v| v as i32).collect();
        md.set_item("indices", to_np(py, idx, &[3 * m.triangles.len()])?)?;
        let n = m.frames.first().map_or(0, Vec::len);
        let flat: Vec<f32> = m
            .frames
            .iter()
            .flatten()
            .flat_map(|p| [p.x, p.y, p.z])
            .collect();
        md.set_item("frames", to_np(py, flat, &[m.frames.len(), n, 3])?)?;
        md.set_item("static", m.time_codes.is_none() && !m.animated)?;
        if let Some(t) = &m.time_codes {
            md.set_item("times", to_np(py, t.clone(), &[t.len()])?)?;
        }
        if let Some(uv) = &m.uv {
            let flat: Vec<f64> = uv.iter().flat_map(|p| [p.x, p.y]).collect();
            md.set_item("st", to_np(py, flat, &[uv.len(), 2])?)?;
        }
        if let Some(ids) = &m.panel_ids {
            let v: Vec<i32> = ids.iter().map(|&x| x as i32).collect();
            md.set_item("panel_ids", to_np(py, v, &[ids.len()])?)?;
        }
        if let Some(pairs) = &m.seam_pairs {
            let v: Vec<i32> = pairs.iter().flatten().map(|&x| x as i32).collect();
            md.set_item("seam_pairs", to_np(py, v, &[pairs.len(), 2])?)?;
        }
        if let Some((fabric, edge)) = &m.fabric {
            md.set_item("fabric", fabric_to(py, fabric, *edge)?)?;
            md.set_item("edge_length", *edge)?;
        }
        md.set_item("collider", m.collider)?;
        if let Some(doc) = &m.doc {
            md.set_item("doc", doc)?;
        }
        meshes.append(md)?;
    }
    spec.set_item("meshes", meshes)?;
    if let Some(o) = &out.over {
        let od = PyDict::new(py);
        od.set_item("input", o.input.to_string_lossy().as_ref())?;
        let prims = PyDict::new(py);
        for (name, prim) in &o.prims {
            prims.set_item(name, prim)?;
        }
        od.set_item("prims", prims)?;
        od.set_item("clip_frames", o.clip_frames)?;
        spec.set_item("over", od)?;
    }
    if let Some(s) = &out.solver {
        let sd = PyDict::new(py);
        sd.set_item("gravity", s.gravity_m_s2.as_slice().to_vec())?;
        sd.set_item("dt", s.dt_s)?;
        spec.set_item("solver", sd)?;
    }
    Ok(spec)
}

/// Writes a stage atomically (temporary file, usd-core validation, rename); returns the
/// validators' warnings.
pub fn write_usd(path: &Path, out: &StageOut<'_>) -> Result<Vec<String>> {
    check_extension(path)?;
    for m in &out.meshes {
        let n = m.frames.first().map_or(0, Vec::len);
        if m.frames
            .iter()
            .any(|f| f.len() != n || f.iter().any(|p| !p.iter().all(|c| c.is_finite())))
        {
            return Err(Error::Invalid(format!(
                "mesh '{}': frames differ in size or are not finite",
                m.name
            )));
        }
    }
    let p = path.to_string_lossy().into_owned();
    with_bridge(|py, module| {
        let spec = stage_spec(py, out)?;
        module
            .call_method1("write_stage", (p.as_str(), spec))?
            .extract::<Vec<String>>()
    })
}

/// Every issue usd-core's validators find in a file: `(severity, validator, message)`.
pub fn validate_usd(path: &Path) -> Result<Vec<(String, String, String)>> {
    let p = path_str(path)?;
    with_bridge(|_py, m| m.call_method1("validate", (p.as_str(),))?.extract())
}

impl MeshOut {
    /// A garment mesh: points, material coordinates as `st`, panel ids, seams, fabric.
    pub fn cloth(
        name: &str,
        mesh: &clothsr_geometry::mesh::ClothMesh,
        fabric: &Fabric,
        edge_m: f64,
    ) -> MeshOut {
        MeshOut {
            name: name.into(),
            group: "Garments".into(),
            triangles: mesh.triangles.clone(),
            frames: vec![mesh.positions.iter().map(|p| p.cast::<f32>()).collect()],
            time_codes: None,
            uv: Some(mesh.material.clone()),
            panel_ids: Some(mesh.panel_of_vertex.clone()),
            seam_pairs: Some(mesh.seam_pairs.clone()),
            fabric: Some((fabric.clone(), edge_m)),
            collider: false,
            animated: false,
            doc: None,
        }
    }

    /// A collider: static points, or one time sample per frame (time codes at `fps`).
    pub fn collider(c: &clothsr_geometry::scene::Collider, fps: f64) -> MeshOut {
        MeshOut {
            name: c.name.clone(),
            group: "Colliders".into(),
            triangles: c.triangles.clone(),
            frames: c.frames.clone(),
            time_codes: c
                .is_animated()
                .then(|| c.times_s.iter().map(|t| t * fps).collect()),
            collider: true,
            ..Default::default()
        }
    }
}

/// Writes an animation frame by frame into a USD file: the static content first, then one time
/// sample of points per frame for the meshes marked `animated`. `checkpoint` publishes a
/// consistent file with the frames so far; `finish` validates and publishes the final file.
pub struct AnimationWriter {
    writer: Py<PyAny>,
    names: Vec<String>,
}

impl AnimationWriter {
    /// Starts writing `out` (its animated meshes' first frame is the rest pose) to `path`.
    pub fn create(path: &Path, out: &StageOut<'_>) -> Result<AnimationWriter> {
        Self::open(path, out, None)
    }

    /// Starts writing `out` to `path` again after an interrupted run: the animated meshes'
    /// time samples up to `until` are taken from the file already at `path` (its last
    /// checkpoint), which must hold that frame.
    pub fn resume(path: &Path, out: &StageOut<'_>, until: f64) -> Result<AnimationWriter> {
        Self::open(path, out, Some(until))
    }

    fn open(path: &Path, out: &StageOut<'_>, until: Option<f64>) -> Result<AnimationWriter> {
        check_extension(path)?;
        let p = path.to_string_lossy().into_owned();
        let names = out
            .meshes
            .iter()
            .filter(|m| m.animated)
            .map(|m| m.name.clone())
            .collect();
        let writer = with_bridge(|py, module| {
            let spec = stage_spec(py, out)?;
            let class = if out.over.is_some() {
                "LayerWriter"
            } else {
                "AnimationWriter"
            };
            Ok(module
                .getattr(class)?
                .call1((p.as_str(), spec, until))?
                .unbind())
        })?;
        Ok(AnimationWriter { writer, names })
    }

    /// Adds one time sample: `points[k]` for the k-th animated mesh, in order.
    pub fn write_frame(&mut self, time_code: f64, points: &[&[Vector3<f64>]]) -> Result<()> {
        if points.len() != self.names.len() {
            return Err(Error::Invalid(format!(
                "{} point sets for {} animated meshes",
                points.len(),
                self.names.len()
            )));
        }
        let writer = &self.writer;
        let names = &self.names;
        with_bridge(|py, _| {
            let d = PyDict::new(py);
            for (name, pts) in names.iter().zip(points) {
                let flat: Vec<f32> = pts
                    .iter()
                    .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
                    .collect();
                d.set_item(name, to_np(py, flat, &[pts.len(), 3])?)?;
            }
            writer.call_method1(py, "write_frame", (time_code, d))?;
            Ok(())
        })
    }

    /// Publishes the frames written so far at the target path.
    pub fn checkpoint(&mut self) -> Result<()> {
        let writer = &self.writer;
        with_bridge(|py, _| writer.call_method0(py, "checkpoint").map(|_| ()))
    }

    /// Validates and publishes the final file; returns the validators' warnings.
    pub fn finish(self) -> Result<Vec<String>> {
        let writer = &self.writer;
        with_bridge(|py, _| writer.call_method0(py, "close")?.extract(py))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> UsdMesh {
        UsdMesh {
            path: "/World/cloth".into(),
            name: "cloth".into(),
            role: MeshRole::Cloth,
            skinned: false,
            face_counts: vec![4],
            face_indices: vec![0, 1, 2, 3],
            time_codes: vec![0.0],
            frames: vec![vec![
                Vector3::new(0.0, 0.0, 0.0),
                Vector3::new(1.0, 0.0, 0.0),
                Vector3::new(1.0, 1.0, 0.0),
                Vector3::new(0.0, 1.0, 0.0),
            ]],
            uv: None,
            panel_ids: None,
            seam_pairs: None,
            fabric: None,
        }
    }

    /// What the bridge hands over is checked on the Rust side too: each broken array is an
    /// error naming the file and the prim, never a panic (fuzz/regressions/usd_arrays).
    #[test]
    fn broken_arrays_from_the_bridge_are_errors_not_panics() {
        let file = Path::new("shot.usda");
        assert!(quad().check(file).is_ok());
        assert_eq!(quad().triangles(), vec![[0, 1, 2], [0, 2, 3]]);
        type Edit = fn(&mut UsdMesh);
        let cases: [(&str, Edit); 9] = [
            ("3 or more", |m| m.face_counts = vec![0, 4]),
            ("add up to", |m| m.face_counts = vec![5]),
            ("past its 4 points", |m| m.face_indices[2] = 9),
            ("topology changes", |m| {
                m.frames.push(vec![Vector3::zeros(); 3]);
                m.time_codes.push(1.0);
            }),
            ("not finite", |m| m.frames[0][1].x = f32::NAN),
            ("time codes", |m| {
                m.frames.push(m.frames[0].clone());
                m.time_codes.push(f64::NAN);
            }),
            ("primvars:st", |m| {
                m.uv = Some(UvData::Vertex(vec![Vector2::zeros(); 2]))
            }),
            ("panelId", |m| m.panel_ids = Some(vec![0; 3])),
            ("seamPairs", |m| m.seam_pairs = Some(vec![[0, 7]])),
        ];
        for (words, edit) in cases {
            let mut m = quad();
            edit(&mut m);
            let _ = m.triangles();
            let err = m.check(file).expect_err(words).to_string();
            assert!(
                err.contains("shot.usda") && err.contains("/World/cloth") && err.contains(words),
                "{words}: {err}"
            );
        }
    }
}
