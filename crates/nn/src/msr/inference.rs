//! Running the ISR network (the paper's §3.2, Fig. 6): per frame, rasterise M_int on the fine
//! panel grids, cut each map into overlapping patches, run them through the network in
//! batches together with the previous frame's fine output (the initialisation), blend the
//! patches back (two-pixel overlap, Laplacian smoothing of the bands) and read the fine mesh
//! out. The fine maps are kept as the next frame's initialisation.

use std::path::Path;
use std::time::Instant;

use burn::tensor::{Device, Tensor, TensorData};
use nalgebra::Vector3;
use ndarray::{s, Array3, Array4, ArrayView2, ArrayView3};

use super::condition::{Condition, CONDITION_CHANNELS};
use super::coordmap::{Boundary, PanelGrid, Rasteriser, Readout};
use super::model::IsrNet;
use super::patches::{blend_patches, split_patches, PatchLayout, DEFAULT_OVERLAP, DEFAULT_SIGMA};
use super::training::IsrTrainingConfig;
use clothsr_geometry::error::{Error, Result};
use clothsr_geometry::mesh::ClothMesh;

/// The training settings and network sizes in a model directory.
pub const CONFIG_FILE: &str = "config.json";
/// The weights in a model directory (burnpack).
pub const WEIGHTS_FILE: &str = "model.bpk";

/// Length change that one unit of the stretch channels stands for (1 %).
pub const STRAIN_UNIT: f32 = 0.01;
/// Curvature that one unit of the curvature channels stands for, 1/m (a 20 mm radius).
pub const CURVATURE_UNIT: f32 = 50.0;
/// Stencil half-width of the curvature channels, pixels (10 mm at 2.5 mm pixels: the coarse
/// mesh's scale, not the rasteriser's kinks at coarse edges).
pub const CURVATURE_STENCIL_PX: usize = 4;
/// Channels of [`geometry_channels`].
pub const GEOMETRY_CHANNELS: usize = 9;

/// The local geometry of a coarse map `(3, H, W)` (metres, on a material grid of `pixel_m`
/// pixels) as [`GEOMETRY_CHANNELS`] channels `(9, H, W)`, zero off the mask:
///
/// * 0–2, stretch: (|∂x/∂u| − 1, |∂x/∂v| − 1, cos ∠(∂x/∂u, ∂x/∂v)) in units of
///   [`STRAIN_UNIT`]. A cloth shortened by its wrinkles shows here as negative stretch.
/// * 3–5, the unit normal ∂x/∂u × ∂x/∂v (normalised; its side is the pattern's orientation).
/// * 6–8, the curvature vector: the Laplacian Σ_axes (x₊ − 2x + x₋)/(s h)², with s the largest
///   step up to [`CURVATURE_STENCIL_PX`] whose whole stencil (every pixel up to s either side)
///   is on the mask (an axis without even s = 1 contributes nothing), in units of [`CURVATURE_UNIT`]. It points into a fold's
///   concave side with length 1/R for a fold of radius R.
///
/// First derivatives are central differences where both neighbours are on the mask,
/// one-sided where one is; a pixel with neither along an axis has zero stretch and normal.
/// Every channel is clamped to ±10 units.
pub fn geometry_channels(
    coarse: ArrayView3<f32>,
    mask: ArrayView2<bool>,
    pixel_m: f32,
) -> Array3<f32> {
    let (_, p, q) = coarse.dim();
    let mut out = Array3::zeros((GEOMETRY_CHANNELS, p, q));
    let at =
        |i: usize, j: usize| Vector3::new(coarse[(0, i, j)], coarse[(1, i, j)], coarse[(2, i, j)]);
    let on = |i: isize, j: isize| {
        i >= 0 && j >= 0 && (i as usize) < p && (j as usize) < q && mask[(i as usize, j as usize)]
    };
    let step = |i: usize, j: usize, k: isize, di: isize, dj: isize| {
        (
            (i as isize + k * di) as usize,
            (j as isize + k * dj) as usize,
        )
    };
    // The derivative along (di, dj) at (i, j), metres per metre of material.
    let derivative = |i: usize, j: usize, di: isize, dj: isize| -> Option<Vector3<f32>> {
        let (ii, jj) = (i as isize, j as isize);
        let (f, b) = (step(i, j, 1, di, dj), step(i, j, -1, di, dj));
        match (on(ii + di, jj + dj), on(ii - di, jj - dj)) {
            (true, true) => Some((at(f.0, f.1) - at(b.0, b.1)) / (2.0 * pixel_m)),
            (true, false) => Some((at(f.0, f.1) - at(i, j)) / pixel_m),
            (false, true) => Some((at(i, j) - at(b.0, b.1)) / pixel_m),
            (false, false) => None,
        }
    };
    // The second derivative along (di, dj) on the widest symmetric stencil available.
    let second = |i: usize, j: usize, di: isize, dj: isize| -> Vector3<f32> {
        let (ii, jj) = (i as isize, j as isize);
        // The widest s whose whole stencil is on the mask (no differencing across a slit or
        // a notch of the pattern).
        let reach = (1..=CURVATURE_STENCIL_PX as isize)
            .take_while(|&k| on(ii + k * di, jj + k * dj) && on(ii - k * di, jj - k * dj))
            .last();
        let Some(s) = reach else {
            return Vector3::zeros();
        };
        let (f, b) = (step(i, j, s, di, dj), step(i, j, -s, di, dj));
        let hs = s as f32 * pixel_m;
        (at(f.0, f.1) - 2.0 * at(i, j) + at(b.0, b.1)) / (hs * hs)
    };
    let mut put = |c: usize, i: usize, j: usize, v: f32| {
        out[(c, i, j)] = if v.is_finite() {
            v.clamp(-10.0, 10.0)
        } else {
            0.0
        };
    };
    for ((i, j), &m) in mask.indexed_iter() {
        if !m {
            continue;
        }
        if let (Some(a), Some(b)) = (derivative(i, j, 1, 0), derivative(i, j, 0, 1)) {
            let (la, lb) = (a.norm(), b.norm());
            if la > 0.0 && lb > 0.0 {
                put(0, i, j, (la - 1.0) / STRAIN_UNIT);
                put(1, i, j, (lb - 1.0) / STRAIN_UNIT);
                put(2, i, j, a.dot(&b) / (la * lb) / STRAIN_UNIT);
            }
            let n = a.cross(&b);
            let ln = n.norm();
            if ln > 0.0 {
                for c in 0..3 {
                    put(3 + c, i, j, n[c] / ln);
                }
            }
        }
        let lap = second(i, j, 1, 0) + second(i, j, 0, 1);
        for c in 0..3 {
            put(6 + c, i, j, lap[c] / CURVATURE_UNIT);
        }
    }
    out
}

/// The network's input for one patch, normalised: channels coarse shape (3), initialisation
/// detail (3, when `init` is given), the coarse map's geometry (9, when `geometry` is given:
/// the patch of [`geometry_channels`] of the whole map), the condition (4, when `condition`
/// is given: [`Condition::channels`], constant) and mask (1), each `P × P`, zero off the
/// mask. The coarse
/// positions are centred on the mean of the patch's masked pixels and divided by `scale_m`;
/// the initialisation enters as its difference to the coarse patch divided by `detail_m`.
/// `None` when no pixel is masked.
pub fn patch_input(
    coarse: ArrayView3<f32>,
    init: Option<ArrayView3<f32>>,
    mask: ArrayView2<bool>,
    scale_m: f32,
    detail_m: f32,
    geometry: Option<ArrayView3<f32>>,
    condition: Option<&[f32; CONDITION_CHANNELS]>,
) -> Option<Vec<f32>> {
    let count = mask.iter().filter(|&&m| m).count();
    if count == 0 {
        return None;
    }
    let mut centre = [0.0f32; 3];
    for (c, centre) in centre.iter_mut().enumerate() {
        let sum: f64 = coarse
            .index_axis(ndarray::Axis(0), c)
            .iter()
            .zip(mask.iter())
            .filter(|(_, &m)| m)
            .map(|(v, _)| f64::from(*v))
            .sum();
        *centre = (sum / count as f64) as f32;
    }
    let (_, p, q) = coarse.dim();
    let channels = 4
        + 3 * usize::from(init.is_some())
        + GEOMETRY_CHANNELS * usize::from(geometry.is_some())
        + CONDITION_CHANNELS * usize::from(condition.is_some());
    let mut out = Vec::with_capacity(channels * p * q);
    for (c, centre) in centre.iter().enumerate() {
        for ((i, j), &m) in mask.indexed_iter() {
            out.push(if m {
                (coarse[(c, i, j)] - centre) / scale_m
            } else {
                0.0
            });
        }
    }
    if let Some(init) = init {
        for c in 0..3 {
            for ((i, j), &m) in mask.indexed_iter() {
                out.push(if m {
                    (init[(c, i, j)] - coarse[(c, i, j)]) / detail_m
                } else {
                    0.0
                });
            }
        }
    }
    if let Some(g) = geometry {
        for ((_, i, j), &v) in g.indexed_iter() {
            out.push(if mask[(i, j)] { v } else { 0.0 });
        }
    }
    for &v in condition.into_iter().flatten() {
        out.extend(mask.iter().map(|&m| if m { v } else { 0.0 }));
    }
    out.extend(mask.iter().map(|&m| if m { 1.0 } else { 0.0 }));
    Some(out)
}

/// A trained ISR network and its settings.
pub struct Isr {
    /// Training settings, with the network's sizes, pixel size and normalisation scale.
    pub cfg: IsrTrainingConfig,
    net: IsrNet,
    device: Device,
}

/// A field of `config.json` (at `path`) that this build does not know is an error: a newer
/// build's option would make a different network of the same weights.
fn unknown_fields(path: &Path, cfg: &IsrTrainingConfig) -> Result<()> {
    fn walk(given: &serde_json::Value, known: &serde_json::Value, at: &str) -> Option<String> {
        let (serde_json::Value::Object(g), serde_json::Value::Object(k)) = (given, known) else {
            return None;
        };
        g.iter().find_map(|(key, v)| {
            let here = if at.is_empty() {
                key.clone()
            } else {
                format!("{at}.{key}")
            };
            match k.get(key) {
                None => Some(here),
                Some(kv) => walk(v, kv, &here),
            }
        })
    }
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let given: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| Error::bad_input(path, e.to_string()))?;
    let known = serde_json::to_value(cfg).map_err(|e| Error::bad_input(path, e.to_string()))?;
    match walk(&given, &known, "") {
        Some(field) => Err(Error::bad_input(
            path,
            format!("unknown field '{field}' (from a newer clothsr?)"),
        )),
        None => Ok(()),
    }
}

impl Isr {
    /// Loads `dir/config.json` and `dir/model.bpk` on the default device
    /// ([`crate::common::default_device`]).
    pub fn load(dir: &Path) -> Result<Isr> {
        let cfg_path = dir.join(CONFIG_FILE);
        let cfg = <IsrTrainingConfig as burn::config::Config>::load(&cfg_path)
            .map_err(|e| Error::bad_input(&cfg_path, e.to_string()))?;
        unknown_fields(&cfg_path, &cfg)?;
        cfg.model.check().map_err(|e| e.in_file(&cfg_path))?;
        let m = cfg.model.patch_multiple();
        if cfg.patch == 0 || !cfg.patch.is_multiple_of(m) {
            return Err(Error::bad_input(
                &cfg_path,
                format!(
                    "the patch ({}) must be a positive multiple of {m}",
                    cfg.patch
                ),
            ));
        }
        let device = crate::common::default_device()?;
        let weights = dir.join(WEIGHTS_FILE);
        let net = crate::common::load_network(&device, &weights, || cfg.model.init(&device))?;
        Ok(Isr { cfg, net, device })
    }

    /// Wraps a network (for instance one just trained).
    pub fn from_net(cfg: IsrTrainingConfig, net: IsrNet, device: Device) -> Isr {
        Isr { cfg, net, device }
    }

    /// Runs the network on normalised inputs `[B, in, P, P]` → `[B, 3, P, P]`, the fine detail
    /// (fine − coarse) in units of `detail_m`.
    pub fn run(&self, inputs: Vec<f32>, batch: usize) -> Result<Vec<f32>> {
        let (cin, p) = (self.cfg.model.in_channels(), self.cfg.patch);
        let x = Tensor::<4>::from_data(TensorData::new(inputs, [batch, cin, p, p]), &self.device);
        self.net
            .forward(x)
            .into_data()
            .try_to_vec::<f32>()
            .map_err(|e| Error::Invalid(format!("ISR output: {e:?}")))
    }
}

/// Seconds spent in each part of the last frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FrameTimes {
    /// Rasterising M_int and cutting patches.
    pub rasterise_s: f64,
    /// The network.
    pub network_s: f64,
    /// Blending patches and reading the fine mesh out.
    pub readout_s: f64,
}

impl FrameTimes {
    /// The whole frame.
    pub fn total_s(&self) -> f64 {
        self.rasterise_s + self.network_s + self.readout_s
    }
}

/// Super-resolves a garment frame by frame: M_int of the coarse mesh in, the fine mesh out.
pub struct SuperResolver<'a> {
    isr: &'a Isr,
    grids: Vec<PanelGrid>,
    rasteriser: Rasteriser,
    readout: Readout,
    layouts: Vec<PatchLayout>,
    /// Each grid's condition channels (when the network takes them).
    conditions: Vec<[f32; CONDITION_CHANNELS]>,
    /// The previous frame's fine maps (the initialisation), metres.
    prev: Option<Vec<Array3<f32>>>,
    /// The previous frame's coarse maps, metres.
    prev_coarse: Option<Vec<Array3<f32>>>,
    /// Patches per network call.
    pub batch: usize,
    /// Times of the last frame.
    pub times: FrameTimes,
}

/// The MSR module's memory between frames: the previous frame's fine maps and the coarse maps
/// they went with, each (3, H, W) per panel grid, metres.
#[derive(Debug, Clone, PartialEq)]
pub struct InitMaps {
    /// Fine maps (the network's output of the previous frame).
    pub fine: Vec<Array3<f32>>,
    /// Coarse maps of the previous frame.
    pub coarse: Vec<Array3<f32>>,
}

impl<'a> SuperResolver<'a> {
    /// Prepares super-resolving `coarse` (the M_int mesh) into `fine` (same panels and material
    /// space), on grids at the model's pixel size, each panel with its condition in
    /// `conditions` (one per panel of `fine`; read only by networks that take it).
    pub fn new(
        isr: &'a Isr,
        coarse: &ClothMesh,
        fine: &ClothMesh,
        conditions: &[Condition],
    ) -> Result<SuperResolver<'a>> {
        let grids = PanelGrid::for_mesh(fine, isr.cfg.pixel_m, Boundary::Extended)?;
        let conditions = if isr.cfg.model.condition() {
            if conditions.len() != fine.panel_names.len() {
                return Err(Error::Invalid(format!(
                    "the ISR network takes each panel's fabric: {} conditions for {} panels",
                    conditions.len(),
                    fine.panel_names.len()
                )));
            }
            for c in conditions {
                c.check()?;
            }
            grids
                .iter()
                .map(|g| conditions[g.panel as usize].channels())
                .collect()
        } else {
            Vec::new()
        };
        let rasteriser = Rasteriser::new(coarse, &grids)?.with_phong(isr.cfg.phong_alpha);
        let readout = Readout::new(fine, &grids)?;
        let layouts = grids
            .iter()
            .map(|g| {
                let (h, w) = g.shape();
                PatchLayout::new(h, w, isr.cfg.patch, DEFAULT_OVERLAP)
            })
            .collect();
        Ok(SuperResolver {
            isr,
            grids,
            rasteriser,
            readout,
            layouts,
            conditions,
            prev: None,
            prev_coarse: None,
            // Patches per call: small batches stay in cache, and 8 was the fastest of the
            // sizes tried (`clothsr lab sr`, `clothsr lab bench pipeline`).
            batch: 8,
            times: FrameTimes::default(),
        })
    }

    /// Sets the previous frame from outside: the fine mesh `fine` (rasterised on the grids; a
    /// fine simulation's frame, for teacher-forced evaluation) and the coarse M_int `coarse` it
    /// went with.
    pub fn set_previous(
        &mut self,
        fine_mesh: &ClothMesh,
        fine: &[Vector3<f64>],
        coarse: &[Vector3<f64>],
    ) -> Result<()> {
        let r = Rasteriser::new(fine_mesh, &self.grids)?;
        self.prev = Some(r.rasterise(fine).into_iter().map(|m| m.image).collect());
        self.prev_coarse = Some(
            self.rasteriser
                .rasterise(coarse)
                .into_iter()
                .map(|m| m.image)
                .collect(),
        );
        Ok(())
    }

    /// The previous frame's fine and coarse maps (the next frame's initialisation), metres.
    pub fn previous_maps(&self) -> Option<InitMaps> {
        Some(InitMaps {
            fine: self.prev.clone()?,
            coarse: self.prev_coarse.clone()?,
        })
    }

    /// Sets the previous frame's maps exactly as [`SuperResolver::previous_maps`] gave them
    /// (resuming a run). Fails when their shapes are not those of the grids.
    pub fn set_previous_maps(&mut self, maps: InitMaps) -> Result<()> {
        let shapes_ok = |maps: &[Array3<f32>]| {
            maps.len() == self.grids.len()
                && maps.iter().zip(&self.grids).all(|(m, g)| {
                    let (h, w) = g.shape();
                    m.shape() == [3, h, w]
                })
        };
        if !shapes_ok(&maps.fine) || !shapes_ok(&maps.coarse) {
            return Err(Error::Invalid(
                "the saved initialisation maps do not fit this garment's grids".into(),
            ));
        }
        self.prev = Some(maps.fine);
        self.prev_coarse = Some(maps.coarse);
        Ok(())
    }

    /// Forgets the previous frame: the next frame starts from the coarse map (a new shot).
    pub fn reset(&mut self) {
        self.prev = None;
        self.prev_coarse = None;
    }

    /// The fine maps of the last frame (metres), one per grid.
    pub fn fine_maps(&self) -> Option<&[Array3<f32>]> {
        self.prev.as_deref()
    }

    /// The panel grids.
    pub fn grids(&self) -> &[PanelGrid] {
        &self.grids
    }

    /// The fine mesh's vertex positions for coarse (M_int) positions `x`.
    pub fn frame(&mut self, x: &[Vector3<f64>]) -> Result<Vec<Vector3<f64>>> {
        let t0 = Instant::now();
        let cfg = &self.isr.cfg;
        let (p, scale, detail) = (cfg.patch, cfg.scale_m as f32, cfg.detail_m as f32);
        let use_init = cfg.model.init_input;
        let use_geometry = cfg.model.geometry();
        let maps = self.rasteriser.rasterise(x);
        // Every patch of every panel: (grid, patch index) and its input.
        let mut index: Vec<(usize, usize)> = Vec::new();
        let mut inputs: Vec<f32> = Vec::new();
        let mut patches: Vec<(Array4<f32>, Array3<bool>)> = Vec::new();
        for (g, (map, layout)) in maps.iter().zip(&self.layouts).enumerate() {
            let init = match (&self.prev, &self.prev_coarse) {
                (Some(prev), Some(pc)) if cfg.init_motion => &prev[g] + &map.image - &pc[g],
                (Some(prev), _) => prev[g].clone(),
                _ => map.image.clone(),
            };
            let (cp, mp) = split_patches(&map.image, &map.mask, layout);
            let (ip, _) = split_patches(&init, &map.mask, layout);
            let gp = use_geometry.then(|| {
                let g = geometry_channels(map.image.view(), map.mask.view(), cfg.pixel_m as f32);
                split_patches(&g, &map.mask, layout).0
            });
            for k in 0..layout.num_patches() {
                let init_k = use_init.then(|| ip.slice(s![k, .., .., ..]));
                let geometry_k = gp.as_ref().map(|g| g.slice(s![k, .., .., ..]));
                if let Some(input) = patch_input(
                    cp.slice(s![k, .., .., ..]),
                    init_k,
                    mp.slice(s![k, .., ..]),
                    scale,
                    detail,
                    geometry_k,
                    self.conditions.get(g),
                ) {
                    inputs.extend(input);
                    index.push((g, k));
                }
            }
            patches.push((cp, mp));
        }
        let t1 = Instant::now();
        let per = cfg.model.in_channels() * p * p;
        let mut outputs: Vec<f32> = Vec::with_capacity(index.len() * 3 * p * p);
        for chunk in inputs.chunks(per * self.batch.max(1)) {
            outputs.extend(self.isr.run(chunk.to_vec(), chunk.len() / per)?);
        }
        if outputs.iter().any(|v| !v.is_finite()) {
            return Err(Error::Simulation(
                "the ISR network produced a non-finite output".into(),
            ));
        }
        let t2 = Instant::now();
        // Add the detail to the coarse patches (patches the network did not see keep the
        // coarse map), blend, read out.
        for (n, &(g, k)) in index.iter().enumerate() {
            let out = &outputs[n * 3 * p * p..(n + 1) * 3 * p * p];
            let cp = &mut patches[g].0;
            for c in 0..3 {
                for i in 0..p {
                    for j in 0..p {
                        cp[(k, c, i, j)] += out[(c * p + i) * p + j] * detail;
                    }
                }
            }
        }
        let fine_maps: Vec<Array3<f32>> = patches
            .iter()
            .zip(&self.layouts)
            .zip(&maps)
            .map(|(((cp, _), layout), map)| blend_patches(cp, layout, &map.mask, DEFAULT_SIGMA))
            .collect();
        let read: Vec<super::coordmap::CoordMap> = fine_maps
            .iter()
            .zip(&maps)
            .map(|(img, m)| super::coordmap::CoordMap {
                image: img.clone(),
                mask: m.mask.clone(),
            })
            .collect();
        let fine = self.readout.read(&read);
        self.prev = Some(fine_maps);
        self.prev_coarse = Some(maps.into_iter().map(|m| m.image).collect());
        self.times = FrameTimes {
            rasterise_s: (t1 - t0).as_secs_f64(),
            network_s: (t2 - t1).as_secs_f64(),
            readout_s: t2.elapsed().as_secs_f64(),
        };
        Ok(fine)
    }
}
