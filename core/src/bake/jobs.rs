//! The job functions (DESIGN §2, §8): each job is a pure function
//! `(spec, dependency outputs, checkpoint?) → outputs`, so a worker can
//! run it anywhere, a retry can resume it, and its outputs are the same
//! bytes however often it was interrupted.
//!
//! This file is the contract every family shares: the job specs, their
//! outputs, checkpoints, sinks and errors, and [`Bake`]. Each family's
//! bake file (`vertex.rs`, `cubemap.rs`, `grid.rs`) builds on it;
//! `family.rs`, above them, hands each concern to its family in one
//! exhaustive `match`.
//!
//! Outputs are named blobs; a job finds its inputs by name in its
//! dependencies' outputs.

use serde::{Deserialize, Serialize};

use crate::{asset::Container, method::vertex::FitStep, trace::AoBlock};

use super::{BakeError, BakeInputs, Plan, report::Timings};

/// Which poses a `sample` job traces.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PoseSet {
    /// The reference poses the model is fitted to.
    Reference,
    /// The held-out poses it is judged on (another ray seed).
    HeldOut,
    /// A few held-out poses traced again with independent rays, for the
    /// ground truth's own noise.
    Noise,
}

impl PoseSet {
    pub(super) fn output(self) -> &'static str {
        match self {
            Self::Reference => "ao-reference",
            Self::HeldOut => "ao-held-out",
            Self::Noise => "ao-noise",
        }
    }
}

/// What one job computes. Serialised into the queue as JSON.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum JobSpec {
    /// Trace poses `first..first + count` of a pose set.
    Sample {
        /// The set.
        set: PoseSet,
        /// The first pose's index in the set.
        first: usize,
        /// Poses in this batch.
        count: usize,
    },
    /// Fit the model and the baseline to the reference blocks.
    Fit,
    /// Trace every shell and time sample of one cubemap face
    /// (checkpointed after every batch of time samples).
    Face {
        /// The face: 0..6 in the order +x, −x, +y, −y, +z, −z.
        face: usize,
        /// Its time samples (the units of its progress).
        times: usize,
    },
    /// Trace z-layers `first..first + count` of one part's grid
    /// (checkpointed after every layer).
    Slab {
        /// The part.
        part: usize,
        /// The first layer.
        first: usize,
        /// Layers in this slab (the units of its progress).
        count: usize,
    },
    /// One fold of the unseen-clips evaluation: the method refitted
    /// without one clip and judged on its held-out frames (see
    /// [`Plan::unseen_fold`]).
    Unseen {
        /// The fold: the clip's index in [`Plan::fold_clips`].
        fold: usize,
    },
    /// Judge the model on the held-out poses.
    Evaluate,
    /// Pack the asset, the report and the plot.
    Assemble,
    /// Trace the ground truth of preview frames `first..first + count`
    /// (the stills', then the animation's: see [`Bake::preview_frames`]).
    /// It needs no model, so it runs beside the tracing jobs and leaves
    /// `preview` only the drawing.
    PreviewTruth {
        /// The first frame.
        first: usize,
        /// Frames in this batch.
        count: usize,
    },
    /// Render the asset's previews (needs a [`Renderer`]).
    Preview,
}

impl JobSpec {
    /// The job's kind, as the queue and the dashboard name it.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Sample { .. } => "sample",
            Self::Fit => "fit",
            Self::Face { .. } => "face",
            Self::Slab { .. } => "slab",
            Self::Unseen { .. } => "unseen",
            Self::Evaluate => "evaluate",
            Self::Assemble => "assemble",
            Self::PreviewTruth { .. } => "preview-truth",
            Self::Preview => "preview",
        }
    }

    /// Whether the job reads a dependency's output named `output`: every
    /// one, but the cubemap ground's truth (a megabyte or more), which
    /// only `evaluate` reads, so other jobs' workers do not fetch it and
    /// the in-process runner does not hand it to them either.
    pub fn reads(&self, output: &str) -> bool {
        output != super::cubemap::GROUND_TRUTH || matches!(self, Self::Evaluate)
    }

    /// The kinds of the jobs that cast rays (what a queue offers GPU
    /// workers first): those whose [`JobSpec::traces`] holds.
    pub const TRACING_KINDS: [&'static str; 4] = ["sample", "face", "slab", "preview-truth"];

    /// Whether the job casts rays (its kind is in
    /// [`JobSpec::TRACING_KINDS`]).
    pub fn traces(&self) -> bool {
        match self {
            Self::Sample { .. }
            | Self::Face { .. }
            | Self::Slab { .. }
            | Self::PreviewTruth { .. } => true,
            Self::Fit | Self::Unseen { .. } | Self::Evaluate | Self::Assemble | Self::Preview => {
                false
            }
        }
    }

    /// Units of progress the job is worth (poses for `sample`, time
    /// samples for `face`, layers for `slab`, frames for `preview-truth`,
    /// the steps of a fit for `fit` and `unseen`, 1 else).
    pub fn work(&self) -> u64 {
        match self {
            Self::Sample { count, .. }
            | Self::Slab { count, .. }
            | Self::PreviewTruth { count, .. } => *count as u64,
            Self::Face { times, .. } => *times as u64,
            Self::Fit | Self::Unseen { .. } => FitStep::ALL.len() as u64,
            _ => 1,
        }
    }
}

impl std::fmt::Display for JobSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Sample { set, first, count } => write!(
                f,
                "sample {} poses {first}..{}",
                set.output().trim_start_matches("ao-"),
                first + count
            ),
            Self::Face { face, .. } => {
                let name = crate::method::cubemap::geometry::FACE_NAMES
                    .get(*face)
                    .unwrap_or(&"?");
                write!(f, "face {name}")
            }
            Self::Slab { part, first, count } => {
                write!(f, "slab part {part} layers {first}..{}", first + count)
            }
            Self::Unseen { fold } => write!(f, "unseen fold {fold}"),
            Self::PreviewTruth { first, count } => {
                write!(f, "preview truth frames {first}..{}", first + count)
            }
            other => f.write_str(other.kind()),
        }
    }
}

/// One named output blob.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Output {
    /// Its name, unique within the job.
    pub name: String,
    /// Its bytes.
    pub bytes: Vec<u8>,
}

/// What a job produced: named blobs, and the seconds spent per stage so
/// far (its own and those it carries forward from its dependencies, for
/// the report; they never enter an asset).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct JobOutput {
    /// The blobs.
    pub outputs: Vec<Output>,
    /// Stage times.
    pub timings: Timings,
}

impl JobOutput {
    /// The bytes of the output named `name`.
    pub fn get(&self, name: &str) -> Option<&[u8]> {
        self.outputs
            .iter()
            .find(|o| o.name == name)
            .map(|o| o.bytes.as_slice())
    }

    pub(super) fn push(&mut self, name: &str, bytes: Vec<u8>) {
        self.outputs.push(Output {
            name: name.to_owned(),
            bytes,
        });
    }
}

/// Resumable state of a job: a named step, a cursor within it (`sample`:
/// poses done) and the data needed to go on from there.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Checkpoint {
    /// The step, such as `sample`.
    pub step: String,
    /// How far the step got.
    pub cursor: u64,
    /// The partial result.
    pub data: Vec<u8>,
}

/// Why a job stopped before finishing, asked for by its runner (lease
/// lost, bake cancelled, shutdown, an injected fault).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stop(pub String);

/// Where a running job reports: checkpoints and progress. The in-process
/// runner ignores checkpoints; a worker saves them as blobs.
///
/// A job whose partial result grows large (a cubemap face: 33 MiB at the
/// defaults) checkpoints incrementally: it saves each new piece once with
/// [`JobSink::save_part`] and its checkpoint's data lists the pieces'
/// digests, so a checkpoint writes only what is new since the last one.
pub trait JobSink {
    /// Saves a checkpoint. `Err` asks the job to stop now; what it saved
    /// is kept for the next attempt.
    fn checkpoint(&mut self, checkpoint: Checkpoint) -> Result<(), Stop>;
    /// `done` of `total` units of the job's work are done.
    fn progress(&mut self, done: u64, total: u64);
    /// Stores a piece of a checkpoint; its sha256 (hex), or `None` when it
    /// could not be stored (the job then keeps it and tries again at its
    /// next checkpoint).
    fn save_part(&mut self, bytes: &[u8]) -> Option<String>;
    /// A piece stored by an earlier attempt, by its sha256.
    fn load_part(&mut self, digest: &str) -> Result<Vec<u8>, JobError>;
}

/// A sink that keeps nothing: for runs that are never resumed.
#[derive(Debug, Default)]
pub struct NoSink;

impl JobSink for NoSink {
    fn checkpoint(&mut self, _: Checkpoint) -> Result<(), Stop> {
        Ok(())
    }

    fn progress(&mut self, _: u64, _: u64) {}

    fn save_part(&mut self, bytes: &[u8]) -> Option<String> {
        Some(crate::digest::sha256_hex(bytes))
    }

    fn load_part(&mut self, digest: &str) -> Result<Vec<u8>, JobError> {
        Err(JobError::Invalid(format!(
            "checkpoint part {digest} was never kept: this run is not resumable"
        )))
    }
}

/// Why a job failed, and whether trying again can help.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum JobError {
    /// The inputs or parameters are wrong: every attempt would fail alike.
    #[error("{0}")]
    Invalid(String),
    /// Something that may pass on another attempt.
    #[error("{0}")]
    Failed(String),
    /// The runner asked the job to stop.
    #[error("stopped: {}", .0.0)]
    Stopped(Stop),
}

impl JobError {
    /// Whether another attempt can succeed.
    pub fn retryable(&self) -> bool {
        !matches!(self, Self::Invalid(_))
    }
}

impl From<crate::trace::TraceError> for JobError {
    fn from(e: crate::trace::TraceError) -> Self {
        Self::Invalid(e.to_string())
    }
}

impl From<crate::image::ImageError> for JobError {
    fn from(e: crate::image::ImageError) -> Self {
        Self::Failed(e.to_string())
    }
}

impl From<BakeError> for JobError {
    fn from(e: BakeError) -> Self {
        Self::Invalid(e.to_string())
    }
}

/// A bake ready to run jobs: its inputs and its pose spaces.
#[derive(Debug, Clone)]
pub struct Bake<'a> {
    /// The imported inputs.
    pub inputs: &'a BakeInputs,
    /// The pose spaces and parameters.
    pub plan: Plan<'a>,
}

impl Bake<'_> {
    /// Why `spec` is not one of this bake's family's jobs.
    pub(super) fn foreign(&self, spec: &JobSpec) -> JobError {
        match spec {
            JobSpec::Preview => JobError::Invalid(
                "a preview job needs a renderer: run it with Bake::preview".into(),
            ),
            _ => JobError::Invalid(format!(
                "a {} job is not part of a {} bake",
                spec.kind(),
                self.plan.params.method
            )),
        }
    }
}

pub(super) fn json(value: &impl Serialize) -> Vec<u8> {
    serde_json::to_vec(value).expect("job documents serialise")
}

pub(super) fn parse<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Result<T, JobError> {
    serde_json::from_slice(bytes).map_err(|e| JobError::Invalid(format!("a job document: {e}")))
}

pub(super) fn find<'o>(deps: &[&'o JobOutput], name: &str) -> Result<&'o JobOutput, JobError> {
    deps.iter()
        .copied()
        .find(|d| d.get(name).is_some())
        .ok_or_else(|| JobError::Invalid(format!("no dependency produced {name}")))
}

pub(super) fn named<'o>(output: &'o JobOutput, name: &str) -> Result<&'o [u8], JobError> {
    output
        .get(name)
        .ok_or_else(|| JobError::Invalid(format!("no output named {name}")))
}

/// An [`AoBlock`] with the index of its first pose in its set, as a blob:
/// `AOBK`, format 1 (u32), first pose (u64), vertices (u32), poses (u32),
/// then the values as little-endian f32, pose-major.
#[derive(Debug, Clone, PartialEq)]
pub struct IndexedBlock {
    /// Index of the block's first pose in its set.
    pub first: usize,
    /// The values.
    pub block: AoBlock,
}

const BLOCK_MAGIC: &[u8; 4] = b"AOBK";
const BLOCK_HEAD: usize = 24;

impl IndexedBlock {
    /// The blob.
    pub fn to_bytes(&self) -> Vec<u8> {
        let b = &self.block;
        let mut out = Vec::with_capacity(BLOCK_HEAD + 4 * b.values.len());
        out.extend(BLOCK_MAGIC);
        out.extend(1u32.to_le_bytes());
        out.extend((self.first as u64).to_le_bytes());
        out.extend((b.vertices as u32).to_le_bytes());
        out.extend((b.poses() as u32).to_le_bytes());
        for v in &b.values {
            out.extend(v.to_le_bytes());
        }
        out
    }

    /// Reads a blob back; `vertices` is what the character has.
    pub fn from_bytes(bytes: &[u8], vertices: usize) -> Result<Self, JobError> {
        let bad = |what: &str| JobError::Invalid(format!("an AO block is malformed: {what}"));
        if bytes.len() < BLOCK_HEAD || &bytes[..4] != BLOCK_MAGIC {
            return Err(bad("no AOBK header"));
        }
        let u32_at = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().expect("4 bytes"));
        if u32_at(4) != 1 {
            return Err(bad("unknown format"));
        }
        let first = u64::from_le_bytes(bytes[8..16].try_into().expect("8 bytes"));
        let (v, p) = (u32_at(16) as usize, u32_at(20) as usize);
        if v != vertices {
            return Err(bad("its vertex count is not the character's"));
        }
        let body = &bytes[BLOCK_HEAD..];
        if Some(body.len()) != v.checked_mul(p).and_then(|n| n.checked_mul(4)) {
            return Err(bad("its length does not match its header"));
        }
        let values = body
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect();
        Ok(Self {
            first: usize::try_from(first).map_err(|_| bad("first pose out of range"))?,
            block: AoBlock { vertices, values },
        })
    }
}

/// The [`IndexedBlock`]s named `name` in `deps`, stacked in pose order;
/// every pose of `0..poses` must be there exactly once.
pub(super) fn stack_blocks(
    deps: &[&JobOutput],
    name: &str,
    vertices: usize,
    poses: usize,
) -> Result<AoBlock, JobError> {
    let mut blocks = Vec::new();
    for d in deps {
        for o in d.outputs.iter().filter(|o| o.name == name) {
            blocks.push(IndexedBlock::from_bytes(&o.bytes, vertices)?);
        }
    }
    blocks.sort_by_key(|b| b.first);
    let mut values = Vec::with_capacity(vertices * poses);
    let mut next = 0;
    for b in blocks {
        if b.first != next {
            return Err(JobError::Invalid(format!(
                "{name} blocks do not cover the poses in order (expected pose {next}, got {})",
                b.first
            )));
        }
        next += b.block.poses();
        values.extend(b.block.values);
    }
    if next != poses {
        return Err(JobError::Invalid(format!(
            "{name} blocks hold {next} poses, not {poses}"
        )));
    }
    Ok(AoBlock { vertices, values })
}

/// The model of an asset, read by its method's codec (`from_container`).
pub(super) fn decode_with<M, H, E: std::fmt::Display>(
    bytes: &[u8],
    read: impl FnOnce(&Container) -> Result<(M, H), E>,
) -> Result<M, JobError> {
    let container = Container::from_bytes(bytes).map_err(|e| JobError::Invalid(e.to_string()))?;
    read(&container)
        .map(|(m, _)| m)
        .map_err(|e| JobError::Invalid(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::{JobSpec, PoseSet};

    #[test]
    fn only_evaluate_reads_the_cubemap_grounds_truth() {
        let truth = super::super::cubemap::GROUND_TRUTH;
        assert!(JobSpec::Evaluate.reads(truth));
        for spec in [JobSpec::Preview, JobSpec::Assemble, JobSpec::Fit] {
            assert!(!spec.reads(truth), "{spec:?}");
            assert!(spec.reads("asset"), "{spec:?}");
        }
    }

    #[test]
    fn the_tracing_kinds_are_the_jobs_that_trace() {
        let specs = [
            JobSpec::Sample {
                set: PoseSet::Reference,
                first: 0,
                count: 1,
            },
            JobSpec::Fit,
            JobSpec::Face { face: 0, times: 1 },
            JobSpec::Slab {
                part: 0,
                first: 0,
                count: 1,
            },
            JobSpec::Unseen { fold: 0 },
            JobSpec::Evaluate,
            JobSpec::Assemble,
            JobSpec::PreviewTruth { first: 0, count: 1 },
            JobSpec::Preview,
        ];
        for spec in &specs {
            assert_eq!(
                JobSpec::TRACING_KINDS.contains(&spec.kind()),
                spec.traces(),
                "{spec}"
            );
        }
        let tracing = specs.iter().filter(|s| s.traces()).count();
        assert_eq!(tracing, JobSpec::TRACING_KINDS.len());
    }
}
