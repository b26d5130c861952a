//! # clothsr-nn — the two networks
//!
//! - [`corrector`]: the GNN that turns each coarse step M_c into M_int, interleaved with the
//!   coarse simulation (the paper's §3.1), with a fused CPU forward pass for inference;
//! - [`msr`]: the SwinIR network on coordinate maps in pattern space that lifts each frame to
//!   the fine mesh (§3.2), with its maps and patches;
//! - [`common`]: what both share (device, weights, model folders' JSON).
//!
//! Each network keeps burn's four files: `model.rs`, `data.rs`, `training.rs`, `inference.rs`.

pub mod common;
pub mod corrector;
pub mod msr;
