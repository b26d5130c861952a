//! The cloth simulator (the paper's §4.4.4): implicit Euler as minimisation of the incremental
//! potential, Baraff-Witkin membrane, Discrete-Shells bending, sewing springs, BVH collision
//! detection with quadratic repulsion against bodies and the cloth itself.

pub mod arrange;
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
    ColliderFrame, LinearSolver, Pin, PinTarget, SimParams, SimState, Simulator, StepStats,
};
