//! Moving cloth states between the coarse and fine meshes of one garment (the paper's §3.3.1).
//!
//! Both meshes come from the same sewing pattern, so every vertex has a material coordinate in
//! its panel's plane, shared by the two resolutions. Each coarse vertex is embedded in the fine
//! triangle of the same panel that contains its material coordinate (barycentric weights), and
//! each fine vertex in a coarse triangle likewise:
//!
//! * **downsample** a fine state (positions or velocities) to the coarse mesh: M_int, the
//!   corrector's target;
//! * **upsample** a coarse state to the fine mesh: the no-learning baseline that every
//!   evaluation compares against.
//!
//! Curved panel edges are polylines at both resolutions, so a vertex on a curve can lie a hair
//! outside the other mesh; it then takes the nearest point of the nearest triangle of its panel.

use nalgebra::Vector3;

use crate::error::Result;
use crate::mesh::{ClothMesh, Embedding};

/// Area-weighted vertex normals of `triangles` at positions `x` (unit length; zero for a
/// vertex in no triangle).
pub fn vertex_normals(triangles: &[[u32; 3]], x: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
    let mut n = vec![Vector3::zeros(); x.len()];
    for t in triangles {
        let (a, b, c) = (x[t[0] as usize], x[t[1] as usize], x[t[2] as usize]);
        let f = (b - a).cross(&(c - a));
        for &i in t {
            n[i as usize] += f;
        }
    }
    for v in &mut n {
        let l = v.norm();
        if l > 0.0 {
            *v /= l;
        }
    }
    n
}

/// Phong tessellation (Boubekeur & Alexa 2008) of the triangle with corners `x` and vertex
/// normals `n` at barycentric weights `w`: the linear point projected onto each corner's
/// tangent plane, those projections interpolated, blended with the linear point by `alpha`
/// (0: linear). A curved surface sampled at the corners is recovered to second order, which
/// removes most of the chord error of piecewise-linear upsampling (its "sagitta").
pub fn phong_point(
    x: [Vector3<f64>; 3],
    n: [Vector3<f64>; 3],
    w: [f64; 3],
    alpha: f64,
) -> Vector3<f64> {
    let p = x[0] * w[0] + x[1] * w[1] + x[2] * w[2];
    if alpha == 0.0 {
        return p;
    }
    let q: Vector3<f64> = (0..3)
        .map(|k| (p - n[k] * (p - x[k]).dot(&n[k])) * w[k])
        .sum();
    p * (1.0 - alpha) + q * alpha
}

impl Embedding {
    /// Host positions `host_x` interpolated at the embedded vertices by Phong tessellation
    /// ([`phong_point`]) with the host's vertex normals `host_n`.
    pub fn apply_phong(
        &self,
        host_x: &[Vector3<f64>],
        host_n: &[Vector3<f64>],
        alpha: f64,
    ) -> Vec<Vector3<f64>> {
        self.verts
            .iter()
            .zip(&self.weights)
            .map(|(v, w)| {
                let g = |k: usize| v[k] as usize;
                phong_point(
                    [host_x[g(0)], host_x[g(1)], host_x[g(2)]],
                    [host_n[g(0)], host_n[g(1)], host_n[g(2)]],
                    *w,
                    alpha,
                )
            })
            .collect()
    }
}

/// Both directions between the coarse and fine meshes of one garment (or of a whole model:
/// panel names carry the part's name).
#[derive(Debug, Clone, PartialEq)]
pub struct Transfer {
    /// Coarse vertices in fine triangles: downsampling.
    pub coarse_in_fine: Embedding,
    /// Fine vertices in coarse triangles: upsampling.
    pub fine_in_coarse: Embedding,
}

impl Transfer {
    /// Embeddings between `coarse` and `fine`.
    pub fn new(coarse: &ClothMesh, fine: &ClothMesh) -> Result<Transfer> {
        Ok(Transfer {
            coarse_in_fine: Embedding::new(coarse, fine)?,
            fine_in_coarse: Embedding::new(fine, coarse)?,
        })
    }

    /// A fine state (positions or velocities) on the coarse mesh.
    pub fn downsample(&self, fine: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
        self.coarse_in_fine.apply(fine)
    }

    /// A coarse state on the fine mesh (piecewise-linear: the baseline without learning).
    pub fn upsample(&self, coarse: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
        self.fine_in_coarse.apply(coarse)
    }

    /// Coarse positions on the fine mesh by Phong tessellation of the coarse mesh
    /// (`coarse_triangles`) with blend `alpha` ([`phong_point`]).
    pub fn upsample_phong(
        &self,
        coarse: &[Vector3<f64>],
        coarse_triangles: &[[u32; 3]],
        alpha: f64,
    ) -> Vec<Vector3<f64>> {
        let n = vertex_normals(coarse_triangles, coarse);
        self.fine_in_coarse.apply_phong(coarse, &n, alpha)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phong_is_linear_on_flat_triangles_and_recovers_sphere_curvature() {
        let x = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(0.02, 0.0, 0.0),
            Vector3::new(0.0, 0.0, 0.02),
        ];
        let w = [0.2, 0.3, 0.5];
        let lin = x[0] * w[0] + x[1] * w[1] + x[2] * w[2];
        // Flat: the normals are the plane's; nothing moves, whatever alpha.
        let n = [Vector3::y(); 3];
        assert!((phong_point(x, n, w, 0.75) - lin).norm() < 1e-15);
        // Alpha 0 is linear on any triangle.
        let r = 0.07;
        let on_sphere = |d: Vector3<f64>| d.normalize() * r;
        let dirs = [
            Vector3::new(0.0, 1.0, 0.0),
            Vector3::new(0.3, 1.0, 0.0),
            Vector3::new(0.0, 1.0, 0.3),
        ];
        let xs = dirs.map(on_sphere);
        let ns = dirs.map(|d| d.normalize());
        let lin = xs[0] * w[0] + xs[1] * w[1] + xs[2] * w[2];
        assert!((phong_point(xs, ns, w, 0.0) - lin).norm() < 1e-15);
        // A sphere sampled at the corners: the chord lies inside by the sagitta; Phong
        // tessellation comes much closer to the surface.
        let lin_err = (lin.norm() - r).abs();
        let ph_err = (phong_point(xs, ns, w, 0.75).norm() - r).abs();
        assert!(lin_err > 1e-4, "{lin_err}");
        assert!(ph_err < 0.5 * lin_err, "Phong {ph_err} vs linear {lin_err}");
        // Vertex normals of a flat fan point along its normal.
        let tris = [[0u32, 2, 1]];
        let vn = vertex_normals(&tris, &x);
        assert!((vn[0] - Vector3::y()).norm() < 1e-12);
    }
    use crate::garment::Fabric;
    use crate::mesh::{mesh_garment, MeshOptions, TriLocator};
    use crate::scene::samples::flat_sheet;
    use nalgebra::Vector2;

    fn meshes(coarse_m: f64, fine_m: f64) -> (ClothMesh, ClothMesh) {
        let g = flat_sheet("s", 0.4, 0.3, Vector3::zeros(), Fabric::default());
        (
            mesh_garment(&g, &MeshOptions::with_edge(coarse_m)).expect("coarse"),
            mesh_garment(&g, &MeshOptions::with_edge(fine_m)).expect("fine"),
        )
    }

    /// A smooth bump over material space (metres): curvature radius ≳ 0.1 m.
    fn bump(m: &Vector2<f64>) -> Vector3<f64> {
        Vector3::new(
            m.x,
            0.02 * (m.x * 12.0).sin() * (m.y * 9.0).cos(),
            m.y + 0.01 * (m.x * 7.0).cos(),
        )
    }

    #[test]
    fn flat_sheet_downsamples_exactly() {
        let (c, f) = meshes(0.02, 0.0025);
        let t = Transfer::new(&c, &f).expect("transfer");
        // Positions affine in material coordinates: interpolation is exact.
        let lift = |m: &ClothMesh| -> Vec<Vector3<f64>> {
            m.material
                .iter()
                .map(|p| Vector3::new(0.3 + p.x, 1.0 - 0.5 * p.y, 0.2 * p.x + p.y))
                .collect()
        };
        let down = t.downsample(&lift(&f));
        let err = down
            .iter()
            .zip(&lift(&c))
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(err < 1e-12, "M_int of a flat sheet is off by {err:e} m");
    }

    #[test]
    fn down_then_up_on_a_smooth_surface_is_within_a_tenth_of_a_millimetre() {
        let (c, f) = meshes(0.02, 0.0025);
        let t = Transfer::new(&c, &f).expect("transfer");
        let fine: Vec<Vector3<f64>> = f.material.iter().map(bump).collect();
        let coarse_truth: Vec<Vector3<f64>> = c.material.iter().map(bump).collect();
        let down = t.downsample(&fine);
        let down_err = down
            .iter()
            .zip(&coarse_truth)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        // The fine mesh samples the surface every 2.5 mm: a coarse vertex read from it is off by
        // the fine mesh's chordal error only.
        assert!(down_err < 1e-4, "downsample error {:.4} mm", down_err * 1e3);
        // Up again: the coarse mesh is piecewise linear at 20 mm, its chordal error is ~h²κ/8.
        let up = t.upsample(&down);
        let mean = up
            .iter()
            .zip(&fine)
            .map(|(a, b)| (a - b).norm())
            .sum::<f64>()
            / fine.len() as f64;
        assert!(mean < 1e-4, "down∘up mean error {:.4} mm", mean * 1e3);
        // And the coarse mesh's own vertices come back where they were.
        let back = t.downsample(&up);
        let err = back
            .iter()
            .zip(&down)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(
            err < 1e-4,
            "down∘up∘down moves coarse vertices {:.4} mm",
            err * 1e3
        );
    }

    #[test]
    fn a_point_outside_takes_the_nearest_triangle() {
        let (c, _) = meshes(0.05, 0.05);
        let loc = TriLocator::new(&c, 0);
        let (t, b) = loc.locate(&Vector2::new(-0.01, 0.1), true).expect("found");
        assert!(b.iter().all(|&w| w >= 0.0));
        let tri = c.triangles[t as usize].map(|v| c.material[v as usize]);
        let q = tri[0] * b[0] + tri[1] * b[1] + tri[2] * b[2];
        assert!(
            (q - Vector2::new(0.0, 0.1)).norm() < 1e-9,
            "nearest point {q:?}"
        );
        let (_, e) = loc.locate(&Vector2::new(-0.01, 0.1), false).expect("found");
        assert!(e.iter().any(|&w| w < 0.0), "extrapolated weights {e:?}");
    }
}
