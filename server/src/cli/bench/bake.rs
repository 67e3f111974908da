//! `aobake bench bake`: a whole bake in this process, stage by stage, with
//! the seconds and the peak memory of each stage (tracing, every level of
//! a fit's cross-validation, the unseen-clip folds, evaluation, assembly,
//! previews), so that what dominates a bake can be seen and compared.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use aobake_core::{
    Limits,
    bake::{Bake, GraphOptions, JobEvent, JobSpec, PoseSet, Renderer, run_graph},
    method::vertex::FitStep,
};
use aobake_worker::gpu::{Gpu, PreviewRenderer};

use crate::cli::common::median;
use crate::cli::params::BakeRequestArgs;

/// Arguments of `aobake bench bake`.
#[derive(Debug, clap::Args)]
pub(super) struct Args {
    #[command(flatten)]
    request: BakeRequestArgs,
    /// Worker threads. Default: one per core.
    #[arg(long)]
    threads: Option<usize>,
    /// Whole bakes to run; each stage's median is printed.
    #[arg(long, default_value_t = 1)]
    repeat: usize,
    /// Render the previews too (on the first GPU adapter wgpu finds; a
    /// machine without one is told so and the stage left out).
    #[arg(long)]
    previews: bool,
}

/// One stage's figures over the runs.
#[derive(Debug, Default)]
struct Stage {
    /// Jobs in the stage (per run).
    jobs: usize,
    /// Seconds per run.
    seconds: Vec<f64>,
    /// Largest resident set seen while the stage ran (bytes), when the
    /// system reports it.
    peak: Option<u64>,
}

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let limits = Limits::default();
    let r = &args.request;
    let params = r.params.params(r.method)?;
    let inputs = crate::cli::bake::load_inputs(&r.file, &r.clips, &limits)?;
    let bake = Bake::new(&inputs, params)?;
    let mut gpu_renderer = None;
    if args.previews {
        match Gpu::shared()
            .map_err(anyhow::Error::from)
            .and_then(|g| PreviewRenderer::new(g).context("cannot make the preview renderer"))
        {
            Ok(r) => gpu_renderer = Some(r),
            Err(e) => eprintln!("previews left out: {e:#}"),
        }
    }
    // The process's own pool (a preview renderer cannot move into another
    // pool's threads).
    if let Some(n) = args.threads {
        anyhow::ensure!(n > 0, "--threads must be at least 1");
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .context("cannot start worker threads")?;
    }
    let threads = rayon::current_num_threads();
    let character = &inputs.character;
    println!(
        "{}: {} vertices, {} triangles; {}, {} reference poses × {} rays; {} threads",
        r.file.display(),
        character.vertex_count(),
        character.triangles.len(),
        bake.plan.params.method,
        bake.plan.params.poses,
        bake.plan.params.samples,
        threads,
    );
    let mut stages: Vec<(String, Stage)> = Vec::new();
    let mut wall = Vec::new();
    for run in 0..args.repeat.max(1) {
        let renderer = gpu_renderer.as_mut().map(|r| r as &mut dyn Renderer);
        let started = Instant::now();
        let times = time_stages(&bake, renderer)?;
        wall.push(started.elapsed().as_secs_f64());
        for (name, jobs, seconds, peak) in times {
            let i = match stages.iter().position(|(n, _)| *n == name) {
                Some(i) => i,
                None => {
                    stages.push((name, Stage::default()));
                    stages.len() - 1
                }
            };
            let stage = &mut stages[i].1;
            if run == 0 {
                stage.jobs = jobs;
            }
            stage.seconds.push(seconds);
            stage.peak = stage.peak.max(peak);
        }
    }
    let total = median(&wall);
    println!(
        "| stage | jobs | seconds (median of {}) | share | peak RSS |",
        wall.len()
    );
    println!("|---|---|---|---|---|");
    for (name, s) in &stages {
        let secs = median(&s.seconds);
        println!(
            "| {name} | {} | {secs:.2} | {:.1} % | {} |",
            s.jobs,
            100.0 * secs / total.max(1e-9),
            s.peak
                .map_or("?".into(), |b| format!("{:.0} MB", b as f64 / 1e6)),
        );
    }
    println!(
        "| whole bake | | {total:.2} | 100 % | {} |",
        peak_rss().map_or("?".into(), |b| format!("{:.0} MB", b as f64 / 1e6))
    );
    let of = |prefix: &str| -> f64 {
        stages
            .iter()
            .filter(|(n, _)| n.starts_with(prefix))
            .map(|(_, s)| median(&s.seconds))
            .sum()
    };
    let trace = of("trace reference");
    let fit_evaluate = of("fit") + of("unseen") + of("evaluate");
    if trace > 0.0 && fit_evaluate > 0.0 {
        println!(
            "fit + unseen folds + evaluate: {fit_evaluate:.2} s, {:.2}× the reference trace ({trace:.2} s)",
            fit_evaluate / trace
        );
    }
    Ok(())
}

/// (stage, jobs, seconds, peak bytes) of one whole bake, in the order the
/// stages first ran.
type StageTimes = Vec<(String, usize, f64, Option<u64>)>;

/// Runs the bake's graph once, timing every stage: a job's kind (a
/// `sample` job's pose set), and a fit's or fold's steps each on its own.
fn time_stages(bake: &Bake<'_>, renderer: Option<&mut dyn Renderer>) -> anyhow::Result<StageTimes> {
    let graph = bake.graph(GraphOptions {
        previews: renderer.is_some(),
        ..GraphOptions::default()
    });
    let mut times: StageTimes = Vec::new();
    // Each stage counts the jobs that passed through it.
    let mut add = |name: String, took: Duration| {
        let peak = peak_rss();
        match times.iter_mut().find(|(n, ..)| *n == name) {
            Some(t) => {
                t.1 += 1;
                t.2 += took.as_secs_f64();
                t.3 = t.3.max(peak);
            }
            None => times.push((name, 1, took.as_secs_f64(), peak)),
        }
        reset_peak_rss();
    };
    reset_peak_rss();
    let mut mark = Instant::now();
    let mut step = 0u64;
    run_graph(
        bake,
        &graph,
        &HashMap::new(),
        renderer,
        &mut |_, job, event| {
            let kind = match &job.spec {
                JobSpec::Sample { set, .. } => match set {
                    PoseSet::Reference => "trace reference".to_owned(),
                    PoseSet::HeldOut => "trace held-out".to_owned(),
                    PoseSet::Noise => "trace noise".to_owned(),
                },
                spec => spec.kind().to_owned(),
            };
            let fits = matches!(job.spec, JobSpec::Fit | JobSpec::Unseen { .. });
            match event {
                // A fit's steps, each timed (the first step's start is the
                // job's: the stacking of its inputs is counted in it).
                JobEvent::Progress { done, .. } if fits && done > step => {
                    let name = FitStep::ALL[(done - 1) as usize].name();
                    add(format!("{kind}: {name}"), mark.elapsed());
                    mark = Instant::now();
                    step = done;
                }
                JobEvent::Progress { .. } => {}
                JobEvent::Done(_) => {
                    if fits {
                        // What follows the last step: packing the outputs.
                        add(format!("{kind}: output"), mark.elapsed());
                    } else {
                        add(kind, mark.elapsed());
                    }
                    mark = Instant::now();
                    step = 0;
                }
            }
        },
    )?;
    Ok(times)
}

/// The process's peak resident set since the last [`reset_peak_rss`]
/// (Linux's `VmHWM`); `None` where the system does not say.
pub(super) fn peak_rss() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Starts the peak resident set afresh (Linux: `5` to `clear_refs`); where
/// it cannot, peaks are the process's since it started.
pub(super) fn reset_peak_rss() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}
