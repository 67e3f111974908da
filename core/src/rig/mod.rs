//! The rig: the skeleton, the merged character mesh bound to it, clips,
//! poses and linear blend skinning, and the summary `aobake inspect`
//! prints. Everything here is geometry in memory; import builds it,
//! pose spaces read it.

pub mod character;
pub mod clip;
pub mod pose;
/// The node hierarchy lives in the runtime, which engines use too.
pub use aobake_runtime::rig as skeleton;
