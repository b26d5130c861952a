//! Rerun previews (the paper's Fig. 2 made visible): the colliders (avatar), the coarse mesh
//! M_c, the corrected M_int and the fine mesh M_f on a `frame` timeline, per-stage timings as
//! scalar plots, and per-vertex error heat maps when a ground truth is known (Fig. 9/10).
//!
//! A recording saved to a file is written beside its target under a temporary name and renamed
//! into place by [`Recorder::finish`]; a run that fails leaves no half-written `.rrd` behind.
//! Topology (triangle indices) is logged once as static data; each frame sends only positions,
//! normals and, for heat maps, colours.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use crate::error::{Error, Result};
use crate::transfer::vertex_normals;

/// Entity paths of the pipeline's meshes.
pub mod paths {
    /// The fine mesh M_f (the super-resolution output).
    pub const FINE: &str = "world/fine";
    /// The coarse simulator's output M_c.
    pub const COARSE: &str = "world/coarse/m_c";
    /// The corrected coarse mesh M_int.
    pub const M_INT: &str = "world/coarse/m_int";
    /// The ground truth's fine mesh, when one is given.
    pub const GROUND_TRUTH: &str = "world/ground_truth";
    /// Colliders (avatars, obstacles) live under this path.
    pub const COLLIDERS: &str = "world/colliders";
    /// Per-stage timings, seconds per frame.
    pub const TIMINGS: &str = "timings";
    /// Fine vertices the pipeline found inside the colliders and pushed out, per frame.
    pub const PUSHED_OUT: &str = "fine/pushed_out_of_bodies";
}

/// Colours (RGBA) of the meshes.
pub mod colours {
    /// Fine cloth.
    pub const FINE: u32 = 0xE8_A0_60_FF;
    /// Coarse simulator output.
    pub const COARSE: u32 = 0x60_90_E0_FF;
    /// Corrected coarse mesh.
    pub const M_INT: u32 = 0x60_C0_80_FF;
    /// The ground truth.
    pub const GROUND_TRUTH: u32 = 0xD0_D0_A0_FF;
    /// Colliders.
    pub const COLLIDER: u32 = 0xB0_B0_B0_FF;
}

fn rerun_error(what: &str, e: impl std::fmt::Display) -> Error {
    Error::Invalid(format!("rerun: {what}: {e}"))
}

fn points(x: &[Vector3<f64>]) -> Vec<[f32; 3]> {
    x.iter()
        .map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect()
}

fn normals(triangles: &[[u32; 3]], x: &[Vector3<f64>]) -> Vec<[f32; 3]> {
    points(&vertex_normals(triangles, x))
}

/// A Rerun recording: saved to an `.rrd` file or streamed to a viewer.
pub struct Recorder {
    rec: rerun::RecordingStream,
    /// (temporary file being written, final path) for a saved recording.
    file: Option<(PathBuf, PathBuf)>,
}

impl Recorder {
    /// A recording saved to `path` (an `.rrd`) when [`Recorder::finish`] is called.
    pub fn save(application: &'static str, path: &Path) -> Result<Recorder> {
        if path.extension().and_then(|e| e.to_str()) != Some("rrd") {
            return Err(Error::bad_input(
                path,
                "a Rerun recording must have the .rrd extension",
            ));
        }
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        if !dir.is_dir() {
            return Err(Error::bad_input(path, "the folder does not exist"));
        }
        // Written under the house's temporary name, which the next recording of `path`
        // removes when its process is gone.
        let tmp = crate::io::temp_path(path);
        let rec = rerun::RecordingStreamBuilder::new(application)
            .save(&tmp)
            .map_err(|e| Error::bad_input(path, format!("cannot start the recording: {e}")))?;
        Ok(Recorder {
            rec,
            file: Some((tmp, path.to_path_buf())),
        })
    }

    /// A recording streamed live to a Rerun viewer, started if none is running (needs the
    /// `rerun` program on the PATH: `pip install rerun-sdk==0.36.3`).
    pub fn spawn(application: &'static str) -> Result<Recorder> {
        let rec = rerun::RecordingStreamBuilder::new(application)
            .spawn()
            .map_err(|e| {
                rerun_error(
                    "cannot start a viewer (install one with 'pip install rerun-sdk==0.36.3', or save with --rrd)",
                    e,
                )
            })?;
        Ok(Recorder { rec, file: None })
    }

    /// Sets the current frame of the `frame` timeline.
    pub fn set_frame(&self, frame: i64) {
        self.rec.set_time_sequence("frame", frame);
    }

    /// Logs a mesh's topology and colour once; positions follow with [`Recorder::mesh_positions`].
    pub fn mesh_topology(&self, entity: &str, triangles: &[[u32; 3]], colour: u32) -> Result<()> {
        let mesh = rerun::Mesh3D::update_fields()
            .with_triangle_indices(triangles.iter().copied())
            .with_albedo_factor(colour);
        self.rec
            .log_static(entity, &mesh)
            .map_err(|e| rerun_error(entity, e))
    }

    /// Logs a mesh's positions (and normals) at the current frame.
    pub fn mesh_positions(
        &self,
        entity: &str,
        triangles: &[[u32; 3]],
        x: &[Vector3<f64>],
    ) -> Result<()> {
        let mesh = rerun::Mesh3D::update_fields()
            .with_vertex_positions(points(x))
            .with_vertex_normals(normals(triangles, x));
        self.rec
            .log(entity, &mesh)
            .map_err(|e| rerun_error(entity, e))
    }

    /// Logs a mesh at the current frame coloured by a per-vertex error, metres, on a colour
    /// scale from 0 (blue) to `max_m` (red) and beyond.
    pub fn mesh_heat_map(
        &self,
        entity: &str,
        triangles: &[[u32; 3]],
        x: &[Vector3<f64>],
        error_m: &[f64],
        max_m: f64,
    ) -> Result<()> {
        let colours: Vec<u32> = error_m
            .iter()
            .map(|&e| heat_colour(e / max_m.max(f64::MIN_POSITIVE)))
            .collect();
        let mesh = rerun::Mesh3D::update_fields()
            .with_vertex_positions(points(x))
            .with_vertex_normals(normals(triangles, x))
            .with_vertex_colors(colours);
        self.rec
            .log(entity, &mesh)
            .map_err(|e| rerun_error(entity, e))
    }

    /// Logs a whole static mesh (a fixed collider) once.
    pub fn static_mesh(
        &self,
        entity: &str,
        triangles: &[[u32; 3]],
        x: &[Vector3<f64>],
        colour: u32,
    ) -> Result<()> {
        let mesh = rerun::Mesh3D::new(points(x))
            .with_triangle_indices(triangles.iter().copied())
            .with_vertex_normals(normals(triangles, x))
            .with_albedo_factor(colour);
        self.rec
            .log_static(entity, &mesh)
            .map_err(|e| rerun_error(entity, e))
    }

    /// Logs a scalar at the current frame (a point of a time plot).
    pub fn scalar(&self, entity: &str, value: f64) -> Result<()> {
        self.rec
            .log(entity, &rerun::Scalars::new([value]))
            .map_err(|e| rerun_error(entity, e))
    }

    /// Flushes the recording and, for a saved one, renames it into place. Returns the path.
    pub fn finish(mut self) -> Result<Option<PathBuf>> {
        self.rec
            .flush_blocking()
            .map_err(|e| rerun_error("flushing the recording", e))?;
        let Some((tmp, path)) = self.file.take() else {
            return Ok(None);
        };
        // Dropping the stream closes the file sink; only then is the file complete.
        let rec = std::mem::replace(&mut self.rec, rerun::RecordingStream::disabled());
        drop(rec);
        std::fs::rename(&tmp, &path).map_err(|e| Error::io(&path, e))?;
        Ok(Some(path))
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        // Not finished: the recording is incomplete, so it is removed rather than published.
        if let Some((tmp, _)) = self.file.take() {
            let rec = std::mem::replace(&mut self.rec, rerun::RecordingStream::disabled());
            drop(rec);
            let _ = std::fs::remove_file(tmp);
        }
    }
}

/// A colour scale for errors: `t` = 0 blue, 0.5 green-yellow, 1 (and beyond) red, as RGBA.
pub fn heat_colour(t: f64) -> u32 {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        1.0
    };
    // Piecewise-linear blue → cyan → yellow → red.
    let stops: [(f64, [f64; 3]); 4] = [
        (0.0, [0.15, 0.25, 0.85]),
        (0.33, [0.1, 0.8, 0.85]),
        (0.66, [0.95, 0.9, 0.2]),
        (1.0, [0.85, 0.1, 0.1]),
    ];
    let i = stops.iter().rposition(|s| s.0 <= t).unwrap_or(0).min(2);
    let (a, b) = (stops[i], stops[i + 1]);
    let s = ((t - a.0) / (b.0 - a.0)).clamp(0.0, 1.0);
    let c: Vec<u32> = (0..3)
        .map(|k| ((a.1[k] + s * (b.1[k] - a.1[k])) * 255.0).round() as u32)
        .collect();
    (c[0] << 24) | (c[1] << 16) | (c[2] << 8) | 0xFF
}

/// What an `.rrd` file holds, read back by decoding every message.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RrdSummary {
    /// Messages of any kind.
    pub messages: usize,
    /// Data chunks.
    pub chunks: usize,
    /// Entity paths that received data, without the leading '/' (as they are logged).
    pub entities: BTreeSet<String>,
}

/// Decodes a whole `.rrd` file: fails on anything that is not a valid recording.
pub fn read_rrd(path: &Path) -> Result<RrdSummary> {
    use rerun::external::re_log_encoding::DecoderApp;
    use rerun::external::re_log_types::LogMsg;
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let decoder = DecoderApp::decode_eager(std::io::BufReader::new(file))
        .map_err(|e| Error::bad_input(path, format!("not a Rerun recording: {e}")))?;
    let mut summary = RrdSummary::default();
    for msg in decoder {
        let msg = msg.map_err(|e| Error::bad_input(path, format!("corrupt recording: {e}")))?;
        summary.messages += 1;
        if let LogMsg::ArrowMsg(_, arrow) = &msg {
            let chunk = rerun::log::Chunk::from_arrow_msg(arrow)
                .map_err(|e| Error::bad_input(path, format!("corrupt chunk: {e}")))?;
            summary.chunks += 1;
            // Rerun prints entity paths with a leading '/'; ours are written without one.
            let entity = chunk.entity_path().to_string();
            summary
                .entities
                .insert(entity.trim_start_matches('/').to_string());
        }
    }
    if summary.messages == 0 {
        return Err(Error::bad_input(path, "the recording is empty"));
    }
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heat_colours_run_blue_to_red() {
        assert_eq!(
            heat_colour(0.0) >> 8 & 0xFF,
            (0.85f64 * 255.0).round() as u32
        );
        assert_eq!(heat_colour(1.0) >> 24, (0.85f64 * 255.0).round() as u32);
        assert_eq!(heat_colour(2.0), heat_colour(1.0));
        assert_eq!(heat_colour(f64::NAN), heat_colour(1.0));
        assert_eq!(heat_colour(-1.0), heat_colour(0.0));
    }

    #[test]
    fn a_saved_recording_reads_back_and_a_dropped_one_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let tris = vec![[0u32, 1, 2]];
        let x = vec![
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
        ];
        let path = dir.path().join("t.rrd");
        let r = Recorder::save("clothsr_test", &path).unwrap();
        r.mesh_topology(paths::FINE, &tris, colours::FINE).unwrap();
        for f in 0..3 {
            r.set_frame(f);
            r.mesh_positions(paths::FINE, &tris, &x).unwrap();
            r.scalar("timings/msr_s", 0.1 * f as f64).unwrap();
        }
        assert!(!path.exists(), "published before finish");
        assert_eq!(r.finish().unwrap().as_deref(), Some(path.as_path()));
        let s = read_rrd(&path).unwrap();
        assert!(s.entities.contains(paths::FINE), "{s:?}");
        assert!(s.entities.contains("timings/msr_s"), "{s:?}");
        assert!(s.chunks >= 2);

        let dropped = dir.path().join("d.rrd");
        let r = Recorder::save("clothsr_test", &dropped).unwrap();
        r.scalar("x", 1.0).unwrap();
        drop(r);
        assert!(!dropped.exists());
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(left.len(), 1, "temporary files left: {left:?}");

        // A partial recording of a process that is gone is removed by the next recording.
        let stale = dir.path().join(".t.clothsr-tmp-2147483600.rrd");
        std::fs::write(&stale, b"partial").unwrap();
        let r = Recorder::save("clothsr_test", &path).unwrap();
        assert!(!stale.exists());
        drop(r);

        std::fs::write(dir.path().join("bad.rrd"), b"not a recording").unwrap();
        assert!(read_rrd(&dir.path().join("bad.rrd")).is_err());
        assert!(Recorder::save("x", &dir.path().join("x.usd")).is_err());
    }
}
