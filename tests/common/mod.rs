//! Fixtures shared by the integration tests (`mod common;` in each test file).

use clothsr::garment::Fabric;
use clothsr::scene::samples::flat_sheet;
use clothsr::scene::{Collider, Scene};
use nalgebra::Vector3;

/// A 0.3 m × 0.3 m sheet of `fabric` held flat `height_m` above the centre of a ball of radius
/// 0.15 m at the origin: it falls and drapes within a few frames.
pub fn sheet_over_ball(fabric: &str, height_m: f64) -> Scene {
    let mut s = Scene {
        garments: vec![flat_sheet(
            "sheet",
            0.3,
            0.3,
            Vector3::new(0.0, height_m, 0.0),
            Fabric::preset(fabric).expect("preset"),
        )],
        ..Scene::default()
    };
    s.colliders
        .push(Collider::sphere("ball", Vector3::zeros(), 0.15, 3));
    s
}
