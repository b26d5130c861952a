//! GarmentCode JSON text: parsed, validated, and small garments meshed at a coarse edge.
#![no_main]

use clothsr_geometry::garment::{garmentcode, Fabric};
use clothsr_geometry::mesh::{mesh_garment, MeshOptions};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(g) = garmentcode::parse(text, "fuzz", Fabric::default()) {
        let area = g.area();
        if area.is_finite() && (1e-4..2.0).contains(&area) {
            let _ = mesh_garment(&g, &MeshOptions::with_edge(0.05));
        }
    }
});
