//! OBJ text: parsed, then made a cloth piece (texture coordinates as material coordinates, or
//! flattened into charts without them).
#![no_main]

use std::path::Path;

use clothsr_geometry::garment::Fabric;
use clothsr_io::obj::parse_obj;
use clothsr_io::scene_files::cloth_of_obj_mesh;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("fuzz.obj");
    if let Ok(m) = parse_obj(data, path) {
        if m.triangles.len() <= 2000 {
            let _ = cloth_of_obj_mesh(path, m, Fabric::default());
        }
    }
});
