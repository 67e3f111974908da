//! The pose spaces of a bake: which clips train and which test, the
//! joint-angle layout and the handles, and from them the seeded
//! reference, held-out and noise poses that `sample` jobs trace.

use crate::{
    Character, Clip,
    method::vertex::{AssetHeaderFields, FitStats, Model},
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
    names
        .iter()
        .map(|name| {
            clips
                .iter()
                .position(|c| &c.name == name)
                .ok_or_else(|| BakeError::UnknownClip {
                    name: name.clone(),
                    known: clips
                        .iter()
                        .map(|c| c.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", "),
                })
        })
        .collect()
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
        let joint_angles = JointAngles::from_clips(
            character,
            &train_clips,
            LayoutOptions {
                margin: p.range_margin,
                ..LayoutOptions::default()
            },
        )?;
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

    fn random_poses(&self, count: usize, seed: u64) -> Vec<Pose> {
        self.joint_angles
            .sample_uniform(count, seed)
            .iter()
            .map(|q| {
                self.joint_angles
                    .pose(&self.character.skeleton, q)
                    .expect("sampled vectors have the layout's length")
            })
            .collect()
    }

    fn clip_poses(&self, count: usize, seed: u64) -> Vec<Pose> {
        random_clip_frames(&self.train_clips, count, seed)
            .iter()
            .map(|f| Pose::sample(&self.character.skeleton, &self.train_clips[f.clip], f.time))
            .collect()
    }

    /// The reference poses, seeded: what `sample` jobs trace, in batches.
    pub fn reference_poses(&self) -> Vec<Pose> {
        let (n, seed) = (self.params.poses, self.params.seed);
        match self.params.reference {
            ReferenceSource::Random => self.random_poses(n, seed),
            ReferenceSource::Clips => self.clip_poses(n, seed),
            ReferenceSource::Mixed => {
                let mut poses = self.random_poses(n / 2, seed);
                poses.extend(self.clip_poses(n - n / 2, seed));
                poses
            }
        }
    }

    /// Held-out poses: random poses from another seed, then every frame of
    /// every test clip at `eval_fps`.
    pub fn test_poses(&self) -> Vec<TestPose> {
        let seed = self.params.seed ^ HELD_OUT_SEED;
        let mut poses: Vec<TestPose> = self
            .random_poses(self.params.eval_poses, seed)
            .into_iter()
            .map(|pose| TestPose { frame: None, pose })
            .collect();
        for &c in &self.test {
            let clip = &self.clips[c];
            for time in clip.frame_times(self.params.eval_fps) {
                poses.push(TestPose {
                    frame: Some(ClipFrame { clip: c, time }),
                    pose: Pose::sample(&self.character.skeleton, clip, time),
                });
            }
        }
        poses
    }

    /// Indices of up to 8 test poses, evenly spread, to trace a second time
    /// for the ground truth's noise (see `report::NoiseEstimate`).
    pub fn noise_sample(&self, tests: &[TestPose]) -> Vec<usize> {
        let n = tests.len();
        let k = n.min(NOISE_POSES);
        (0..k).map(|i| i * n / k).collect()
    }

    /// Fits the method to the reference poses' AO (the `fit` job's work;
    /// the dispatch on the method is [`crate::method::vertex::fit`]).
    pub fn fit(&self, poses: &[Pose], ao: &AoBlock) -> Result<(Model, FitStats), BakeError> {
        let p = &self.params;
        crate::method::vertex::fit(
            p.method,
            (&p.linear, &p.clustered),
            p.seed,
            &self.character.skeleton,
            (&self.joint_angles, &self.handles),
            poses,
            ao,
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
