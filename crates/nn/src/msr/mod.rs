//! Mesh super-resolution (the paper's §3.2): meshes ↔ coordinate maps in material space at the
//! fine pixel size, overlapping patches, the SwinIR network that adds the fine detail
//! ([`model`]), its training ([`training`]), per-frame inference ([`inference`]) and evaluation
//! against fine simulations ([`eval`]).

pub mod condition;
pub mod coordmap;
pub mod data;
pub mod eval;
pub mod gradients;
pub mod inference;
pub mod model;
pub mod patches;
pub mod training;

pub use condition::Condition;
pub use coordmap::{CoordMap, Normalisation, PanelGrid};
pub use inference::{Isr, SuperResolver};
pub use patches::{blend_patches, split_patches, PatchLayout};
