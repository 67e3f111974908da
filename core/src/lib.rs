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
//!    [`Limits`] bounds what an upload may declare before anything is
//!    allocated.
//! 2. [`rig`]: a clip sampled at a time gives a [`Pose`] (local transforms
//!    of every node, and morph weights); linear blend skinning turns a pose
//!    into a [`PosedMesh`].
//! 3. [`pose_space`]: poses as numbers. Joint angles (Kontkanen & Aila) go
//!    both ways between pose and vector, with ranges taken from the clips;
//!    handles (Kirk & Arikan) are computed from a pose. Seeded samplers
//!    give reference poses. [`summary`] reports a character and its
//!    clips (counts, bounds, pose parameters) from both floors.
//! 4. [`trace`]: ground-truth AO by ray tracing (surface, obscurance,
//!    volume and Kroon's estimators); [`trace::trace_poses`] traces a batch
//!    of poses into the block of AO values that the models are fitted to.
//! 5. [`method`]: the methods, fitted to traced AO and evaluated at run
//!    time, and the one place that dispatches on [`method::Method`]; each
//!    family in its own folder.
//! 6. [`bake`]: a bake as jobs. [`bake::BakeParams`] (the only home of
//!    defaults) and the bake key; the planner's job graph; the job
//!    functions `(spec, inputs, checkpoint) → outputs`, one file per
//!    method family with its jobs, evaluation and report, and
//!    `bake::family` handing each concern to its family; and the
//!    in-process runner that `aobake bake`, the benches and the tests use
//!    (workers run the same functions one job at a time).
//! 7. [`asset`]: the versioned container the bake publishes (from
//!    `aobake-runtime`) and the quality metrics; [`image`]: the heat map, sRGB, the PNG/APNG encoder
//!    and the plot font that plots, charts and previews share.
//!
//! **Layers**, bottom up: `digest`, `geometry`, `image`, `rig`, `import`,
//! `pose_space`, `summary`, `trace`, `asset`, `method`, `bake`. A file
//! imports files of its own layer or below, and the file-level import
//! graph has no circle (`python3 tools/import-graph.py core <layers>`).
//! Below them all is the `aobake-runtime` crate: the asset container and
//! the method an asset holds, which engines read assets with.

pub mod asset;
pub mod bake;
pub mod digest;
pub mod geometry;
pub mod image;
pub mod import;
pub mod method;
pub mod pose_space;
pub mod rig;
pub mod summary;
pub mod trace;

pub use import::{
    ImportError, Imported, SideFile, Upload, import_character, import_clips, limits::Limits,
};
pub use rig::{
    character::Character,
    clip::Clip,
    pose::{Pose, PosedMesh},
};
