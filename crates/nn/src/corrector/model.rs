//! The corrector network (the paper's §3.1.2, §3.3.2): MeshGraphNets' encode–process–decode
//! (Pfaff et al. 2020) on the coarse mesh graph.
//!
//! * Encoder: node MLP `NODE_FEATURES → L`, edge MLP `EDGE_FEATURES → L`.
//! * Processor: `steps` message-passing blocks with independent parameters,
//!   e′_ij ← e_ij + f_e(e_ij, v_i, v_j), v′_i ← v_i + f_v(v_i, Σ_j e′_ij) (messages summed at the
//!   receiver). With `attention`, the sum is replaced by a GATv2-style weighted sum
//!   (Brody et al. 2022): a score a·LeakyReLU(e′_ij) per edge, softmax over each receiver's
//!   incoming edges.
//! * Decoder: MLP `L → 3`, the velocity correction p_i (normalised units), the paper's
//!   ([`Decoder::Node`]).
//! * Or, with the `Gated` decoder (beyond the paper), p_i = −(1 − c_i)·γ_i ⊙ Δq_i +
//!   c_i·h(v_i): γ_i ∈ (0, 1)³ a sigmoid of a node MLP, Δq_i the simulator step's velocity
//!   change beyond gravity ([`super::graph::step_change`]), c_i = max(0, 1 − d_i/`CONTACT_RADIUS_M`)
//!   the contact weight (d_i the distance to the nearest collider). Away from colliders the
//!   corrector can then only scale down, per vertex and axis, what the simulator's forces did
//!   in the step: it is exactly zero in free fall, and interleaved with the simulator it makes
//!   a cloth that responds less (a fine cloth wrinkles where the coarse mesh must stretch),
//!   never one that gains energy from the corrector. In contact, where Δq holds the
//!   collider's push (which taking back would drive the cloth in), the correction is free
//!   instead: the resolutions' contacts differ. At inference the share taken back is
//!   further scaled per vertex by w = clamp(1 − ε̄/ramp, 0, 1), ε̄ the mean strain of its
//!   edges after the step ([`CorrectorConfig::tension_ramp`]): the fine cloth's wrinkles take
//!   up compression, not tension.
//!
//! Every MLP is ReLU with `hidden_layers` hidden layers of `latent` units; all but the decoder
//! end in a LayerNorm. Inputs and outputs are normalised outside the network
//! ([`super::normalise`]). Training runs this burn network; inference on the CPU runs its
//! weights through [`super::fused`].

use burn::module::Module;
use burn::nn::{LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::tensor::activation::{leaky_relu, relu, sigmoid};
use burn::tensor::{Device, IndexingUpdateOp, Int, Tensor, TensorData};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use clothsr_geometry::error::{Error, Result};

use super::graph::{MeshGraph, BODY_COLUMN, BODY_RADIUS_M, EDGE_FEATURES, NODE_FEATURES};

/// Sizes of the corrector network and its settings at inference (saved in `config.json`
/// beside the weights, [`super::training::TrainingConfig::model`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CorrectorConfig {
    /// Width of every latent vector and hidden layer (the paper: 64).
    pub latent: usize,
    /// Hidden layers per MLP (the paper: 2).
    pub hidden_layers: usize,
    /// Message-passing blocks (L).
    pub steps: usize,
    /// GATv2-style attention weights on the edge aggregation instead of a plain sum.
    pub attention: bool,
    /// The decoder ([`Decoder::Node`], the paper's, by default).
    pub decoder: Decoder,
    /// The gated decoder's tension limit at inference (beyond the paper): the share of the
    /// step's velocity change taken back is scaled by w = clamp(1 − ε̄/ramp, 0, 1), ε̄ the
    /// mean strain of the vertex's edges after the step
    /// ([`super::graph::MeshGraph::tension_weight`]). The finer cloth's wrinkles take up
    /// compression, not tension: the fine and coarse membranes resist stretching alike, and
    /// a corrector taking back their tension lets gravity stretch the interleaved cloth into
    /// states never seen in training (stretched where the data is slightly shortened).
    /// [`DEFAULT_TENSION_RAMP`] by default; 0: no limit. Training leaves it out: the data's
    /// one-step results are stretched by the simulator's spring-back at many vertices, and a
    /// corrector trained with the limit moved what it could not take back there into its
    /// free contact term and diverged.
    pub tension_ramp: f64,
    /// The gated decoder's take-back scale at inference (beyond the paper): the share of the
    /// step's velocity change taken back is multiplied by this, in (0, 1] (1 by default).
    /// Taking back most of each step's velocity change also takes back most of the cloth's
    /// elastic restoring force, and the corrected cloth then drifts under small per-step
    /// biases where the simulation alone would be pulled back (a corrector started on a
    /// settled ground truth drifts further from it than the simulation alone, and less with
    /// a smaller scale).
    pub take_back: f64,
    /// Low-pass filter on the correction at inference (beyond the paper, any decoder): this
    /// many rounds of mass-weighted averaging over each vertex and its graph neighbours
    /// ([`super::graph::MeshGraph::smooth`]) before the correction is applied (0, the
    /// default: none). It keeps a uniform correction, but not exactly the gated decoder's
    /// zero where the tension limit holds a vertex (neighbours' take-back spreads there). The
    /// one-step targets are dominated by the coarse mesh springing back out of M_int's
    /// compressed edges, a local (edge-scale) motion the interleaved run does not have; its
    /// learned cancellation is then a local bias, while the fine cloth's drift from the
    /// coarse one is smooth over the garment.
    pub smoothing: usize,
    /// The gated decoder's lowest share (beyond the paper): γ = m + (1 − m)·σ(·) ∈ (m, 1)³
    /// instead of (0, 1)³ (0 by default). Below 0 the decoder may also amplify the step's
    /// velocity change, where the fine cloth responds faster than the coarse one (the
    /// hanging flaps swinging in under an impact).
    pub share_min: f64,
}

setters!(CorrectorConfig {
    with_latent: latent: usize,
    with_hidden_layers: hidden_layers: usize,
    with_steps: steps: usize,
    with_attention: attention: bool,
    with_decoder: decoder: Decoder,
    with_tension_ramp: tension_ramp: f64,
    with_take_back: take_back: f64,
    with_smoothing: smoothing: usize,
    with_share_min: share_min: f64,
});

impl Default for CorrectorConfig {
    fn default() -> Self {
        Self::new()
    }
}

/// How the network's node latents become velocity corrections.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Decoder {
    /// The paper's: a node MLP, any correction anywhere.
    #[default]
    Node,
    /// A per-vertex, per-axis share γ ∈ (0, 1)³ of the step's velocity change beyond gravity
    /// taken back, node terms only near colliders.
    Gated,
}

impl std::str::FromStr for Decoder {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.trim() {
            "node" => Ok(Self::Node),
            "gated" => Ok(Self::Gated),
            t => Err(format!("{t}: 'node' or 'gated'")),
        }
    }
}

impl Decoder {
    /// Whether the decoder takes back a share of the step's velocity change.
    pub fn is_gated(self) -> bool {
        self == Decoder::Gated
    }
}

/// The gated decoder's default tension ramp: 1 % strain (the data's M_int is shortened by
/// 0.3 % on average, the simulator's spring-back from it stretches by 0.1 %).
pub const DEFAULT_TENSION_RAMP: f64 = 0.01;

impl CorrectorConfig {
    /// The paper's network (latent 64, 2 hidden layers, node decoder) with 8 message-passing
    /// blocks, no attention, and the inference settings' defaults (the tension ramp
    /// [`DEFAULT_TENSION_RAMP`], no take-back scale, no smoothing, lowest share 0).
    pub fn new() -> Self {
        CorrectorConfig {
            latent: 64,
            hidden_layers: 2,
            steps: 8,
            attention: false,
            decoder: Decoder::Node,
            tension_ramp: DEFAULT_TENSION_RAMP,
            take_back: 1.0,
            smoothing: 0,
            share_min: 0.0,
        }
    }

    /// Checks the settings a saved configuration may hold wrong; `Err` names the problem.
    pub fn check(&self) -> Result<()> {
        let r = self.tension_ramp;
        if !(r.is_finite() && r >= 0.0) {
            return Err(Error::Invalid(
                "the tension ramp must not be negative (0: no limit)".into(),
            ));
        }
        let k = self.take_back;
        if !(k.is_finite() && k > 0.0 && k <= 1.0) {
            return Err(Error::Invalid(
                "the take-back scale must be in (0, 1]".into(),
            ));
        }
        let m = self.share_min;
        if !(m.is_finite() && m < 1.0) {
            return Err(Error::Invalid(
                "the gated decoder's lowest share must be below 1".into(),
            ));
        }
        Ok(())
    }

    /// The gated decoder's take-back scale at inference ([`Self::take_back`]); `None`: 1 (or
    /// another decoder).
    pub fn take_back(&self) -> Option<f64> {
        (self.decoder.is_gated() && self.take_back != 1.0).then_some(self.take_back)
    }

    /// The gated decoder's tension ramp at inference ([`Self::tension_ramp`]); `None`: no
    /// limit (other decoders, or a ramp of 0).
    pub fn tension_ramp(&self) -> Option<f64> {
        (self.decoder.is_gated() && self.tension_ramp > 0.0).then_some(self.tension_ramp)
    }
}

/// An MLP: `hidden_layers` ReLU layers of `latent` units, a linear output, an optional
/// LayerNorm.
#[derive(Module, Debug)]
pub struct Mlp {
    pub(super) layers: Vec<Linear>,
    pub(super) norm: Option<LayerNorm>,
}

impl Mlp {
    fn new(
        input: usize,
        hidden: usize,
        layers: usize,
        output: usize,
        norm: bool,
        device: &Device,
    ) -> Mlp {
        let mut sizes = vec![input];
        sizes.extend(std::iter::repeat_n(hidden, layers));
        sizes.push(output);
        Mlp {
            layers: sizes
                .windows(2)
                .map(|w| LinearConfig::new(w[0], w[1]).init(device))
                .collect(),
            norm: norm.then(|| LayerNormConfig::new(output).init(device)),
        }
    }

    /// `[n, input] → [n, output]`.
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        self.after_first(self.layers[0].forward(x))
    }

    /// The MLP from the first layer's output (pre-activation) on.
    fn after_first(&self, x: Tensor<2>) -> Tensor<2> {
        let mut x = x;
        for layer in &self.layers[1..] {
            x = layer.forward(relu(x));
        }
        match &self.norm {
            Some(norm) => norm.forward(x),
            None => x,
        }
    }
}

/// One message-passing block.
///
/// The edge MLP's first layer acts on the concatenation [e_ij, v_i, v_j]; it is computed as
/// W_e·e_ij + (W_s·v)_i + (W_r·v)_j, applying W_s and W_r once per node rather than once per
/// edge (the same function with fewer operations: a mesh has ~6 directed edges per vertex).
#[derive(Module, Debug)]
pub struct Block {
    pub(super) edge: Mlp,
    pub(super) edge_sender: Linear,
    pub(super) edge_receiver: Linear,
    pub(super) node: Mlp,
    pub(super) score: Option<Linear>,
}

/// An edge list (`[E]` node indices) on `device`.
pub fn index_tensor(indices: &[u32], device: &Device) -> Tensor<1, Int> {
    let v: Vec<i64> = indices.iter().map(|&i| i64::from(i)).collect();
    let e = v.len();
    Tensor::from_data(TensorData::new(v, [e]), device)
}

/// A batch of graphs on a device, features already normalised.
#[derive(Debug, Clone)]
pub struct GraphTensors {
    /// `[N, NODE_FEATURES]`.
    pub nodes: Tensor<2>,
    /// `[E, EDGE_FEATURES]`.
    pub edges: Tensor<2>,
    /// `[E]` sender node of each edge.
    pub senders: Tensor<1, Int>,
    /// `[E]` receiver node of each edge.
    pub receivers: Tensor<1, Int>,
    /// `[N, 3]` the step's velocity change beyond gravity in the targets' normalised units
    /// (for the gated decoder).
    pub step_change: Tensor<2>,
    /// `[N, 1]` the gated decoder's tension limit ([`CorrectorConfig::tension_ramp`]); `None`
    /// is 1 everywhere.
    pub tension: Option<Tensor<2>>,
}

/// Distance from a collider within which the gated decoder's correction turns from a share
/// of the step's velocity change to a free one, m (a few contact thicknesses).
pub const CONTACT_RADIUS_M: f64 = 0.005;

/// The attention's score LeakyReLU slope for negative inputs (GATv2's 0.2).
pub const ATTENTION_SLOPE: f32 = 0.2;

/// Attention scores are clamped to ±this before the exponential, rather than shifted by a
/// per-receiver maximum, which keeps every weight representable.
pub const SCORE_LIMIT: f32 = 30.0;

impl GraphTensors {
    /// Uploads row-major features (`nodes`: `[n, NODE_FEATURES]`, `edges`: `[e, EDGE_FEATURES]`),
    /// edge lists and step changes (`[n, 3]`, normalised as the targets). Edges come in pairs:
    /// edge 2k + 1 is edge 2k reversed ([`MeshGraph::new`]).
    pub fn new(
        nodes: Vec<f32>,
        edges: Vec<f32>,
        senders: &[u32],
        receivers: &[u32],
        step_change: Vec<f32>,
        device: &Device,
    ) -> GraphTensors {
        GraphTensors::with_indices(
            nodes,
            edges,
            index_tensor(senders, device),
            index_tensor(receivers, device),
            step_change,
        )
    }

    /// Uploads features for a graph whose edge lists (`[E]` each) are already on the device:
    /// a mesh's topology does not change between steps, so they are uploaded once.
    pub fn with_indices(
        nodes: Vec<f32>,
        edges: Vec<f32>,
        senders: Tensor<1, Int>,
        receivers: Tensor<1, Int>,
        step_change: Vec<f32>,
    ) -> GraphTensors {
        let device = senders.device();
        let [e] = senders.dims();
        let n = nodes.len() / NODE_FEATURES;
        debug_assert_eq!(edges.len(), e * EDGE_FEATURES);
        debug_assert_eq!(step_change.len(), 3 * n);
        GraphTensors {
            nodes: Tensor::from_data(TensorData::new(nodes, [n, NODE_FEATURES]), &device),
            edges: Tensor::from_data(TensorData::new(edges, [e, EDGE_FEATURES]), &device),
            senders,
            receivers,
            step_change: Tensor::from_data(TensorData::new(step_change, [n, 3]), &device),
            tension: None,
        }
    }

    /// The same graph with the gated decoder's tension limit `w` (`[n]`,
    /// [`super::graph::MeshGraph::tension_weight`]); `None` leaves it off.
    pub fn with_tension(mut self, w: Option<Vec<f32>>) -> Self {
        self.tension = w.map(|w| {
            let n = w.len();
            Tensor::from_data(TensorData::new(w, [n, 1]), &self.nodes.device())
        });
        self
    }

    /// The graph of `graph` with the given (normalised) features and step changes.
    pub fn of(
        graph: &MeshGraph,
        nodes: Vec<f32>,
        edges: Vec<f32>,
        step_change: Vec<f32>,
        device: &Device,
    ) -> Self {
        GraphTensors::new(
            nodes,
            edges,
            &graph.senders,
            &graph.receivers,
            step_change,
            device,
        )
    }
}

/// A contiguous range of a graph's directed edges with their latents (`[E_k, L]`) and end
/// nodes (`[E_k]` each): the unit the edge MLPs run on, one range per thread at inference
/// ([`CorrectorNet::forward_in_parts`]).
#[derive(Debug, Clone)]
struct EdgePart {
    edges: Tensor<2>,
    senders: Tensor<1, Int>,
    receivers: Tensor<1, Int>,
}

/// `f` applied to every part, on its own rayon task where there are several (each part's edge
/// MLP is a few matrix products too small for the matrix kernels to spread over threads).
fn map_parts<P: Sync, T: Send>(parts: &[P], f: impl Fn(&P) -> T + Sync + Send) -> Vec<T> {
    if parts.len() > 1 {
        parts.par_iter().map(f).collect()
    } else {
        parts.iter().map(f).collect()
    }
}

/// The sum of `[N, C]` tensors (one per part).
fn sum_parts(terms: Vec<Tensor<2>>) -> Tensor<2> {
    let mut terms = terms.into_iter();
    let first = terms.next().expect("a graph has at least one edge part");
    terms.fold(first, |acc, t| acc + t)
}

impl Block {
    /// `nodes [N, L]`, edge parts (latents `[E_k, L]`) → the same after the block.
    fn forward(&self, nodes: Tensor<2>, parts: Vec<EdgePart>) -> (Tensor<2>, Vec<EdgePart>) {
        let [n, latent] = nodes.dims();
        let device = nodes.device();
        let sent = self.edge_sender.forward(nodes.clone()); // [N, L]
        let received = self.edge_receiver.forward(nodes.clone()); // [N, L]

        // e′ on each part, with the attention's unnormalised weights.
        let updated = map_parts(&parts, |p| {
            let first = self.edge.layers[0].forward(p.edges.clone())
                + sent.clone().select(0, p.senders.clone())
                + received.clone().select(0, p.receivers.clone()); // [E_k, L]
            let e_new = self.edge.after_first(first); // [E_k, L]

            // Softmax over each receiver's incoming edges, of scores clamped to ±SCORE_LIMIT.
            let w = self.score.as_ref().map(|score| {
                score
                    .forward(leaky_relu(e_new.clone(), f64::from(ATTENTION_SLOPE)))
                    .clamp(-SCORE_LIMIT, SCORE_LIMIT)
                    .exp() // [E_k, 1]
            });
            (e_new, w)
        });
        let both: Vec<_> = parts.iter().zip(&updated).collect();
        // The attention's normaliser: each receiver's total weight over all parts.
        let total = self.score.as_ref().map(|_| {
            sum_parts(map_parts(&both, |(p, u)| {
                let w = u.1.clone().expect("scored edges"); // [E_k, 1]
                Tensor::<2>::zeros([n, 1], &device).select_assign(
                    0,
                    p.receivers.clone(),
                    w,
                    IndexingUpdateOp::Add,
                ) // [N, 1]
            }))
        });
        let sums = map_parts(&both, |(p, u)| {
            let (e_new, w) = u;
            let messages = match (w, &total) {
                (Some(w), Some(total)) => {
                    e_new.clone() * (w.clone() / total.clone().select(0, p.receivers.clone()))
                } // [E_k, L]
                _ => e_new.clone(),
            };
            Tensor::<2>::zeros([n, latent], &device).select_assign(
                0,
                p.receivers.clone(),
                messages,
                IndexingUpdateOp::Add,
            ) // [N, L]
        });
        let sum = sum_parts(sums); // [N, L]
        let v_new = self.node.forward(Tensor::cat(vec![nodes.clone(), sum], 1)); // [N, L]
        let parts = parts
            .into_iter()
            .zip(updated)
            .map(|(p, (e_new, _))| EdgePart {
                edges: p.edges + e_new,
                ..p
            })
            .collect();
        (nodes + v_new, parts)
    }
}

/// The corrector network.
#[derive(Module, Debug)]
pub struct CorrectorNet {
    pub(super) encode_nodes: Mlp,
    pub(super) encode_edges: Mlp,
    pub(super) blocks: Vec<Block>,
    pub(super) decode: Mlp,
    pub(super) gate: Option<Mlp>,
    pub(super) share_min: f64,
}

impl CorrectorConfig {
    /// A freshly initialised network on `device`.
    pub fn init(&self, device: &Device) -> CorrectorNet {
        let (l, h) = (self.latent, self.hidden_layers);
        CorrectorNet {
            encode_nodes: Mlp::new(NODE_FEATURES, l, h, l, true, device),
            encode_edges: Mlp::new(EDGE_FEATURES, l, h, l, true, device),
            blocks: (0..self.steps)
                .map(|_| Block {
                    edge: Mlp::new(l, l, h, l, true, device),
                    edge_sender: LinearConfig::new(l, l).with_bias(false).init(device),
                    edge_receiver: LinearConfig::new(l, l).with_bias(false).init(device),
                    node: Mlp::new(2 * l, l, h, l, true, device),
                    score: self.attention.then(|| LinearConfig::new(l, 1).init(device)),
                })
                .collect(),
            decode: Mlp::new(l, l, h, 3, false, device),
            gate: self
                .decoder
                .is_gated()
                .then(|| Mlp::new(l, l, h, 3, false, device)),
            share_min: self.share_min,
        }
    }
}

impl CorrectorNet {
    /// Normalised velocity corrections `[N, 3]` for a batch of graphs.
    pub fn forward(&self, g: &GraphTensors) -> Tensor<2> {
        self.forward_in_parts(g, 1)
    }

    /// [`Self::forward`] with the graph's directed edges cut into `parts` contiguous ranges
    /// (each of whole edge pairs) whose edge MLPs run as parallel rayon tasks: the same
    /// function, up to the order of the floating-point sums at each receiver. At inference
    /// the edge MLPs are most of the work, and their matrix products are too small for the
    /// matrix kernels to use more than one core (`clothsr lab rollout` on the three balls,
    /// latent 32: see the corrector's README). Training keeps one part. On burn's CPU device
    /// inference runs [`super::fused::FusedNet`] instead, the same function evaluated tile by
    /// tile outside burn; this runs it on other devices.
    pub fn forward_in_parts(&self, g: &GraphTensors, parts: usize) -> Tensor<2> {
        let [e] = g.senders.dims();
        let pairs = e / 2;
        let parts = parts.clamp(1, pairs.max(1));
        // Part k holds edge pairs k·pairs/parts up to the next part's; the last ends at e.
        let start = |k: usize| {
            if k == parts {
                e
            } else {
                2 * (k * pairs / parts)
            }
        };
        let ranges: Vec<std::ops::Range<usize>> =
            (0..parts).map(|k| start(k)..start(k + 1)).collect();
        let mut edge_parts = map_parts(&ranges, |r| {
            let features = if parts == 1 {
                g.edges.clone()
            } else {
                g.edges.clone().slice([r.clone(), 0..EDGE_FEATURES])
            }; // [E_k, EDGE_FEATURES]
            EdgePart {
                edges: self.encode_edges.forward(features), // [E_k, L]
                senders: g.senders.clone().slice([r.clone()]),
                receivers: g.receivers.clone().slice([r.clone()]),
            }
        });
        let mut nodes = self.encode_nodes.forward(g.nodes.clone()); // [N, L]
        for block in &self.blocks {
            (nodes, edge_parts) = block.forward(nodes, edge_parts);
        }
        let Some(gate) = &self.gate else {
            return self.decode.forward(nodes); // [N, 3]
        };
        let [n, _] = nodes.dims();
        let body = g.nodes.clone().slice([0..n, BODY_COLUMN..BODY_COLUMN + 1]); // [N, 1]
                                                                                // d = (1 − b)·BODY_RADIUS_M, c = max(0, 1 − d/CONTACT_RADIUS_M).
        let ratio = (BODY_RADIUS_M / CONTACT_RADIUS_M) as f32;
        let contact = ((body - 1.0) * ratio + 1.0).clamp(0.0, 1.0); // [N, 1]
        let share = sigmoid(gate.forward(nodes.clone())); // [N, 3]
        let m = self.share_min;
        let share = if m != 0.0 {
            share * (1.0 - m) as f32 + m as f32 // [N, 3]
        } else {
            share
        };
        let mut taken = share * g.step_change.clone() * (contact.clone().neg() + 1.0); // [N, 3]
        if let Some(w) = &g.tension {
            taken = taken * w.clone(); // [N, 3]
        }
        self.decode.forward(nodes) * contact - taken // [N, 3]
    }
}
