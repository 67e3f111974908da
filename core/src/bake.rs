//! A per-vertex bake as the service runs it (DESIGN §1.3, §5–6): the
//! reference poses, the fit, the held-out evaluation and the asset, each a
//! function of its inputs so the planner can hand them to workers as jobs
//! (`sample` → `fit` → `evaluate`). Tracing itself is
//! [`crate::reference::trace_poses`].
//!
//! Everything is seeded from [`BakeParams::seed`]: the same request gives
//! the same poses, the same rays, the same coefficients and the same bytes.

use serde::{Deserialize, Serialize};

use crate::{
    Character, Clip,
    asset::Method,
    metrics::{Errors, FrameError},
    model::{
        ALGORITHM_VERSION, AssetHeaderFields, ClusteredFitStats, ClusteredOptions, LinearFitStats,
        LinearOptions, Model, StaticAverage, VertexClustered, VertexLinear,
    },
    params::{ClipFrame, Handles, JointAngles, LayoutOptions, ParamError, random_clip_frames},
    pose::Pose,
    reference::AoBlock,
    trace::{Falloff, SurfaceParams},
};

/// Mixed into the seed of everything held out ("heldout!" in ASCII).
const HELD_OUT_SEED: u64 = 0x6865_6c64_6f75_7421;
/// Mixed into the ray seed of the noise estimate ("noise!!!").
const NOISE_SEED: u64 = 0x6e6f_6973_6521_2121;
/// Held-out poses traced twice to estimate the ground truth's noise.
const NOISE_POSES: usize = 8;

/// Where reference (training) poses come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ReferenceSource {
    /// Every joint angle uniform in its range (Kontkanen & Aila).
    Random,
    /// Random times in the training clips (Kirk & Arikan train on clip
    /// frames).
    Clips,
    /// Half of each.
    Mixed,
}

/// Everything that determines a per-vertex bake besides its inputs. The
/// fully defaulted value goes into the bake key and the asset header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BakeParams {
    /// The method.
    pub method: Method,
    /// Reference poses to fit to.
    pub poses: usize,
    /// Where they come from (default: mixed for vertex-linear, clip frames
    /// otherwise).
    pub reference: ReferenceSource,
    /// Rays per vertex and pose.
    pub samples: u32,
    /// Hits farther than this (model units) do not occlude; `None`: no
    /// limit.
    pub max_distance: Option<f32>,
    /// Seed of poses, rays and k-means.
    pub seed: u64,
    /// Clips whose poses train the model (empty: all).
    pub train_clips: Vec<String>,
    /// Clips whose every frame is a held-out test (empty: all).
    pub test_clips: Vec<String>,
    /// Held-out random poses (joint angles uniform in the training
    /// clips' ranges, another seed).
    pub eval_poses: usize,
    /// Frame rate at which test clips are evaluated.
    pub eval_fps: f32,
    /// Joint-angle ranges: the training clips' range widened by this
    /// fraction of its span on each side.
    pub range_margin: f32,
    /// vertex-linear options.
    pub linear: LinearOptions,
    /// vertex-clustered options.
    pub clustered: ClusteredOptions,
}

impl BakeParams {
    /// Defaults for a method.
    pub fn new(method: Method) -> Self {
        Self {
            method,
            poses: 256,
            // Random joint angles alone combine every joint's extremes and
            // fit clip poses poorly (Fox: +0.5 dB over the baseline on
            // clip frames against +9 dB with half clip frames); clip frames
            // alone leave correlated angles that random poses decorrelate.
            reference: match method {
                Method::VertexLinear => ReferenceSource::Mixed,
                _ => ReferenceSource::Clips,
            },
            samples: 256,
            max_distance: None,
            seed: 0,
            train_clips: Vec::new(),
            test_clips: Vec::new(),
            eval_poses: 32,
            eval_fps: 30.0,
            range_margin: 0.1,
            linear: LinearOptions::default(),
            clustered: ClusteredOptions::default(),
        }
    }

    /// The tracing parameters of the reference poses.
    pub fn surface(&self) -> SurfaceParams {
        SurfaceParams {
            samples: self.samples,
            max_distance: self.max_distance.unwrap_or(f32::INFINITY),
            seed: self.seed,
            falloff: Falloff::None,
        }
    }

    /// The tracing parameters of the held-out poses: another ray seed, so
    /// that the ground truth's sampling noise is independent of the noise
    /// the model was fitted to (with the same seed a vertex would cast the
    /// same rays in both, and errors would come out too small).
    pub fn held_out_surface(&self) -> SurfaceParams {
        SurfaceParams {
            seed: self.seed ^ HELD_OUT_SEED,
            ..self.surface()
        }
    }

    /// The tracing parameters of the second trace that estimates the
    /// ground truth's noise: independent of both other seeds.
    pub fn noise_surface(&self) -> SurfaceParams {
        SurfaceParams {
            seed: self.seed ^ NOISE_SEED,
            ..self.surface()
        }
    }

    /// The parameters as they enter the key: only the chosen method's
    /// options.
    fn canonical(&self) -> serde_json::Value {
        let mut v = serde_json::to_value(self).expect("params serialise");
        let map = v.as_object_mut().expect("an object");
        if self.method != Method::VertexLinear {
            map.remove("linear");
        }
        if self.method != Method::VertexClustered {
            map.remove("clustered");
        }
        v
    }
}

/// Why a bake cannot run; each names the offending input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BakeError {
    /// A parameter is out of range.
    #[error("invalid parameter: {0}")]
    Param(String),
    /// The character cannot be parameterised.
    #[error(transparent)]
    Layout(#[from] ParamError),
    /// The fit failed; the message says what to change.
    #[error("{0}")]
    Fit(String),
    /// A named clip does not exist.
    #[error("no clip named {name:?}; the clips are: {known}")]
    UnknownClip {
        /// The name asked for.
        name: String,
        /// The names there are.
        known: String,
    },
}

pub use crate::digest::sha256_hex;

/// The bake key (DESIGN §1.2): sha256 over the canonical JSON (keys sorted,
/// no whitespace) of the input digests, the method, the fully defaulted
/// parameters and the algorithm version.
pub fn bake_key(character: &str, clips: &[String], params: &BakeParams) -> String {
    let request = serde_json::json!({
        "algorithm_version": ALGORITHM_VERSION,
        "character": character,
        "clips": clips,
        "method": params.method,
        "params": params.canonical(),
    });
    sha256_hex(request.to_string().as_bytes())
}

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
        let p = &params;
        if clips.is_empty() {
            return Err(BakeError::Param(
                "the character has no clips: pose-dependent AO needs at least one animation (pass --clips FILE)".into(),
            ));
        }
        if p.poses == 0 || p.poses > 100_000 {
            return Err(BakeError::Param(format!(
                "poses must be between 1 and 100000, not {}",
                p.poses
            )));
        }
        if p.eval_poses > 100_000 {
            return Err(BakeError::Param(format!(
                "eval_poses must be at most 100000, not {}",
                p.eval_poses
            )));
        }
        if p.samples == 0 || p.samples > crate::trace::MAX_SAMPLES {
            return Err(BakeError::Param(format!(
                "samples must be between 1 and {}, not {}",
                crate::trace::MAX_SAMPLES,
                p.samples
            )));
        }
        if p.max_distance.is_some_and(|d| d.is_nan() || d <= 0.0) {
            return Err(BakeError::Param("max_distance must be positive".into()));
        }
        if !(p.eval_fps > 0.0 && p.eval_fps <= 240.0) {
            return Err(BakeError::Param("eval_fps must be in (0, 240]".into()));
        }
        if !(p.range_margin >= 0.0 && p.range_margin <= 10.0) {
            return Err(BakeError::Param("range_margin must be in [0, 10]".into()));
        }
        if !(p.linear.ridge >= 0.0 && p.linear.ridge.is_finite()) {
            return Err(BakeError::Param("ridge must be a finite number ≥ 0".into()));
        }
        if !(p.linear.threshold >= 0.0 && p.linear.threshold.is_finite()) {
            return Err(BakeError::Param(
                "threshold must be a finite number ≥ 0".into(),
            ));
        }
        let c = &p.clustered;
        if c.pose_clusters == 0 || c.pose_clusters > 1024 {
            return Err(BakeError::Param(
                "pose_clusters must be between 1 and 1024".into(),
            ));
        }
        if c.dimensions == 0 || c.dimensions > 256 {
            return Err(BakeError::Param(
                "dimensions must be between 1 and 256".into(),
            ));
        }
        if !(c.alpha > 0.0 && c.alpha <= 100.0) {
            return Err(BakeError::Param("alpha must be in (0, 100]".into()));
        }
        if !(c.vertex_tolerance >= 0.0 && c.vertex_tolerance.is_finite()) {
            return Err(BakeError::Param(
                "vertex_tolerance must be a finite number ≥ 0".into(),
            ));
        }
        if !(c.ridge >= 0.0 && c.ridge.is_finite()) {
            return Err(BakeError::Param("ridge must be a finite number ≥ 0".into()));
        }
        if !(c.clamp >= 0.0 && c.clamp.is_finite()) {
            return Err(BakeError::Param("clamp must be a finite number ≥ 0".into()));
        }
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

    /// Fits the method to the reference poses' AO (the `fit` job).
    pub fn fit(&self, poses: &[Pose], ao: &AoBlock) -> Result<(Model, FitStats), BakeError> {
        let skeleton = &self.character.skeleton;
        Ok(match self.params.method {
            Method::StaticAverage => (
                Model::StaticAverage(StaticAverage::fit(ao)),
                FitStats::StaticAverage,
            ),
            Method::VertexLinear => {
                let q: Vec<Vec<f32>> = poses
                    .iter()
                    .map(|p| self.joint_angles.params(skeleton, p))
                    .collect();
                let (m, stats) =
                    VertexLinear::fit(&q, &self.joint_angles.ranges, ao, &self.params.linear)
                        .map_err(|e| BakeError::Fit(e.to_string()))?;
                (
                    Model::VertexLinear(self.joint_angles.clone(), m),
                    FitStats::VertexLinear(stats),
                )
            }
            Method::VertexClustered => {
                let h: Vec<Vec<f32>> = poses
                    .iter()
                    .map(|p| self.handles.handles(skeleton, p))
                    .collect();
                let (m, stats) =
                    VertexClustered::fit(&h, ao, &self.params.clustered, self.params.seed)
                        .map_err(|e| BakeError::Fit(e.to_string()))?;
                (
                    Model::VertexClustered(self.handles.clone(), m),
                    FitStats::VertexClustered(stats),
                )
            }
        })
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

    /// Compares the model and the baseline with ground truth on the
    /// held-out poses (the `evaluate` job).
    pub fn evaluate(
        &self,
        model: &Model,
        baseline: &StaticAverage,
        tests: &[TestPose],
        truth: &AoBlock,
    ) -> Evaluation {
        let skeleton = &self.character.skeleton;
        let base = baseline.evaluate();
        let mut random = (Vec::new(), Vec::new());
        struct PerClip {
            clip: usize,
            times: Vec<f32>,
            model: Vec<FrameError>,
            baseline: Vec<FrameError>,
        }
        let mut per_clip: Vec<PerClip> = Vec::new();
        let mut multiply_adds = 0.0;
        for (i, t) in tests.iter().enumerate() {
            let w = model.weights(skeleton, &t.pose);
            multiply_adds += model.multiply_adds(&w);
            let predicted = model.evaluate_weights(&w);
            let e_model = FrameError::of(&predicted, truth.row(i));
            let e_base = FrameError::of(&base, truth.row(i));
            match t.frame {
                None => {
                    random.0.push(e_model);
                    random.1.push(e_base);
                }
                Some(f) => {
                    if per_clip.last().is_none_or(|c| c.clip != f.clip) {
                        per_clip.push(PerClip {
                            clip: f.clip,
                            times: Vec::new(),
                            model: Vec::new(),
                            baseline: Vec::new(),
                        });
                    }
                    let c = per_clip.last_mut().expect("just pushed");
                    c.times.push(f.time);
                    c.model.push(e_model);
                    c.baseline.push(e_base);
                }
            }
        }
        let all_model: Vec<FrameError> = per_clip
            .iter()
            .flat_map(|c| c.model.iter().copied())
            .collect();
        let all_base: Vec<FrameError> = per_clip
            .iter()
            .flat_map(|c| c.baseline.iter().copied())
            .collect();
        let clip_frames = Comparison::new(Errors::of(&all_model), Errors::of(&all_base));
        Evaluation {
            random_poses: Comparison::new(Errors::of(&random.0), Errors::of(&random.1)),
            clips: per_clip
                .into_iter()
                .map(|c| ClipEvaluation {
                    clip: self.clips[c.clip].name.clone(),
                    fps: self.params.eval_fps,
                    times: c.times,
                    errors: Comparison::new(Errors::of(&c.model), Errors::of(&c.baseline)),
                })
                .collect(),
            clip_frames,
            multiply_adds_per_vertex: multiply_adds / tests.len().max(1) as f64,
        }
    }
}

/// What a fit reports.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "method", rename_all = "kebab-case")]
pub enum FitStats {
    /// Nothing to report.
    StaticAverage,
    /// vertex-linear.
    VertexLinear(LinearFitStats),
    /// vertex-clustered.
    VertexClustered(ClusteredFitStats),
}

/// The model against the baseline on one set of frames.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Comparison {
    /// The model's errors.
    pub model: Errors,
    /// The static average's errors.
    pub baseline: Errors,
    /// Mean PSNR of the model minus the baseline's (dB; positive: better).
    pub psnr_gain_db: f64,
    /// The model's mean MAE over the baseline's (below 1: better).
    pub mae_ratio: f64,
}

impl Comparison {
    fn new(model: Errors, baseline: Errors) -> Self {
        let psnr_gain_db = model.mean.psnr_db - baseline.mean.psnr_db;
        let mae_ratio = if baseline.mean.mae > 0.0 {
            model.mean.mae / baseline.mean.mae
        } else {
            1.0
        };
        Self {
            model,
            baseline,
            psnr_gain_db,
            mae_ratio,
        }
    }
}

/// One test clip's frames.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClipEvaluation {
    /// The clip's name.
    pub clip: String,
    /// Frames per second.
    pub fps: f32,
    /// Frame times.
    pub times: Vec<f32>,
    /// Errors per frame and their means.
    pub errors: Comparison,
}

/// The held-out evaluation of a bake (DESIGN §6).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    /// Random poses not in the training set.
    pub random_poses: Comparison,
    /// Every test clip frame together.
    pub clip_frames: Comparison,
    /// Per test clip.
    pub clips: Vec<ClipEvaluation>,
    /// Multiply-adds per vertex at run time, mean over the test poses.
    pub multiply_adds_per_vertex: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOLDEN_KEY: &str = "a183eed2ca53af54d3001ad66878cec5c6bb801ce94ba9a1c0a92cfdbb690218";

    #[test]
    fn key_depends_on_what_matters_only() {
        let a = BakeParams::new(Method::VertexLinear);
        let k = bake_key("c", &[], &a);
        assert_eq!(k.len(), 64);
        assert_eq!(k, bake_key("c", &[], &a.clone()));
        assert_ne!(k, bake_key("d", &[], &a));
        let mut b = a.clone();
        b.seed = 1;
        assert_ne!(k, bake_key("c", &[], &b));
        // Options of another method do not change the key.
        let mut c = a.clone();
        c.clustered.alpha = 3.0;
        assert_eq!(k, bake_key("c", &[], &c));
        // Pinned: a change here invalidates every cached bake, so it must be
        // deliberate (and come with an ALGORITHM_VERSION bump if fitting
        // changed).
        assert_eq!(
            k,
            bake_key("c", &[], &BakeParams::new(Method::VertexLinear)),
        );
        assert_eq!(
            bake_key("c", &[], &BakeParams::new(Method::VertexLinear)),
            GOLDEN_KEY
        );
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}
