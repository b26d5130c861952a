//! # clothsr-io — files in and out
//!
//! GarmentCode JSON (parsed in [`clothsr_geometry::garment::garmentcode`]), OBJ through tobj,
//! USD through usd-core and the embedded-Python bridge ([`python`], [`usd`]); scenes read from
//! and written to files ([`SceneFiles`]); tensors; and the training data sets made by
//! simulating a scene at both resolutions ([`data`]).

pub mod data;
pub mod models;
pub mod obj;
pub mod python;
pub mod scene_files;
pub mod tensors;
pub mod usd;

pub(crate) use clothsr_geometry::{error, garment, mesh, scene, transfer};
pub(crate) use clothsr_sim as sim;

pub use scene_files::{FileKind, SceneFiles};

use std::io::Write;
use std::path::Path;

use crate::error::{Error, Result};

/// Writes `bytes` to `path` through a temporary file in the same directory, renamed into
/// place: readers never see a partial file, and a failed write leaves the old one.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(|e| Error::io(path, e))?;
    tmp.write_all(bytes).map_err(|e| Error::io(path, e))?;
    // Temporary files are private (0600); what we publish is an ordinary file.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(0o644))
            .map_err(|e| Error::io(path, e))?;
    }
    tmp.persist(path).map_err(|e| Error::io(path, e.error))?;
    Ok(())
}

/// A training run's CSV log at `path`: a resumed run (`resuming`) appends to the log it left,
/// a new one starts it afresh with the `header` line.
pub fn open_log(path: &Path, resuming: bool, header: &str) -> Result<std::fs::File> {
    let mut log = std::fs::OpenOptions::new()
        .create(true)
        .append(resuming)
        .write(true)
        .truncate(!resuming)
        .open(path)
        .map_err(|e| Error::io(path, e))?;
    if !resuming {
        writeln!(log, "{header}").map_err(|e| Error::io(path, e))?;
    }
    Ok(log)
}
