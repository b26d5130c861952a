//! Garments made from 2D sewing patterns: panels (closed outlines of straight and curved edges in
//! metres), seams (pairs of panel edges sewn together), a 3D placement per panel and a fabric.

mod curve;
mod fabric;
pub mod garmentcode;

pub use curve::Curve;
pub use fabric::{Fabric, FabricPreset, UnknownFabric};

use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};

use crate::error::{Error, Result};

/// Points per curved edge used for outline area and intersection tests.
const OUTLINE_SAMPLES_PER_CURVE: usize = 64;

/// One edge of a panel outline, from vertex `start` to vertex `end`.
#[derive(Debug, Clone, PartialEq)]
pub struct PanelEdge {
    /// Index of the start vertex in [`Panel::vertices`].
    pub start: usize,
    /// Index of the end vertex.
    pub end: usize,
    /// Shape between the two.
    pub curve: Curve,
}

/// Rigid placement of a panel's plane around the body: `x = R · (u, v, 0) + t`.
#[derive(Debug, Clone, PartialEq)]
pub struct Placement {
    /// Translation, metres.
    pub translation_m: Vector3<f64>,
    /// Euler angles about x, y, z in degrees, applied x first (Maya's and GarmentCode's `xyz`
    /// order, USD's `rotateXYZ`): R = Rz·Ry·Rx.
    pub rotation_xyz_deg: Vector3<f64>,
}

impl Default for Placement {
    fn default() -> Self {
        Placement {
            translation_m: Vector3::zeros(),
            rotation_xyz_deg: Vector3::zeros(),
        }
    }
}

impl Placement {
    /// The rotation matrix R = Rz·Ry·Rx.
    pub fn rotation(&self) -> Matrix3<f64> {
        let r = self.rotation_xyz_deg.map(f64::to_radians);
        let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), r.x);
        let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), r.y);
        let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), r.z);
        (rz * ry * rx).into_inner()
    }

    /// World position of a material point.
    pub fn apply(&self, uv: Vector2<f64>) -> Vector3<f64> {
        self.rotation() * Vector3::new(uv.x, uv.y, 0.0) + self.translation_m
    }
}

/// A flat piece of fabric: a closed outline in its own 2D material frame (metres).
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    /// Unique name within the garment.
    pub name: String,
    /// Corner vertices of the outline, metres.
    pub vertices: Vec<Vector2<f64>>,
    /// Edges forming one closed loop: `edges[i].end == edges[i + 1].start`.
    pub edges: Vec<PanelEdge>,
    /// Where the panel sits in 3D before sewing.
    pub placement: Placement,
}

impl Panel {
    /// A `w` × `h` rectangle, counter-clockwise from its lower-left corner at the origin of its
    /// plane, with straight edges, placed by `placement`.
    pub fn rectangle(name: &str, w: f64, h: f64, placement: Placement) -> Panel {
        let vertices = vec![
            Vector2::new(0.0, 0.0),
            Vector2::new(w, 0.0),
            Vector2::new(w, h),
            Vector2::new(0.0, h),
        ];
        let edges = (0..4)
            .map(|i| PanelEdge {
                start: i,
                end: (i + 1) % 4,
                curve: Curve::Straight,
            })
            .collect();
        Panel {
            name: name.into(),
            vertices,
            edges,
            placement,
        }
    }

    /// Length of edge `e`, metres.
    pub fn edge_length(&self, e: usize) -> f64 {
        let edge = &self.edges[e];
        edge.curve
            .length(self.vertices[edge.start], self.vertices[edge.end])
    }

    /// Sample edge `e` with `n` segments, equally spaced in arc length (`n + 1` points).
    pub fn sample_edge(&self, e: usize, n: usize) -> Vec<Vector2<f64>> {
        let edge = &self.edges[e];
        edge.curve
            .sample_uniform(self.vertices[edge.start], self.vertices[edge.end], n)
    }

    /// A fine polygonal approximation of the closed outline (no repeated closing point).
    pub fn outline_polygon(&self) -> Vec<Vector2<f64>> {
        let mut out = Vec::new();
        for (e, edge) in self.edges.iter().enumerate() {
            let n = if edge.curve == Curve::Straight {
                1
            } else {
                OUTLINE_SAMPLES_PER_CURVE
            };
            let pts = self.sample_edge(e, n);
            out.extend_from_slice(&pts[..pts.len() - 1]);
        }
        out
    }

    /// Signed area of the outline (positive when counter-clockwise), m².
    pub fn signed_area(&self) -> f64 {
        signed_area(&self.outline_polygon())
    }

    /// Checks the outline: at least one edge, indices in range, finite coordinates, edges forming one
    /// closed loop, non-zero area and no self-intersection. Errors name the panel and edge.
    pub fn validate(&self) -> Result<()> {
        let name = &self.name;
        if self.edges.is_empty() || self.vertices.len() < 2 {
            return Err(Error::Invalid(format!(
                "panel '{name}': needs at least 2 vertices and 1 edge"
            )));
        }
        for (i, v) in self.vertices.iter().enumerate() {
            if !(v.x.is_finite() && v.y.is_finite()) {
                return Err(Error::Invalid(format!(
                    "panel '{name}': vertex {i} is not finite ({}, {})",
                    v.x, v.y
                )));
            }
        }
        let n = self.edges.len();
        for (i, e) in self.edges.iter().enumerate() {
            if e.start >= self.vertices.len() || e.end >= self.vertices.len() {
                return Err(Error::Invalid(format!(
                    "panel '{name}' edge {i}: endpoint index out of range ({} vertices)",
                    self.vertices.len()
                )));
            }
            let next = &self.edges[(i + 1) % n];
            if e.end != next.start {
                return Err(Error::Invalid(format!(
                    "panel '{name}' edge {i}: ends at vertex {} but edge {} starts at vertex {}: \
                     the edges do not form a closed loop",
                    e.end,
                    (i + 1) % n,
                    next.start
                )));
            }
            if e.start == e.end {
                return Err(Error::Invalid(format!(
                    "panel '{name}' edge {i}: starts and ends at the same vertex"
                )));
            }
            if !e.curve.params().iter().all(|p| p.is_finite()) {
                return Err(Error::Invalid(format!(
                    "panel '{name}' edge {i}: curvature is not finite"
                )));
            }
            let len = self.edge_length(i);
            if !(len.is_finite() && len > 1e-6) {
                return Err(Error::Invalid(format!(
                    "panel '{name}' edge {i}: zero length"
                )));
            }
        }
        let poly = self.outline_polygon();
        let area = signed_area(&poly).abs();
        let scale = poly.iter().map(|p| p.norm()).fold(0.0, f64::max).max(1e-3);
        if !(area > 1e-8 * scale * scale && area > 1e-10) {
            return Err(Error::Invalid(format!(
                "panel '{name}': outline has zero area"
            )));
        }
        if let Some((a, b)) = first_self_intersection(&poly) {
            let edge_of = |k: usize| self.edge_of_outline_point(k);
            return Err(Error::Invalid(format!(
                "panel '{name}': outline self-intersects (edge {} crosses edge {})",
                edge_of(a),
                edge_of(b)
            )));
        }
        Ok(())
    }

    /// Which edge the `k`-th point of [`Panel::outline_polygon`] starts on.
    fn edge_of_outline_point(&self, k: usize) -> usize {
        let mut count = 0;
        for (e, edge) in self.edges.iter().enumerate() {
            count += if edge.curve == Curve::Straight {
                1
            } else {
                OUTLINE_SAMPLES_PER_CURVE
            };
            if k < count {
                return e;
            }
        }
        self.edges.len().saturating_sub(1)
    }
}

/// One side of a seam: an edge of a panel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct EdgeRef {
    /// Panel index in [`Garment::panels`].
    pub panel: usize,
    /// Edge index in that panel's [`Panel::edges`].
    pub edge: usize,
}

/// Two panel edges sewn together, vertex for vertex.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Seam {
    /// First side.
    pub a: EdgeRef,
    /// Second side.
    pub b: EdgeRef,
    /// `true` when `a`'s start is sewn to `b`'s end (the edges run in opposite directions).
    pub reversed: bool,
}

/// Seams whose two sides differ by more than this ratio are rejected. Gathering (a skirt sewn to a
/// shorter waistband) is legitimate up to about 2–3× (the shared waistband templates gather 2.2×);
/// beyond that it is a pattern error.
pub const MAX_SEAM_LENGTH_RATIO: f64 = 3.0;

/// A garment: panels, seams and fabric.
#[derive(Debug, Clone, PartialEq)]
pub struct Garment {
    /// Name (a valid USD prim name is derived from it).
    pub name: String,
    /// The flat pieces.
    pub panels: Vec<Panel>,
    /// Sewing between panel edges.
    pub seams: Vec<Seam>,
    /// What it is made of.
    pub fabric: Fabric,
}

impl Garment {
    /// Total pattern area, m².
    pub fn area(&self) -> f64 {
        self.panels.iter().map(|p| p.signed_area().abs()).sum()
    }

    /// Index of the panel called `name`.
    pub fn panel_index(&self, name: &str) -> Option<usize> {
        self.panels.iter().position(|p| p.name == name)
    }

    /// Checks panels, seams and fabric; errors name the element at fault.
    pub fn validate(&self) -> Result<()> {
        if self.panels.is_empty() {
            return Err(Error::Invalid(format!(
                "garment '{}': no panels",
                self.name
            )));
        }
        for (i, p) in self.panels.iter().enumerate() {
            p.validate()?;
            if self.panels[..i].iter().any(|q| q.name == p.name) {
                return Err(Error::Invalid(format!(
                    "garment '{}': two panels are named '{}'",
                    self.name, p.name
                )));
            }
        }
        let mut used = std::collections::HashSet::new();
        for (s, seam) in self.seams.iter().enumerate() {
            let mut lengths = [0.0; 2];
            for (k, side) in [seam.a, seam.b].iter().enumerate() {
                let panel = self.panels.get(side.panel).ok_or_else(|| {
                    Error::Invalid(format!("seam {s}: panel index {} out of range", side.panel))
                })?;
                if side.edge >= panel.edges.len() {
                    return Err(Error::Invalid(format!(
                        "seam {s}: panel '{}' has no edge {} ({} edges)",
                        panel.name,
                        side.edge,
                        panel.edges.len()
                    )));
                }
                if !used.insert(*side) {
                    return Err(Error::Invalid(format!(
                        "seam {s}: edge {} of panel '{}' is already sewn by another seam",
                        side.edge, panel.name
                    )));
                }
                lengths[k] = panel.edge_length(side.edge);
            }
            let ratio = lengths[0].max(lengths[1]) / lengths[0].min(lengths[1]);
            if ratio > MAX_SEAM_LENGTH_RATIO {
                return Err(Error::Invalid(format!(
                    "seam {s}: '{}' edge {} is {:.1} mm long but '{}' edge {} is {:.1} mm \
                     (ratio {ratio:.2} > {MAX_SEAM_LENGTH_RATIO})",
                    self.panels[seam.a.panel].name,
                    seam.a.edge,
                    lengths[0] * 1e3,
                    self.panels[seam.b.panel].name,
                    seam.b.edge,
                    lengths[1] * 1e3
                )));
            }
        }
        self.fabric.validate()
    }

    /// Decides each seam's direction from the 3D placement: the pairing of end points that are
    /// closer in space wins. Patterns placed around a body sew correctly this way whichever way
    /// round their outlines run.
    pub fn orient_seams_by_placement(&mut self) {
        for seam in &mut self.seams {
            let ends = |r: EdgeRef| {
                let p = &self.panels[r.panel];
                let e = &p.edges[r.edge];
                (
                    p.placement.apply(p.vertices[e.start]),
                    p.placement.apply(p.vertices[e.end]),
                )
            };
            let (a0, a1) = ends(seam.a);
            let (b0, b1) = ends(seam.b);
            let same = (a0 - b0).norm() + (a1 - b1).norm();
            let opposite = (a0 - b1).norm() + (a1 - b0).norm();
            seam.reversed = opposite < same;
        }
    }
}

/// Signed area of a closed polygon (shoelace), positive when counter-clockwise.
pub fn signed_area(poly: &[Vector2<f64>]) -> f64 {
    let n = poly.len();
    (0..n)
        .map(|i| poly[i].perp(&poly[(i + 1) % n]))
        .sum::<f64>()
        * 0.5
}

/// First pair of non-adjacent crossing segments of a closed polygon (indices of segment starts).
/// O(n²) but outlines have at most a few thousand points.
fn first_self_intersection(poly: &[Vector2<f64>]) -> Option<(usize, usize)> {
    let n = poly.len();
    if n < 4 {
        return None;
    }
    for i in 0..n {
        let (p0, p1) = (poly[i], poly[(i + 1) % n]);
        let (lo_x, hi_x) = (p0.x.min(p1.x), p0.x.max(p1.x));
        for j in i + 2..n {
            if i == 0 && j == n - 1 {
                continue;
            }
            let (q0, q1) = (poly[j], poly[(j + 1) % n]);
            if q0.x.max(q1.x) < lo_x || q0.x.min(q1.x) > hi_x {
                continue;
            }
            if segments_cross(p0, p1, q0, q1) {
                return Some((i, j));
            }
        }
    }
    None
}

/// Whether segments `p0`–`p1` and `q0`–`q1` cross at a point inside both.
pub(crate) fn segments_cross(
    p0: Vector2<f64>,
    p1: Vector2<f64>,
    q0: Vector2<f64>,
    q1: Vector2<f64>,
) -> bool {
    let d1 = (p1 - p0).perp(&(q0 - p0));
    let d2 = (p1 - p0).perp(&(q1 - p0));
    let d3 = (q1 - q0).perp(&(p0 - q0));
    let d4 = (q1 - q0).perp(&(p1 - q0));
    d1 * d2 < 0.0 && d3 * d4 < 0.0
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A `w` × `h` rectangle panel, counter-clockwise from its lower-left corner.
    pub fn rectangle(name: &str, w: f64, h: f64) -> Panel {
        Panel::rectangle(name, w, h, Placement::default())
    }

    #[test]
    fn rotation_applies_x_first() {
        let p = Placement {
            translation_m: Vector3::new(1.0, 2.0, 3.0),
            rotation_xyz_deg: Vector3::new(90.0, 0.0, 90.0),
        };
        // Rz(90)·Rx(90)·e_x = Rz(90)·e_x = e_y; Rz(90)·Rx(90)·e_y = Rz(90)·e_z = e_z.
        let x = p.apply(Vector2::new(1.0, 0.0)) - p.translation_m;
        assert!((x - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-12, "{x}");
        let y = p.apply(Vector2::new(0.0, 1.0)) - p.translation_m;
        assert!((y - Vector3::new(0.0, 0.0, 1.0)).norm() < 1e-12, "{y}");
    }

    #[test]
    fn validation_catches_broken_outlines() {
        let ok = rectangle("r", 1.0, 0.5);
        ok.validate().expect("rectangle is valid");
        assert!((ok.signed_area() - 0.5).abs() < 1e-12);

        let mut bowtie = ok.clone();
        bowtie.vertices[2] = Vector2::new(0.0, 0.5);
        bowtie.vertices[3] = Vector2::new(1.2, 0.6);
        let err = bowtie.validate().expect_err("bow-tie").to_string();
        assert!(err.contains("self-intersects"), "{err}");

        let mut flat = ok.clone();
        for v in &mut flat.vertices {
            v.y = 0.0;
        }
        flat.vertices[2].x = 0.7;
        flat.vertices[3].x = 0.3;
        let err = flat.validate().expect_err("flat").to_string();
        assert!(
            err.contains("zero area") || err.contains("self-intersects"),
            "{err}"
        );

        let mut open = ok.clone();
        open.edges[1].end = 3;
        assert!(open
            .validate()
            .expect_err("open")
            .to_string()
            .contains("closed loop"));

        let mut nan = ok;
        nan.vertices[1].x = f64::NAN;
        assert!(nan
            .validate()
            .expect_err("nan")
            .to_string()
            .contains("not finite"));
    }

    #[test]
    fn seams_of_very_different_length_are_rejected() {
        let mut g = Garment {
            name: "g".into(),
            panels: vec![rectangle("a", 1.6, 0.5), rectangle("b", 0.3, 0.5)],
            seams: vec![Seam {
                a: EdgeRef { panel: 0, edge: 0 },
                b: EdgeRef { panel: 1, edge: 0 },
                reversed: true,
            }],
            fabric: Fabric::default(),
        };
        assert!(g
            .validate()
            .expect_err("ratio")
            .to_string()
            .contains("ratio"));
        g.seams[0].a.edge = 1;
        g.validate().expect("0.5 vs 0.3 is within the ratio");
    }
}
