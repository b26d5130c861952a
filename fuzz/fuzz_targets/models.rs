//! A models folder's JSON files: `coarse.json` (the coarse model) and `models.json` (the
//! held-out figures of each path); the input is split at its first NUL byte.
#![no_main]

use std::path::Path;

use clothsr_io::models::ModelsManifest;
use clothsr_sim::coarse::CoarseCalibration;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let (a, b) = match data.iter().position(|&c| c == 0) {
        Some(k) => (&data[..k], &data[k + 1..]),
        None => (data, &data[..0]),
    };
    if let Ok(text) = std::str::from_utf8(a) {
        if let Ok(cal) = CoarseCalibration::parse(text, Path::new("coarse.json")) {
            let _ = cal.to_string();
        }
    }
    if let Ok(text) = std::str::from_utf8(b) {
        for corrector in [false, true] {
            if let Ok(m) = ModelsManifest::parse(text, Path::new("models.json"), corrector) {
                let _ = m.best();
            }
        }
    }
});
