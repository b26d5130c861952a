//! OBJ through tobj: triangle meshes, texture coordinates (`vt`) as material coordinates, and
//! numbered OBJ sequences (`frame_%04d.obj`) as animated colliders.

use std::path::{Path, PathBuf};

use nalgebra::{Vector2, Vector3};

use clothsr_geometry::error::{Error, Result};

/// A triangle mesh read from OBJ; vertices are split where texture coordinates differ.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjMesh {
    /// Positions, metres (as written in the file).
    pub positions: Vec<Vector3<f64>>,
    /// Per-vertex texture coordinates, when the file has `vt` for every face corner.
    pub uv: Option<Vec<Vector2<f64>>>,
    /// Triangles (polygons are fan-triangulated).
    pub triangles: Vec<[u32; 3]>,
}

/// Reads every object of an OBJ file into one mesh.
pub fn read_obj(path: &Path) -> Result<ObjMesh> {
    let bytes = std::fs::read(path)
        .map_err(|e| Error::bad_input(path, format!("cannot open the file: {e}")))?;
    parse_obj(&bytes, path)
}

/// The first face corner of OBJ text `bytes` whose vertex index is out of range, in words.
fn bad_face_index(bytes: &[u8]) -> Option<String> {
    let text = String::from_utf8_lossy(bytes);
    let mut vertices: i64 = 0;
    for (line_no, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => vertices += 1,
            Some("f") => {
                for corner in words {
                    let Some(Ok(i)) = corner.split('/').next().map(str::parse::<i64>) else {
                        continue;
                    };
                    let resolved = if i < 0 { vertices + i + 1 } else { i };
                    if i == 0 || resolved < 1 || resolved > vertices {
                        return Some(format!(
                            "line {}: face vertex index {i} is outside the {vertices} vertices \
                             defined before it",
                            line_no + 1
                        ));
                    }
                }
            }
            _ => {}
        }
    }
    None
}

/// Reads OBJ text (`bytes`; errors name `path`); materials are ignored.
pub fn parse_obj(bytes: &[u8], path: &Path) -> Result<ObjMesh> {
    let mut reader = std::io::BufReader::new(bytes);
    let opts = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, _) =
        tobj::load_obj_buf(&mut reader, &opts, |_| Err(tobj::LoadError::OpenFileFailed)).map_err(
            |e| match e {
                tobj::LoadError::OpenFileFailed => Error::bad_input(path, "cannot open the file"),
                other => match bad_face_index(bytes) {
                    Some(why) => Error::bad_input(path, format!("malformed OBJ: {why}")),
                    None => Error::bad_input(path, format!("malformed OBJ: {other}")),
                },
            },
        )?;
    let mut mesh = ObjMesh {
        positions: Vec::new(),
        uv: Some(Vec::new()),
        triangles: Vec::new(),
    };
    for model in &models {
        let m = &model.mesh;
        let offset = mesh.positions.len() as u32;
        let n = m.positions.len() / 3;
        for (i, c) in m.positions.chunks_exact(3).enumerate() {
            let p = Vector3::new(f64::from(c[0]), f64::from(c[1]), f64::from(c[2]));
            if !p.iter().all(|x| x.is_finite()) {
                return Err(Error::bad_input(
                    path,
                    format!(
                        "object '{}' vertex {i}: coordinates are not finite",
                        model.name
                    ),
                ));
            }
            mesh.positions.push(p);
        }
        match (&mut mesh.uv, m.texcoords.len() == 2 * n && n > 0) {
            (Some(uv), true) => uv.extend(
                m.texcoords
                    .chunks_exact(2)
                    .map(|c| Vector2::new(f64::from(c[0]), f64::from(c[1]))),
            ),
            (uv, _) => *uv = None,
        }
        for t in m.indices.chunks_exact(3) {
            if t.iter().any(|&v| v as usize >= n) {
                return Err(Error::bad_input(
                    path,
                    format!("object '{}': face index out of range", model.name),
                ));
            }
            mesh.triangles
                .push([t[0] + offset, t[1] + offset, t[2] + offset]);
        }
    }
    if mesh.triangles.is_empty() {
        return Err(Error::bad_input(path, "no faces"));
    }
    Ok(mesh)
}

/// Expands a numbered sequence pattern: `frame_%04d.obj` (printf style) or `frame_####.obj`.
/// Returns the existing files in order, starting at frame 0 or 1, stopping at the first gap.
pub fn sequence_files(pattern: &Path) -> Result<Vec<PathBuf>> {
    let text = pattern.to_string_lossy();
    let (prefix, width, suffix) = if let Some(i) = text.find('%') {
        let rest = &text[i + 1..];
        let d = rest
            .find('d')
            .ok_or_else(|| Error::bad_input(pattern, "expected %0Nd in a sequence pattern"))?;
        let width: usize = rest[..d].trim_start_matches('0').parse().unwrap_or(1);
        (text[..i].to_string(), width, rest[d + 1..].to_string())
    } else if let Some(i) = text.find('#') {
        let n = text[i..].chars().take_while(|c| *c == '#').count();
        (text[..i].to_string(), n, text[i + n..].to_string())
    } else {
        return Err(Error::bad_input(
            pattern,
            "not a sequence pattern (use %04d or ####)",
        ));
    };
    let name = |k: usize| PathBuf::from(format!("{prefix}{k:0width$}{suffix}"));
    let first = if name(0).exists() { 0 } else { 1 };
    let files: Vec<PathBuf> = (first..).map(name).take_while(|p| p.exists()).collect();
    if files.is_empty() {
        return Err(Error::bad_input(pattern, "no file of the sequence exists"));
    }
    Ok(files)
}

/// Triangles shared by every frame of a sequence, and the points of each frame.
pub type Sequence = (Vec<[u32; 3]>, Vec<Vec<Vector3<f64>>>);

/// Reads an OBJ sequence: the shared triangles and one frame of positions per file. Every file
/// must have the same topology.
pub fn read_obj_sequence(pattern: &Path) -> Result<Sequence> {
    let files = sequence_files(pattern)?;
    let first = read_obj(&files[0])?;
    let mut frames = vec![first.positions];
    for f in &files[1..] {
        let m = read_obj(f)?;
        if m.triangles != first.triangles {
            return Err(Error::bad_input(
                f,
                format!(
                    "topology differs from the sequence's first file {}",
                    files[0].display()
                ),
            ));
        }
        frames.push(m.positions);
    }
    Ok((first.triangles, frames))
}
