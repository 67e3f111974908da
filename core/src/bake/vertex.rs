//! The per-vertex family's bake (vertex-linear, vertex-clustered and the
//! static average; DESIGN §5–6): its jobs and its evaluation.
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
//! * `preview`: as for every method (`bake::preview`).
//!
//! The evaluation (DESIGN §6): the model and the static-average baseline
//! against ray-traced ground truth on held-out poses, per clip and over
//! random poses, and on clips the model never saw: each of up to
//! `eval_folds` clips left out of a refit in turn (leave one clip out).
//! The baseline is the strongest static average: the mean over training
//! clip frames ([`Plan::baseline_rows`]), not over random poses.

use std::ops::Range;
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use plotters::prelude::*;

use crate::{
    asset::metrics::{Errors, FrameError, psnr},
    method::Method,
    method::vertex::{FitStats, FitStep, Model, Rows, Source, StaticAverage, fit_static_average},
    rig::pose::Pose,
    trace::{AoBlock, SceneOptions, no_progress},
};

use super::{
    Bake, BakeError, BakeParams, Checkpoint, GraphOptions, JobError, JobGraph, JobOutput, JobSink,
    JobSpec, Plan, PlannedJob, PoseSet, Receivers, TestPose,
    jobs::{IndexedBlock, decode_with, find, json, named, parse, stack_blocks},
    report::{CharacterInfo, Sizes, Timings},
};

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

impl Bake<'_> {
    /// `sample` (reference) → `fit`; `sample` (reference, held-out) →
    /// one `unseen` per unseen-clips fold; `fit`, the `unseen` folds and
    /// `sample` (held-out, noise) → `evaluate`; `fit` and `evaluate` →
    /// `assemble`; `assemble` and the `preview-truth` jobs (and a texel
    /// bake's `unseen` folds) → `preview`.
    ///
    /// Workers take the first ready job in this order, so it is the
    /// schedule: `fit`, the longest chain, comes right after the
    /// reference poses it needs and starts while other workers trace the
    /// held-out poses; the unseen-clip folds and the previews' truth fill
    /// the workers beside it.
    pub(super) fn vertex_graph(&self, options: GraphOptions) -> JobGraph {
        let p = &self.plan.params;
        let rays = self.plan.receiver_count() as u64 * u64::from(p.samples);
        let batch = options.batch(rays);
        let mut jobs: Vec<PlannedJob> = Vec::new();
        let samples = |set: PoseSet, jobs: &mut Vec<PlannedJob>| -> Vec<usize> {
            let n = self.poses_in(set);
            (0..n)
                .step_by(batch)
                .map(|first| {
                    jobs.push(PlannedJob {
                        spec: JobSpec::Sample {
                            set,
                            first,
                            count: batch.min(n - first),
                        },
                        deps: Vec::new(),
                    });
                    jobs.len() - 1
                })
                .collect()
        };
        let reference = samples(PoseSet::Reference, &mut jobs);
        jobs.push(PlannedJob {
            spec: JobSpec::Fit,
            deps: reference.clone(),
        });
        let fit = jobs.len() - 1;
        let held_out = samples(PoseSet::HeldOut, &mut jobs);
        let mut deps = vec![fit];
        let mut unseen = Vec::new();
        for fold in 0..self.plan.fold_clips().len() {
            jobs.push(PlannedJob {
                spec: JobSpec::Unseen { fold },
                deps: reference.iter().chain(&held_out).copied().collect(),
            });
            unseen.push(jobs.len() - 1);
        }
        deps.extend(&unseen);
        let noise = samples(PoseSet::Noise, &mut jobs);
        // The previews' truth: it needs no model.
        let mut truth = Vec::new();
        for job in self.preview_truth_jobs(options) {
            jobs.push(job);
            truth.push(jobs.len() - 1);
        }
        deps.extend(held_out);
        deps.extend(noise);
        jobs.push(PlannedJob {
            spec: JobSpec::Evaluate,
            deps,
        });
        let evaluate = jobs.len() - 1;
        jobs.push(PlannedJob {
            spec: JobSpec::Assemble,
            deps: vec![fit, evaluate],
        });
        if options.previews {
            let assemble = jobs.len() - 1;
            let mut deps = vec![assemble];
            deps.extend(truth);
            // A texel bake's previews judge each fold's model per pixel
            // on stills of the clip it left out.
            if let Receivers::Texels(_) = self.plan.receivers {
                deps.extend(unseen);
            }
            jobs.push(PlannedJob {
                spec: JobSpec::Preview,
                deps,
            });
        }
        JobGraph { jobs }
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

    /// Runs one of the family's jobs.
    pub(super) fn vertex_job(
        &self,
        spec: &JobSpec,
        deps: &[&JobOutput],
        resume: Option<Checkpoint>,
        sink: &mut dyn JobSink,
    ) -> Result<JobOutput, JobError> {
        match spec {
            JobSpec::Sample { set, first, count } => {
                self.sample(*set, *first, *count, resume, sink)
            }
            JobSpec::Fit => self.fit(deps, sink),
            JobSpec::Unseen { fold } => self.unseen(*fold, deps, sink),
            JobSpec::Evaluate => self.evaluate(deps),
            JobSpec::Assemble => self.assemble(deps),
            JobSpec::Face { .. }
            | JobSpec::Slab { .. }
            | JobSpec::PreviewTruth { .. }
            | JobSpec::Preview => Err(self.foreign(spec)),
        }
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
        let vertices = self.plan.receiver_count();
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
        // A checkpoint per pose; on a GPU tracer, per batch of poses of
        // about 256k vertices, at most 64.
        let step = crate::trace::engine::batch_items(vertices, 262_144, 64);
        let mut next = done.block.poses();
        while next < poses.len() {
            let end = (next + step).min(poses.len());
            let rows = self
                .plan
                .trace(&poses[next..end], &options, &surface, &no_progress)
                .map_err(|e| JobError::Invalid(e.to_string()))?;
            next = end;
            done.block.values.extend(rows.values);
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
        out.timings.gpu_trace_s = super::report::on_gpu(seconds);
        Ok(out)
    }

    /// The blocks of a set, from `deps`, stacked in pose order; every pose
    /// of the set must be there exactly once.
    fn stack(&self, set: PoseSet, deps: &[&JobOutput]) -> Result<AoBlock, JobError> {
        stack_blocks(
            deps,
            set.output(),
            self.plan.receiver_count(),
            self.poses_in(set),
        )
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
        let mut header = self
            .plan
            .header(&self.inputs.character_digest, &self.inputs.clip_digests);
        if let Receivers::Texels(_) = self.plan.receivers {
            // A texel asset's columns are texels: the glTF primitives'
            // vertices are found through its atlas instead.
            header.primitives.clear();
        }
        header
    }

    /// The fitted model as the bake's asset: a texel bake's with its
    /// atlas.
    fn encode_model(&self, model: Model) -> Vec<u8> {
        let skeleton = &self.plan.character.skeleton;
        match &self.plan.receivers {
            Receivers::Vertices => model.to_container(self.header(), skeleton).to_bytes(),
            Receivers::Texels(t) => {
                super::texel::encode(self.plan.params.method, model, t, self.header(), skeleton)
            }
        }
    }

    /// The model of an asset [`Self::encode_model`] wrote.
    fn decode_model(&self, bytes: &[u8]) -> Result<Model, JobError> {
        match &self.plan.receivers {
            Receivers::Vertices => decode(bytes),
            Receivers::Texels(_) => super::texel::decode(bytes).map(|m| m.model),
        }
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
        let baseline = Model::StaticAverage(fit_static_average(
            &reference.select(self.plan.baseline_rows()),
        ));
        let mut out = JobOutput::default();
        let skeleton = &self.plan.character.skeleton;
        out.push("model", self.encode_model(model));
        out.push(
            "baseline",
            baseline.to_container(self.header(), skeleton).to_bytes(),
        );
        out.push("fit.json", json(&FitInfo { fit }));
        out.timings.reference_trace_s = deps.iter().map(|d| d.timings.reference_trace_s).sum();
        out.timings.gpu_trace_s = super::report::gpu_seconds(deps);
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
        out.push(&unseen_output(fold), json(&result.fold));
        if let Receivers::Texels(atlas) = &self.plan.receivers {
            // What the previews judge the fold with per pixel: its model
            // as an asset, and its static average and the traced AO of
            // its stills, one row each.
            let texels = atlas.texels.len();
            let mut values = result.baseline;
            for &r in &result.still_rows {
                values.extend_from_slice(truth.row(r));
            }
            let block = IndexedBlock {
                first: 0,
                block: AoBlock {
                    vertices: texels,
                    values,
                },
            };
            out.push(&unseen_model(fold), self.encode_model(result.model));
            out.push(&unseen_texels(fold), block.to_bytes());
        }
        out.timings.unseen_s = started.elapsed().as_secs_f64();
        Ok(out)
    }

    fn evaluate(&self, deps: &[&JobOutput]) -> Result<JobOutput, JobError> {
        let fit = find(deps, "model")?;
        let model = self.decode_model(named(fit, "model")?)?;
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
        let vertices = self.plan.receiver_count() as u64;
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
            // The fit's (its reference samples') and the test samples'.
            gpu_trace_s: super::report::gpu_seconds(deps),
            ..fit.timings
        };
        Ok(out)
    }

    fn assemble(&self, deps: &[&JobOutput]) -> Result<JobOutput, JobError> {
        let fit = find(deps, "model")?;
        let evaluated = find(deps, "evaluation.json")?;
        let asset = named(fit, "model")?.to_vec();
        let model = self.decode_model(&asset)?;
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
                baseline_bytes: 2 * self.plan.receiver_count(),
            },
            evaluation: info.evaluation,
            ground_truth_noise: info.ground_truth_noise,
            texel: super::texel::report(&self.plan.receivers, &model),
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
/// A texel bake's fold model, as an asset ([`Bake::unseen`]).
pub(super) fn unseen_model(fold: usize) -> String {
    format!("unseen-{fold}-model")
}

/// A texel bake's fold's static average (row 0) and the traced AO at its
/// stills (one row each), an [`IndexedBlock`] over the atlas's texels.
pub(super) fn unseen_texels(fold: usize) -> String {
    format!("unseen-{fold}-texels")
}

pub(super) fn unseen_output(fold: usize) -> String {
    format!("unseen-{fold}.json")
}

/// A per-vertex asset's model.
pub(super) fn decode(bytes: &[u8]) -> Result<Model, JobError> {
    decode_with(bytes, Model::from_container)
}

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
        let judged: Vec<(f64, usize, FrameError, FrameError)> = tests
            .par_iter()
            .enumerate()
            .map(|(i, t)| {
                let w = model.weights(skeleton, &t.pose.locals);
                let predicted = model.evaluate_weights(&w);
                let drawn = self.drawn(&t.pose);
                (
                    model.multiply_adds(&w),
                    drawn.iter().filter(|&&d| !d).count(),
                    FrameError::of_drawn(&predicted, truth.row(i), Some(&drawn)),
                    FrameError::of_drawn(&base, truth.row(i), Some(&drawn)),
                )
            })
            .collect();
        let mut multiply_adds = 0.0;
        let mut hidden = 0;
        for (t, (cost, undrawn, e_model, e_base)) in tests.iter().zip(judged) {
            multiply_adds += cost;
            hidden += undrawn;
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
            undrawn_vertex_frames: hidden,
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
    ) -> Result<FoldFit, BakeError> {
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
        let baseline = fit_static_average(&reference.select(if frames.is_empty() {
            keep.clone()
        } else {
            frames
        }))
        .evaluate();
        let of_clip: Vec<usize> = (0..tests.len())
            .filter(|&i| tests[i].frame.is_some_and(|f| f.clip == c))
            .collect();
        let still_rows: Vec<usize> = super::preview::UNSEEN_STILL_FRACTIONS
            .iter()
            .filter_map(|&f| {
                let last = of_clip.len().checked_sub(1)?;
                Some(of_clip[((f * last as f32).round() as usize).min(last)])
            })
            .fold(Vec::new(), |mut rows, r| {
                if rows.last() != Some(&r) {
                    rows.push(r);
                }
                rows
            });
        let judged: Vec<(FrameError, FrameError)> = of_clip
            .par_iter()
            .map(|&i| (i, &tests[i]))
            .map(|(i, t)| {
                let predicted = model.evaluate(skeleton, &t.pose.locals);
                let drawn = self.drawn(&t.pose);
                (
                    FrameError::of_drawn(&predicted, truth.row(i), Some(&drawn)),
                    FrameError::of_drawn(&baseline, truth.row(i), Some(&drawn)),
                )
            })
            .collect();
        let (m, b): (Vec<FrameError>, Vec<FrameError>) = judged.into_iter().unzip();
        let fold = UnseenFold {
            clip: self.clips[c].name.clone(),
            reference_poses: keep.len(),
            rows: stats.reference().map(|r| r.rows),
            basis: stats.basis().map(|b| b.rank),
            errors: Comparison::new(Errors::of(&m), Errors::of(&b)),
            stills: still_rows
                .iter()
                .filter_map(|&i| tests[i].frame.map(|f| f.time))
                .collect(),
        };
        Ok(FoldFit {
            fold,
            model,
            baseline,
            still_rows,
        })
    }
}

/// One fold of the unseen-clips evaluation as [`Plan::unseen_fold`]
/// leaves it: its figures, and what a texel bake's previews judge per
/// pixel at the clip's stills.
#[derive(Debug, Clone)]
pub struct FoldFit {
    /// The figures.
    pub fold: UnseenFold,
    /// The model refitted without the clip.
    pub model: Model,
    /// The other clips' static average, one value per receiver.
    pub baseline: Vec<f32>,
    /// The held-out rows of the stills ([`UnseenFold::stills`]).
    pub still_rows: Vec<usize>,
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
    /// Clip times (s) of the held-out frames where a texel bake's previews
    /// judge the fold per pixel ([`super::preview::UNSEEN_STILL_FRACTIONS`]
    /// of the way through the clip's frames).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stills: Vec<f32>,
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
    /// The fold the model did worst on against the static average (the
    /// first on a tie): what a studio's next clip risks, shown first.
    pub fn worst(&self) -> Option<&UnseenFold> {
        self.folds
            .iter()
            .min_by(|a, b| a.errors.psnr_gain_db.total_cmp(&b.errors.psnr_gain_db))
    }

    /// The folds, the worst first (by gain over the static average).
    pub fn worst_first(&self) -> Vec<&UnseenFold> {
        let mut folds: Vec<&UnseenFold> = self.folds.iter().collect();
        folds.sort_by(|a, b| a.errors.psnr_gain_db.total_cmp(&b.errors.psnr_gain_db));
        folds
    }

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
    /// Vertex-frames of the held-out poses left out of the errors because
    /// the vertex drew nothing in that pose (every incident triangle of
    /// zero area, such as a part scaled to zero: no pixel, no defined AO).
    #[serde(default)]
    pub undrawn_vertex_frames: usize,
}

/// A bake's report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// The method.
    pub method: Method,
    /// The bake key.
    pub bake_key: String,
    /// The parameters.
    pub params: BakeParams,
    /// The character.
    pub character: CharacterInfo,
    /// Rays traced for reference and held-out poses.
    pub rays: u64,
    /// Stage times.
    pub timings: Timings,
    /// The fit's own figures.
    pub fit: FitStats,
    /// Sizes.
    pub sizes: Sizes,
    /// Held-out errors against the baseline.
    pub evaluation: Evaluation,
    /// How noisy the ground truth itself is.
    pub ground_truth_noise: NoiseEstimate,
    /// A texel bake's atlas and textures (`bake::texel`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texel: Option<super::texel::TexelReport>,
}

/// The Monte Carlo noise of the ground truth: some held-out poses traced a
/// second time with independent rays. The difference of two independent
/// estimates has twice the variance of one, so the figures are the
/// difference's divided by √2: what a perfect model would still score
/// against this ground truth. Model errors close to them are noise, not
/// model error; more `--samples` lowers them.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct NoiseEstimate {
    /// Poses traced twice.
    pub frames: usize,
    /// RMSE of one ground-truth estimate.
    pub rmse: f64,
    /// Mean absolute error of one estimate.
    pub mae: f64,
    /// PSNR of one estimate against the exact AO (peak 1).
    pub psnr_db: f64,
}

impl NoiseEstimate {
    /// From `truth` rows `rows` and the same poses traced again (`again`,
    /// in that order).
    pub fn of(rows: &[usize], truth: &AoBlock, again: &AoBlock) -> Self {
        let (mut se, mut ae, mut n) = (0.0f64, 0.0f64, 0usize);
        for (k, &r) in rows.iter().enumerate() {
            for (&a, &b) in truth.row(r).iter().zip(again.row(k)) {
                let d = f64::from(a) - f64::from(b);
                se += d * d;
                ae += d.abs();
                n += 1;
            }
        }
        let n = n.max(1) as f64;
        let mse = se / n / 2.0;
        Self {
            frames: rows.len(),
            rmse: mse.sqrt(),
            mae: ae / n / std::f64::consts::SQRT_2,
            psnr_db: psnr(mse),
        }
    }
}

/// Draws PSNR per frame over each test clip's frames (one panel per clip,
/// the model and the baseline in each, the legend above the panels) as
/// PNG bytes.
pub fn psnr_plot_png(report: &Report) -> Result<Vec<u8>, String> {
    crate::image::register_plot_font()?;
    let clips = &report.evaluation.clips;
    let (width, panel, head) = (900u32, 280u32, 64u32);
    let height = head + panel * clips.len().max(1) as u32;
    let mut rgb = vec![255u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        let e = |e: DrawingAreaErrorKind<_>| e.to_string();
        root.fill(&WHITE).map_err(e)?;
        let (title, body) = root.split_vertically(head);
        // What the curves are: frames of the training clips traced with
        // fresh rays (the unseen-clip folds are numbers in the report).
        title
            .draw(&Text::new(
                format!(
                    "{}: PSNR per frame of the training clips, fresh rays",
                    report.method.name()
                ),
                (12, 8),
                ("sans-serif", 20),
            ))
            .map_err(e)?;
        // The legend above the panels, where it covers no curve.
        let legend = [
            (report.method.name().to_owned(), BLUE),
            ("static average".to_owned(), RED),
        ];
        for (i, (label, colour)) in legend.into_iter().enumerate() {
            let x = 12 + 260 * i as i32;
            title
                .draw(&PathElement::new(
                    vec![(x, 46), (x + 28, 46)],
                    colour.stroke_width(3),
                ))
                .map_err(e)?;
            title
                .draw(&Text::new(label, (x + 36, 37), ("sans-serif", 16)))
                .map_err(e)?;
        }
        let panels = body.split_evenly((clips.len().max(1), 1));
        for (clip, area) in clips.iter().zip(&panels) {
            let psnr = |v: &[f64]| -> Vec<(f64, f64)> {
                clip.times
                    .iter()
                    .zip(v)
                    .map(|(&t, &p)| (f64::from(t), p))
                    .collect()
            };
            let model = psnr(&clip.errors.model.psnr_db);
            let base = psnr(&clip.errors.baseline.psnr_db);
            let all = model.iter().chain(&base).map(|p| p.1);
            let lo = all.clone().fold(f64::INFINITY, f64::min);
            let hi = all.fold(f64::NEG_INFINITY, f64::max);
            let (lo, hi) = if lo.is_finite() {
                (lo - 2.0, hi + 2.0)
            } else {
                (0.0, 1.0)
            };
            let t_max = clip.times.last().map_or(1.0, |&t| f64::from(t)).max(1e-3);
            let mut chart = ChartBuilder::on(area)
                .caption(
                    format!(
                        "{}: model {:.1} dB, baseline {:.1} dB (mean)",
                        clip.clip,
                        clip.errors.model.mean.psnr_db,
                        clip.errors.baseline.mean.psnr_db
                    ),
                    ("sans-serif", 16),
                )
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(50)
                .build_cartesian_2d(0f64..t_max, lo..hi)
                .map_err(e)?;
            chart
                .configure_mesh()
                .x_desc("time (s)")
                .y_desc("PSNR (dB)")
                .draw()
                .map_err(e)?;
            chart
                .draw_series(LineSeries::new(model, BLUE.stroke_width(2)))
                .map_err(e)?;
            chart
                .draw_series(LineSeries::new(base, RED.stroke_width(2)))
                .map_err(e)?;
        }
        root.present().map_err(e)?;
    }
    Ok(crate::image::encode_rgb_png(&rgb, width, height)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_worst_left_out_clip_comes_first() {
        use crate::asset::metrics::{Errors, FrameError};
        // A fold whose model is off by `model` and the static average by
        // 0.1 on one vertex of one frame.
        let fold = |clip: &str, model: f32| {
            let errors = |e: f32| Errors::of(&[FrameError::of(&[0.5 + e], &[0.5])]);
            UnseenFold {
                clip: clip.into(),
                reference_poses: 1,
                rows: None,
                basis: None,
                errors: Comparison::new(errors(model), errors(0.1)),
                stills: Vec::new(),
            }
        };
        let u = UnseenClips::of(vec![
            fold("walk", 0.02),
            fold("wave", 0.2),
            fold("run", 0.05),
        ]);
        assert_eq!(u.worst().unwrap().clip, "wave");
        assert!(u.worst().unwrap().errors.psnr_gain_db < 0.0);
        assert_eq!(u.worst().unwrap().errors.psnr_gain_db, u.min_psnr_gain_db);
        let order: Vec<&str> = u.worst_first().iter().map(|f| f.clip.as_str()).collect();
        assert_eq!(order, ["wave", "run", "walk"]);
    }

    #[test]
    fn noise_of_one_estimate_is_the_difference_over_root_two() {
        let truth = AoBlock {
            vertices: 2,
            values: vec![0.5, 0.5, 0.2, 0.2],
        };
        // Row 1 traced again, off by ±0.1.
        let again = AoBlock {
            vertices: 2,
            values: vec![0.3, 0.1],
        };
        let n = NoiseEstimate::of(&[1], &truth, &again);
        assert_eq!(n.frames, 1);
        assert!((n.rmse - 0.1 / 2f64.sqrt()).abs() < 1e-7, "{n:?}");
        assert!((n.mae - 0.1 / 2f64.sqrt()).abs() < 1e-7, "{n:?}");
        assert!((n.psnr_db - 10.0 * (1.0 / 0.005f64).log10()).abs() < 1e-4);
    }
}
