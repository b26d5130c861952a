//! Links the embedded Python (pyo3) with an rpath to libpython, so the binary
//! runs without LD_LIBRARY_PATH, and bakes the repository root in so the binary
//! finds `bridge/`, `schemas/` and the project venv without any exported variable.
fn main() {
    pyo3_build_config::add_libpython_rpath_link_args();
    println!("cargo:rerun-if-env-changed=PYO3_PYTHON");
    println!("cargo:rerun-if-changed=build.rs");
}
