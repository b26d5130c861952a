//! Overlapping image patches for the ISR network (the paper's §3.2.1, "Overlapping patches").
//!
//! The ISR network sees small square patches rather than whole pattern images so that it
//! generalises across 2D pattern parameterisations. Each coordinate map is cut regularly into
//! patches of equal size; neighbouring patches share `overlap` pixel lines (two in the paper)
//! because each patch is processed independently and their shared boundaries would otherwise
//! disagree and leave seams in the fine mesh.
//!
//! Reassembly ([`blend_patches`]) follows the paper: pixels covered by several patches are
//! first averaged in image space (x̂), then every overlapped pixel line gets a Laplacian
//! smoothing step across its band, x_b = σ·(x̂_a + x̂_c)/2 + (1 − σ)·x̂_b. (The paper prints the
//! second term as "(1 − σ)x̂_b/2", which would shrink the coordinates; it is a typo — with it a
//! constant image would not be reproduced — so the affine combination is used here.)
//!
//! Choices where the paper is silent:
//! - The last patch along an axis is clamped to end at the image border, so it may overlap its
//!   predecessor by more than `overlap` lines. Smoothing is applied to *every* overlapped line
//!   whose two neighbours across the band exist, which reduces to the paper's two lines b and c
//!   for an ordinary 2-line band.
//! - All neighbours are read from the averaged image x̂ (a Jacobi-style step), as in the paper's
//!   x̃_b = (x_a + x̂_c)/2, so the result does not depend on the order lines are visited.
//! - Pixels in both a horizontal and a vertical band (band crossings) receive both smoothing
//!   terms additively, x = x̂ + σ/2·(Δ_rows x̂ + Δ_cols x̂), so rows and columns are treated
//!   symmetrically; with σ ≤ 1 every weight stays non-negative.

use ndarray::{s, Array2, Array3, Array4};

/// The paper's overlap between adjacent patches, in pixel lines.
pub const DEFAULT_OVERLAP: usize = 2;

/// The paper's weight σ of the Laplacian smoothing over overlap bands.
pub const DEFAULT_SIGMA: f32 = 0.5;

/// A regular grid of square, overlapping patches covering a `height × width` image.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PatchLayout {
    /// Side length P of every (square) patch, in pixels.
    pub size: usize,
    /// Number of pixel lines shared by two neighbouring patches (at least; the last patch along
    /// an axis may overlap more because it is clamped inside the image).
    pub overlap: usize,
    /// Height H of the image the layout covers.
    pub height: usize,
    /// Width W of the image the layout covers.
    pub width: usize,
    /// Top-left (row, col) of each patch, row-major over the grid.
    pub origins: Vec<(usize, usize)>,
}

impl PatchLayout {
    /// Lays out `size × size` patches sharing `overlap` pixel lines over a `height × width`
    /// image.
    ///
    /// Along each axis the starts are 0, stride, 2·stride, … with stride = size − overlap, and
    /// the last start is clamped to `len − size` so that the patches cover the whole image while
    /// each lies fully inside it. When `len < size` there is a single start 0 and the patch
    /// reaches past the image; [`split_patches`] pads it with zeros and mask `false`.
    ///
    /// # Panics
    /// If `size <= overlap` (the stride would not advance) — a programming error.
    pub fn new(height: usize, width: usize, size: usize, overlap: usize) -> PatchLayout {
        assert!(
            size > overlap,
            "PatchLayout: patch size ({size}) must exceed the overlap ({overlap})"
        );
        let stride = size - overlap;
        let rows = axis_starts(height, size, stride);
        let cols = axis_starts(width, size, stride);
        let origins = rows
            .iter()
            .flat_map(|&r| cols.iter().map(move |&c| (r, c)))
            .collect();
        PatchLayout {
            size,
            overlap,
            height,
            width,
            origins,
        }
    }

    /// Number of patches N.
    pub fn num_patches(&self) -> usize {
        self.origins.len()
    }

    /// The part of patch `origin` that lies inside the image, as (rows, cols) extents.
    fn extent(&self, origin: (usize, usize)) -> (usize, usize) {
        let (r0, c0) = origin;
        (
            self.size.min(self.height.saturating_sub(r0)),
            self.size.min(self.width.saturating_sub(c0)),
        )
    }
}

/// Patch starts along one axis of length `len`: multiples of `stride`, the last one clamped so
/// the patch ends at the border (or 0 when the axis is shorter than a patch).
fn axis_starts(len: usize, size: usize, stride: usize) -> Vec<usize> {
    let mut starts = Vec::new();
    let mut s = 0;
    loop {
        if s + size >= len {
            starts.push(len.saturating_sub(size));
            return starts;
        }
        starts.push(s);
        s += stride;
    }
}

/// Cuts `image` (C, H, W) and its `mask` (H, W) into the patches of `layout`.
///
/// Returns (N, C, P, P) patches and (N, P, P) masks, in the order of `layout.origins`. Pixels
/// are copied as they are (a pure crop); parts of a patch outside the image are zero with mask
/// `false`.
///
/// # Panics
/// If the image or mask shape does not match the layout — a programming error.
pub fn split_patches(
    image: &Array3<f32>,
    mask: &Array2<bool>,
    layout: &PatchLayout,
) -> (Array4<f32>, Array3<bool>) {
    let (channels, height, width) = image.dim();
    assert_eq!(
        (height, width),
        (layout.height, layout.width),
        "split_patches: image is {height}×{width} but the layout is for {}×{}",
        layout.height,
        layout.width
    );
    assert_eq!(
        mask.dim(),
        (height, width),
        "split_patches: mask shape differs from the image's"
    );
    let p = layout.size;
    let n = layout.num_patches();
    let mut patches = Array4::<f32>::zeros((n, channels, p, p));
    let mut masks = Array3::<bool>::from_elem((n, p, p), false);
    for (k, &(r0, c0)) in layout.origins.iter().enumerate() {
        let (hr, wc) = layout.extent((r0, c0));
        patches
            .slice_mut(s![k, .., ..hr, ..wc])
            .assign(&image.slice(s![.., r0..r0 + hr, c0..c0 + wc]));
        masks
            .slice_mut(s![k, ..hr, ..wc])
            .assign(&mask.slice(s![r0..r0 + hr, c0..c0 + wc]));
    }
    (patches, masks)
}

/// Reassembles (N, C, P, P) `patches` laid out by `layout` into a (C, H, W) image, following
/// the paper: average where patches overlap, then Laplacian-smooth every overlap band with
/// weight `sigma` ([`DEFAULT_SIGMA`] = 0.5 in the paper; 0 gives plain averaging).
///
/// Only pixels where `mask` is `true` serve as smoothing neighbours; where a needed neighbour is
/// masked out (or outside the image) that direction's smoothing is skipped and x̂ is kept.
/// Pixels outside the mask come out 0. See the module documentation for the choices made.
///
/// # Panics
/// If the shapes of `patches`, `layout` and `mask` disagree, or `sigma` is not in [0, 1] — a
/// programming error.
pub fn blend_patches(
    patches: &Array4<f32>,
    layout: &PatchLayout,
    mask: &Array2<bool>,
    sigma: f32,
) -> Array3<f32> {
    let (n, channels, ph, pw) = patches.dim();
    let (height, width) = (layout.height, layout.width);
    assert_eq!(
        (n, ph, pw),
        (layout.num_patches(), layout.size, layout.size),
        "blend_patches: patches shape does not match the layout"
    );
    assert_eq!(
        mask.dim(),
        (height, width),
        "blend_patches: mask shape does not match the layout"
    );
    assert!(
        (0.0..=1.0).contains(&sigma),
        "blend_patches: sigma ({sigma}) must lie in [0, 1]"
    );

    // Average of all patches covering each pixel (the paper's x̂), plus, per pixel, the range of
    // row and column origins of the covering patches: a pixel lies in a horizontal overlap band
    // exactly when vertically neighbouring patches (different row origins) both cover it, and
    // likewise for vertical bands. Deriving bands this way needs no grid bookkeeping.
    let mut sum = Array3::<f32>::zeros((channels, height, width));
    let mut count = Array2::<u32>::zeros((height, width));
    let mut row_lo = Array2::<usize>::from_elem((height, width), usize::MAX);
    let mut row_hi = Array2::<usize>::zeros((height, width));
    let mut col_lo = Array2::<usize>::from_elem((height, width), usize::MAX);
    let mut col_hi = Array2::<usize>::zeros((height, width));
    for (k, &(r0, c0)) in layout.origins.iter().enumerate() {
        let (hr, wc) = layout.extent((r0, c0));
        let mut target = sum.slice_mut(s![.., r0..r0 + hr, c0..c0 + wc]);
        target += &patches.slice(s![k, .., ..hr, ..wc]);
        count
            .slice_mut(s![r0..r0 + hr, c0..c0 + wc])
            .mapv_inplace(|c| c + 1);
        for i in r0..r0 + hr {
            for j in c0..c0 + wc {
                row_lo[(i, j)] = row_lo[(i, j)].min(r0);
                row_hi[(i, j)] = row_hi[(i, j)].max(r0);
                col_lo[(i, j)] = col_lo[(i, j)].min(c0);
                col_hi[(i, j)] = col_hi[(i, j)].max(c0);
            }
        }
    }
    let mut avg = sum;
    for ((_, i, j), v) in avg.indexed_iter_mut() {
        let k = count[(i, j)];
        // Uncovered pixels only occur with a hand-edited layout; they stay 0 like masked ones.
        *v = if k > 0 && mask[(i, j)] {
            *v / k as f32
        } else {
            0.0
        };
    }

    let mut out = avg.clone();
    if sigma == 0.0 {
        return out;
    }
    let half_sigma = 0.5 * sigma;
    for i in 0..height {
        for j in 0..width {
            if !mask[(i, j)] || count[(i, j)] == 0 {
                continue;
            }
            // Smoothing across a horizontal band runs along the rows (neighbours i ± 1).
            let across_rows = row_lo[(i, j)] != row_hi[(i, j)]
                && i > 0
                && i + 1 < height
                && mask[(i - 1, j)]
                && mask[(i + 1, j)];
            let across_cols = col_lo[(i, j)] != col_hi[(i, j)]
                && j > 0
                && j + 1 < width
                && mask[(i, j - 1)]
                && mask[(i, j + 1)];
            if !across_rows && !across_cols {
                continue;
            }
            for c in 0..channels {
                let centre = avg[(c, i, j)];
                let mut lap = 0.0;
                if across_rows {
                    lap += avg[(c, i - 1, j)] + avg[(c, i + 1, j)] - 2.0 * centre;
                }
                if across_cols {
                    lap += avg[(c, i, j - 1)] + avg[(c, i, j + 1)] - 2.0 * centre;
                }
                // σ·(x̂_a + x̂_c)/2 + (1 − σ)·x̂_b  ==  x̂_b + σ/2·(x̂_a + x̂_c − 2x̂_b).
                out[(c, i, j)] = centre + half_sigma * lap;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Max |a − b| over masked pixels divided by max |b| there.
    fn rel_err(a: &Array3<f32>, b: &Array3<f32>, mask: &Array2<bool>) -> f32 {
        let mut num = 0.0f32;
        let mut den = 0.0f32;
        for ((c, i, j), &v) in b.indexed_iter() {
            if mask[(i, j)] {
                num = num.max((a[(c, i, j)] - v).abs());
                den = den.max(v.abs());
            }
        }
        num / den.max(f32::MIN_POSITIVE)
    }

    fn in_band(layout: &PatchLayout) -> (Array2<bool>, Array2<bool>) {
        // (horizontal-band, vertical-band) membership recomputed from the grid starts.
        let mut rows: Vec<usize> = layout.origins.iter().map(|o| o.0).collect();
        let mut cols: Vec<usize> = layout.origins.iter().map(|o| o.1).collect();
        rows.sort_unstable();
        rows.dedup();
        cols.sort_unstable();
        cols.dedup();
        let cover = |starts: &[usize], x: usize| {
            starts
                .iter()
                .filter(|&&s| s <= x && x < s + layout.size)
                .count()
        };
        let (h, w) = (layout.height, layout.width);
        let hb = Array2::from_shape_fn((h, w), |(i, _)| cover(&rows, i) >= 2);
        let vb = Array2::from_shape_fn((h, w), |(_, j)| cover(&cols, j) >= 2);
        (hb, vb)
    }

    #[test]
    fn layout_covers_every_pixel_and_stays_inside() {
        for &(h, w, p, o) in &[
            (70, 53, 16, 2),
            (58, 30, 16, 2),
            (16, 17, 16, 2),
            (64, 64, 8, 3),
        ] {
            let layout = PatchLayout::new(h, w, p, o);
            let mut cover = Array2::<u32>::zeros((h, w));
            for &(r, c) in &layout.origins {
                assert!(r + p <= h && c + p <= w, "patch ({r},{c}) leaves {h}×{w}");
                cover
                    .slice_mut(s![r..r + p, c..c + p])
                    .mapv_inplace(|k| k + 1);
            }
            assert!(cover.iter().all(|&k| k >= 1), "uncovered pixel in {h}×{w}");
            // Neighbouring starts overlap by at least `o` lines (stride never exceeds P − o).
            let mut rows: Vec<usize> = layout.origins.iter().map(|x| x.0).collect();
            rows.sort_unstable();
            rows.dedup();
            for pair in rows.windows(2) {
                assert!(pair[1] - pair[0] <= p - o && pair[1] > pair[0]);
            }
        }
        let layout = PatchLayout::new(70, 53, 16, 2);
        // Rows 0,14,28,42,54 and columns 0,14,28,37.
        assert_eq!(layout.num_patches(), 5 * 4);
        assert_eq!(layout.origins[4], (14, 0));
        assert_eq!(layout.origins.last(), Some(&(54, 37)));
    }

    #[test]
    #[should_panic(expected = "must exceed the overlap")]
    fn layout_rejects_overlap_not_below_size() {
        let _ = PatchLayout::new(10, 10, 4, 4);
    }

    #[test]
    fn image_smaller_than_a_patch_is_padded() {
        let (h, w) = (5, 7);
        let layout = PatchLayout::new(h, w, 16, DEFAULT_OVERLAP);
        assert_eq!(layout.origins, vec![(0, 0)]);
        let image =
            Array3::from_shape_fn((3, h, w), |(c, i, j)| 1.0 + (c * 100 + i * 10 + j) as f32);
        let mask = Array2::from_elem((h, w), true);
        let (patches, masks) = split_patches(&image, &mask, &layout);
        assert_eq!(patches.dim(), (1, 3, 16, 16));
        assert_eq!(masks.dim(), (1, 16, 16));
        assert_eq!(patches.slice(s![0, .., ..h, ..w]), image);
        assert!(patches.slice(s![0, .., h.., ..]).iter().all(|&v| v == 0.0));
        assert!(patches.slice(s![0, .., .., w..]).iter().all(|&v| v == 0.0));
        assert_eq!(masks.iter().filter(|&&m| m).count(), h * w);
        let back = blend_patches(&patches, &layout, &mask, DEFAULT_SIGMA);
        assert_eq!(back, image);
    }

    #[test]
    fn linear_image_round_trips() {
        let (h, w) = (70, 53);
        let coef = [
            (0.5f32, 0.3f32, -0.2f32),
            (-2.0, 0.01, 0.7),
            (10.0, -0.4, -0.05),
        ];
        let image = Array3::from_shape_fn((3, h, w), |(c, i, j)| {
            let (a, b, d) = coef[c];
            a + b * i as f32 + d * j as f32
        });
        let mask = Array2::from_elem((h, w), true);
        let layout = PatchLayout::new(h, w, 16, DEFAULT_OVERLAP);
        let (patches, _) = split_patches(&image, &mask, &layout);
        let back = blend_patches(&patches, &layout, &mask, DEFAULT_SIGMA);
        let err = rel_err(&back, &image, &mask);
        assert!(err < 1e-6, "relative error {err}");
    }

    #[test]
    fn smooth_image_changes_only_by_the_smoothing_term() {
        let (h, w) = (70, 53);
        let (ka, kb) = (
            2.0 * std::f32::consts::PI / 40.0,
            2.0 * std::f32::consts::PI / 37.0,
        );
        let f = |i: usize, j: usize| (ka * i as f32).sin() + 0.5 * (kb * j as f32 + 0.3).cos();
        let image = Array3::from_shape_fn((1, h, w), |(_, i, j)| f(i, j));
        let mask = Array2::from_elem((h, w), true);
        let layout = PatchLayout::new(h, w, 16, DEFAULT_OVERLAP);
        let (patches, _) = split_patches(&image, &mask, &layout);
        let sigma = DEFAULT_SIGMA;
        let back = blend_patches(&patches, &layout, &mask, sigma);
        let (hb, vb) = in_band(&layout);
        // A second difference of f is bounded by max|f''| (pixel spacing 1), so smoothing moves a
        // pixel by at most σ/2·(max|f_ii| + max|f_jj|).
        let bound = 0.5 * sigma * (ka * ka + 0.5 * kb * kb);
        let mut max_band_err = 0.0f32;
        for i in 0..h {
            for j in 0..w {
                let err = (back[(0, i, j)] - f(i, j)).abs();
                let rows = hb[(i, j)] && i > 0 && i + 1 < h;
                let cols = vb[(i, j)] && j > 0 && j + 1 < w;
                if !rows && !cols {
                    assert!(
                        err < 1e-6 * 1.5,
                        "averaged-only pixel ({i},{j}) off by {err}"
                    );
                    continue;
                }
                assert!(
                    err <= bound + 1e-6,
                    "band pixel ({i},{j}) off by {err} > {bound}"
                );
                // And the change is exactly the Laplacian term.
                let mut lap = 0.0;
                if rows {
                    lap += f(i - 1, j) + f(i + 1, j) - 2.0 * f(i, j);
                }
                if cols {
                    lap += f(i, j - 1) + f(i, j + 1) - 2.0 * f(i, j);
                }
                let expected = f(i, j) + 0.5 * sigma * lap;
                assert!((back[(0, i, j)] - expected).abs() < 2e-6);
                max_band_err = max_band_err.max(err);
            }
        }
        assert!(
            max_band_err > 0.1 * bound,
            "smoothing did not act: {max_band_err}"
        );
    }

    #[test]
    fn two_patch_seam_matches_paper_formula() {
        // 1×30 image, P = 16: patches at columns 0 and 14 share columns 14 (b) and 15 (c).
        let layout = PatchLayout::new(1, 30, 16, DEFAULT_OVERLAP);
        assert_eq!(layout.origins, vec![(0, 0), (0, 14)]);
        let (left, right) = (1.0f32, 3.0f32);
        let mut patches = Array4::<f32>::zeros((2, 1, 16, 16));
        patches.slice_mut(s![0, .., .., ..]).fill(left);
        patches.slice_mut(s![1, .., .., ..]).fill(right);
        let mask = Array2::from_elem((1, 30), true);
        let out = blend_patches(&patches, &layout, &mask, 0.5);
        let d = right - left;
        // x̃_b = (x_a + x̂_c)/2 = L + D/4, x_b = ½x̃_b + ½x̂_b = L + 3D/8; symmetric for c.
        assert!((out[(0, 0, 13)] - left).abs() < 1e-6);
        assert!((out[(0, 0, 14)] - (left + 3.0 * d / 8.0)).abs() < 1e-6);
        assert!((out[(0, 0, 15)] - (right - 3.0 * d / 8.0)).abs() < 1e-6);
        assert!((out[(0, 0, 16)] - right).abs() < 1e-6);
        // A masked-out neighbour disables smoothing: column 14 keeps the plain average.
        let mut mask = mask;
        mask[(0, 13)] = false;
        let out = blend_patches(&patches, &layout, &mask, 0.5);
        assert_eq!(out[(0, 0, 13)], 0.0);
        assert!((out[(0, 0, 14)] - (left + right) / 2.0).abs() < 1e-6);
    }

    #[test]
    fn independent_patch_offsets_blend_continuously() {
        let (h, w) = (70, 53);
        let layout = PatchLayout::new(h, w, 16, DEFAULT_OVERLAP);
        let image = Array3::from_shape_fn((1, h, w), |(_, i, j)| 0.01 * i as f32 - 0.02 * j as f32);
        let mask = Array2::from_elem((h, w), true);
        let (mut patches, _) = split_patches(&image, &mask, &layout);
        // Deterministic pseudo-random offset per patch in [-1, 1].
        let offsets: Vec<f32> = (0..layout.num_patches())
            .map(|k| ((k as f32 * 12.9898).sin() * 43758.547).fract())
            .collect();
        for (k, &o) in offsets.iter().enumerate() {
            patches.slice_mut(s![k, .., .., ..]).mapv_inplace(|v| v + o);
        }
        // Largest offset difference between grid neighbours (the raw jump at a seam).
        let mut raw_jump = 0.0f32;
        for (a, &oa) in layout.origins.iter().zip(&offsets) {
            for (b, &ob) in layout.origins.iter().zip(&offsets) {
                let stride = layout.size - layout.overlap;
                let neighbours = (a.0 == b.0 && a.1 < b.1 && b.1 - a.1 <= stride)
                    || (a.1 == b.1 && a.0 < b.0 && b.0 - a.0 <= stride);
                if neighbours {
                    raw_jump = raw_jump.max((oa - ob).abs());
                }
            }
        }
        assert!(raw_jump > 0.5);
        // Largest step between adjacent pixels after removing the smooth underlying image.
        let max_step = |out: &Array3<f32>| {
            let r = out - &image;
            let mut m = 0.0f32;
            for i in 0..h {
                for j in 0..w {
                    if i + 1 < h {
                        m = m.max((r[(0, i + 1, j)] - r[(0, i, j)]).abs());
                    }
                    if j + 1 < w {
                        m = m.max((r[(0, i, j + 1)] - r[(0, i, j)]).abs());
                    }
                }
            }
            m
        };
        let averaged = max_step(&blend_patches(&patches, &layout, &mask, 0.0));
        let smoothed = max_step(&blend_patches(&patches, &layout, &mask, DEFAULT_SIGMA));
        assert!(
            averaged <= 0.5 * raw_jump + 1e-5,
            "{averaged} vs {raw_jump}"
        );
        assert!(
            smoothed <= 0.5 * raw_jump + 1e-5,
            "{smoothed} vs {raw_jump}"
        );
        assert!(smoothed < raw_jump);
        // Smoothing spreads the seam further than averaging alone.
        assert!(smoothed < averaged, "{smoothed} vs {averaged}");
    }

    #[test]
    fn masked_out_pixels_are_zero() {
        let (h, w) = (30, 30);
        let image = Array3::from_elem((3, h, w), 2.0f32);
        // A diagonal strip: band pixels meet masked-out neighbours on both sides of every band
        // (e.g. (14, 6) has (13, 6) masked out, (15, 24) has (16, 24)), which must then keep x̂.
        let mask = Array2::from_shape_fn((h, w), |(i, j)| (20..40).contains(&(i + j)));
        let layout = PatchLayout::new(h, w, 16, DEFAULT_OVERLAP);
        let (patches, masks) = split_patches(&image, &mask, &layout);
        assert_eq!(masks.iter().filter(|&&m| m).count(), {
            let mut n = 0;
            for &(r, c) in &layout.origins {
                n += mask
                    .slice(s![r..r + 16, c..c + 16])
                    .iter()
                    .filter(|&&m| m)
                    .count();
            }
            n
        });
        let out = blend_patches(&patches, &layout, &mask, DEFAULT_SIGMA);
        for ((_, i, j), &v) in out.indexed_iter() {
            let expected = if mask[(i, j)] { 2.0 } else { 0.0 };
            assert!((v - expected).abs() < 1e-6, "({i},{j}) = {v}");
        }
    }
}
