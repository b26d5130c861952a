//! # clothsr-io — files in and out
//!
//! GarmentCode JSON (parsed in [`clothsr_geometry::garment::garmentcode`]), OBJ through tobj,
//! USD through usd-core and the embedded-Python bridge ([`python`], [`usd`]); scenes read from
//! and written to files ([`SceneFiles`]); tensors; and the training data sets made by
//! simulating a scene at both resolutions ([`data`]).

pub mod data;
pub mod dressed;
pub mod models;
pub mod obj;
pub mod python;
pub mod scene_files;
pub mod tensors;
pub mod usd;

pub use scene_files::{FileKind, SceneFiles};

use std::io::Write;
use std::path::{Component, Path, PathBuf};

use clothsr_geometry::error::{Error, Result};

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

/// `path` as a file in folder `base` names it: relative to `base` when both are on the same
/// root, else absolute. A folder that travels (a models folder in a repository, a data set
/// moved to another machine) keeps naming its inputs through the paths around it.
pub fn relative_to(path: &Path, base: &Path) -> PathBuf {
    let (path, base) = (absolute(path), absolute(base));
    pathdiff::diff_paths(&path, &base).unwrap_or(path)
}

/// A path read from a file in folder `base` ([`relative_to`]): relative ones are from `base`.
pub fn resolve_against(path: &Path, base: &Path) -> PathBuf {
    absolute(&base.join(path))
}

/// `path` made absolute from the working directory, `.` and `..` taken lexically (as
/// [`relative_to`] makes them), so that one file has one name.
pub fn absolute(path: &Path) -> PathBuf {
    let full = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut out = PathBuf::new();
    for c in full.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    out.push(c);
                }
            }
            _ => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_relative_to_a_folder_resolve_back() {
        let base = Path::new("/repo/samples/models/table");
        let scene = Path::new("/repo/samples/./x/../sheet_table.usda");
        let rel = relative_to(scene, base);
        assert_eq!(rel, Path::new("../../sheet_table.usda"));
        assert_eq!(
            resolve_against(&rel, base),
            Path::new("/repo/samples/sheet_table.usda")
        );
        // Absolute paths read back as they are; relative inputs are from the working folder.
        assert_eq!(resolve_against(scene, base), absolute(scene));
        let cwd = std::env::current_dir().expect("cwd");
        assert_eq!(absolute(Path::new("a/../b")), cwd.join("b"));
    }
}
