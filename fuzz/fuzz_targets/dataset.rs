//! A training data set's files: `manifest.json` (the part before the first NUL byte) and a
//! safetensors file (the rest), read as the data set's meshes and a frame's arrays.
#![no_main]

use std::path::Path;

use clothsr_io::data::{mesh_of_tensors, Manifest};
use clothsr_io::tensors::TensorReader;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some(k) = data.iter().position(|&c| c == 0) else {
        return;
    };
    let Ok(manifest) = serde_json::from_slice::<Manifest>(&data[..k]) else {
        return;
    };
    let path = Path::new("meshes.safetensors");
    let Ok(r) = TensorReader::from_bytes(data[k + 1..].to_vec(), path) else {
        return;
    };
    for (which, n) in [
        ("coarse", manifest.coarse_vertices),
        ("fine", manifest.fine_vertices),
    ] {
        let _ = mesh_of_tensors(&r, path, &manifest, which, n);
    }
    for name in ["int_x", "coarse_x", "fine_x"] {
        let _ = r.f32(name);
    }
    let _ = r.f64("resume_fine_x");
});
