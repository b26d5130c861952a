//! Sewing springs. Being written.
