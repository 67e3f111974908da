//! The `evaluate` job's work (DESIGN §6): the model and the static-average
//! baseline against ray-traced ground truth on held-out poses, per clip
//! and over random poses.

use serde::{Deserialize, Serialize};

use crate::{
    asset::metrics::{Errors, FrameError},
    method::vertex::{Model, StaticAverage},
    trace::AoBlock,
};

use super::{Plan, TestPose};

impl Plan<'_> {
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
