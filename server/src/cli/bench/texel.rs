//! `aobake bench texel`: texel-linear, the vertex-linear model fitted per
//! texel of a generated atlas, traced and fitted here (stage by stage,
//! with seconds and peak memory) and judged per pixel on stills of
//! training clips and of clips left out of its training, beside the
//! texel static average, the texel floor, the per-vertex floor and GTAO.
//! The figures the texel family's defaults are chosen from.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context as _;
use aobake_core::{
    Limits,
    bake::{
        BakeParams, Plan, PreviewModel, Receivers, RenderScene, Renderer,
        preview::{STILL_FRACTIONS, STILL_PANEL, Subject, frame_poses},
        screen_space::{Gtao, ScreenSpaceInfo, TexelJudge},
    },
    image::HEAT_MAP,
    method::{
        Method,
        texel::DEFAULT_ATLAS,
        vertex::{Model, fit_static_average},
    },
    trace::{AoBlock, SceneOptions, no_progress},
};
use aobake_worker::gpu::{Gpu, PreviewRenderer};

use super::bake::{peak_rss, reset_peak_rss};

/// Arguments of `aobake bench texel`.
#[derive(Debug, clap::Args)]
pub(super) struct Args {
    /// The character (.glb, or .gltf with its side files beside it).
    file: PathBuf,
    /// glTF files whose animations drive the character.
    #[arg(long, num_args = 1..)]
    clips: Vec<PathBuf>,
    /// The atlas's side in texels.
    #[arg(long, default_value_t = DEFAULT_ATLAS)]
    atlas: u32,
    /// Reference poses (a third each random, clip frames and perturbed
    /// frames, as the vertex methods draw them). Default: texel-linear's.
    #[arg(long)]
    poses: Option<usize>,
    /// Rays per texel and reference pose. Default: texel-linear's.
    #[arg(long)]
    samples: Option<u32>,
    /// Rays per pixel of the per-pixel truth and per texel of the floor.
    #[arg(long, default_value_t = 256)]
    truth_samples: u32,
    /// A clip left out of training and judged as unseen (repeat for
    /// several). Default: none.
    #[arg(long = "leave-out", value_name = "CLIP")]
    leave_out: Vec<String>,
    /// Training clips judged too (the first ones).
    #[arg(long, default_value_t = 2)]
    train_judged: usize,
    /// Seed of poses and rays.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

/// One still's per-pixel errors on the character.
struct Judged {
    clip: String,
    unseen: bool,
    time: f32,
    model: (f64, f64),
    baseline: (f64, f64),
    floor: f64,
    per_vertex: f64,
    gtao: f64,
}

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let inputs = crate::cli::bake::load_inputs(&args.file, &args.clips, &Limits::default())?;
    let c = &inputs.character;
    let clips = &inputs.clips;
    for name in &args.leave_out {
        anyhow::ensure!(
            clips.iter().any(|k| &k.name == name),
            "no clip {name:?} to leave out"
        );
    }
    // A texel-linear bake's plan: its defaults, its atlas, its fit.
    let mut params = BakeParams::new(Method::TexelLinear);
    params.texel.atlas = args.atlas;
    params.poses = args.poses.unwrap_or(params.poses);
    params.samples = args.samples.unwrap_or(params.samples);
    params.seed = args.seed;
    params.eval_folds = 0;
    params.train_clips = clips
        .iter()
        .map(|k| k.name.clone())
        .filter(|n| !args.leave_out.contains(n))
        .collect();
    let started = Instant::now();
    let plan = Plan::new(c, clips, params)?;
    let atlas_s = started.elapsed().as_secs_f64();
    let Receivers::Texels(atlas) = plan.receivers.clone() else {
        anyhow::bail!("a texel-linear plan traces texels");
    };
    println!(
        "{}: {} vertices, {} triangles; atlas {}×{} ({} charts, {} texels, {:.0} % used); {} reference poses × {} rays; {} threads",
        args.file.display(),
        c.vertex_count(),
        c.triangles.len(),
        atlas.atlas.width,
        atlas.atlas.height,
        atlas.atlas.charts,
        atlas.texels.len(),
        100.0 * atlas.texels.utilisation(),
        plan.params.poses,
        plan.params.samples,
        rayon::current_num_threads()
    );
    println!("| stage | seconds | peak RSS |\n|---|---|---|");
    let mb = || peak_rss().map_or("?".into(), |b| format!("{:.0} MB", b as f64 / 1e6));
    println!("| atlas | {atlas_s:.2} | {} |", mb());
    reset_peak_rss();
    let started = Instant::now();
    let poses = plan.reference_poses();
    let reference = plan.trace(
        &poses,
        &SceneOptions::default(),
        &plan.params.surface(),
        &no_progress,
    )?;
    println!(
        "| trace | {:.1} | {} |",
        started.elapsed().as_secs_f64(),
        mb()
    );
    reset_peak_rss();
    let started = Instant::now();
    let mut step_started = Instant::now();
    let (model, stats) =
        plan.fit_stepwise(&poses, &reference, &plan.reference_sources(), &mut |step| {
            println!(
                "| fit: {} | {:.1} | {} |",
                step.name(),
                step_started.elapsed().as_secs_f64(),
                mb()
            );
            reset_peak_rss();
            step_started = Instant::now();
        })?;
    let baseline = fit_static_average(&reference.select(plan.baseline_rows())).evaluate();
    println!(
        "| fit | {:.1} | {} |",
        started.elapsed().as_secs_f64(),
        mb()
    );
    drop(reference);
    if let Some(b) = stats.basis() {
        println!("basis rank {}", b.rank);
    }
    println!(
        "model: {} weights per pose, {:.1} MB of coefficients",
        model.weight_count(),
        model.bytes() as f64 / 1e6
    );

    // Per pixel, on stills.
    let gpu = Gpu::shared().context("no GPU adapter for the stills")?;
    let mut renderer = PreviewRenderer::new(gpu)?;
    let vertices = c.vertex_count();
    let open = Model::StaticAverage(fit_static_average(&AoBlock {
        vertices,
        values: vec![0.0; vertices],
    }));
    let surface = aobake_core::trace::SurfaceParams {
        samples: args.truth_samples,
        ..plan.params.held_out_surface()
    };
    let subject = Subject::new(c, PreviewModel::Vertex(&open), surface);
    let judged_clips: Vec<usize> = plan
        .train
        .iter()
        .copied()
        .take(args.train_judged)
        .chain((0..clips.len()).filter(|&i| args.leave_out.contains(&clips[i].name)))
        .collect();
    let mut rows = Vec::new();
    let started = Instant::now();
    for &k in &judged_clips {
        let clip = &clips[k];
        let camera = subject.camera(Some(clip));
        let ground = camera.ground();
        let times: Vec<f32> = STILL_FRACTIONS.iter().map(|f| f * clip.duration).collect();
        let frames = subject.frames(Some(clip), &times, &ground)?;
        let scene = RenderScene {
            triangles: &c.triangles,
            model: subject.model,
            camera,
            ground: &ground,
            size: (STILL_PANEL, STILL_PANEL),
            heat_map: HEAT_MAP,
            gtao: Gtao::for_camera(&camera, surface.max_distance),
        };
        let screens = renderer
            .screen_space(&scene, &frames)
            .map_err(|e| anyhow::anyhow!("the renderer failed: {e}"))?;
        let poses = frame_poses(c, Some(clip), &times);
        for ((screen, frame), (pose, &time)) in
            screens.iter().zip(&frames).zip(poses.iter().zip(&times))
        {
            let models = [model.evaluate(&c.skeleton, &pose.locals), baseline.clone()];
            let info = ScreenSpaceInfo::measure(
                screen,
                frame,
                &c.triangles,
                &scene.model,
                &camera,
                scene.gtao,
                &surface,
                Some(TexelJudge {
                    atlas: &atlas,
                    models: &models,
                }),
            )?;
            let Some(e) = info.character else { continue };
            let floor = e.texel_truth.context("no texel floor")?;
            rows.push(Judged {
                clip: clip.name.clone(),
                unseen: args.leave_out.contains(&clip.name),
                time,
                model: (e.texel_models[0].rmse, e.texel_models[0].psnr_db),
                baseline: (e.texel_models[1].rmse, e.texel_models[1].psnr_db),
                floor: floor.rmse,
                per_vertex: e.per_vertex_truth.rmse,
                gtao: e.gtao.rmse,
            });
        }
    }
    println!(
        "judged {} stills in {:.1} s; RMSE per pixel on the character against ray-traced AO ({} rays):",
        rows.len(),
        started.elapsed().as_secs_f64(),
        args.truth_samples
    );
    println!(
        "| clip | time (s) | texel-linear | texel static average | gain (dB) | texel floor | per-vertex floor | GTAO | texel-linear / GTAO |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for r in &rows {
        println!(
            "| {}{} | {:.2} | {:.4} | {:.4} | {:+.2} | {:.4} | {:.4} | {:.4} | {:.2} |",
            r.clip,
            if r.unseen { " (unseen)" } else { "" },
            r.time,
            r.model.0,
            r.baseline.0,
            r.model.1 - r.baseline.1,
            r.floor,
            r.per_vertex,
            r.gtao,
            r.model.0 / r.gtao
        );
    }
    for unseen in [false, true] {
        let group: Vec<&Judged> = rows.iter().filter(|r| r.unseen == unseen).collect();
        if group.is_empty() {
            continue;
        }
        let gains: Vec<f64> = group.iter().map(|r| r.model.1 - r.baseline.1).collect();
        let worst_ratio = group
            .iter()
            .map(|r| r.model.0 / r.gtao)
            .fold(0.0f64, f64::max);
        println!(
            "{}: mean gain over the texel static average {:+.2} dB, worst still {:+.2} dB; worst texel-linear / GTAO {:.2}; below the per-vertex floor on {} of {}",
            if unseen {
                "unseen clips"
            } else {
                "training clips"
            },
            gains.iter().sum::<f64>() / gains.len() as f64,
            gains.iter().copied().fold(f64::INFINITY, f64::min),
            worst_ratio,
            group.iter().filter(|r| r.model.0 < r.per_vertex).count(),
            group.len()
        );
    }
    Ok(())
}
