//! The pose spaces of a bake: which clips train and which test, the
//! joint-angle layout and the handles, and from them the seeded
//! reference, held-out and noise poses that `sample` jobs trace.

use std::ops::Range;
use std::sync::Arc;

use rand::SeedableRng as _;
use rand_chacha::ChaCha8Rng;

use crate::{
    Character, Clip,
    method::texel::{
        atlas::{AtlasOptions, PADDING, TexelAtlas, rest_positions},
        trace::{drawn_texels, trace_texels},
    },
    method::vertex::{AssetHeaderFields, FitStats, FitStep, Model, PrimitiveSpan, Source},
    method::{Family, Method},
    pose_space::{self, ParamError},
    pose_space::{ClipFrame, Handles, JointAngles, LayoutOptions, random_clip_frames},
    rig::pose::Pose,
    trace::{
        AoBlock, HELD_OUT_SEED, Progress, SceneOptions, SurfaceParams, TraceError, trace_poses,
    },
};

use super::{
    BakeError, BakeParams, ReferenceSource,
    params::{NOISE_POSES, bake_key},
};

/// Mixed into the seed of perturbed reference poses ("perturb!").
const PERTURBED_SEED: u64 = 0x7065_7274_7572_6221;

/// The pose spaces of a bake: the training and test clips, the joint-angle
/// layout (ranges from the training clips) and the handles.
#[derive(Debug, Clone)]
pub struct Plan<'a> {
    /// The character.
    pub character: &'a Character,
    /// Every clip.
    pub clips: &'a [Clip],
    /// Indices of the training clips.
    pub train: Vec<usize>,
    /// Indices of the test clips.
    pub test: Vec<usize>,
    /// Joint angles over the training clips.
    pub joint_angles: JointAngles,
    /// Kirk & Arikan's handles.
    pub handles: Handles,
    /// The parameters.
    pub params: BakeParams,
    /// Where AO is traced, fitted and judged.
    pub receivers: Receivers,
    /// The training clips, in `train` order (what clip-frame sampling and
    /// the joint-angle ranges read).
    train_clips: Vec<Clip>,
}

/// Where a bake of `params` traces, fits and judges AO: a texel bake
/// generates its atlas here, from the bind pose (deterministic: every
/// job of a bake, on any worker, sees the same texels).
fn receivers(character: &Character, params: &BakeParams) -> Result<Receivers, BakeError> {
    Ok(match params.method.family() {
        Family::Texel => {
            let t = &params.texel;
            let atlas = match t.uv_set {
                None => TexelAtlas::of_character(
                    character,
                    &AtlasOptions {
                        size: t.atlas,
                        padding: PADDING,
                    },
                ),
                Some(k) => {
                    let uvs = match character.uv_sets.get(k as usize) {
                        Some(Ok(uvs)) => uvs,
                        Some(Err(why)) => {
                            return Err(BakeError::Param(format!(
                                "texel.uv_set: TEXCOORD_{k} is not whole: {why}"
                            )));
                        }
                        None => {
                            return Err(BakeError::Param(format!(
                                "texel.uv_set: the character has no TEXCOORD_{k} ({} UV sets)",
                                character.uv_sets.len()
                            )));
                        }
                    };
                    // At rest, as the scene places it: two instances of
                    // one mesh on the same UVs are two places.
                    TexelAtlas::of_uv_set(
                        &rest_positions(character),
                        &character.triangles,
                        (k, uvs),
                        t.atlas,
                    )
                }
            }
            .map_err(|e| BakeError::Param(format!("texel: {e}")))?;
            Receivers::Texels(Arc::new(atlas))
        }
        Family::Vertex | Family::Cubemap | Family::Grid => Receivers::Vertices,
    })
}

/// Where a bake traces, fits and judges AO: the columns of its
/// [`AoBlock`]s.
#[derive(Debug, Clone, Default)]
pub enum Receivers {
    /// The character's vertices (the per-vertex family).
    #[default]
    Vertices,
    /// The texels of an atlas of the character (the texel family).
    Texels(Arc<TexelAtlas>),
}

fn select(clips: &[Clip], names: &[String]) -> Result<Vec<usize>, BakeError> {
    if names.is_empty() {
        return Ok((0..clips.len()).collect());
    }
    names.iter().map(|name| clip_index(clips, name)).collect()
}

/// The index of the clip named `name`; the error lists the clips there are.
pub(crate) fn clip_index(clips: &[Clip], name: &str) -> Result<usize, BakeError> {
    clips
        .iter()
        .position(|c| c.name == name)
        .ok_or_else(|| BakeError::UnknownClip {
            name: name.to_owned(),
            known: clips
                .iter()
                .map(|c| c.name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
        })
}

/// A held-out pose and where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct TestPose {
    /// A clip index and time, or `None` for a random pose.
    pub frame: Option<ClipFrame>,
    /// The pose.
    pub pose: Pose,
}

impl<'a> Plan<'a> {
    /// Checks the parameters and derives the pose spaces.
    pub fn new(
        character: &'a Character,
        clips: &'a [Clip],
        params: BakeParams,
    ) -> Result<Self, BakeError> {
        if clips.is_empty() {
            return Err(BakeError::Param(
                "the character has no clips: pose-dependent AO needs at least one animation (pass --clips FILE)".into(),
            ));
        }
        params.validate()?;
        let p = &params;
        let train = select(clips, &p.train_clips)?;
        let test = select(clips, &p.test_clips)?;
        let train_clips: Vec<Clip> = train.iter().map(|&i| clips[i].clone()).collect();
        let joint_angles = match pose_space::joint_angles(
            character,
            &train_clips,
            LayoutOptions {
                margin: p.range_margin,
                scales: p.scale_parameters,
                ..LayoutOptions::default()
            },
        ) {
            Ok(layout) => layout,
            // A static mesh's one pose: the static average needs no
            // angles, and texel-linear is then its static AO texture.
            Err(ParamError::NothingAnimated)
                if !p.method.family().needs_joint_angles()
                    || matches!(p.method, Method::StaticAverage | Method::TexelLinear) =>
            {
                JointAngles::default()
            }
            Err(ParamError::NothingAnimated) => {
                return Err(BakeError::Param(format!(
                    "no clip moves the mesh (a static mesh, or clips that animate nothing it is skinned to): {} fits AO to poses; bake static-average (per-vertex AO) or texel-linear (an AO texture) for a mesh that does not move, or give clips that move it (--clips FILE)",
                    p.method
                )));
            }
            Err(e) => return Err(e.into()),
        };
        Ok(Self {
            character,
            clips,
            train,
            test,
            joint_angles,
            handles: pose_space::handles(character),
            receivers: receivers(character, &params)?,
            params,
            train_clips,
        })
    }

    /// The plan with AO traced, fitted and judged at `receivers`.
    pub fn with_receivers(self, receivers: Receivers) -> Self {
        Self { receivers, ..self }
    }

    /// Receivers per pose: the columns of the bake's [`AoBlock`]s.
    pub fn receiver_count(&self) -> usize {
        match &self.receivers {
            Receivers::Vertices => self.character.vertex_count(),
            Receivers::Texels(t) => t.texels.len(),
        }
    }

    /// The AO of every receiver in every pose of a batch (see
    /// [`trace_poses`] and [`trace_texels`]).
    pub fn trace(
        &self,
        poses: &[Pose],
        options: &SceneOptions,
        surface: &SurfaceParams,
        progress: Progress<'_>,
    ) -> Result<AoBlock, TraceError> {
        match &self.receivers {
            Receivers::Vertices => trace_poses(self.character, poses, options, surface, progress),
            Receivers::Texels(t) => {
                trace_texels(self.character, &t.texels, poses, options, surface, progress)
            }
        }
    }

    /// Which receivers draw something in `pose` (see
    /// [`Character::drawn_vertices`] and [`drawn_texels`]): the
    /// evaluations judge only them.
    pub fn drawn(&self, pose: &Pose) -> Vec<bool> {
        let character = self.character;
        match &self.receivers {
            Receivers::Vertices => character.drawn_vertices(&character.skin(pose).positions),
            Receivers::Texels(t) => drawn_texels(character, &t.texels, pose),
        }
    }

    /// Poses `range` of `count` random joint-angle poses: every vector is
    /// drawn (the sequence is seeded), only those in `range` are built.
    fn random_poses(&self, count: usize, seed: u64, range: Range<usize>) -> Vec<Pose> {
        let vectors = pose_space::sample_uniform(&self.joint_angles, count, seed);
        vectors
            .get(range)
            .unwrap_or_default()
            .iter()
            .map(|q| {
                pose_space::pose(&self.joint_angles, &self.character.skeleton, q)
                    .expect("sampled vectors have the layout's length")
            })
            .collect()
    }

    /// Poses `range` of `count` random training-clip frames.
    fn clip_poses(&self, count: usize, seed: u64, range: Range<usize>) -> Vec<Pose> {
        let frames = random_clip_frames(&self.train_clips, count, seed);
        frames
            .get(range)
            .unwrap_or_default()
            .iter()
            .map(|f| Pose::sample(&self.character.skeleton, &self.train_clips[f.clip], f.time))
            .collect()
    }

    /// How many reference poses are random, clip frames and perturbed
    /// clip frames, in that order.
    fn reference_counts(&self) -> [usize; 3] {
        let n = self.params.poses;
        match self.params.reference {
            ReferenceSource::Random => [n, 0, 0],
            ReferenceSource::Clips => [0, n, 0],
            ReferenceSource::Mixed => [n / 2, n - n / 2, 0],
            ReferenceSource::Perturbed => [0, n - n / 2, n / 2],
            ReferenceSource::Cv => [n / 3, n / 3, n - 2 * (n / 3)],
        }
    }

    /// Poses `range` of `count` perturbed training-clip frames: random
    /// frames (another seed than the plain ones) with every joint
    /// parameter moved at random (see [`pose_space::perturb`]).
    fn perturbed_poses(&self, count: usize, seed: u64, range: Range<usize>) -> Vec<Pose> {
        let seed = seed ^ PERTURBED_SEED;
        let frames = random_clip_frames(&self.train_clips, count, seed);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        // Another stream than the one that drew the frames.
        rng.set_stream(1);
        let skeleton = &self.character.skeleton;
        let mut poses = Vec::new();
        for (i, f) in frames.iter().enumerate().take(range.end) {
            // Every earlier pose's offsets are drawn (on a stand-in), so a
            // batch's poses are those of the whole set; only the batch's
            // frames are sampled.
            let mut q = if range.contains(&i) {
                self.joint_angles.params(
                    skeleton,
                    &Pose::sample(skeleton, &self.train_clips[f.clip], f.time).locals,
                )
            } else {
                vec![0.0; self.joint_angles.len()]
            };
            pose_space::perturb(
                &self.joint_angles,
                &mut q,
                self.params.perturbation,
                &mut rng,
            );
            if range.contains(&i) {
                poses.push(
                    pose_space::pose(&self.joint_angles, skeleton, &q)
                        .expect("the parameters have the layout's length"),
                );
            }
        }
        poses
    }

    /// The reference poses, seeded: what `sample` jobs trace, in batches.
    pub fn reference_poses(&self) -> Vec<Pose> {
        self.reference_poses_in(0..self.params.poses)
    }

    /// Reference poses `range` (random poses, then clip frames, then
    /// perturbed clip frames), built alone: a `sample` job builds only its
    /// batch.
    pub fn reference_poses_in(&self, range: Range<usize>) -> Vec<Pose> {
        let seed = self.params.seed;
        let counts = self.reference_counts();
        let end = range.end.min(self.params.poses);
        let mut poses = Vec::new();
        let mut first = 0;
        for (kind, &count) in counts.iter().enumerate() {
            let (from, to) = (range.start.max(first), end.min(first + count));
            if from < to {
                let part = from - first..to - first;
                poses.extend(match kind {
                    0 => self.random_poses(count, seed, part),
                    1 => self.clip_poses(count, seed, part),
                    _ => self.perturbed_poses(count, seed, part),
                });
            }
            first += count;
        }
        poses
    }

    /// Where each reference pose comes from, in order (clips are indices
    /// into [`Plan::clips`]).
    pub fn reference_sources(&self) -> Vec<Source> {
        let seed = self.params.seed;
        let [random, frames, perturbed] = self.reference_counts();
        let plain = random_clip_frames(&self.train_clips, frames, seed);
        let moved = random_clip_frames(&self.train_clips, perturbed, seed ^ PERTURBED_SEED);
        std::iter::repeat_n(Source::Random, random)
            .chain(plain.iter().map(|f| Source::Frame(self.train[f.clip])))
            .chain(moved.iter().map(|f| Source::Perturbed(self.train[f.clip])))
            .collect()
    }

    /// The reference rows that are plain clip frames, or every row when
    /// none is: what the static average is fitted to (the mean over
    /// training clip frames, the strongest static baseline; the mean over
    /// random or perturbed poses is weaker).
    pub fn baseline_rows(&self) -> Vec<usize> {
        let [random, frames, _] = self.reference_counts();
        if frames == 0 {
            (0..self.params.poses).collect()
        } else {
            (random..random + frames).collect()
        }
    }

    /// Every frame of every test clip at `eval_fps`, in order.
    fn test_frames(&self) -> Vec<ClipFrame> {
        self.test
            .iter()
            .flat_map(|&clip| {
                self.clips[clip]
                    .frame_times(self.params.eval_fps)
                    .into_iter()
                    .map(move |time| ClipFrame { clip, time })
            })
            .collect()
    }

    /// Held-out poses: random poses from another seed, then every frame of
    /// every test clip at `eval_fps`.
    pub fn test_poses(&self) -> Vec<TestPose> {
        self.test_poses_in(0..usize::MAX)
    }

    /// Held-out poses `range`, built alone.
    pub fn test_poses_in(&self, range: Range<usize>) -> Vec<TestPose> {
        let e = self.params.eval_poses;
        let seed = self.params.seed ^ HELD_OUT_SEED;
        let mut poses: Vec<TestPose> = self
            .random_poses(e, seed, range.start.min(e)..range.end.min(e))
            .into_iter()
            .map(|pose| TestPose { frame: None, pose })
            .collect();
        let frames = self.test_frames();
        let (from, to) = (range.start.saturating_sub(e), range.end.saturating_sub(e));
        for &f in frames
            .get(from.min(frames.len())..to.min(frames.len()))
            .unwrap_or_default()
        {
            poses.push(TestPose {
                frame: Some(f),
                pose: Pose::sample(&self.character.skeleton, &self.clips[f.clip], f.time),
            });
        }
        poses
    }

    /// How many held-out poses there are, without building them.
    pub fn test_count(&self) -> usize {
        self.params.eval_poses + self.test_frames().len()
    }

    /// Indices of up to 8 held-out poses, evenly spread, to trace a second
    /// time for the ground truth's noise (see `report::NoiseEstimate`).
    pub fn noise_rows(&self) -> Vec<usize> {
        let n = self.test_count();
        let k = n.min(NOISE_POSES);
        (0..k).map(|i| i * n / k).collect()
    }

    /// Fits the method to the reference poses' AO (the `fit` job's work;
    /// the dispatch on the method is [`crate::method::vertex::fit`]).
    /// `sources` says where each pose comes from (see
    /// [`Plan::reference_sources`]).
    pub fn fit(
        &self,
        poses: &[Pose],
        ao: &AoBlock,
        sources: &[Source],
    ) -> Result<(Model, FitStats), BakeError> {
        self.fit_stepwise(poses, ao, sources, &mut |_| {})
    }

    /// [`Plan::fit`], calling `on_step` (on this thread) as each step of
    /// the fit ends.
    pub fn fit_stepwise(
        &self,
        poses: &[Pose],
        ao: &AoBlock,
        sources: &[Source],
        on_step: &mut dyn FnMut(FitStep),
    ) -> Result<(Model, FitStats), BakeError> {
        let p = &self.params;
        crate::method::vertex::fit(
            p.method,
            (&p.linear, &p.clustered),
            p.seed,
            self.character,
            (&self.joint_angles, &self.handles),
            poses,
            ao,
            sources,
            on_step,
        )
        .map_err(BakeError::Fit)
    }

    /// The asset header fields of this bake.
    pub fn header(&self, character: &str, clips: &[String]) -> AssetHeaderFields {
        AssetHeaderFields {
            generator: format!("aobake {}", env!("CARGO_PKG_VERSION")),
            bake_key: bake_key(character, clips, &self.params),
            character: character.to_owned(),
            clips: clips.to_vec(),
            params: self.params.canonical(),
            primitives: self
                .character
                .primitives
                .iter()
                .map(|p| PrimitiveSpan {
                    node: p.node,
                    mesh: p.mesh,
                    primitive: p.primitive,
                    first: p.vertices.start,
                    count: p.vertices.len(),
                })
                .collect(),
        }
    }
}
