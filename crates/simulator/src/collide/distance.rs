//! Exact closest-point distances: point–segment, point–triangle and segment–segment.
//!
//! Point–triangle follows the Voronoi-region walk of Ericson, "Real-Time Collision Detection"
//! (2005), §5.1.5: the closest point is a vertex, a point on an edge or the projection onto the
//! face, decided by signs of dot products, with barycentric coordinates read off the same
//! quantities. For a non-degenerate triangle every division is by a squared edge length or by
//! |(b−a)×(c−a)|² > 0; (nearly) degenerate triangles (|(b−a)×(c−a)|² ≤ 10⁻¹⁴·max|e|⁴) fall
//! back to the closest of the three point–segment distances.
//!
//! Segment–segment follows Ericson §5.1.9: minimise |p₀ + s(p₁−p₀) − q₀ − t(q₁−q₀)|² over
//! s, t ∈ [0, 1] by solving the 2×2 normal equations for s, clamping, recomputing t and
//! re-clamping s. Parallel segments (1 − cos²θ ≤ 10⁻¹²) take s = 0, zero-length segments are
//! points. The returned parameters are exactly 0.0 or 1.0 when clamped, so the closest features
//! can be read off them.

use nalgebra::Vector3;

/// Which feature of a triangle (a, b, c) = (0, 1, 2) holds the closest point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TriangleFeature {
    /// Vertex 0, 1 or 2.
    Vertex(usize),
    /// The edge between the two local vertices (i < j).
    Edge(usize, usize),
    /// The interior of the face.
    Face,
}

/// Closest point of a triangle to a point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointTriangle {
    /// Distance |p − q|, metres.
    pub dist: f64,
    /// Barycentric coordinates of the closest point q = Σᵢ baryᵢ·xᵢ (non-negative, sum 1).
    pub bary: [f64; 3],
    /// The feature holding q.
    pub feature: TriangleFeature,
}

/// Closest point of a segment to a point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointSegment {
    /// Distance, metres.
    pub dist: f64,
    /// Parameter of the closest point a + t(b − a), t ∈ [0, 1].
    pub t: f64,
}

/// Closest points of two segments.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentSegment {
    /// Distance, metres.
    pub dist: f64,
    /// Parameter on the first segment: p₀ + s(p₁ − p₀), s ∈ [0, 1].
    pub s: f64,
    /// Parameter on the second segment: q₀ + t(q₁ − q₀), t ∈ [0, 1].
    pub t: f64,
}

/// Distance from `p` to the segment `ab` (t = 0 for a zero-length segment).
pub fn point_segment(p: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> PointSegment {
    let ab = b - a;
    let l2 = ab.norm_squared();
    let t = if l2 > 0.0 {
        ((p - a).dot(&ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    PointSegment {
        dist: (p - (a + ab * t)).norm(),
        t,
    }
}

/// Distance from `p` to the triangle `abc` and its closest point (Ericson 2005, §5.1.5).
pub fn point_triangle(
    p: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> PointTriangle {
    let ab = b - a;
    let ac = c - a;
    let bc = c - b;
    let n2 = ab.cross(&ac).norm_squared();
    let emax = ab
        .norm_squared()
        .max(ac.norm_squared())
        .max(bc.norm_squared());
    if n2.is_nan() || n2 <= 1e-14 * emax * emax {
        return degenerate_point_triangle(p, a, b, c);
    }
    let at = |bary: [f64; 3], feature| {
        let q = a * bary[0] + b * bary[1] + c * bary[2];
        PointTriangle {
            dist: (p - q).norm(),
            bary,
            feature,
        }
    };
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return PointTriangle {
            dist: ap.norm(),
            bary: [1.0, 0.0, 0.0],
            feature: TriangleFeature::Vertex(0),
        };
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return PointTriangle {
            dist: bp.norm(),
            bary: [0.0, 1.0, 0.0],
            feature: TriangleFeature::Vertex(1),
        };
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        // d1 − d3 = |ab|² > 0.
        let v = (d1 / (d1 - d3)).clamp(0.0, 1.0);
        return at([1.0 - v, v, 0.0], TriangleFeature::Edge(0, 1));
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return PointTriangle {
            dist: cp.norm(),
            bary: [0.0, 0.0, 1.0],
            feature: TriangleFeature::Vertex(2),
        };
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        // d2 − d6 = |ac|² > 0.
        let w = (d2 / (d2 - d6)).clamp(0.0, 1.0);
        return at([1.0 - w, 0.0, w], TriangleFeature::Edge(0, 2));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        // (d4 − d3) + (d5 − d6) = |bc|² > 0.
        let w = ((d4 - d3) / ((d4 - d3) + (d5 - d6))).clamp(0.0, 1.0);
        return at([0.0, 1.0 - w, w], TriangleFeature::Edge(1, 2));
    }
    // va + vb + vc = |ab × ac|² > 0.
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    at([1.0 - v - w, v, w], TriangleFeature::Face)
}

/// Closest point of a degenerate (collinear or point-like) triangle: the best of its edges.
fn degenerate_point_triangle(
    p: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> PointTriangle {
    let x = [a, b, c];
    let mut best: Option<PointTriangle> = None;
    for (i, j) in [(0usize, 1usize), (1, 2), (0, 2)] {
        let ps = point_segment(p, x[i], x[j]);
        if best.is_none_or(|b| ps.dist < b.dist) {
            let mut bary = [0.0; 3];
            bary[i] = 1.0 - ps.t;
            bary[j] = ps.t;
            let feature = if ps.t <= 0.0 {
                TriangleFeature::Vertex(i)
            } else if ps.t >= 1.0 {
                TriangleFeature::Vertex(j)
            } else {
                TriangleFeature::Edge(i, j)
            };
            best = Some(PointTriangle {
                dist: ps.dist,
                bary,
                feature,
            });
        }
    }
    // The loop ran three times, so `best` is set; the fallback only satisfies the types.
    best.unwrap_or(PointTriangle {
        dist: (p - a).norm(),
        bary: [1.0, 0.0, 0.0],
        feature: TriangleFeature::Vertex(0),
    })
}

/// Closest points of segments p₀p₁ and q₀q₁ (Ericson 2005, §5.1.9).
pub fn segment_segment(
    p0: &Vector3<f64>,
    p1: &Vector3<f64>,
    q0: &Vector3<f64>,
    q1: &Vector3<f64>,
) -> SegmentSegment {
    let d1 = p1 - p0;
    let d2 = q1 - q0;
    let r = p0 - q0;
    let a = d1.norm_squared();
    let e = d2.norm_squared();
    let f = d2.dot(&r);
    let (s, t);
    if a <= 0.0 && e <= 0.0 {
        s = 0.0;
        t = 0.0;
    } else if a <= 0.0 {
        s = 0.0;
        t = (f / e).clamp(0.0, 1.0);
    } else {
        let c = d1.dot(&r);
        if e <= 0.0 {
            t = 0.0;
            s = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = d1.dot(&d2);
            let denom = a * e - b * b;
            let mut s0 = if denom > 1e-12 * a * e {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t0 = (b * s0 + f) / e;
            if t0 < 0.0 {
                t0 = 0.0;
                s0 = (-c / a).clamp(0.0, 1.0);
            } else if t0 > 1.0 {
                t0 = 1.0;
                s0 = ((b - c) / a).clamp(0.0, 1.0);
            }
            s = s0;
            t = t0;
        }
    }
    let dist = ((p0 + d1 * s) - (q0 + d2 * t)).norm();
    SegmentSegment { dist, s, t }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Tiny deterministic LCG.
    pub(crate) struct Lcg(pub u64);
    impl Lcg {
        /// Uniform in [0, 1).
        pub fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
        /// Uniform in [−s, s]³.
        pub fn v3(&mut self, s: f64) -> Vector3<f64> {
            Vector3::new(
                (2.0 * self.next() - 1.0) * s,
                (2.0 * self.next() - 1.0) * s,
                (2.0 * self.next() - 1.0) * s,
            )
        }
    }

    /// Brute-force min over a barycentric grid of the triangle.
    fn brute_triangle(p: &Vector3<f64>, x: [Vector3<f64>; 3], k: usize) -> f64 {
        let mut best = f64::INFINITY;
        for i in 0..=k {
            for j in 0..=k - i {
                let (u, v) = (i as f64 / k as f64, j as f64 / k as f64);
                let q = x[0] * (1.0 - u - v) + x[1] * u + x[2] * v;
                best = best.min((p - q).norm());
            }
        }
        best
    }

    fn brute_segments(x: [Vector3<f64>; 4], k: usize) -> f64 {
        let mut best = f64::INFINITY;
        for i in 0..=k {
            for j in 0..=k {
                let (s, t) = (i as f64 / k as f64, j as f64 / k as f64);
                let d = (x[0] + (x[1] - x[0]) * s) - (x[2] + (x[3] - x[2]) * t);
                best = best.min(d.norm());
            }
        }
        best
    }

    #[test]
    fn point_triangle_matches_sampling() {
        let mut rng = Lcg(1);
        let k = 200;
        let mut seen = std::collections::HashSet::new();
        for it in 0..400 {
            let x = [rng.v3(1.0), rng.v3(1.0), rng.v3(1.0)];
            let p = rng.v3(1.5);
            let r = point_triangle(&p, &x[0], &x[1], &x[2]);
            let q = x[0] * r.bary[0] + x[1] * r.bary[1] + x[2] * r.bary[2];
            assert!(((p - q).norm() - r.dist).abs() < 1e-12);
            assert!(
                r.bary.iter().all(|&b| b >= 0.0)
                    && (r.bary.iter().sum::<f64>() - 1.0).abs() < 1e-12
            );
            let brute = brute_triangle(&p, x, k);
            // The grid is at most (longest edge)/k away from any triangle point.
            let h = (x[1] - x[0])
                .norm()
                .max((x[2] - x[0]).norm())
                .max((x[2] - x[1]).norm())
                / k as f64;
            assert!(
                r.dist <= brute + 1e-12,
                "it {it}: {} > brute {}",
                r.dist,
                brute
            );
            assert!(brute <= r.dist + h, "it {it}: brute {} ≫ {}", brute, r.dist);
            // Features agree with the barycentric zeros.
            let nz = r.bary.iter().filter(|&&b| b > 0.0).count();
            match r.feature {
                TriangleFeature::Vertex(_) => assert_eq!(nz, 1),
                TriangleFeature::Edge(i, j) => assert!(nz <= 2 && r.bary[3 - i - j] == 0.0),
                TriangleFeature::Face => {}
            }
            seen.insert(format!("{:?}", r.feature));
        }
        assert_eq!(seen.len(), 7, "all regions hit: {seen:?}");
    }

    #[test]
    fn point_triangle_degenerate() {
        let a = Vector3::new(0.0, 0.0, 0.0);
        let b = Vector3::new(1.0, 0.0, 0.0);
        let c = Vector3::new(2.0, 0.0, 0.0); // collinear
        let p = Vector3::new(1.5, 1.0, 0.0);
        let r = point_triangle(&p, &a, &b, &c);
        assert!((r.dist - 1.0).abs() < 1e-14);
        let r = point_triangle(&p, &a, &a, &a); // a point
        assert!((r.dist - p.norm()).abs() < 1e-14);
        assert!(r.dist.is_finite() && r.bary.iter().all(|b| b.is_finite()));
    }

    #[test]
    fn segment_segment_matches_sampling() {
        let mut rng = Lcg(2);
        let k = 400;
        for it in 0..300 {
            let x = [rng.v3(1.0), rng.v3(1.0), rng.v3(1.0), rng.v3(1.0)];
            let r = segment_segment(&x[0], &x[1], &x[2], &x[3]);
            let d = (x[0] + (x[1] - x[0]) * r.s) - (x[2] + (x[3] - x[2]) * r.t);
            assert!((d.norm() - r.dist).abs() < 1e-12);
            let brute = brute_segments(x, k);
            let h = ((x[1] - x[0]).norm() + (x[3] - x[2]).norm()) / k as f64;
            assert!(
                r.dist <= brute + 1e-12,
                "it {it}: {} > brute {}",
                r.dist,
                brute
            );
            assert!(brute <= r.dist + h, "it {it}");
        }
    }

    #[test]
    fn segment_segment_parallel_and_degenerate() {
        let p0 = Vector3::new(0.0, 0.0, 0.0);
        let p1 = Vector3::new(1.0, 0.0, 0.0);
        // Parallel, overlapping.
        let q0 = Vector3::new(0.5, 0.2, 0.0);
        let q1 = Vector3::new(1.5, 0.2, 0.0);
        let r = segment_segment(&p0, &p1, &q0, &q1);
        assert!((r.dist - 0.2).abs() < 1e-14);
        // Parallel, disjoint along the line.
        let r = segment_segment(
            &p0,
            &p1,
            &(q0 + Vector3::new(1.0, 0.0, 0.0)),
            &(q1 + Vector3::new(1.0, 0.0, 0.0)),
        );
        assert!((r.dist - (0.25f64 + 0.04).sqrt()).abs() < 1e-14);
        // Anti-parallel, nearly parallel.
        let r = segment_segment(
            &p0,
            &p1,
            &Vector3::new(1.5, 0.2, 1e-9),
            &Vector3::new(0.5, 0.2, 0.0),
        );
        assert!((r.dist - 0.2).abs() < 1e-8);
        // Zero-length segments.
        let r = segment_segment(&p0, &p0, &q0, &q1);
        assert!((r.dist - point_segment(&p0, &q0, &q1).dist).abs() < 1e-14);
        let r = segment_segment(&p0, &p1, &q0, &q0);
        assert!((r.dist - point_segment(&q0, &p0, &p1).dist).abs() < 1e-14);
        let r = segment_segment(&p0, &p0, &q0, &q0);
        assert!((r.dist - q0.norm()).abs() < 1e-14);
    }
}
