//! The in-process runner: a whole job graph in this process, in order.
//! `aobake bake`, the benches and the tests use it; workers run the same
//! job functions one at a time, so the stage order is written once, in
//! [`Bake::graph`].

use std::collections::HashMap;

use crate::asset::report::Report;

use super::{Bake, GraphOptions, JobError, JobGraph, JobOutput, JobSpec, NoSink, PlannedJob};

/// What a finished bake publishes.
#[derive(Debug, Clone)]
pub struct Baked {
    /// The asset bytes.
    pub asset: Vec<u8>,
    /// The report.
    pub report: Report,
    /// The report as the JSON document the service serves.
    pub report_json: Vec<u8>,
    /// The PSNR-per-frame plot (PNG).
    pub plot: Vec<u8>,
}

impl Baked {
    /// Reads the published outputs from the last job's output.
    pub fn from_output(out: &JobOutput) -> Result<Self, JobError> {
        let get = |name: &str| {
            out.get(name)
                .map(<[u8]>::to_vec)
                .ok_or_else(|| JobError::Invalid(format!("the bake produced no {name}")))
        };
        let report_json = get("report.json")?;
        Ok(Self {
            asset: get("asset")?,
            report: serde_json::from_slice(&report_json)
                .map_err(|e| JobError::Invalid(format!("report.json: {e}")))?,
            report_json,
            plot: get("plot.png")?,
        })
    }
}

/// Runs every job of `graph` in order. Jobs whose spec is in `known` are
/// not run again: their output is taken from there (a bench that fits many
/// variants to one traced set passes the `sample` outputs). `on_done` is
/// called after each job with its index.
pub fn run_graph(
    bake: &Bake<'_>,
    graph: &JobGraph,
    known: &HashMap<JobSpec, JobOutput>,
    on_done: &mut dyn FnMut(usize, &PlannedJob, &JobOutput),
) -> Result<Vec<JobOutput>, JobError> {
    let mut outputs: Vec<JobOutput> = Vec::with_capacity(graph.jobs.len());
    for (i, job) in graph.jobs.iter().enumerate() {
        let out = match known.get(&job.spec) {
            Some(o) => o.clone(),
            None => {
                let deps: Vec<&JobOutput> = job.deps.iter().map(|&d| &outputs[d]).collect();
                bake.run_job(&job.spec, &deps, None, &mut NoSink)?
            }
        };
        on_done(i, job, &out);
        outputs.push(out);
    }
    Ok(outputs)
}

/// A whole bake in this process with the default cutting.
pub fn bake_in_process(bake: &Bake<'_>) -> Result<Baked, JobError> {
    let graph = bake.graph(GraphOptions::default());
    let outputs = run_graph(bake, &graph, &HashMap::new(), &mut |_, _, _| {})?;
    Baked::from_output(outputs.last().expect("a graph has jobs"))
}
