//! Kroon's cubemaps as an engine reads them: the spheroid and its shells
//! ([`geometry`]), the two encodings of a texel's (time × distance) field
//! ([`discrete`], [`continuous`], and Kroon's own thirds in [`blurhash`]),
//! the baked model and its lookup at a point and a phase ([`model`]), and
//! how an asset stores it ([`codec`]). aobake-core traces the faces and
//! encodes them.

pub mod blurhash;
pub mod codec;
pub mod continuous;
pub mod discrete;
pub mod geometry;
pub mod gpu;
pub mod model;

pub use codec::CubemapHeader;
pub use model::{CubemapLayout, CubemapModel, Encoding};

/// The version of the cubemap bake's algorithm, part of the bake key.
pub const ALGORITHM_VERSION: u32 = 1;
