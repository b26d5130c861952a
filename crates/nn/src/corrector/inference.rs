//! The trained corrector at run time (the paper's §3.1.2–3.1.3): after every coarse simulator
//! step, M_c → M_int by q′ = q + p, x′ = x + h·p, and the simulator goes on from M_int.
//!
//! A model directory holds `config.json` ([`super::training::TrainingConfig`], which includes
//! the network's [`CorrectorConfig`]), `normalisation.json` and `model.bpk` (burnpack weights).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use burn::tensor::{Device, Int, Tensor};
use nalgebra::Vector3;

use super::fused::{FusedInputs, FusedNet};
use super::graph::{step_change, MeshGraph, ProximityCache, EDGE_FEATURES, NODE_FEATURES};
use super::model::{index_tensor, CorrectorConfig, CorrectorNet, GraphTensors};
use super::normalise::Normalisation;
use super::training::TrainingConfig;
use crate::common::{default_device, load_network};
use clothsr_geometry::error::{Error, Result};
use clothsr_geometry::mesh::ClothMesh;
use clothsr_io::data::flat32;
use clothsr_sim::driver::Simulation;
use clothsr_sim::SimState;

/// The weights file in a model directory.
pub const WEIGHTS_FILE: &str = "model.bpk";
/// The training configuration file in a model directory.
pub const CONFIG_FILE: &str = "config.json";
/// The normalisation statistics file in a model directory.
pub const NORMALISATION_FILE: &str = "normalisation.json";

/// Normalised network inputs for positions `x`, velocities `v`, the step's velocity changes
/// `dv` ([`super::graph::step_change`]) and body proximities `body` on `graph`: node rows
/// `[n, NODE_FEATURES]`, edge rows `[e, EDGE_FEATURES]`.
pub fn features(
    graph: &MeshGraph,
    x: &[Vector3<f64>],
    v: &[Vector3<f64>],
    dv: &[Vector3<f64>],
    body: &[f32],
    norm: &Normalisation,
) -> (Vec<f32>, Vec<f32>) {
    let (mut nodes, mut edges) = (Vec::new(), Vec::new());
    graph.node_features(v, dv, body, &mut nodes);
    graph.edge_features(x, v, &mut edges);
    norm.nodes.apply(&mut nodes);
    norm.edges.apply(&mut edges);
    (nodes, edges)
}

/// Largest correction accepted beyond the step's velocity change (which the gated decoder
/// may take back), in standard deviations of the training targets (per component):
/// the network extrapolating far outside its data is a failure to report, not a correction
/// to apply. The data sets here have |p̄| below ~8 σ.
pub const MAX_CORRECTION_STD: f32 = 25.0;

/// Fastest vertex accepted after a correction, m/s. Interleaving can run away without any
/// single correction being large (each step's velocity bias is fed back into the next step);
/// garments on people and cloth falling a few metres stay well below this.
pub const MAX_CORRECTED_SPEED_M_S: f64 = 20.0;

/// Time spent in each part of [`Corrector::correct`] since the corrector was loaded.
#[derive(Debug, Default)]
pub struct CorrectorTimes {
    calls: AtomicU64,
    proximity_ns: AtomicU64,
    features_ns: AtomicU64,
    network_ns: AtomicU64,
}

impl CorrectorTimes {
    fn add(counter: &AtomicU64, since: Instant) {
        counter.fetch_add(since.elapsed().as_nanos() as u64, Ordering::Relaxed);
    }

    /// Mean ms per call: (body proximity, features and normalisation, network forward and
    /// read-back).
    pub fn mean_ms(&self) -> (f64, f64, f64) {
        let n = self.calls.load(Ordering::Relaxed).max(1) as f64 * 1e6;
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed) as f64 / n;
        (
            get(&self.proximity_ns),
            get(&self.features_ns),
            get(&self.network_ns),
        )
    }
}

/// A loaded corrector for one coarse mesh.
#[derive(Debug)]
pub struct Corrector {
    /// Where its time goes.
    pub times: CorrectorTimes,
    net: CorrectorNet,
    /// The network's weights for the fused CPU forward pass ([`super::fused`]), used when
    /// the network is on burn's CPU device; `None`: burn runs it.
    fused: Option<FusedNet>,
    norm: Normalisation,
    graph: MeshGraph,
    /// The graph's edge lists on the device, uploaded once.
    senders: Tensor<1, Int>,
    receivers: Tensor<1, Int>,
    /// The network's sizes.
    pub config: CorrectorConfig,
    /// How it was trained (including the coarse simulator's set-up it needs,
    /// [`TrainingConfig::prepare_coarse`]).
    pub training: TrainingConfig,
    /// Where it was loaded from.
    pub dir: PathBuf,
    /// The colliders' BVHs for the body proximity, kept between steps.
    proximity: Mutex<ProximityCache>,
}

/// Reads a JSON file, naming it in errors.
pub(super) fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| Error::bad_input(path, e.to_string()))
}

/// Loads the network and statistics saved in `dir` onto `device`.
pub fn load_net(
    dir: &Path,
    device: &Device,
) -> Result<(CorrectorNet, Normalisation, TrainingConfig)> {
    let config_path = dir.join(CONFIG_FILE);
    if !config_path.exists() {
        return Err(Error::bad_input(
            dir,
            "not a corrector model directory (no config.json); train one with \
             'clothsr lab train corrector'",
        ));
    }
    let config = TrainingConfig::load(&config_path)?;
    config.model.check().map_err(|e| e.in_file(&config_path))?;
    let norm_path = dir.join(NORMALISATION_FILE);
    let norm: Normalisation = read_json(&norm_path)?;
    if norm.nodes.mean.len() != NODE_FEATURES || norm.edges.mean.len() != EDGE_FEATURES {
        return Err(Error::bad_input(
            &norm_path,
            format!(
                "the model has {} node and {} edge features, this clothsr's corrector {} and {}: \
                 it was made by an older clothsr; train it again with 'clothsr lab train corrector'",
                norm.nodes.mean.len(),
                norm.edges.mean.len(),
                NODE_FEATURES,
                EDGE_FEATURES
            ),
        ));
    }
    let weights = dir.join(WEIGHTS_FILE);
    let net = load_network(device, &weights, || config.model.init(device))?;
    Ok((net, norm, config))
}

/// Per-vertex weights on the gated decoder's take-back at positions `x` of `graph`'s mesh, as
/// a network with `config` runs at inference: the tension limit
/// ([`CorrectorConfig::tension_ramp`]) times the take-back scale
/// ([`CorrectorConfig::take_back`]); `None` when neither applies.
pub fn take_back_weights(
    config: &CorrectorConfig,
    graph: &MeshGraph,
    x: &[Vector3<f64>],
) -> Option<Vec<f32>> {
    let scale = config.take_back();
    let mut w = match config.tension_ramp() {
        Some(r) => graph.tension_weight(x, r),
        None if scale.is_some() => vec![1.0; x.len()],
        None => return None,
    };
    if let Some(k) = scale {
        w.iter_mut().for_each(|w| *w *= k as f32);
    }
    Some(w)
}

impl Corrector {
    /// Loads the model in `dir` for `mesh` (the coarse simulation mesh).
    pub fn load(dir: &Path, mesh: &ClothMesh) -> Result<Corrector> {
        let device = default_device()?;
        let (net, norm, config) = load_net(dir, &device)?;
        Ok(Corrector::new(net, norm, config, mesh, dir, &device))
    }

    /// A corrector from a network on `device` (trained with `config`, inputs and outputs
    /// scaled by `norm`) for `mesh`; `dir` is only reported (training validates the network
    /// it is training this way).
    pub fn new(
        net: CorrectorNet,
        norm: Normalisation,
        config: TrainingConfig,
        mesh: &ClothMesh,
        dir: &Path,
        device: &Device,
    ) -> Corrector {
        let graph = MeshGraph::new(mesh);
        Corrector {
            times: CorrectorTimes::default(),
            fused: (*device == Device::flex()).then(|| FusedNet::of(&net)),
            net,
            norm,
            senders: index_tensor(&graph.senders, device),
            receivers: index_tensor(&graph.receivers, device),
            graph,
            config: config.model.clone(),
            training: config,
            dir: dir.to_path_buf(),
            proximity: Mutex::default(),
        }
    }

    /// Whether the network runs on the fused CPU forward pass ([`super::fused`]) rather than
    /// on burn (only for a network on burn's CPU device).
    pub fn is_fused(&self) -> bool {
        self.fused.is_some()
    }

    /// Runs the network on burn from now on (the same function as the fused pass, to the
    /// rounding of its sums): for comparing the two (`clothsr lab bench pipeline`, the tests).
    pub fn use_burn(&mut self) {
        self.fused = None;
    }

    /// The predicted velocity correction p for M_c = (x, v), reached by a step that changed
    /// the velocities by `dv` beyond gravity ([`step_change`]), with body proximities `body`
    /// ([`super::graph::body_proximity`]), m/s per vertex.
    /// The gated decoder's tension limit ([`CorrectorConfig::tension_ramp`]) is measured at x.
    pub fn predict(
        &self,
        x: &[Vector3<f64>],
        v: &[Vector3<f64>],
        dv: &[Vector3<f64>],
        body: &[f32],
    ) -> Result<Vec<Vector3<f64>>> {
        let n = x.len();
        if n != self.graph.num_nodes || v.len() != n || dv.len() != n || body.len() != n {
            return Err(Error::Invalid(format!(
                "the corrector was set up for {} vertices, the state has {}",
                self.graph.num_nodes,
                x.len()
            )));
        }
        let t = Instant::now();
        let (nodes, edges) = features(&self.graph, x, v, dv, body, &self.norm);
        CorrectorTimes::add(&self.times.features_ns, t);
        let t = Instant::now();
        let mut step_change = flat32(dv);
        self.norm.targets.apply(&mut step_change);
        let tension = self.take_back_weights(x);
        let parts = rayon::current_num_threads();
        let mut p: Vec<f32> = match &self.fused {
            Some(fused) => fused.forward(
                FusedInputs {
                    nodes: &nodes,
                    edges: &edges,
                    senders: &self.graph.senders,
                    receivers: &self.graph.receivers,
                    step_change: &step_change,
                    tension: tension.as_deref(),
                },
                parts,
            ),
            // On rayon's threads too, as the fused pass runs.
            None => rayon::scope(|_| {
                let g = GraphTensors::with_indices(
                    nodes,
                    edges,
                    self.senders.clone(),
                    self.receivers.clone(),
                    step_change.clone(),
                )
                .with_tension(tension);
                self.net
                    .forward_in_parts(&g, parts)
                    .into_data()
                    .try_to_vec::<f32>()
                    .map_err(|e| Error::Invalid(format!("corrector output: {e:?}")))
            })?,
        };
        CorrectorTimes::add(&self.times.network_ns, t);
        if let Some(k) = (0..p.len()).find(|&k| {
            (p[k].abs() > MAX_CORRECTION_STD + step_change[k].abs()) || !p[k].is_finite()
        }) {
            return Err(Error::Simulation(format!(
                "the corrector diverged: its correction at vertex {} is {:.1} standard deviations \
                 of its training data (limit {MAX_CORRECTION_STD} beyond the step's velocity \
                 change, {:.1})",
                k / 3,
                p[k],
                step_change[k]
            )));
        }
        self.norm.targets.invert(&mut p);
        let p: Vec<Vector3<f64>> = p
            .chunks_exact(3)
            .map(|c| Vector3::new(f64::from(c[0]), f64::from(c[1]), f64::from(c[2])))
            .collect();
        if p.iter().any(|c| !c.iter().all(|x| x.is_finite())) {
            return Err(Error::Simulation(
                "the corrector produced a non-finite correction".into(),
            ));
        }
        Ok(p)
    }

    /// Per-vertex weights on the gated decoder's take-back at positions `x`
    /// ([`take_back_weights`]).
    fn take_back_weights(&self, x: &[Vector3<f64>]) -> Option<Vec<f32>> {
        take_back_weights(&self.config, &self.graph, x)
    }

    /// Corrects M_c = `state`, the result of a step of `sim` from velocities `start_v`, in
    /// place into M_int: q′ = q + p, x′ = x + h·p, p low-pass filtered by the model's
    /// [`CorrectorConfig::smoothing`] (the time step, gravity and colliders are
    /// `sim`'s, the colliders taken at `state.t_s`). A diverged correction (too large, or too
    /// fast a result) is an error and leaves `state` as it was.
    pub fn correct(
        &self,
        start_v: &[Vector3<f64>],
        state: &mut SimState,
        sim: &Simulation,
    ) -> Result<()> {
        // On one of rayon's threads, so that the proximity search's and the network's parallel
        // steps do not each hand their work over from the caller's thread and wait to be woken.
        rayon::scope(|_| self.correct_in_pool(start_v, state, sim))
    }

    /// [`Self::correct`] on the calling thread.
    fn correct_in_pool(
        &self,
        start_v: &[Vector3<f64>],
        state: &mut SimState,
        sim: &Simulation,
    ) -> Result<()> {
        let t = Instant::now();
        self.times.calls.fetch_add(1, Ordering::Relaxed);
        let body = self
            .proximity
            .lock()
            .map_err(|_| Error::Invalid("the corrector's collider cache was poisoned".into()))?
            .proximity(&state.x, &sim.colliders, state.t_s);
        let dt_s = sim.sim.params.dt_s;
        let dv = step_change(&state.v, start_v, sim.sim.params.gravity_m_s2 * dt_s);
        CorrectorTimes::add(&self.times.proximity_ns, t);
        let mut p = self.predict(&state.x, &state.v, &dv, &body)?;
        self.graph.smooth(&mut p, self.config.smoothing);
        if let Some((i, q)) = state
            .v
            .iter()
            .zip(&p)
            .map(|(v, p)| v + p)
            .enumerate()
            .find(|(_, q)| q.norm() > MAX_CORRECTED_SPEED_M_S)
        {
            return Err(Error::Simulation(format!(
                "the corrector diverged: vertex {i} would move at {:.1} m/s after its \
                 correction at t = {:.4} s (limit {MAX_CORRECTED_SPEED_M_S} m/s)",
                q.norm(),
                state.t_s
            )));
        }
        for ((x, v), p) in state.x.iter_mut().zip(state.v.iter_mut()).zip(&p) {
            *v += p;
            *x += p * dt_s;
        }
        Ok(())
    }
}
