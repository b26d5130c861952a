//! Stages what the wheel carries beside the extension module (`pyproject.toml` includes them
//! from here): the USD bridge `clothsr_usd` (with its schema) and the generic models.
use std::path::Path;

fn copy_dir(src: &Path, dst: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(dst)?;
    for entry in std::fs::read_dir(src)? {
        let entry = entry?;
        let path = entry.path();
        let name = entry.file_name();
        if path.is_dir() {
            if name != "__pycache__" && name != "data" {
                copy_dir(&path, &dst.join(&name))?;
            }
        } else if path.extension().is_none_or(|e| e != "pyc") {
            std::fs::copy(&path, dst.join(&name))?;
        }
    }
    Ok(())
}

fn main() -> std::io::Result<()> {
    let out = std::path::PathBuf::from(std::env::var("OUT_DIR").map_err(std::io::Error::other)?);
    // Read when the script runs, not when it was compiled: a target directory shared by two
    // checkouts reuses the compiled script.
    let manifest_dir = std::env::var("CARGO_MANIFEST_DIR").map_err(std::io::Error::other)?;
    let root = Path::new(&manifest_dir).join("../..");
    copy_dir(&root.join("bridge/clothsr_usd"), &out.join("clothsr_usd"))?;
    // The generic models without their training-data manifests.
    copy_dir(&root.join("models/generic"), &out.join("models/generic"))?;
    println!("cargo:rerun-if-changed=../../bridge/clothsr_usd");
    println!("cargo:rerun-if-changed=../../models/generic");
    println!("cargo:rerun-if-changed=build.rs");
    Ok(())
}
