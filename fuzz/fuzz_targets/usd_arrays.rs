//! What the USD bridge hands over for a stage (topology, time-sampled points, texture
//! coordinates, panel ids, sewing pairs) as arbitrary values, made a scene.
#![no_main]

use std::path::Path;

use arbitrary::Arbitrary;
use clothsr_geometry::garment::Fabric;
use clothsr_io::scene_files::scene_of_usd;
use clothsr_io::usd::{MeshRole, UsdMesh, UsdStage, UvData};
use libfuzzer_sys::fuzz_target;
use nalgebra::{Vector2, Vector3};

#[derive(Debug, Arbitrary)]
struct Mesh {
    cloth: bool,
    skinned: bool,
    counts: Vec<u8>,
    indices: Vec<u16>,
    points: Vec<[f32; 3]>,
    /// Extra frames: each moves every point by this much.
    moves: Vec<[f32; 3]>,
    time_codes: Vec<f64>,
    st: Option<(bool, Vec<[f64; 2]>)>,
    panel_ids: Option<Vec<u8>>,
    seam_pairs: Option<Vec<[u16; 2]>>,
}

#[derive(Debug, Arbitrary)]
struct Stage {
    fps: f64,
    start: f64,
    end: f64,
    meshes: Vec<Mesh>,
}

fuzz_target!(|s: Stage| {
    if s.meshes.len() > 4
        || s.meshes
            .iter()
            .any(|m| m.points.len() > 600 || m.moves.len() > 4)
    {
        return;
    }
    let meshes = s
        .meshes
        .into_iter()
        .enumerate()
        .map(|(k, m)| {
            let base: Vec<Vector3<f32>> = m
                .points
                .iter()
                .map(|p| Vector3::new(p[0], p[1], p[2]))
                .collect();
            let mut frames = vec![base.clone()];
            for d in &m.moves {
                frames.push(
                    base.iter()
                        .map(|p| p + Vector3::new(d[0], d[1], d[2]))
                        .collect(),
                );
            }
            UsdMesh {
                path: format!("/World/m{k}"),
                name: format!("m{k}"),
                role: if m.cloth {
                    MeshRole::Cloth
                } else {
                    MeshRole::Collider
                },
                skinned: m.skinned,
                face_counts: m.counts.iter().map(|&c| u32::from(c)).collect(),
                face_indices: m.indices.iter().map(|&i| u32::from(i)).collect(),
                time_codes: m.time_codes,
                frames,
                uv: m.st.map(|(corner, v)| {
                    let v: Vec<Vector2<f64>> = v.iter().map(|c| Vector2::new(c[0], c[1])).collect();
                    if corner {
                        UvData::Corner(v)
                    } else {
                        UvData::Vertex(v)
                    }
                }),
                panel_ids: m.panel_ids.map(|v| v.into_iter().map(u32::from).collect()),
                seam_pairs: m.seam_pairs.map(|v| {
                    v.into_iter()
                        .map(|p| [u32::from(p[0]), u32::from(p[1])])
                        .collect()
                }),
                fabric: None,
            }
        })
        .collect();
    let stage = UsdStage {
        fps: s.fps,
        start: s.start,
        end: s.end,
        meters_per_unit: 1.0,
        up_axis: "Y".into(),
        meshes,
        garments: Vec::new(),
        garment_paths: Vec::new(),
        solver: None,
        warnings: Vec::new(),
    };
    let _ = scene_of_usd(Path::new("fuzz.usda"), stage, &Fabric::default());
});
