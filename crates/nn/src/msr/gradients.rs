//! Finite-difference deformation gradients and Hessians of a coordinate map (the paper's
//! §3.2.1, "Coordinate map"), and the gradient-consistency loss L_cons of §3.2.2.
//!
//! A coordinate map stores 3D positions p on a regular grid in material space, so central
//! differences of neighbouring pixels give the deformation gradient (in-plane stretch and
//! shear) and second differences the Hessian (out-of-plane curvature, i.e. wrinkles). The ISR
//! loss compares these gradients between prediction and ground truth so that the network is
//! penalised for wrong wrinkle shape, not only for wrong positions.
//!
//! The formulas are the paper's, verbatim, with p_{i,j} the pixel in row i, column j:
//!
//! - g^u_{i,j} = (p_{i+1,j} − p_{i−1,j})/h,  g^v_{i,j} = (p_{i,j+1} − p_{i,j−1})/h;
//! - H^{uu} = (g^u_{i+1,j} − g^u_{i−1,j})/h,  H^{uv} = (g^u_{i,j+1} − g^u_{i,j−1})/h,
//!   H^{vu} = (g^v_{i+1,j} − g^v_{i−1,j})/h,  H^{vv} = (g^v_{i,j+1} − g^v_{i,j−1})/h;
//!
//! with h twice the pixel size (a central difference spans two pixels). Note that the paper's
//! superscript u therefore differentiates along the *row index* i (down the image), and v along
//! the column index j; the labels are kept as printed so the code can be checked against the
//! paper. The loss uses both directions symmetrically, so the naming does not affect it.
//!
//! Validity: a value is only meaningful where every pixel it reads lies on the pattern, so each
//! result carries a `valid` mask and is zero elsewhere. Gradients additionally require the centre
//! pixel to be on the pattern: the gradient is attributed to that pixel, and a pixel off the
//! pattern has no material point to attach it to.

use ndarray::{Array2, Array3, Zip};

/// Finite-difference deformation gradients of a (C, H, W) coordinate map.
#[derive(Debug, Clone, PartialEq)]
pub struct MapGradients {
    /// g^u: central difference along the row index i, (C, H, W); zero where not `valid`.
    pub gu: Array3<f32>,
    /// g^v: central difference along the column index j, (C, H, W); zero where not `valid`.
    pub gv: Array3<f32>,
    /// (H, W): `true` where the pixel and its four neighbours are on the pattern.
    pub valid: Array2<bool>,
}

/// Finite-difference Hessians of a coordinate map, from its [`MapGradients`].
#[derive(Debug, Clone, PartialEq)]
pub struct MapHessians {
    /// H^{uu}: g^u differenced along the row index, (C, H, W).
    pub uu: Array3<f32>,
    /// H^{uv}: g^u differenced along the column index, (C, H, W).
    pub uv: Array3<f32>,
    /// H^{vu}: g^v differenced along the row index, (C, H, W).
    pub vu: Array3<f32>,
    /// H^{vv}: g^v differenced along the column index, (C, H, W).
    pub vv: Array3<f32>,
    /// (H, W): `true` where the gradients at the pixel and its four neighbours are valid.
    pub valid: Array2<bool>,
}

/// `valid[i,j] && valid` at the four neighbours (i±1, j), (i, j±1); false on the border.
fn cross_valid(valid: &Array2<bool>) -> Array2<bool> {
    let (h, w) = valid.dim();
    Array2::from_shape_fn((h, w), |(i, j)| {
        i > 0
            && j > 0
            && i + 1 < h
            && j + 1 < w
            && valid[(i, j)]
            && valid[(i - 1, j)]
            && valid[(i + 1, j)]
            && valid[(i, j - 1)]
            && valid[(i, j + 1)]
    })
}

/// Central differences of `f` along rows and columns, divided by `h`, where `valid` holds.
fn central_differences(
    f: &Array3<f32>,
    valid: &Array2<bool>,
    h: f32,
) -> (Array3<f32>, Array3<f32>) {
    let dim = f.dim();
    let along_rows = Array3::from_shape_fn(dim, |(c, i, j)| {
        if valid[(i, j)] {
            (f[(c, i + 1, j)] - f[(c, i - 1, j)]) / h
        } else {
            0.0
        }
    });
    let along_cols = Array3::from_shape_fn(dim, |(c, i, j)| {
        if valid[(i, j)] {
            (f[(c, i, j + 1)] - f[(c, i, j - 1)]) / h
        } else {
            0.0
        }
    });
    (along_rows, along_cols)
}

fn step(pixel_m: f32) -> f32 {
    assert!(
        pixel_m.is_finite() && pixel_m > 0.0,
        "pixel size must be positive and finite, got {pixel_m}"
    );
    2.0 * pixel_m
}

/// Deformation gradients g^u, g^v of a (C, H, W) `map` with pattern `mask` (H, W) and pixel
/// size `pixel_m` (metres, or whatever unit the gradients should be per), h = 2·`pixel_m`.
///
/// # Panics
/// If `mask` does not match the map's (H, W) or `pixel_m` is not positive — programming errors.
pub fn gradients(map: &Array3<f32>, mask: &Array2<bool>, pixel_m: f32) -> MapGradients {
    let (_, height, width) = map.dim();
    assert_eq!(
        mask.dim(),
        (height, width),
        "gradients: mask shape differs from the map's"
    );
    let h = step(pixel_m);
    let valid = cross_valid(mask);
    let (gu, gv) = central_differences(map, &valid, h);
    MapGradients { gu, gv, valid }
}

/// Hessians H^{uu}, H^{uv}, H^{vu}, H^{vv} from gradients `g` computed with the same
/// `pixel_m` (h = 2·`pixel_m` again, as in the paper).
///
/// # Panics
/// If `g.gu` and `g.gv` disagree in shape or `pixel_m` is not positive — programming errors.
pub fn hessians(g: &MapGradients, pixel_m: f32) -> MapHessians {
    assert_eq!(
        g.gu.dim(),
        g.gv.dim(),
        "hessians: g^u and g^v shapes differ"
    );
    let (_, height, width) = g.gu.dim();
    assert_eq!(
        g.valid.dim(),
        (height, width),
        "hessians: valid mask shape differs from the gradients'"
    );
    let h = step(pixel_m);
    let valid = cross_valid(&g.valid);
    let (uu, uv) = central_differences(&g.gu, &valid, h);
    let (vu, vv) = central_differences(&g.gv, &valid, h);
    MapHessians {
        uu,
        uv,
        vu,
        vv,
        valid,
    }
}

/// The gradient-consistency term L_cons of §3.2.2 (without its weight β): the mean of
/// |g_a − g_b| over every valid pixel, channel and both directions u and v, i.e. the L1 loss
/// of the stacked (2, C, H, W) gradient tensors restricted to valid pixels. Both maps share
/// `mask`. Returns 0 when no pixel is valid.
///
/// # Panics
/// If the maps' shapes differ, or as [`gradients`].
pub fn gradient_l1(a: &Array3<f32>, b: &Array3<f32>, mask: &Array2<bool>, pixel_m: f32) -> f32 {
    assert_eq!(a.dim(), b.dim(), "gradient_l1: map shapes differ");
    let ga = gradients(a, mask, pixel_m);
    let gb = gradients(b, mask, pixel_m);
    let n_valid = ga.valid.iter().filter(|&&v| v).count();
    if n_valid == 0 {
        return 0.0;
    }
    // Invalid pixels are zero in both, so summing everything adds only valid differences.
    // Accumulate in f64: large maps have millions of terms.
    let mut total = 0.0f64;
    Zip::from(&ga.gu)
        .and(&gb.gu)
        .and(&ga.gv)
        .and(&gb.gv)
        .for_each(|&au, &bu, &av, &bv| {
            total += f64::from((au - bu).abs()) + f64::from((av - bv).abs());
        });
    let channels = a.dim().0;
    (total / (2 * channels * n_valid) as f64) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all_true(h: usize, w: usize) -> Array2<bool> {
        Array2::from_elem((h, w), true)
    }

    #[test]
    fn linear_map_has_exact_constant_gradient_and_zero_hessian() {
        let (h, w, px) = (12, 9, 0.0025f32);
        // p_c = a_c + b_c·(i·px) + d_c·(j·px): ∂/∂(row) = b, ∂/∂(col) = d.
        let coef = [
            (0.1f32, 1.0f32, 0.0f32),
            (-0.3, 0.2, 0.9),
            (0.7, -0.5, 0.25),
        ];
        let map = Array3::from_shape_fn((3, h, w), |(c, i, j)| {
            let (a, b, d) = coef[c];
            a + b * i as f32 * px + d * j as f32 * px
        });
        let g = gradients(&map, &all_true(h, w), px);
        for i in 0..h {
            for j in 0..w {
                let interior = i > 0 && j > 0 && i + 1 < h && j + 1 < w;
                assert_eq!(g.valid[(i, j)], interior);
                for (c, &(_, b, d)) in coef.iter().enumerate() {
                    let (eu, ev) = if interior { (b, d) } else { (0.0, 0.0) };
                    assert!((g.gu[(c, i, j)] - eu).abs() < 1e-3, "gu {c} {i} {j}");
                    assert!((g.gv[(c, i, j)] - ev).abs() < 1e-3, "gv {c} {i} {j}");
                }
            }
        }
        let hs = hessians(&g, px);
        // Hessians need the gradients' neighbours too: two pixels in from every border.
        assert!(hs.valid[(2, 2)]);
        assert!(!hs.valid[(1, 4)]);
        for m in [&hs.uu, &hs.uv, &hs.vu, &hs.vv] {
            // Only f32 rounding remains: ~1e-7 in p over h² = 25 mm² is ~1e-2 (a 1 cm wrinkle
            // has curvatures of order 100 /m, so this is zero for every practical purpose).
            let max = m.iter().fold(0f32, |a, v| a.max(v.abs()));
            assert!(max < 0.05, "max |H| = {max}");
        }
    }

    #[test]
    fn quadratic_map_has_exact_hessian() {
        let (h, w, px) = (15, 13, 0.1f32);
        // p = A s² + B s t + C t² + D s + E t with s = i·px (rows), t = j·px (cols):
        // H^uu = 2A, H^uv = H^vu = B, H^vv = 2C, exactly, for central differences.
        let (a, b, c2, d, e) = (0.7f32, -1.3f32, 0.4f32, 0.2f32, -0.6f32);
        let map = Array3::from_shape_fn((1, h, w), |(_, i, j)| {
            let (s, t) = (i as f32 * px, j as f32 * px);
            a * s * s + b * s * t + c2 * t * t + d * s + e * t
        });
        let g = gradients(&map, &all_true(h, w), px);
        // Gradients are exact too: g^u = 2As + Bt + D.
        let (s, t) = (5.0 * px, 7.0 * px);
        assert!((g.gu[(0, 5, 7)] - (2.0 * a * s + b * t + d)).abs() < 1e-4);
        assert!((g.gv[(0, 5, 7)] - (b * s + 2.0 * c2 * t + e)).abs() < 1e-4);
        let hs = hessians(&g, px);
        let mut checked = 0;
        for i in 0..h {
            for j in 0..w {
                let interior = i >= 2 && j >= 2 && i + 2 < h && j + 2 < w;
                assert_eq!(hs.valid[(i, j)], interior);
                if !interior {
                    assert_eq!(hs.uu[(0, i, j)], 0.0);
                    continue;
                }
                assert!(
                    (hs.uu[(0, i, j)] - 2.0 * a).abs() < 1e-3,
                    "uu {}",
                    hs.uu[(0, i, j)]
                );
                assert!(
                    (hs.uv[(0, i, j)] - b).abs() < 1e-3,
                    "uv {}",
                    hs.uv[(0, i, j)]
                );
                assert!(
                    (hs.vu[(0, i, j)] - b).abs() < 1e-3,
                    "vu {}",
                    hs.vu[(0, i, j)]
                );
                assert!(
                    (hs.vv[(0, i, j)] - 2.0 * c2).abs() < 1e-3,
                    "vv {}",
                    hs.vv[(0, i, j)]
                );
                checked += 1;
            }
        }
        assert_eq!(checked, (h - 4) * (w - 4));
    }

    #[test]
    fn masked_out_pixel_invalidates_its_neighbours() {
        let (h, w) = (8, 8);
        let map = Array3::from_shape_fn((3, h, w), |(c, i, j)| (c + i * j) as f32);
        let mut mask = all_true(h, w);
        mask[(4, 4)] = false;
        let g = gradients(&map, &mask, 1.0);
        for (i, j) in [(4, 4), (3, 4), (5, 4), (4, 3), (4, 5)] {
            assert!(!g.valid[(i, j)], "({i},{j}) should be invalid");
            assert!(g.gu.slice(ndarray::s![.., i, j]).iter().all(|&v| v == 0.0));
            assert!(g.gv.slice(ndarray::s![.., i, j]).iter().all(|&v| v == 0.0));
        }
        // Diagonal neighbours do not read (4, 4) and stay valid.
        assert!(g.valid[(3, 3)] && g.valid[(5, 5)]);
        assert_eq!(g.gu[(1, 3, 3)], (4.0 * 3.0 - 2.0 * 3.0) / 2.0);
        let hs = hessians(&g, 1.0);
        // (3, 3) is valid itself but its gradient neighbours (3, 4) and (4, 3) are not.
        assert!(!hs.valid[(3, 3)]);
        assert!(hs.valid[(2, 2)]);
    }

    #[test]
    fn gradient_l1_of_identical_maps_is_zero_and_of_a_ramp_is_its_slope() {
        let (h, w, px) = (20, 17, 0.0025f32);
        let a = Array3::from_shape_fn((3, h, w), |(c, i, j)| {
            ((c as f32 + 1.0) * 0.3 * i as f32).sin() * 0.01 + 0.002 * (j * j) as f32 * px
        });
        let mut mask = all_true(h, w);
        mask[(10, 3)] = false;
        assert_eq!(gradient_l1(&a, &a, &mask, px), 0.0);

        // A ramp of slope k along both axes shifts every |Δg^u| and |Δg^v| by exactly k.
        let k = 0.8f32;
        let both = Array3::from_shape_fn((3, h, w), |(c, i, j)| {
            a[(c, i, j)] + k * (i as f32 + j as f32) * px
        });
        let l = gradient_l1(&a, &both, &mask, px);
        assert!((l - k).abs() < 1e-3 * k, "{l} vs {k}");

        // A ramp along the rows only changes g^u: half of the averaged terms are zero.
        let rows = Array3::from_shape_fn((3, h, w), |(c, i, j)| a[(c, i, j)] + k * i as f32 * px);
        let l = gradient_l1(&a, &rows, &mask, px);
        assert!((l - 0.5 * k).abs() < 1e-3 * k, "{l} vs {}", 0.5 * k);

        // No valid pixel: the loss is defined as 0 rather than NaN.
        let none = Array2::from_elem((h, w), false);
        assert_eq!(gradient_l1(&a, &both, &none, px), 0.0);
    }
}
