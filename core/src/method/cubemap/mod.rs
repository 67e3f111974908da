//! Kroon's cubemaps (Kroon 2023; DESIGN §5): the occlusion an animated
//! character casts into the space around it over a cyclic clip, stored in
//! nested spheroidal cubemaps. This room grows with the method:
//!
//! * [`geometry`]: the spheroid, its shells and the cube-face texels.
//! * [`field`]: Eq. 3.1 at every texel and shell of a face, one time
//!   sample at a time (what a `face` job computes).
//! * [`discrete`]: the discrete-radial-distance encoding of one texel's
//!   time curve (Algorithm 1, bounded quadratics, 16 bytes).
//!
//! Still to come (issue 12): the per-face field (`face` jobs, Eq. 3.1 at
//! every texel, shell and time sample), the discrete and continuous
//! encodings, the run-time decoding (CPU and WGSL) and the evaluation.

pub mod discrete;
pub mod field;
pub mod geometry;
