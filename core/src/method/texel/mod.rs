//! The texture-space family (DESIGN §5, "texel"; beyond the four papers):
//! the vertex methods' models fitted per texel of a UV atlas instead of
//! per vertex, so that AO can change between vertices, where per-vertex
//! storage cannot.
//!
//! So far this room holds what every texel method stands on:
//! * [`atlas`]: a lightmap atlas of the character, generated
//!   deterministically (uvunwrap, a pure-Rust xatlas-style unwrapper),
//!   and its texels as surface points: each texel that shows the surface
//!   names a triangle and barycentric coordinates, so it is posed with the
//!   mesh and traced like a vertex; the texture an engine samples is then
//!   dilated past the charts' borders.
//! * [`trace`]: a batch of poses traced at the texels (an `AoBlock` whose
//!   columns are texels), and which texels a pose draws.
//!
//! It must not know about jobs, files or GPUs (core's rule).

pub mod atlas;
pub mod trace;
