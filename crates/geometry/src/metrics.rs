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
