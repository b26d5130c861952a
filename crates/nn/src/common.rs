//! What the two networks share: the device they run on, their weights files and their
//! model folders' JSON files.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, PoisonError};

use burn::module::{Module, ModuleVisitor, Param};
use burn::store::ModuleRecord;
use burn::tensor::{Bytes, Device, Tensor};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use clothsr_geometry::error::{Error, Result};
use clothsr_io::write_atomic;

/// Held while a network is initialised. burn's CPU backend draws every random weight from one
/// process-wide generator, so a seeded network is only reproducible if no other thread draws
/// between the seed and the last weight.
static INIT: Mutex<()> = Mutex::new(());

/// Initialises a network with `init`, from `seed` when given, under the process-wide lock on
/// burn's random generator. burn initialises parameters lazily, on first use: every one is
/// drawn here, under the lock. Every network in this crate is made through it, weights to be
/// loaded over included, so that a seeded initialisation is the same whatever other threads do.
pub fn init_network<M: Module>(device: &Device, seed: Option<u64>, init: impl FnOnce() -> M) -> M {
    let _draws = INIT.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some(seed) = seed {
        device.seed(seed);
    }
    let net = init();
    net.visit(&mut DrawEveryParameter);
    net
}

/// A network of the shape `init` makes ([`init_network`]), with the weights of the burnpack
/// file at `path` ([`load_weights`]).
pub fn load_network<M: Module>(
    device: &Device,
    path: &Path,
    init: impl FnOnce() -> M,
) -> Result<M> {
    load_weights(init_network(device, None, init), path)
}

/// Draws every lazily initialised float parameter of a module.
struct DrawEveryParameter;

impl ModuleVisitor for DrawEveryParameter {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let _ = param.val();
    }
}

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

/// The file in a checkpoint folder that names its resume point.
const STATE_FILE: &str = "state.json";

/// `state.json` in a training's checkpoint folder: where the training stands and the
/// generation of the weights and optimiser files that go with it.
#[derive(Serialize, Deserialize)]
struct State<P> {
    #[serde(flatten)]
    position: P,
    /// Resume points written before generations have none; their files are `model.bpk` and
    /// `optim.bpk`.
    #[serde(default)]
    generation: Option<u64>,
}

/// A training's resume point: its position, and the files of its weights and optimiser state.
pub struct ResumePoint<P> {
    /// Where the training stands.
    pub position: P,
    /// The network's weights file.
    pub weights: PathBuf,
    /// The optimiser state's file.
    pub optim: PathBuf,
}

fn generation_files(dir: &Path, generation: Option<u64>) -> (PathBuf, PathBuf) {
    match generation {
        Some(g) => (
            dir.join(format!("model.{g}.bpk")),
            dir.join(format!("optim.{g}.bpk")),
        ),
        None => (dir.join("model.bpk"), dir.join("optim.bpk")),
    }
}

/// The resume point in the checkpoint folder `dir`, if one is there.
pub fn read_resume_point<P: DeserializeOwned>(dir: &Path) -> Result<Option<ResumePoint<P>>> {
    let path = dir.join(STATE_FILE);
    if !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
    let state: State<P> =
        serde_json::from_str(&text).map_err(|e| Error::bad_input(&path, e.to_string()))?;
    let (weights, optim) = generation_files(dir, state.generation);
    Ok(Some(ResumePoint {
        position: state.position,
        weights,
        optim,
    }))
}

/// Writes a resume point into the checkpoint folder `dir`: `write` saves the weights and the
/// optimiser state to the two paths it is given, which name a new generation; then
/// `state.json`, written whole and renamed into place, names that generation beside
/// `position`; then older generations are removed. A run killed at any instant so leaves
/// one consistent resume point: the previous one until the rename, the new one after.
pub fn write_resume_point<P: Serialize>(
    dir: &Path,
    position: &P,
    write: impl FnOnce(&Path, &Path) -> Result<()>,
) -> Result<()> {
    let path = dir.join(STATE_FILE);
    let previous = match std::fs::read_to_string(&path) {
        Ok(text) => serde_json::from_str::<State<serde::de::IgnoredAny>>(&text)
            .map_err(|e| Error::bad_input(&path, e.to_string()))?
            .generation
            .unwrap_or(0),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => 0,
        Err(e) => return Err(Error::io(&path, e)),
    };
    let generation = previous
        .checked_add(1)
        .ok_or_else(|| Error::bad_input(&path, "its generation is at the largest number"))?;
    let (weights, optim) = generation_files(dir, Some(generation));
    write(&weights, &optim)?;
    write_json(
        &path,
        &State {
            position,
            generation: Some(generation),
        },
    )?;
    let keep = [weights, optim, path];
    for entry in std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))? {
        let file = entry.map_err(|e| Error::io(dir, e))?.path();
        let name = file.file_name().and_then(|n| n.to_str()).unwrap_or("");
        // Other generations, and the temporary files of writes that a kill interrupted.
        let stale =
            (name.starts_with("model.") || name.starts_with("optim.")) && !keep.contains(&file);
        if stale {
            std::fs::remove_file(&file).map_err(|e| Error::io(&file, e))?;
        }
    }
    Ok(())
}

/// Writes a training's resume point into the checkpoint folder `dir`
/// ([`write_resume_point`]): `net`'s weights and `optim`'s state beside `position`.
pub fn write_training_checkpoint<P: Serialize, M: Module>(
    dir: &Path,
    position: &P,
    net: &M,
    optim: &burn::optim::ModuleOptimizer,
) -> Result<()> {
    write_resume_point(dir, position, |w, o| {
        net.clone()
            .save_file(w)
            .map_err(|e| Error::Invalid(format!("{}: {e}", w.display())))?;
        optim
            .save(o)
            .map_err(|e| Error::Invalid(format!("{}: {e}", o.display())))
    })
}

/// Removes a finished training's checkpoint folder `dir`, its `state.json` first: a run killed
/// while the folder goes never finds a resume point whose files are gone.
pub fn remove_checkpoint(dir: &Path) -> Result<()> {
    let state = dir.join(STATE_FILE);
    match std::fs::remove_file(&state) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(Error::io(&state, e)),
    }
    std::fs::remove_dir_all(dir).map_err(|e| Error::io(dir, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
    struct Step {
        done: usize,
    }

    /// Writes a resume point at `done` whose two files hold `done` as text.
    fn save(dir: &Path, done: usize) -> Result<()> {
        write_resume_point(dir, &Step { done }, |w, o| {
            std::fs::write(w, done.to_string()).map_err(|e| Error::io(w, e))?;
            std::fs::write(o, done.to_string()).map_err(|e| Error::io(o, e))
        })
    }

    fn read(dir: &Path) -> (usize, String, String) {
        let p = read_resume_point::<Step>(dir)
            .expect("read")
            .expect("a point");
        let text = |f: &Path| std::fs::read_to_string(f).expect("its file");
        (p.position.done, text(&p.weights), text(&p.optim))
    }

    #[test]
    fn a_resume_point_stays_whole_when_a_write_stops_before_its_state() {
        let dir = tempfile::tempdir().expect("tmp");
        assert!(read_resume_point::<Step>(dir.path())
            .expect("read")
            .is_none());
        save(dir.path(), 250).expect("first");
        save(dir.path(), 500).expect("second");
        assert_eq!(read(dir.path()), (500, "500".into(), "500".into()));
        // Stopped after both files of the next generation are written, before `state.json`.
        let stopped = write_resume_point(dir.path(), &Step { done: 750 }, |w, o| {
            std::fs::write(w, "750").map_err(|e| Error::io(w, e))?;
            std::fs::write(o, "750").map_err(|e| Error::io(o, e))?;
            Err(Error::Invalid("killed".into()))
        });
        assert!(stopped.is_err());
        assert_eq!(read(dir.path()), (500, "500".into(), "500".into()));
        // The next point writes over the orphans, and only its generation stays.
        save(dir.path(), 750).expect("third");
        assert_eq!(read(dir.path()), (750, "750".into(), "750".into()));
        let mut names: Vec<_> = std::fs::read_dir(dir.path())
            .expect("dir")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, ["model.3.bpk", "optim.3.bpk", "state.json"]);
        // A write killed midway leaves its temporary file; the next point removes it.
        std::fs::write(dir.path().join("model.4.bpk.123-0.tmp"), "partial").expect("tmp");
        save(dir.path(), 1000).expect("fourth");
        assert!(!dir.path().join("model.4.bpk.123-0.tmp").exists());
    }

    #[test]
    fn a_resume_point_from_before_generations_names_its_plain_files() {
        let dir = tempfile::tempdir().expect("tmp");
        std::fs::write(dir.path().join("state.json"), r#"{"done": 250}"#).expect("state");
        std::fs::write(dir.path().join("model.bpk"), "250").expect("weights");
        std::fs::write(dir.path().join("optim.bpk"), "250").expect("optim");
        assert_eq!(read(dir.path()), (250, "250".into(), "250".into()));
        save(dir.path(), 500).expect("next");
        assert_eq!(read(dir.path()), (500, "500".into(), "500".into()));
        assert!(!dir.path().join("model.bpk").exists());
    }
}
