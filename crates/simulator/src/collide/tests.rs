//! Detection against brute force, and its timing.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::distance::{point_triangle, segment_segment};
use super::repulsion::{obstacle_eval, ObstacleEval};
use super::*;
use super::{body::*, contact::*, detector::*, inside::*};
use crate::collide::distance::tests::Lcg;
use crate::energy::fd::check_psd;
use std::collections::{BTreeMap, BTreeSet};

/// A sphere of radius `r` around `c`: an octahedron with each face split into n² triangles,
/// projected to the sphere; counter-clockwise seen from outside.
fn sphere(c: Vector3<f64>, r: f64, n: usize) -> (Vec<Vector3<f64>>, Vec<[u32; 3]>) {
    let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
    let faces = [
        [x, y, z],
        [y, -x, z],
        [-x, -y, z],
        [-y, x, z],
        [y, x, -z],
        [-x, y, -z],
        [-y, -x, -z],
        [x, -y, -z],
    ];
    let mut pts = Vec::new();
    let mut tris = Vec::new();
    for [a, b, cc] in faces {
        let mut idx = vec![vec![0u32; n + 1]; n + 1];
        for (i, row) in idx.iter_mut().enumerate() {
            for (j, slot) in row.iter_mut().enumerate().take(n + 1 - i) {
                let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                let p = a * (1.0 - u - v) + b * u + cc * v;
                *slot = pts.len() as u32;
                pts.push(c + p.normalize() * r);
            }
        }
        for i in 0..n {
            for j in 0..n - i {
                tris.push([idx[i][j], idx[i + 1][j], idx[i][j + 1]]);
                if j + 1 < n - i {
                    tris.push([idx[i + 1][j], idx[i + 1][j + 1], idx[i][j + 1]]);
                }
            }
        }
    }
    (pts, tris)
}

/// A flat grid sheet of (m+1)² vertices at height z over [x0, x0 + m·h] × [y0, y0 + m·h].
fn sheet(m: usize, h: f64, o: Vector3<f64>) -> (Vec<Vector3<f64>>, Vec<[u32; 3]>) {
    let mut x = Vec::new();
    for i in 0..=m {
        for j in 0..=m {
            x.push(o + Vector3::new(i as f64 * h, j as f64 * h, 0.0));
        }
    }
    let id = |i: usize, j: usize| (i * (m + 1) + j) as u32;
    let mut t = Vec::new();
    for i in 0..m {
        for j in 0..m {
            t.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            t.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    (x, t)
}

fn edges_of(tris: &[[u32; 3]]) -> Vec<[u32; 2]> {
    let mut s = BTreeSet::new();
    for t in tris {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            s.insert([a.min(b), a.max(b)]);
        }
    }
    s.into_iter().collect()
}

#[test]
fn sphere_mesh_is_outward() {
    let (p, t) = sphere(Vector3::zeros(), 1.0, 4);
    for tri in &t {
        let [a, b, c] = tri_points(&p, tri);
        let n = (b - a).cross(&(c - a));
        assert!(n.dot(&(a + b + c)) > 0.0);
    }
}

/// Expected obstacle contacts by brute force over all faces: per vertex, the sorted contact
/// distances, and the penetration depth.
fn brute_obstacle(
    p: &Vector3<f64>,
    pts: &[Vector3<f64>],
    tris: &[[u32; 3]],
    dhat: f64,
) -> (Vec<f64>, f64) {
    let evals: Vec<ObstacleEval> = tris
        .iter()
        .map(|t| {
            let [a, b, c] = tri_points(pts, t);
            obstacle_eval(p, &a, &b, &c)
        })
        .collect();
    let umin = evals
        .iter()
        .map(|e| e.closest.dist)
        .fold(f64::INFINITY, f64::min);
    if umin > OBSTACLE_SEARCH_M.max(dhat) {
        return (vec![], 0.0);
    }
    // The sphere is convex: inside iff below every face plane.
    let inside = evals.iter().all(|e| e.signed_plane < 0.0);
    let mut d: Vec<f64> = if inside {
        evals
            .iter()
            .filter(|e| e.projects_inside && e.closest.dist <= umin + dhat)
            .map(|e| e.distance())
            .collect()
    } else {
        evals
            .iter()
            .filter(|e| e.signed_plane >= 0.0 && e.closest.dist < dhat)
            .map(|e| e.distance())
            .collect()
    };
    d.sort_by(f64::total_cmp);
    (d, if inside { umin } else { 0.0 })
}

/// Asserts the obstacle contacts of `x` equal brute force over all faces of the convex
/// collider; returns the expected per-vertex distances and the deepest penetration.
fn compare_with_brute(
    x: &[Vector3<f64>],
    contacts: &[Contact],
    pts: &[Vector3<f64>],
    tris: &[[u32; 3]],
    dhat: f64,
) -> (BTreeMap<u32, Vec<f64>>, f64) {
    let mut got: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
    for c in contacts {
        // Crease contacts are compared in their own test.
        if matches!(c, Contact::EdgeObstacle { .. }) {
            assert!(c.distance(x) < dhat);
            continue;
        }
        let Contact::VertexObstacle { v, .. } = c else {
            panic!("self contact with self_collision off");
        };
        got.entry(*v).or_default().push(c.distance(x));
        assert!(c.distance(x) < dhat);
        assert_eq!(c.cloth_dofs(), [Some(*v), None, None, None]);
    }
    for d in got.values_mut() {
        d.sort_by(f64::total_cmp);
    }
    let mut want: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
    let mut deepest: f64 = 0.0;
    for (v, p) in x.iter().enumerate() {
        let (d, depth) = brute_obstacle(p, pts, tris, dhat);
        deepest = deepest.max(depth);
        if !d.is_empty() {
            want.insert(v as u32, d);
        }
    }
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        want.keys().collect::<Vec<_>>()
    );
    for (v, d) in &want {
        assert_eq!(got[v].len(), d.len(), "vertex {v}");
        for (a, b) in got[v].iter().zip(d) {
            assert!((a - b).abs() < 1e-14);
        }
    }
    (want, deepest)
}

/// A cube [−0.1, 0.1]³, two counter-clockwise triangles per face.
pub(super) fn cube() -> (Vec<Vector3<f64>>, Vec<[u32; 3]>) {
    let pts: Vec<Vector3<f64>> = (0..8)
        .map(|i| {
            let c = |b: usize| if i & b != 0 { 0.1 } else { -0.1 };
            Vector3::new(c(1), c(2), c(4))
        })
        .collect();
    let quads = [
        [0, 2, 3, 1], // z−
        [4, 5, 7, 6], // z+
        [0, 1, 5, 4], // y−
        [2, 6, 7, 3], // y+
        [0, 4, 6, 2], // x−
        [1, 3, 7, 5], // x+
    ];
    let tris: Vec<[u32; 3]> = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    (pts, tris)
}

/// The contacts of one cloth vertex at `p` that began the step at `from` (a slice: one
/// of another length is tested too) against one collider, held still or not.
fn contacts_since(
    det: &mut CollisionDetector,
    p: Vector3<f64>,
    from: &[Vector3<f64>],
    still: bool,
    body: Collider<'_>,
    params: &CollisionParams,
) -> Vec<Contact> {
    let since = StepStart {
        x: from,
        still: &[still],
    };
    det.find_contacts_since(&[p], since, &[], &[], &[body], params)
}

/// A vertex that a step carried 1.7 mm through a cube's top, 0.5 mm in from its side, is
/// nearer the side: found alone it is pushed out sideways (a sheet landing on a table slid
/// off it so). Knowing where it began the step, it goes back out through the top, and
/// vertices whose nearest face is the one they came in by, or that began inside, are found
/// as before.
#[test]
fn a_vertex_that_came_in_through_the_top_near_an_edge_goes_back_out_through_it() {
    let (pts, tris) = cube();
    let params = CollisionParams {
        dhat_m: 0.001,
        kappa: 1e3,
        self_collision: false,
    };
    let bodies = [(pts.as_slice(), tris.as_slice())];
    let normals = |contacts: &[Contact]| -> Vec<Vector3<f64>> {
        contacts
            .iter()
            .map(|c| match c {
                Contact::VertexObstacle { tri: [a, b, c], .. } => {
                    (b - a).cross(&(c - a)).normalize()
                }
                other => panic!("not a vertex–obstacle contact: {other:?}"),
            })
            .collect()
    };
    let faces = |contacts: &[Contact]| -> Vec<[u32; 2]> {
        contacts
            .iter()
            .filter_map(|c| match c {
                Contact::VertexObstacle { face, .. } => Some(*face),
                _ => None,
            })
            .collect()
    };
    let mut det = CollisionDetector::new();
    let p = Vector3::new(0.0995, 0.0983, 0.02);
    let above = Vector3::new(0.098, 0.1004, 0.021);
    let alone = det.find_contacts(&[p], &[], &[], &bodies, &params);
    assert!(!alone.is_empty());
    for n in normals(&alone) {
        assert!((n - Vector3::x()).norm() < 1e-12, "nearest face {n}");
    }
    assert!((det.vertex_depths()[0] - 0.0005).abs() < 1e-12);

    let since = contacts_since(&mut det, p, &[above], true, bodies[0], &params);
    assert!(!since.is_empty());
    for n in normals(&since) {
        assert!((n - Vector3::y()).norm() < 1e-12, "entry face {n}");
    }
    assert!((det.vertex_depths()[0] - 0.0017).abs() < 1e-12);
    // Pushed up, not sideways: the repulsion's force on the vertex is along +y.
    let force: Vector3<f64> = since
        .iter()
        .map(|c| {
            let (_, g, _) = c.energy_gradient_hessian(&[p], &params);
            -Vector3::new(g[0], g[1], g[2])
        })
        .sum();
    assert!(
        force.y > 0.0 && force.x.abs() < 1e-9 * force.y,
        "force {force}"
    );

    // Came in through the side: its nearest face, as before.
    let beside = Vector3::new(0.1004, 0.0983, 0.02);
    let side = contacts_since(&mut det, p, &[beside], true, bodies[0], &params);
    assert_eq!(faces(&side), faces(&alone));
    // Began inside (a body that moved onto it): as before.
    let inside = Vector3::new(0.0990, 0.0990, 0.02);
    let began_in = contacts_since(&mut det, p, &[inside], true, bodies[0], &params);
    assert_eq!(faces(&began_in), faces(&alone));
    // Deep in the cube's middle, from above: the top is both nearest and entry.
    let q = Vector3::new(0.0, 0.098, 0.0);
    let middle = contacts_since(
        &mut det,
        q,
        &[q + Vector3::y() * 0.003],
        true,
        bodies[0],
        &params,
    );
    assert_eq!(
        faces(&middle),
        faces(&det.find_contacts(&[q], &[], &[], &bodies, &params))
    );
    // A start of another length than the positions is not used.
    let wrong = contacts_since(&mut det, p, &[above, above], true, bodies[0], &params);
    assert_eq!(faces(&wrong), faces(&alone));
    // Nearer the top it came in by, but within reach of the side: found alone, the side
    // pushes it too; knowing where it came from, only the top does.
    let r = Vector3::new(0.0985, 0.0990, 0.02);
    let alone = det.find_contacts(&[r], &[], &[], &bodies, &params);
    assert!(normals(&alone)
        .iter()
        .any(|n| (n - Vector3::x()).norm() < 1e-12));
    let since = contacts_since(&mut det, r, &[above], true, bodies[0], &params);
    assert!(!since.is_empty());
    for n in normals(&since) {
        assert!((n - Vector3::y()).norm() < 1e-12, "entry face {n}");
    }
    assert!((det.vertex_depths()[0] - 0.001).abs() < 1e-12);
    // A moving cube (held still: false): the nearest face, as alone.
    let moving = contacts_since(&mut det, p, &[above], false, bodies[0], &params);
    assert_eq!(
        faces(&moving),
        faces(&det.find_contacts(&[p], &[], &[], &bodies, &params))
    );
    // A faceted sphere (neighbouring faces 6–12° apart): from wherever outside a vertex
    // came in, the same contacts and depth as alone.
    let (spts, stris) = sphere(Vector3::zeros(), 0.1, 8);
    let ball = [(spts.as_slice(), stris.as_slice())];
    let mut rng = Lcg(5);
    for _ in 0..200 {
        let dir = rng.v3(1.0).normalize();
        let p = dir * (0.097 - 0.002 * rng.next());
        let from = p + dir * 0.012 + rng.v3(0.003);
        assert!(from.norm() > 0.1, "starts outside");
        let alone = det.find_contacts(&[p], &[], &[], &ball, &params);
        let depth = det.vertex_depths()[0];
        let since = contacts_since(&mut det, p, &[from], true, ball[0], &params);
        assert!(!alone.is_empty() && depth > 0.0);
        assert_eq!(faces(&since), faces(&alone), "at {p} from {from}");
        assert_eq!(det.vertex_depths()[0], depth);
    }
}

#[test]
fn cube_edges_and_corners_match_brute_force() {
    let (pts, tris) = cube();
    for t in &tris {
        let [a, b, c] = tri_points(&pts, t);
        assert!(
            (b - a).cross(&(c - a)).dot(&(a + b + c)) > 0.0,
            "cube orientation"
        );
    }
    // Points in a shell around the surface, many near edges and corners, some inside.
    let mut rng = Lcg(17);
    let x: Vec<Vector3<f64>> = (0..3000)
        .map(|_| {
            let p = rng.v3(0.115);
            // Snap some coordinates close to the faces to populate edge and corner regions.
            p.map(|c| {
                if rng.next() < 0.5 {
                    c.signum() * (0.1 + 0.01 * (rng.next() - 0.3))
                } else {
                    c
                }
            })
        })
        .collect();
    let dhat = 0.006;
    let params = CollisionParams {
        dhat_m: dhat,
        kappa: 1e3,
        self_collision: false,
    };
    let colliders: Vec<Collider> = vec![(&pts, &tris)];
    let contacts = find_contacts(&x, &[], &[], &colliders, &params);
    let (want, deepest) = compare_with_brute(&x, &contacts, &pts, &tris, dhat);
    assert!(want.len() > 500, "{} vertices in contact", want.len());
    assert!(deepest > 0.002);
    assert!((max_penetration(&x, &colliders) - deepest).abs() < 1e-15);
    // Every contact pushes its vertex away from the cube (outward along the SDF gradient),
    // or at worst sideways; the sum per vertex strictly outward.
    let mut total: BTreeMap<usize, (Vector3<f64>, Vector3<f64>)> = BTreeMap::new();
    for c in &contacts {
        let (_, g, _) = c.energy_gradient_hessian(&x, &params);
        let v = c.cloth_dofs()[0].map_or(0, |v| v as usize);
        let p = x[v];
        // Outward direction of the cube's distance field at p (for the box it is the
        // clamped-difference direction outside, the nearest-face normal inside).
        let q = p.map(|c| c.clamp(-0.1, 0.1));
        let out = if (p - q).norm() > 0.0 {
            (p - q).normalize()
        } else {
            let k = p.iamax();
            let mut n = Vector3::zeros();
            n[k] = p[k].signum();
            n
        };
        let f = -g.fixed_rows::<3>(0);
        assert!(
            f.dot(&out) > -1e-9 * f.norm(),
            "contact pulls vertex {v} inward: p {p:?}, d {}, f {f:?}",
            c.distance(&x)
        );
        total.entry(v).or_insert((Vector3::zeros(), out)).0 += f;
    }
    for (v, (f, out)) in total {
        assert!(f.dot(&out) > 0.0, "vertex {v}: net force {f:?} not outward");
    }
}

#[test]
fn sheet_above_sphere_finds_exactly_the_vertices_within_dhat() {
    let r = 0.3;
    let (spts, stris) = sphere(Vector3::zeros(), r, 12);
    let dhat = 0.01;
    // Sheet touching the top: the central vertices are within d̂ of the sphere.
    let (mut x, t) = sheet(20, 0.01, Vector3::new(-0.1, -0.1, r + 0.002));
    // Push a few vertices inside, one shallow one deeper, and lift one far away.
    x[220].z = r - 0.004;
    x[221].z = r - 0.02;
    x[0].z += 0.2;
    let e = edges_of(&t);
    let params = CollisionParams {
        dhat_m: dhat,
        kappa: 1e3,
        self_collision: false,
    };
    let colliders: Vec<Collider> = vec![(&spts, &stris)];
    let contacts = find_contacts(&x, &t, &e, &colliders, &params);
    let (want, deepest) = compare_with_brute(&x, &contacts, &spts, &stris, dhat);
    assert!(
        want.len() > 20 && want.len() < x.len() / 2,
        "{} vertices in contact",
        want.len()
    );
    assert!(want.contains_key(&220) && want.contains_key(&221) && !want.contains_key(&0));
    // Penetrating vertices have negative distances and get pushed outward.
    for c in contacts
        .iter()
        .filter(|c| matches!(c, Contact::VertexObstacle { v: 221, .. }))
    {
        assert!(c.distance(&x) < -0.015);
        let (e, g, h) = c.energy_gradient_hessian(&x, &params);
        assert!(e > 0.0 && (-g.fixed_rows::<3>(0)).dot(&x[221]) > 0.0);
        check_psd(&h);
    }
    let mp = max_penetration(&x, &colliders);
    assert!(
        (mp - deepest).abs() < 1e-15 && mp > 0.015 && mp < 0.02,
        "{mp} vs {deepest}"
    );
    let mut det = CollisionDetector::new();
    det.find_contacts(&x, &t, &e, &colliders, &params);
    assert_eq!(det.max_penetration(), mp);

    // The same through a detector that refits a moved collider.
    let shift = Vector3::new(0.0, 0.0, 0.003);
    let moved: Vec<Vector3<f64>> = spts.iter().map(|p| p + shift).collect();
    let colliders2: Vec<Collider> = vec![(&moved, &stris)];
    let again = det.find_contacts(&x, &t, &e, &colliders2, &params);
    let fresh = find_contacts(&x, &t, &e, &colliders2, &params);
    let key = |v: &[Contact]| {
        let mut s: Vec<String> = v.iter().map(|c| format!("{c:?}")).collect();
        s.sort();
        s
    };
    assert_eq!(key(&again), key(&fresh));
    assert!(again.len() > contacts.len());
}

#[test]
fn self_contacts_match_brute_force() {
    let (mut x, mut t) = sheet(6, 0.01, Vector3::zeros());
    let (x2, t2) = sheet(6, 0.01, Vector3::new(0.003, 0.002, 0.004));
    let off = x.len() as u32;
    x.extend(x2);
    t.extend(t2.iter().map(|tri| tri.map(|i| i + off)));
    // Crumple the top sheet a little.
    let mut rng = Lcg(9);
    for p in x.iter_mut().skip(off as usize) {
        p.z += 0.002 * rng.next();
    }
    let e = edges_of(&t);
    let dhat = 0.005;
    let params = CollisionParams {
        dhat_m: dhat,
        kappa: 1e3,
        self_collision: true,
    };
    let contacts = find_contacts(&x, &t, &e, &[], &params);
    let mut vt = BTreeSet::new();
    let mut ee = BTreeSet::new();
    for c in &contacts {
        match c {
            Contact::VertexTriangle { v, t } => assert!(vt.insert((*v, *t))),
            Contact::EdgeEdge { a, b } => assert!(ee.insert((*a, *b))),
            Contact::VertexObstacle { .. } | Contact::EdgeObstacle { .. } => {
                panic!("no colliders")
            }
        }
        assert!(c.distance(&x) < dhat);
        let (en, g, h) = c.energy_gradient_hessian(&x, &params);
        assert!(en > 0.0 && g.norm() > 0.0);
        check_psd(&h);
    }
    let mut want_vt = BTreeSet::new();
    for (v, p) in x.iter().enumerate() {
        for tri in &t {
            let [a, b, c] = tri_points(&x, tri);
            if !tri.contains(&(v as u32)) && point_triangle(p, &a, &b, &c).dist < dhat {
                want_vt.insert((v as u32, *tri));
            }
        }
    }
    let mut want_ee = BTreeSet::new();
    for (i, a) in e.iter().enumerate() {
        for b in &e[i + 1..] {
            let shared = a.contains(&b[0]) || a.contains(&b[1]);
            let d = segment_segment(
                &x[a[0] as usize],
                &x[a[1] as usize],
                &x[b[0] as usize],
                &x[b[1] as usize],
            )
            .dist;
            if !shared && d < dhat {
                want_ee.insert((*a, *b));
            }
        }
    }
    assert!(want_vt.len() > 30 && want_ee.len() > 30);
    assert_eq!(vt, want_vt);
    assert_eq!(ee, want_ee);
    // Off means off.
    let off = CollisionParams {
        self_collision: false,
        ..params
    };
    assert!(find_contacts(&x, &t, &e, &[], &off).is_empty());
}

/// Detection timings on an ~80K-triangle sphere with a 10K-vertex sheet draped on it (print
/// only; `--release -- --nocapture detection_timing`).
#[test]
fn detection_timing_80k_collider() {
    let r = 0.3;
    let (spts, stris) = sphere(Vector3::zeros(), r, 100);
    let (mut x, t) = sheet(99, 0.006, Vector3::new(-0.297, -0.297, 0.0));
    for p in x.iter_mut() {
        // Drape: lie on the sphere at 1 mm (plus noise) where above it, flat elsewhere.
        let rho2 = p.x * p.x + p.y * p.y;
        p.z = if rho2 < r * r {
            (r * r - rho2).sqrt() + 0.001
        } else {
            0.001
        };
    }
    let e = edges_of(&t);
    let colliders: Vec<Collider> = vec![(&spts, &stris)];
    let params = CollisionParams {
        dhat_m: 0.003,
        kappa: 1e3,
        self_collision: true,
    };
    let mut det = CollisionDetector::new();
    let t0 = std::time::Instant::now();
    let c1 = det.find_contacts(&x, &t, &e, &colliders, &params);
    let first = t0.elapsed();
    let best_of = |det: &mut CollisionDetector, p: &CollisionParams| {
        let mut best = std::time::Duration::MAX;
        let mut c = Vec::new();
        for _ in 0..5 {
            let t0 = std::time::Instant::now();
            c = det.find_contacts(&x, &t, &e, &colliders, p);
            best = best.min(t0.elapsed());
        }
        (c, best)
    };
    let (c2, refit) = best_of(&mut det, &params);
    let no_self = CollisionParams {
        self_collision: false,
        ..params
    };
    let (c3, obstacles_only) = best_of(&mut det, &no_self);
    let t0 = std::time::Instant::now();
    let s: f64 = c2
        .par_iter()
        .map(|c| c.energy_gradient_hessian(&x, &params).0)
        .sum();
    let eval = t0.elapsed();
    let t0 = std::time::Instant::now();
    let mp = max_penetration(&x, &colliders);
    let pen = t0.elapsed();
    println!(
        "detection: {} collider tris, {} cloth verts / {} tris / {} edges, {} threads: first call {:?}, refit call {:?} ({} contacts), obstacles only {:?} ({} contacts), parallel GN eval {:?} (E = {s:.3e}), max_penetration from scratch {:?} ({mp})",
        stris.len(),
        x.len(),
        t.len(),
        e.len(),
        rayon::current_num_threads(),
        first,
        refit,
        c2.len(),
        obstacles_only,
        c3.len(),
        eval,
        pen
    );
    assert_eq!(c1, c2);
    assert!(c2.len() > 1000);
}

/// A detector keeps a collider's hierarchy and creases while its points stay where they were
/// (dressing holds the body still; a step's Newton iterations see one collider frame): called
/// again on the same cube it finds what a new detector finds, and once the cube has moved
/// (with the cloth draped over its edge) it finds what a new detector finds there, crease
/// contacts and surface turns included.
#[test]
fn a_collider_held_still_or_moved_gives_a_new_detectors_contacts() {
    let (cube_pts, cube_tris) = cube();
    // A sheet over the cube's top edge at x = 0.1: half on the top, half hanging past it.
    let (sheet_x, sheet_tris) = sheet(12, 0.01, Vector3::new(0.04, -0.06, 0.1015));
    let edges = edges_of(&sheet_tris);
    let params = CollisionParams {
        dhat_m: 0.003,
        kappa: 1e3,
        self_collision: false,
    };
    let fresh = |x: &[Vector3<f64>], pts: &[Vector3<f64>]| {
        let mut det = CollisionDetector::new();
        det.surface_turns = true;
        let contacts = det.find_contacts(x, &sheet_tris, &edges, &[(pts, &cube_tris)], &params);
        (format!("{contacts:?}"), det)
    };
    let mut kept = CollisionDetector::new();
    kept.surface_turns = true;
    let mut sheet_now = sheet_x.clone();
    let mut cube_now = cube_pts.clone();
    for call in 0..40 {
        // Still for a while, then moving by 1 mm a call, then still again.
        if (10..25).contains(&call) {
            let d = Vector3::new(0.001, 0.0005, 0.0);
            cube_now.iter_mut().for_each(|p| *p += d);
            sheet_now.iter_mut().for_each(|p| *p += d);
        }
        let got = kept.find_contacts(
            &sheet_now,
            &sheet_tris,
            &edges,
            &[(&cube_now, &cube_tris)],
            &params,
        );
        let (want, new_det) = fresh(&sheet_now, &cube_now);
        assert!(
            got.iter()
                .any(|c| matches!(c, Contact::EdgeObstacle { .. })),
            "call {call}: the sheet meets the cube's edge"
        );
        assert_eq!(format!("{got:?}"), want, "call {call}");
        // Surface turns follow the cube: its top edge where it is now, not where it was.
        let edge_mid = Vector3::new(0.1, 0.0, 0.1) + (cube_now[0] - cube_pts[0]);
        assert!(kept.crease_within(0, &edge_mid, 1e-4), "call {call}");
        let first_place = Vector3::new(0.1, 0.0, 0.1);
        assert_eq!(
            kept.crease_within(0, &first_place, 1e-4),
            new_det.crease_within(0, &first_place, 1e-4),
            "call {call}"
        );
    }
}
