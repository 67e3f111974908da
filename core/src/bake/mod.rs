//! A bake as the service runs it (DESIGN §1.3, §5–6, §8), in this order:
//!
//! 1. [`BakeParams`] ([`params`]): everything that determines a bake
//!    besides its inputs, the only home of defaults, validated, and the
//!    bake key.
//! 2. [`BakeInputs`] ([`inputs`]): the uploads imported.
//! 3. [`Plan`] ([`plan`]): the pose spaces and the seeded reference,
//!    held-out and noise poses.
//! 4. [`JobGraph`] ([`graph`]): the bake cut into jobs.
//! 5. The job functions, each `(spec, dependency outputs, checkpoint?) →
//!    outputs`: the contract and the one dispatch on the family in
//!    [`jobs`]; each family's graph, jobs, evaluation and report in its
//!    own file: [`vertex`] (`sample`, `fit`, `unseen`, `evaluate`,
//!    `assemble`), [`cubemap`] (`face`, `assemble`, `evaluate`), [`grid`]
//!    (`slab`, `assemble`, `evaluate`); `preview-truth` and `preview`
//!    ([`preview`]), the same for all (in [`family`]), the second of
//!    which also needs a [`Renderer`] and judges the screen-space
//!    baseline beside the model ([`screen_space`]); [`report`] holds what the
//!    reports share. [`family`], above them all, is the one place per
//!    concern that hands a bake to its family.
//! 6. [`run_graph`] ([`runner`]): the whole graph in this process.
//!
//! Everything is seeded from [`BakeParams::seed`]: the same request gives
//! the same poses, the same rays, the same coefficients and the same bytes,
//! however the bake was cut into jobs and however often a job was
//! interrupted.

pub mod cubemap;
pub mod family;
pub mod graph;
pub mod grid;
pub mod inputs;
pub mod jobs;
pub mod params;
pub mod plan;
pub mod preview;
pub mod report;
pub mod runner;
pub mod screen_space;
pub mod texel;
pub mod vertex;
pub mod viewer;

pub use family::{AssetUseError, BakeReport, BakedAsset};
pub use graph::{GraphOptions, JobGraph, PlannedJob};
pub use inputs::{
    BakeInputs, BundleError, ClipListError, InputError, MAX_CLIP_FILES, MAX_SIDE_FILES,
    UploadBytes, check_clip_list,
};
pub use jobs::{
    Bake, Checkpoint, IndexedBlock, JobError, JobOutput, JobSink, JobSpec, NoSink, Output, PoseSet,
    Stop,
};
pub use params::{BakeError, BakeParams, ReferenceSource, bake_key};
pub use plan::{Plan, Receivers, TestPose};
pub use preview::{
    Camera, Panel, Preview, PreviewInfo, PreviewModel, RenderFrame, RenderScene, Renderer,
};
pub use runner::{Baked, JobEvent, bake_in_process, run_graph};
pub use vertex::{ClipEvaluation, Comparison, Evaluation, UnseenClips, UnseenFold};

pub use crate::digest::sha256_hex;
pub use crate::method::vertex::FitStats;
