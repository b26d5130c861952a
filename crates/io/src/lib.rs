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
pub mod render;
pub mod scene_files;
pub mod tensors;
pub mod usd;

pub use scene_files::{FileKind, SceneFiles};

use std::io::Write;
use std::path::{Component, Path, PathBuf};

use clothsr_geometry::error::{Error, Result};

/// Writes `bytes` to `path` through a temporary file in the same directory, renamed into
/// place: readers never see a partial file, and a failed write leaves the old one. The
/// temporary file is `.{stem}.clothsr-tmp-{pid}{.ext}`, the name the USD bridge uses too, so
/// that the next writer of `path` removes what a killed one left.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = temp_path(path);
    let written = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written.map_err(|e| Error::io(path, e))
}

/// The temporary file a write of `path` by this process goes through, after removing those
/// that writers of `path` which are gone left behind.
pub fn temp_path(path: &Path) -> PathBuf {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = path
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    let prefix = format!(".{stem}.clothsr-tmp-");
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let Some(pid) = name
                .strip_prefix(&prefix)
                .and_then(|r| r.strip_suffix(ext.as_str()))
                .and_then(|p| p.parse::<u32>().ok())
            else {
                continue;
            };
            // A process that is gone has no /proc entry (Linux); elsewhere nothing is removed.
            if pid != std::process::id()
                && Path::new("/proc/self").exists()
                && !Path::new(&format!("/proc/{pid}")).exists()
            {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
    dir.join(format!("{prefix}{}{ext}", std::process::id()))
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

    /// A write killed mid-way leaves its temporary file: the next write of the same file
    /// removes it (its process is gone), keeps a live writer's, and leaves only the target.
    #[test]
    fn a_killed_writers_temporary_file_is_removed_by_the_next_write() {
        let dir = tempfile::tempdir().expect("tempdir");
        let target = dir.path().join("report.md");
        let dead = dir.path().join(".report.clothsr-tmp-4000000000.md");
        let other = dir.path().join(".plot.clothsr-tmp-4000000000.png");
        std::fs::write(&dead, b"partial").expect("write");
        std::fs::write(&other, b"partial").expect("write");
        write_atomic(&target, b"whole").expect("write_atomic");
        assert_eq!(std::fs::read(&target).expect("read"), b"whole");
        assert!(!dead.exists(), "the dead writer's file stays");
        assert!(other.exists(), "another file's temporary was removed");
        let mut names: Vec<_> = std::fs::read_dir(dir.path())
            .expect("read_dir")
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, [".plot.clothsr-tmp-4000000000.png", "report.md"]);
    }
}
