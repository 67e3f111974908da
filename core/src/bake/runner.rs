//! The in-process runner: a whole job graph in this process, in order.
//! `aobake bake`, the benches and the tests use it; workers run the same
//! job functions one at a time, so the stage order is written once, in
//! [`Bake::graph`].

use std::collections::HashMap;

use super::family::BakeReport;

use super::{
    Bake, Checkpoint, GraphOptions, JobError, JobGraph, JobOutput, JobSink, JobSpec, NoSink,
    PlannedJob, Stop,
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
    /// The previews' stills judged per pixel, pooled per clip
    /// (`pixels.json`), when the previews judged any.
    pub pixels: Option<super::screen_space::PixelSummary>,
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
        let pixels = match get(super::screen_space::PIXELS) {
            Ok(bytes) => Some(
                serde_json::from_slice(&bytes)
                    .map_err(|e| JobError::Invalid(format!("pixels.json: {e}")))?,
            ),
            Err(_) => None,
        };
        Ok(Self {
            pixels,
            asset: get("asset")?,
            report: serde_json::from_slice(&report_json)
                .map_err(|e| JobError::Invalid(format!("report.json: {e}")))?,
            report_json,
            plot: get("plot.png")?,
            previews,
        })
    }
}

/// What [`run_graph`] tells its caller about a job.
#[derive(Debug, Clone, Copy)]
pub enum JobEvent<'o> {
    /// `done` of the job's `total` units of work are done (a `sample` job
    /// after each pose, a fit after each step).
    Progress {
        /// Units done.
        done: u64,
        /// Units in all.
        total: u64,
    },
    /// The job finished with this output.
    Done(&'o JobOutput),
}

/// Runs every job of `graph` in order (each job spreads its own work over
/// the threads). Jobs whose spec is in `known` are not run again: their
/// output is taken from there (a bench that fits many variants to one
/// traced set passes the `sample` outputs). A `preview` job needs
/// `renderer`. `on_event` hears each job's progress and its end, with
/// the job's index.
pub fn run_graph(
    bake: &Bake<'_>,
    graph: &JobGraph,
    known: &HashMap<JobSpec, JobOutput>,
    mut renderer: Option<&mut dyn Renderer>,
    on_event: &mut dyn FnMut(usize, &PlannedJob, JobEvent<'_>),
) -> Result<Vec<JobOutput>, JobError> {
    let mut outputs: Vec<JobOutput> = Vec::with_capacity(graph.jobs.len());
    for (i, job) in graph.jobs.iter().enumerate() {
        let out = match known.get(&job.spec) {
            Some(o) => o.clone(),
            None => {
                // What the job reads of each dependency, as a worker
                // fetches it (a copy only where something is left out).
                let deps: Vec<std::borrow::Cow<'_, JobOutput>> = job
                    .deps
                    .iter()
                    .map(|&d| {
                        let dep = &outputs[d];
                        if dep.outputs.iter().all(|o| job.spec.reads(&o.name)) {
                            std::borrow::Cow::Borrowed(dep)
                        } else {
                            std::borrow::Cow::Owned(JobOutput {
                                timings: dep.timings,
                                outputs: dep
                                    .outputs
                                    .iter()
                                    .filter(|o| job.spec.reads(&o.name))
                                    .cloned()
                                    .collect(),
                            })
                        }
                    })
                    .collect();
                let deps: Vec<&JobOutput> = deps.iter().map(AsRef::as_ref).collect();
                match (&job.spec, renderer.as_deref_mut()) {
                    (JobSpec::Preview, Some(r)) => bake.preview(&deps, r)?,
                    (spec, _) => {
                        let mut sink = Reporting {
                            report: &mut |done, total| {
                                on_event(i, job, JobEvent::Progress { done, total });
                            },
                        };
                        bake.run_job(spec, &deps, None, &mut sink)?
                    }
                }
            }
        };
        on_event(i, job, JobEvent::Done(&out));
        outputs.push(out);
    }
    Ok(outputs)
}

/// The in-process runner's sink: no checkpoints (nothing resumes), progress
/// passed on.
struct Reporting<'a> {
    report: &'a mut dyn FnMut(u64, u64),
}

impl JobSink for Reporting<'_> {
    fn checkpoint(&mut self, checkpoint: Checkpoint) -> Result<(), Stop> {
        NoSink.checkpoint(checkpoint)
    }

    fn progress(&mut self, done: u64, total: u64) {
        (self.report)(done, total);
    }

    fn save_part(&mut self, bytes: &[u8]) -> Option<String> {
        NoSink.save_part(bytes)
    }

    fn load_part(&mut self, digest: &str) -> Result<Vec<u8>, JobError> {
        NoSink.load_part(digest)
    }
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
