//! # clothsr — super-resolution cloth animation
//!
//! An implementation of Yu & Wang, "Super-Resolution Cloth Animation with Spatial and Temporal
//! Coherence" (SIGGRAPH 2024). Data flows through the stages of the paper's Fig. 2:
//!
//! 1. [`io`] reads sewing patterns (GarmentCode JSON), meshes (OBJ, USD) and avatars (UsdSkel);
//! 2. [`garment`] holds panels, seams and fabric; [`mesh`] meshes them at the coarse (20 mm) and
//!    fine (2.5 mm) resolutions in one shared material space;
//! 3. [`sim`] simulates cloth; [`transfer`] moves states between the coarse and fine meshes;
//!    [`data`] is the training data's format and [`dataset`] makes it; [`corrector`] turns each coarse step M_c into M_int and the
//!    simulator goes on from it; [`msr`] turns meshes into coordinate maps and patches and back;
//! 4. [`pipeline`] runs these stages per frame; [`io`] writes time-sampled USD and [`viz`]
//!    streams previews to Rerun; [`eval`] measures results against fine simulations.
//!
//! The stages below the pipeline are crates of their own, each using only those before it:
//! `clothsr-geometry` ([`garment`], [`mesh`], [`scene`], [`transfer`], [`metrics`]) →
//! `clothsr-sim` ([`sim`]) → `clothsr-io` ([`io`], [`data`]) → `clothsr-nn` ([`corrector`],
//! [`msr`]) → this crate ([`dataset`], [`pipeline`], [`eval`], [`viz`]) → the `clothsr` command.

pub mod dataset;
pub mod eval;
pub mod pipeline;
pub mod viz;

pub use clothsr_geometry::{
    error, garment, mesh, metrics, scene, transfer, Error, ErrorKind, Result,
};
pub use clothsr_io as io;
pub use clothsr_io::data;
pub use clothsr_nn as nn;
pub use clothsr_nn::{corrector, msr};
pub use clothsr_sim as sim;
