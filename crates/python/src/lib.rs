//! `clothsr._clothsr`: the clothsr library loaded in-process into a Python interpreter (a venv's,
//! or a DCC's own with its `pxr`). It only wires the library: each function turns its arguments
//! into a library call, runs it with the GIL released, and returns plain Python values. The
//! `clothsr` package (`python/clothsr/__init__.py`) wraps these for users: `Usd.Stage` inputs,
//! default models, the output layer.

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::Mutex;

use clothsr::data::SceneSource;
use clothsr::garment::{Fabric, FabricPreset};
use clothsr::io::scene_files::{convert as convert_scene, Convert};
use clothsr::io::SceneFiles;
use clothsr::pipeline::shot::{run_shot, RunModels, ShotFiles};
use clothsr::pipeline::CorrectorChoice;
use clothsr::pipeline::Options;
use clothsr::scene::Scene;
use clothsr::ErrorKind;
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};

create_exception!(
    _clothsr,
    ClothsrError,
    PyException,
    "A clothsr failure: bad input (naming the file and element), a failed simulation, I/O."
);
create_exception!(
    _clothsr,
    UsageError,
    ClothsrError,
    "The call asks for something that cannot be done (an option out of range, an unknown \
     fabric); the `clothsr` command exits with 2."
);
create_exception!(
    _clothsr,
    BadInputError,
    ClothsrError,
    "An input file (scene, garment, avatar, models folder) is wrong; the message names the \
     file and the element. The `clothsr` command exits with 3."
);
create_exception!(
    _clothsr,
    RunError,
    ClothsrError,
    "The work failed while running (a simulation that cannot go on, a full disk, the USD \
     library); the `clothsr` command exits with 4."
);
create_exception!(
    _clothsr,
    Cancelled,
    ClothsrError,
    "The progress callback stopped the work (it returned False). A run's output keeps the \
     frames so far and a resume point: the same call again continues from there."
);

/// The library's error as the exception of its kind.
fn error(e: clothsr::Error) -> PyErr {
    let message = e.to_string();
    match e.kind() {
        ErrorKind::Usage => UsageError::new_err(message),
        ErrorKind::Input => BadInputError::new_err(message),
        ErrorKind::Failure => RunError::new_err(message),
    }
}

fn usage(message: String) -> PyErr {
    UsageError::new_err(message)
}

fn fabric(name: &str) -> PyResult<Fabric> {
    name.parse::<FabricPreset>()
        .map(Fabric::from)
        .map_err(|e| UsageError::new_err(e.to_string()))
}

/// A progress callback shared with the worker: it is called with the GIL taken; returning
/// `False` stops the work, raising stops it and the exception is re-raised to the caller.
/// Ctrl-C (when the call came from the main thread) stops it too.
struct Callback {
    callback: Option<Py<PyAny>>,
    failure: Mutex<Option<PyErr>>,
    cancelled: Mutex<bool>,
}

impl Callback {
    fn new(callback: Option<Py<PyAny>>) -> Callback {
        Callback {
            callback,
            failure: Mutex::new(None),
            cancelled: Mutex::new(false),
        }
    }

    /// Calls the callback with the arguments `args` makes; `Break` asks the work to stop.
    fn call(
        &self,
        args: impl for<'py> FnOnce(Python<'py>) -> PyResult<Bound<'py, PyTuple>>,
    ) -> ControlFlow<()> {
        Python::attach(|py| {
            let outcome = py.check_signals().and_then(|()| match &self.callback {
                Some(cb) => cb.call1(py, args(py)?).map(Some),
                None => Ok(None),
            });
            match outcome {
                Ok(Some(r)) if r.bind(py).is(pyo3::types::PyBool::new(py, false)) => {
                    if let Ok(mut c) = self.cancelled.lock() {
                        *c = true;
                    }
                    ControlFlow::Break(())
                }
                Ok(_) => ControlFlow::Continue(()),
                Err(e) => {
                    if let Ok(mut f) = self.failure.lock() {
                        *f = Some(e);
                    }
                    ControlFlow::Break(())
                }
            }
        })
    }

    /// The exception to raise when the work stopped early: the callback's own, else
    /// [`Cancelled`].
    fn stopped(&self, what: &str) -> PyErr {
        if let Some(e) = self.failure.lock().ok().and_then(|mut f| f.take()) {
            return e;
        }
        Cancelled::new_err(format!("{what} cancelled by the progress callback"))
    }

    fn was_stopped(&self) -> bool {
        self.cancelled.lock().map(|c| *c).unwrap_or(false)
            || self.failure.lock().map(|f| f.is_some()).unwrap_or(false)
    }
}

/// Runs the whole pipeline on one shot into `output` (see `clothsr.run`).
#[pyfunction]
#[pyo3(signature = (scene, output, models, *, frames=None, fabric="cotton", avatar=None,
    colliders=Vec::new(), corrector="auto", restart=false, ascii=false, rrd=None,
    layer="auto", clip_frames=clothsr::pipeline::shot::DEFAULT_CLIP_FRAMES,
    publish_every_s=None, progress=None))]
#[allow(clippy::too_many_arguments)]
fn run<'py>(
    py: Python<'py>,
    scene: PathBuf,
    output: PathBuf,
    models: PathBuf,
    frames: Option<usize>,
    fabric: &str,
    avatar: Option<PathBuf>,
    colliders: Vec<PathBuf>,
    corrector: &str,
    restart: bool,
    ascii: bool,
    rrd: Option<PathBuf>,
    layer: &str,
    clip_frames: usize,
    publish_every_s: Option<f64>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    self::fabric(fabric)?;
    let choice: CorrectorChoice = corrector.parse().map_err(usage)?;
    let source = SceneSource {
        scene,
        colliders,
        avatar,
        fabric: fabric.to_string(),
    };
    let files = ShotFiles {
        output,
        rrd,
        ascii,
        restart,
        kind: layer.parse().map_err(usage)?,
        clip_frames,
        publish_every_s,
        ..ShotFiles::default()
    };
    let callback = Callback::new(progress);
    let report = py.detach(|| {
        let models = RunModels::load(&models, choice, Options::default())?;
        run_shot(&models, &source, &files, frames, |g| {
            callback.call(|py| (g.frame, g.frames).into_pyobject(py))
        })
    });
    let report = report.map_err(error)?;
    if report.run.stopped || callback.was_stopped() {
        return Err(callback.stopped("the run"));
    }
    let out = PyDict::new(py);
    out.set_item("frames_computed", report.run.frames_computed)?;
    out.set_item("resumed_after", report.run.resumed_after)?;
    out.set_item("wall_s", report.run.wall_s)?;
    out.set_item("simulator_s", report.run.totals.simulator_s)?;
    out.set_item("corrector_s", report.run.totals.corrector_s)?;
    out.set_item("msr_s", report.run.totals.msr_s)?;
    out.set_item("coarse_vertices", report.coarse_vertices)?;
    out.set_item("fine_vertices", report.fine_vertices)?;
    Ok(out)
}

/// A USD scene with clothsr's schema from garments and colliders (see `clothsr.convert`);
/// returns the writer's warnings.
#[pyfunction]
#[pyo3(signature = (inputs, output, *, colliders=Vec::new(), avatar=None, fabric="cotton",
    fps=None, frames=None, ascii=false))]
#[allow(clippy::too_many_arguments)]
fn convert(
    py: Python<'_>,
    inputs: Vec<PathBuf>,
    output: PathBuf,
    colliders: Vec<PathBuf>,
    avatar: Option<PathBuf>,
    fabric: &str,
    fps: Option<f64>,
    frames: Option<i64>,
    ascii: bool,
) -> PyResult<Vec<String>> {
    let c = Convert {
        inputs,
        colliders: colliders.into_iter().chain(avatar).collect(),
        fabric: self::fabric(fabric)?,
        fps,
        frames,
    };
    py.detach(|| {
        clothsr::io::usd::check_extension(&output)?;
        convert_scene(&c)?.write_usd(&output, ascii)
    })
    .map_err(error)
}

/// What a garment, mesh or scene file holds (see `clothsr.inspect`).
#[pyfunction]
#[pyo3(signature = (path, *, fabric="cotton"))]
fn inspect<'py>(py: Python<'py>, path: PathBuf, fabric: &str) -> PyResult<Bound<'py, PyDict>> {
    let fabric = self::fabric(fabric)?;
    let scene = py.detach(|| Scene::load(&path, &fabric)).map_err(error)?;
    let out = PyDict::new(py);
    let garments = PyList::empty(py);
    for g in &scene.garments {
        let d = PyDict::new(py);
        d.set_item("name", &g.name)?;
        d.set_item(
            "panels",
            g.panels.iter().map(|p| p.name.clone()).collect::<Vec<_>>(),
        )?;
        d.set_item("seams", g.seams.len())?;
        d.set_item("area_m2", g.area())?;
        d.set_item("fabric", &g.fabric.name)?;
        garments.append(d)?;
    }
    let cloths = PyList::empty(py);
    for c in &scene.cloths {
        let d = PyDict::new(py);
        d.set_item("name", &c.name)?;
        d.set_item("vertices", c.mesh.num_vertices())?;
        d.set_item("triangles", c.mesh.triangles.len())?;
        d.set_item("fabric", &c.fabric.name)?;
        cloths.append(d)?;
    }
    let colliders = PyList::empty(py);
    for c in &scene.colliders {
        let d = PyDict::new(py);
        d.set_item("name", &c.name)?;
        d.set_item("vertices", c.frames.first().map_or(0, Vec::len))?;
        d.set_item("triangles", c.triangles.len())?;
        d.set_item("frames", c.frames.len())?;
        colliders.append(d)?;
    }
    out.set_item("garments", garments)?;
    out.set_item("cloths", cloths)?;
    out.set_item("colliders", colliders)?;
    out.set_item("fps", scene.fps)?;
    out.set_item("frame_start", scene.frame_start)?;
    out.set_item("frame_end", scene.frame_end)?;
    Ok(out)
}

/// Where a batch writes the shot `scene` in `out_dir` (as `clothsr run --out-dir`).
#[pyfunction]
fn shot_output(scene: PathBuf, out_dir: PathBuf) -> PyResult<PathBuf> {
    clothsr::pipeline::shot::shot_output(&scene, &out_dir)
        .ok_or_else(|| UsageError::new_err(format!("{}: no file name", scene.display())))
}

/// A batch's summary (the `clothsr run --json` form, as JSON text) of its shots' summaries
/// (JSON text of a list) and an error before any shot (JSON text, or None): its status and
/// exit code as the command gives them.
#[pyfunction]
#[pyo3(signature = (shots, error=None))]
fn summarise(shots: &str, error: Option<&str>) -> PyResult<String> {
    use clothsr::pipeline::shot::{ErrorSummary, RunSummary, ShotSummary};
    let bad = |e: serde_json::Error| UsageError::new_err(format!("not a shot summary: {e}"));
    let shots: Vec<ShotSummary> = serde_json::from_str(shots).map_err(bad)?;
    let error: Option<ErrorSummary> = error.map(serde_json::from_str).transpose().map_err(bad)?;
    let summary = RunSummary::of(shots, error.map(|e| (e.kind, e.message)));
    serde_json::to_string(&summary).map_err(|e| RunError::new_err(e.to_string()))
}

/// Per-frame errors of `prediction` (and baselines) against a fine simulation (see
/// `clothsr.eval`).
#[pyfunction]
#[pyo3(signature = (prediction, ground_truth, *, baselines=Vec::new()))]
fn eval<'py>(
    py: Python<'py>,
    prediction: PathBuf,
    ground_truth: PathBuf,
    baselines: Vec<(String, PathBuf)>,
) -> PyResult<Bound<'py, PyDict>> {
    use clothsr::eval::{measure, summarise, Animation};
    let series = py
        .detach(|| -> clothsr::Result<_> {
            let pred = Animation::read_usd(&prediction)?;
            let start = pred.time_codes.first().copied().unwrap_or(0.0);
            let gt = Animation::read(&ground_truth, start)?;
            let mut anims = vec![pred];
            for (_, path) in &baselines {
                anims.push(Animation::read(path, start)?);
            }
            let names = std::iter::once(("prediction".to_string(), prediction.as_path()))
                .chain(baselines.iter().map(|(n, p)| (n.clone(), p.as_path())));
            let labelled: Vec<_> = names
                .zip(&anims)
                .map(|((name, path), a)| (name, a, path))
                .collect();
            measure(&gt, &labelled)
        })
        .map_err(error)?;
    let out = PyDict::new(py);
    for (name, frames) in &series {
        let s = summarise(frames);
        let d = PyDict::new(py);
        d.set_item("frames", s.frames)?;
        d.set_item("mean_mm", s.mean_mm)?;
        d.set_item("max_mm", s.max_mm)?;
        d.set_item("std_mm", s.std_mm)?;
        d.set_item("normal_deg", s.normal_deg)?;
        d.set_item("jitter_mm", s.jitter_mm)?;
        d.set_item(
            "per_frame_mean_mm",
            frames
                .iter()
                .map(|f| (f.time_code, f.mean_mm))
                .collect::<Vec<_>>(),
        )?;
        out.set_item(name, d)?;
    }
    Ok(out)
}

/// A fit's plan for `shot` (see `clothsr.fit`).
#[allow(clippy::too_many_arguments)]
fn fit_plan_of(
    shot: PathBuf,
    generic_isr: Option<PathBuf>,
    quality: &str,
    fabric: &str,
    avatar: Option<PathBuf>,
    colliders: Vec<PathBuf>,
    frames: Option<usize>,
    isr_steps: Option<usize>,
    coarse_mm: Option<f64>,
    fine_mm: Option<f64>,
) -> PyResult<(clothsr::pipeline::fit::Plan, SceneSource)> {
    use clothsr::pipeline::fit::{FitOptions, Plan, Quality};
    self::fabric(fabric)?;
    let quality: Quality = quality.parse().map_err(usage)?;
    let source = SceneSource {
        scene: shot,
        colliders,
        avatar,
        fabric: fabric.to_string(),
    }
    .absolute();
    let edge = |mm: Option<f64>, default_m: f64, name: &str| match mm {
        Some(v) if v.is_finite() && v > 0.0 => Ok(v * 1e-3),
        Some(v) => Err(usage(format!("{name} must be positive, got {v}"))),
        None => Ok(default_m),
    };
    let opts = FitOptions {
        quality,
        coarse_edge_m: edge(coarse_mm, clothsr::mesh::COARSE_EDGE_M, "coarse_mm")?,
        fine_edge_m: edge(fine_mm, clothsr::mesh::FINE_EDGE_M, "fine_mm")?,
        frames,
        isr_steps,
        generic_isr,
    };
    let scene = source.load().map_err(error)?;
    let plan = Plan::new(source.clone(), &scene, &opts).map_err(error)?;
    Ok((plan, source))
}

/// The best models for one shot (see `clothsr.fit`).
#[pyfunction]
#[pyo3(signature = (shot, output, *, generic_isr=None, quality="preview", fabric="cotton",
    avatar=None, colliders=Vec::new(), frames=None, isr_steps=None, coarse_mm=None,
    fine_mm=None, progress=None))]
#[allow(clippy::too_many_arguments)]
fn fit(
    py: Python<'_>,
    shot: PathBuf,
    output: PathBuf,
    generic_isr: Option<PathBuf>,
    quality: &str,
    fabric: &str,
    avatar: Option<PathBuf>,
    colliders: Vec<PathBuf>,
    frames: Option<usize>,
    isr_steps: Option<usize>,
    coarse_mm: Option<f64>,
    fine_mm: Option<f64>,
    progress: Option<Py<PyAny>>,
) -> PyResult<()> {
    let (plan, _) = py.detach(|| {
        fit_plan_of(
            shot,
            generic_isr,
            quality,
            fabric,
            avatar,
            colliders,
            frames,
            isr_steps,
            coarse_mm,
            fine_mm,
        )
    })?;
    let callback = Callback::new(progress);
    let done = py
        .detach(|| {
            clothsr::pipeline::fit::run(&plan, &output, |p| {
                callback.call(|py| (p.done, p.total, p.message.as_str()).into_pyobject(py))
            })
        })
        .map_err(error)?;
    if !done || callback.was_stopped() {
        return Err(callback.stopped("the fit"));
    }
    Ok(())
}

/// Writes a fit's plan into `output` (a plan already there must be the same) and returns its
/// tasks in order, as (id, ids of the tasks it needs): for running them on a cluster
/// (`clothsr.batch.fit`), each with `fit_task`.
#[pyfunction]
#[pyo3(signature = (shot, output, *, generic_isr=None, quality="preview", fabric="cotton",
    avatar=None, colliders=Vec::new(), frames=None, isr_steps=None, coarse_mm=None,
    fine_mm=None))]
#[allow(clippy::too_many_arguments)]
fn fit_plan(
    py: Python<'_>,
    shot: PathBuf,
    output: PathBuf,
    generic_isr: Option<PathBuf>,
    quality: &str,
    fabric: &str,
    avatar: Option<PathBuf>,
    colliders: Vec<PathBuf>,
    frames: Option<usize>,
    isr_steps: Option<usize>,
    coarse_mm: Option<f64>,
    fine_mm: Option<f64>,
) -> PyResult<Vec<(String, Vec<String>)>> {
    py.detach(|| {
        let (plan, _) = fit_plan_of(
            shot,
            generic_isr,
            quality,
            fabric,
            avatar,
            colliders,
            frames,
            isr_steps,
            coarse_mm,
            fine_mm,
        )?;
        clothsr::pipeline::fit::save_plan(&plan, &output).map_err(error)?;
        Ok(plan
            .tasks
            .iter()
            .map(|t| (t.id.clone(), t.after.clone()))
            .collect())
    })
}

/// Runs task `id` of the fit planned in `output` (`fit_plan`), once the tasks it needs are
/// done; `progress(done, total, message)` as `fit`'s.
#[pyfunction]
#[pyo3(signature = (output, id, *, progress=None))]
fn fit_task(
    py: Python<'_>,
    output: PathBuf,
    id: &str,
    progress: Option<Py<PyAny>>,
) -> PyResult<()> {
    let callback = Callback::new(progress);
    let done = py
        .detach(|| {
            let plan = clothsr::pipeline::fit::Plan::load(&output)?;
            clothsr::pipeline::fit::run_one(&plan, &output, id, |p| {
                callback.call(|py| (p.done, p.total, p.message.as_str()).into_pyobject(py))
            })
        })
        .map_err(error)?;
    if !done || callback.was_stopped() {
        return Err(callback.stopped("the task"));
    }
    Ok(())
}

/// The clothsr library, in-process.
#[pymodule]
fn _clothsr(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // USD through this interpreter's own `pxr` and the bridge installed beside this module.
    clothsr::io::python::use_host_interpreter();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("ClothsrError", m.py().get_type::<ClothsrError>())?;
    m.add("UsageError", m.py().get_type::<UsageError>())?;
    m.add("BadInputError", m.py().get_type::<BadInputError>())?;
    m.add("RunError", m.py().get_type::<RunError>())?;
    m.add("Cancelled", m.py().get_type::<Cancelled>())?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(convert, m)?)?;
    m.add_function(wrap_pyfunction!(inspect, m)?)?;
    m.add_function(wrap_pyfunction!(eval, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(fit_plan, m)?)?;
    m.add_function(wrap_pyfunction!(fit_task, m)?)?;
    m.add_function(wrap_pyfunction!(shot_output, m)?)?;
    m.add_function(wrap_pyfunction!(summarise, m)?)?;
    Ok(())
}
