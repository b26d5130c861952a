//! The ISR network of the MSR module (the paper's §3.2.2): SwinIR (Liang et al. 2021) working at
//! the fine pixel size, without an upsampler.
//!
//! * **Shallow features**: a 3×3 convolution `in → C` of the input patch, whose channels are the
//!   coarse coordinate-map patch (3), the previous frame's fine output patch (3, the
//!   initialisation of §3.2.2; left out when `init_input` is off), the coarse map's geometry
//!   (9, with `geometry_input`: stretch, normal, curvature) and the mask (1).
//! * **Deep features**: `depths.len()` residual Swin transformer blocks (RSTB). Each holds
//!   `depths[k]` Swin transformer layers (LayerNorm → window multi-head self-attention with a
//!   learned relative-position bias → residual; LayerNorm → MLP (GELU) → residual), the windows
//!   shifted by half a window in every other layer, then a 3×3 convolution and the block's
//!   residual. A LayerNorm and a 3×3 convolution follow the blocks, with the global residual to
//!   the shallow features.
//! * **Reconstruction**: a 3×3 convolution `C → 3` giving the fine detail as a residual over
//!   the coarse patch: I_f = I_c + δ·f(·).
//!
//! The relative-position bias and the shifted-window mask enter burn's fused `attention` as its
//! additive bias (`[B·nW, heads, N, N]`, N = window²). Patches must be multiples of the window.
//! Inputs are normalised outside the network ([`super::inference::patch_input`]) with two
//! length scales: the coarse patch is centred on the mean of its pixels and divided by a shape
//! scale (1 cm), so the network sees the same input wherever the garment is in the world; the
//! initialisation enters as its difference to the coarse patch and the output is that same
//! difference for the fine patch, both divided by a detail scale δ (1 mm). Wrinkles are a
//! fraction of a millimetre to a few millimetres deep, so they arrive at unit size rather than
//! as a 1 % ripple on centimetre-sized coordinates (which the network could not learn to copy).

use burn::config::Config;
use burn::module::{Module, Param};
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Initializer, LayerNorm, LayerNormConfig, Linear, LinearConfig, PaddingConfig2d};
use burn::tensor::activation::gelu;
use burn::tensor::module::attention;
use burn::tensor::ops::AttentionModuleOptions;
use burn::tensor::{Device, Int, Tensor, TensorData};

use clothsr_geometry::error::{Error, Result};

/// Sizes of the ISR network (saved with the training settings in `config.json`).
#[derive(Config, Debug, PartialEq)]
pub struct IsrConfig {
    /// Feature channels C (SwinIR-light: 60).
    #[config(default = 32)]
    pub embed_dim: usize,
    /// Swin transformer layers in each residual block (SwinIR-light: [6, 6, 6, 6]).
    #[config(default = "vec![2, 2]")]
    pub depths: Vec<usize>,
    /// Attention heads (C must be a multiple).
    #[config(default = 4)]
    pub heads: usize,
    /// Window side, pixels.
    #[config(default = 8)]
    pub window: usize,
    /// MLP hidden width as a multiple of C.
    #[config(default = 2.0)]
    pub mlp_ratio: f64,
    /// The previous frame's fine output is an input (§3.2.2); off for the ablation.
    #[config(default = true)]
    pub init_input: bool,
    /// The coarse map's local geometry (stretch, normal, curvature vector: nine channels,
    /// [`super::inference::geometry_channels`]) is an input (beyond the paper). The fine
    /// detail is mostly folds sharper than the coarse mesh, along its curved lines, and
    /// wrinkles taking up the length it has lost; the coordinates show curvature and a ~1 %
    /// shortening only as tiny second differences. `None` (models saved before it existed)
    /// is off.
    pub geometry_input: Option<bool>,
    /// Pixel-unshuffle factor s (beyond the paper): the patch's s × s pixel blocks become one
    /// token of `in·s²` channels, the Swin body works on a `P/s × P/s` grid and a pixel
    /// shuffle of a `C → 3·s²` reconstruction returns the full fine resolution. The body's
    /// cost falls by s² and a window covers s² times the cloth; the fine cloth's folds are
    /// 10–20 mm wide, several 2.5 mm pixels. `None` (models saved before it existed) is 1.
    pub unshuffle: Option<usize>,
    /// The panel's fabric and the coarse/fine ratio are inputs ([`super::condition`]: four
    /// constant channels). `None` (models saved before it existed) is off.
    pub condition_input: Option<bool>,
}

impl IsrConfig {
    /// Input channels: coarse (3), previous fine (3, with `init_input`), coarse geometry (9,
    /// with `geometry_input`), condition (4, with `condition_input`), mask (1).
    pub fn in_channels(&self) -> usize {
        4 + 3 * usize::from(self.init_input)
            + super::inference::GEOMETRY_CHANNELS * usize::from(self.geometry())
            + super::condition::CONDITION_CHANNELS * usize::from(self.condition())
    }

    /// The pixel-unshuffle factor (1: none).
    pub fn unshuffle_factor(&self) -> usize {
        self.unshuffle.unwrap_or(1)
    }

    /// Patch sides must be multiples of this: the window times the unshuffle factor.
    pub fn patch_multiple(&self) -> usize {
        self.window * self.unshuffle_factor()
    }

    /// Whether the coarse map's geometry is an input.
    pub fn geometry(&self) -> bool {
        self.geometry_input.unwrap_or(false)
    }

    /// Whether the fabric and the coarse/fine ratio are inputs.
    pub fn condition(&self) -> bool {
        self.condition_input.unwrap_or(false)
    }

    /// The same network with every optional input spelled out (`None`, in models saved before
    /// an input existed, is off; an unshuffle of `None` is 1), for comparing configurations.
    pub fn settled(&self) -> IsrConfig {
        let mut m = self.clone();
        m.geometry_input = Some(self.geometry());
        m.unshuffle = Some(self.unshuffle_factor());
        m.condition_input = Some(self.condition());
        m
    }

    /// Checks the sizes; `Err` names the problem.
    pub fn check(&self) -> Result<()> {
        if self.embed_dim == 0 || self.heads == 0 || !self.embed_dim.is_multiple_of(self.heads) {
            return Err(Error::Invalid(format!(
                "embed_dim ({}) must be a positive multiple of heads ({})",
                self.embed_dim, self.heads
            )));
        }
        if self.window < 2 || self.depths.is_empty() || self.depths.contains(&0) {
            return Err(Error::Invalid(
                "window must be at least 2 and every depth at least 1".into(),
            ));
        }
        if !(self.mlp_ratio.is_finite() && self.mlp_ratio > 0.0) {
            return Err(Error::Invalid("mlp_ratio must be positive".into()));
        }
        if !(1..=8).contains(&self.unshuffle_factor()) {
            return Err(Error::Invalid(format!(
                "unshuffle must lie in 1..=8, got {}",
                self.unshuffle_factor()
            )));
        }
        Ok(())
    }

    /// A network with random weights on `device`.
    pub fn init(&self, device: &Device) -> IsrNet {
        let c = self.embed_dim;
        let hidden = ((c as f64) * self.mlp_ratio).round().max(1.0) as usize;
        let layers = self
            .depths
            .iter()
            .map(|&d| Rstb {
                layers: (0..d)
                    .map(|i| SwinLayer::new(c, self.heads, self.window, i % 2 == 1, hidden, device))
                    .collect(),
                conv: conv3(c, c, device),
            })
            .collect();
        let s2 = self.unshuffle_factor().pow(2);
        IsrNet {
            conv_first: conv3(self.in_channels() * s2, c, device),
            layers,
            norm: LayerNormConfig::new(c).init(device),
            conv_after_body: conv3(c, c, device),
            // Zero-initialised: an untrained network returns the coarse patch unchanged, so
            // training starts from the upsampled baseline instead of from noise.
            conv_last: Conv2dConfig::new([c, 3 * s2], [3, 3])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .with_initializer(Initializer::Zeros)
                .init(device),
            window: self.window,
            unshuffle: self.unshuffle_factor(),
        }
    }
}

fn conv3(cin: usize, cout: usize, device: &Device) -> Conv2d {
    Conv2dConfig::new([cin, cout], [3, 3])
        .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
        .init(device)
}

/// The SwinIR network.
#[derive(Module, Debug)]
pub struct IsrNet {
    conv_first: Conv2d,
    layers: Vec<Rstb>,
    norm: LayerNorm,
    conv_after_body: Conv2d,
    conv_last: Conv2d,
    window: usize,
    unshuffle: usize,
}

/// Pixel unshuffle: `[B, C, H, W] → [B, C·s², H/s, W/s]`, channel `c·s² + i·s + j` holding
/// pixel `(s·y + i, s·x + j)` of channel c (PyTorch's `pixel_unshuffle` order).
pub fn pixel_unshuffle(x: Tensor<4>, s: usize) -> Tensor<4> {
    if s == 1 {
        return x;
    }
    let [b, c, h, w] = x.dims();
    x.reshape([b, c, h / s, s, w / s, s])
        .permute([0, 1, 3, 5, 2, 4])
        .reshape([b, c * s * s, h / s, w / s])
}

/// The inverse of [`pixel_unshuffle`]: `[B, C·s², H, W] → [B, C, H·s, W·s]`.
pub fn pixel_shuffle(x: Tensor<4>, s: usize) -> Tensor<4> {
    if s == 1 {
        return x;
    }
    let [b, cs, h, w] = x.dims();
    let c = cs / (s * s);
    x.reshape([b, c, s, s, h, w])
        .permute([0, 1, 4, 2, 5, 3])
        .reshape([b, c, h * s, w * s])
}

/// A residual Swin transformer block.
#[derive(Module, Debug)]
pub struct Rstb {
    layers: Vec<SwinLayer>,
    conv: Conv2d,
}

/// A Swin transformer layer (window attention + MLP), optionally on shifted windows.
#[derive(Module, Debug)]
pub struct SwinLayer {
    norm1: LayerNorm,
    qkv: Linear,
    proj: Linear,
    /// `[(2w − 1)², heads]` learned bias per relative offset.
    bias_table: Param<Tensor<2>>,
    norm2: LayerNorm,
    fc1: Linear,
    fc2: Linear,
    heads: usize,
    window: usize,
    shifted: bool,
}

impl SwinLayer {
    fn new(
        c: usize,
        heads: usize,
        window: usize,
        shifted: bool,
        hidden: usize,
        device: &Device,
    ) -> SwinLayer {
        let side = 2 * window - 1;
        SwinLayer {
            norm1: LayerNormConfig::new(c).init(device),
            qkv: LinearConfig::new(c, 3 * c).init(device),
            proj: LinearConfig::new(c, c).init(device),
            bias_table: Initializer::Normal {
                mean: 0.0,
                std: 0.02,
            }
            .init([side * side, heads], device),
            norm2: LayerNormConfig::new(c).init(device),
            fc1: LinearConfig::new(c, hidden).init(device),
            fc2: LinearConfig::new(hidden, c).init(device),
            heads,
            window,
            shifted,
        }
    }

    /// The shift of this layer for an `h × w` image: half a window, or none when the image is a
    /// single window (as SwinIR).
    fn shift(&self, h: usize, w: usize) -> usize {
        if self.shifted && h > self.window && w > self.window {
            self.window / 2
        } else {
            0
        }
    }

    /// `[heads, N, N]` relative-position bias, N = window².
    fn position_bias(&self, device: &Device) -> Tensor<3> {
        let n = self.window * self.window;
        let idx = index_tensor(&relative_position_index(self.window), device);
        self.bias_table
            .val()
            .select(0, idx) // [N·N, heads]
            .reshape([n, n, self.heads])
            .permute([2, 0, 1])
    }

    /// `[B, H, W, C] → [B, H, W, C]`.
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let [b, h, w, c] = x.dims();
        let device = x.device();
        let ws = self.window;
        let n = ws * ws;
        let nw = (h / ws) * (w / ws);
        let d = c / self.heads;
        let s = self.shift(h, w) as i64;
        let shortcut = x.clone();
        let mut y = self.norm1.forward(x);
        if s > 0 {
            y = y.roll(&[-s, -s], &[1, 2]);
        }
        let win = window_partition(y, ws); // [B·nW, N, C]
        let qkv = self.qkv.forward(win); // [B·nW, N, 3C]
        let heads = |t: Tensor<3>| t.reshape([b * nw, n, self.heads, d]).swap_dims(1, 2);
        let q = heads(qkv.clone().narrow(2, 0, c)); // [B·nW, heads, N, d]
        let k = heads(qkv.clone().narrow(2, c, c));
        let v = heads(qkv.narrow(2, 2 * c, c));
        // Additive bias: relative position [1, 1, heads, N, N] + shift mask [1, nW, 1, N, N].
        let mut bias: Tensor<5> = self
            .position_bias(&device)
            .unsqueeze_dims::<5>(&[0, 1])
            .expand([b, nw, self.heads, n, n]);
        if s > 0 {
            let mask = shift_mask(h, w, ws, s as usize);
            let mask = Tensor::<3>::from_data(TensorData::new(mask, [nw, n, n]), &device)
                .unsqueeze_dims::<5>(&[0, 2]);
            bias = bias + mask;
        }
        let bias = bias.reshape([b * nw, self.heads, n, n]);
        let o = attention(q, k, v, None, Some(bias), AttentionModuleOptions::default());
        let o = self.proj.forward(o.swap_dims(1, 2).reshape([b * nw, n, c]));
        let mut y = window_reverse(o, ws, b, h, w); // [B, H, W, C]
        if s > 0 {
            y = y.roll(&[s, s], &[1, 2]);
        }
        let x = shortcut + y;
        let m = self
            .fc2
            .forward(gelu(self.fc1.forward(self.norm2.forward(x.clone()))));
        x + m
    }
}

/// An index list on `device`.
fn index_tensor(indices: &[i64], device: &Device) -> Tensor<1, Int> {
    Tensor::from_data(TensorData::new(indices.to_vec(), [indices.len()]), device)
}

/// For every (query, key) pair of tokens in a `w × w` window, the row of the bias table of their
/// relative offset (SwinIR's `relative_position_index`), `[w⁴]`.
pub fn relative_position_index(w: usize) -> Vec<i64> {
    let n = w * w;
    let side = 2 * w as i64 - 1;
    let mut out = Vec::with_capacity(n * n);
    for a in 0..n {
        for b in 0..n {
            let (ai, aj) = ((a / w) as i64, (a % w) as i64);
            let (bi, bj) = ((b / w) as i64, (b % w) as i64);
            out.push((ai - bi + w as i64 - 1) * side + (aj - bj + w as i64 - 1));
        }
    }
    out
}

/// The additive attention mask of shifted windows on an `h × w` image rolled by `-shift`
/// (SwinIR's `calculate_mask`): `[nW · N · N]`, 0 between tokens that were neighbours before the
/// roll, −100 between tokens that only meet because the roll wrapped the image around.
pub fn shift_mask(h: usize, w: usize, ws: usize, shift: usize) -> Vec<f32> {
    let region = |i: usize, len: usize| -> usize {
        if i < len - ws {
            0
        } else if i < len - shift {
            1
        } else {
            2
        }
    };
    let (nh, nw) = (h / ws, w / ws);
    let n = ws * ws;
    let mut out = Vec::with_capacity(nh * nw * n * n);
    for wi in 0..nh {
        for wj in 0..nw {
            let label = |t: usize| {
                let (i, j) = (wi * ws + t / ws, wj * ws + t % ws);
                region(i, h) * 3 + region(j, w)
            };
            for a in 0..n {
                for b in 0..n {
                    out.push(if label(a) == label(b) { 0.0 } else { -100.0 });
                }
            }
        }
    }
    out
}

/// `[B, H, W, C] → [B·nW, ws², C]`, windows in row-major order per image.
pub fn window_partition(x: Tensor<4>, ws: usize) -> Tensor<3> {
    let [b, h, w, c] = x.dims();
    x.reshape([b, h / ws, ws, w / ws, ws, c])
        .permute([0, 1, 3, 2, 4, 5])
        .reshape([b * (h / ws) * (w / ws), ws * ws, c])
}

/// The inverse of [`window_partition`]: `[B·nW, ws², C] → [B, H, W, C]`.
pub fn window_reverse(x: Tensor<3>, ws: usize, b: usize, h: usize, w: usize) -> Tensor<4> {
    let [_, _, c] = x.dims();
    x.reshape([b, h / ws, w / ws, ws, ws, c])
        .permute([0, 1, 3, 2, 4, 5])
        .reshape([b, h, w, c])
}

impl IsrNet {
    /// Patch sides must be multiples of this: the window times the unshuffle factor.
    pub fn patch_multiple(&self) -> usize {
        self.window * self.unshuffle
    }

    /// `input [B, in, P, P]` (normalised: coarse shape, initialisation detail, mask)
    /// `→ [B, 3, P, P]`, the fine patch's detail (fine − coarse)
    /// in detail units. P must be a multiple of [`Self::patch_multiple`].
    pub fn forward(&self, input: Tensor<4>) -> Tensor<4> {
        let [_, _, h, w] = input.dims();
        let m = self.patch_multiple();
        assert!(
            h.is_multiple_of(m) && w.is_multiple_of(m),
            "ISR patches ({h}×{w}) must be multiples of the window times the unshuffle factor ({m})"
        );
        let input = pixel_unshuffle(input, self.unshuffle); // [B, in·s², P/s, P/s]
        let shallow = self.conv_first.forward(input); // [B, C, P/s, P/s]
        let mut x = shallow.clone();
        for rstb in &self.layers {
            let mut y = x.clone().permute([0, 2, 3, 1]); // [B, P, P, C]
            for layer in &rstb.layers {
                y = layer.forward(y);
            }
            x = x + rstb.conv.forward(y.permute([0, 3, 1, 2]));
        }
        let x = self
            .norm
            .forward(x.permute([0, 2, 3, 1]))
            .permute([0, 3, 1, 2]);
        let deep = self.conv_after_body.forward(x) + shallow;
        pixel_shuffle(self.conv_last.forward(deep), self.unshuffle) // [B, 3, P, P]
    }
}
