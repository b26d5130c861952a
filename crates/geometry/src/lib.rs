//! # clothsr-geometry — the data every stage shares
//!
//! The first layer of clothsr (Yu & Wang, *Super-Resolution Cloth Animation with Spatial and
//! Temporal Coherence*, SIGGRAPH 2024): no file formats, no simulation, no networks.
//!
//! - [`garment`]: sewing patterns (panels, seams, fabric), GarmentCode's JSON parsed;
//! - [`mesh`]: patterns meshed at the coarse (20 mm) and fine (2.5 mm) resolutions in one shared
//!   material space;
//! - [`scene`]: garments, colliders (static or animated), gravity, time step and frame range;
//! - [`transfer`]: states moved between the coarse and the fine mesh (the paper's §3.2 upsampling
//!   and M_int, the fine cloth downsampled);
//! - [`metrics`]: distances between two states of one mesh;
//! - [`error`]: the error type every layer returns, naming the file and the element at fault.

pub mod error;
pub mod garment;
pub mod mesh;
pub mod metrics;
pub mod scene;
pub mod transfer;

pub use error::{Error, ErrorKind, Result};
