//! Distances between two states of one mesh: what `eval`, the corrector's rollouts and the ISR
//! network's validation measure.

use nalgebra::Vector3;

use crate::transfer::vertex_normals;

/// Mean distance between two vertex sets of the same mesh, mm.
pub fn mean_distance_mm(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
    1e3 * a.iter().zip(b).map(|(p, q)| (p - q).norm()).sum::<f64>() / a.len().max(1) as f64
}

/// Per-vertex distances between two position sets, metres.
pub fn vertex_errors(gt: &[Vector3<f64>], pred: &[Vector3<f64>]) -> Vec<f64> {
    gt.iter().zip(pred).map(|(a, b)| (a - b).norm()).collect()
}

/// Mean, max and standard deviation of `v`.
pub fn mean_max_std(v: &[f64]) -> (f64, f64, f64) {
    if v.is_empty() {
        return (0.0, 0.0, 0.0);
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let max = v.iter().copied().fold(0.0, f64::max);
    let var = v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n;
    (mean, max, var.sqrt())
}

/// Mean angle between the vertex normals of two positions of one mesh, degrees.
pub fn normal_angle_deg(triangles: &[[u32; 3]], gt: &[Vector3<f64>], pred: &[Vector3<f64>]) -> f64 {
    let (a, b) = (
        vertex_normals(triangles, gt),
        vertex_normals(triangles, pred),
    );
    let angles: Vec<f64> = a
        .iter()
        .zip(&b)
        .filter(|(p, q)| p.norm_squared() > 0.0 && q.norm_squared() > 0.0)
        .map(|(p, q)| p.normalize().dot(&q.normalize()).clamp(-1.0, 1.0).acos())
        .collect();
    if angles.is_empty() {
        return 0.0;
    }
    angles.iter().sum::<f64>() / angles.len() as f64 * 180.0 / std::f64::consts::PI
}

/// Mean ‖x_{t+1} − 2x_t + x_{t−1}‖ over vertices, metres.
pub fn jitter_m(prev: &[Vector3<f64>], cur: &[Vector3<f64>], next: &[Vector3<f64>]) -> f64 {
    let n = cur.len().max(1) as f64;
    prev.iter()
        .zip(cur)
        .zip(next)
        .map(|((a, b), c)| (c - 2.0 * b + a).norm())
        .sum::<f64>()
        / n
}

/// The hinges of a triangle mesh: each edge two triangles share, as the two triangles'
/// indices, in the order the edges first appear. Edges of one triangle (the boundary) and of
/// three or more (non-manifold) have no hinge.
pub fn hinges(triangles: &[[u32; 3]]) -> Vec<[u32; 2]> {
    let mut edges: Vec<([u32; 2], u32)> = triangles
        .iter()
        .enumerate()
        .flat_map(|(t, v)| {
            [[v[0], v[1]], [v[1], v[2]], [v[2], v[0]]]
                .map(|[a, b]| (if a < b { [a, b] } else { [b, a] }, t as u32))
        })
        .collect();
    edges.sort_unstable();
    let mut out = Vec::new();
    let mut i = 0;
    while i < edges.len() {
        let mut j = i + 1;
        while j < edges.len() && edges[j].0 == edges[i].0 {
            j += 1;
        }
        if j - i == 2 {
            out.push([edges[i].1, edges[i + 1].1]);
        }
        i = j;
    }
    out
}

/// The bend angle of each hinge (the angle between its two triangles' normals, 0 where flat,
/// degrees), sorted ascending: the distribution of a cloth's folds and wrinkles, which two
/// fine simulations from starts a fraction of a millimetre apart share even where their
/// vertices have drifted apart. Degenerate triangles' hinges are left out.
pub fn bend_angles_deg(
    triangles: &[[u32; 3]],
    hinges: &[[u32; 2]],
    x: &[Vector3<f64>],
) -> Vec<f64> {
    let normal = |t: u32| -> Option<Vector3<f64>> {
        let [a, b, c] = triangles[t as usize].map(|i| x.get(i as usize).copied());
        let n = (b? - a?).cross(&(c? - a?));
        let len = n.norm();
        (len > 0.0 && len.is_finite()).then(|| n / len)
    };
    let mut out: Vec<f64> = hinges
        .iter()
        .filter_map(|&[s, t]| {
            Some(
                normal(s)?
                    .dot(&normal(t)?)
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees(),
            )
        })
        .collect();
    out.sort_unstable_by(f64::total_cmp);
    out
}

/// The 1-Wasserstein (earth mover's) distance between two distributions given as sorted
/// samples: the mean distance between their quantiles. Its unit is the samples'.
pub fn wasserstein1_sorted(a: &[f64], b: &[f64]) -> f64 {
    if a.is_empty() || b.is_empty() {
        return 0.0;
    }
    if a.len() == b.len() {
        return a.iter().zip(b).map(|(p, q)| (p - q).abs()).sum::<f64>() / a.len() as f64;
    }
    // Quantiles at the midpoints of a fine common grid.
    let n = a.len().max(b.len());
    let q = |s: &[f64], u: f64| s[((u * s.len() as f64) as usize).min(s.len() - 1)];
    (0..n)
        .map(|k| {
            let u = (k as f64 + 0.5) / n as f64;
            (q(a, u) - q(b, u)).abs()
        })
        .sum::<f64>()
        / n as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles folded along their shared edge by a known angle, one lone triangle.
    #[test]
    fn a_known_fold_has_its_bend_angle() {
        let tris = [[0, 1, 2], [1, 0, 3], [4, 5, 6]];
        let h = hinges(&tris);
        assert_eq!(h, vec![[0, 1]]);
        for deg in [0.0_f64, 30.0, 90.0, 150.0] {
            let r = deg.to_radians();
            // Edge 0–1 along x; triangle 0 in the xy half-plane y > 0, triangle 1 turned
            // about x by 180° − deg from it.
            let x = vec![
                Vector3::new(0.0, 0.0, 0.0),
                Vector3::new(1.0, 0.0, 0.0),
                Vector3::new(0.5, 1.0, 0.0),
                Vector3::new(0.5, -r.cos(), r.sin()),
                Vector3::zeros(),
                Vector3::x(),
                Vector3::y(),
            ];
            let a = bend_angles_deg(&tris, &h, &x);
            assert_eq!(a.len(), 1);
            assert!((a[0] - deg).abs() < 1e-9, "{deg}: {}", a[0]);
        }
    }

    #[test]
    fn wasserstein_of_shifted_and_resampled_distributions() {
        let a: Vec<f64> = (0..100).map(f64::from).collect();
        let b: Vec<f64> = a.iter().map(|v| v + 2.5).collect();
        assert!((wasserstein1_sorted(&a, &b) - 2.5).abs() < 1e-12);
        assert_eq!(wasserstein1_sorted(&a, &a), 0.0);
        // The same uniform distribution sampled at other counts: about zero.
        let c: Vec<f64> = (0..400).map(|k| f64::from(k) / 4.0).collect();
        assert!(wasserstein1_sorted(&a, &c) < 0.5);
        assert!(wasserstein1_sorted(&c, &b) > 2.0);
    }
}
