//! # clothsr-sim — the cloth simulator
//!
//! The coarse and the fine simulation of clothsr (the paper's §4.4.4): implicit Euler as
//! minimisation of the incremental potential, Baraff-Witkin membrane, Discrete-Shells bending,
//! sewing springs, BVH collision detection with quadratic repulsion against bodies and the cloth
//! itself. It knows no file format and no network: the pipeline reads and overwrites its state
//! ([`SimState`]) between steps. [`coarse`] holds the coarse model's settings.

pub mod arrange;
pub mod bench;
pub mod coarse;
pub mod collide;
pub mod driver;
pub mod energy;
pub mod model;
pub mod reduce;
pub mod scatter;
pub mod sparse;
pub mod step;

pub use model::{ClothModel, WrinkleBending};
pub use step::{
    ColliderFrame, LinearSolver, PhaseTimes, Pin, PinTarget, SimParams, SimState, Simulator,
    StepStats,
};
