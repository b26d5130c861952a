//! Cloth vertices against collider faces: inside or outside, entry faces and contacts.

use nalgebra::Vector3;

use super::bvh::{Aabb, Bvh};
use super::crease::SHARP_EDGE_DEG;
use super::crossings::segment_crosses_triangle;
use super::distance::{point_triangle, TriangleFeature};
use super::repulsion::{face_normal, obstacle_eval_with, ObstacleEval};

pub(super) fn tri_points(pts: &[Vector3<f64>], t: &[u32; 3]) -> [Vector3<f64>; 3] {
    [pts[t[0] as usize], pts[t[1] as usize], pts[t[2] as usize]]
}

/// Interior angle of triangle `x` at local vertex `k`.
pub(super) fn corner_angle(x: &[Vector3<f64>; 3], k: usize) -> f64 {
    let e1 = x[(k + 1) % 3] - x[k];
    let e2 = x[(k + 2) % 3] - x[k];
    e1.angle(&e2)
}

/// The face of a collider through which the path `start` → `p` last went in: its unit
/// normal, and how far `p` is below its plane. A face counts where `start` is on or above its
/// plane, `p` below it, and the path passes through the triangle; of several (a path in, out
/// and in again), the last is the one the region `p` is in was entered by. Slivers, whose
/// normals are noise, do not count.
pub(super) fn entry_face(
    start: &Vector3<f64>,
    p: &Vector3<f64>,
    pts: &[Vector3<f64>],
    tris: &[[u32; 3]],
    bvh: &Bvh,
) -> Option<(Vector3<f64>, f64)> {
    let mut last: Option<(f64, Vector3<f64>, f64)> = None;
    bvh.query(&Aabb::from_points([start, p]), |t| {
        let [a, b, c] = tri_points(pts, &tris[t as usize]);
        // Slivers get no normal from `obstacle_eval_with` either (and so no contact).
        let Some((nrm, n2)) = face_normal(&a, &b, &c) else {
            return;
        };
        let n = nrm / n2.sqrt();
        let (above, below) = (n.dot(&(start - a)), -n.dot(&(p - a)));
        if above < 0.0 || below <= 0.0 || !segment_crosses_triangle(start, p, &a, &b, &c) {
            return;
        }
        let at = above / (above + below);
        if last.is_none_or(|f| at > f.0) {
            last = Some((at, n, below));
        }
    });
    last.map(|(_, n, below)| (n, below))
}

/// The closest surface point and the angle-weighted pseudo-normal (Bærentzen & Aanæs; not
/// normalised) of the faces of `cands` (gathered around a point) that tie for nearest at
/// `umin`: a point is inside where it lies behind that normal. `None` when none ties.
pub(super) fn nearest_side(
    pts: &[Vector3<f64>],
    tris: &[[u32; 3]],
    cands: &[(u32, ObstacleEval)],
    umin: f64,
) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let tie = 1e-12 + 1e-9 * umin;
    let mut pseudo = Vector3::zeros();
    let mut q: Option<Vector3<f64>> = None;
    for (t, e) in cands.iter() {
        if e.closest.dist > umin + tie {
            continue;
        }
        let x = tri_points(pts, &tris[*t as usize]);
        if q.is_none() {
            let b = e.closest.bary;
            q = Some(x[0] * b[0] + x[1] * b[1] + x[2] * b[2]);
        }
        if let Some(n) = e.normal {
            let w = match e.closest.feature {
                TriangleFeature::Vertex(k) => corner_angle(&x, k),
                _ => 1.0,
            };
            pseudo += n * w;
        }
    }
    q.map(|q| (q, pseudo))
}

/// Classifies cloth point `p` against one collider and calls `emit(face)` for each contact
/// face (module docs); `start`, where `p` began the step against this collider (`None`: not
/// known), gives the face an inside point came in through. `cands` is scratch space. Returns
/// the penetration depth (0 when outside or farther than `search`; below the entry face's
/// plane when the nearest face is turned away from it) and the clearance (0 when inside).
#[allow(clippy::too_many_arguments)]
pub(super) fn classify_vertex(
    p: &Vector3<f64>,
    start: Option<&Vector3<f64>>,
    pts: &[Vector3<f64>],
    tris: &[[u32; 3]],
    bvh: &Bvh,
    dhat: f64,
    search: f64,
    cands: &mut Vec<(u32, ObstacleEval)>,
    mut emit: impl FnMut(u32),
) -> (f64, f64) {
    let tri = |t: u32| tri_points(pts, &tris[t as usize]);
    let tie = |u: f64| 1e-12 + 1e-9 * u;
    // Gathers the faces within `r`, returning the nearest distance among them.
    let gather = |r: f64, cands: &mut Vec<(u32, ObstacleEval)>| {
        cands.clear();
        let mut umin = f64::INFINITY;
        bvh.query_ball(p, r, |t| {
            let [a, b, c] = tri(t);
            let closest = point_triangle(p, &a, &b, &c);
            if closest.dist <= r {
                umin = umin.min(closest.dist);
                cands.push((t, obstacle_eval_with(p, &a, &b, &c, closest)));
            }
        });
        umin
    };
    // Common case first: faces within d̂ (then the nearest one is among them).
    let mut rho = dhat;
    let mut umin = if dhat > 0.0 {
        gather(dhat, cands)
    } else {
        f64::INFINITY
    };
    if umin.is_infinite() || umin + tie(umin) > dhat {
        // None within d̂: is the vertex deep inside, or just away? One query, out to 4× the
        // search: beyond the search only the clearance needs the distance.
        let nearest = bvh.nearest(p, 4.0 * search, |t| {
            let [a, b, c] = tri(t);
            point_triangle(p, &a, &b, &c).dist
        });
        let u = match nearest {
            Some((_, u)) if u <= search => u,
            // No face within the search: far outside, or deeper inside than the search
            // reaches, where a full pass finds it (inside) once it comes within the search of
            // a face. Its side is unknown, so what is certified is how far it may move before
            // it can come within the search of a face: its distance beyond the search, which
            // the caller's test against d̂ then takes on top.
            _ => return (0.0, nearest.map_or(3.0 * search, |(_, u)| u - search)),
        };
        rho = u + dhat;
        umin = gather(rho, cands);
    }
    let (q, pseudo) = match nearest_side(pts, tris, cands, umin) {
        Some((q, n)) => (Some(q), n),
        None => (None, Vector3::zeros()),
    };
    let inside = umin > 0.0 && q.is_some_and(|q| (p - q).dot(&pseudo) < 0.0);
    if inside {
        // Where it is known, the face the vertex came in through decides which faces push it
        // out: those that meet it at a sharp angle do not (a vertex that came in through a
        // table's top near its edge is not pushed sideways by the side, nor one that came in
        // through the side upwards by the top). When even its nearest face is one of those,
        // it goes out the way it came: depth and reach are measured from the entry plane.
        let cos_sharp = SHARP_EDGE_DEG.to_radians().cos();
        let entry = start
            .filter(|s| *s != p)
            .and_then(|s| entry_face(s, p, pts, tris, bvh));
        let turned = entry.filter(|(n0, _)| {
            pseudo
                .try_normalize(0.0)
                .is_some_and(|m| m.dot(n0) < cos_sharp)
        });
        // Without an entry face: every face within the nearest one's distance plus d̂ (or the
        // faces already gathered, if further) that the vertex projects into and is below.
        let nearest_reach = rho.max(umin + dhat);
        let (depth, reach) = match turned {
            Some((_, below)) => (below, below + dhat),
            None => (umin, nearest_reach),
        };
        let mut gathered = rho;
        if gathered < reach {
            gather(reach, cands);
            gathered = reach;
        }
        let pushes = |e: &ObstacleEval, r: f64| {
            e.projects_inside && e.signed_plane < 0.0 && e.closest.dist <= r
        };
        let mut found = false;
        for (t, e) in cands.iter() {
            let aligned =
                entry.is_none_or(|(n0, _)| e.normal.is_some_and(|n| n.dot(&n0) >= cos_sharp));
            if pushes(e, reach) && aligned {
                emit(*t);
                found = true;
            }
        }
        if found || entry.is_none() {
            return (depth, 0.0);
        }
        // No face in line with the entry lies over it: the faces it would have without one.
        if gathered < nearest_reach {
            gather(nearest_reach, cands);
        }
        for (t, e) in cands.iter() {
            if pushes(e, nearest_reach) {
                emit(*t);
            }
        }
        (umin, 0.0)
    } else {
        for (t, e) in cands.iter() {
            if e.signed_plane >= 0.0 && e.closest.dist < dhat {
                emit(*t);
            }
        }
        (0.0, umin)
    }
}
