//! Kroon's cubemaps (Kroon 2023; DESIGN §5): the occlusion an animated
//! character casts into the space around it over a cyclic clip, stored in
//! nested spheroidal cubemaps. This room grows with the method:
//!
//! * [`geometry`]: the spheroid, its shells and the cube-face texels.
//! * [`field`]: Eq. 3.1 at every texel and shell of a face, one time
//!   sample at a time (what a `face` job computes).
//! * [`discrete`]: the discrete-radial-distance encoding of one texel's
//!   time curve (Algorithm 1, bounded quadratics, 16 bytes).
//! * [`continuous`]: the continuous-radial-distance encoding of one
//!   texel's (time × distance) field (5 × 5 cosine basis and two residual
//!   cubics, 64 bytes over four cubemaps).
//! * [`face`]: one face's raw field (a byte per texel, shell and time
//!   sample), [`face::compute_face`] (the `face` job's loop) and the parts
//!   and manifest its incremental checkpoints are made of.
//! * [`model`]: a baked cubemap at run time: the texel layout an engine
//!   uploads and the CPU lookup (bilinear over texels, linear over shells,
//!   continuous in time).
//!
//! Still to come (issue 12): the methods' names and options in
//! `BakeParams`, the `face` → `assemble` → `evaluate` → `preview` graph in
//! `bake/` (with `JobSink` saving and loading checkpoint parts), the asset
//! container sections, the WGSL lookup, the evaluation and previews, the
//! EXR export.

pub mod continuous;
pub mod discrete;
pub mod face;
pub mod field;
pub mod geometry;
pub mod model;
