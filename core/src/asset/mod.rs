//! What a bake publishes: the versioned binary container (generic over
//! methods: a preamble, a JSON header and typed, checksummed sections),
//! and the quality metrics (the report is a bake product: `bake::report`).
//!
//! Nothing here fits or traces; the methods decide what goes into the
//! sections, `bake` decides when.

pub mod gltf;
pub mod metrics;

/// The container lives in the runtime crate, which engines read assets with.
pub use aobake_runtime::container::{AssetError, Container, Data, MAGIC, MAJOR, MINOR, Section};
