//! What a bake publishes: the versioned binary container (generic over
//! methods: a preamble, a JSON header and typed, checksummed sections),
//! and the quality metrics (the report is a bake product: `bake::report`).
//!
//! Nothing here fits or traces; the methods decide what goes into the
//! sections, `bake` decides when.

mod container;
pub mod metrics;

pub use container::{AssetError, Container, Data, MAGIC, MAJOR, MINOR, Section};
