//! The corrector network's forward pass on the CPU outside burn, for inference: the same
//! function as [`CorrectorNet::forward_in_parts`] to the rounding of its sums.
//!
//! burn runs each operation over the whole graph. An edge MLP there is three matrix products
//! and about a dozen element-wise passes (bias, ReLU, the gathers, LayerNorm's statistics and
//! scaling, the residual, the scatter), each streaming `[E, L]` tensors (1.1 MB for the
//! three balls' sheet at L = 64) through memory: `perf` put half the network's time in
//! those passes, and the products themselves ran below the vector units' speed. Here each
//! tile of [`TILE`] edges goes through its whole MLP, residual and scatter while it is in
//! the core's cache; the products are `gemm`'s kernels (the crate burn's CPU backend uses,
//! picking AVX2 or AVX-512 at run time) on the tile, and the element-wise loops around them
//! are compiled for the same vector width through `pulp`. The edges are cut into one
//! contiguous range of whole edge pairs per rayon thread, each range a task that sums its
//! messages into its own `[N, L]` buffer, added in range order afterwards; the whole pass
//! runs on rayon's threads.
//!
//! It is faster than burn's pass on the shipped networks (`clothsr lab bench pipeline`
//! compares the two).
//!
//! Shapes: node rows `[N, ·]`, edge rows `[E, ·]`, all row-major `f32`.

use burn::nn::{LayerNorm, LayerNormConfig, Linear};
use burn::tensor::Tensor;
use gemm::{gemm, Parallelism};
use rayon::prelude::*;

use super::graph::{BODY_COLUMN, BODY_RADIUS_M, EDGE_FEATURES, NODE_FEATURES};
use super::model::{Block, CorrectorNet, Mlp, ATTENTION_SLOPE, CONTACT_RADIUS_M, SCORE_LIMIT};

/// Rows (edges or nodes) that go through an MLP together: at L = 64 a tile's activations are
/// 32 KB, beside the layer's 16 KB of weights.
pub const TILE: usize = 128;

/// A tensor's values on the host.
fn host<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().iter::<f32>().collect()
}

/// A linear layer: `y = x·W + b`, W `[input, output]` row-major.
#[derive(Debug, Clone)]
struct Dense {
    w: Vec<f32>,
    b: Option<Vec<f32>>,
    input: usize,
    output: usize,
}

impl Dense {
    fn of(l: &Linear) -> Dense {
        let w = l.weight.val();
        let [input, output] = w.dims();
        Dense {
            w: host(w),
            b: l.bias.as_ref().map(|b| host(b.val())),
            input,
            output,
        }
    }

    /// `x [rows, input]` → `y [rows, output]` = x·W + b.
    #[inline(always)]
    #[allow(unsafe_code)] // gemm's API takes raw pointers and strides.
    fn apply(&self, x: &[f32], rows: usize, y: &mut [f32]) {
        let (x, y) = (&x[..rows * self.input], &mut y[..rows * self.output]);
        if rows == 0 {
            return;
        }
        // SAFETY: x holds rows × input values, y rows × output and w input × output (the
        // slices above and the constructor), all row-major with the strides given; y does not
        // alias x or w.
        unsafe {
            gemm(
                rows,
                self.output,
                self.input,
                y.as_mut_ptr(),
                1,
                self.output as isize,
                false,
                x.as_ptr(),
                1,
                self.input as isize,
                self.w.as_ptr(),
                1,
                self.output as isize,
                0.0,
                1.0,
                false,
                false,
                false,
                Parallelism::None,
            );
        }
        if let Some(b) = &self.b {
            for row in y.chunks_exact_mut(self.output) {
                row.iter_mut().zip(b).for_each(|(y, b)| *y += b);
            }
        }
    }
}

/// Two buffers an MLP's layers alternate between.
#[derive(Debug, Default)]
struct Scratch {
    a: Vec<f32>,
    b: Vec<f32>,
}

/// [`Mlp`]: ReLU layers, a linear output, an optional LayerNorm (γ, β, ε).
#[derive(Debug, Clone)]
struct FusedMlp {
    layers: Vec<Dense>,
    norm: Option<(Vec<f32>, Option<Vec<f32>>, f32)>,
}

impl FusedMlp {
    fn of(mlp: &Mlp) -> FusedMlp {
        FusedMlp {
            layers: mlp.layers.iter().map(Dense::of).collect(),
            norm: mlp.norm.as_ref().map(|n: &LayerNorm| {
                let [d] = n.gamma.dims();
                (
                    host(n.gamma.val()),
                    n.beta.as_ref().map(|b| host(b.val())),
                    // The network's LayerNorms are made with the default ε (model.rs).
                    LayerNormConfig::new(d).epsilon as f32,
                )
            }),
        }
    }

    fn input(&self) -> usize {
        self.layers[0].input
    }

    fn output(&self) -> usize {
        self.layers[self.layers.len() - 1].output
    }

    /// `x [rows, input]` → `[rows, output]`, held in `s`; `pre` adds to the first layer's
    /// output before its activation (`[rows, hidden]`).
    #[inline(always)]
    fn run<'s>(
        &self,
        x: &[f32],
        rows: usize,
        s: &'s mut Scratch,
        pre: impl FnOnce(&mut [f32]),
    ) -> &'s mut [f32] {
        let first = &self.layers[0];
        s.a.resize(rows * first.output, 0.0);
        first.apply(x, rows, &mut s.a);
        pre(&mut s.a[..rows * first.output]);
        for layer in &self.layers[1..] {
            s.a.iter_mut().for_each(|x| *x = x.max(0.0));
            s.b.resize(rows * layer.output, 0.0);
            layer.apply(&s.a, rows, &mut s.b);
            std::mem::swap(&mut s.a, &mut s.b);
        }
        let out = &mut s.a[..rows * self.output()];
        if let Some((gamma, beta, eps)) = &self.norm {
            for row in out.chunks_exact_mut(gamma.len()) {
                layer_norm(row, gamma, beta.as_deref(), *eps);
            }
        }
        out
    }

    /// `x [rows, input]` → `[rows, output]`, tiles in parallel.
    fn run_rows(&self, x: &[f32], rows: usize) -> Vec<f32> {
        let (i, o) = (self.input(), self.output());
        let mut y = vec![0.0; rows * o];
        y.par_chunks_mut(TILE * o)
            .zip(x[..rows * i].par_chunks(TILE * i))
            .for_each_init(Scratch::default, |scratch, (y, x)| {
                simd(RowTile {
                    mlp: self,
                    x,
                    y,
                    scratch,
                })
            });
        y
    }
}

/// Σ f(x) over `row`, summed in [`LANES`] interleaved partial sums: a float sum in one chain
/// is one dependent add after another (the compiler may not reorder it), the lanes are
/// vector adds. Rounding differs from a sequential sum by a few ulps.
#[inline(always)]
fn lane_sum(row: &[f32], f: impl Fn(f32) -> f32) -> f32 {
    let mut lanes = [0.0f32; LANES];
    let mut chunks = row.chunks_exact(LANES);
    for c in &mut chunks {
        for (l, &x) in lanes.iter_mut().zip(c) {
            *l += f(x);
        }
    }
    let tail: f32 = chunks.remainder().iter().map(|&x| f(x)).sum();
    lanes.iter().sum::<f32>() + tail
}

/// Partial sums in [`lane_sum`].
const LANES: usize = 16;

/// One row normalised to zero mean and unit variance (population variance), then scaled by γ
/// and shifted by β.
#[inline(always)]
fn layer_norm(row: &mut [f32], gamma: &[f32], beta: Option<&[f32]>, eps: f32) {
    let n = row.len() as f32;
    let mean = lane_sum(row, |x| x) / n;
    let var = lane_sum(row, |x| (x - mean) * (x - mean)) / n;
    let inv = 1.0 / (var + eps).sqrt();
    match beta {
        Some(beta) => {
            for ((x, g), b) in row.iter_mut().zip(gamma).zip(beta) {
                *x = (*x - mean) * inv * g + b;
            }
        }
        None => {
            for (x, g) in row.iter_mut().zip(gamma) {
                *x = (*x - mean) * inv * g;
            }
        }
    }
}

/// [`Block`].
#[derive(Debug, Clone)]
struct FusedBlock {
    edge: FusedMlp,
    sender: FusedMlp,
    receiver: FusedMlp,
    node: FusedMlp,
    score: Option<Dense>,
}

/// `op` compiled for the CPU's widest vector instructions (AVX-512 or AVX2 on x86, picked at
/// run time by `pulp`): the element-wise loops its `#[inline(always)]` body holds are
/// vectorised that wide (the crate itself is compiled for baseline x86-64, SSE2).
#[inline(always)]
fn simd<Op: pulp::WithSimd>(op: Op) -> Op::Output {
    pulp::Arch::new().dispatch(op)
}

/// A range's messages summed at each receiver (`[N, L]`), and with attention each receiver's
/// total weight (`[N]`).
struct RangeSums {
    sum: Vec<f32>,
    total: Vec<f32>,
}

impl RangeSums {
    /// No messages yet for `n` nodes of width `l` (totals only with `attention`).
    fn zeros(n: usize, l: usize, attention: bool) -> RangeSums {
        RangeSums {
            sum: vec![0.0; n * l],
            total: vec![0.0; if attention { n } else { 0 }],
        }
    }

    /// Adds another range's sums.
    fn add(&mut self, other: &RangeSums) {
        self.sum
            .iter_mut()
            .zip(&other.sum)
            .for_each(|(a, b)| *a += b);
        self.total
            .iter_mut()
            .zip(&other.total)
            .for_each(|(a, b)| *a += b);
    }
}

/// One thread's range of whole edge pairs for [`FusedBlock::edge_range`]: latents `[E_k, L]`
/// updated in place, end nodes from the range's first edge on, the block's sender and receiver
/// terms `[N, L]`.
struct EdgeRange<'a> {
    block: &'a FusedBlock,
    range: &'a mut [f32],
    senders: &'a [u32],
    receivers: &'a [u32],
    sent: &'a [f32],
    received: &'a [f32],
    sums: &'a mut RangeSums,
}

impl pulp::WithSimd for EdgeRange<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        self.block.edge_range(self)
    }
}

/// One tile of rows through an MLP for [`FusedMlp::run_rows`].
struct RowTile<'a> {
    mlp: &'a FusedMlp,
    x: &'a [f32],
    y: &'a mut [f32],
    scratch: &'a mut Scratch,
}

impl pulp::WithSimd for RowTile<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        let rows = self.y.len() / self.mlp.output();
        let out = self.mlp.run(self.x, rows, self.scratch, |_| ());
        self.y.copy_from_slice(out);
    }
}

/// The edge MLP's first layer terms of each edge's end nodes added to `h` (`[rows, L]`):
/// (W_s·v)_i from `sent` and (W_r·v)_j from `received` (`[N, L]`).
#[inline(always)]
fn add_ends(h: &mut [f32], snd: &[u32], rcv: &[u32], sent: &[f32], received: &[f32], l: usize) {
    for ((h, &i), &j) in h.chunks_exact_mut(l).zip(snd).zip(rcv) {
        let (a, b) = (row(sent, i, l), row(received, j, l));
        for ((h, a), b) in h.iter_mut().zip(a).zip(b) {
            *h += a + b;
        }
    }
}

/// A row of `rows` (`[·, width]`).
#[inline(always)]
fn row(rows: &[f32], i: u32, width: usize) -> &[f32] {
    &rows[i as usize * width..][..width]
}

/// A mutable row of `rows` (`[·, width]`).
#[inline(always)]
fn row_mut(rows: &mut [f32], i: u32, width: usize) -> &mut [f32] {
    &mut rows[i as usize * width..][..width]
}

/// Edges per thread's range: whole pairs, `parts` ranges covering `e` edges.
fn range_len(e: usize, parts: usize) -> usize {
    (e / 2).div_ceil(parts.max(1)).max(1) * 2
}

impl FusedBlock {
    /// One range of edges through the edge MLP, their messages summed at their receivers.
    #[inline(always)]
    fn edge_range(&self, r: EdgeRange<'_>) {
        let l = self.edge.output();
        let mut s = Scratch::default();
        let mut w = Vec::new();
        let RangeSums { sum, total } = r.sums;
        for (t, tile) in r.range.chunks_mut(TILE * l).enumerate() {
            let rows = tile.len() / l;
            let (snd, rcv) = (
                &r.senders[t * TILE..t * TILE + rows],
                &r.receivers[t * TILE..t * TILE + rows],
            );
            let e_new = self.edge.run(tile, rows, &mut s, |h| {
                add_ends(h, snd, rcv, r.sent, r.received, l)
            }); // [rows, L]
            match &self.score {
                Some(score) => {
                    // exp(clamp(a·LeakyReLU(e′) + c, ±SCORE_LIMIT)), as the burn network.
                    let c = score.b.as_ref().map_or(0.0, |b| b[0]);
                    w.clear();
                    w.extend(e_new.chunks_exact(l).map(|e| {
                        let z: f32 = e
                            .iter()
                            .zip(&score.w)
                            .map(|(&x, a)| (if x >= 0.0 { x } else { ATTENTION_SLOPE * x }) * a)
                            .sum();
                        (z + c).clamp(-SCORE_LIMIT, SCORE_LIMIT).exp()
                    }));
                    for ((e, &j), &w) in e_new.chunks_exact(l).zip(rcv).zip(&w) {
                        total[j as usize] += w;
                        for (s, e) in row_mut(sum, j, l).iter_mut().zip(e) {
                            *s += w * e;
                        }
                    }
                }
                None => {
                    for (e, &j) in e_new.chunks_exact(l).zip(rcv) {
                        for (s, e) in row_mut(sum, j, l).iter_mut().zip(e) {
                            *s += e;
                        }
                    }
                }
            }
            tile.iter_mut().zip(e_new.iter()).for_each(|(e, d)| *e += d);
        }
    }

    fn of(b: &Block) -> FusedBlock {
        let linear = |l: &Linear| FusedMlp {
            layers: vec![Dense::of(l)],
            norm: None,
        };
        FusedBlock {
            edge: FusedMlp::of(&b.edge),
            sender: linear(&b.edge_sender),
            receiver: linear(&b.edge_receiver),
            node: FusedMlp::of(&b.node),
            score: b.score.as_ref().map(Dense::of),
        }
    }

    /// Updates node latents `[N, L]` and edge latents `[E, L]` in place.
    fn forward(
        &self,
        nodes: &mut [f32],
        edges: &mut [f32],
        senders: &[u32],
        receivers: &[u32],
        parts: usize,
    ) {
        let l = self.edge.output();
        let n = nodes.len() / l;
        let sent = self.sender.run_rows(nodes, n); // [N, L]
        let received = self.receiver.run_rows(nodes, n); // [N, L]
        let per = range_len(senders.len(), parts);
        // Each range's messages summed at its receivers, and with attention each receiver's
        // total weight.
        let empty = || RangeSums::zeros(n, l, self.score.is_some());
        let partial: Vec<RangeSums> = edges
            .par_chunks_mut(per * l)
            .enumerate()
            .map(|(k, range)| {
                let mut sums = empty();
                simd(EdgeRange {
                    block: self,
                    range,
                    senders: &senders[k * per..],
                    receivers: &receivers[k * per..],
                    sent: &sent,
                    received: &received,
                    sums: &mut sums,
                });
                sums
            })
            .collect();
        // A graph without edges has no range: its nodes get no messages, as in burn.
        let mut ranges = partial.into_iter();
        let mut sums = ranges.next().unwrap_or_else(empty);
        for range in ranges {
            sums.add(&range);
        }
        let RangeSums { mut sum, total } = sums;
        if self.score.is_some() {
            for (s, t) in sum.chunks_exact_mut(l).zip(&total) {
                // A node no edge reaches has no message (the burn network's sum is 0 there).
                let inv = if *t > 0.0 { 1.0 / t } else { 0.0 };
                s.iter_mut().for_each(|s| *s *= inv);
            }
        }
        // v′ = v + f_v([v, Σ e′]).
        let mut both = vec![0.0f32; n * 2 * l]; // [N, 2L]
        for ((b, v), s) in both
            .chunks_exact_mut(2 * l)
            .zip(nodes.chunks_exact(l))
            .zip(sum.chunks_exact(l))
        {
            b[..l].copy_from_slice(v);
            b[l..].copy_from_slice(s);
        }
        let v_new = self.node.run_rows(&both, n);
        nodes.iter_mut().zip(&v_new).for_each(|(v, d)| *v += d);
    }
}

/// [`CorrectorNet`]'s weights on the host, run tile by tile.
#[derive(Debug, Clone)]
pub struct FusedNet {
    encode_nodes: FusedMlp,
    encode_edges: FusedMlp,
    blocks: Vec<FusedBlock>,
    decode: FusedMlp,
    gate: Option<FusedMlp>,
    share_min: f64,
}

/// The inputs of one forward pass: normalised features and the graph, as
/// [`super::model::GraphTensors`] holds them on a device.
#[derive(Debug, Clone, Copy)]
pub struct FusedInputs<'a> {
    /// `[N, NODE_FEATURES]`.
    pub nodes: &'a [f32],
    /// `[E, EDGE_FEATURES]`.
    pub edges: &'a [f32],
    /// `[E]` sender node of each edge; edge 2k + 1 is edge 2k reversed.
    pub senders: &'a [u32],
    /// `[E]` receiver node of each edge.
    pub receivers: &'a [u32],
    /// `[N, 3]` the step's velocity change beyond gravity, normalised as the targets.
    pub step_change: &'a [f32],
    /// `[N]` the gated decoder's take-back weights; `None`: 1.
    pub tension: Option<&'a [f32]>,
}

impl FusedNet {
    /// A copy of `net`'s weights.
    pub fn of(net: &CorrectorNet) -> FusedNet {
        FusedNet {
            encode_nodes: FusedMlp::of(&net.encode_nodes),
            encode_edges: FusedMlp::of(&net.encode_edges),
            blocks: net.blocks.iter().map(FusedBlock::of).collect(),
            decode: FusedMlp::of(&net.decode),
            gate: net.gate.as_ref().map(FusedMlp::of),
            share_min: net.share_min,
        }
    }

    /// Normalised velocity corrections `[N, 3]`, the edges cut into at most `parts` ranges of
    /// whole edge pairs, each a rayon task (one per thread at inference).
    pub fn forward(&self, g: FusedInputs<'_>, parts: usize) -> Vec<f32> {
        // The whole pass runs on one of rayon's threads: each parallel step called from a
        // thread outside the pool would hand its work over and wait to be woken.
        rayon::scope(|_| self.forward_in_pool(g, parts))
    }

    /// [`Self::forward`] on the calling thread.
    fn forward_in_pool(&self, g: FusedInputs<'_>, parts: usize) -> Vec<f32> {
        let n = g.nodes.len() / NODE_FEATURES;
        let e = g.senders.len();
        debug_assert_eq!(g.edges.len(), e * EDGE_FEATURES);
        debug_assert_eq!(g.receivers.len(), e);
        let mut nodes = self.encode_nodes.run_rows(g.nodes, n); // [N, L]
        let mut edges = self.encode_edges.run_rows(g.edges, e); // [E, L]
        for block in &self.blocks {
            block.forward(&mut nodes, &mut edges, g.senders, g.receivers, parts);
        }
        let decoded = self.decode.run_rows(&nodes, n); // [N, 3]
        let Some(gate) = &self.gate else {
            return decoded;
        };
        let ratio = (BODY_RADIUS_M / CONTACT_RADIUS_M) as f32;
        let share_min = (self.share_min != 0.0).then_some(self.share_min as f32);
        let gated = gate.run_rows(&nodes, n); // [N, 3]
        let mut out = vec![0.0f32; 3 * n];
        for (i, f) in g.nodes.chunks_exact(NODE_FEATURES).enumerate() {
            // c = max(0, 1 − d/CONTACT_RADIUS_M), d = (1 − b)·BODY_RADIUS_M.
            let contact = ((f[BODY_COLUMN] - 1.0) * ratio + 1.0).clamp(0.0, 1.0);
            let w = g.tension.map_or(1.0, |w| w[i]);
            for a in 3 * i..3 * i + 3 {
                let mut share = 1.0 / (1.0 + (-gated[a]).exp());
                if let Some(m) = share_min {
                    share = share * (1.0 - m) + m;
                }
                let taken = share * g.step_change[a] * (1.0 - contact) * w;
                out[a] = decoded[a] * contact - taken;
            }
        }
        out
    }
}
