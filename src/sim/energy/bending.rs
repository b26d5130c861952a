//! Discrete Shells bending (Grinspun et al. 2003). Being written.
