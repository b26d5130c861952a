//! The scenes the generic models are trained on and measured with: procedural shots named
//! `garment-fabric-collider-motion` (e.g. `square-silk-sphere-still`), any combination of the
//! parts below. [`TRAINING`] and [`HELD_OUT`] are the two fixed lists; `clothsr lab scenes`
//! writes them as USD.
//!
//! Every shot drops a flat garment from 2 cm above a collider whose top is 0.3 m high, over a
//! floor; the collider then moves (or not) for the whole shot. Motions turn or move the whole
//! collider about the centre of its points, so they are rigid and smooth in time.

use nalgebra::{Rotation3, Vector2, Vector3};

use super::{Collider, Scene};
use crate::garment::{Curve, Fabric, Garment, Panel, PanelEdge, Placement};

/// Garment shapes: a 0.5 m square, a 0.6 × 0.3 m strip, a disc of radius 0.27 m (a 12-gon of
/// curved edges).
pub const GARMENTS: [&str; 3] = ["square", "strip", "disc"];
/// Fabrics: the four presets, and the halfway mixes of neighbouring ones (every parameter the
/// geometric mean of the two presets').
pub const FABRICS: [&str; 7] = [
    "silk",
    "cotton",
    "denim",
    "leather",
    "silk_cotton",
    "cotton_denim",
    "denim_leather",
];
/// Colliders: a sphere of radius 0.15 m, three balls of 0.07 m, a table edge, a cube turned
/// 45° about the vertical, a horizontal bar of radius 4 cm.
pub const COLLIDERS: [&str; 5] = ["sphere", "balls", "table", "cube", "bar"];
/// Motions: none; sliding sideways ±6 cm every 2 s; spinning at 60°/s about the vertical
/// through the garment's centre;
/// rising 8 cm over the first second; swinging ±20° about a horizontal axis every 1.6 s.
pub const MOTIONS: [&str; 5] = ["still", "slide", "spin", "rise", "swing"];

/// The generic models' training shots. Never in it: the disc, the bar, the swing, and the
/// fabrics `silk_cotton` and `denim_leather` (kept for [`HELD_OUT`]). The last two are
/// avatar shots ([`AVATAR`]).
pub const TRAINING: [&str; 26] = [
    "square-silk-sphere-still",
    "square-cotton-table-still",
    "square-denim-balls-still",
    "square-leather-cube-still",
    "strip-cotton-sphere-still",
    "strip-silk-balls-still",
    "strip-cotton_denim-table-still",
    "strip-denim-cube-still",
    "square-cotton-sphere-slide",
    "square-silk-table-slide",
    "strip-leather-balls-slide",
    "strip-cotton_denim-cube-slide",
    "square-cotton_denim-sphere-spin",
    "square-denim-cube-spin",
    "strip-silk-balls-spin",
    "strip-cotton-table-spin",
    "square-leather-table-rise",
    "square-silk-balls-rise",
    "strip-denim-sphere-rise",
    "strip-cotton-cube-rise",
    "square-silk-cube-still",
    "square-cotton-balls-still",
    "strip-leather-sphere-still",
    "strip-silk-table-still",
    "miniskirt-cotton-avatar-walk",
    "miniskirt-denim-avatar-walk",
];

/// The collider and motion of avatar shots, `miniskirt-FABRIC-avatar-walk`: a two-panel
/// A-line skirt 28 cm long at the waist of the walking avatar, which the shot does not hold:
/// give it with `--avatar` (`tests/data/avatars`).
pub const AVATAR: &str = "avatar-walk";

/// Shots no generic model is trained on: an unseen garment (the disc), collider (the bar),
/// motion (the swing) and fabrics (the mixes `silk_cotton`, `denim_leather`).
pub const HELD_OUT: [&str; 3] = [
    "disc-silk_cotton-sphere-still",
    "square-denim_leather-bar-still",
    "strip-cotton-balls-swing",
];

/// Height of every collider's top, m.
const TOP_M: f64 = 0.3;
/// Garments start this far above it, m.
const DROP_M: f64 = 0.02;
/// Output frame rate of the shots, and of the colliders' animation.
const FPS: f64 = 30.0;

/// The shot called `name` (`garment-fabric-collider-motion`, each from the lists above) with
/// `frames` output frames; `None` for a name that is not one.
pub fn scene(name: &str, frames: usize) -> Option<Scene> {
    let parts: Vec<&str> = name.split('-').collect();
    let [garment, fabric, collider, motion] = parts.as_slice() else {
        return None;
    };
    let fabric = fabric_named(fabric)?;
    if (*collider, *motion) == ("avatar", "walk") {
        return (*garment == "miniskirt").then(|| Scene {
            garments: vec![miniskirt(fabric)],
            fps: FPS,
            frame_end: frames as i64,
            ..Scene::default()
        });
    }
    let garment = garment_named(garment, fabric)?;
    let body = collider_named(collider)?;
    let duration_s = frames as f64 / FPS;
    let body = animate(body, motion, duration_s)?;
    let floor = Collider::cuboid(
        "floor",
        Vector3::new(-1.0, -0.02, -1.0),
        Vector3::new(1.0, 0.0, 1.0),
    );
    Some(Scene {
        garments: vec![garment],
        colliders: vec![body, floor],
        fps: FPS,
        frame_end: frames as i64,
        ..Scene::default()
    })
}

/// A preset, or the mix `a_b` of two presets.
pub fn fabric_named(name: &str) -> Option<Fabric> {
    if let Some((a, b)) = name.split_once('_') {
        let (a, b) = (Fabric::preset(a)?, Fabric::preset(b)?);
        let mid = |x: f64, y: f64| (x * y).sqrt();
        return Some(Fabric {
            name: name.to_string(),
            areal_density_kg_m2: mid(a.areal_density_kg_m2, b.areal_density_kg_m2),
            stretch_warp_n_m: mid(a.stretch_warp_n_m, b.stretch_warp_n_m),
            stretch_weft_n_m: mid(a.stretch_weft_n_m, b.stretch_weft_n_m),
            shear_n_m: mid(a.shear_n_m, b.shear_n_m),
            bending_n_m: mid(a.bending_n_m, b.bending_n_m),
            thickness_m: mid(a.thickness_m, b.thickness_m),
            damping_s: mid(a.damping_s, b.damping_s),
        });
    }
    Fabric::preset(name)
}

/// A flat garment facing +y, centred over the collider, `DROP_M` above its top.
fn garment_named(name: &str, fabric: Fabric) -> Option<Garment> {
    let centre = Vector3::new(0.0, TOP_M + DROP_M, 0.0);
    let panel = match name {
        "square" => rectangle(0.5, 0.5, centre),
        "strip" => rectangle(0.6, 0.3, centre),
        "disc" => disc(0.27, 12, centre),
        _ => return None,
    };
    Some(Garment {
        name: name.into(),
        panels: vec![panel],
        seams: Vec::new(),
        fabric,
    })
}

/// The sample skirt ([`super::samples::skirt`]) cut to 28 cm: its panels' sides keep their
/// slope, so the hem is narrower.
fn miniskirt(fabric: Fabric) -> Garment {
    let mut g = super::samples::skirt(fabric);
    g.name = "miniskirt".into();
    for p in &mut g.panels {
        // Vertices 0 and 1 are the hem's ends, at -0.55 below the waist, ±0.36 wide; the
        // waist's ends are ±0.19 wide.
        let (len, hem_half) = (0.28, 0.19 + (0.36 - 0.19) * 0.28 / 0.55);
        p.vertices[0] = Vector2::new(-hem_half, -len);
        p.vertices[1] = Vector2::new(hem_half, -len);
        p.edges[0].curve = Curve::Quadratic {
            control: Vector2::new(0.0, -len - 0.035),
        };
    }
    g
}

/// Rx(-90°) maps a panel's (u, v, 0) to (u, 0, -v): the panel lies flat, facing +y.
fn flat(translation_m: Vector3<f64>) -> Placement {
    Placement {
        translation_m,
        rotation_xyz_deg: Vector3::new(-90.0, 0.0, 0.0),
    }
}

fn rectangle(w: f64, h: f64, centre: Vector3<f64>) -> Panel {
    Panel::rectangle(
        "sheet",
        w,
        h,
        flat(centre + Vector3::new(-0.5 * w, 0.0, 0.5 * h)),
    )
}

/// A regular `n`-gon of radius `r` whose edges are quadratic curves through the circle at
/// their middles.
fn disc(r: f64, n: usize, centre: Vector3<f64>) -> Panel {
    let at = |k: f64| {
        let a = std::f64::consts::TAU * k / n as f64;
        Vector2::new(a.cos(), a.sin()) * r
    };
    let vertices: Vec<Vector2<f64>> = (0..n).map(|k| at(k as f64)).collect();
    let edges = (0..n)
        .map(|k| {
            let (a, b) = (vertices[k], vertices[(k + 1) % n]);
            // A quadratic's middle is (a + 2c + b) / 4: put it on the circle.
            let control = at(k as f64 + 0.5) * 2.0 - (a + b) * 0.5;
            PanelEdge {
                start: k,
                end: (k + 1) % n,
                curve: Curve::Quadratic { control },
            }
        })
        .collect();
    Panel {
        name: "sheet".into(),
        vertices,
        edges,
        placement: flat(centre),
    }
}

/// The collider `name`, at rest, its top at `TOP_M`.
fn collider_named(name: &str) -> Option<Collider> {
    let c = match name {
        "sphere" => Collider::sphere("sphere", Vector3::new(0.0, TOP_M - 0.15, 0.0), 0.15, 4),
        "balls" => {
            let (r, ring) = (0.07, 0.12);
            let mut balls = Vec::new();
            for a in [90.0f64, 210.0, 330.0] {
                let (s, c) = a.to_radians().sin_cos();
                let centre = Vector3::new(ring * c, TOP_M - r, ring * s);
                balls.push(Collider::sphere("ball", centre, r, 3));
            }
            merge("balls", balls)
        }
        "table" => Collider::cuboid(
            "table",
            Vector3::new(-0.5, 0.0, -0.5),
            Vector3::new(0.1, TOP_M, 0.5),
        ),
        "cube" => {
            let h = 0.1;
            let cube = Collider::cuboid(
                "cube",
                Vector3::new(-h, TOP_M - 2.0 * h, -h),
                Vector3::new(h, TOP_M, h),
            );
            let turn = Rotation3::from_axis_angle(&Vector3::y_axis(), 45f64.to_radians());
            rigid(&cube, |p| turn * p)
        }
        "bar" => cylinder("bar", 0.04, 0.8, Vector3::new(0.0, TOP_M - 0.04, 0.0), 24),
        _ => return None,
    };
    Some(c)
}

/// One collider of all of `parts`' triangles (each static).
fn merge(name: &str, parts: Vec<Collider>) -> Collider {
    let mut points = Vec::new();
    let mut triangles = Vec::new();
    for p in parts {
        let base = points.len() as u32;
        triangles.extend(p.triangles.iter().map(|t| t.map(|i| i + base)));
        points.extend(p.frames[0].iter().map(|q| q.cast::<f64>()));
    }
    Collider::fixed(name, points, triangles)
}

/// A closed cylinder of radius `r` and length `len` along z around `centre`, `n` sides.
fn cylinder(name: &str, r: f64, len: f64, centre: Vector3<f64>, n: usize) -> Collider {
    let mut points = Vec::with_capacity(2 * n + 2);
    for z in [-0.5 * len, 0.5 * len] {
        for k in 0..n {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            points.push(centre + Vector3::new(r * a.cos(), r * a.sin(), z));
        }
    }
    let (c0, c1) = (2 * n as u32, 2 * n as u32 + 1);
    points.push(centre - Vector3::new(0.0, 0.0, 0.5 * len));
    points.push(centre + Vector3::new(0.0, 0.0, 0.5 * len));
    let mut triangles = Vec::with_capacity(4 * n);
    let n32 = n as u32;
    for k in 0..n32 {
        let k1 = (k + 1) % n32;
        // Sides (outward: counter-clockwise seen from outside), then the two caps.
        triangles.push([k, k1, n32 + k1]);
        triangles.push([k, n32 + k1, n32 + k]);
        triangles.push([c0, k1, k]);
        triangles.push([c1, n32 + k, n32 + k1]);
    }
    Collider::fixed(name, points, triangles)
}

/// `c`'s points moved by `f`.
fn rigid(c: &Collider, f: impl Fn(Vector3<f64>) -> Vector3<f64>) -> Collider {
    let points = c.frames[0].iter().map(|p| f(p.cast::<f64>())).collect();
    Collider::fixed(&c.name, points, c.triangles.clone())
}

/// A rigid motion at one time: turn about the body's pivot, then move.
type Pose = (Rotation3<f64>, Vector3<f64>);

/// `body` moving by `motion` for `duration_s` (one frame of the shot's rate per sample).
fn animate(body: Collider, motion: &str, duration_s: f64) -> Option<Collider> {
    let pivot = {
        let pts = &body.frames[0];
        pts.iter().map(|p| p.cast::<f64>()).sum::<Vector3<f64>>() / pts.len().max(1) as f64
    };
    let pose: Box<dyn Fn(f64) -> Pose> = match motion {
        "still" => return Some(body),
        "slide" => Box::new(|t: f64| {
            let x = 0.06 * (std::f64::consts::TAU * t / 2.0).sin();
            (Rotation3::identity(), Vector3::new(x, 0.0, 0.0))
        }),
        // About the vertical through the garment's centre, not the body's: a table turned
        // about its own middle would sweep its edge out from under the cloth.
        "spin" => Box::new(move |t: f64| {
            let r = Rotation3::from_axis_angle(&Vector3::y_axis(), 60f64.to_radians() * t);
            let centre = Vector3::new(0.0, pivot.y, 0.0);
            // Turning about `centre` instead of the pivot the caller applies.
            (r, (centre - pivot) - r * (centre - pivot))
        }),
        "rise" => Box::new(|t: f64| {
            let s = t.clamp(0.0, 1.0);
            let y = 0.08 * s * s * (3.0 - 2.0 * s);
            (Rotation3::identity(), Vector3::new(0.0, y, 0.0))
        }),
        "swing" => Box::new(|t: f64| {
            let a = 20f64.to_radians() * (std::f64::consts::TAU * t / 1.6).sin();
            (
                Rotation3::from_axis_angle(&Vector3::z_axis(), a),
                Vector3::zeros(),
            )
        }),
        _ => return None,
    };
    let samples = (duration_s * FPS).ceil() as usize + 1;
    let rest: Vec<Vector3<f64>> = body.frames[0].iter().map(|p| p.cast::<f64>()).collect();
    let mut times_s = Vec::with_capacity(samples);
    let mut frames = Vec::with_capacity(samples);
    for k in 0..samples {
        let t = k as f64 / FPS;
        let (r, d) = pose(t);
        times_s.push(t);
        frames.push(
            rest.iter()
                .map(|p| (r * (p - pivot) + pivot + d).cast::<f32>())
                .collect(),
        );
    }
    Some(Collider {
        times_s,
        frames,
        ..body
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_shot_is_a_scene_with_a_valid_garment() {
        for name in TRAINING.iter().chain(&HELD_OUT) {
            let s = scene(name, 30).unwrap_or_else(|| panic!("{name} is not a shot"));
            assert_eq!(s.garments.len(), 1);
            s.garments[0]
                .validate()
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(s.frame_end, 30);
        }
        assert!(scene("square-silk-sphere", 30).is_none());
        assert!(scene("square-wool-sphere-still", 30).is_none());
    }

    #[test]
    fn held_out_parts_are_never_trained_on() {
        for part in ["disc", "bar", "swing", "silk_cotton", "denim_leather"] {
            for name in TRAINING {
                assert!(
                    !name.split('-').any(|p| p == part),
                    "{name} uses the held-out {part}"
                );
            }
            assert!(HELD_OUT.iter().any(|n| n.split('-').any(|p| p == part)));
        }
    }

    #[test]
    fn colliders_top_out_where_garments_drop_onto() {
        for name in COLLIDERS {
            let c = collider_named(name).unwrap_or_else(|| panic!("{name}"));
            let top = c.frames[0]
                .iter()
                .map(|p| p.y as f64)
                .fold(f64::MIN, f64::max);
            assert!((top - TOP_M).abs() < 1e-6, "{name}: top at {top}");
        }
    }

    #[test]
    fn motions_are_rigid_and_start_at_rest() {
        for motion in MOTIONS {
            let c = animate(collider_named("cube").expect("cube"), motion, 2.0).expect(motion);
            let rest = &c.frames[0];
            let (a, b) = (rest[0].cast::<f64>(), rest[7].cast::<f64>());
            for f in &c.frames {
                let d = (f[0].cast::<f64>() - f[7].cast::<f64>()).norm();
                assert!((d - (a - b).norm()).abs() < 1e-5, "{motion} is not rigid");
            }
            if motion == "still" {
                assert!(!c.is_animated());
            } else {
                assert_eq!(c.frames.len(), 61, "{motion}");
                assert!(c.frames.iter().any(|f| (f[0] - rest[0]).norm() > 0.01));
            }
        }
    }

    #[test]
    fn spinning_turns_about_the_garments_vertical() {
        let c = animate(collider_named("table").expect("table"), "spin", 2.0).expect("spin");
        let radius = |p: &Vector3<f32>| (p.x * p.x + p.z * p.z).sqrt();
        for (k, p) in c.frames[0].iter().enumerate() {
            for f in &c.frames {
                assert!((radius(&f[k]) - radius(p)).abs() < 1e-5);
                assert!((f[k].y - p.y).abs() < 1e-6);
            }
        }
        // A quarter turn in 1.5 s at 60°/s.
        let q = &c.frames[45][0];
        let p = &c.frames[0][0];
        let turned = (p.x * q.x + p.z * q.z) / (radius(p) * radius(q));
        assert!(turned.abs() < 1e-4, "{turned}");
    }

    #[test]
    fn the_miniskirt_is_the_sample_skirt_shortened_and_needs_the_avatar() {
        let s = scene("miniskirt-cotton-avatar-walk", 60).expect("avatar shot");
        assert!(s.colliders.is_empty());
        let g = &s.garments[0];
        g.validate().expect("valid");
        assert_eq!(g.seams.len(), 2);
        let full = super::super::samples::skirt(Fabric::preset("cotton").expect("cotton"));
        assert!(g.area() < 0.55 * full.area() && g.area() > 0.35 * full.area());
        assert!(scene("square-cotton-avatar-walk", 60).is_none());
        assert!(scene("miniskirt-cotton-sphere-still", 60).is_none());
        assert!(TRAINING.iter().any(|n| n.ends_with(AVATAR)));
    }

    #[test]
    fn a_mix_lies_between_its_presets() {
        let (s, c) = (
            Fabric::preset("silk").expect("silk"),
            Fabric::preset("cotton").expect("cotton"),
        );
        let m = fabric_named("silk_cotton").expect("mix");
        assert!(m.bending_n_m > s.bending_n_m && m.bending_n_m < c.bending_n_m);
        assert!((m.bending_n_m - (s.bending_n_m * c.bending_n_m).sqrt()).abs() < 1e-12);
        m.validate().expect("valid");
    }

    #[test]
    fn the_disc_is_round() {
        let p = disc(0.27, 12, Vector3::zeros());
        let area = p.signed_area();
        let circle = std::f64::consts::PI * 0.27 * 0.27;
        assert!((area - circle).abs() / circle < 0.01, "{area} vs {circle}");
    }
}
