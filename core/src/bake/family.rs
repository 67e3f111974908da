//! What each method family brings to a bake, and the one exhaustive
//! `match` per concern that hands it over: the checks of a bake's
//! parameters against its inputs, its work, its job graph, its jobs, its
//! previews' model and its report. The families' bake files (`vertex.rs`,
//! `cubemap.rs`, `grid.rs`) sit below this file and never import it; a new
//! family adds a file beside them and an arm to each `match` here, and
//! the compiler lists every arm it still lacks (docs/methods/adding.md).

use serde::{Deserialize, Serialize};

use crate::method::{Family, Method};

use super::{
    Bake, BakeError, BakeInputs, BakeParams, Checkpoint, GraphOptions, JobError, JobGraph,
    JobOutput, JobSink, JobSpec, Plan, PoseSet,
    cubemap::{CubemapReport, decode_cubemap},
    grid::{GridReport, decode_grid},
    jobs::{find, json, named},
    preview::{PreviewInfo, PreviewModel, Renderer, STILL_FRACTIONS, Subject, preview_clip},
    vertex::{Report, decode},
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
            Family::Vertex => {}
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
            Family::Vertex | Family::Cubemap => 0,
        };
        p.work(self.inputs.character.vertex_count(), frames, parts)
    }

    /// The job graph of this bake.
    pub fn graph(&self, options: GraphOptions) -> JobGraph {
        match self.plan.params.method.family() {
            Family::Vertex => self.vertex_graph(options),
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
        match self.plan.params.method.family() {
            Family::Vertex => self.vertex_job(spec, deps, resume, sink),
            Family::Cubemap => self.cubemap_job(spec, deps, resume, sink),
            Family::Grid => self.grid_job(spec, deps, resume, sink),
        }
    }

    /// Runs a `preview` job: the stills and the animation of the asset
    /// that `assemble` produced, on `renderer`, and `previews.json`
    /// listing them.
    pub fn preview(
        &self,
        deps: &[&JobOutput],
        renderer: &mut dyn Renderer,
    ) -> Result<JobOutput, JobError> {
        let assembled = find(deps, "asset")?;
        let asset = named(assembled, "asset")?;
        let clips = &self.inputs.clips;
        let vertex_model;
        let cubemap_model;
        let grid_model;
        let owners: Vec<u32>;
        let mut grid_truth = None;
        let (model, clip) = match self.plan.params.method.family() {
            Family::Cubemap => {
                cubemap_model = decode_cubemap(asset)?;
                // The ground's truth is what the cubemap stores: Eq. 3.1.
                let kroon = self
                    .plan
                    .params
                    .cubemap_truth(&cubemap_model.layout.spheroid);
                (
                    PreviewModel::Cubemap(&cubemap_model, kroon),
                    Some(&clips[self.cubemap_clip()?]),
                )
            }
            Family::Grid => {
                grid_model = decode_grid(asset)?;
                let parts = self.grid_parts()?;
                owners = crate::method::grid::parts::owner_indices(
                    &parts,
                    self.inputs.character.vertex_count(),
                );
                // The grids' truth is traced as their evaluation traces it.
                grid_truth = Some(self.plan.params.grid.truth(
                    self.grid_distance(&parts),
                    self.plan.params.held_out_surface().seed,
                ));
                (
                    PreviewModel::Grid(&grid_model, &owners),
                    preview_clip(clips, &self.plan.test).map(|i| &clips[i]),
                )
            }
            Family::Vertex => {
                vertex_model = decode(asset)?;
                (
                    PreviewModel::Vertex(&vertex_model),
                    preview_clip(clips, &self.plan.test).map(|i| &clips[i]),
                )
            }
        };
        let surface = grid_truth.unwrap_or_else(|| self.plan.params.held_out_surface());
        let subject = Subject {
            character: &self.inputs.character,
            model,
            surface,
        };
        let times: Vec<f32> = clip.map_or_else(Vec::new, |c| {
            STILL_FRACTIONS.iter().map(|f| f * c.duration).collect()
        });
        let mut previews = subject.stills(clip, &times, renderer)?;
        if let Some(c) = clip {
            previews.push(subject.animation(c, renderer)?);
        }
        let mut out = JobOutput::default();
        let infos: Vec<&PreviewInfo> = previews.iter().map(|p| &p.info).collect();
        out.push("previews.json", json(&infos));
        for p in previews {
            out.push(&p.info.name, p.png);
        }
        out.timings = assembled.timings;
        Ok(out)
    }
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
            Family::Vertex => serde_json::from_value(value).map(Self::Vertex),
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
