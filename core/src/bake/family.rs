//! What each method family brings to a bake, and the one exhaustive
//! `match` per concern that hands it over: the checks of a bake's
//! parameters against its inputs, its work, its job graph, its jobs, its
//! previews' model and its report. The families' bake files (`vertex.rs`,
//! `cubemap.rs`, `grid.rs`) sit below this file and never import it; a new
//! family adds a file beside them and an arm to each `match` here, and
//! the compiler lists every arm it still lacks (docs/methods/adding.md).

use serde::{Deserialize, Serialize};

use crate::{
    asset::Container,
    image::FloatImage,
    method::{Family, Method},
};

use super::{
    Bake, BakeError, BakeInputs, BakeParams, Checkpoint, GraphOptions, JobError, JobGraph,
    JobOutput, JobSink, JobSpec, Plan, PlannedJob, PoseSet, Receivers,
    cubemap::CubemapReport,
    grid::GridReport,
    jobs::{IndexedBlock, find, json, named, parse, stack_blocks},
    preview::{
        self, FrameTruth, GROUND_GRID, GROUND_SAMPLES, PreviewFrames, PreviewInfo, PreviewModel,
        Renderer, STILL_FRACTIONS, Subject, TruthTracing, animation_times, frame_poses,
        preview_clip, still_times,
    },
    screen_space::{PIXELS, PixelSummary},
    vertex::Report,
};

impl<'a> Bake<'a> {
    /// Checks the parameters against the inputs.
    pub fn new(inputs: &'a BakeInputs, params: BakeParams) -> Result<Self, BakeError> {
        let bake = Self {
            inputs,
            plan: Plan::new(&inputs.character, &inputs.clips, params)?,
        };
        let params = &bake.plan.params;
        match params.method.family() {
            // A texel bake's atlas is generated (and checked) by the plan.
            Family::Vertex | Family::Texel => {}
            Family::Cubemap => {
                if let Some(name) = &params.cubemap.clip {
                    super::plan::clip_index(&inputs.clips, name)?;
                }
            }
            Family::Grid => {
                crate::method::grid::parts::parts(&inputs.character, params.grid.parts)
                    .map_err(|e| BakeError::Param(e.to_string()))?;
            }
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
            Family::Vertex | Family::Cubemap | Family::Texel => 0,
        };
        p.work(self.plan.receiver_count(), frames, parts)
    }

    /// The job graph of this bake.
    pub fn graph(&self, options: GraphOptions) -> JobGraph {
        match self.plan.params.method.family() {
            Family::Vertex | Family::Texel => self.vertex_graph(options),
            Family::Cubemap => self.cubemap_graph(options),
            Family::Grid => self.grid_graph(options),
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
        if let JobSpec::PreviewTruth { first, count } = spec {
            return self.preview_truth(*first, *count);
        }
        match self.plan.params.method.family() {
            Family::Vertex | Family::Texel => self.vertex_job(spec, deps, resume, sink),
            Family::Cubemap => self.cubemap_job(spec, deps, resume, sink),
            Family::Grid => self.grid_job(spec, deps, resume, sink),
        }
    }

    /// How the previews' ground truth is traced: the held-out rays, as
    /// [`BakedAsset::preview_model`] reads them from the asset (a grid's
    /// distance limit and rays as its evaluation traces; a cubemap's
    /// ground as Eq. 3.1 over its spheroid, what it stores).
    pub fn preview_tracing(&self) -> Result<TruthTracing, JobError> {
        let params = &self.plan.params;
        let surface = params.held_out_surface();
        Ok(match params.method.family() {
            Family::Vertex | Family::Texel => TruthTracing {
                surface,
                kroon: None,
            },
            Family::Cubemap => TruthTracing {
                surface,
                kroon: Some(params.cubemap_truth(&self.cubemap_setup()?.spheroid)),
            },
            Family::Grid => TruthTracing {
                surface: params
                    .grid
                    .truth(self.grid_distance(&self.grid_parts()?), surface.seed),
                kroon: None,
            },
        })
    }

    /// The frames the previews show: the clip (a cubemap's baked clip,
    /// else the first held-out clip), the stills' times and the
    /// animation's.
    pub fn preview_frames(&self) -> Result<PreviewFrames<'_>, JobError> {
        let clips = &self.inputs.clips;
        let clip = match self.plan.params.method.family() {
            Family::Cubemap => Some(&clips[self.cubemap_clip()?]),
            Family::Vertex | Family::Grid | Family::Texel => {
                preview_clip(clips, &self.plan.test).map(|i| &clips[i])
            }
        };
        let fractions: Vec<f32> = clip.map_or_else(Vec::new, |c| {
            STILL_FRACTIONS.iter().map(|f| f * c.duration).collect()
        });
        Ok(PreviewFrames {
            clip,
            stills: still_times(clip, &fractions),
            animation: clip.map(animation_times).unwrap_or_default(),
        })
    }

    /// The `preview-truth` jobs of the previews' frames in batches
    /// ([`GraphOptions::batch`]); none without previews.
    pub(super) fn preview_truth_jobs(&self, options: GraphOptions) -> Vec<PlannedJob> {
        let frames = match self.preview_frames() {
            Ok(f) if options.previews => f.len(),
            // A bake without previews, or one whose clip is missing (its
            // preview job says so).
            _ => 0,
        };
        // About: the character's rays and the ground's, per frame.
        let samples = u64::from(self.plan.params.held_out_surface().samples);
        let ground = (GROUND_GRID * GROUND_GRID) as u64 * samples.min(GROUND_SAMPLES.into());
        let points =
            self.inputs.character.vertex_count() + self.preview_texels().map_or(0, |t| t.len());
        let rays = points as u64 * samples + ground;
        let batch = options.batch(rays);
        (0..frames)
            .step_by(batch)
            .map(|first| PlannedJob {
                spec: JobSpec::PreviewTruth {
                    first,
                    count: batch.min(frames - first),
                },
                deps: Vec::new(),
            })
            .collect()
    }

    /// The texels whose truth a texel bake's previews show (the plan's
    /// atlas, whose texels are the asset's columns); none for the other
    /// families.
    fn preview_texels(&self) -> Option<&crate::method::texel::atlas::Texels> {
        match &self.plan.receivers {
            Receivers::Texels(atlas) => Some(&atlas.texels),
            Receivers::Vertices => None,
        }
    }

    /// Runs a `preview-truth` job: the ground truth of preview frames
    /// `first..first + count`, as three outputs: `preview-truth` and
    /// `preview-ground` ([`IndexedBlock`]s of the character's and the
    /// ground's occlusion) and `preview-truth.json` (the seconds each
    /// frame took); a texel bake's a fourth, `preview-texels` (the
    /// occlusion at its atlas's texels).
    fn preview_truth(&self, first: usize, count: usize) -> Result<JobOutput, JobError> {
        let frames = self.preview_frames()?;
        let times = frames.times();
        let end = first.checked_add(count).filter(|&e| e <= times.len());
        let Some(end) = end else {
            return Err(JobError::Invalid(format!(
                "preview frames {first}..{} are outside the {} frames",
                first.saturating_add(count),
                times.len()
            )));
        };
        let character = &self.inputs.character;
        let ground = preview::camera(character, frames.clip).ground();
        let poses = frame_poses(character, frames.clip, &times[first..end]);
        let truth =
            self.preview_tracing()?
                .trace(character, &poses, &ground, self.preview_texels())?;
        let mut out = JobOutput::default();
        if let Some(block) = truth.texels {
            out.push(TEXELS, IndexedBlock { first, block }.to_bytes());
        }
        out.push(
            TRUTH,
            IndexedBlock {
                first,
                block: truth.character,
            }
            .to_bytes(),
        );
        out.push(
            GROUND,
            IndexedBlock {
                first,
                block: truth.ground,
            }
            .to_bytes(),
        );
        out.push(
            SECONDS,
            json(&TruthSeconds {
                first,
                seconds: truth.seconds,
            }),
        );
        Ok(out)
    }

    /// The ray-traced truth of every preview frame
    /// ([`Self::preview_frames`]), stacked from the outputs of the bake's
    /// `preview-truth` jobs; `None` when there are none.
    pub fn preview_truth_of(&self, outputs: &[&JobOutput]) -> Result<Option<FrameTruth>, JobError> {
        self.stacked_truth(outputs, self.preview_frames()?.len())
    }

    /// The previews' truth from the `preview-truth` jobs among `deps`, or
    /// `None` when there are none (a graph from before those jobs: the
    /// preview traces it itself).
    fn stacked_truth(
        &self,
        deps: &[&JobOutput],
        frames: usize,
    ) -> Result<Option<FrameTruth>, JobError> {
        if !deps.iter().any(|d| d.get(SECONDS).is_some()) {
            return Ok(None);
        }
        let ground = GROUND_GRID * GROUND_GRID;
        let character = stack_blocks(deps, TRUTH, self.inputs.character.vertex_count(), frames)?;
        let ground = stack_blocks(deps, GROUND, ground, frames)?;
        let texels = self
            .preview_texels()
            .map(|t| stack_blocks(deps, TEXELS, t.len(), frames))
            .transpose()?;
        let mut parts: Vec<TruthSeconds> = deps
            .iter()
            .filter_map(|d| d.get(SECONDS))
            .map(parse)
            .collect::<Result<_, _>>()?;
        parts.sort_by_key(|p| p.first);
        let seconds: Vec<f64> = parts.into_iter().flat_map(|p| p.seconds).collect();
        if seconds.len() != frames {
            return Err(JobError::Invalid(format!(
                "the preview truth's seconds cover {} frames, not {frames}",
                seconds.len()
            )));
        }
        Ok(Some(FrameTruth {
            character,
            ground,
            texels,
            seconds,
        }))
    }

    /// Runs a `preview` job: the stills and the animation of the asset
    /// that `assemble` produced, on `renderer`, and `previews.json`
    /// listing them. Their truth comes from the `preview-truth` jobs.
    pub fn preview(
        &self,
        deps: &[&JobOutput],
        renderer: &mut dyn Renderer,
    ) -> Result<JobOutput, JobError> {
        let assembled = find(deps, "asset")?;
        let container = Container::from_bytes(named(assembled, "asset")?)
            .map_err(|e| JobError::Invalid(e.to_string()))?;
        let baked = BakedAsset::read(&container, Some(&self.inputs.character))
            .map_err(|e| JobError::Invalid(e.to_string()))?;
        let (model, surface) = baked
            .preview_model()
            .map_err(|e| JobError::Invalid(e.to_string()))?;
        // A texel model whose fit kept more weights than GPUs hold array
        // layers (its basis compression found nothing to compress): the
        // asset stands, its previews cannot be drawn.
        let layers = crate::method::texel::MAX_TEXTURES;
        if let PreviewModel::Texel(m, _) = model
            && m.model.weight_count() > layers
        {
            return Ok(preview::unavailable(&format!(
                "the texel model takes {} weights, more than the {layers} texture layers GPUs hold: its previews cannot be drawn",
                m.model.weight_count()
            )));
        }
        let frames = self.preview_frames()?;
        let truth = self.stacked_truth(deps, frames.len())?;
        let stills = frames.stills.len();
        let subject = Subject::new(&self.inputs.character, model, surface);
        let mut previews = subject.stills(
            frames.clip,
            &frames.stills,
            truth.as_ref().map(|t| t.select(0..stills)),
            renderer,
        )?;
        if let Some(c) = frames.clip {
            let animation = truth.as_ref().map(|t| t.select(stills..t.frames()));
            previews.push(subject.animation(c, animation, renderer)?);
        }
        if let PreviewModel::Texel(m, atlas) = model {
            previews.extend(super::texel::unseen_previews(
                self, deps, m, atlas, surface, renderer,
            )?);
        }
        let mut out = JobOutput::default();
        let infos: Vec<&PreviewInfo> = previews.iter().map(|p| &p.info).collect();
        let trained = |clip: &str| {
            self.plan
                .train
                .iter()
                .any(|&c| self.inputs.clips[c].name == clip)
        };
        if let Some(pixels) = PixelSummary::of(infos.iter().copied(), trained) {
            out.push(PIXELS, json(&pixels));
        }
        out.push("previews.json", json(&infos));
        for p in previews {
            out.push(&p.info.name, p.png);
        }
        out.timings = assembled.timings;
        Ok(out)
    }
}

/// A `preview-truth` job's character occlusion ([`IndexedBlock`]).
const TRUTH: &str = "preview-truth";
/// A `preview-truth` job's ground occlusion ([`IndexedBlock`]).
const GROUND: &str = "preview-ground";
/// A texel bake's `preview-truth` job's occlusion at the atlas's texels
/// ([`IndexedBlock`]).
const TEXELS: &str = "preview-texels";
/// A `preview-truth` job's seconds per frame ([`TruthSeconds`]).
const SECONDS: &str = "preview-truth.json";

/// The seconds each frame of a `preview-truth` job took to trace.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct TruthSeconds {
    /// The job's first frame.
    first: usize,
    /// Seconds per frame.
    seconds: Vec<f64>,
}

/// Either kind of report, told apart by its method's family.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum BakeReport {
    /// A per-vertex bake's.
    Vertex(Box<Report>),
    /// A cubemap bake's.
    Cubemap(Box<CubemapReport>),
    /// A grid bake's.
    Grid(Box<GridReport>),
}

impl<'de> Deserialize<'de> for BakeReport {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error as _;
        let value = serde_json::Value::deserialize(d)?;
        let method: Method = serde_json::from_value(value["method"].clone())
            .map_err(|e| D::Error::custom(format!("report.method: {e}")))?;
        match method.family() {
            // A texel bake's report is the per-vertex family's, over texels.
            Family::Vertex | Family::Texel => serde_json::from_value(value).map(Self::Vertex),
            Family::Cubemap => serde_json::from_value(value).map(Self::Cubemap),
            Family::Grid => serde_json::from_value(value).map(Self::Grid),
        }
        .map_err(D::Error::custom)
    }
}

impl BakeReport {
    /// The per-vertex report, if it is one.
    pub fn vertex(&self) -> Option<&Report> {
        match self {
            Self::Vertex(r) => Some(r),
            Self::Cubemap(_) | Self::Grid(_) => None,
        }
    }
}

/// Why a published asset cannot serve a use.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AssetUseError {
    /// Its header or sections do not decode.
    #[error("{0}")]
    Unreadable(String),
    /// It was baked for another character: what differs.
    #[error("{0}")]
    Mismatch(String),
    /// Its method holds no such data: what it holds instead.
    #[error("{0}")]
    Unsupported(String),
}

/// A published asset's model, read from its container and, given the
/// character it was baked for, checked against it: what previews,
/// `aobake eval`, `export` and `preview` start from.
#[derive(Debug)]
pub struct BakedAsset {
    /// The bake's parameters, from the asset's header.
    pub params: BakeParams,
    /// sha256 of the character it was baked for.
    pub character: String,
    model: AssetModel,
}

#[derive(Debug)]
enum AssetModel {
    Vertex(Box<crate::method::vertex::Model>),
    /// A texel model; whether it was read with its character; and its
    /// atlas's texels as surface points, found from its UVs when the
    /// previews first ask (evaluating and exporting need none).
    Texel(
        Box<crate::method::texel::TexelModel>,
        bool,
        std::sync::OnceLock<Result<crate::method::texel::atlas::TexelAtlas, String>>,
    ),
    /// The model and its clip's name.
    Cubemap(crate::method::cubemap::model::CubemapModel, String),
    /// The grids and, with the character, each vertex's part (`u32::MAX`
    /// for none) and the truth's reach.
    Grid(
        crate::method::grid::model::GridModel,
        Option<(Vec<u32>, f32)>,
    ),
}

impl BakedAsset {
    /// Reads `container`'s model; with `character`, checks that the asset
    /// was baked for it and prepares what its vertices need.
    pub fn read(
        container: &Container,
        character: Option<&crate::Character>,
    ) -> Result<Self, AssetUseError> {
        use crate::method::{cubemap::model::CubemapModel, grid, vertex::Model};
        let unreadable = |e: &dyn std::fmt::Display| AssetUseError::Unreadable(e.to_string());
        let params = |v: &serde_json::Value| {
            BakeParams::from_canonical(v).map_err(|e| {
                AssetUseError::Unreadable(format!("the asset's parameters are unreadable: {e}"))
            })
        };
        Ok(match container.method.family() {
            Family::Vertex => {
                let (model, header) =
                    Model::from_container(container).map_err(|e| unreadable(&e))?;
                if let Some(c) = character {
                    crate::method::vertex::check_character(&model, c).map_err(|e| {
                        AssetUseError::Mismatch(format!("{e} (character {})", header.character))
                    })?;
                }
                Self {
                    params: params(&header.params)?,
                    character: header.character,
                    model: AssetModel::Vertex(Box::new(model)),
                }
            }
            Family::Texel => {
                let (model, header) =
                    super::texel::read(container, character).map_err(|r| match r {
                        super::texel::Refusal::Unreadable(e) => AssetUseError::Unreadable(e),
                        super::texel::Refusal::Mismatch(e) => AssetUseError::Mismatch(e),
                    })?;
                Self {
                    params: params(&header.params)?,
                    character: header.character,
                    model: AssetModel::Texel(
                        Box::new(model),
                        character.is_some(),
                        std::sync::OnceLock::new(),
                    ),
                }
            }
            Family::Cubemap => {
                let (model, header) =
                    CubemapModel::from_container(container).map_err(|e| unreadable(&e))?;
                Self {
                    params: params(&header.params)?,
                    character: header.character,
                    model: AssetModel::Cubemap(model, header.clip),
                }
            }
            Family::Grid => {
                let (model, header) = grid::model::GridModel::from_container(container)
                    .map_err(|e| unreadable(&e))?;
                let params = params(&header.params)?;
                let fitted = match character {
                    Some(c) => {
                        model
                            .check_palette(c.joints.len())
                            .map_err(|e| AssetUseError::Mismatch(e.to_string()))?;
                        let found = grid::parts::parts(c, params.grid.parts)
                            .map_err(|e| AssetUseError::Mismatch(e.to_string()))?;
                        if found.len() != model.parts.len()
                            || found
                                .iter()
                                .zip(&model.parts)
                                .any(|(a, b)| a.joint != b.joint)
                        {
                            return Err(AssetUseError::Mismatch(format!(
                                "its parts are not the character's (character {})",
                                header.character
                            )));
                        }
                        let owners = grid::parts::owner_indices(&found, c.vertex_count());
                        Some((owners, params.grid.distance(c, &found)))
                    }
                    None => None,
                };
                Self {
                    params,
                    character: header.character,
                    model: AssetModel::Grid(model, fitted),
                }
            }
        })
    }

    /// Whether it is a texel asset (its stills measure its own atlas's
    /// texel floor).
    pub fn is_texel(&self) -> bool {
        matches!(self.model, AssetModel::Texel(..))
    }

    /// The clip a cubemap asset was baked over (it darkens the world as
    /// that clip plays); `None` for the other families, which follow any
    /// pose.
    pub fn clip(&self) -> Option<&str> {
        match &self.model {
            AssetModel::Cubemap(_, clip) => Some(clip),
            AssetModel::Vertex(_) | AssetModel::Grid(..) | AssetModel::Texel(..) => None,
        }
    }

    /// The model to preview and the tracing parameters of its ground
    /// truth (a grid's as its evaluation traces it; a cubemap's ground
    /// truth is Eq. 3.1, what it stores, in the model itself).
    pub fn preview_model(
        &self,
    ) -> Result<(PreviewModel<'_>, crate::trace::SurfaceParams), AssetUseError> {
        let surface = self.params.held_out_surface();
        Ok(match &self.model {
            AssetModel::Vertex(m) => (PreviewModel::Vertex(m), surface),
            AssetModel::Texel(m, with_character, atlas) => {
                if !with_character {
                    return Err(not_fitted());
                }
                let atlas = atlas
                    .get_or_init(|| {
                        crate::method::texel::atlas::TexelAtlas::from_layout(&m.atlas)
                            .map_err(|e| e.to_string())
                    })
                    .as_ref()
                    .map_err(|e| AssetUseError::Unreadable(e.clone()))?;
                (PreviewModel::Texel(m, atlas), surface)
            }
            AssetModel::Cubemap(m, _) => (
                PreviewModel::Cubemap(m, self.params.cubemap_truth(&m.layout.spheroid)),
                surface,
            ),
            AssetModel::Grid(m, fitted) => {
                let (owners, distance) = fitted.as_ref().ok_or_else(not_fitted)?;
                (
                    PreviewModel::Grid(m, owners),
                    self.params.grid.truth(*distance, surface.seed),
                )
            }
        })
    }

    /// Occlusion per vertex of `character` posed (`pose`, skinned into
    /// `mesh`), as an engine evaluates the asset at run time.
    pub fn vertex_ao(
        &self,
        character: &crate::Character,
        pose: &crate::Pose,
        mesh: &crate::PosedMesh,
    ) -> Result<Vec<f32>, AssetUseError> {
        use crate::method::grid::base::Receiver;
        match &self.model {
            AssetModel::Vertex(m) => Ok(m.evaluate(&character.skeleton, &pose.locals)),
            AssetModel::Texel(m, ..) => Ok(super::texel::vertex_ao(m, character, pose)),
            AssetModel::Cubemap(..) => Err(AssetUseError::Unsupported(
                "it holds the occlusion cast into space, not per-vertex AO; `aobake preview` renders it on the ground and `aobake export --exr` writes its faces".into(),
            )),
            // Each vertex a receiver on its own part, shaded by every
            // part's grid (on the static base, when the asset has one).
            AssetModel::Grid(m, fitted) => {
                let (owners, _) = fitted.as_ref().ok_or_else(not_fitted)?;
                let poses = m.poses(&character.joint_matrices(pose));
                Ok(mesh
                    .positions
                    .iter()
                    .zip(&mesh.normals)
                    .zip(owners)
                    .enumerate()
                    .map(|(i, ((&p, &n), &owner))| {
                        m.ao(&poses, p, n, Receiver::vertex(i, owner))
                    })
                    .collect())
            }
        }
    }

    /// The asset's data as float images: a cubemap's decoded faces, one
    /// image per clip time and shell (the six faces side by side, +x −x
    /// +y −y +z −z, in one channel `Y`); a grid's parts, one image per
    /// part (its z-slices top to bottom, +y up, +x right; `ao_grid`, and
    /// with cones `axis.x`, `axis.y`, `axis.z` in the part's bind space)
    /// and, with a static ground (a grid's base, a cubemap's), its texture
    /// (`ground-offsets.exr`, `offset`), each value exactly what the run
    /// time reads.
    pub fn images(&self, times: &[f32]) -> Result<Vec<FloatImage>, AssetUseError> {
        match &self.model {
            AssetModel::Vertex(_) => Err(AssetUseError::Unsupported(
                "per-vertex AO has no image to export".into(),
            )),
            AssetModel::Texel(m, ..) => super::texel::images(m).map_err(AssetUseError::Unsupported),
            AssetModel::Cubemap(m, clip) => {
                let mut images = super::cubemap::face_strips(m, clip, times);
                images.extend(m.ground.as_ref().map(ground_offsets));
                Ok(images)
            }
            AssetModel::Grid(m, _) => Ok(m
                .parts
                .iter()
                .enumerate()
                .map(|(k, part)| super::grid::part_slices(k, part))
                .chain(m.base.as_ref().map(|b| ground_offsets(&b.ground)))
                .collect()),
        }
    }
}

fn not_fitted() -> AssetUseError {
    AssetUseError::Mismatch("the asset was read without its character".into())
}

/// A static ground texture (a grid's base, a cubemap's ground) as an
/// image, `ground-offsets.exr`: texel (x, z) at pixel (x, z), so rows run
/// along +z from the square's `min` corner; the channel `offset`, exactly
/// the value the run time reads.
fn ground_offsets(ground: &crate::method::ground::GroundBase) -> FloatImage {
    let g = &ground.square;
    FloatImage {
        file: "ground-offsets.exr".into(),
        layer: "ground".into(),
        comment: format!(
            "aobake static ground: offsets, texel (x, z) at pixel (x, z) of a {size} x {size} square from ({}, {}) at height {}; ao = clamp({} x model + offset, 0, 1)",
            g.min[0],
            g.min[1],
            g.height,
            ground.gain,
            size = g.size
        ),
        width: g.resolution,
        height: g.resolution,
        channels: vec![("offset".to_owned(), ground.offsets.clone())],
    }
}
