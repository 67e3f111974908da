//! The planner: a bake as a graph of jobs (DESIGN §1.3). The server stores
//! the graph and hands its jobs to workers as their dependencies finish;
//! the in-process runner walks it in order. Jobs are listed so that every
//! job comes after its dependencies.

use super::JobSpec;

/// How a bake is cut into jobs. Cutting never changes the result: `sample`
/// batches stack byte for byte into the whole.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GraphOptions {
    /// Fewest poses per `sample` job (frames per `preview-truth` job).
    pub sample_batch: usize,
    /// Rays a `sample` or `preview-truth` job should trace: a batch takes
    /// as many poses as make about this many, [`Self::sample_batch`] at
    /// least (0: exactly that many).
    pub sample_rays: u64,
    /// Grid layers per `slab` job.
    pub slab_layers: usize,
    /// Whether the graph ends with a `preview` job (it needs a GPU
    /// renderer; benches and core's tests leave it out).
    pub previews: bool,
}

impl Default for GraphOptions {
    /// `sample` jobs of about 2²³ rays (about a second on one core) and
    /// four poses at least: long enough that the queue's cost per job (a
    /// lease, the outputs' upload, a few statements; about 15 ms) stays
    /// near 1 % of the work, short enough that a lost job costs little and
    /// a bake's progress moves steadily. Eight layers per `slab` job (four
    /// slabs for a grid of 32). Previews included.
    fn default() -> Self {
        Self {
            sample_batch: 4,
            sample_rays: 1 << 23,
            slab_layers: 8,
            previews: true,
        }
    }
}

impl GraphOptions {
    /// Poses per batch when each traces `rays_per_pose` rays.
    pub fn batch(&self, rays_per_pose: u64) -> usize {
        let by_rays = self.sample_rays / rays_per_pose.max(1);
        self.sample_batch
            .max(usize::try_from(by_rays).unwrap_or(usize::MAX))
            .max(1)
    }
}

/// One job of the graph and the indices of the jobs it needs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlannedJob {
    /// What it computes.
    pub spec: JobSpec,
    /// Indices (into [`JobGraph::jobs`]) of its dependencies, all smaller
    /// than its own.
    pub deps: Vec<usize>,
}

/// A bake's jobs in dependency order.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct JobGraph {
    /// The jobs.
    pub jobs: Vec<PlannedJob>,
}

impl JobGraph {
    /// Units of progress of the whole bake.
    pub fn total_work(&self) -> u64 {
        self.jobs.iter().map(|j| j.spec.work()).sum()
    }
}

impl JobGraph {
    /// The stages after a volume method's tracing jobs (`producers`):
    /// the previews' `truth` jobs beside them, `assemble` after the
    /// producers, `evaluate` after `assemble` and them (it judges the
    /// encoding against the raw fields), and, with `previews`, `preview`
    /// after `assemble`, `evaluate` and the truth jobs.
    pub(super) fn assemble_evaluate_preview(
        producers: Vec<PlannedJob>,
        truth: Vec<PlannedJob>,
        previews: bool,
    ) -> Self {
        let mut jobs = producers;
        let producers: Vec<usize> = (0..jobs.len()).collect();
        let truth: Vec<usize> = truth
            .into_iter()
            .map(|job| {
                jobs.push(job);
                jobs.len() - 1
            })
            .collect();
        jobs.push(PlannedJob {
            spec: JobSpec::Assemble,
            deps: producers.clone(),
        });
        let assemble = jobs.len() - 1;
        let mut deps = vec![assemble];
        deps.extend(producers);
        jobs.push(PlannedJob {
            spec: JobSpec::Evaluate,
            deps,
        });
        if previews {
            let evaluate = jobs.len() - 1;
            let mut deps = vec![assemble, evaluate];
            deps.extend(truth);
            jobs.push(PlannedJob {
                spec: JobSpec::Preview,
                deps,
            });
        }
        Self { jobs }
    }
}
