//! # clothsr — super-resolution cloth animation
//!
//! An implementation of Yu & Wang, "Super-Resolution Cloth Animation with Spatial and Temporal
//! Coherence" (SIGGRAPH 2024). Data flows through the stages of the paper's Fig. 2:
//!
//! 1. [`io`] reads sewing patterns (GarmentCode JSON), meshes (OBJ, USD) and avatars (UsdSkel);
//! 2. [`garment`] holds panels, seams and fabric; [`mesh`] meshes them at the coarse (20 mm) and
//!    fine (2.5 mm) resolutions in one shared material space;
//! 3. [`sim`] simulates cloth; [`transfer`] moves states between the coarse and fine meshes;
//!    [`data`] makes training data; [`corrector`] turns each coarse step M_c into M_int and the
//!    simulator goes on from it; [`msr`] turns meshes into coordinate maps and patches and back;
//! 4. [`pipeline`] runs these stages per frame; [`io`] writes time-sampled USD and [`viz`]
//!    streams previews to Rerun; [`eval`] measures results against fine simulations.

pub mod corrector;
pub mod data;
pub mod error;
pub mod eval;
pub mod garment;
pub mod io;
pub mod mesh;
pub mod msr;
pub mod pipeline;
pub mod scene;
pub mod sim;
pub mod transfer;
pub mod viz;

pub use error::{Error, Result};
