//! The corrector network (the paper's §3.1.2, §3.3.2): MeshGraphNets' encode–process–decode
//! (Pfaff et al. 2020) on the coarse mesh graph.
//!
//! * Encoder: node MLP `NODE_FEATURES → L`, edge MLP `EDGE_FEATURES → L`.
//! * Processor: `steps` message-passing blocks with independent parameters,
//!   e′_ij ← e_ij + f_e(e_ij, v_i, v_j), v′_i ← v_i + f_v(v_i, Σ_j e′_ij) (messages summed at the
//!   receiver). With `attention`, the sum is replaced by a GATv2-style weighted sum
//!   (Brody et al. 2022): a score a·LeakyReLU(e′_ij) per edge, softmax over each receiver's
//!   incoming edges.
//! * Decoder: MLP `L → 3`, the velocity correction p_i (normalised units).
//!
//! Every MLP is ReLU with `hidden_layers` hidden layers of `latent` units; all but the decoder
//! end in a LayerNorm. Inputs and outputs are normalised outside the network
//! ([`super::normalise`]).

use burn::config::Config;
use burn::module::Module;
use burn::nn::{LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::tensor::activation::{leaky_relu, relu};
use burn::tensor::{Device, IndexingUpdateOp, Int, Tensor, TensorData};

use super::graph::{MeshGraph, EDGE_FEATURES, NODE_FEATURES};

/// Sizes of the corrector network (saved as `config.json` beside the weights).
#[derive(Config, Debug, PartialEq)]
pub struct CorrectorConfig {
    /// Width of every latent vector and hidden layer (the paper: 64).
    #[config(default = 64)]
    pub latent: usize,
    /// Hidden layers per MLP (the paper: 2).
    #[config(default = 2)]
    pub hidden_layers: usize,
    /// Message-passing blocks (L).
    #[config(default = 8)]
    pub steps: usize,
    /// GATv2-style attention weights on the edge aggregation instead of a plain sum.
    #[config(default = false)]
    pub attention: bool,
}

/// An MLP: `hidden_layers` ReLU layers of `latent` units, a linear output, an optional
/// LayerNorm.
#[derive(Module, Debug)]
pub struct Mlp {
    layers: Vec<Linear>,
    norm: Option<LayerNorm>,
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
    edge: Mlp,
    edge_sender: Linear,
    edge_receiver: Linear,
    node: Mlp,
    score: Option<Linear>,
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
}

impl GraphTensors {
    /// Uploads row-major features (`nodes`: `[n, NODE_FEATURES]`, `edges`: `[e, EDGE_FEATURES]`)
    /// and edge lists.
    pub fn new(
        nodes: Vec<f32>,
        edges: Vec<f32>,
        senders: &[u32],
        receivers: &[u32],
        device: &Device,
    ) -> GraphTensors {
        GraphTensors::with_indices(
            nodes,
            edges,
            index_tensor(senders, device),
            index_tensor(receivers, device),
        )
    }

    /// Uploads features for a graph whose edge lists (`[E]` each) are already on the device:
    /// a mesh's topology does not change between steps, so they are uploaded once.
    pub fn with_indices(
        nodes: Vec<f32>,
        edges: Vec<f32>,
        senders: Tensor<1, Int>,
        receivers: Tensor<1, Int>,
    ) -> GraphTensors {
        let device = senders.device();
        let [e] = senders.dims();
        let n = nodes.len() / NODE_FEATURES;
        debug_assert_eq!(edges.len(), e * EDGE_FEATURES);
        GraphTensors {
            nodes: Tensor::from_data(TensorData::new(nodes, [n, NODE_FEATURES]), &device),
            edges: Tensor::from_data(TensorData::new(edges, [e, EDGE_FEATURES]), &device),
            senders,
            receivers,
        }
    }

    /// The graph of `graph` with the given (normalised) features.
    pub fn of(graph: &MeshGraph, nodes: Vec<f32>, edges: Vec<f32>, device: &Device) -> Self {
        GraphTensors::new(nodes, edges, &graph.senders, &graph.receivers, device)
    }
}

impl Block {
    /// `nodes [N, L], edges [E, L] → (nodes [N, L], edges [E, L])`.
    fn forward(
        &self,
        nodes: Tensor<2>,
        edges: Tensor<2>,
        senders: &Tensor<1, Int>,
        receivers: &Tensor<1, Int>,
    ) -> (Tensor<2>, Tensor<2>) {
        let [n, latent] = nodes.dims();
        let from_i = self
            .edge_sender
            .forward(nodes.clone())
            .select(0, senders.clone()); // [E, L]
        let from_j = self
            .edge_receiver
            .forward(nodes.clone())
            .select(0, receivers.clone()); // [E, L]
        let first = self.edge.layers[0].forward(edges.clone()) + from_i + from_j; // [E, L]
        let e_new = self.edge.after_first(first); // [E, L]
        let device = nodes.device();
        let messages = match &self.score {
            None => e_new.clone(),
            Some(score) => {
                // Softmax over each receiver's incoming edges; scores are clamped rather than
                // shifted by a per-receiver maximum, which keeps every weight representable.
                let w = score
                    .forward(leaky_relu(e_new.clone(), 0.2))
                    .clamp(-30.0, 30.0)
                    .exp(); // [E, 1]
                let total = Tensor::<2>::zeros([n, 1], &device).select_assign(
                    0,
                    receivers.clone(),
                    w.clone(),
                    IndexingUpdateOp::Add,
                ); // [N, 1]
                let alpha = w / total.select(0, receivers.clone()); // [E, 1]
                e_new.clone() * alpha
            }
        };
        let sum = Tensor::<2>::zeros([n, latent], &device).select_assign(
            0,
            receivers.clone(),
            messages,
            IndexingUpdateOp::Add,
        ); // [N, L]
        let v_new = self.node.forward(Tensor::cat(vec![nodes.clone(), sum], 1)); // [N, L]
        (nodes + v_new, edges + e_new)
    }
}

/// The corrector network.
#[derive(Module, Debug)]
pub struct CorrectorNet {
    encode_nodes: Mlp,
    encode_edges: Mlp,
    blocks: Vec<Block>,
    decode: Mlp,
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
        }
    }
}

impl CorrectorNet {
    /// Normalised velocity corrections `[N, 3]` for a batch of graphs.
    pub fn forward(&self, g: &GraphTensors) -> Tensor<2> {
        let mut nodes = self.encode_nodes.forward(g.nodes.clone()); // [N, L]
        let mut edges = self.encode_edges.forward(g.edges.clone()); // [E, L]
        for block in &self.blocks {
            (nodes, edges) = block.forward(nodes, edges, &g.senders, &g.receivers);
        }
        self.decode.forward(nodes) // [N, 3]
    }
}
