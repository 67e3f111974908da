//! `aobake bench`: speed measurements that print their figures.

mod bake;
mod cubemap;
mod grid;
mod load;
mod service;
mod tables;
mod texel;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context as _, bail};
use aobake_core::{
    Limits,
    import::ply,
    trace::shapes,
    trace::{
        Axis, BvhQuality, Falloff, Ground, Scene, SceneOptions, SurfaceMesh, SurfaceParams,
        Traversal, no_progress, vertex_occlusion,
    },
};
use glam::Vec3;

use crate::cli::common::median;

/// Arguments of `aobake bench`.
#[derive(Debug, clap::Args)]
pub(super) struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(Debug, clap::Subcommand)]
enum What {
    /// Per-vertex AO tracing speed (BVH build + 256 cosine rays per vertex)
    /// on the ~100k-triangle mesh of the Blender reference, optionally
    /// interleaved with Blender's Cycles bake of the same PLY.
    Trace(TraceArgs),
    /// Kirk & Arikan's Table 1 on a character: vertex-clustered's mean
    /// error and size for every pose-cluster count, dimension and
    /// vertex-cluster level, beside vertex-linear and the static average,
    /// all judged on the same held-out clip frames.
    Clusters(tables::ClusterArgs),
    /// vertex-linear's ridge weight and sparsification threshold: error,
    /// size and multiply-adds on the same held-out clip frames.
    Linear(tables::LinearArgs),
    /// Jobs scheduled per second (lease + complete) on SQLite or
    /// PostgreSQL, through the store and over HTTP.
    Queue(service::QueueArgs),
    /// Status-request latency (p50, p99) under concurrent pollers, and the
    /// server's memory.
    Api(service::ApiArgs),
    /// One or two servers under a studio's load for a bounded time:
    /// pollers, server-sent-event listeners, uploads and completing jobs;
    /// 5xx answers, status latency and memory per interval.
    Load(load::LoadArgs),
    /// Preview render time per panel (the model's AO on the GPU, raster,
    /// readback) on every adapter among Vulkan and GL, and a frame's GTAO
    /// pass beside the model's evaluation with their per-pixel errors.
    Preview(super::preview::BenchArgs),
    /// A cubemap face job's tracing rate (Kroon's Eq. 3.1 from points in
    /// space) beside the per-vertex tracer's on the same posed meshes.
    Cubemap(cubemap::Args),
    /// A grid slab's tracing rate (Malmer et al.'s Eq. 5 at the cell
    /// centres of a part's grid, every layer), on the CPU and the GPU
    /// tracer in turn.
    Grid(grid::Args),
    /// A whole bake here, stage by stage: the seconds and peak memory of
    /// tracing, each step of the fit and of the unseen-clip folds
    /// (cross-validation of the reference rows, of the ridge, of the
    /// basis), evaluation, assembly and previews.
    Bake(bake::Args),
    /// texel-linear (the vertex-linear model per texel of a generated
    /// atlas) traced and fitted here, stage by stage, and judged per pixel
    /// on stills of training clips and of clips left out of its training,
    /// beside the texel static average, the texel floor, the per-vertex
    /// floor and GTAO.
    Texel(texel::Args),
}

#[derive(Debug, clap::Args)]
struct TraceArgs {
    /// A z-up PLY mesh to trace instead of the built-in benchmark mesh (an
    /// icosphere and four boxes on the ground: 101,120 triangles, 50,570
    /// vertices, as `make_test_meshes.py timing` writes it).
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Rays per vertex.
    #[arg(long, default_value_t = 256)]
    samples: u32,
    /// Maximum ray distance (model units).
    #[arg(long, default_value_t = 10.0)]
    max_distance: f32,
    /// Timed runs (the first run is not discarded; medians are quoted).
    #[arg(long, default_value_t = 5)]
    repeat: usize,
    /// BVH build quality.
    #[arg(long, value_enum, default_value = "medium")]
    quality: Quality,
    /// Traversal kernels to time, comma-separated; several are run in
    /// turn within each repetition: `wide` (aobake's, the default) and
    /// `obvhs` (obvhs's own CWBVH traversal on the same tree) and `bvh2`
    /// (obvhs's binary BVH).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "wide")]
    traversal: Vec<Kernel>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Tracers to time, comma-separated, in turn within each repetition:
    /// `cpu` (the traversal kernels above), `gpu` (the wgpu compute
    /// tracer, aobake's wide BVH with exact boxes, on the best adapter with
    /// compute; its time includes the upload and the readback) and
    /// `gpu-quantised` (the same with the boxes as bytes: 96-byte nodes
    /// instead of 256) and `free` (no rays cast). With several, the
    /// figures of the same run are compared, and the values too.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "cpu")]
    tracer: Vec<BenchTracer>,
    /// Also bake with Blender: the path of a Blender script that bakes
    /// vertex AO (the developers' `blender-ao` tool's `bake_vertex_ao.py`,
    /// not part of this repository); `blender` must be on the PATH. Runs
    /// alternate between aobake and Blender, so drift in machine speed hits
    /// both alike.
    #[arg(long, value_name = "BAKE_VERTEX_AO_PY")]
    blender: Option<PathBuf>,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum Quality {
    Fast,
    Medium,
    Slow,
}

/// A tracer a bench times.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum BenchTracer {
    Cpu,
    Gpu,
    GpuQuantised,
    /// No rays cast (every ray a miss): what the job costs besides
    /// tracing, the floor under any tracer's time.
    Free,
}

/// The `free` tracer: every tally empty, at once.
#[derive(Debug)]
struct FreeTracer;

impl aobake_core::trace::RayEngine for FreeTracer {
    fn label(&self) -> String {
        "free (no rays cast)".into()
    }

    fn trace(
        &self,
        batch: &aobake_core::trace::RayBatch<'_>,
        progress: aobake_core::trace::Progress<'_>,
    ) -> Result<Option<Vec<aobake_core::trace::Tally>>, aobake_core::trace::TraceError> {
        let tallies = vec![aobake_core::trace::Tally::default(); batch.tallies()];
        progress(tallies.len());
        Ok(Some(tallies))
    }
}

/// Which tracers a tracing bench times, and how often.
#[derive(Debug, clap::Args)]
struct TracerRuns {
    /// Timed runs of each tracer (medians are quoted).
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// Tracers to time in turn within each run, comma-separated: `cpu`,
    /// `gpu` (the wgpu compute tracer on the best adapter with compute;
    /// its times include uploads and readbacks), `gpu-quantised` (the
    /// same with its tree's boxes as bytes) and `free` (no rays cast:
    /// what the work costs besides tracing).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "cpu")]
    tracer: Vec<BenchTracer>,
}

/// A tracer to time: its name and its engine (`None`: the CPU).
type Timed = (
    String,
    Option<std::sync::Arc<dyn aobake_core::trace::RayEngine>>,
);

/// The tracers of `list`, in order, the GPU one opened on the best adapter
/// with compute shaders (its label printed).
fn bench_tracers(list: &[BenchTracer]) -> anyhow::Result<Vec<Timed>> {
    let mut list = list.to_vec();
    list.dedup();
    // The tracers that cast rays first: `free` is compared with them.
    list.sort_by_key(|t| *t == BenchTracer::Free);
    if list.is_empty() {
        bail!("--tracer names no tracer");
    }
    if list == [BenchTracer::Free] {
        bail!(
            "--tracer free is compared with a tracer that casts rays: name one too (such as cpu,free)"
        );
    }
    list.iter()
        .map(|t| match t {
            BenchTracer::Cpu => Ok(("cpu".to_owned(), None)),
            BenchTracer::Free => Ok((
                "free".to_owned(),
                Some(std::sync::Arc::new(FreeTracer) as _),
            )),
            BenchTracer::Gpu | BenchTracer::GpuQuantised => {
                use aobake_core::trace::{RayEngine, engine::NodeLayout};
                use aobake_worker::gpu::{Gpu, GpuTracer};
                let (name, layout) = match t {
                    BenchTracer::Gpu => ("gpu", NodeLayout::Exact),
                    _ => ("gpu-quantised", NodeLayout::Quantised),
                };
                let tracer = Gpu::shared()
                    .and_then(|gpu| GpuTracer::with_layout(gpu, layout))
                    .map_err(|e| anyhow::anyhow!("--tracer {name}: {e}"))?;
                println!("GPU tracer: {} ({layout:?} nodes)", tracer.label());
                let engine: std::sync::Arc<dyn RayEngine> = std::sync::Arc::new(tracer);
                Ok((name.to_owned(), Some(engine)))
            }
        })
        .collect()
}

/// Prints what each engine counted over all runs (the GPU tracer: its
/// compute passes' seconds beside its calls').
fn tracer_summaries(tracers: &[Timed]) {
    for (name, engine) in tracers {
        if let Some(summary) = engine.as_ref().and_then(|e| e.summary()) {
            println!("{name} tracer, all runs: {summary}");
        }
    }
}

/// The name of the tracer that casts no rays.
const FREE: &str = "free";

/// Whether the tracer named `name` casts rays (all but `free`): its rate,
/// speed and values mean something.
fn casts_rays(name: &str) -> bool {
    name != FREE
}

/// "N run(s)".
fn run_count(n: usize) -> String {
    if n == 1 {
        "1 run".to_owned()
    } else {
        format!("{n} runs")
    }
}

/// Prints each tracer's median rate and every other tracer's speed
/// against the first that casts rays (median of the runs' ratios);
/// `rates[t]` holds the runs of tracer `t`, in G rays per second (for
/// `free`, the rays the work stands for over its time). `free` is given
/// as the share of that tracer's time that is not tracing.
fn compare_tracers(what: &str, tracers: &[Timed], rates: &[Vec<f64>]) {
    let base = tracers.iter().position(|(name, _)| casts_rays(name));
    for ((name, _), r) in tracers.iter().zip(rates) {
        if casts_rays(name) {
            println!(
                "{what}, {name}: median {:.3} Grays/s over {}",
                median(r),
                run_count(r.len())
            );
        }
    }
    let Some(base) = base else {
        return;
    };
    let base_name = &tracers[base].0;
    for (t, ((name, _), r)) in tracers.iter().zip(rates).enumerate() {
        if t == base {
            continue;
        }
        // Rates over the same rays: their ratio is the inverse of the
        // times'.
        let ratios: Vec<f64> = r.iter().zip(&rates[base]).map(|(a, b)| a / b).collect();
        if casts_rays(name) {
            println!(
                "{what}: {name} traces {:.2}x as fast as {base_name} (median over {})",
                median(&ratios),
                run_count(ratios.len())
            );
        } else {
            println!(
                "{what}: its work besides tracing (no rays cast) takes {:.1} % of {base_name}'s time (median over {})",
                100.0 / median(&ratios),
                run_count(ratios.len())
            );
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Kernel {
    Wide,
    Obvhs,
    Bvh2,
}

impl Kernel {
    fn traversal(self) -> Traversal {
        match self {
            Kernel::Wide => Traversal::Wide,
            Kernel::Obvhs => Traversal::Obvhs,
            Kernel::Bvh2 => Traversal::ObvhsBvh2,
        }
    }
}

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    match &args.what {
        What::Trace(a) => trace(a),
        What::Clusters(a) => tables::clusters(a),
        What::Linear(a) => tables::linear(a),
        What::Queue(a) => service::queue(a),
        What::Api(a) => service::api(a),
        What::Load(a) => load::load(a),
        What::Preview(a) => super::preview::bench(a),
        What::Cubemap(a) => cubemap::run(a),
        What::Bake(a) => bake::run(a),
        What::Texel(a) => texel::run(a),
        What::Grid(a) => grid::run(a),
    }
}

struct Run {
    build_s: f64,
    trace_s: f64,
    values: Vec<f32>,
}

fn run_aobake(
    positions: &[Vec3],
    normals: &[Vec3],
    triangles: &[[u32; 3]],
    options: &SceneOptions,
    params: &SurfaceParams,
) -> anyhow::Result<Run> {
    let started = Instant::now();
    let scene = Scene::new(positions, triangles, options)?;
    let build_s = started.elapsed().as_secs_f64();
    let started = Instant::now();
    let mesh = SurfaceMesh {
        positions,
        normals,
        triangles,
    };
    let values = vertex_occlusion(&scene, &mesh, params, &no_progress)?;
    let trace_s = started.elapsed().as_secs_f64();
    Ok(Run {
        build_s,
        trace_s,
        values,
    })
}

fn run_blender(script: &Path, ply: &Path, csv: &Path, args: &TraceArgs) -> anyhow::Result<f64> {
    let mut cmd = Command::new("blender");
    cmd.args(["-b", "--factory-startup", "--python"])
        .arg(script)
        .arg("--")
        .arg("--mesh")
        .arg(ply)
        .arg("--out")
        .arg(csv)
        .args([
            "--samples",
            &args.samples.to_string(),
            "--distance",
            &args.max_distance.to_string(),
            "--ground",
        ]);
    if let Some(t) = args.threads {
        cmd.args(["--threads", &t.to_string()]);
    }
    let out = cmd
        .output()
        .context("cannot run `blender` (is it installed?)")?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    let Some(line) = stdout.lines().find_map(|l| l.strip_prefix("BAKE_RESULT ")) else {
        bail!(
            "Blender printed no BAKE_RESULT (exit {}): {}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let result: serde_json::Value = serde_json::from_str(line)?;
    result["bake_seconds"]
        .as_f64()
        .context("BAKE_RESULT has no bake_seconds")
}

fn trace(args: &TraceArgs) -> anyhow::Result<()> {
    let mesh = match &args.mesh {
        Some(path) => {
            let m = super::trace::read_ply(path, &Limits::default())?;
            shapes::TriMesh {
                positions: m.positions,
                triangles: m.triangles,
            }
        }
        None => shapes::timing_mesh(),
    };
    let normals = mesh.normals();
    let lowest = mesh
        .positions
        .iter()
        .map(|p| p.z)
        .fold(f32::INFINITY, f32::min);
    let options = SceneOptions {
        ground: Some(Ground {
            up: Axis::Z,
            height: lowest,
            half_size: None,
        }),
        quality: match args.quality {
            Quality::Fast => BvhQuality::Fast,
            Quality::Medium => BvhQuality::Medium,
            Quality::Slow => BvhQuality::Slow,
        },
        traversal: Traversal::default(),
    };
    let params = SurfaceParams {
        samples: args.samples,
        max_distance: args.max_distance,
        seed: 0,
        falloff: Falloff::None,
    };
    let dir = tempfile::tempdir()?;
    let ply_path = dir.path().join("bench.ply");
    if args.blender.is_some() {
        std::fs::write(
            &ply_path,
            ply::write(
                &mesh.positions,
                &normals,
                &mesh.triangles,
                ply::Encoding::Binary,
            ),
        )?;
    }
    let vertices = mesh.positions.len() as f64;
    let rays = vertices * f64::from(args.samples);
    println!(
        "mesh: {} vertices, {} triangles; {} rays per vertex, max distance {}, ground at z = {lowest}",
        mesh.positions.len(),
        mesh.triangles.len(),
        args.samples,
        args.max_distance
    );
    let mut kernels = args.traversal.clone();
    kernels.dedup();
    if kernels.is_empty() {
        bail!("--traversal names no kernel");
    }
    // What is timed: the CPU with each kernel, then the GPU.
    let tracers = bench_tracers(&args.tracer)?;
    // A row per CPU kernel and one for the GPU, with its engine.
    let mut rows: Vec<(String, Option<Kernel>, Timed)> = Vec::new();
    for tracer in &tracers {
        match &tracer.1 {
            None => rows.extend(
                kernels
                    .iter()
                    .map(|k| (format!("{} {k:?}", tracer.0), Some(*k), tracer.clone())),
            ),
            Some(_) => rows.push((tracer.0.clone(), None, tracer.clone())),
        }
    }
    let mut ours: Vec<Vec<Run>> = rows.iter().map(|_| Vec::new()).collect();
    let mut theirs = Vec::new();
    for r in 0..args.repeat {
        for (k, (name, kernel, (_, engine))) in rows.iter().enumerate() {
            aobake_core::trace::engine::set_engine(engine.clone());
            let options = SceneOptions {
                traversal: kernel.map_or(Traversal::Wide, Kernel::traversal),
                ..options
            };
            let run = super::trace::with_threads(args.threads, || {
                run_aobake(
                    &mesh.positions,
                    &normals,
                    &mesh.triangles,
                    &options,
                    &params,
                )
            })??;
            if casts_rays(name) {
                println!(
                    "[{r}] aobake ({name}): BVH {:.1} ms, trace {:.3} s: {:.2} Mrays/s",
                    run.build_s * 1e3,
                    run.trace_s,
                    rays / run.trace_s / 1e6
                );
            } else {
                println!(
                    "[{r}] aobake ({name}): BVH {:.1} ms, no rays cast: {:.3} s",
                    run.build_s * 1e3,
                    run.trace_s,
                );
            }
            ours[k].push(run);
        }
        if let Some(script) = &args.blender {
            let s = run_blender(script, &ply_path, &dir.path().join("blender.csv"), args)?;
            println!(
                "[{r}] Blender: bake {s:.2} s: {:.3} M vertex-samples/s",
                rays / s / 1e6
            );
            theirs.push(s);
        }
    }
    tracer_summaries(&tracers);
    aobake_core::trace::engine::set_engine(None);
    for ((name, _, _), runs) in rows.iter().zip(&ours) {
        let build = median(&runs.iter().map(|r| r.build_s).collect::<Vec<_>>());
        let traced = median(&runs.iter().map(|r| r.trace_s).collect::<Vec<_>>());
        let total = median(
            &runs
                .iter()
                .map(|r| r.build_s + r.trace_s)
                .collect::<Vec<_>>(),
        );
        if !casts_rays(name) {
            println!(
                "aobake ({name}) median of {}: BVH build {:.1} ms, no rays cast: {traced:.3} s",
                runs.len(),
                build * 1e3,
            );
            continue;
        }
        println!(
            "aobake ({name}) median of {}: BVH build {:.1} ms, trace {:.3} s, {:.2} Mrays/s = {:.3} Grays/s ({:.2} M vertex-samples/s with the build)",
            runs.len(),
            build * 1e3,
            traced,
            rays / traced / 1e6,
            rays / traced / 1e9,
            rays / total / 1e6
        );
    }
    if rows.len() > 1 {
        for ((name, _, _), runs) in rows.iter().zip(&ours).skip(1) {
            let pairs: Vec<f64> = runs
                .iter()
                .zip(&ours[0])
                .map(|(other, first)| other.trace_s / first.trace_s)
                .collect();
            if !casts_rays(name) {
                println!(
                    "the work besides tracing (no rays cast) takes {:.1} % of {}'s trace time (median over {})",
                    100.0 * median(&pairs),
                    rows[0].0,
                    run_count(pairs.len())
                );
                continue;
            }
            let speed: Vec<f64> = pairs.iter().map(|p| 1.0 / p).collect();
            println!(
                "trace time {name} / {}: {:.3}x median of pairs ({name} traces {:.1}x as fast)",
                rows[0].0,
                median(&pairs),
                median(&speed)
            );
            // The same rays: how many vertices' values differ.
            let (a, b) = (&runs[0].values, &ours[0][0].values);
            let differ = a.iter().zip(b).filter(|(x, y)| x != y).count();
            let worst = a
                .iter()
                .zip(b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max);
            println!(
                "values {name} against {}: {differ} of {} vertices differ (worst by {worst}, one ray is {})",
                rows[0].0,
                a.len(),
                1.0 / params.samples as f32
            );
        }
    }
    let ours = &ours[0];
    if !theirs.is_empty() {
        let blender = median(&theirs);
        let pairs: Vec<f64> = theirs
            .iter()
            .zip(ours)
            .map(|(b, o)| b / (o.build_s + o.trace_s))
            .collect();
        println!(
            "Blender median of {}: bake {blender:.2} s, {:.3} M vertex-samples/s",
            theirs.len(),
            rays / blender / 1e6
        );
        println!(
            "speed-up of aobake ({}) over Blender (bake time / build+trace): {:.1}x median of pairs (min {:.1}x, max {:.1}x)",
            rows[0].0,
            median(&pairs),
            pairs.iter().copied().fold(f64::INFINITY, f64::min),
            pairs.iter().copied().fold(0.0, f64::max)
        );
    }
    Ok(())
}
