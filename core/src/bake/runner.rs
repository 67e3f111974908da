//! The in-process runner: a whole job graph in this process, in order.
//! `aobake bake`, the benches and the tests use it; workers run the same
//! job functions one at a time, so the stage order is written once, in
//! [`Bake::graph`].

use std::collections::HashMap;

use crate::asset::report::BakeReport;

use super::{
    Bake, GraphOptions, JobError, JobGraph, JobOutput, JobSpec, NoSink, PlannedJob,
    preview::{PreviewInfo, Renderer},
};

/// What a finished bake publishes.
#[derive(Debug, Clone)]
pub struct Baked {
    /// The asset bytes.
    pub asset: Vec<u8>,
    /// The report.
    pub report: BakeReport,
    /// The report as the JSON document the service serves.
    pub report_json: Vec<u8>,
    /// The PSNR-per-frame plot (PNG).
    pub plot: Vec<u8>,
    /// The previews (PNG or APNG) and how each was made, when the graph
    /// had a `preview` job.
    pub previews: Vec<(PreviewInfo, Vec<u8>)>,
}

impl Baked {
    /// Collects the published outputs from the outputs of a graph's jobs.
    pub fn from_outputs(outputs: &[JobOutput]) -> Result<Self, JobError> {
        let get = |name: &str| {
            outputs
                .iter()
                .find_map(|o| o.get(name))
                .map(<[u8]>::to_vec)
                .ok_or_else(|| JobError::Invalid(format!("the bake produced no {name}")))
        };
        let report_json = get("report.json")?;
        let mut previews = Vec::new();
        if let Ok(list) = get("previews.json") {
            let infos: Vec<PreviewInfo> = serde_json::from_slice(&list)
                .map_err(|e| JobError::Invalid(format!("previews.json: {e}")))?;
            for info in infos {
                let png = get(&info.name)?;
                previews.push((info, png));
            }
        }
        Ok(Self {
            asset: get("asset")?,
            report: serde_json::from_slice(&report_json)
                .map_err(|e| JobError::Invalid(format!("report.json: {e}")))?,
            report_json,
            plot: get("plot.png")?,
            previews,
        })
    }
}

/// Runs every job of `graph` in order. Jobs whose spec is in `known` are
/// not run again: their output is taken from there (a bench that fits many
/// variants to one traced set passes the `sample` outputs). A `preview`
/// job needs `renderer`. `on_done` is called after each job with its
/// index.
pub fn run_graph(
    bake: &Bake<'_>,
    graph: &JobGraph,
    known: &HashMap<JobSpec, JobOutput>,
    mut renderer: Option<&mut dyn Renderer>,
    on_done: &mut dyn FnMut(usize, &PlannedJob, &JobOutput),
) -> Result<Vec<JobOutput>, JobError> {
    let mut outputs: Vec<JobOutput> = Vec::with_capacity(graph.jobs.len());
    for (i, job) in graph.jobs.iter().enumerate() {
        let out = match known.get(&job.spec) {
            Some(o) => o.clone(),
            None => {
                let deps: Vec<&JobOutput> = job.deps.iter().map(|&d| &outputs[d]).collect();
                match (&job.spec, renderer.as_deref_mut()) {
                    (JobSpec::Preview, Some(r)) => bake.preview(&deps, r)?,
                    (spec, _) => bake.run_job(spec, &deps, None, &mut NoSink)?,
                }
            }
        };
        on_done(i, job, &out);
        outputs.push(out);
    }
    Ok(outputs)
}

/// A whole bake in this process with the default cutting; previews when
/// a renderer is given.
pub fn bake_in_process(
    bake: &Bake<'_>,
    renderer: Option<&mut dyn Renderer>,
) -> Result<Baked, JobError> {
    let graph = bake.graph(GraphOptions {
        previews: renderer.is_some(),
        ..GraphOptions::default()
    });
    let outputs = run_graph(bake, &graph, &HashMap::new(), renderer, &mut |_, _, _| {})?;
    Baked::from_outputs(&outputs)
}
