//! Training and evaluation data for the ISR network, read from data sets made by
//! `clothsr::dataset::generate`: per frame, M_int (the downsampled fine simulation at the frame's
//! end) rasterised on the fine mesh's panel grids (the coarse map I_c), the fine simulation M_f
//! rasterised on the same grids (the ground truth I_gt), and the initialisation of §3.3.3: the
//! ground-truth map of the frame before, smoothed with a Gaussian kernel.

use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use ndarray::{Array2, Array3};

use super::condition::{data_conditions, Condition};
use super::coordmap::{Boundary, PanelGrid, Rasteriser};
use clothsr_geometry::error::{Error, Result};
use clothsr_geometry::mesh::ClothMesh;
use clothsr_io::data::{
    read_coarse_mesh, read_fine_mesh, read_frame_positions, read_manifest, Manifest,
};

/// One frame's maps, one per panel grid, each (3, H, W) in metres (zero off the mask).
#[derive(Debug, Clone)]
pub struct FrameMaps {
    /// M_int rasterised: the coarse map I_c.
    pub coarse: Vec<Array3<f32>>,
    /// M_f rasterised: the ground truth I_gt.
    pub fine: Vec<Array3<f32>>,
    /// I_gt smoothed with the Gaussian kernel (the next frame's training initialisation).
    pub smoothed: Vec<Array3<f32>>,
}

/// A data set's frames as coordinate maps, plus the vertex positions for evaluation.
#[derive(Debug, Clone)]
pub struct IsrSequence {
    /// The data set directory.
    pub dir: PathBuf,
    /// Its manifest.
    pub manifest: Manifest,
    /// The coarse mesh (positions zero).
    pub coarse_mesh: ClothMesh,
    /// The fine mesh (positions zero).
    pub fine_mesh: ClothMesh,
    /// Panel grids at the fine pixel size (made from the fine mesh).
    pub grids: Vec<PanelGrid>,
    /// Each panel's fabric and resolution ratio; `None` when the data set does not say its
    /// fabric's parameters ([`super::condition::data_conditions`]).
    pub conditions: Option<Vec<Condition>>,
    /// First frame loaded (1-based).
    pub first_frame: usize,
    /// Maps of every loaded frame, in order.
    pub frames: Vec<FrameMaps>,
    /// M_int at each loaded frame's end.
    pub int_x: Vec<Vec<Vector3<f64>>>,
    /// M_f at each loaded frame's end.
    pub fine_x: Vec<Vec<Vector3<f64>>>,
}

fn vectors(v: &[f32]) -> Vec<Vector3<f64>> {
    v.chunks_exact(3)
        .map(|c| Vector3::new(f64::from(c[0]), f64::from(c[1]), f64::from(c[2])))
        .collect()
}

impl IsrSequence {
    /// Loads frames `frames` (1-based, inclusive; `None`: every complete frame) of the data set
    /// in `dir`, rasterised at `pixel_m` (M_int by Phong tessellation with blend
    /// `phong_alpha`, 0: linear), with the initialisation smoothed by a Gaussian of `blur_px`
    /// pixels (0: none).
    pub fn load(
        dir: &Path,
        frames: Option<RangeInclusive<usize>>,
        pixel_m: f64,
        phong_alpha: f64,
        blur_px: f64,
    ) -> Result<IsrSequence> {
        let manifest = read_manifest(dir)?;
        manifest.check_reference(dir)?;
        let coarse_mesh = read_coarse_mesh(dir, &manifest)?;
        let fine_mesh = read_fine_mesh(dir, &manifest)?;
        let range = frames.unwrap_or(1..=manifest.frames_done);
        if *range.start() == 0 || *range.end() > manifest.frames_done || range.is_empty() {
            return Err(Error::bad_input(
                dir.join("manifest.json"),
                format!(
                    "frames {}..={} requested, the data set has frames 1..={}",
                    range.start(),
                    range.end(),
                    manifest.frames_done
                ),
            ));
        }
        let grids = PanelGrid::for_mesh(&fine_mesh, pixel_m, Boundary::Extended)?;
        let conditions = data_conditions(&manifest, &fine_mesh).ok();
        let coarse_r = Rasteriser::new(&coarse_mesh, &grids)?.with_phong(phong_alpha);
        let fine_r = Rasteriser::new(&fine_mesh, &grids)?;
        let (nc, nf) = (coarse_mesh.num_vertices(), fine_mesh.num_vertices());
        let mut seq = IsrSequence {
            dir: dir.to_path_buf(),
            first_frame: *range.start(),
            manifest,
            coarse_mesh,
            fine_mesh,
            grids,
            conditions,
            frames: Vec::new(),
            int_x: Vec::new(),
            fine_x: Vec::new(),
        };
        for k in range {
            let path = dir.join("frames").join(format!("frame_{k:05}.safetensors"));
            let f = read_frame_positions(dir, k)?;
            let (ishape, int_all) = f.int_x;
            let (fshape, fine) = f.fine_x;
            if ishape.len() != 3 || ishape[1] != nc || ishape[2] != 3 || ishape[0] == 0 {
                return Err(Error::bad_input(
                    &path,
                    format!("'int_x' has shape {ishape:?}, expected [steps, {nc}, 3]"),
                ));
            }
            if fshape != [nf, 3] {
                return Err(Error::bad_input(
                    &path,
                    format!("'fine_x' has shape {fshape:?}, expected [{nf}, 3]"),
                ));
            }
            let int = &int_all[(ishape[0] - 1) * nc * 3..];
            if int.iter().chain(&fine).any(|v| !v.is_finite()) {
                return Err(Error::bad_input(&path, "non-finite positions"));
            }
            let (int, fine) = (vectors(int), vectors(&fine));
            let coarse: Vec<Array3<f32>> = coarse_r
                .rasterise(&int)
                .into_iter()
                .map(|m| m.image)
                .collect();
            let fine_maps: Vec<Array3<f32>> = fine_r
                .rasterise(&fine)
                .into_iter()
                .map(|m| m.image)
                .collect();
            let smoothed = fine_maps
                .iter()
                .zip(&seq.grids)
                .map(|(m, g)| gaussian_blur(m, &g.mask, blur_px))
                .collect();
            seq.frames.push(FrameMaps {
                coarse,
                fine: fine_maps,
                smoothed,
            });
            seq.int_x.push(int);
            seq.fine_x.push(fine);
        }
        Ok(seq)
    }
}

/// Gaussian smoothing of a (C, H, W) map over its `mask` only (weights renormalised over masked
/// pixels, so the boundary does not shrink towards zero), σ = `sigma_px` pixels, truncated at
/// 3σ. Pixels off the mask stay 0; σ = 0 returns the map.
pub fn gaussian_blur(map: &Array3<f32>, mask: &Array2<bool>, sigma_px: f64) -> Array3<f32> {
    if sigma_px <= 0.0 {
        return map.clone();
    }
    let r = (3.0 * sigma_px).ceil() as i64;
    let kernel: Vec<f32> = (-r..=r)
        .map(|d| (-(d * d) as f64 / (2.0 * sigma_px * sigma_px)).exp() as f32)
        .collect();
    let (c, h, w) = map.dim();
    let m = mask.mapv(|b| if b { 1.0f32 } else { 0.0 });
    // Separable: rows then columns, carrying the mask weight along.
    let pass = |src: &Array3<f32>, wt: &Array2<f32>, along_rows: bool| {
        let mut out = Array3::<f32>::zeros((c, h, w));
        let mut wout = Array2::<f32>::zeros((h, w));
        for i in 0..h {
            for j in 0..w {
                let mut acc = [0.0f32; 3];
                let mut wsum = 0.0f32;
                for (t, k) in kernel.iter().enumerate() {
                    let d = t as i64 - r;
                    let (a, b) = if along_rows {
                        (i as i64 + d, j as i64)
                    } else {
                        (i as i64, j as i64 + d)
                    };
                    if a < 0 || b < 0 || a >= h as i64 || b >= w as i64 {
                        continue;
                    }
                    let (a, b) = (a as usize, b as usize);
                    let wk = k * wt[(a, b)];
                    if wk == 0.0 {
                        continue;
                    }
                    wsum += wk;
                    for (ch, v) in acc.iter_mut().enumerate().take(c) {
                        *v += wk * src[(ch, a, b)];
                    }
                }
                wout[(i, j)] = wsum;
                if wsum > 0.0 {
                    for (ch, v) in acc.iter().enumerate().take(c) {
                        out[(ch, i, j)] = v / wsum;
                    }
                }
            }
        }
        (out, wout)
    };
    // Values stay normalised (weighted means) after each pass; the weights carry the mask.
    let (rows, wrows) = pass(map, &m, true);
    let (mut out, _) = pass(&rows, &wrows, false);
    for ((_, i, j), v) in out.indexed_iter_mut() {
        if !mask[(i, j)] {
            *v = 0.0;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blur_keeps_affine_maps_and_the_mask() {
        // An affine map is reproduced exactly away from the mask's edge, and the mask's outside
        // stays zero.
        let (h, w) = (20, 24);
        let mut mask = Array2::from_elem((h, w), false);
        for i in 2..18 {
            for j in 3..20 {
                mask[(i, j)] = true;
            }
        }
        let map = Array3::from_shape_fn((3, h, w), |(c, i, j)| {
            if mask[(i, j)] {
                c as f32 + 0.1 * i as f32 - 0.05 * j as f32
            } else {
                0.0
            }
        });
        let out = gaussian_blur(&map, &mask, 1.0);
        for i in 5..15 {
            for j in 6..17 {
                for c in 0..3 {
                    assert!((out[(c, i, j)] - map[(c, i, j)]).abs() < 1e-5);
                }
            }
        }
        assert_eq!(out[(0, 0, 0)], 0.0);
        // A bump is smoothed: its peak drops.
        let mut bump = map.clone();
        bump[(1, 10, 10)] += 1.0;
        let b = gaussian_blur(&bump, &mask, 1.0);
        assert!(b[(1, 10, 10)] - map[(1, 10, 10)] < 0.3);
        assert!(b[(1, 10, 11)] - map[(1, 10, 11)] > 0.05);
    }
}
