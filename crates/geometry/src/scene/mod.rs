//! A scene: garments (sewing patterns or meshes with material coordinates), colliders (static or
//! animated triangle meshes: avatars, balls, tables), gravity, time step, frame rate and range.

use nalgebra::Vector3;

use crate::garment::{Fabric, Garment};
use crate::mesh::ClothMesh;

pub mod catalogue;
pub mod samples;

/// Default simulation time step (the paper's 1/300 s).
pub const DEFAULT_DT_S: f64 = 1.0 / 300.0;
/// Default output frame rate.
pub const DEFAULT_FPS: f64 = 30.0;

/// A garment already meshed (from OBJ or USD), with its fabric.
#[derive(Debug, Clone)]
pub struct ClothPiece {
    /// Name.
    pub name: String,
    /// Mesh with material coordinates.
    pub mesh: ClothMesh,
    /// Fabric.
    pub fabric: Fabric,
}

/// A collision body: fixed triangles, points at one or more times (linearly interpolated).
#[derive(Debug, Clone, PartialEq)]
pub struct Collider {
    /// Name.
    pub name: String,
    /// Triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Time of each frame, seconds (one entry for a static body).
    pub times_s: Vec<f64>,
    /// Points per frame, metres, y up.
    pub frames: Vec<Vec<Vector3<f32>>>,
}

impl Collider {
    /// A static collider.
    pub fn fixed(name: &str, positions: Vec<Vector3<f64>>, triangles: Vec<[u32; 3]>) -> Self {
        Collider {
            name: name.into(),
            triangles,
            times_s: vec![0.0],
            frames: vec![positions.iter().map(|p| p.cast::<f32>()).collect()],
        }
    }

    /// Number of points.
    pub fn num_points(&self) -> usize {
        self.frames.first().map_or(0, Vec::len)
    }

    /// Whether the points move.
    pub fn is_animated(&self) -> bool {
        self.frames.len() > 1
    }

    /// Points at time `t_s`, linearly interpolated between frames and held outside their range.
    pub fn positions_at(&self, t_s: f64, out: &mut Vec<Vector3<f64>>) {
        out.clear();
        let k = self.times_s.partition_point(|&t| t <= t_s);
        let (i, j, w) = if k == 0 {
            (0, 0, 0.0)
        } else if k >= self.times_s.len() {
            (k - 1, k - 1, 0.0)
        } else {
            let (t0, t1) = (self.times_s[k - 1], self.times_s[k]);
            (k - 1, k, (t_s - t0) / (t1 - t0))
        };
        out.extend(
            self.frames[i]
                .iter()
                .zip(&self.frames[j])
                .map(|(a, b)| a.cast::<f64>() * (1.0 - w) + b.cast::<f64>() * w),
        );
    }

    /// Scales the collider about the origin by `scale`, then moves it by `offset_m`.
    pub fn transformed(mut self, scale: f64, offset_m: Vector3<f64>) -> Self {
        let off = offset_m.cast::<f32>();
        for frame in &mut self.frames {
            for p in frame.iter_mut() {
                *p = *p * scale as f32 + off;
            }
        }
        self
    }

    /// An icosphere of `radius` around `centre` (`subdivisions` = 3 gives 642 points).
    pub fn sphere(name: &str, centre: Vector3<f64>, radius: f64, subdivisions: usize) -> Self {
        let t = (1.0 + 5f64.sqrt()) / 2.0;
        let mut pts: Vec<Vector3<f64>> = [
            (-1.0, t, 0.0),
            (1.0, t, 0.0),
            (-1.0, -t, 0.0),
            (1.0, -t, 0.0),
            (0.0, -1.0, t),
            (0.0, 1.0, t),
            (0.0, -1.0, -t),
            (0.0, 1.0, -t),
            (t, 0.0, -1.0),
            (t, 0.0, 1.0),
            (-t, 0.0, -1.0),
            (-t, 0.0, 1.0),
        ]
        .iter()
        .map(|&(x, y, z)| Vector3::new(x, y, z).normalize())
        .collect();
        let mut tris: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..subdivisions {
            let mut mid = std::collections::HashMap::new();
            let mut next = Vec::with_capacity(tris.len() * 4);
            let mut midpoint = |a: u32, b: u32, pts: &mut Vec<Vector3<f64>>| {
                *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    pts.push(((pts[a as usize] + pts[b as usize]) * 0.5).normalize());
                    (pts.len() - 1) as u32
                })
            };
            for [a, b, c] in tris {
                let ab = midpoint(a, b, &mut pts);
                let bc = midpoint(b, c, &mut pts);
                let ca = midpoint(c, a, &mut pts);
                next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            tris = next;
        }
        let pts = pts.into_iter().map(|p| centre + p * radius).collect();
        Collider::fixed(name, pts, tris)
    }

    /// An axis-aligned box from `min` to `max` (12 triangles, outward facing).
    pub fn cuboid(name: &str, min: Vector3<f64>, max: Vector3<f64>) -> Self {
        let pts = (0..8)
            .map(|i| {
                Vector3::new(
                    if i & 1 == 0 { min.x } else { max.x },
                    if i & 2 == 0 { min.y } else { max.y },
                    if i & 4 == 0 { min.z } else { max.z },
                )
            })
            .collect();
        let tris = vec![
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ];
        Collider::fixed(name, pts, tris)
    }
}

/// Everything one simulation needs.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Garments given as sewing patterns (meshed at the resolution a stage asks for).
    pub garments: Vec<Garment>,
    /// Garments given as meshes.
    pub cloths: Vec<ClothPiece>,
    /// Collision bodies.
    pub colliders: Vec<Collider>,
    /// Gravity, m/s².
    pub gravity_m_s2: Vector3<f64>,
    /// Simulation time step, s.
    pub dt_s: f64,
    /// Output frames per second.
    pub fps: f64,
    /// First output frame.
    pub frame_start: i64,
    /// Last output frame.
    pub frame_end: i64,
    /// Where the garments and cloth meshes read from a USD stage are in it, by name: a
    /// layered output writes each fine mesh back at its prim.
    pub sources: std::collections::BTreeMap<String, PrimSource>,
    /// Garments with seams are dressed this long before the first frame, on the bodies as
    /// they were then (an easier pose than mid-stride: legs together, arms down), carried back
    /// with the bodies' walk ([`root_motion`]), and then worn through the motion up to the
    /// first frame, s. Zero: dressed on the first frame.
    pub preroll_s: f64,
}

/// The horizontal (x, z) move of the animated colliders' point centroid from time `from_s` to
/// `to_s`, m (zero without animated colliders): how far the bodies walked.
pub fn root_motion(colliders: &[Collider], from_s: f64, to_s: f64) -> Vector3<f64> {
    let (mut start, mut then, mut n) = (Vector3::zeros(), Vector3::zeros(), 0usize);
    let mut buf = Vec::new();
    for c in colliders.iter().filter(|c| c.is_animated()) {
        c.positions_at(from_s, &mut buf);
        start += buf.iter().sum::<Vector3<f64>>();
        c.positions_at(to_s, &mut buf);
        then += buf.iter().sum::<Vector3<f64>>();
        n += buf.len();
    }
    if n == 0 {
        return Vector3::zeros();
    }
    let d = (then - start) / n as f64;
    Vector3::new(d.x, 0.0, d.z)
}

/// A garment's prim in the USD file it was read from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PrimSource {
    /// The file (the stage's root layer).
    pub file: std::path::PathBuf,
    /// The prim's path.
    pub prim: String,
}

impl Scene {
    /// Adds `other`'s garments, cloth meshes and colliders to this scene (several garments on
    /// one avatar), keeping this scene's timing and gravity. A name already taken gets a
    /// suffix (`skirt_2`), so that every garment has its own prim in USD.
    pub fn merge(&mut self, other: Scene) {
        let mut taken: std::collections::HashSet<String> = self
            .garments
            .iter()
            .map(|g| g.name.clone())
            .chain(self.cloths.iter().map(|c| c.name.clone()))
            .collect();
        let mut unique = |name: &str| {
            let mut candidate = name.to_string();
            let mut k = 1;
            while taken.contains(&candidate) {
                k += 1;
                candidate = format!("{name}_{k}");
            }
            taken.insert(candidate.clone());
            candidate
        };
        let mut sources = other.sources;
        let mut renamed = |name: &mut String| {
            let new = unique(name);
            if let Some(s) = sources.remove(name.as_str()) {
                self.sources.insert(new.clone(), s);
            }
            *name = new;
        };
        for mut g in other.garments {
            renamed(&mut g.name);
            self.garments.push(g);
        }
        for mut c in other.cloths {
            renamed(&mut c.name);
            self.cloths.push(c);
        }
        let mut bodies: std::collections::HashSet<String> =
            self.colliders.iter().map(|c| c.name.clone()).collect();
        for mut c in other.colliders {
            let name = c.name.clone();
            let mut k = 1;
            while bodies.contains(&c.name) {
                k += 1;
                c.name = format!("{name}_{k}");
            }
            bodies.insert(c.name.clone());
            self.colliders.push(c);
        }
    }
}

impl Default for Scene {
    fn default() -> Self {
        Scene {
            garments: Vec::new(),
            cloths: Vec::new(),
            colliders: Vec::new(),
            gravity_m_s2: Vector3::new(0.0, -9.81, 0.0),
            dt_s: DEFAULT_DT_S,
            fps: DEFAULT_FPS,
            frame_start: 0,
            frame_end: 0,
            sources: Default::default(),
            preroll_s: 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merged_scenes_keep_every_garment_and_body_under_its_own_name() {
        let shot = |name| catalogue::scene(name, 10).expect("a catalogue shot");
        let mut scene = shot("square-silk-sphere-still");
        scene.fps = 24.0;
        scene.merge(shot("strip-denim-sphere-still"));
        scene.merge(shot("square-cotton-cube-still"));
        assert_eq!(scene.garments.len(), 3);
        assert_eq!(scene.fps, 24.0, "the first scene's timing stays");
        let names: std::collections::HashSet<_> =
            scene.garments.iter().map(|g| g.name.as_str()).collect();
        assert_eq!(names.len(), 3, "garment names must differ: {names:?}");
        let bodies: std::collections::HashSet<_> =
            scene.colliders.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(bodies.len(), scene.colliders.len(), "{bodies:?}");
        assert_eq!(scene.colliders.len(), 6);
    }
}
