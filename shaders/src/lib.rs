//! # aobake-shaders
//!
//! This crate will own the WGSL of aobake, one file per pipeline under
//! `shaders/` (run-time AO evaluation per method, the preview raster, GPU AO
//! tracing), embedded with `include_str!` so the worker, the tests (naga
//! validation) and the asset exports all use the same text (DESIGN §2).
//!
//! No shader exists yet; the first arrives with the vertex methods.
