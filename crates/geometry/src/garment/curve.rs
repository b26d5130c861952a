//! Panel edge curves (straight, quadratic / cubic Bézier, circular arc) and their sampling at a
//! target arc length.
//!
//! Curves are stored in absolute panel coordinates (metres), so a pattern read from GarmentCode
//! (relative control points) and one read back from USD compare exactly.

use nalgebra::Vector2;

/// Shape of one panel edge between its two end vertices.
#[derive(Debug, Clone, PartialEq)]
pub enum Curve {
    /// A straight segment.
    Straight,
    /// Quadratic Bézier with one control point (panel coordinates, metres).
    Quadratic {
        /// Control point.
        control: Vector2<f64>,
    },
    /// Cubic Bézier with two control points (panel coordinates, metres).
    Cubic {
        /// First control point (next to the start vertex).
        control1: Vector2<f64>,
        /// Second control point (next to the end vertex).
        control2: Vector2<f64>,
    },
    /// Circular arc with SVG's parametrisation: radius, large-arc flag and `right` (the arc bulges
    /// to the right of the start → end direction, y up), as GarmentCode writes it.
    Arc {
        /// Radius in metres (raised to half the chord if smaller, as SVG does).
        radius_m: f64,
        /// The arc spans more than 180°.
        large_arc: bool,
        /// The arc bulges to the right of the chord direction.
        right: bool,
    },
}

/// Number of points used to tabulate arc length of a curved edge.
const TABULATION: usize = 256;

impl Curve {
    /// The name stored in USD (`clothsr:edgeCurveTypes`).
    pub fn type_name(&self) -> &'static str {
        match self {
            Curve::Straight => "straight",
            Curve::Quadratic { .. } => "quadratic",
            Curve::Cubic { .. } => "cubic",
            Curve::Arc { .. } => "circle",
        }
    }

    /// Four numbers that, with [`Curve::type_name`], describe the curve (`clothsr:edgeCurveParams`):
    /// quadratic `(cx, cy, 0, 0)`, cubic `(c1x, c1y, c2x, c2y)`, circle `(radius, large, right, 0)`.
    pub fn params(&self) -> [f64; 4] {
        match self {
            Curve::Straight => [0.0; 4],
            Curve::Quadratic { control } => [control.x, control.y, 0.0, 0.0],
            Curve::Cubic { control1, control2 } => [control1.x, control1.y, control2.x, control2.y],
            Curve::Arc {
                radius_m,
                large_arc,
                right,
            } => [
                *radius_m,
                f64::from(u8::from(*large_arc)),
                f64::from(u8::from(*right)),
                0.0,
            ],
        }
    }

    /// Inverse of [`Curve::type_name`] + [`Curve::params`].
    pub fn from_type_params(type_name: &str, p: [f64; 4]) -> Option<Curve> {
        Some(match type_name {
            "straight" => Curve::Straight,
            "quadratic" => Curve::Quadratic {
                control: Vector2::new(p[0], p[1]),
            },
            "cubic" => Curve::Cubic {
                control1: Vector2::new(p[0], p[1]),
                control2: Vector2::new(p[2], p[3]),
            },
            "circle" => Curve::Arc {
                radius_m: p[0],
                large_arc: p[1] != 0.0,
                right: p[2] != 0.0,
            },
            _ => return None,
        })
    }

    /// Point at parameter `t ∈ [0, 1]` of the edge from `a` to `b`.
    pub fn eval(&self, a: Vector2<f64>, b: Vector2<f64>, t: f64) -> Vector2<f64> {
        match self {
            Curve::Straight => a + (b - a) * t,
            Curve::Quadratic { control } => {
                let s = 1.0 - t;
                a * (s * s) + control * (2.0 * s * t) + b * (t * t)
            }
            Curve::Cubic { control1, control2 } => {
                let s = 1.0 - t;
                a * (s * s * s)
                    + control1 * (3.0 * s * s * t)
                    + control2 * (3.0 * s * t * t)
                    + b * (t * t * t)
            }
            Curve::Arc { .. } => {
                let (c, r, th0, dth) = self.arc_geometry(a, b);
                let th = th0 + dth * t;
                c + Vector2::new(th.cos(), th.sin()) * r
            }
        }
    }

    /// Centre, radius, start angle and signed sweep of an arc edge.
    fn arc_geometry(&self, a: Vector2<f64>, b: Vector2<f64>) -> (Vector2<f64>, f64, f64, f64) {
        let Curve::Arc {
            radius_m,
            large_arc,
            right,
        } = *self
        else {
            return (a, 0.0, 0.0, 0.0);
        };
        let d = b - a;
        let len = d.norm();
        let r = radius_m.abs().max(0.5 * len);
        let left = Vector2::new(-d.y, d.x) / len.max(f64::MIN_POSITIVE);
        let h = (r * r - 0.25 * len * len).max(0.0).sqrt();
        let mid = (a + b) * 0.5;
        // A minor arc bulging right has its centre on the left of the chord; a major arc on the
        // right; and mirrored for left-bulging arcs.
        let centre = if right != large_arc {
            mid + left * h
        } else {
            mid - left * h
        };
        let apex = if right {
            centre - left * r
        } else {
            centre + left * r
        };
        let ang = |p: Vector2<f64>| (p.y - centre.y).atan2(p.x - centre.x);
        let (th0, th1, tha) = (ang(a), ang(b), ang(apex));
        let tau = std::f64::consts::TAU;
        let ccw = (th1 - th0).rem_euclid(tau);
        let apex_ccw = (tha - th0).rem_euclid(tau);
        let sweep = if apex_ccw <= ccw { ccw } else { ccw - tau };
        (centre, r, th0, sweep)
    }

    /// Arc-length table: cumulative lengths at `TABULATION + 1` uniform parameters.
    fn length_table(&self, a: Vector2<f64>, b: Vector2<f64>) -> Vec<f64> {
        let mut cum = Vec::with_capacity(TABULATION + 1);
        cum.push(0.0);
        let mut prev = a;
        for i in 1..=TABULATION {
            let p = self.eval(a, b, i as f64 / TABULATION as f64);
            let last = cum.last().copied().unwrap_or(0.0);
            cum.push(last + (p - prev).norm());
            prev = p;
        }
        cum
    }

    /// Length of the edge from `a` to `b` in metres.
    pub fn length(&self, a: Vector2<f64>, b: Vector2<f64>) -> f64 {
        match self {
            Curve::Straight => (b - a).norm(),
            Curve::Arc { .. } => {
                let (_, r, _, sweep) = self.arc_geometry(a, b);
                r * sweep.abs()
            }
            _ => self.length_table(a, b).last().copied().unwrap_or(0.0),
        }
    }

    /// `n + 1` points along the edge from `a` to `b` (both included), equally spaced in arc length.
    pub fn sample_uniform(&self, a: Vector2<f64>, b: Vector2<f64>, n: usize) -> Vec<Vector2<f64>> {
        let n = n.max(1);
        match self {
            Curve::Straight | Curve::Arc { .. } => (0..=n)
                .map(|i| self.eval(a, b, i as f64 / n as f64))
                .collect(),
            _ => {
                let cum = self.length_table(a, b);
                let total = cum[TABULATION];
                let mut out = Vec::with_capacity(n + 1);
                let mut j = 0;
                for i in 0..=n {
                    if i == 0 {
                        out.push(a);
                        continue;
                    }
                    if i == n {
                        out.push(b);
                        continue;
                    }
                    let s = total * i as f64 / n as f64;
                    while j + 1 < TABULATION && cum[j + 1] < s {
                        j += 1;
                    }
                    let seg = (cum[j + 1] - cum[j]).max(f64::MIN_POSITIVE);
                    let t = (j as f64 + ((s - cum[j]) / seg).clamp(0.0, 1.0)) / TABULATION as f64;
                    out.push(self.eval(a, b, t));
                }
                out
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn semicircle_arc_has_half_circumference_and_bulges_right() {
        let a = Vector2::new(0.0, 0.0);
        let b = Vector2::new(2.0, 0.0);
        let arc = Curve::Arc {
            radius_m: 1.0,
            large_arc: false,
            right: true,
        };
        assert!((arc.length(a, b) - std::f64::consts::PI).abs() < 1e-9);
        // Travelling +x, "right" is -y.
        let mid = arc.eval(a, b, 0.5);
        assert!((mid - Vector2::new(1.0, -1.0)).norm() < 1e-9, "{mid}");
        let left = Curve::Arc {
            radius_m: 1.0,
            large_arc: false,
            right: false,
        };
        assert!((left.eval(a, b, 0.5) - Vector2::new(1.0, 1.0)).norm() < 1e-9);
    }

    #[test]
    fn large_arc_goes_the_long_way() {
        let a = Vector2::new(0.0, 0.0);
        let b = Vector2::new(1.0, 0.0);
        let r = 1.0;
        let minor = Curve::Arc {
            radius_m: r,
            large_arc: false,
            right: true,
        };
        let major = Curve::Arc {
            radius_m: r,
            large_arc: true,
            right: true,
        };
        let full = 2.0 * std::f64::consts::PI * r;
        assert!((minor.length(a, b) + major.length(a, b) - full).abs() < 1e-9);
        // Both bulge to the right (negative y) at their midpoint.
        assert!(minor.eval(a, b, 0.5).y < 0.0);
        assert!(major.eval(a, b, 0.5).y < -1.0);
        assert!((major.eval(a, b, 1.0) - b).norm() < 1e-9);
    }

    #[test]
    fn uniform_sampling_of_a_bezier_is_equal_in_arc_length() {
        let a = Vector2::new(0.0, 0.0);
        let b = Vector2::new(1.0, 0.0);
        let c = Curve::Cubic {
            control1: Vector2::new(0.05, 0.3),
            control2: Vector2::new(0.9, -0.2),
        };
        let n = 20;
        let pts = c.sample_uniform(a, b, n);
        // Arc length of each sample from a dense polyline of the curve.
        let dense: Vec<Vector2<f64>> = (0..=20_000)
            .map(|k| c.eval(a, b, k as f64 / 20_000.0))
            .collect();
        let mut cum = vec![0.0];
        for w in dense.windows(2) {
            cum.push(cum.last().copied().unwrap_or(0.0) + (w[1] - w[0]).norm());
        }
        let total = cum[cum.len() - 1];
        assert!((total - c.length(a, b)).abs() < 1e-4 * total);
        for (i, p) in pts.iter().enumerate() {
            let k = (0..dense.len())
                .min_by(|&x, &y| (dense[x] - p).norm().total_cmp(&(dense[y] - p).norm()))
                .unwrap_or(0);
            let expect = total * i as f64 / n as f64;
            assert!(
                (cum[k] - expect).abs() < 1e-3 * total,
                "sample {i}: s = {} vs {expect}",
                cum[k]
            );
        }
    }

    #[test]
    fn params_round_trip() {
        for c in [
            Curve::Straight,
            Curve::Quadratic {
                control: Vector2::new(0.3, -0.1),
            },
            Curve::Cubic {
                control1: Vector2::new(0.1, 0.2),
                control2: Vector2::new(0.3, 0.4),
            },
            Curve::Arc {
                radius_m: 0.7,
                large_arc: true,
                right: false,
            },
        ] {
            assert_eq!(
                Curve::from_type_params(c.type_name(), c.params()),
                Some(c.clone())
            );
        }
    }
}
