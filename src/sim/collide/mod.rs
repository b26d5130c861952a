//! Collision detection and quadratic repulsion. Being written.
