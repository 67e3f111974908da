//! `aobake bench clusters`: Kirk & Arikan's Table 1 on our data. The
//! reference and held-out AO are traced once; every (pose clusters m,
//! dimensions n, vertex clusters) combination is then fitted and judged on
//! the same held-out clip frames, beside vertex-linear and the static
//! average fitted to the same poses.

use std::path::PathBuf;
use std::time::Instant;

use aobake_core::{
    Limits, Pose,
    asset::Method,
    bake::{BakeParams, Plan},
    metrics::{Errors, FrameError},
    model::StaticAverage,
};

use super::bake::{load_inputs, trace_all};
use super::trace::with_threads;

/// Arguments of `aobake bench clusters`.
#[derive(Debug, clap::Args)]
pub(super) struct Args {
    /// The character.
    file: PathBuf,
    /// glTF files with more clips for it.
    #[arg(long, num_args = 1..)]
    clips: Vec<PathBuf>,
    /// Reference poses (random clip frames of the training clips).
    #[arg(long, default_value_t = 256)]
    poses: usize,
    /// Rays per vertex and pose.
    #[arg(long, default_value_t = 128)]
    samples: u32,
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

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let inputs = load_inputs(&args.file, &args.clips, &Limits::default())?;
    let mut params = BakeParams::new(Method::VertexClustered);
    params.poses = args.poses;
    params.samples = args.samples;
    params.seed = args.seed;
    params.train_clips.clone_from(&args.train_clips);
    params.test_clips.clone_from(&args.test_clips);
    params.eval_poses = 0;
    let plan = Plan::new(&inputs.character, &inputs.clips, params)?;
    let character = &inputs.character;
    let v = character.vertex_count();
    let (poses, reference, tests, truth, trace_s) = with_threads(args.threads, || {
        let started = Instant::now();
        let poses = plan.reference_poses();
        let reference = trace_all(character, &poses, &plan.params.surface(), "reference AO")?;
        let tests = plan.test_poses();
        let test_poses: Vec<Pose> = tests.iter().map(|t| t.pose.clone()).collect();
        let truth = trace_all(
            character,
            &test_poses,
            &plan.params.held_out_surface(),
            "held-out AO",
        )?;
        anyhow::Ok((
            poses,
            reference,
            tests,
            truth,
            started.elapsed().as_secs_f64(),
        ))
    })??;
    let baseline = StaticAverage::fit(&reference);
    println!(
        "{}: {v} vertices, {} reference poses (clip frames), {} held-out clip frames, {} rays per vertex; tracing took {trace_s:.1} s",
        args.file.display(),
        poses.len(),
        tests.len(),
        plan.params.samples
    );
    println!();
    println!(
        "| pose clusters m | dimensions n | vertex clusters | mean abs error | PSNR (dB) | size (bytes) | multiply-adds / vertex | fit (s) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let row = |label: [String; 3], p: &BakeParams| -> anyhow::Result<()> {
        let mut plan = plan.clone();
        plan.params = p.clone();
        let started = Instant::now();
        let (model, _) = plan.fit(&poses, &reference)?;
        let fit_s = started.elapsed().as_secs_f64();
        let e = plan.evaluate(&model, &baseline, &tests, &truth);
        let c = &e.clip_frames.model.mean;
        println!(
            "| {} | {} | {} | {:.4} | {:.2} | {} | {:.0} | {:.2} |",
            label[0],
            label[1],
            label[2],
            c.mae,
            c.psnr_db,
            model.bytes(),
            e.multiply_adds_per_vertex,
            fit_s
        );
        Ok(())
    };
    for &m in &args.pose_clusters {
        for &n in &args.dimensions {
            for &f in &args.vertex_fractions {
                let mut p = plan.params.clone();
                p.clustered.pose_clusters = m;
                p.clustered.dimensions = n;
                p.clustered.vertex_clusters = (f * v as f64).round() as usize;
                let label = if p.clustered.vertex_clusters == 0 {
                    "none".to_owned()
                } else {
                    p.clustered.vertex_clusters.to_string()
                };
                row([m.to_string(), n.to_string(), label], &p)?;
            }
        }
    }
    let mut linear = plan.params.clone();
    linear.method = Method::VertexLinear;
    row(
        [
            "vertex-linear".into(),
            plan.joint_angles.len().to_string(),
            "-".into(),
        ],
        &linear,
    )?;
    let base = baseline.evaluate();
    let frames: Vec<FrameError> = (0..tests.len())
        .map(|i| FrameError::of(&base, truth.row(i)))
        .collect();
    let c = Errors::of(&frames).mean;
    println!(
        "| static average | - | - | {:.4} | {:.2} | {} | 1 | - |",
        c.mae,
        c.psnr_db,
        2 * v
    );
    Ok(())
}
