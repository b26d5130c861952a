//! The Python interpreter (pyo3) that runs clothsr's USD bridge (`bridge/clothsr_usd`).
//!
//! Two cases:
//! - **Embedded** (the `clothsr` command, the tests): on first use it starts an interpreter, adds
//!   the project venv's site-packages (where usd-core and numpy live), puts `bridge/` on
//!   `sys.path` and imports it (the bridge registers its `schemas/`). Locations default to the
//!   repository the binary was built from, so nothing has to be exported:
//!   - `CLOTHSR_ROOT`: the directory holding `bridge/`;
//!   - `CLOTHSR_VENV` (else `VIRTUAL_ENV`, else `<root>/.venv`): the Python environment.
//! - **Host** (the `clothsr` Python package, in a venv or a DCC's own Python, after
//!   [`use_host_interpreter`]): the interpreter that loaded the package, with its own `pxr`,
//!   imports the bridge installed beside the package; nothing is added to its paths.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::OnceLock;

use pyo3::exceptions::PyImportError;
use pyo3::prelude::*;
use pyo3::types::PyModule;

use clothsr_geometry::error::{Error, Result};

/// Name of the bridge package.
const BRIDGE: &str = "clothsr_usd";

/// The directory holding `bridge/`.
pub fn repo_root() -> PathBuf {
    std::env::var_os("CLOTHSR_ROOT")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            // This crate lives in `crates/io` of the repository.
            let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
            crate_dir
                .parent()
                .and_then(Path::parent)
                .unwrap_or(crate_dir)
                .to_path_buf()
        })
}

/// The Python environment that holds usd-core and numpy.
pub fn venv_dir() -> PathBuf {
    std::env::var_os("CLOTHSR_VENV")
        .or_else(|| std::env::var_os("VIRTUAL_ENV"))
        .map(PathBuf::from)
        .unwrap_or_else(|| repo_root().join(".venv"))
}

fn setup_hint() -> String {
    format!(
        "run `bash .ci/setup` in {} (it creates .venv with usd-core==26.11 and numpy), or point \
         CLOTHSR_VENV at an environment that has them",
        repo_root().display()
    )
}

/// Set when a host interpreter loaded clothsr (see [`use_host_interpreter`]).
static HOST: AtomicBool = AtomicBool::new(false);

/// Runs the bridge in the Python interpreter that loaded clothsr as an extension module (the
/// `clothsr` package), with that interpreter's own `pxr` and the `clothsr_usd` package
/// installed beside it; no environment or path is added. Call it before the first USD call.
pub fn use_host_interpreter() {
    HOST.store(true, Ordering::SeqCst);
}

/// Imports the bridge in a host interpreter.
fn init_host(py: Python<'_>) -> std::result::Result<(), String> {
    match py.import(BRIDGE) {
        Ok(_) => Ok(()),
        Err(e) if e.is_instance_of::<PyImportError>(py) => Err(format!(
            "cannot import clothsr's USD bridge in this Python: {e}. The host needs USD's Python \
             modules (`pxr`): a DCC's own, or `pip install usd-core`"
        )),
        Err(e) => Err(format!("cannot start the USD bridge: {e}")),
    }
}

fn init(py: Python<'_>) -> std::result::Result<(), String> {
    if HOST.load(Ordering::SeqCst) {
        return init_host(py);
    }
    let fail = |e: PyErr| e.to_string();
    let sys = py.import("sys").map_err(fail)?;
    let (major, minor): (u32, u32) = {
        let vi = sys.getattr("version_info").map_err(fail)?;
        (
            vi.getattr("major")
                .and_then(|v| v.extract())
                .map_err(fail)?,
            vi.getattr("minor")
                .and_then(|v| v.extract())
                .map_err(fail)?,
        )
    };
    let venv = venv_dir();
    let site_packages = venv
        .join("lib")
        .join(format!("python{major}.{minor}"))
        .join("site-packages");
    if !site_packages.is_dir() {
        return Err(format!(
            "no Python {major}.{minor} environment at {}: {}",
            venv.display(),
            setup_hint()
        ));
    }
    let site = py.import("site").map_err(fail)?;
    site.call_method1("addsitedir", (site_packages.to_string_lossy().as_ref(),))
        .map_err(fail)?;
    let root = repo_root();
    let bridge_dir = root.join("bridge");
    if !bridge_dir.join(BRIDGE).is_dir() {
        return Err(format!(
            "the USD bridge is not at {} (set CLOTHSR_ROOT to the clothsr repository)",
            bridge_dir.display()
        ));
    }
    sys.getattr("path")
        .and_then(|p| p.call_method1("insert", (0, bridge_dir.to_string_lossy().as_ref())))
        .map_err(fail)?;
    match py.import(BRIDGE) {
        Ok(_) => Ok(()),
        Err(e) if e.is_instance_of::<PyImportError>(py) => Err(format!(
            "cannot import usd-core from {}: {e}. {}",
            venv.display(),
            setup_hint()
        )),
        Err(e) => Err(format!("cannot start the USD bridge: {e}")),
    }
}

/// Turns a Python exception into an [`Error::Bridge`]: the bridge's own errors already name the
/// file and element, others keep their type name.
fn to_error(py: Python<'_>, e: PyErr) -> Error {
    let ty = e
        .get_type(py)
        .name()
        .map(|n| n.to_string())
        .unwrap_or_default();
    let msg = e.value(py).to_string();
    if ty == "BadInput" || ty == "ValueError" {
        Error::Bridge {
            message: msg,
            input: ty == "BadInput",
        }
    } else {
        Error::Bridge {
            message: format!("{ty}: {msg}"),
            input: false,
        }
    }
}

/// Variables numpy sets at import when they are absent (`numpy/_core/__init__.py`), which it does
/// with `putenv`, outside the lock that `std::process::Command` holds while it hands the
/// environment to a child. A `putenv` that reallocates the environment while another thread spawns
/// gives that child a freed pointer (seen as `EFAULT` from exec in our CLI tests). Setting them
/// first, through `std::env`, which takes that lock, leaves numpy nothing to write. (The bridge
/// itself registers the schema without touching the environment.)
const NUMPY_SETS: [&str; 2] = ["OPENBLAS_MAIN_FREE", "GOTOBLAS_MAIN_FREE"];

fn settle_environment() {
    for key in NUMPY_SETS {
        if std::env::var_os(key).is_none() {
            std::env::set_var(key, "1");
        }
    }
}

/// Runs `f` with the imported bridge module, starting Python on first use.
pub fn with_bridge<T>(
    f: impl for<'py> FnOnce(Python<'py>, &Bound<'py, PyModule>) -> PyResult<T>,
) -> Result<T> {
    static INIT: OnceLock<std::result::Result<(), String>> = OnceLock::new();
    // Initialise before taking the GIL for the call: a thread waiting on the OnceLock must not
    // hold the GIL, which the initialising thread (importing modules) gives up and takes back.
    INIT.get_or_init(|| {
        settle_environment();
        // Starts the embedded interpreter where none runs (the `clothsr` command, tests); in a
        // host that has one (a DCC's Python) this does nothing.
        Python::initialize();
        Python::attach(init)
    })
    .clone()
    .map_err(|message| Error::Bridge {
        message,
        input: false,
    })?;
    Python::attach(|py| {
        let module = py.import(BRIDGE).map_err(|e| to_error(py, e))?;
        f(py, &module).map_err(|e| to_error(py, e))
    })
}
