//! Mesh super-resolution (the paper's §3.2): meshes ↔ coordinate maps in material space at the
//! fine pixel size, overlapping patches for the ISR network, and the finite-difference
//! gradients of §3.2.1 used by its loss.

pub mod coordmap;
pub mod gradients;
pub mod patches;

pub use coordmap::{CoordMap, Normalisation, PanelGrid};
pub use patches::{blend_patches, split_patches, PatchLayout};
