//! Files in and out: GarmentCode JSON (in [`crate::garment::garmentcode`]), OBJ through tobj,
//! USD through usd-core and the embedded-Python bridge.

pub mod obj;
pub mod python;
pub mod usd;
