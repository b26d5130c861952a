//! Baraff-Witkin membrane. Being written.
