//! `aobake bench clusters` and `aobake bench linear`: parameter sweeps of
//! the vertex methods on one character. The reference and held-out AO are
//! traced once; every setting is then fitted to the same reference poses
//! and judged on the same held-out clip frames.
//!
//! * `clusters` is Kirk & Arikan's Table 1 (pose clusters m × dimensions n
//!   × vertex clusters), beside vertex-linear and the static average.
//! * `linear` shows the effect of vertex-linear's ridge weight and
//!   sparsification threshold on error, size and run-time cost.

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::Instant;

use aobake_core::{
    Limits,
    bake::vertex::Report,
    bake::{
        Bake, BakeInputs, BakeParams, Baked, GraphOptions, JobOutput, JobSpec, ReferenceSource,
    },
    method::Method,
};

use crate::cli::bake::{load_inputs, run_with_progress};
use crate::cli::trace::with_threads;

/// What both sweeps take.
#[derive(Debug, clap::Args)]
pub(super) struct Common {
    /// The character.
    file: PathBuf,
    /// glTF files with more clips for it.
    #[arg(long, num_args = 1..)]
    clips: Vec<PathBuf>,
    /// Reference poses.
    #[arg(long, default_value_t = 256)]
    poses: usize,
    /// Rays per vertex and pose.
    #[arg(long, default_value_t = 128)]
    samples: u32,
    /// Fit on these clips only (repeat). Default: all.
    #[arg(long = "train-clip", value_name = "NAME")]
    train_clips: Vec<String>,
    /// Test on every frame of these clips (repeat). Default: all.
    #[arg(long = "test-clip", value_name = "NAME")]
    test_clips: Vec<String>,
    /// Seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Worker threads for tracing.
    #[arg(long)]
    threads: Option<usize>,
}

/// Arguments of `aobake bench clusters`.
#[derive(Debug, clap::Args)]
pub(super) struct ClusterArgs {
    #[command(flatten)]
    common: Common,
    /// Pose cluster counts m to try.
    #[arg(long, value_delimiter = ',', default_value = "5,10,15")]
    pose_clusters: Vec<usize>,
    /// PCA dimensions n to try.
    #[arg(long, value_delimiter = ',', default_value = "5,10,15")]
    dimensions: Vec<usize>,
    /// Vertex-cluster levels to try, as fractions of the vertex count
    /// (0: none, one coefficient vector per vertex).
    #[arg(long, value_delimiter = ',', default_value = "0,0.25,0.05")]
    vertex_fractions: Vec<f64>,
}

/// Arguments of `aobake bench linear`.
#[derive(Debug, clap::Args)]
pub(super) struct LinearArgs {
    #[command(flatten)]
    common: Common,
    /// Ridge weights to try.
    #[arg(long, value_delimiter = ',', default_value = "0,0.001,0.01,0.1")]
    ridges: Vec<f64>,
    /// Sparsification thresholds to try (with the default ridge).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "0,0.001,0.002,0.005,0.01"
    )]
    thresholds: Vec<f32>,
}

/// Reference and held-out AO, traced once: the `sample` jobs' outputs,
/// which every setting's `fit` and `evaluate` jobs reuse.
///
/// The tables compare per-vertex settings; a cubemap bake's report has
/// its own table (`aobake bake` prints it).
struct Traced<'a> {
    inputs: &'a BakeInputs,
    params: BakeParams,
    threads: Option<usize>,
    samples: HashMap<JobSpec, JobOutput>,
    joint_angles: usize,
    /// The first setting's report (for the baseline's row).
    first: Report,
}

impl<'a> Traced<'a> {
    fn new(inputs: &'a BakeInputs, common: &Common, params: BakeParams) -> anyhow::Result<Self> {
        let bake = Bake::new(inputs, params.clone())?;
        let started = Instant::now();
        let outputs = with_threads(common.threads, || {
            run_with_progress(&bake, &HashMap::new(), None)
        })??;
        let graph = bake.graph(GraphOptions {
            previews: false,
            ..GraphOptions::default()
        });
        let samples = graph
            .jobs
            .iter()
            .zip(&outputs)
            .filter(|(j, _)| j.spec.kind() == "sample")
            .map(|(j, o)| (j.spec.clone(), o.clone()))
            .collect();
        let first = vertex_report(Baked::from_outputs(&outputs)?)?;
        println!(
            "{}: {} vertices, {} reference poses ({:?}), {} held-out clip frames, {} rays per vertex; baking took {:.1} s",
            common.file.display(),
            inputs.character.vertex_count(),
            params.poses,
            params.reference,
            first.evaluation.training_clip_frames.model.frames,
            params.samples,
            started.elapsed().as_secs_f64()
        );
        println!();
        Ok(Self {
            inputs,
            threads: common.threads,
            joint_angles: bake.plan.joint_angles.len(),
            params,
            samples,
            first,
        })
    }

    /// Fits `params` to the traced poses and prints a table row: the
    /// labels, then mean absolute error, PSNR, size, multiply-adds and fit
    /// time.
    fn row(&self, labels: &[String], params: &BakeParams) -> anyhow::Result<()> {
        let bake = Bake::new(self.inputs, params.clone())?;
        let outputs = with_threads(self.threads, || {
            run_with_progress(&bake, &self.samples, None)
        })??;
        let r = vertex_report(Baked::from_outputs(&outputs)?)?;
        let c = &r.evaluation.training_clip_frames.model.mean;
        println!(
            "| {} | {:.4} | {:.2} | {} | {:.1} | {:.2} |",
            labels.join(" | "),
            c.mae,
            c.psnr_db,
            r.sizes.model_bytes,
            r.evaluation.multiply_adds_per_vertex,
            r.timings.fit_s
        );
        Ok(())
    }

    /// The static average's row.
    fn baseline_row(&self, blank: usize) {
        let c = &self.first.evaluation.training_clip_frames.baseline.mean;
        println!(
            "| static average |{} {:.4} | {:.2} | {} | 1 | - |",
            " - |".repeat(blank),
            c.mae,
            c.psnr_db,
            self.first.sizes.baseline_bytes
        );
    }
}

fn params(common: &Common, method: Method) -> BakeParams {
    let mut p = BakeParams::new(method);
    p.poses = common.poses;
    p.samples = common.samples;
    p.seed = common.seed;
    p.train_clips.clone_from(&common.train_clips);
    p.test_clips.clone_from(&common.test_clips);
    p.eval_poses = 0;
    p
}

pub(super) fn clusters(args: &ClusterArgs) -> anyhow::Result<()> {
    let inputs = load_inputs(&args.common.file, &args.common.clips, &Limits::default())?;
    let t = Traced::new(
        &inputs,
        &args.common,
        params(&args.common, Method::VertexClustered),
    )?;
    let v = inputs.character.vertex_count();
    println!(
        "| pose clusters m | dimensions n | vertex clusters | mean abs error | PSNR (dB) | size (bytes) | multiply-adds / vertex | fit (s) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for &m in &args.pose_clusters {
        for &n in &args.dimensions {
            for &f in &args.vertex_fractions {
                let mut p = t.params.clone();
                p.clustered.pose_clusters = m;
                p.clustered.dimensions = n;
                p.clustered.vertex_clusters = (f * v as f64).round() as usize;
                let vc = match p.clustered.vertex_clusters {
                    0 => "none".to_owned(),
                    c => c.to_string(),
                };
                t.row(&[m.to_string(), n.to_string(), vc], &p)?;
            }
        }
    }
    let mut linear = t.params.clone();
    linear.method = Method::VertexLinear;
    t.row(
        &[
            "vertex-linear".into(),
            format!("{} angles", t.joint_angles),
            "-".into(),
        ],
        &linear,
    )?;
    t.baseline_row(2);
    Ok(())
}

pub(super) fn linear(args: &LinearArgs) -> anyhow::Result<()> {
    let inputs = load_inputs(&args.common.file, &args.common.clips, &Limits::default())?;
    let mut p = params(&args.common, Method::VertexLinear);
    p.reference = ReferenceSource::Mixed;
    let t = Traced::new(&inputs, &args.common, p)?;
    println!(
        "| ridge | threshold | mean abs error | PSNR (dB) | size (bytes) | multiply-adds / vertex | fit (s) |"
    );
    println!("|---|---|---|---|---|---|---|");
    for &ridge in &args.ridges {
        let mut p = t.params.clone();
        p.linear.ridge = ridge;
        t.row(&[ridge.to_string(), "0".into()], &p)?;
    }
    for &threshold in args.thresholds.iter().filter(|&&x| x > 0.0) {
        let mut p = t.params.clone();
        p.linear.threshold = threshold;
        t.row(&[p.linear.ridge.to_string(), threshold.to_string()], &p)?;
    }
    t.baseline_row(1);
    Ok(())
}

fn vertex_report(baked: Baked) -> anyhow::Result<Report> {
    match baked.report {
        aobake_core::bake::BakeReport::Vertex(r) => Ok(*r),
        _ => anyhow::bail!("the tables compare per-vertex methods"),
    }
}
