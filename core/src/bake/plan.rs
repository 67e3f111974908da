//! The pose spaces of a bake: which clips train and which test, the
//! joint-angle layout and the handles, and from them the seeded
//! reference, held-out and noise poses that `sample` jobs trace.

use std::ops::Range;

use crate::{
    Character, Clip,
    method::Family,
    method::vertex::{AssetHeaderFields, FitStats, Model},
    pose_space::ParamError,
    pose_space::{ClipFrame, Handles, JointAngles, LayoutOptions, random_clip_frames},
    rig::pose::Pose,
    trace::AoBlock,
};

use super::{
    BakeError, BakeParams, ReferenceSource,
    params::{HELD_OUT_SEED, NOISE_POSES, bake_key},
};

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
    /// The training clips, in `train` order (what clip-frame sampling and
    /// the joint-angle ranges read).
    train_clips: Vec<Clip>,
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
        let joint_angles = match JointAngles::from_clips(
            character,
            &train_clips,
            LayoutOptions {
                margin: p.range_margin,
                ..LayoutOptions::default()
            },
        ) {
            Ok(layout) => layout,
            // A cubemap bakes the world around the clip as it plays, root
            // motion included (Kroon's spinning cube has nothing else), and
            // a grid is baked per part, so neither needs joint angles.
            Err(ParamError::NothingAnimated) if p.method.family() != Family::Vertex => {
                JointAngles::default()
            }
            Err(e) => return Err(e.into()),
        };
        Ok(Self {
            character,
            clips,
            train,
            test,
            joint_angles,
            handles: Handles::new(character),
            params,
            train_clips,
        })
    }

    /// Poses `range` of `count` random joint-angle poses: every vector is
    /// drawn (the sequence is seeded), only those in `range` are built.
    fn random_poses(&self, count: usize, seed: u64, range: Range<usize>) -> Vec<Pose> {
        let vectors = self.joint_angles.sample_uniform(count, seed);
        vectors
            .get(range)
            .unwrap_or_default()
            .iter()
            .map(|q| {
                self.joint_angles
                    .pose(&self.character.skeleton, q)
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

    /// How many reference poses are random (they come first).
    fn random_reference_count(&self) -> usize {
        let n = self.params.poses;
        match self.params.reference {
            ReferenceSource::Random => n,
            ReferenceSource::Clips => 0,
            ReferenceSource::Mixed => n / 2,
        }
    }

    /// The reference poses, seeded: what `sample` jobs trace, in batches.
    pub fn reference_poses(&self) -> Vec<Pose> {
        self.reference_poses_in(0..self.params.poses)
    }

    /// Reference poses `range` (random poses first, then clip frames), built
    /// alone: a `sample` job builds only its batch.
    pub fn reference_poses_in(&self, range: Range<usize>) -> Vec<Pose> {
        let (n, seed) = (self.params.poses, self.params.seed);
        let random = self.random_reference_count();
        let end = range.end.min(n);
        let mut poses = Vec::new();
        if range.start < random {
            poses.extend(self.random_poses(random, seed, range.start..end.min(random)));
        }
        if end > random {
            let from = range.start.max(random) - random;
            poses.extend(self.clip_poses(n - random, seed, from..end - random));
        }
        poses
    }

    /// Where each reference pose comes from, in order: `None` for a random
    /// pose, the clip's index (into [`Plan::clips`]) for a clip frame.
    pub fn reference_sources(&self) -> Vec<Option<usize>> {
        let (n, seed) = (self.params.poses, self.params.seed);
        let random = self.random_reference_count();
        let frames = random_clip_frames(&self.train_clips, n - random, seed);
        std::iter::repeat_n(None, random)
            .chain(frames.iter().map(|f| Some(self.train[f.clip])))
            .collect()
    }

    /// The reference rows that are clip frames, or every row when none
    /// is: what the static average is fitted to (the mean over training
    /// clip frames, the strongest static baseline; the mean over random
    /// poses is weaker).
    pub fn baseline_rows(&self) -> Vec<usize> {
        let sources = self.reference_sources();
        let frames: Vec<usize> = (0..sources.len())
            .filter(|&i| sources[i].is_some())
            .collect();
        if frames.is_empty() {
            (0..sources.len()).collect()
        } else {
            frames
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
    /// `groups` is each pose's clip (`None`: a random pose; see
    /// [`Plan::reference_sources`]).
    pub fn fit(
        &self,
        poses: &[Pose],
        ao: &AoBlock,
        groups: &[Option<usize>],
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
            groups,
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
        }
    }
}
