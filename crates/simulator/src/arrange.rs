//! Arranging flat sewing-pattern panels around a body before sewing, as garment CAD tools do
//! with their arrangement cylinders: a flat, upright panel that faces the body is rolled onto a
//! vertical cylinder around the body's axis, without stretching it.
//!
//! GarmentCode places panels flat, in front of and behind the body (tens of centimetres
//! apart). Sewn as they are, a front and a back panel close their side seams along straight
//! lines that run through the hips: the cloth is pressed into the body by the seams' pull and
//! stalls open (the pencil skirt on the walking avatar stopped 36 mm open). Rolled around the
//! body first, the same panels form an open tube whose side seams close tangentially, around
//! the body rather than through it.

use std::ops::Range;

use nalgebra::Vector3;

use super::step::ColliderFrame;
use clothsr_geometry::error::{Error, Result};
use clothsr_geometry::mesh::ClothMesh;

/// When and how panels are rolled ([`wrap_panels_around_body`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WrapOptions {
    /// Gap kept between a rolled panel and every body point near it, m.
    pub clearance_m: f64,
    /// Panels whose normal leans more than this from horizontal are left flat, degrees.
    pub max_tilt_deg: f64,
    /// Panels whose normal points more than this away from the body's axis (a sleeve beside
    /// the torso) are left flat, degrees.
    pub max_facing_deg: f64,
    /// Panels that would cover a wider angle than this around the axis (a circle skirt's
    /// panels) are left flat, degrees.
    pub max_span_deg: f64,
    /// Panels that are not flat to within this are left as they are (already draped), m.
    pub flatness_m: f64,
    /// Panels that would have to move out further than this to clear the body are left flat, m.
    pub max_push_m: f64,
}

impl Default for WrapOptions {
    fn default() -> Self {
        WrapOptions {
            clearance_m: 0.01,
            max_tilt_deg: 15.0,
            max_facing_deg: 35.0,
            max_span_deg: 200.0,
            flatness_m: 1e-3,
            max_push_m: 0.05,
        }
    }
}

/// One panel rolled onto a cylinder.
#[derive(Debug, Clone, PartialEq)]
pub struct WrappedPanel {
    /// Panel index in the mesh.
    pub panel: usize,
    /// Cylinder radius, m (the panel's distance from the axis, or more to clear the body).
    pub radius_m: f64,
    /// Angle the panel covers around the axis, degrees.
    pub span_deg: f64,
}

/// Rolls the flat, upright panels of each garment (`garments`: vertex ranges of `mesh`) that
/// face the body onto vertical cylinders about the body's axis, writing into `x` (positions of
/// all of `mesh`'s vertices). The axis of a garment passes through the area-weighted median
/// (x, z) of the body surface (`body`: collider meshes) within the garment's height, so that
/// finely meshed hands do not pull it aside. Each panel keeps its distance from the axis, so
/// its centre stays where it was placed; a panel whose cylinder would pass within
/// `clearance_m` of a body point of its sector moves out until it clears them, and stays flat
/// if that takes it more than `max_push_m` out (an arm beside the hips). Mesh edges keep their
/// lengths along the cylinder (the map is an isometry of the plane), so the rolled panel is
/// unstretched; only its bending energy changes.
pub fn wrap_panels_around_body(
    mesh: &ClothMesh,
    garments: &[Range<usize>],
    x: &mut [Vector3<f64>],
    body: &[ColliderFrame<'_>],
    opts: &WrapOptions,
) -> Vec<WrappedPanel> {
    let mut out = Vec::new();
    for g in garments {
        let (y_lo, y_hi) = height_range(g.clone().map(|i| &x[i]));
        let Some(garment_axis) = axis_in(body, y_lo, y_hi) else {
            continue;
        };
        let band = band_in(body, y_lo, y_hi, opts.clearance_m);
        let mut panels: Vec<usize> = mesh.panel_of_vertex[g.clone()]
            .iter()
            .map(|&p| p as usize)
            .collect();
        panels.sort_unstable();
        panels.dedup();
        for panel in panels {
            let verts: Vec<usize> = g
                .clone()
                .filter(|&i| mesh.panel_of_vertex[i] as usize == panel)
                .collect();
            let wrapped = match wrap_panel(mesh, panel, &verts, x, garment_axis, &band, false, opts)
            {
                // A panel beside the torso (a sleeve in front of or behind an arm) rolls
                // around the limb it covers instead.
                Err(Error::Invalid(why)) if why == NOT_FACING => {
                    match limb_under(mesh, panel, &verts, x, body) {
                        Some((limb, points)) => wrap_panel(
                            mesh, panel, &verts, x, limb, &points, false, opts,
                        )
                        .map_err(|w| {
                            Error::Invalid(format!("{why}, and around the limb under it: {w}"))
                        }),
                        None => Err(Error::Invalid(format!("{why}, and covers no limb"))),
                    }
                }
                // A panel above or below most of the garment (a hood beside the head, over the
                // shoulders) rolls around the body at its own height, clear of the body points
                // it covers: those under its outline, not of its whole height range.
                Err(Error::Invalid(why)) if why.starts_with(CLEARING) => {
                    let (lo, hi) = height_range(verts.iter().map(|&i| &x[i]));
                    match axis_in(body, lo, hi) {
                        Some(own) => {
                            let near = band_in(body, lo, hi, opts.clearance_m);
                            wrap_panel(mesh, panel, &verts, x, own, &near, true, opts).map_err(
                                |w| {
                                    Error::Invalid(format!(
                                        "{why}, and around the body at its own height: {w}"
                                    ))
                                },
                            )
                        }
                        None => Err(Error::Invalid(why)),
                    }
                }
                other => other,
            };
            match wrapped {
                Ok(w) => out.push(w),
                Err(why) => {
                    tracing::debug!("panel '{}' left as placed: {why}", mesh.panel_names[panel])
                }
            }
        }
    }
    out
}

/// The lowest and highest `y` of `points`.
fn height_range<'a>(points: impl Iterator<Item = &'a Vector3<f64>>) -> (f64, f64) {
    points.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
        (lo.min(p.y), hi.max(p.y))
    })
}

/// The vertical axis of the body between heights `lo` and `hi`: through the area-weighted
/// median (x, z) of its triangles' centroids there, so that finely meshed hands do not pull it
/// aside. `None` when no triangle lies there.
fn axis_in(body: &[ColliderFrame<'_>], lo: f64, hi: f64) -> Option<Axis> {
    let mut cx: Vec<(f64, f64)> = Vec::new();
    let mut cz: Vec<(f64, f64)> = Vec::new();
    for b in body {
        for t in b.triangles {
            let [p, q, r] = t.map(|v| b.points[v as usize]);
            let c = (p + q + r) / 3.0;
            if c.y < lo || c.y > hi {
                continue;
            }
            let area = 0.5 * (q - p).cross(&(r - p)).norm();
            if area.is_finite() && area > 0.0 {
                cx.push((c.x, area));
                cz.push((c.z, area));
            }
        }
    }
    Some(Axis {
        point: Vector3::new(weighted_median(cx)?, 0.0, weighted_median(cz)?),
        up: Vector3::y(),
    })
}

/// The body points between heights `lo` and `hi`, `clearance_m` more each way.
fn band_in(body: &[ColliderFrame<'_>], lo: f64, hi: f64, clearance_m: f64) -> Vec<Vector3<f64>> {
    body.iter()
        .flat_map(|b| b.points.iter())
        .filter(|p| p.y >= lo - clearance_m && p.y <= hi + clearance_m)
        .copied()
        .collect()
}

/// The weighted median (None when empty): the value below which half the weight lies. When
/// the weight splits evenly between two neighbouring values (to rounding: a symmetric body
/// always does), their midpoint, so that a symmetric body's axis is its centre and not a
/// triangle's width to one side of it, whichever way the sum's last bit rounds.
fn weighted_median(mut v: Vec<(f64, f64)>) -> Option<f64> {
    v.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let total = v.iter().map(|p| p.1).sum::<f64>();
    let half = 0.5 * total;
    let tie = 1e-9 * total;
    let mut acc = 0.0;
    for (k, (value, w)) in v.iter().enumerate() {
        acc += w;
        if acc >= half - tie {
            if acc <= half + tie {
                if let Some((next, _)) = v.get(k + 1) {
                    return Some(0.5 * (value + next));
                }
            }
            return Some(*value);
        }
    }
    v.last().map(|p| p.0)
}

/// Why a panel beside the body's axis is not rolled around it.
const NOT_FACING: &str = "does not face the body's axis";

/// Along the roll, how far from a body point's angle a panel's vertices count as over it when
/// only the panel's outline is cleared, m (about two coarse edges).
const OUTLINE_WINDOW_M: f64 = 0.04;

/// How the reason begins when a panel would have to move too far out to clear the body.
const CLEARING: &str = "clearing the body";

/// How far from a panel's plane body points count as under it, m.
const LIMB_REACH_M: f64 = 0.15;

/// The limb a flat panel covers (a sleeve panel in front of or behind an arm): the body points
/// within [`LIMB_REACH_M`] of its plane whose projection falls on the panel's extent (2 cm
/// more each way), narrowed to those near their principal axis; that axis, and those points.
/// `None` when they are few, or not elongated along the panel (a torso, not a limb).
fn limb_under(
    mesh: &ClothMesh,
    panel: usize,
    verts: &[usize],
    x: &[Vector3<f64>],
    body: &[ColliderFrame<'_>],
) -> Option<(Axis, Vec<Vector3<f64>>)> {
    let (c, n) = centre_and_normal(mesh, panel, verts, x)?;
    // The panel's long direction in its plane, and across it.
    let (e1, _) = principal(verts.iter().map(|&i| x[i]))?;
    let e1 = (e1 - n * e1.dot(&n)).try_normalize(1e-9)?;
    let e2 = n.cross(&e1);
    let extent = |e: &Vector3<f64>| {
        verts
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &i| {
                let u = (x[i] - c).dot(e);
                (lo.min(u), hi.max(u))
            })
    };
    let ((u_lo, u_hi), (v_lo, v_hi)) = (extent(&e1), extent(&e2));
    let pad = 0.02;
    let mut points: Vec<Vector3<f64>> = body
        .iter()
        .flat_map(|b| b.points.iter())
        .filter(|p| {
            let q = *p - c;
            let (u, v) = (q.dot(&e1), q.dot(&e2));
            q.dot(&n).abs() <= LIMB_REACH_M
                && u >= u_lo - pad
                && u <= u_hi + pad
                && v >= v_lo - pad
                && v <= v_hi + pad
        })
        .copied()
        .collect();
    // Twice: the second fit keeps the points near the first axis (an arm, not the torso
    // beside it).
    let mut axis = None;
    for _ in 0..2 {
        if points.len() < 20 {
            return None;
        }
        let (up, ratio) = principal(points.iter().copied())?;
        if ratio < 4.0 {
            return None;
        }
        let m = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
        let a = Axis { point: m, up };
        let mut r: Vec<f64> = points.iter().map(|p| a.across(p - m).norm()).collect();
        r.sort_unstable_by(f64::total_cmp);
        let keep = 1.5 * r[r.len() / 2];
        points.retain(|p| a.across(p - m).norm() <= keep);
        axis = Some(a);
    }
    axis.map(|a| (a, points))
}

/// A panel's centroid (of its vertices `verts`) and the area-weighted normal of its triangles;
/// `None` for a panel without area.
fn centre_and_normal(
    mesh: &ClothMesh,
    panel: usize,
    verts: &[usize],
    x: &[Vector3<f64>],
) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let c = verts.iter().map(|&i| x[i]).sum::<Vector3<f64>>() / verts.len().max(1) as f64;
    let n = mesh
        .triangles
        .iter()
        .filter(|t| mesh.panel_of_vertex[t[0] as usize] as usize == panel)
        .map(|t| {
            let [a, b, d] = t.map(|v| x[v as usize]);
            (b - a).cross(&(d - a))
        })
        .sum::<Vector3<f64>>()
        .try_normalize(1e-12)?;
    Some((c, n))
}

/// The principal direction of `points` and how elongated they are along it (the largest
/// variance over the second).
fn principal(points: impl Iterator<Item = Vector3<f64>>) -> Option<(Vector3<f64>, f64)> {
    let pts: Vec<Vector3<f64>> = points.collect();
    if pts.len() < 3 {
        return None;
    }
    let m = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
    let cov = pts
        .iter()
        .map(|p| (p - m) * (p - m).transpose())
        .sum::<nalgebra::Matrix3<f64>>()
        / pts.len() as f64;
    let eig = cov.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_unstable_by(|&i, &j| eig.eigenvalues[j].total_cmp(&eig.eigenvalues[i]));
    let (l1, l2) = (eig.eigenvalues[order[0]], eig.eigenvalues[order[1]]);
    let dir = eig.eigenvectors.column(order[0]).into_owned();
    Some((dir, l1 / l2.max(1e-12)))
}

/// A cylinder's axis: a point on it and its (unit) direction.
#[derive(Debug, Clone, Copy)]
struct Axis {
    point: Vector3<f64>,
    up: Vector3<f64>,
}

impl Axis {
    /// `v` less its component along the axis.
    fn across(&self, v: Vector3<f64>) -> Vector3<f64> {
        v - self.up * v.dot(&self.up)
    }

    /// The height of `p` along the axis.
    fn height(&self, p: &Vector3<f64>) -> f64 {
        p.dot(&self.up)
    }
}

/// Rolls one panel (its vertices `verts`) about `axis`, or says why it stays as placed. It
/// clears the body points of `band` in its sector at any of its heights, or with `outline`
/// only those within the panel's own height span where they are (a hood's outline rises from
/// the shoulders).
#[allow(clippy::too_many_arguments)]
fn wrap_panel(
    mesh: &ClothMesh,
    panel: usize,
    verts: &[usize],
    x: &mut [Vector3<f64>],
    axis: Axis,
    band: &[Vector3<f64>],
    outline: bool,
    opts: &WrapOptions,
) -> Result<WrappedPanel> {
    let invalid = |why: &str| Error::Invalid(why.into());
    if verts.len() < 3 {
        return Err(invalid("fewer than 3 vertices"));
    }
    let (c, n) = centre_and_normal(mesh, panel, verts, x).ok_or_else(|| invalid("no area"))?;
    if verts
        .iter()
        .any(|&i| (x[i] - c).dot(&n).abs() > opts.flatness_m)
    {
        return Err(invalid("not flat"));
    }
    let up = axis.up;
    if n.dot(&up).abs() > opts.max_tilt_deg.to_radians().sin() {
        return Err(invalid("not upright"));
    }
    let a = axis.across(axis.point);
    let to_centre = (axis.across(c) - a)
        .try_normalize(1e-3)
        .ok_or_else(|| invalid("centred on the body's axis"))?;
    let n_h = axis
        .across(n)
        .try_normalize(1e-12)
        .ok_or_else(|| invalid("not upright"))?;
    if n_h.dot(&to_centre).abs() < opts.max_facing_deg.to_radians().cos() {
        return Err(invalid(NOT_FACING));
    }
    // The roll is about the panel's plane's nearest line to the axis: the cylinder touches the
    // plane there, so the panel's distance from the axis and its sideways placement are kept
    // exactly, however unevenly its vertices are spread.
    let r_hat = if n_h.dot(&to_centre) > 0.0 { n_h } else { -n_h };
    let placed_r = (c - a).dot(&r_hat);
    if placed_r < 1e-3 {
        return Err(invalid("its plane passes through the body's axis"));
    }
    let t_hat = up.cross(&r_hat);
    let u: Vec<f64> = verts.iter().map(|&i| (x[i] - a).dot(&t_hat)).collect();
    let (u_lo, u_hi) = u
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    // Body points of the panel's height range, as (angle from r̂, distance from the axis).
    let (y_lo, y_hi) = verts
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &i| {
            let y = axis.height(&x[i]);
            (lo.min(y), hi.max(y))
        });
    // With `outline`, the panel's height span near a point's angle: that of its vertices
    // within a window of it along the roll.
    let window = OUTLINE_WINDOW_M + opts.clearance_m;
    let span_at = |phi: f64| {
        let at = phi * placed_r;
        verts
            .iter()
            .zip(&u)
            .filter(|(_, &ui)| (ui - at).abs() <= window)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (&i, _)| {
                let y = axis.height(&x[i]);
                (lo.min(y), hi.max(y))
            })
    };
    let near: Vec<(f64, f64)> = band
        .iter()
        .filter_map(|p| {
            let y = axis.height(p);
            let q = axis.across(*p) - a;
            let phi = q.dot(&t_hat).atan2(q.dot(&r_hat));
            let (lo, hi) = if outline { span_at(phi) } else { (y_lo, y_hi) };
            (y >= lo - opts.clearance_m && y <= hi + opts.clearance_m).then_some((phi, q.norm()))
        })
        .collect();
    // Move out past every body point of the sector that lies within the clearance of the
    // cylinder (the sector of the starting radius holds those of every larger one).
    let margin = opts.clearance_m / placed_r;
    let (lo, hi) = (u_lo / placed_r - margin, u_hi / placed_r + margin);
    let mut sector: Vec<f64> = near
        .iter()
        .filter(|(phi, _)| *phi >= lo && *phi <= hi)
        .map(|&(_, rho)| rho)
        .collect();
    sector.sort_unstable_by(f64::total_cmp);
    let mut radius = placed_r;
    for &rho in &sector {
        if rho > radius + opts.clearance_m {
            break;
        }
        radius = radius.max(rho + opts.clearance_m);
    }
    if radius > placed_r + opts.max_push_m {
        return Err(Error::Invalid(format!(
            "{CLEARING} would take it from {:.0} to {:.0} mm from the axis",
            placed_r * 1e3,
            radius * 1e3
        )));
    }
    let span = (u_hi - u_lo) / radius;
    if span.to_degrees() > opts.max_span_deg {
        return Err(Error::Invalid(format!(
            "would cover {:.0}° around the body",
            span.to_degrees()
        )));
    }
    // Where the plane touches its starting cylinder, at the axis' foot (height 0).
    let touch = a + r_hat * placed_r;
    for (&i, &ui) in verts.iter().zip(&u) {
        // What is not along the roll: the height and the (sub-millimetre) offset off the plane.
        let rest = x[i] - touch - t_hat * ui;
        let phi = ui / radius;
        x[i] = a + r_hat * (radius * phi.cos()) + t_hat * (radius * phi.sin()) + rest;
    }
    Ok(WrappedPanel {
        panel,
        radius_m: radius,
        span_deg: span.to_degrees(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use clothsr_geometry::garment::Fabric;
    use clothsr_geometry::mesh::{mesh_garment, MeshOptions};
    use clothsr_geometry::scene::samples::two_panel_tube;

    /// Two `w` × 0.2 m panels facing each other across the y axis at z = ±`d`, sewn along
    /// both vertical sides (as the sewing test's tube), meshed at 2 cm.
    fn tube(w: f64, d: f64) -> ClothMesh {
        let g = two_panel_tube(w, 0.2, d, Fabric::default());
        mesh_garment(&g, &MeshOptions::with_edge(0.02)).expect("mesh")
    }

    /// A vertical cylinder of radius `r` about the y axis, y from -0.1 to 0.3 m: points and
    /// triangles.
    fn cylinder(r: f64) -> (Vec<Vector3<f64>>, Vec<[u32; 3]>) {
        let (rings, around) = (41u32, 72u32);
        let mut points = Vec::new();
        for k in 0..rings {
            for j in 0..around {
                let a = j as f64 * std::f64::consts::TAU / around as f64;
                points.push(Vector3::new(
                    r * a.cos(),
                    -0.1 + 0.01 * k as f64,
                    r * a.sin(),
                ));
            }
        }
        let mut triangles = Vec::new();
        for k in 0..rings - 1 {
            for j in 0..around {
                let (p, q) = (k * around + j, k * around + (j + 1) % around);
                triangles.push([p, q + around, q]);
                triangles.push([p, p + around, q + around]);
            }
        }
        (points, triangles)
    }

    fn frame<'a>(body: &'a (Vec<Vector3<f64>>, Vec<[u32; 3]>)) -> [ColliderFrame<'a>; 1] {
        [ColliderFrame {
            points: &body.0,
            triangles: &body.1,
        }]
    }

    fn widest_seam_gap(mesh: &ClothMesh, x: &[Vector3<f64>]) -> f64 {
        mesh.seam_pairs
            .iter()
            .map(|p| (x[p[0] as usize] - x[p[1] as usize]).norm())
            .fold(0.0, f64::max)
    }

    /// One garment made of every vertex.
    fn whole(n: usize) -> Vec<Range<usize>> {
        std::iter::once(0..n).collect()
    }

    fn horizontal_radius(p: &Vector3<f64>) -> f64 {
        p.x.hypot(p.z)
    }

    /// A hood's side: one upright panel 0.2 m wide and 0.3 m high, 0.1 m in front of the y
    /// axis and facing it, whose lower edge rises from a low corner on its left (x ≤ −0.04)
    /// to 0.12 m at its right; meshed at 2 cm.
    fn hood_side() -> ClothMesh {
        use clothsr_geometry::garment::{Curve, Garment, Panel, PanelEdge, Placement};
        let vertices = [(0.0, 0.0), (0.06, 0.0), (0.2, 0.12), (0.2, 0.3), (0.0, 0.3)]
            .map(|(u, v)| nalgebra::Vector2::new(u, v))
            .to_vec();
        let edges = (0..vertices.len())
            .map(|k| PanelEdge {
                start: k,
                end: (k + 1) % vertices.len(),
                curve: Curve::Straight,
            })
            .collect();
        let g = Garment {
            name: "hood".into(),
            panels: vec![Panel {
                name: "side".into(),
                vertices,
                edges,
                placement: Placement {
                    translation_m: Vector3::new(-0.1, 0.0, 0.1),
                    rotation_xyz_deg: Vector3::zeros(),
                },
            }],
            seams: Vec::new(),
            fabric: Fabric::default(),
        };
        mesh_garment(&g, &MeshOptions::with_edge(0.02)).expect("mesh")
    }

    /// Rolled around the y axis, the hood's side clears every body point of its sector within
    /// its height range, or with `outline` only those within its height span where they are: a
    /// shoulder (points from 0.102 to 0.2 m out, 2 cm high, under its raised right side) keeps
    /// it flat unless only its outline is cleared; a point under the outline, 0.105 m out,
    /// moves it out to the clearance from that point either way.
    #[test]
    fn a_panel_clears_the_body_under_its_outline() {
        let mesh = hood_side();
        let verts: Vec<usize> = (0..mesh.num_vertices()).collect();
        let opts = WrapOptions::default();
        let axis = Axis {
            point: Vector3::zeros(),
            up: Vector3::y(),
        };
        let out = Vector3::new(0.09, 0.0, 0.1).normalize();
        let mut band: Vec<Vector3<f64>> = (0..20)
            .map(|k| out * (0.102 + 0.005 * k as f64) + Vector3::new(0.0, 0.02, 0.0))
            .collect();
        let under = Vector3::new(0.03, 0.2, (0.105f64.powi(2) - 0.03f64.powi(2)).sqrt());
        band.push(under);
        let mut x = mesh.positions.clone();
        let whole = wrap_panel(&mesh, 0, &verts, &mut x, axis, &band, false, &opts);
        match whole {
            Err(Error::Invalid(why)) => assert!(why.starts_with(CLEARING), "{why}"),
            other => panic!("rolled clear of the shoulder: {other:?}"),
        }
        assert_eq!(x, mesh.positions, "left as placed");
        let w = wrap_panel(&mesh, 0, &verts, &mut x, axis, &band, true, &opts).expect("rolled");
        assert!((w.radius_m - 0.115).abs() < 1e-9, "{w:?}");
        for p in &x {
            assert!((horizontal_radius(p) - 0.115).abs() < 1e-9, "{p}");
        }
        // Without the shoulder, the whole height range and the outline roll it alike.
        band.drain(..20);
        let mut y = mesh.positions.clone();
        wrap_panel(&mesh, 0, &verts, &mut y, axis, &band, false, &opts).expect("rolled");
        assert_eq!(x, y);
    }

    #[test]
    fn weighted_median_splits_even_ties_and_follows_the_weight() {
        assert_eq!(weighted_median(Vec::new()), None);
        assert_eq!(weighted_median(vec![(3.0, 1.0)]), Some(3.0));
        // Half the weight on each side: the midpoint, whatever the order given.
        assert_eq!(weighted_median(vec![(2.0, 1.0), (-1.0, 1.0)]), Some(0.5));
        // 0.1 + 0.2 is not 0.3 in binary, yet it splits {0.1, 0.2 | 0.3} evenly.
        assert_eq!(
            weighted_median(vec![(1.0, 0.1), (2.0, 0.2), (3.0, 0.3)]),
            Some(2.5)
        );
        // A heavy value wins.
        assert_eq!(
            weighted_median(vec![(1.0, 1.0), (5.0, 3.0), (9.0, 1.0)]),
            Some(5.0)
        );
    }

    #[test]
    fn facing_panels_roll_onto_cylinders_without_stretching() {
        let mesh = tube(0.3, 0.15);
        let mut x = mesh.positions.clone();
        let body = cylinder(0.1);
        let n = x.len();
        let wrapped = wrap_panels_around_body(
            &mesh,
            &whole(n),
            &mut x,
            &frame(&body),
            &WrapOptions::default(),
        );
        assert_eq!(wrapped.len(), 2, "both panels face the body: {wrapped:?}");
        for w in &wrapped {
            assert!((w.radius_m - 0.15).abs() < 1e-9, "kept its distance: {w:?}");
            // 0.3 m of cloth around a radius of 0.15 m: 2 rad.
            assert!((w.span_deg - 2f64.to_degrees()).abs() < 0.5, "{w:?}");
        }
        for p in &x {
            assert!(
                (horizontal_radius(p) - 0.15).abs() < 1e-9,
                "off the cylinder: {p}"
            );
        }
        // Edges become chords of their arcs: at most θ²/24 shorter, θ = length / 15 cm (the
        // arc is no longer than the edge).
        for e in mesh.edges() {
            let (i, j) = (e[0] as usize, e[1] as usize);
            let before = (mesh.positions[i] - mesh.positions[j]).norm();
            let after = (x[i] - x[j]).norm();
            let theta = before / 0.15;
            assert!(
                after <= before + 1e-12 && after >= before * (1.0 - theta * theta / 24.0) - 1e-12,
                "{before} → {after}"
            );
        }
        // The side seams now close around the body, not across it.
        let (g0, g1) = (
            widest_seam_gap(&mesh, &mesh.positions),
            widest_seam_gap(&mesh, &x),
        );
        assert!(g1 < 0.75 * g0, "widest seam gap {g0} → {g1}");
    }

    #[test]
    fn a_sleeve_beside_the_torso_rolls_around_the_arm_it_covers() {
        // A vertical torso (r = 12 cm) and an arm (r = 4 cm) leaning out 45° from it, 0.3 m to
        // the side; a two-panel sleeve laid flat in front of and behind the arm, 8 cm from its
        // axis, along it. The sleeve faces away from the torso's axis: it rolls around the arm.
        let turn = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), -45f64.to_radians());
        let shift = Vector3::new(0.3, 0.0, 0.0);
        let torso = cylinder(0.12);
        let arm = cylinder(0.04);
        let arm_points: Vec<Vector3<f64>> = arm.0.iter().map(|p| turn * p + shift).collect();
        let mesh = tube(0.16, 0.08);
        let mut x: Vec<Vector3<f64>> = mesh.positions.iter().map(|p| turn * p + shift).collect();
        let placed = x.clone();
        let body = [
            ColliderFrame {
                points: &torso.0,
                triangles: &torso.1,
            },
            ColliderFrame {
                points: &arm_points,
                triangles: &arm.1,
            },
        ];
        let n = x.len();
        let wrapped =
            wrap_panels_around_body(&mesh, &whole(n), &mut x, &body, &WrapOptions::default());
        assert_eq!(wrapped.len(), 2, "both sleeve panels: {wrapped:?}");
        // On the cylinder 8 cm around the arm's axis (the arm's points fit it to within their
        // discretisation).
        let axis = turn * Vector3::y();
        for p in &x {
            let q = p - shift;
            let r = (q - axis * q.dot(&axis)).norm();
            assert!((r - 0.08).abs() < 3e-3, "{r} from the arm's axis");
        }
        let (g0, g1) = (widest_seam_gap(&mesh, &placed), widest_seam_gap(&mesh, &x));
        assert!(g1 < 0.75 * g0, "widest seam gap {g0} → {g1}");
    }

    #[test]
    fn panels_move_out_to_clear_the_body() {
        let mesh = tube(0.3, 0.15);
        let mut x = mesh.positions.clone();
        let body = cylinder(0.145);
        let n = x.len();
        let opts = WrapOptions::default();
        let wrapped = wrap_panels_around_body(&mesh, &whole(n), &mut x, &frame(&body), &opts);
        assert_eq!(wrapped.len(), 2);
        for w in &wrapped {
            assert!(w.radius_m >= 0.145 + opts.clearance_m - 1e-9, "{w:?}");
        }
        for p in &x {
            assert!(
                horizontal_radius(p) >= 0.145 + opts.clearance_m - 1e-9,
                "{p}"
            );
        }
        // Body all the way out from the panel's radius (an arm beside its path): the panel
        // stays flat rather than move far out.
        let layers: Vec<_> = (0..6).map(|k| cylinder(0.15 + 0.015 * k as f64)).collect();
        let frames: Vec<ColliderFrame<'_>> = layers.iter().map(|b| frame(b)[0]).collect();
        let mut x = mesh.positions.clone();
        assert!(wrap_panels_around_body(&mesh, &whole(n), &mut x, &frames, &opts).is_empty());
        assert_eq!(x, mesh.positions);
    }

    #[test]
    fn panels_that_do_not_face_the_body_stay_flat() {
        let body = cylinder(0.1);
        // Beside the body (a sleeve): facing along z but 0.4 m off to the side.
        let mut mesh = tube(0.1, 0.15);
        for p in &mut mesh.positions {
            p.x += 0.4;
        }
        let mut x = mesh.positions.clone();
        let n = x.len();
        let opts = WrapOptions::default();
        let wrapped = wrap_panels_around_body(&mesh, &whole(n), &mut x, &frame(&body), &opts);
        assert!(wrapped.is_empty(), "{wrapped:?}");
        assert_eq!(x, mesh.positions);
        // Too wide to roll around the body (a circle skirt's panel).
        let mesh = tube(1.5, 0.15);
        let mut x = mesh.positions.clone();
        let n = x.len();
        assert!(wrap_panels_around_body(&mesh, &whole(n), &mut x, &frame(&body), &opts).is_empty());
        assert_eq!(x, mesh.positions);
        // Lying flat (normal along y), and already bent (not flat).
        let mut flat = tube(0.3, 0.15);
        let mut bent = flat.clone();
        for p in &mut flat.positions {
            *p = Vector3::new(p.x, 0.1 + p.z * 0.01, p.y);
        }
        for p in &mut bent.positions {
            p.z += 0.2 * p.x * p.x * p.z.signum();
        }
        for mesh in [flat, bent] {
            let mut x = mesh.positions.clone();
            let n = x.len();
            assert!(
                wrap_panels_around_body(&mesh, &whole(n), &mut x, &frame(&body), &opts).is_empty()
            );
            assert_eq!(x, mesh.positions);
        }
        // No body at the garment's height.
        let mesh = tube(0.3, 0.15);
        let mut x = mesh.positions.clone();
        let high = (
            body.0.iter().map(|p| p + Vector3::y()).collect(),
            body.1.clone(),
        );
        let n = x.len();
        assert!(wrap_panels_around_body(&mesh, &whole(n), &mut x, &frame(&high), &opts).is_empty());
        assert_eq!(x, mesh.positions);
    }
}
