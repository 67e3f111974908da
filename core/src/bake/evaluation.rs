//! The `evaluate` job's work (DESIGN §6): the model and the static-average
//! baseline against ray-traced ground truth on held-out poses, per clip
//! and over random poses, and on clips the model never saw: each of up to
//! `eval_folds` clips left out of a refit in turn (leave one clip out).
//!
//! The baseline is the strongest static average: the mean over training
//! clip frames ([`Plan::baseline_rows`]), not over random poses.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::{
    asset::metrics::{Errors, FrameError},
    method::vertex::{FitStep, Model, Rows, Source, StaticAverage},
    rig::pose::Pose,
    trace::AoBlock,
};

use super::{BakeError, Plan, TestPose};

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
        // Every pose on its own thread; the figures gathered in order.
        let judged: Vec<(f64, FrameError, FrameError)> = tests
            .par_iter()
            .enumerate()
            .map(|(i, t)| {
                let w = model.weights(skeleton, &t.pose);
                let predicted = model.evaluate_weights(&w);
                (
                    model.multiply_adds(&w),
                    FrameError::of(&predicted, truth.row(i)),
                    FrameError::of(&base, truth.row(i)),
                )
            })
            .collect();
        let mut multiply_adds = 0.0;
        for (t, (cost, e_model, e_base)) in tests.iter().zip(judged) {
            multiply_adds += cost;
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
            training_clip_frames: clip_frames,
            unseen_clips: None,
            multiply_adds_per_vertex: multiply_adds / tests.len().max(1) as f64,
        }
    }

    /// The clips an unseen-clips evaluation leaves out in turn: up to
    /// `eval_folds` clips that both train and test, evenly spread; none
    /// when fewer than two.
    pub fn fold_clips(&self) -> Vec<usize> {
        let eligible: Vec<usize> = self
            .train
            .iter()
            .copied()
            .filter(|c| self.test.contains(c))
            .collect();
        let k = self.params.eval_folds.min(eligible.len());
        if eligible.len() < 2 || k == 0 {
            return Vec::new();
        }
        (0..k).map(|i| eligible[i * eligible.len() / k]).collect()
    }

    /// Leave one clip out, one fold of it: clip `c` (one of
    /// [`Plan::fold_clips`]) left out, the method refitted to the
    /// reference poses not drawn from it (the traced AO of the rest, so
    /// no new rays), and the static average of the other clips' frames,
    /// both judged on every held-out frame of the clip. `poses`,
    /// `reference` and `sources` are the reference poses, their AO and
    /// where each comes from; `tests` and `truth` the held-out poses and
    /// theirs. The joint-angle ranges stay those of all training clips.
    /// `on_step` is called as each step of the refit ends. Each fold is a
    /// job of its own (`unseen`), so folds run side by side on workers.
    #[allow(clippy::too_many_arguments)]
    pub fn unseen_fold(
        &self,
        c: usize,
        poses: &[Pose],
        reference: &AoBlock,
        sources: &[Source],
        tests: &[TestPose],
        truth: &AoBlock,
        on_step: &mut dyn FnMut(FitStep),
    ) -> Result<UnseenFold, BakeError> {
        let plain: std::collections::BTreeSet<usize> = self.baseline_rows().into_iter().collect();
        let skeleton = &self.character.skeleton;
        let keep: Vec<usize> = (0..sources.len())
            .filter(|&i| sources[i].clip() != Some(c))
            .collect();
        let fold_poses: Vec<Pose> = keep.iter().map(|&i| poses[i].clone()).collect();
        let fold_sources: Vec<_> = keep.iter().map(|&i| sources[i]).collect();
        let (model, stats) = self.fit_stepwise(
            &fold_poses,
            &reference.select(keep.iter().copied()),
            &fold_sources,
            on_step,
        )?;
        let frames: Vec<usize> = keep.iter().copied().filter(|i| plain.contains(i)).collect();
        let baseline = StaticAverage::fit(&reference.select(if frames.is_empty() {
            keep.clone()
        } else {
            frames
        }))
        .evaluate();
        let judged: Vec<(FrameError, FrameError)> = tests
            .par_iter()
            .enumerate()
            .filter(|(_, t)| t.frame.is_some_and(|f| f.clip == c))
            .map(|(i, t)| {
                let predicted = model.evaluate(skeleton, &t.pose);
                (
                    FrameError::of(&predicted, truth.row(i)),
                    FrameError::of(&baseline, truth.row(i)),
                )
            })
            .collect();
        let (m, b): (Vec<FrameError>, Vec<FrameError>) = judged.into_iter().unzip();
        Ok(UnseenFold {
            clip: self.clips[c].name.clone(),
            reference_poses: keep.len(),
            rows: stats.reference().map(|r| r.rows),
            basis: stats.basis().map(|b| b.rank),
            errors: Comparison::new(Errors::of(&m), Errors::of(&b)),
        })
    }
}

/// One left-out clip of the unseen-clips evaluation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UnseenFold {
    /// The clip left out.
    pub clip: String,
    /// Reference poses the fold's fit was given (none from the clip;
    /// with `reference = cv` it uses the rows its own cross-validation
    /// chooses among them).
    pub reference_poses: usize,
    /// The rows its cross-validation chose, when it did.
    #[serde(default)]
    pub rows: Option<Rows>,
    /// The eigen-AO basis rows of the fold's model, when it has a basis
    /// (with `basis_cv`, the rank its own cross-validation chose).
    #[serde(default)]
    pub basis: Option<usize>,
    /// The fold's model and the other clips' static average on every
    /// frame of the clip.
    pub errors: Comparison,
}

/// Leave one clip out (see [`Plan::unseen_fold`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UnseenClips {
    /// One per left-out clip.
    pub folds: Vec<UnseenFold>,
    /// Mean over the folds of the model's mean PSNR (dB).
    pub model_psnr_db: f64,
    /// Mean over the folds of the baseline's mean PSNR (dB).
    pub baseline_psnr_db: f64,
    /// Mean over the folds of the PSNR gain (dB).
    pub mean_psnr_gain_db: f64,
    /// The smallest gain of any fold (dB).
    pub min_psnr_gain_db: f64,
}

impl UnseenClips {
    /// Summarises folds.
    pub fn of(folds: Vec<UnseenFold>) -> Self {
        let n = folds.len().max(1) as f64;
        let mean = |f: &dyn Fn(&UnseenFold) -> f64| folds.iter().map(f).sum::<f64>() / n;
        Self {
            model_psnr_db: mean(&|f| f.errors.model.mean.psnr_db),
            baseline_psnr_db: mean(&|f| f.errors.baseline.mean.psnr_db),
            mean_psnr_gain_db: mean(&|f| f.errors.psnr_gain_db),
            min_psnr_gain_db: folds
                .iter()
                .map(|f| f.errors.psnr_gain_db)
                .fold(f64::INFINITY, f64::min),
            folds,
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
    /// Every frame of the test clips together. By default the test clips
    /// are the training clips: these are poses between training poses,
    /// traced with fresh rays (interpolation); [`Evaluation::unseen_clips`]
    /// measures motion the model never saw.
    #[serde(alias = "clip_frames")]
    pub training_clip_frames: Comparison,
    /// Leave one clip out: clips the model was refitted without.
    #[serde(default)]
    pub unseen_clips: Option<UnseenClips>,
    /// Per test clip.
    pub clips: Vec<ClipEvaluation>,
    /// Multiply-adds per vertex at run time, mean over the test poses.
    pub multiply_adds_per_vertex: f64,
}
