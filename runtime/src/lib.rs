//! # aobake-runtime
//!
//! What reading a baked AO asset takes, apart from everything that bakes
//! one: the versioned container (magic, version, the method, a JSON
//! header and typed, checksummed sections; `docs/asset-format.md`) and the
//! method an asset holds. aobake's core, worker and CLI read assets
//! through it, and so can an engine's tools: it depends on no ray tracer,
//! linear algebra, glTF reader or async runtime (DESIGN §2).
//!
//! Layers, bottom up: `method`, `container`.

pub mod container;
pub mod method;

pub use container::{AssetError, Container, Data, MAGIC, MAJOR, MINOR, Section};
pub use method::{Family, Method};
