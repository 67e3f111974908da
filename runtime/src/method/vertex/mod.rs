//! The vertex methods (static average, Kontkanen & Aila's vertex-linear,
//! Kirk & Arikan's vertex-clustered) as an engine evaluates them: the
//! per-pose weights of each ([`linear`], [`clustered`], [`average`]), the
//! eigen-AO basis's per-pose step ([`basis`]), the per-vertex linear form
//! they all reduce to ([`form`]), the [`Model`] an asset holds and its
//! [`codec`]. aobake-core fits the models.

pub mod average;
pub mod basis;
pub mod clustered;
pub mod codec;
pub mod form;
pub mod linear;
pub mod model;
pub mod play;

pub use average::StaticAverage;
pub use basis::Basis;
pub use clustered::{Centering, LinearBase, PoseCluster, VertexClustered};
pub use codec::{AssetHeader, Layout, UNITS};
pub use form::{Block, Coefficients, FormRef, LinearForm, SparseForm};
pub use linear::{Features, VertexLinear};
pub use model::{Model, PoseScratch};
pub use play::VertexAo;

/// Version of the vertex methods' algorithms, part of the bake key: bump
/// it when a change to fitting changes the coefficients a bake produces,
/// or what an asset holds (8: the rig in the header; 9: the angle ranges
/// its fitted rows cover; 10: the primitive table in the header).
pub const ALGORITHM_VERSION: u32 = 10;
