//! The jobs of a grid bake (Malmer et al. 2005; DESIGN §1.3, §5):
//!
//! * `slab` (per part, per run of z-layers of its grid): Eq. 5 at every
//!   cell of the layers, the part alone in bind space. It checkpoints after
//!   every layer (the layers done so far, a few tens of KiB); a layer's
//!   rays depend on the seed, the part and the layer alone, so the cells do
//!   not depend on how the grid was cut or how often a slab was
//!   interrupted. Output: `slab-{part}-{first}` (raw cells) and a small
//!   `.json` of how it ran.
//! * `sample` (with the static base; batches of the training frames):
//!   ray-traced truth at every vertex and at the centres of the base's
//!   ground texels. Output: `ao-reference` and `ground-reference`
//!   ([`IndexedBlock`]s).
//! * `assemble`: every part's slabs stacked, finished (§3.3: boundary
//!   rescale, inside cells filled, ×2 in a byte, cones), `T_clip` with
//!   cones, and the static base fitted to the `sample` jobs' truth →
//!   `asset`.
//! * `evaluate`: ray-traced truth on clip frames at the parts' vertices
//!   and on the ground; the grids with and without cones and the
//!   baselines against it → `report.json`, `plot.png` (slices of every
//!   part's grid).
//! * `preview`: as for every method (`bake::preview`), the grids shading
//!   the parts and the ground.

use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::{
    image::encode_rgb_png,
    method::Method,
    method::grid::{
        base::GroundSquare,
        evaluate::{GridEvaluation, GridVariant, GroundTruth, Inputs, Predictor},
        field::{self, GridBox, RawCell, Slab, finish, part_scene, trace_layers},
        model::{GridModel, PartGrid, Terms},
        parts::{Part, owners, parts},
        static_base::{self, TrainingFrame},
        tclip::TClip,
    },
    trace::AoBlock,
    trace::VolumeParams,
};

use super::{
    Bake, BakeParams, Checkpoint, GraphOptions, JobError, JobGraph, JobOutput, JobSink, JobSpec,
    PlannedJob, PoseSet,
    jobs::{IndexedBlock, decode_with, find, json, named, parse, stack_blocks},
    report::{CharacterInfo, Sizes, Timings},
};

/// The outputs of a grid `sample` job: the truth at the vertices and at
/// the base's ground texels.
const VERTEX_TRUTH: &str = "ao-reference";
const GROUND_TRUTH: &str = "ground-reference";

/// The step name of a slab job's checkpoints.
const SLAB_STEP: &str = "slab";

/// How a slab job ran, as `slab-{part}-{first}.json`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SlabInfo {
    /// Seconds this attempt traced.
    pub seconds: f64,
    /// Layers this attempt computed (the rest came from its checkpoint).
    pub computed: usize,
    /// The layer it started at, relative to the slab's first.
    pub resumed_at: usize,
}

fn slab_name(part: usize, first: usize) -> String {
    format!("slab-{part}-{first}")
}

impl Bake<'_> {
    /// Runs one of the family's jobs.
    pub(super) fn grid_job(
        &self,
        spec: &JobSpec,
        deps: &[&JobOutput],
        resume: Option<Checkpoint>,
        sink: &mut dyn JobSink,
    ) -> Result<JobOutput, JobError> {
        match spec {
            JobSpec::Slab { part, first, count } => self.slab(*part, *first, *count, resume, sink),
            JobSpec::Sample {
                set: PoseSet::Reference,
                first,
                count,
            } => self.grid_sample(*first, *count),
            JobSpec::Assemble => self.grid_assemble(deps),
            JobSpec::Evaluate => self.grid_evaluate(deps),
            JobSpec::Sample { .. }
            | JobSpec::Fit
            | JobSpec::Unseen { .. }
            | JobSpec::Face { .. }
            | JobSpec::PreviewTruth { .. }
            | JobSpec::Preview => Err(self.foreign(spec)),
        }
    }

    /// The parts of a grid bake.
    pub fn grid_parts(&self) -> Result<Vec<Part>, JobError> {
        parts(&self.inputs.character, self.plan.params.grid.parts)
            .map_err(|e| JobError::Invalid(e.to_string()))
    }

    /// The distance limit of every trace: `grid.max_distance`, or the
    /// largest part's Eq. 4 reach.
    pub fn grid_distance(&self, parts: &[Part]) -> f32 {
        self.plan
            .params
            .grid
            .distance(&self.inputs.character, parts)
    }

    /// What the grid's truth is traced with: the bake's clips, parts,
    /// options, distance and seed.
    fn grid_inputs<'a>(&'a self, parts: &'a [Part]) -> Inputs<'a> {
        Inputs {
            character: &self.inputs.character,
            clips: &self.inputs.clips,
            train: &self.plan.train,
            test: &self.plan.test,
            parts,
            options: &self.plan.params.grid,
            max_distance: self.grid_distance(parts),
            seed: self.plan.params.seed,
        }
    }

    /// The static base's ground square, under the training frames.
    fn base_square(&self, inputs: &Inputs<'_>) -> GroundSquare {
        static_base::ground_square(
            inputs.character,
            inputs.clips,
            &inputs.training_frames(),
            self.plan.params.grid.ground_resolution,
        )
    }

    /// A part's mesh and grid box.
    fn part_grid(&self, part: &Part) -> (Vec<glam::Vec3>, Vec<[u32; 3]>, GridBox) {
        let o = &self.plan.params.grid;
        let (_, positions, triangles) = part.mesh(&self.inputs.character);
        let grid = field::around(&positions, o.epsilon, o.resolution);
        (positions, triangles, grid)
    }

    /// `slab` jobs (per part, `options.slab_layers` layers each) and, with
    /// the static base, `sample` jobs (batches of its training frames) →
    /// `assemble` → `evaluate` → `preview`.
    pub(super) fn grid_graph(&self, options: GraphOptions) -> JobGraph {
        let o = &self.plan.params.grid;
        let n = o.resolution;
        let step = options.slab_layers.clamp(1, n);
        let count = self.grid_parts().map_or(0, |p| p.len());
        let mut jobs: Vec<PlannedJob> = Vec::new();
        for part in 0..count {
            for first in (0..n).step_by(step) {
                jobs.push(PlannedJob {
                    spec: JobSpec::Slab {
                        part,
                        first,
                        count: step.min(n - first),
                    },
                    deps: Vec::new(),
                });
            }
        }
        if o.static_base {
            let frames = o.average_frames;
            let receivers = self.inputs.character.vertex_count() + o.ground_resolution.pow(2);
            let batch = options.batch(receivers as u64 * u64::from(o.eval_rays));
            for first in (0..frames).step_by(batch) {
                jobs.push(PlannedJob {
                    spec: JobSpec::Sample {
                        set: PoseSet::Reference,
                        first,
                        count: batch.min(frames - first),
                    },
                    deps: Vec::new(),
                });
            }
        }
        JobGraph::assemble_evaluate_preview(
            jobs,
            self.preview_truth_jobs(options),
            options.previews,
        )
    }

    /// A grid `sample` job: the truth of training frames
    /// `first..first + count` at the vertices and the base's ground
    /// texels.
    fn grid_sample(&self, first: usize, count: usize) -> Result<JobOutput, JobError> {
        let started = Instant::now();
        let parts = self.grid_parts()?;
        let inputs = self.grid_inputs(&parts);
        let frames = inputs.training_frames();
        let end = first.checked_add(count).filter(|&e| e <= frames.len());
        let Some(end) = end.filter(|_| self.plan.params.grid.static_base) else {
            return Err(JobError::Invalid(format!(
                "frames {first}..{} are not a batch of this bake's static base",
                first.saturating_add(count)
            )));
        };
        let texels = self.base_square(&inputs).texel_centres();
        let traced = inputs
            .trace_frames(&frames[first..end], &texels)
            .map_err(|e| JobError::Invalid(e.to_string()))?;
        let block = |values: Vec<f32>, vertices: usize| {
            IndexedBlock {
                first,
                block: AoBlock { vertices, values },
            }
            .to_bytes()
        };
        let (v, g): (Vec<Vec<f32>>, Vec<Vec<f32>>) =
            traced.into_iter().map(|t| (t.vertices, t.ground)).unzip();
        let mut out = JobOutput::default();
        out.push(
            VERTEX_TRUTH,
            block(v.concat(), self.inputs.character.vertex_count()),
        );
        out.push(GROUND_TRUTH, block(g.concat(), texels.len()));
        out.timings.reference_trace_s = started.elapsed().as_secs_f64();
        out.timings.gpu_trace_s = super::report::on_gpu(out.timings.reference_trace_s);
        Ok(out)
    }

    /// The static base of `model`, fitted to the `sample` jobs' truth
    /// among `deps`.
    fn fit_base(
        &self,
        parts: &[Part],
        model: &GridModel,
        deps: &[&JobOutput],
    ) -> Result<crate::method::grid::base::StaticBase, JobError> {
        let inputs = self.grid_inputs(parts);
        let frames = inputs.training_frames();
        let square = self.base_square(&inputs);
        let character = &self.inputs.character;
        let vertices = character.vertex_count();
        let truth_v = stack_blocks(deps, VERTEX_TRUTH, vertices, frames.len())?;
        let truth_g = stack_blocks(deps, GROUND_TRUTH, square.texels(), frames.len())?;
        let training: Vec<TrainingFrame> = frames
            .iter()
            .zip(truth_v.values.chunks_exact(vertices.max(1)))
            .zip(truth_g.values.chunks_exact(square.texels()))
            .map(|((frame, v), g)| {
                TrainingFrame::new(character, inputs.clips, frame, v.to_vec(), g.to_vec())
            })
            .collect();
        Ok(static_base::fit(
            model,
            &owners(parts, vertices),
            square,
            &training,
        ))
    }

    /// A `slab` job: layers `first..first + count` of part `part`'s grid,
    /// resumed from `resume`, checkpointed after every layer.
    pub(super) fn slab(
        &self,
        part: usize,
        first: usize,
        count: usize,
        resume: Option<Checkpoint>,
        sink: &mut dyn JobSink,
    ) -> Result<JobOutput, JobError> {
        let started = Instant::now();
        let o = &self.plan.params.grid;
        let n = o.resolution;
        let all = self.grid_parts()?;
        let end = first.checked_add(count).filter(|&e| e <= n && count > 0);
        let (Some(p), Some(end)) = (all.get(part), end) else {
            return Err(JobError::Invalid(format!(
                "layers {first}..{} of part {part} are not a slab of this bake",
                first.saturating_add(count)
            )));
        };
        let (positions, triangles, grid) = self.part_grid(p);
        let mut done = Slab {
            part,
            resolution: n,
            first,
            cells: Vec::with_capacity(count * n * n),
        };
        if let Some(cp) = resume.filter(|cp| cp.step == SLAB_STEP) {
            let saved = Slab::from_bytes(&cp.data, n).map_err(JobError::Invalid)?;
            let ok = saved.part == part
                && saved.first == first
                && saved.layers() as u64 == cp.cursor
                && saved.layers() <= count;
            if !ok {
                return Err(JobError::Invalid(
                    "the checkpoint does not belong to this job".into(),
                ));
            }
            done = saved;
        }
        let resumed_at = done.layers();
        sink.progress(resumed_at as u64, count as u64);
        let scene =
            part_scene(&positions, &triangles).map_err(|e| JobError::Invalid(e.to_string()))?;
        let params = VolumeParams {
            samples: o.rays,
            max_distance: self.grid_distance(&all),
            seed: self.plan.params.seed,
        };
        trace_layers::<JobError>(
            &scene,
            &grid,
            part,
            first + resumed_at..end,
            params,
            &mut |_, cells| {
                done.cells.extend(cells);
                let layers = done.layers() as u64;
                sink.progress(layers, count as u64);
                if layers < count as u64 {
                    sink.checkpoint(Checkpoint {
                        step: SLAB_STEP.into(),
                        cursor: layers,
                        data: done.to_bytes(),
                    })
                    .map_err(JobError::Stopped)?;
                }
                Ok(())
            },
        )?;
        let seconds = started.elapsed().as_secs_f64();
        let mut out = JobOutput::default();
        let name = slab_name(part, first);
        out.push(&name, done.to_bytes());
        out.push(
            &format!("{name}.json"),
            json(&SlabInfo {
                seconds,
                computed: count - resumed_at,
                resumed_at,
            }),
        );
        out.timings.reference_trace_s = seconds;
        out.timings.gpu_trace_s = super::report::on_gpu(seconds);
        Ok(out)
    }

    /// Every part's traced cells from the slab jobs' outputs, each grid
    /// covered exactly once, and the seconds its slabs took.
    fn raw_cells(
        &self,
        parts: &[Part],
        deps: &[&JobOutput],
    ) -> Result<Vec<(Vec<RawCell>, f64)>, JobError> {
        let n = self.plan.params.grid.resolution;
        let mut slabs: Vec<Vec<Slab>> = vec![Vec::new(); parts.len()];
        let mut seconds = vec![0.0; parts.len()];
        for d in deps {
            for o in d
                .outputs
                .iter()
                .filter(|o| o.name.starts_with("slab-") && !o.name.ends_with(".json"))
            {
                let slab = Slab::from_bytes(&o.bytes, n).map_err(JobError::Invalid)?;
                let Some(list) = slabs.get_mut(slab.part) else {
                    return Err(JobError::Invalid(format!(
                        "a slab of part {} of {}",
                        slab.part,
                        parts.len()
                    )));
                };
                if let Some(info) = d.get(&format!("{}.json", o.name)) {
                    seconds[slab.part] += parse::<SlabInfo>(info)?.seconds;
                }
                list.push(slab);
            }
        }
        slabs
            .into_iter()
            .zip(seconds)
            .enumerate()
            .map(|(p, (mut list, s))| {
                list.sort_by_key(|s| s.first);
                let mut cells = Vec::with_capacity(n * n * n);
                let mut next = 0;
                for slab in list {
                    if slab.first != next {
                        return Err(JobError::Invalid(format!(
                            "the slabs of part {p} do not cover its layers in order (expected layer {next}, got {})",
                            slab.first
                        )));
                    }
                    next += slab.layers();
                    cells.extend(slab.cells);
                }
                if next != n {
                    return Err(JobError::Invalid(format!(
                        "the slabs of part {p} hold {next} layers, not {n}"
                    )));
                }
                Ok((cells, s))
            })
            .collect()
    }

    /// The model finished from raw cells, with or without cones.
    fn finish_model(&self, parts: &[Part], raw: &[(Vec<RawCell>, f64)], cones: bool) -> GridModel {
        let o = &self.plan.params.grid;
        let grids = parts
            .iter()
            .zip(raw)
            .map(|(part, (cells, _))| {
                let (_, _, grid) = self.part_grid(part);
                let f = finish(cells, o.resolution, cones);
                PartGrid {
                    name: part.name.clone(),
                    joint: part.joint,
                    node: part.node,
                    grid,
                    boundary_max: f.boundary_max,
                    inside: f.inside,
                    occlusion: f.occlusion,
                    directions: f.directions,
                }
            })
            .collect();
        GridModel {
            parts: grids,
            tclip: cones.then(|| TClip::compute(o.tclip_resolution)),
            base: None,
        }
    }

    /// `assemble`: the finished grids → `asset`.
    pub(super) fn grid_assemble(&self, deps: &[&JobOutput]) -> Result<JobOutput, JobError> {
        let parts = self.grid_parts()?;
        let raw = self.raw_cells(&parts, deps)?;
        let started = Instant::now();
        let mut model = self.finish_model(&parts, &raw, self.plan.params.grid.cones);
        if self.plan.params.grid.static_base {
            model.base = Some(self.fit_base(&parts, &model, deps)?);
        }
        let mut out = JobOutput::default();
        out.push("asset", model.to_container(self.header()).to_bytes());
        let sampled: f64 = deps
            .iter()
            .filter(|d| d.get(VERTEX_TRUTH).is_some())
            .map(|d| d.timings.reference_trace_s)
            .sum();
        out.timings.reference_trace_s = raw.iter().map(|(_, s)| s).sum::<f64>() + sampled;
        out.timings.gpu_trace_s = super::report::gpu_seconds(deps);
        out.timings.fit_s = started.elapsed().as_secs_f64();
        Ok(out)
    }

    /// `evaluate`: the ground truth, every variant's errors, the slices
    /// and the report.
    pub(super) fn grid_evaluate(&self, deps: &[&JobOutput]) -> Result<JobOutput, JobError> {
        let parts = self.grid_parts()?;
        let raw = self.raw_cells(&parts, deps)?;
        let assembled = find(deps, "asset")?;
        let asset = named(assembled, "asset")?;
        let model = decode_grid(asset)?;
        let o = &self.plan.params.grid;
        let character = &self.inputs.character;
        let clips = &self.inputs.clips;
        let traced = Instant::now();
        let inputs = self.grid_inputs(&parts);
        // The static base's `sample` jobs (among `deps`) traced the
        // training frames at the vertices already, as the static average
        // needs them.
        let training_vertices = if o.static_base {
            let frames = inputs.training_frames().len();
            Some(stack_blocks(deps, VERTEX_TRUTH, character.vertex_count(), frames)?.values)
        } else {
            None
        };
        let truth = GroundTruth::trace(&inputs, training_vertices.as_deref())
            .map_err(|e| JobError::Invalid(e.to_string()))?;
        let trace_s = traced.elapsed().as_secs_f64();
        let started = Instant::now();
        // The paper's grids: the baked cells without the base, and the
        // same cells finished with the other cone setting.
        let paper = GridModel {
            base: None,
            ..model.clone()
        };
        let other = self.finish_model(&parts, &raw, !o.cones);
        let (with, without) = if o.cones {
            (&paper, &other)
        } else {
            (&other, &paper)
        };
        let variant = |name: &str, description: &str, bytes: usize, predict: &Predictor<'_>| {
            let (vertices, ground) = truth.errors(predict);
            GridVariant {
                name: name.into(),
                description: description.into(),
                bytes,
                vertices,
                ground,
            }
        };
        let mut grids = [
            variant(
                "grids (cones)",
                "every part's grid through T_clip: its cone clipped by the receiver's tangent plane (§5.1), its own part included; parts combined 1 − Π(1 − aᵢ)",
                with.bytes(),
                &|f| truth.predict(with, f, Terms::All, false),
            ),
            variant(
                "grids",
                "every part's grid: ao_grid for other parts, (ao_grid − 1)/2 for the receiver's own (§4.2); parts combined 1 − Π(1 − aᵢ)",
                without.bytes(),
                &|f| truth.predict(without, f, Terms::All, false),
            ),
        ];
        if !o.cones {
            grids.swap(0, 1); // the baked cells first
        }
        let mut variants: Vec<GridVariant> = Vec::new();
        if model.base.is_some() {
            variants.push(variant(
                if o.cones {
                    "grids on a static base (cones)"
                } else {
                    "grids on a static base"
                },
                &format!(
                    "aobake's product form, as baked: per receiver, a static base (the mean ray-traced occlusion over {} training frames) plus the grids' change from their own mean over those frames, scaled by a least-squares gain per part and for the ground; per-vertex offsets and a {r}×{r} ground texture beside the grids",
                    o.average_frames,
                    r = o.ground_resolution
                ),
                model.bytes(),
                &|f| truth.predict_ao(&model, f),
            ));
        }
        variants.extend(grids);
        let alone = "no occlusion between parts: each vertex shaded by its own part's grid alone, the ground by nothing";
        for (name, m) in [("own grid only (cones)", with), ("own grid only", without)] {
            variants.push(variant(name, alone, m.bytes(), &|f| {
                truth.predict(m, f, Terms::Own, false)
            }));
        }
        let self_bytes = 2 * character.vertex_count();
        for (name, m, description) in [
            (
                "traced self + grids (cones)",
                with,
                "each vertex's exact self-occlusion (its part traced alone, as a per-vertex bake stores it: a rigid part's never changes) combined with the other parts' grids through their cones",
            ),
            (
                "traced self + grids",
                without,
                "each vertex's exact self-occlusion combined with the other parts' grids (ao_grid)",
            ),
        ] {
            variants.push(variant(name, description, m.bytes() + self_bytes, &|f| {
                truth.predict(m, f, Terms::Others, true)
            }));
        }
        variants.push(variant(
            "traced self only",
            "no occlusion between parts: each vertex's exact self-occlusion, the ground open",
            self_bytes,
            &|f| truth.predict(without, f, Terms::Own, true),
        ));
        let (average_v, average_g) = &truth.average;
        variants.push(variant(
            "static average",
            &format!(
                "per receiver, the mean ray-traced occlusion over {} random frames of the training clips (other frames than those evaluated)",
                o.average_frames
            ),
            2 * (character.vertex_count() + truth.ground.len()),
            &|_| (average_v.clone(), average_g.clone()),
        ));
        let plot = slices_png(&model, &variants)
            .map_err(|e| JobError::Failed(format!("cannot draw the slices: {e}")))?;
        let evaluation = GridEvaluation {
            frames: truth
                .frames
                .iter()
                .map(|f| (f.frame.clip.map(|c| clips[c].name.clone()), f.frame.time))
                .collect(),
            vertices: truth.owner.iter().filter(|o| o.is_some()).count(),
            ground_points: truth.ground.len(),
            ground_hidden: truth.ground_hidden(),
            rays_per_point: o.eval_rays,
            max_distance: self.grid_distance(&parts),
            noise_rmse_vertices: truth.noise_rmse.0,
            noise_rmse_ground: truth.noise_rmse.1,
            variants,
            lookup_ns_per_receiver: truth.lookup_cost(&model),
        };
        let mut timings = assembled.timings;
        timings.test_trace_s = trace_s;
        timings.gpu_trace_s += super::report::on_gpu(trace_s);
        timings.evaluate_s = started.elapsed().as_secs_f64();
        let plan = &self.plan;
        let names =
            |idx: &[usize]| -> Vec<String> { idx.iter().map(|&i| clips[i].name.clone()).collect() };
        let part_reports = parts
            .iter()
            .zip(&model.parts)
            .zip(&raw)
            .map(|((part, grid), (_, seconds))| PartReport {
                name: part.name.clone(),
                node: part.node,
                vertices: part.vertices.len(),
                triangles: part.triangles.len(),
                resolution: grid.grid.resolution,
                half_extent: grid.grid.half.to_array(),
                boundary_max: grid.boundary_max,
                inside_cells: grid.inside,
                bytes: [4 * grid.occlusion.len(), grid.occlusion.len()],
                bake_s: *seconds,
            })
            .collect();
        let cells: u64 = model.parts.iter().map(|p| p.occlusion.len() as u64).sum();
        // The static base's `sample` jobs: its frames at the vertices and
        // the ground texture's texels.
        let base_rays = model.base.as_ref().map_or(0, |b| {
            (o.average_frames * (character.vertex_count() + b.ground.square.texels())) as u64
                * u64::from(o.eval_rays)
        });
        let report = GridReport {
            method: plan.params.method,
            bake_key: self.header().bake_key,
            params: plan.params.clone(),
            character: CharacterInfo {
                digest: self.inputs.character_digest.clone(),
                vertices: character.vertex_count(),
                triangles: character.triangles.len(),
                clips: clips.iter().map(|c| c.name.clone()).collect(),
                train_clips: names(&plan.train),
                test_clips: names(&plan.test),
                joint_angle_parameters: plan.joint_angles.len(),
                handle_coordinates: plan.handles.len(),
            },
            parts: part_reports,
            rays: cells * u64::from(o.rays) + base_rays + truth.rays,
            timings,
            sizes: Sizes {
                asset_bytes: asset.len(),
                model_bytes: model.bytes(),
                baseline_bytes: 2 * character.vertex_count(),
            },
            evaluation,
        };
        let mut out = JobOutput::default();
        out.push(
            "report.json",
            serde_json::to_vec_pretty(&report).expect("reports serialise"),
        );
        out.push("plot.png", plot);
        out.timings = timings;
        Ok(out)
    }
}

/// Each part's grid as three slices through its middle (x, y and z
/// constant), dark where occluded, a row per part named with its cells;
/// the title gives the held-out errors of the baked variant and of the
/// static average (`variants`, baked first, static average last).
fn slices_png(model: &GridModel, variants: &[GridVariant]) -> Result<Vec<u8>, String> {
    use plotters::prelude::*;
    const SIDE: usize = 200;
    const GAP: usize = 12;
    const LABEL: usize = 22;
    const TOP: usize = 70;
    crate::image::register_plot_font()?;
    let rows = model.parts.len();
    let width = 3 * SIDE + 4 * GAP;
    let height = TOP + rows * (LABEL + SIDE + GAP);
    let row_top = |r: usize| TOP + r * (LABEL + SIDE + GAP);
    let mut rgb = vec![255u8; 3 * width * height];
    for (r, part) in model.parts.iter().enumerate() {
        let n = part.grid.resolution;
        let mid = n / 2;
        for axis in 0..3 {
            for py in 0..SIDE {
                for px in 0..SIDE {
                    let (a, b) = (px * n / SIDE, (SIDE - 1 - py) * n / SIDE);
                    let (x, y, z) = match axis {
                        0 => (mid, b, a),
                        1 => (a, mid, b),
                        _ => (a, b, mid),
                    };
                    let v = part.occlusion[(z * n + y) * n + x];
                    let shade = 255 - v;
                    let (ox, oy) = (GAP + axis * (SIDE + GAP) + px, row_top(r) + LABEL + py);
                    let i = 3 * (oy * width + ox);
                    rgb[i..i + 3].copy_from_slice(&[shade, shade, shade]);
                }
            }
        }
    }
    {
        let root =
            BitMapBackend::with_buffer(&mut rgb, (width as u32, height as u32)).into_drawing_area();
        let e = |e: DrawingAreaErrorKind<_>| e.to_string();
        let text = |s: String, x: usize, y: usize, size: u32| {
            root.draw(&Text::new(s, (x as i32, y as i32), ("sans-serif", size)))
        };
        text(
            "grid: each part's cells through its middle, dark = occluded".into(),
            GAP,
            6,
            15,
        )
        .map_err(e)?;
        let psnr = |v: &GridVariant| {
            format!(
                "{}: {:.1} dB, {:.1} dB",
                v.name, v.vertices.mean.psnr_db, v.ground.mean.psnr_db
            )
        };
        let average = variants.iter().find(|v| v.name == "static average");
        if let (Some(baked), Some(average)) = (variants.first(), average) {
            let frames = baked.vertices.frames;
            let judged =
                format!("PSNR at the vertices, on the ground; {frames} clip frames, fresh rays:");
            text(judged, GAP, 26, 11).map_err(e)?;
            let line = format!("{};   {}", psnr(baked), psnr(average));
            text(line, GAP, 40, 11).map_err(e)?;
        }
        for (axis, label) in [
            "x = middle: z →, y ↑",
            "y = middle: x →, z ↑",
            "z = middle: x →, y ↑",
        ]
        .into_iter()
        .enumerate()
        {
            text(label.into(), GAP + axis * (SIDE + GAP), TOP - 16, 11).map_err(e)?;
        }
        for (r, part) in model.parts.iter().enumerate() {
            let n = part.grid.resolution;
            let size = 2.0 * part.grid.half;
            let label = format!(
                "{}: {n}³ cells over {:.3} × {:.3} × {:.3}",
                part.name, size.x, size.y, size.z
            );
            text(label, GAP, row_top(r) + 4, 12).map_err(e)?;
        }
        root.present().map_err(e)?;
    }
    Ok(encode_rgb_png(&rgb, width as u32, height as u32)?)
}

/// A grid asset's model.
pub(super) fn decode_grid(bytes: &[u8]) -> Result<GridModel, JobError> {
    decode_with(bytes, GridModel::from_container)
}

/// A grid bake's report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GridReport {
    /// The method.
    pub method: Method,
    /// The bake key.
    pub bake_key: String,
    /// The parameters.
    pub params: BakeParams,
    /// The character.
    pub character: CharacterInfo,
    /// Every part's grid.
    pub parts: Vec<PartReport>,
    /// Rays traced: the cells, the static base's frames and the
    /// evaluation's ground truth ([`crate::method::grid::GridOptions::rays_total`]).
    pub rays: u64,
    /// Stage times (`reference_trace_s`: the slabs, summed).
    pub timings: Timings,
    /// Sizes: the asset, its cells (and `T_clip`), and the static average
    /// (one f16 per vertex).
    pub sizes: Sizes,
    /// Every variant against the ground truth.
    pub evaluation: GridEvaluation,
}

/// One part's grid in a report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartReport {
    /// The part (its node's name).
    pub name: String,
    /// Its node.
    pub node: usize,
    /// Vertices it carries.
    pub vertices: usize,
    /// Its triangles.
    pub triangles: usize,
    /// Cells per grid edge.
    pub resolution: usize,
    /// The grid's half extent per axis (Eq. 4), bind space.
    pub half_extent: [f32; 3],
    /// V_M, the boundary maximum the cells were rescaled by.
    pub boundary_max: f32,
    /// Cells inside the part, filled from their neighbours.
    pub inside_cells: usize,
    /// Bytes its cells take with cones (RGBA) and without (one byte).
    pub bytes: [usize; 2],
    /// Seconds its slabs traced (summed over slab jobs).
    pub bake_s: f64,
}

/// Part `k`'s grid as one image of its z-slices, `part{k}-{name}.exr`:
/// slice z in rows z·n .. (z + 1)·n, +y up within a slice, +x left to
/// right; the channel `ao_grid` (the stored 2·ao′, 0..2) and, with cones,
/// `axis.x`, `axis.y`, `axis.z` (the average occluded direction in the
/// part's bind space), each exactly the value the run time reads.
pub(super) fn part_slices(k: usize, part: &PartGrid) -> crate::image::FloatImage {
    let n = part.grid.resolution;
    // The cell shown at pixel (x, y).
    let cell = |x: usize, y: usize| {
        let (z, row) = (y / n, y % n);
        (z * n + (n - 1 - row)) * n + x
    };
    let cells: Vec<usize> = (0..n * n)
        .flat_map(|y| (0..n).map(move |x| cell(x, y)))
        .collect();
    let mut channels = vec![(
        "ao_grid".to_owned(),
        cells
            .iter()
            .map(|&i| 2.0 * f32::from(part.occlusion[i]) / 255.0)
            .collect::<Vec<f32>>(),
    )];
    if let Some(d) = &part.directions {
        for (c, name) in ["axis.x", "axis.y", "axis.z"].into_iter().enumerate() {
            channels.push((
                name.to_owned(),
                cells
                    .iter()
                    .map(|&i| f32::from(d[i][c]) / 255.0 * 2.0 - 1.0)
                    .collect(),
            ));
        }
    }
    let safe: String = part
        .name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .take(64)
        .collect();
    crate::image::FloatImage {
        file: format!("part{k}-{safe}.exr"),
        layer: part.name.clone(),
        comment: format!(
            "aobake grid: part {} ({n}^3 cells); ao_grid = 2 x occluded fraction of the sphere; z-slices top to bottom, +y up, +x right; axis in the part's bind space",
            part.name
        ),
        width: n,
        height: n * n,
        channels,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::asset::metrics::{Errors, FrameError};

    /// The plot's pixels as RGB rows.
    fn decode(png: &[u8]) -> (usize, usize, Vec<u8>) {
        let mut reader = png::Decoder::new(std::io::Cursor::new(png))
            .read_info()
            .unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        buf.truncate(info.buffer_size());
        (info.width as usize, info.height as usize, buf)
    }

    #[test]
    fn the_slices_show_each_parts_cells_under_a_labelled_title() {
        let n = 4;
        // Occluded exactly where x is the middle cell: the x = middle
        // slice is dark all over, the y and z slices in one column.
        let occlusion = (0..n * n * n)
            .map(|i| if i % n == n / 2 { 200 } else { 0 })
            .collect();
        let part = PartGrid {
            name: "hull".into(),
            joint: 0,
            node: 0,
            grid: GridBox {
                centre: glam::Vec3::ZERO,
                half: glam::Vec3::ONE,
                resolution: n,
            },
            boundary_max: 1.0,
            inside: 0,
            occlusion,
            directions: None,
        };
        let model = GridModel {
            parts: vec![part],
            tclip: None,
            base: None,
        };
        let errors = Errors::of(&[FrameError::of(&[0.5, 0.5], &[0.4, 0.6])]);
        let variant = |name: &str| GridVariant {
            name: name.into(),
            description: String::new(),
            bytes: 0,
            vertices: errors.clone(),
            ground: errors.clone(),
        };
        let variants = [variant("grids"), variant("static average")];
        let (width, height, rgb) = decode(&slices_png(&model, &variants).unwrap());
        let pixel = |x: usize, y: usize| &rgb[3 * (y * width + x)..3 * (y * width + x) + 3];
        let ink = |y0: usize, y1: usize| {
            (y0..y1).any(|y| (0..width).any(|x| pixel(x, y) != [255, 255, 255]))
        };
        // Title, the errors, the column heads and the part's name are
        // drawn above the slices, which start at 70 + 22.
        assert!(ink(0, 20), "a title");
        assert!(
            ink(24, 54),
            "the errors of the baked variant and the baseline"
        );
        assert!(ink(70, 92), "the part's name");
        let (top, side, gap) = (92, 200, 12);
        // x = middle slice: every cell is 200, drawn as 255 − 200.
        for (x, y) in [(gap + 1, top + 1), (gap + side - 2, top + side - 2)] {
            assert_eq!(pixel(x, y), [55, 55, 55], "({x}, {y})");
        }
        // z = middle slice: the middle column is dark, the first is open.
        let z0 = gap + 2 * (side + gap);
        assert_eq!(pixel(z0 + side / 2 + 5, top + 10), [55, 55, 55]);
        assert_eq!(pixel(z0 + 5, top + 10), [255, 255, 255]);
        assert_eq!(height, top + side + gap);
    }
}
