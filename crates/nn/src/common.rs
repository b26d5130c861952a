//! What the two networks share: the device they run on, their weights files and their
//! model folders' JSON files.

use std::path::Path;

use burn::module::Module;
use burn::store::ModuleRecord;
use burn::tensor::{Bytes, Device};
use serde::Serialize;

use clothsr_geometry::error::{Error, Result};
use clothsr_io::write_atomic;

/// Loads `module`'s weights from the burnpack file at `path`, read whole into memory first.
/// burn's own `try_load_file` keeps the file open as the tensors' lazy source and reads each one
/// when it is first used, so a model folder removed or rewritten during a long run (a re-train
/// beside `clothsr run`) made burn panic mid-run; here it is read, or refused with the file
/// named, before any work.
pub fn load_weights<M: Module>(module: M, path: &Path) -> Result<M> {
    let bytes = std::fs::read(path)
        .map_err(|e| Error::bad_input(path, format!("cannot read the weights: {e}")))?;
    let record = ModuleRecord::from_bytes(Bytes::from_bytes_vec(bytes))
        .map_err(|e| Error::bad_input(path, format!("cannot load the weights: {e}")))?;
    module
        .try_load_record(record)
        .map_err(|e| Error::bad_input(path, format!("cannot load the weights: {e}")))
}

/// The device networks run on, chosen at run time by `CLOTHSR_DEVICE`: `flex` (the default:
/// burn's pure-Rust CPU backend, the fastest of burn's CPU backends here), or `cuda` / `wgpu`
/// in builds with those cargo features.
pub fn default_device() -> Result<Device> {
    let name = std::env::var("CLOTHSR_DEVICE").unwrap_or_else(|_| "flex".into());
    match name.as_str() {
        "flex" | "" => Ok(Device::flex()),
        #[cfg(feature = "cuda")]
        "cuda" => Ok(Device::cuda(0)),
        #[cfg(feature = "wgpu")]
        "wgpu" => Ok(Device::wgpu(burn::tensor::DeviceKind::DefaultDevice)),
        other => Err(Error::Invalid(format!(
            "CLOTHSR_DEVICE={other}: this build knows flex{}{}",
            if cfg!(feature = "cuda") { ", cuda" } else { "" },
            if cfg!(feature = "wgpu") { ", wgpu" } else { "" },
        ))),
    }
}

/// Writes `value` as pretty JSON, atomically.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_vec_pretty(value)
        .map_err(|e| Error::Invalid(format!("{}: {e}", path.display())))?;
    write_atomic(path, &text)
}
