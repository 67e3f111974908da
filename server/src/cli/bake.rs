//! `aobake bake`: a whole per-vertex bake on this machine, stage by stage
//! as the service's jobs run it (reference AO → fit → held-out AO →
//! evaluate), writing the asset, the JSON report and the PSNR plot.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, bail};
use aobake_core::{
    Character, Clip, Limits, Pose,
    asset::Method,
    bake::{BakeParams, Plan, ReferenceSource},
    model::{Centering, StaticAverage},
    reference::{AoBlock, trace_poses},
    report::{CharacterInfo, NoiseEstimate, Report, Sizes, Timings, psnr_plot_png},
    trace::{SceneOptions, SurfaceParams},
};

use super::trace::{progress_bar, with_threads};

/// Arguments of `aobake bake`.
#[derive(Debug, clap::Args)]
#[command(allow_negative_numbers = true)]
pub(super) struct Args {
    /// The character (.glb, or .gltf with its side files beside it).
    file: PathBuf,
    /// glTF files whose animations drive the character, bound to its nodes
    /// by name; the character's own clips count too.
    #[arg(long, num_args = 1..)]
    clips: Vec<PathBuf>,
    /// The method: vertex-linear (Kontkanen & Aila 2006), vertex-clustered
    /// (Kirk & Arikan 2007) or static-average (the baseline alone).
    #[arg(long, value_enum)]
    method: MethodArg,
    /// Reference poses to fit to.
    #[arg(long, default_value_t = 256)]
    poses: usize,
    /// Where reference poses come from: random joint angles in the
    /// clips' ranges, random clip frames, or half each. Default: mixed
    /// for vertex-linear, clips otherwise.
    #[arg(long, value_enum)]
    reference: Option<ReferenceArg>,
    /// Rays per vertex and pose.
    #[arg(long, default_value_t = 256)]
    samples: u32,
    /// Hits farther than this (model units) do not occlude. Default: no
    /// limit.
    #[arg(long)]
    max_distance: Option<f32>,
    /// Seed of poses, ray directions and k-means: the same seed gives the
    /// same asset, byte for byte.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Fit on this clip only (repeat for several). Default: every clip.
    #[arg(long = "train-clip", value_name = "NAME")]
    train_clips: Vec<String>,
    /// Hold out every frame of this clip (repeat for several). Default:
    /// every clip.
    #[arg(long = "test-clip", value_name = "NAME")]
    test_clips: Vec<String>,
    /// Held-out random poses (another seed than the reference poses).
    #[arg(long, default_value_t = 32)]
    eval_poses: usize,
    /// Frame rate at which test clips are evaluated.
    #[arg(long, default_value_t = 30.0)]
    eval_fps: f32,
    /// Widen each joint-angle range by this fraction of its span.
    #[arg(long, default_value_t = 0.1)]
    range_margin: f32,
    /// vertex-linear, vertex-clustered: ridge weight λ per pose on
    /// standardised pose coordinates (minimises (1/P)‖JT − A‖² + λ‖T‖²);
    /// 0 is the pseudo-inverse.
    #[arg(long, default_value_t = aobake_core::model::DEFAULT_RIDGE)]
    ridge: f64,
    /// vertex-linear: drop coefficients whose effect is below this much AO
    /// per standard deviation of their joint angle, and store the rest
    /// sparse (see `aobake bench linear` for the trade-off).
    #[arg(long, default_value_t = 0.0)]
    threshold: f32,
    /// vertex-clustered: pose clusters m.
    #[arg(long, default_value_t = 10)]
    pose_clusters: usize,
    /// vertex-clustered: PCA dimensions n per pose cluster.
    #[arg(long, default_value_t = 10)]
    dimensions: usize,
    /// vertex-clustered: vertex clusters per pose cluster (0: one
    /// coefficient vector per vertex).
    #[arg(long, default_value_t = 0)]
    vertex_clusters: usize,
    /// vertex-clustered: stop splitting vertex clusters once every vertex
    /// is within this RMS AO distance of its cluster's centre.
    #[arg(long, default_value_t = 0.0)]
    vertex_tolerance: f32,
    /// vertex-clustered: MLS blend falloff α (Kirk & Arikan Eq. 5).
    #[arg(long, default_value_t = 10.0)]
    alpha: f32,
    /// vertex-clustered: centre each pose cluster's model on the global
    /// mean AO (the paper's Eq. 1) or on the cluster's own mean (one more
    /// coefficient, more accurate).
    #[arg(long, value_enum, default_value = "cluster")]
    centering: CenteringArg,
    /// vertex-clustered: clamp each whitened PCA coordinate to ± this many
    /// standard deviations of its cluster's training poses (0: off), so
    /// poses unlike any training pose do not extrapolate without bound.
    #[arg(long, default_value_t = 3.0)]
    clamp: f32,
    /// Worker threads for tracing. Default: one per core.
    #[arg(long)]
    threads: Option<usize>,
    /// The asset to write (aobake asset format v1, docs/asset-format.md).
    #[arg(long)]
    out: PathBuf,
    /// The JSON report to write: held-out errors of the model and the
    /// static-average baseline, sizes, timings.
    #[arg(long)]
    report: PathBuf,
    /// The PSNR-per-frame plot (PNG). Default: the report's path with
    /// `.png`.
    #[arg(long)]
    plot: Option<PathBuf>,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum MethodArg {
    VertexLinear,
    VertexClustered,
    StaticAverage,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum ReferenceArg {
    Random,
    Clips,
    Mixed,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum CenteringArg {
    Global,
    Cluster,
}

impl Args {
    fn params(&self) -> BakeParams {
        let method = match self.method {
            MethodArg::VertexLinear => Method::VertexLinear,
            MethodArg::VertexClustered => Method::VertexClustered,
            MethodArg::StaticAverage => Method::StaticAverage,
        };
        let mut p = BakeParams::new(method);
        p.poses = self.poses;
        if let Some(r) = self.reference {
            p.reference = match r {
                ReferenceArg::Random => ReferenceSource::Random,
                ReferenceArg::Clips => ReferenceSource::Clips,
                ReferenceArg::Mixed => ReferenceSource::Mixed,
            };
        }
        p.samples = self.samples;
        p.max_distance = self.max_distance;
        p.seed = self.seed;
        p.train_clips.clone_from(&self.train_clips);
        p.test_clips.clone_from(&self.test_clips);
        p.eval_poses = self.eval_poses;
        p.eval_fps = self.eval_fps;
        p.range_margin = self.range_margin;
        p.linear.ridge = self.ridge;
        p.linear.threshold = self.threshold;
        p.clustered.ridge = self.ridge;
        p.clustered.pose_clusters = self.pose_clusters;
        p.clustered.dimensions = self.dimensions;
        p.clustered.vertex_clusters = self.vertex_clusters;
        p.clustered.vertex_tolerance = self.vertex_tolerance;
        p.clustered.alpha = self.alpha;
        p.clustered.clamp = self.clamp;
        p.clustered.centering = match self.centering {
            CenteringArg::Global => Centering::Global,
            CenteringArg::Cluster => Centering::Cluster,
        };
        p
    }
}

/// The character, every clip (files given first, then its own) and the
/// digests of the uploads.
#[derive(Debug)]
pub(super) struct Inputs {
    pub character: Character,
    pub clips: Vec<Clip>,
    pub character_digest: String,
    pub clip_digests: Vec<String>,
}

pub(super) fn load_inputs(
    file: &Path,
    clip_files: &[PathBuf],
    limits: &Limits,
) -> anyhow::Result<Inputs> {
    let (imported, character_digest) = super::load::character_with_digest(file, limits)?;
    for w in &imported.warnings {
        eprintln!("warning: {}: {w}", file.display());
    }
    let mut clips = Vec::new();
    let mut clip_digests = Vec::new();
    for path in clip_files {
        let (extra, warnings, digest) = super::load::clips_with_digest(path, &imported, limits)?;
        for w in warnings {
            eprintln!("warning: {}: {w}", path.display());
        }
        clips.extend(extra);
        clip_digests.push(digest);
    }
    clips.extend(imported.clips.iter().cloned());
    Ok(Inputs {
        character: imported.character,
        clips,
        character_digest,
        clip_digests,
    })
}

/// Traces `poses` with a progress bar counting poses.
pub(super) fn trace_all(
    character: &Character,
    poses: &[Pose],
    surface: &SurfaceParams,
    what: &str,
) -> anyhow::Result<AoBlock> {
    let bar = progress_bar(poses.len() as u64, what);
    let options = SceneOptions::default();
    let mut block = AoBlock {
        vertices: character.vertex_count(),
        values: Vec::with_capacity(character.vertex_count() * poses.len()),
    };
    for chunk in poses.chunks(4) {
        let b = trace_poses(
            character,
            chunk,
            &options,
            surface,
            &aobake_core::trace::no_progress,
        )?;
        block.values.extend(b.values);
        bar.inc(chunk.len() as u64);
    }
    bar.finish_and_clear();
    Ok(block)
}

fn write(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    std::fs::write(path, bytes).with_context(|| format!("cannot write {}", path.display()))
}

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let limits = Limits::default();
    let params = args.params();
    if args.out == args.report {
        bail!("--out and --report must be different files");
    }
    let inputs = load_inputs(&args.file, &args.clips, &limits)?;
    let plan = Plan::new(&inputs.character, &inputs.clips, params)?;
    with_threads(args.threads, || bake(args, &inputs, &plan))?
}

fn bake(args: &Args, inputs: &Inputs, plan: &Plan<'_>) -> anyhow::Result<()> {
    let character = &inputs.character;
    let params = &plan.params;
    let vertices = character.vertex_count();
    let names = |idx: &[usize]| -> Vec<String> {
        idx.iter().map(|&i| inputs.clips[i].name.clone()).collect()
    };
    eprintln!(
        "{}: {} vertices, {} triangles; {} joint-angle parameters, {} handle coordinates; training on {:?}, testing on {:?}",
        args.file.display(),
        vertices,
        character.triangles.len(),
        plan.joint_angles.len(),
        plan.handles.len(),
        names(&plan.train),
        names(&plan.test),
    );
    let mut timings = Timings::default();

    let started = Instant::now();
    let poses = plan.reference_poses();
    let reference = trace_all(character, &poses, &params.surface(), "reference AO")?;
    timings.reference_trace_s = started.elapsed().as_secs_f64();

    let started = Instant::now();
    let (model, fit) = plan.fit(&poses, &reference)?;
    let baseline = StaticAverage::fit(&reference);
    timings.fit_s = started.elapsed().as_secs_f64();

    let started = Instant::now();
    let tests = plan.test_poses();
    let test_poses: Vec<Pose> = tests.iter().map(|t| t.pose.clone()).collect();
    let truth = trace_all(
        character,
        &test_poses,
        &params.held_out_surface(),
        "held-out AO",
    )?;

    // The ground truth's own noise: a few held-out poses traced again with
    // other rays.
    let noise_poses = plan.noise_sample(&tests);
    let again: Vec<Pose> = noise_poses.iter().map(|&i| tests[i].pose.clone()).collect();
    let retraced = trace_all(character, &again, &params.noise_surface(), "noise estimate")?;
    let ground_truth_noise = NoiseEstimate::of(&noise_poses, &truth, &retraced);
    timings.test_trace_s = started.elapsed().as_secs_f64();

    let started = Instant::now();
    let evaluation = plan.evaluate(&model, &baseline, &tests, &truth);
    timings.evaluate_s = started.elapsed().as_secs_f64();

    let header = plan.header(&inputs.character_digest, &inputs.clip_digests);
    let bake_key = header.bake_key.clone();
    let asset = model.to_container(header).to_bytes();
    write(&args.out, &asset)?;

    let report = Report {
        method: params.method,
        bake_key,
        params: params.clone(),
        character: CharacterInfo {
            digest: inputs.character_digest.clone(),
            vertices,
            triangles: character.triangles.len(),
            clips: inputs.clips.iter().map(|c| c.name.clone()).collect(),
            train_clips: names(&plan.train),
            test_clips: names(&plan.test),
            joint_angle_parameters: plan.joint_angles.len(),
            handle_coordinates: plan.handles.len(),
        },
        rays: (poses.len() + tests.len()) as u64 * vertices as u64 * u64::from(params.samples),
        timings,
        fit,
        sizes: Sizes {
            asset_bytes: asset.len(),
            model_bytes: model.bytes(),
            baseline_bytes: 2 * vertices,
        },
        evaluation,
        ground_truth_noise,
    };
    let json = serde_json::to_string_pretty(&report).expect("reports serialise");
    write(&args.report, json.as_bytes())?;
    let plot_path = args
        .plot
        .clone()
        .unwrap_or_else(|| args.report.with_extension("png"));
    let png = psnr_plot_png(&report).map_err(|e| anyhow::anyhow!("cannot draw the plot: {e}"))?;
    write(&plot_path, &png)?;

    let e = &report.evaluation;
    eprintln!(
        "wrote {} ({} bytes), {}, {}",
        args.out.display(),
        asset.len(),
        args.report.display(),
        plot_path.display()
    );
    eprintln!(
        "held-out clip frames ({}): {} PSNR {:.2} dB, MAE {:.4}; static average {:.2} dB, MAE {:.4} ({:+.2} dB, MAE ×{:.2})",
        e.clip_frames.model.frames,
        params.method.name(),
        e.clip_frames.model.mean.psnr_db,
        e.clip_frames.model.mean.mae,
        e.clip_frames.baseline.mean.psnr_db,
        e.clip_frames.baseline.mean.mae,
        e.clip_frames.psnr_gain_db,
        e.clip_frames.mae_ratio,
    );
    eprintln!(
        "ground truth's own noise ({} poses traced twice): RMSE {:.4}, MAE {:.4} (PSNR {:.2} dB): model errors near it are noise",
        report.ground_truth_noise.frames,
        report.ground_truth_noise.rmse,
        report.ground_truth_noise.mae,
        report.ground_truth_noise.psnr_db,
    );
    eprintln!(
        "held-out random poses ({}): {:.2} dB against {:.2} dB; times: trace {:.1} s + {:.1} s, fit {:.2} s",
        e.random_poses.model.frames,
        e.random_poses.model.mean.psnr_db,
        e.random_poses.baseline.mean.psnr_db,
        report.timings.reference_trace_s,
        report.timings.test_trace_s,
        report.timings.fit_s,
    );
    Ok(())
}
