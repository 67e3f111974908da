//! The job functions (DESIGN §2, §8): each job is a pure function
//! `(spec, dependency outputs, checkpoint?) → outputs`, so a worker can
//! run it anywhere, a retry can resume it, and its outputs are the same
//! bytes however often it was interrupted.
//!
//! Per-vertex bakes have five kinds of job:
//!
//! * `sample`: a batch of poses of one set (reference, held-out, or the
//!   noise re-trace) → their AO block; checkpointed after every pose.
//! * `fit`: the reference blocks → the model and the baseline (each as an
//!   asset container) and the fit's statistics; its progress counts the
//!   fit's steps ([`FitStep`]).
//! * `unseen`: one fold of the unseen-clips evaluation: the reference and
//!   held-out blocks → the method refitted without one clip, judged on its
//!   frames. The folds need not wait for `fit`, so workers run them beside
//!   it and beside each other.
//! * `evaluate`: the model, the held-out blocks, the noise re-trace and
//!   the folds → the evaluation and the ground truth's noise estimate.
//! * `assemble`: → the asset, the JSON report and the PSNR plot.
//!
//! Outputs are named blobs; a job finds its inputs by name in its
//! dependencies' outputs.

use std::ops::Range;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::{
    asset::{
        Container,
        report::{CharacterInfo, NoiseEstimate, Report, Sizes, Timings, psnr_plot_png},
    },
    method::{
        Family,
        vertex::{FitStats, FitStep, Model, StaticAverage},
    },
    rig::pose::Pose,
    trace::{AoBlock, SceneOptions, no_progress, trace_poses},
};

use super::{
    BakeError, BakeInputs, BakeParams, Evaluation, Plan, UnseenClips, UnseenFold,
    preview::{PreviewInfo, PreviewModel, Renderer, STILL_FRACTIONS, Subject, preview_clip},
};

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
    fn output(self) -> &'static str {
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
            Self::Preview => "preview",
        }
    }

    /// Units of progress the job is worth (poses for `sample`, time
    /// samples for `face`, layers for `slab`, the steps of a fit for `fit`
    /// and `unseen`, 1 else).
    pub fn work(&self) -> u64 {
        match self {
            Self::Sample { count, .. } | Self::Slab { count, .. } => *count as u64,
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

impl From<BakeError> for JobError {
    fn from(e: BakeError) -> Self {
        Self::Invalid(e.to_string())
    }
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

/// The fit's statistics and where its inputs came from, as `fit.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct FitInfo {
    fit: FitStats,
}

/// The evaluation and the noise estimate, as `evaluation.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct EvaluationInfo {
    evaluation: Evaluation,
    ground_truth_noise: NoiseEstimate,
    rays: u64,
}

/// A bake ready to run jobs: its inputs and its pose spaces.
#[derive(Debug, Clone)]
pub struct Bake<'a> {
    /// The imported inputs.
    pub inputs: &'a BakeInputs,
    /// The pose spaces and parameters.
    pub plan: Plan<'a>,
}

impl<'a> Bake<'a> {
    /// Checks the parameters against the inputs.
    pub fn new(inputs: &'a BakeInputs, params: BakeParams) -> Result<Self, BakeError> {
        let bake = Self {
            inputs,
            plan: Plan::new(&inputs.character, &inputs.clips, params)?,
        };
        if let Some(name) = &bake.plan.params.cubemap.clip
            && bake.plan.params.method.family() == Family::Cubemap
        {
            super::plan::clip_index(&inputs.clips, name)?;
        }
        if bake.plan.params.method.family() == Family::Grid {
            crate::method::grid::parts::parts(&inputs.character, bake.plan.params.grid.parts)
                .map_err(|e| BakeError::Param(e.to_string()))?;
        }
        Ok(bake)
    }

    /// Ray-point pairs the whole bake traces: what the service bounds per
    /// request.
    pub fn work(&self) -> u128 {
        let p = &self.plan.params;
        let frames = self.poses_in(PoseSet::HeldOut).saturating_sub(p.eval_poses);
        let parts = match p.method.family() {
            Family::Grid => self.grid_parts().map_or(0, |p| p.len()),
            _ => 0,
        };
        p.work(self.inputs.character.vertex_count(), frames, parts)
    }

    /// Poses `range` of a set, seeded: the same request gives the same
    /// poses; only those in the range are built.
    pub fn poses(&self, set: PoseSet, range: Range<usize>) -> Vec<Pose> {
        match set {
            PoseSet::Reference => self.plan.reference_poses_in(range),
            PoseSet::HeldOut => self
                .plan
                .test_poses_in(range)
                .into_iter()
                .map(|t| t.pose)
                .collect(),
            PoseSet::Noise => {
                let rows = self.plan.noise_rows();
                rows.get(range)
                    .unwrap_or_default()
                    .iter()
                    .flat_map(|&r| self.plan.test_poses_in(r..r + 1))
                    .map(|t| t.pose)
                    .collect()
            }
        }
    }

    /// Runs one job. `deps` are the outputs of the job's dependencies (in
    /// any order); `resume` is the last checkpoint of an earlier attempt.
    pub fn run_job(
        &self,
        spec: &JobSpec,
        deps: &[&JobOutput],
        resume: Option<Checkpoint>,
        sink: &mut dyn JobSink,
    ) -> Result<JobOutput, JobError> {
        let family = self.plan.params.method.family();
        match (spec, family) {
            (JobSpec::Sample { set, first, count }, Family::Vertex) => {
                self.sample(*set, *first, *count, resume, sink)
            }
            (JobSpec::Fit, Family::Vertex) => self.fit(deps, sink),
            (JobSpec::Unseen { fold }, Family::Vertex) => self.unseen(*fold, deps, sink),
            (JobSpec::Evaluate, Family::Vertex) => self.evaluate(deps),
            (JobSpec::Assemble, Family::Vertex) => self.assemble(deps),
            (JobSpec::Face { face, times }, Family::Cubemap) => {
                self.face(*face, *times, resume, sink)
            }
            (JobSpec::Evaluate, Family::Cubemap) => self.cubemap_evaluate(deps),
            (JobSpec::Assemble, Family::Cubemap) => self.cubemap_assemble(deps),
            (JobSpec::Slab { part, first, count }, Family::Grid) => {
                self.slab(*part, *first, *count, resume, sink)
            }
            (JobSpec::Evaluate, Family::Grid) => self.grid_evaluate(deps),
            (JobSpec::Assemble, Family::Grid) => self.grid_assemble(deps),
            (
                JobSpec::Sample { .. }
                | JobSpec::Fit
                | JobSpec::Unseen { .. }
                | JobSpec::Face { .. }
                | JobSpec::Slab { .. },
                _,
            ) => Err(JobError::Invalid(format!(
                "a {} job is not part of a {} bake",
                spec.kind(),
                self.plan.params.method
            ))),
            (JobSpec::Preview, _) => Err(JobError::Invalid(
                "a preview job needs a renderer: run it with Bake::preview".into(),
            )),
        }
    }

    /// Runs a `preview` job: the stills and the animation of the asset
    /// that `assemble` produced, on `renderer`, and `previews.json`
    /// listing them.
    pub fn preview(
        &self,
        deps: &[&JobOutput],
        renderer: &mut dyn Renderer,
    ) -> Result<JobOutput, JobError> {
        let assembled = find(deps, "asset")?;
        let asset = named(assembled, "asset")?;
        let clips = &self.inputs.clips;
        let vertex_model;
        let cubemap_model;
        let grid_model;
        let owners: Vec<u32>;
        let mut grid_truth = None;
        let (model, clip) = match self.plan.params.method.family() {
            Family::Cubemap => {
                cubemap_model = decode_cubemap(asset)?;
                // The ground's truth is what the cubemap stores: Eq. 3.1.
                let kroon = self
                    .plan
                    .params
                    .cubemap_truth(&cubemap_model.layout.spheroid);
                (
                    PreviewModel::Cubemap(&cubemap_model, kroon),
                    Some(&clips[self.cubemap_clip()?]),
                )
            }
            Family::Grid => {
                grid_model = decode_grid(asset)?;
                let parts = self.grid_parts()?;
                owners = crate::method::grid::parts::owner_indices(
                    &parts,
                    self.inputs.character.vertex_count(),
                );
                // The grids' truth is traced as their evaluation traces it.
                grid_truth = Some(self.plan.params.grid.truth(
                    self.grid_distance(&parts),
                    self.plan.params.held_out_surface().seed,
                ));
                (
                    PreviewModel::Grid(&grid_model, &owners),
                    preview_clip(clips, &self.plan.test).map(|i| &clips[i]),
                )
            }
            Family::Vertex => {
                vertex_model = decode(asset)?;
                (
                    PreviewModel::Vertex(&vertex_model),
                    preview_clip(clips, &self.plan.test).map(|i| &clips[i]),
                )
            }
        };
        let surface = grid_truth.unwrap_or_else(|| self.plan.params.held_out_surface());
        let subject = Subject {
            character: &self.inputs.character,
            model,
            surface,
        };
        let times: Vec<f32> = clip.map_or_else(Vec::new, |c| {
            STILL_FRACTIONS.iter().map(|f| f * c.duration).collect()
        });
        let mut previews = subject.stills(clip, &times, renderer)?;
        if let Some(c) = clip {
            previews.push(subject.animation(c, renderer)?);
        }
        let mut out = JobOutput::default();
        let infos: Vec<&PreviewInfo> = previews.iter().map(|p| &p.info).collect();
        out.push("previews.json", json(&infos));
        for p in previews {
            out.push(&p.info.name, p.png);
        }
        out.timings = assembled.timings;
        Ok(out)
    }

    fn sample(
        &self,
        set: PoseSet,
        first: usize,
        count: usize,
        resume: Option<Checkpoint>,
        sink: &mut dyn JobSink,
    ) -> Result<JobOutput, JobError> {
        let started = Instant::now();
        let total = self.poses_in(set);
        let end = first.checked_add(count).filter(|&e| e <= total);
        let Some(end) = end else {
            return Err(JobError::Invalid(format!(
                "poses {first}..{} are outside the set's {total} poses",
                first.saturating_add(count),
            )));
        };
        let poses = self.poses(set, first..end);
        let vertices = self.inputs.character.vertex_count();
        let mut done = IndexedBlock {
            first,
            block: AoBlock {
                vertices,
                values: Vec::with_capacity(vertices * count),
            },
        };
        if let Some(cp) = resume.filter(|cp| cp.step == "sample") {
            let saved = IndexedBlock::from_bytes(&cp.data, vertices)?;
            let ok = saved.first == first
                && saved.block.poses() as u64 == cp.cursor
                && saved.block.poses() <= count;
            if !ok {
                return Err(JobError::Invalid(
                    "the checkpoint does not belong to this job".into(),
                ));
            }
            done = saved;
        }
        let p = &self.plan.params;
        let surface = match set {
            PoseSet::Reference => p.surface(),
            PoseSet::HeldOut => p.held_out_surface(),
            PoseSet::Noise => p.noise_surface(),
        };
        let options = SceneOptions::default();
        sink.progress(done.block.poses() as u64, count as u64);
        for pose in &poses[done.block.poses()..] {
            let row = trace_poses(
                &self.inputs.character,
                std::slice::from_ref(pose),
                &options,
                &surface,
                &no_progress,
            )
            .map_err(|e| JobError::Invalid(e.to_string()))?;
            done.block.values.extend(row.values);
            let cursor = done.block.poses() as u64;
            sink.progress(cursor, count as u64);
            if cursor < count as u64 {
                sink.checkpoint(Checkpoint {
                    step: "sample".into(),
                    cursor,
                    data: done.to_bytes(),
                })
                .map_err(JobError::Stopped)?;
            }
        }
        let mut out = JobOutput::default();
        out.push(set.output(), done.to_bytes());
        let seconds = started.elapsed().as_secs_f64();
        match set {
            PoseSet::Reference => out.timings.reference_trace_s = seconds,
            _ => out.timings.test_trace_s = seconds,
        }
        Ok(out)
    }

    /// The blocks of a set, from `deps`, stacked in pose order; every pose
    /// of the set must be there exactly once.
    fn stack(&self, set: PoseSet, deps: &[&JobOutput]) -> Result<AoBlock, JobError> {
        let vertices = self.inputs.character.vertex_count();
        let mut blocks = Vec::new();
        for d in deps {
            for o in d.outputs.iter().filter(|o| o.name == set.output()) {
                blocks.push(IndexedBlock::from_bytes(&o.bytes, vertices)?);
            }
        }
        blocks.sort_by_key(|b| b.first);
        let mut values = Vec::new();
        let mut next = 0;
        for b in blocks {
            if b.first != next {
                return Err(JobError::Invalid(format!(
                    "{} blocks do not cover the poses in order (expected pose {next}, got {})",
                    set.output(),
                    b.first
                )));
            }
            next += b.block.poses();
            values.extend(b.block.values);
        }
        let want = self.poses_in(set);
        if next != want {
            return Err(JobError::Invalid(format!(
                "{} blocks hold {next} poses, not {want}",
                set.output()
            )));
        }
        Ok(AoBlock { vertices, values })
    }

    /// The number of poses in a set.
    pub fn poses_in(&self, set: PoseSet) -> usize {
        match set {
            PoseSet::Reference => self.plan.params.poses,
            PoseSet::HeldOut => self.plan.test_count(),
            PoseSet::Noise => self.plan.noise_rows().len(),
        }
    }

    pub(super) fn header(&self) -> crate::method::vertex::AssetHeaderFields {
        self.plan
            .header(&self.inputs.character_digest, &self.inputs.clip_digests)
    }

    fn fit(&self, deps: &[&JobOutput], sink: &mut dyn JobSink) -> Result<JobOutput, JobError> {
        let reference = self.stack(PoseSet::Reference, deps)?;
        let started = Instant::now();
        let poses = self.plan.reference_poses();
        let (model, fit) = self.plan.fit_stepwise(
            &poses,
            &reference,
            &self.plan.reference_sources(),
            &mut fit_progress(sink),
        )?;
        let baseline = Model::StaticAverage(StaticAverage::fit(
            &reference.select(self.plan.baseline_rows()),
        ));
        let mut out = JobOutput::default();
        out.push("model", model.to_container(self.header()).to_bytes());
        out.push("baseline", baseline.to_container(self.header()).to_bytes());
        out.push("fit.json", json(&FitInfo { fit }));
        out.timings.reference_trace_s = deps.iter().map(|d| d.timings.reference_trace_s).sum();
        out.timings.fit_s = started.elapsed().as_secs_f64();
        Ok(out)
    }

    /// One fold of the unseen-clips evaluation (an `unseen` job): its
    /// [`UnseenFold`] as `unseen-{fold}.json`.
    fn unseen(
        &self,
        fold: usize,
        deps: &[&JobOutput],
        sink: &mut dyn JobSink,
    ) -> Result<JobOutput, JobError> {
        let clips = self.plan.fold_clips();
        let Some(&clip) = clips.get(fold) else {
            return Err(JobError::Invalid(format!(
                "fold {fold} is outside the bake's {} unseen-clip folds",
                clips.len()
            )));
        };
        let reference = self.stack(PoseSet::Reference, deps)?;
        let truth = self.stack(PoseSet::HeldOut, deps)?;
        let started = Instant::now();
        let result = self.plan.unseen_fold(
            clip,
            &self.plan.reference_poses(),
            &reference,
            &self.plan.reference_sources(),
            &self.plan.test_poses(),
            &truth,
            &mut fit_progress(sink),
        )?;
        let mut out = JobOutput::default();
        out.push(&unseen_output(fold), json(&result));
        out.timings.unseen_s = started.elapsed().as_secs_f64();
        Ok(out)
    }

    fn evaluate(&self, deps: &[&JobOutput]) -> Result<JobOutput, JobError> {
        let fit = find(deps, "model")?;
        let model = decode(named(fit, "model")?)?;
        let Model::StaticAverage(baseline) = decode(named(fit, "baseline")?)? else {
            return Err(JobError::Invalid(
                "the baseline is not a static average".into(),
            ));
        };
        let truth = self.stack(PoseSet::HeldOut, deps)?;
        let again = self.stack(PoseSet::Noise, deps)?;
        let started = Instant::now();
        let tests = self.plan.test_poses();
        let mut evaluation = self.plan.evaluate(&model, &baseline, &tests, &truth);
        // The folds, in their order, from the `unseen` jobs.
        let folds = (0..self.plan.fold_clips().len())
            .map(|fold| {
                let name = unseen_output(fold);
                parse::<UnseenFold>(named(find(deps, &name)?, &name)?)
            })
            .collect::<Result<Vec<_>, _>>()?;
        if !folds.is_empty() {
            evaluation.unseen_clips = Some(UnseenClips::of(folds));
        }
        let noise_rows = self.plan.noise_rows();
        let ground_truth_noise = NoiseEstimate::of(&noise_rows, &truth, &again);
        let vertices = self.inputs.character.vertex_count() as u64;
        let rays = (self.plan.params.poses + tests.len()) as u64
            * vertices
            * u64::from(self.plan.params.samples);
        let mut out = JobOutput::default();
        out.push(
            "evaluation.json",
            json(&EvaluationInfo {
                evaluation,
                ground_truth_noise,
                rays,
            }),
        );
        out.timings = Timings {
            test_trace_s: deps.iter().map(|d| d.timings.test_trace_s).sum(),
            unseen_s: deps.iter().map(|d| d.timings.unseen_s).sum(),
            evaluate_s: started.elapsed().as_secs_f64(),
            ..fit.timings
        };
        Ok(out)
    }

    fn assemble(&self, deps: &[&JobOutput]) -> Result<JobOutput, JobError> {
        let fit = find(deps, "model")?;
        let evaluated = find(deps, "evaluation.json")?;
        let asset = named(fit, "model")?.to_vec();
        let model = decode(&asset)?;
        let FitInfo { fit: fit_stats } = parse(named(fit, "fit.json")?)?;
        let info: EvaluationInfo = parse(named(evaluated, "evaluation.json")?)?;
        let plan = &self.plan;
        let clips = &self.inputs.clips;
        let names =
            |idx: &[usize]| -> Vec<String> { idx.iter().map(|&i| clips[i].name.clone()).collect() };
        let character = &self.inputs.character;
        let vertices = character.vertex_count();
        let report = Report {
            method: plan.params.method,
            bake_key: self.header().bake_key,
            params: plan.params.clone(),
            character: CharacterInfo {
                digest: self.inputs.character_digest.clone(),
                vertices,
                triangles: character.triangles.len(),
                clips: clips.iter().map(|c| c.name.clone()).collect(),
                train_clips: names(&plan.train),
                test_clips: names(&plan.test),
                joint_angle_parameters: plan.joint_angles.len(),
                handle_coordinates: plan.handles.len(),
            },
            rays: info.rays,
            timings: evaluated.timings,
            fit: fit_stats,
            sizes: Sizes {
                asset_bytes: asset.len(),
                model_bytes: model.bytes(),
                baseline_bytes: 2 * vertices,
            },
            evaluation: info.evaluation,
            ground_truth_noise: info.ground_truth_noise,
        };
        let plot = psnr_plot_png(&report)
            .map_err(|e| JobError::Failed(format!("cannot draw the plot: {e}")))?;
        let mut out = JobOutput::default();
        out.push("asset", asset);
        out.push(
            "report.json",
            serde_json::to_vec_pretty(&report).expect("reports serialise"),
        );
        out.push("plot.png", plot);
        out.timings = evaluated.timings;
        Ok(out)
    }
}

/// A fit's progress on `sink`, in steps ([`FitStep`]): 0 now, then one
/// more as each step ends (what `fit` and `unseen` jobs are worth).
fn fit_progress(sink: &mut dyn JobSink) -> impl FnMut(FitStep) + '_ {
    let steps = FitStep::ALL.len() as u64;
    sink.progress(0, steps);
    move |step| sink.progress(step.done(), steps)
}

/// The output of the `unseen` job of `fold`.
fn unseen_output(fold: usize) -> String {
    format!("unseen-{fold}.json")
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

fn decode(bytes: &[u8]) -> Result<Model, JobError> {
    let container = Container::from_bytes(bytes).map_err(|e| JobError::Invalid(e.to_string()))?;
    Model::from_container(&container)
        .map(|(m, _)| m)
        .map_err(|e| JobError::Invalid(e.to_string()))
}

/// A grid asset's model.
pub(super) fn decode_grid(bytes: &[u8]) -> Result<crate::method::grid::model::GridModel, JobError> {
    let container = Container::from_bytes(bytes).map_err(|e| JobError::Invalid(e.to_string()))?;
    crate::method::grid::model::GridModel::from_container(&container)
        .map(|(m, _)| m)
        .map_err(|e| JobError::Invalid(e.to_string()))
}

/// A cubemap asset's model.
pub(super) fn decode_cubemap(
    bytes: &[u8],
) -> Result<crate::method::cubemap::model::CubemapModel, JobError> {
    let container = Container::from_bytes(bytes).map_err(|e| JobError::Invalid(e.to_string()))?;
    crate::method::cubemap::model::CubemapModel::from_container(&container)
        .map(|(m, _)| m)
        .map_err(|e| JobError::Invalid(e.to_string()))
}
