//! What a bake publishes: the versioned binary container (generic over
//! methods: a preamble, a JSON header and typed, checksummed sections),
//! the quality metrics, and the JSON report with its PSNR plot.
//!
//! Nothing here fits or traces; the methods decide what goes into the
//! sections, `bake` decides when.

mod container;
pub mod metrics;
pub mod report;

pub use container::{AssetError, Container, Data, MAGIC, MAJOR, MINOR, Section};
