//! Files in and out: GarmentCode JSON (in [`crate::garment::garmentcode`]), OBJ through tobj,
//! USD through usd-core and the embedded-Python bridge.

pub mod obj;
pub mod python;
pub mod tensors;
pub mod usd;

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
