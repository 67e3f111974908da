//! The jobs of a cubemap bake (Kroon 2023; DESIGN §1.3, §5):
//!
//! * `face` (six of them, one per cube face): Eq. 3.1 at every texel,
//!   shell and time sample of the face ([`face::compute_face`]). It saves
//!   a checkpoint after every batch of time samples
//!   ([`face::checkpoint_batch`]: 8 at the defaults, about 32 a face);
//!   each checkpoint stores only the new slices, as a part blob through
//!   [`JobSink::save_part`], and its data is a small manifest of every
//!   part's digest. A new attempt loads the parts and goes on at the first
//!   missing time sample; since a slice is a pure function of (seed, face,
//!   time sample), the face's field does not depend on interruptions.
//!   Output: `face-{n}`, the raw field.
//! * `assemble`: the six fields encoded in the bake's encoding → `asset`.
//! * `evaluate`: ground truth at random clip times, in space and on the
//!   ground ([`GroundTruth`]); every encoding and the references judged
//!   against it; Kroon's charts → `report.json`, `plot.png`.
//! * `preview`: as for every method (`bake::preview`), with the ground
//!   shaded by the cubemap in the model's panel.

use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::{
    digest::sha256_hex,
    method::Method,
    method::cubemap::{
        continuous,
        evaluate::{
            CubemapEvaluation, GroundTruth, Lookup, RawCubemap, StaticCubemap, VariantErrors,
            chart_sums, chart_texels, charts_png, fit_error,
        },
        face::{FaceError, FaceField, Manifest, Part, checkpoint_batch, compute_face},
        geometry::FACES,
        ground::{self, TexelTruth},
        model::{CubemapLayout, CubemapModel, Encoding},
        setup::Setup,
    },
    method::ground::GroundBase,
};

use super::{
    Bake, BakeParams, Checkpoint, GraphOptions, JobError, JobGraph, JobOutput, JobSink, JobSpec,
    PlannedJob,
    jobs::{decode_with, find, json, named, parse},
    report::{CharacterInfo, Sizes, Timings},
};

/// The output of `assemble` holding the static ground texture alone (the
/// mean truth per texel, f32 little-endian), for the report.
const STILL_GROUND: &str = "ground-static";

/// The output of `assemble` holding the truth the static ground is fitted
/// to ([`TexelTruth::to_bytes`]), so that `evaluate` fits the other
/// encodings' grounds to it without tracing it again.
pub(super) const GROUND_TRUTH: &str = "ground-truth";

/// The step name of a face job's checkpoints.
const FACE_STEP: &str = "face";

/// How a face job checkpointed, as `face-{n}.json`: what the note on
/// checkpoint sizes reads.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FaceInfo {
    /// Time samples per checkpoint.
    pub batch: usize,
    /// Checkpoints a whole face saves.
    pub checkpoints: usize,
    /// Bytes of one full part (a batch of slices and its 20-byte head).
    pub part_bytes: usize,
    /// Bytes of the face's raw field.
    pub field_bytes: usize,
    /// Time samples this attempt computed (the rest came from parts).
    pub computed: usize,
    /// The time sample this attempt started at: its checkpoint's cursor.
    pub resumed_at: usize,
}

impl Bake<'_> {
    /// Runs one of the family's jobs.
    pub(super) fn cubemap_job(
        &self,
        spec: &JobSpec,
        deps: &[&JobOutput],
        resume: Option<Checkpoint>,
        sink: &mut dyn JobSink,
    ) -> Result<JobOutput, JobError> {
        match spec {
            JobSpec::Face { face, times } => self.face(*face, *times, resume, sink),
            JobSpec::Assemble => self.cubemap_assemble(deps),
            JobSpec::Evaluate => self.cubemap_evaluate(deps),
            JobSpec::Sample { .. }
            | JobSpec::Fit
            | JobSpec::Unseen { .. }
            | JobSpec::Slab { .. }
            | JobSpec::PreviewTruth { .. }
            | JobSpec::Preview => Err(self.foreign(spec)),
        }
    }

    /// The cubemap bake's clip, time samples and spheroid.
    pub fn cubemap_setup(&self) -> Result<Setup<'_>, JobError> {
        let clip = self.cubemap_clip()?;
        Ok(Setup::new(
            &self.inputs.character,
            &self.inputs.clips[clip],
            &self.plan.params.cubemap,
        ))
    }

    /// The index of the clip a cubemap bake bakes: `cubemap.clip`, or
    /// the first training clip.
    pub fn cubemap_clip(&self) -> Result<usize, JobError> {
        match &self.plan.params.cubemap.clip {
            Some(name) => Ok(super::plan::clip_index(&self.inputs.clips, name)?),
            None => self
                .plan
                .train
                .first()
                .copied()
                .ok_or_else(|| JobError::Invalid("the bake has no clip".into())),
        }
    }

    fn encoding(&self) -> Result<Encoding, JobError> {
        let p = &self.plan.params;
        crate::method::cubemap_encoding(p.method, p.cubemap.continuous_layout).ok_or_else(|| {
            JobError::Invalid(format!(
                "{} is not a cubemap method",
                self.plan.params.method
            ))
        })
    }

    /// Six `face` jobs → `assemble` → `evaluate` → `preview`.
    pub(super) fn cubemap_graph(&self, options: GraphOptions) -> JobGraph {
        let times = self.plan.params.cubemap.times;
        let jobs: Vec<PlannedJob> = (0..FACES)
            .map(|face| PlannedJob {
                spec: JobSpec::Face { face, times },
                deps: Vec::new(),
            })
            .collect();
        JobGraph::assemble_evaluate_preview(
            jobs,
            self.preview_truth_jobs(options),
            options.previews,
        )
    }

    /// A `face` job: resumes from `resume`'s parts, traces the remaining
    /// time samples, checkpointing after every batch.
    pub(super) fn face(
        &self,
        face: usize,
        times: usize,
        resume: Option<Checkpoint>,
        sink: &mut dyn JobSink,
    ) -> Result<JobOutput, JobError> {
        let started = Instant::now();
        let setup = self.cubemap_setup()?;
        let (res, shells, t) = setup.shape();
        if face >= FACES || times != t {
            return Err(JobError::Invalid(format!(
                "face {face} with {times} time samples is not a face of this bake"
            )));
        }
        let mut field = FaceField::new(res, shells, times);
        let n = field.slice_len();
        let mut manifest = Manifest::default();
        let mut next = 0;
        if let Some(cp) = resume.filter(|cp| cp.step == FACE_STEP) {
            manifest = parse(&cp.data)?;
            for digest in &manifest.parts {
                let bytes = sink.load_part(digest)?;
                if sha256_hex(&bytes) != *digest {
                    return Err(JobError::Failed(format!(
                        "checkpoint part {digest} came back with other bytes"
                    )));
                }
                next = Part::from_bytes(&bytes, face, n)
                    .and_then(|p| p.apply(&mut field, next))
                    .map_err(JobError::Invalid)?;
            }
            if next as u64 != cp.cursor {
                return Err(JobError::Invalid(
                    "the checkpoint's parts do not reach its cursor".into(),
                ));
            }
        }
        let resumed_at = next;
        sink.progress(next as u64, times as u64);
        let sampling = setup.sampling(self.plan.params.seed);
        // Parts not stored yet (a failed upload): tried again, in order,
        // at the next checkpoint, so a manifest never has a gap.
        let mut pending: Vec<Vec<u8>> = Vec::new();
        let result = compute_face(
            &sampling,
            face,
            &self.inputs.character.triangles,
            &mut |m| setup.positions(m),
            &mut field,
            next,
            &mut |part: Part, done: usize| {
                sink.progress(done as u64, times as u64);
                if done == times {
                    return Ok(());
                }
                pending.push(part.to_bytes(face, n));
                while let Some(bytes) = pending.first() {
                    match sink.save_part(bytes) {
                        Some(digest) => {
                            manifest.parts.push(digest);
                            pending.remove(0);
                        }
                        None => return Ok(()),
                    }
                }
                sink.checkpoint(Checkpoint {
                    step: FACE_STEP.into(),
                    cursor: done as u64,
                    data: json(&manifest),
                })
            },
        );
        match result {
            Ok(()) => {}
            Err(FaceError::Stopped(stop)) => return Err(JobError::Stopped(stop)),
            Err(FaceError::Trace(e)) => return Err(JobError::Invalid(e.to_string())),
        }
        let batch = checkpoint_batch(times);
        let info = FaceInfo {
            batch,
            checkpoints: times.div_ceil(batch) - 1,
            part_bytes: 20 + batch * n,
            field_bytes: field.values.len(),
            computed: times - resumed_at,
            resumed_at,
        };
        let mut out = JobOutput::default();
        out.push(&format!("face-{face}"), field.to_bytes());
        out.push(&format!("face-{face}.json"), json(&info));
        out.timings.reference_trace_s = started.elapsed().as_secs_f64();
        out.timings.gpu_trace_s = super::report::on_gpu(out.timings.reference_trace_s);
        Ok(out)
    }

    /// The six raw fields from the face jobs' outputs.
    fn faces(&self, setup: &Setup<'_>, deps: &[&JobOutput]) -> Result<Vec<FaceField>, JobError> {
        (0..FACES)
            .map(|face| {
                let name = format!("face-{face}");
                let bytes = named(find(deps, &name)?, &name)?;
                FaceField::from_bytes(bytes, setup.shape()).map_err(JobError::Invalid)
            })
            .collect()
    }

    fn encode(
        &self,
        setup: &Setup<'_>,
        faces: &[FaceField],
        encoding: Encoding,
        residuals: bool,
    ) -> Result<CubemapModel, JobError> {
        let o = &setup.options;
        crate::method::cubemap::model::encode(
            setup.layout(encoding),
            faces,
            continuous::Encoding {
                bright_weight: o.bright_weight,
                residuals,
            },
        )
        .map_err(JobError::Invalid)
    }

    /// `assemble`: the six fields encoded → `asset`.
    pub(super) fn cubemap_assemble(&self, deps: &[&JobOutput]) -> Result<JobOutput, JobError> {
        let setup = self.cubemap_setup()?;
        let faces = self.faces(&setup, deps)?;
        let started = Instant::now();
        let mut model = self.encode(&setup, &faces, self.encoding()?, setup.options.residuals)?;
        let mut out = JobOutput::default();
        if setup.options.static_ground {
            let kroon = setup.options.kroon(&setup.spheroid, self.plan.params.seed);
            let texels = TexelTruth::trace(&setup, &kroon, setup.options.ground_resolution)
                .map_err(|e| JobError::Invalid(e.to_string()))?;
            let (ground, still) = texels.fit(&setup, &model);
            model.ground = Some(ground);
            // The texture alone, for the report's static ground baseline,
            // and the truth the other encodings' grounds are fitted to.
            let bytes: Vec<u8> = still.offsets.iter().flat_map(|x| x.to_le_bytes()).collect();
            out.push(STILL_GROUND, bytes);
            out.push(GROUND_TRUTH, texels.to_bytes());
        }
        let asset = model
            .to_container(self.header(), &setup.clip.name)
            .to_bytes();
        out.push("asset", asset);
        out.timings.reference_trace_s = deps.iter().map(|d| d.timings.reference_trace_s).sum();
        out.timings.gpu_trace_s = super::report::gpu_seconds(deps);
        out.timings.fit_s = started.elapsed().as_secs_f64();
        Ok(out)
    }

    /// `evaluate`: ground truth, every variant's errors, the charts and
    /// the report.
    pub(super) fn cubemap_evaluate(&self, deps: &[&JobOutput]) -> Result<JobOutput, JobError> {
        let setup = self.cubemap_setup()?;
        let faces = self.faces(&setup, deps)?;
        let assembled = find(deps, "asset")?;
        let asset = named(assembled, "asset")?;
        let model = decode_cubemap(asset)?;
        let traced = Instant::now();
        let truth = GroundTruth::trace(&setup, self.plan.params.seed)
            .map_err(|e| JobError::Invalid(e.to_string()))?;
        let trace_s = traced.elapsed().as_secs_f64();
        let started = Instant::now();
        // The static ground's truth (assemble's), when the asset has one.
        let texels = match assembled.get(GROUND_TRUTH) {
            Some(bytes) if model.ground.is_some() => Some(
                TexelTruth::from_bytes(&setup, setup.options.ground_resolution, bytes)
                    .map_err(JobError::Invalid)?,
            ),
            _ => None,
        };
        // The baked encoding first, then the others from the same fields.
        let baked = model.layout.encoding;
        let residuals = setup.options.residuals;
        let mut encoded: Vec<(String, String, CubemapModel)> = Vec::new();
        let describe = |e: Encoding, r: bool| {
            match (e, r) {
            (Encoding::Discrete, _) => (
                "cubemap-discrete".to_owned(),
                "one cubemap per shell; 4 bounded quadratic segments per texel (16 B)".to_owned(),
            ),
            (Encoding::Continuous, true) => (
                "cubemap-continuous".to_owned(),
                "4 cubemaps; 5×5 cosine basis + residual cubics along distance and time (64 B)"
                    .to_owned(),
            ),
            (Encoding::Continuous, false) => (
                "cubemap-continuous without residuals".to_owned(),
                "4 cubemaps; the 5×5 cosine basis alone (Kroon's plain Blurhash)".to_owned(),
            ),
            (Encoding::Thirds, true) => (
                "cubemap-continuous (thirds)".to_owned(),
                "4 cubemaps in Kroon's layout: the cycle in three thirds as the channels of a 5×5 Blurhash (its quantisation) + the same residual cubics (51 of 64 B)".to_owned(),
            ),
            (Encoding::Thirds, false) => (
                "cubemap-continuous (thirds) without residuals".to_owned(),
                "Kroon's layout, the Blurhash alone".to_owned(),
            ),
        }
        };
        let (name, text) = describe(baked, residuals);
        encoded.push((name, text, model.clone()));
        for (e, r) in [
            (Encoding::Discrete, true),
            (Encoding::Continuous, true),
            (Encoding::Continuous, false),
            (Encoding::Thirds, true),
        ] {
            if e == baked && (e == Encoding::Discrete || r == residuals) {
                continue;
            }
            let (name, mut text) = describe(e, r);
            let mut other = self.encode(&setup, &faces, e, r)?;
            match (&model.ground, &texels) {
                // As it would be baked: on a static ground fitted to its
                // own lookups, from the same truth as the asset's.
                (Some(_), Some(texels)) => {
                    other.ground = Some(texels.fit(&setup, &other).0);
                    text.push_str("; on a static ground fitted to it");
                }
                // An `assemble` from before the truth was handed over:
                // its ground columns compare with the baked encoding's
                // "without the static ground" row.
                (Some(_), None) => text.push_str(
                    "; without a static ground (the asset's is fitted to its own encoding)",
                ),
                (None, _) => {}
            }
            encoded.push((name, text, other));
        }
        let layout = model.layout;
        let mut variants: Vec<VariantErrors> = Vec::new();
        let mut per_texel = Vec::new();
        for (i, (name, description, m)) in encoded.iter().enumerate() {
            let (space, ground) = truth.errors(m, &layout);
            let (texels, fit) = fit_error(m, &faces);
            if i == 0 {
                per_texel = texels;
            }
            variants.push(VariantErrors {
                name: name.clone(),
                description: description.clone(),
                bytes: m.bytes(),
                space,
                ground,
                fit: Some(fit),
            });
        }
        // With the static ground: the baked encoding without it, and the
        // texture alone (gain 0: a static ground bake).
        if let Some(g) = &model.ground {
            let bare = CubemapModel {
                ground: None,
                ..model.clone()
            };
            let offsets: Vec<f32> = assembled
                .get(STILL_GROUND)
                .ok_or_else(|| JobError::Invalid(format!("assemble left no {STILL_GROUND}")))?
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            let still = CubemapModel {
                ground: Some(GroundBase {
                    gain: 0.0,
                    offsets,
                    ..g.clone()
                }),
                ..model.clone()
            };
            let r = g.square.resolution;
            for (name, description, m) in [
                (
                    format!("{} without the static ground", encoded[0].0),
                    "Kroon's cubemap alone on the ground too".to_owned(),
                    &bare,
                ),
                (
                    "static ground texture".to_owned(),
                    format!(
                        "on the ground plane the static texture alone ({r}², traced on the plane over {} of the clip's time samples: a static ground bake); elsewhere the cubemap",
                        ground::GROUND_TIMES
                    ),
                    &still,
                ),
            ] {
                let (space, on) = truth.errors(m, &layout);
                variants.push(VariantErrors {
                    name,
                    description,
                    bytes: m.bytes(),
                    space,
                    ground: on,
                    fit: None,
                });
            }
        }
        let raw = RawCubemap {
            layout,
            faces: &faces,
        };
        let still = StaticCubemap::of(layout, &faces);
        let references: [(&str, &str, &dyn Lookup, usize); 2] = [
            (
                "uncompressed",
                "the traced fields as they are (a byte per texel, shell and time sample), interpolated: what sampling alone loses",
                &raw,
                faces.iter().map(|f| f.values.len()).sum(),
            ),
            (
                "static (time average)",
                "each texel's field averaged over the cycle: the pose-independent baseline",
                &still,
                still.bytes(),
            ),
        ];
        for (name, description, lookup, bytes) in references {
            let (space, ground) = truth.errors(lookup, &layout);
            variants.push(VariantErrors {
                name: name.into(),
                description: description.into(),
                bytes,
                space,
                ground,
                fit: None,
            });
        }
        let chosen = chart_texels(&per_texel);
        let models: Vec<(&str, &CubemapModel)> =
            encoded.iter().map(|(n, _, m)| (n.as_str(), m)).collect();
        let charts = chosen
            .iter()
            .map(|&(name, texel, _)| ChartTexel {
                name: name.into(),
                face: texel.0,
                texel: texel.1,
                sums: models
                    .iter()
                    .map(|&(n, m)| (n.to_owned(), chart_sums(m, &faces, texel)))
                    .collect(),
            })
            .collect();
        let plot = charts_png(
            &faces,
            &models,
            &chosen,
            &format!(
                "{}: time × distance at chosen texels of clip {} (input, decoded, error)",
                self.plan.params.method, setup.clip.name
            ),
        )
        .map_err(|e| JobError::Failed(format!("cannot draw the charts: {e}")))?;
        let evaluation = CubemapEvaluation {
            times: truth.times.clone(),
            space_points: truth.space,
            ground_points: truth.ground,
            space_hidden: truth.hidden().0,
            ground_hidden: truth.hidden().1,
            rays_per_point: setup.options.eval_rays,
            ground_truth_noise_rmse: truth.noise_rmse(),
            variants,
        };
        let mut timings = assembled.timings;
        timings.test_trace_s = trace_s;
        timings.gpu_trace_s += super::report::on_gpu(trace_s);
        timings.evaluate_s = started.elapsed().as_secs_f64();
        let character = &self.inputs.character;
        let clips = &self.inputs.clips;
        let report = CubemapReport {
            method: self.plan.params.method,
            bake_key: self.header().bake_key,
            params: self.plan.params.clone(),
            character: CharacterInfo {
                digest: self.inputs.character_digest.clone(),
                vertices: character.vertex_count(),
                triangles: character.triangles.len(),
                clips: clips.iter().map(|c| c.name.clone()).collect(),
                train_clips: vec![setup.clip.name.clone()],
                test_clips: vec![setup.clip.name.clone()],
                joint_angle_parameters: self.plan.joint_angles.len(),
                handle_coordinates: self.plan.handles.len(),
            },
            clip: setup.clip.name.clone(),
            layout,
            rays: setup.options.points() * u64::from(setup.options.rays) + truth.rays,
            timings,
            sizes: Sizes {
                asset_bytes: asset.len(),
                model_bytes: model.bytes(),
                baseline_bytes: still.bytes(),
            },
            evaluation,
            charts,
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

/// A cubemap asset's model.
pub(super) fn decode_cubemap(bytes: &[u8]) -> Result<CubemapModel, JobError> {
    decode_with(bytes, CubemapModel::from_container)
}

/// A cubemap bake's report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CubemapReport {
    /// The method.
    pub method: Method,
    /// The bake key.
    pub bake_key: String,
    /// The parameters.
    pub params: BakeParams,
    /// The character (its train and test clips are the baked clip).
    pub character: CharacterInfo,
    /// The baked clip.
    pub clip: String,
    /// Where the cubemaps sit.
    pub layout: CubemapLayout,
    /// Rays traced: the faces' sample points and the ground truth.
    pub rays: u64,
    /// Stage times.
    pub timings: Timings,
    /// Sizes: the asset, its texels, and the static baseline (a byte per
    /// texel and shell).
    pub sizes: Sizes,
    /// Every encoding and reference against the ground truth.
    pub evaluation: CubemapEvaluation,
    /// The texels the charts (`plot.png`) show, with each encoding's
    /// summed squared errors there.
    pub charts: Vec<ChartTexel>,
}

/// A texel of the charts and each encoding's squared errors summed over
/// its (time × distance) chart against the input, as Kroon's Tables
/// 5.1–5.3 give them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChartTexel {
    /// Why it was chosen: `worst`, `90th percentile` or `median`.
    pub name: String,
    /// Its face.
    pub face: usize,
    /// Its texel in the face (`j · resolution + i`).
    pub texel: usize,
    /// Per encoding: (too dark, too bright, total).
    pub sums: Vec<(String, [f64; 3])>,
}

/// A cubemap asset's decoded faces at each of `times` (seconds into the
/// clip): one image per time and shell, `t{time}-shell{k}.exr`, the six
/// faces side by side (+x, −x, +y, −y, +z, −z, each `resolution` texels
/// square, rows top to bottom as the cube-map convention has them) in one
/// channel `Y`, decoded at each texel's centre exactly as the run time
/// decodes it.
pub(super) fn face_strips(
    model: &CubemapModel,
    clip: &str,
    times: &[f32],
) -> Vec<crate::image::FloatImage> {
    let res = model.layout.resolution;
    let mut images = Vec::new();
    for &t in times {
        let phase = model.layout.phase(t);
        for shell in 0..model.layout.spheroid.shells {
            let faces: Vec<Vec<f32>> = (0..FACES)
                .map(|face| model.decode_face(face, shell, phase))
                .collect();
            let mut y = Vec::with_capacity(FACES * res * res);
            for j in 0..res {
                for face in &faces {
                    y.extend_from_slice(&face[j * res..(j + 1) * res]);
                }
            }
            images.push(crate::image::FloatImage {
                file: format!("t{t:.3}-shell{shell}.exr"),
                layer: format!("shell {shell}"),
                comment: format!(
                    "aobake {}: occlusion (0 open, 1 blocked) of clip {clip} at t = {t} s (phase {phase:.4}) on shell {shell}; faces +x -x +y -y +z -z left to right",
                    model.method()
                ),
                width: FACES * res,
                height: res,
                channels: vec![("Y".into(), y)],
            });
        }
    }
    images
}
