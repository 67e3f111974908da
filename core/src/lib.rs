//! # aobake-core
//!
//! Everything aobake computes, as functions from bytes and values to bytes
//! and values: no files, sockets, SQL or GPUs (DESIGN §2).
//!
//! The flow through this crate, in the order a bake needs it:
//!
//! 1. [`import`]: an untrusted glTF upload becomes a [`Character`] (every
//!    mesh of the scene merged into one occluder, bound to a joint palette)
//!    and its [`Clip`]s; clips shipped in a second file bind by node name.
//! 2. [`pose`]: a clip sampled at a time gives a [`Pose`] (local transforms
//!    of every node, and morph weights); linear blend skinning turns a pose
//!    into a [`PosedMesh`].
//! 3. [`params`]: poses as numbers. Joint angles (rotation vectors relative
//!    to the rest pose, for Kontkanen & Aila) go both ways between pose and
//!    vector, with ranges taken from the clips; handles (Kirk & Arikan) are
//!    computed from a pose. Seeded samplers give reference poses.
//! 4. [`ply`]: the posed mesh as PLY, in the product's vertex order, so
//!    other tools can bake the very same triangles.
//! 5. [`trace`]: ground-truth AO by ray tracing (surface, obscurance,
//!    volume and Kroon's estimators); [`reference`] traces a batch of poses
//!    into the block of AO values that the models are fitted to.
//!
//! [`Limits`] bounds what an upload may declare; it is checked before
//! anything is allocated.

pub mod asset;
pub mod bake;
pub mod character;
pub mod clip;
pub mod digest;
pub mod geometry;
pub mod import;
pub mod limits;
pub mod metrics;
pub mod model;
pub mod params;
pub mod ply;
pub mod pose;
pub mod reference;
pub mod report;
pub mod shapes;
pub mod skeleton;
pub mod summary;
pub mod trace;

pub use character::Character;
pub use clip::Clip;
pub use import::{ImportError, Imported, SideFile, Upload, import_character, import_clips};
pub use limits::Limits;
pub use pose::{Pose, PosedMesh};
