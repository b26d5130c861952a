//! Triangulating one polygon face (of a USD or OBJ mesh) by ear clipping in its own plane: a
//! concave face stays inside its outline, and corners on a straight side (a grid's outline)
//! make no zero-area triangle.

use nalgebra::{Vector2, Vector3};

/// Triangles (indices into `points`, in the polygon's winding) of the planar polygon `points`:
/// the fan from its first corner where every fan triangle is proper (a convex face), else by ear
/// clipping; `None` where it has no proper triangulation (self-intersecting, or of zero area).
pub fn triangulate_polygon(points: &[Vector3<f64>]) -> Option<Vec<[usize; 3]>> {
    let n = points.len();
    if n < 3 {
        return None;
    }
    if n == 3 {
        return Some(vec![[0, 1, 2]]);
    }
    let fan: Vec<[usize; 3]> = (1..n - 1).map(|j| [0, j, j + 1]).collect();
    // Newell's normal, and two axes of the plane it is normal to.
    let mut normal = Vector3::zeros();
    for i in 0..n {
        let (a, b) = (points[i], points[(i + 1) % n]);
        normal += Vector3::new(
            (a.y - b.y) * (a.z + b.z),
            (a.z - b.z) * (a.x + b.x),
            (a.x - b.x) * (a.y + b.y),
        );
    }
    let normal = normal.try_normalize(1e-300)?;
    let size = points
        .iter()
        .map(|q| (q - points[0]).norm())
        .fold(0.0, f64::max);
    let proper = |t: &[usize; 3]| {
        let (a, b, c) = (points[t[0]], points[t[1]], points[t[2]]);
        (b - a).cross(&(c - a)).dot(&normal) > 1e-9 * size * size
    };
    if fan.iter().all(proper) {
        return Some(fan);
    }
    let helper = if normal.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let u = normal.cross(&helper).normalize();
    let v = normal.cross(&u);
    // In (u, v) the polygon winds counter-clockwise (Newell's normal is its right-hand normal).
    let p: Vec<Vector2<f64>> = points
        .iter()
        .map(|q| Vector2::new(q.dot(&u), q.dot(&v)))
        .collect();
    let cross = |a: Vector2<f64>, b: Vector2<f64>, c: Vector2<f64>| (b - a).perp(&(c - a));
    let scale = p.iter().map(|q| q.norm()).fold(0.0, f64::max).max(1e-300);
    let eps = 1e-12 * scale * scale;
    let mut ring: Vec<usize> = (0..n).collect();
    let mut out = Vec::with_capacity(n - 2);
    while ring.len() > 3 {
        let m = ring.len();
        let ear = (0..m).find(|&k| {
            let (a, b, c) = (ring[(k + m - 1) % m], ring[k], ring[(k + 1) % m]);
            if cross(p[a], p[b], p[c]) <= eps {
                return false;
            }
            // No other corner inside (or on) the ear.
            ring.iter().all(|&q| {
                q == a
                    || q == b
                    || q == c
                    || cross(p[a], p[b], p[q]) < -eps
                    || cross(p[b], p[c], p[q]) < -eps
                    || cross(p[c], p[a], p[q]) < -eps
            })
        })?;
        let (a, b, c) = (ring[(ear + m - 1) % m], ring[ear], ring[(ear + 1) % m]);
        out.push([a, b, c]);
        ring.remove(ear);
    }
    let (a, b, c) = (ring[0], ring[1], ring[2]);
    if cross(p[a], p[b], p[c]) <= eps {
        return None;
    }
    out.push([a, b, c]);
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area(points: &[Vector3<f64>], tris: &[[usize; 3]]) -> f64 {
        tris.iter()
            .map(|t| {
                0.5 * (points[t[1]] - points[t[0]])
                    .cross(&(points[t[2]] - points[t[0]]))
                    .z
            })
            .sum()
    }

    #[test]
    fn a_concave_l_stays_inside_and_a_grid_outline_has_no_flat_triangle() {
        // An L of area 3 (unit squares), counter-clockwise.
        let l: Vec<Vector3<f64>> = [(0., 0.), (2., 0.), (2., 1.), (1., 1.), (1., 2.), (0., 2.)]
            .iter()
            .map(|&(x, y)| Vector3::new(x, y, 0.0))
            .collect();
        let t = triangulate_polygon(&l).expect("an L triangulates");
        assert_eq!(t.len(), 4);
        assert!((area(&l, &t) - 3.0).abs() < 1e-12);
        // A 2 × 2 square with a corner at the middle of each side: all used, none flat.
        let square: Vec<Vector3<f64>> = [
            (0., 0.),
            (1., 0.),
            (2., 0.),
            (2., 1.),
            (2., 2.),
            (1., 2.),
            (0., 2.),
            (0., 1.),
        ]
        .iter()
        .map(|&(x, y)| Vector3::new(x, y, 0.0))
        .collect();
        let t = triangulate_polygon(&square).expect("triangulates");
        assert_eq!(t.len(), 6);
        assert!((area(&square, &t) - 4.0).abs() < 1e-12);
        assert!(t.iter().all(|t| area(&square, &[*t]) > 1e-9));
        // Clockwise input keeps its winding.
        let cw: Vec<_> = l.iter().rev().copied().collect();
        let t = triangulate_polygon(&cw).expect("clockwise");
        assert!((area(&cw, &t) + 3.0).abs() < 1e-12);
    }
}
