//! `aobake bench cubemap`: the speed of a cubemap `face` job (Kroon's Eq.
//! 3.1 at every texel, shell and time sample of a face, full-sphere rays
//! from points in space) beside the per-vertex tracer's rate on the same
//! posed meshes, runs interleaved so that drift in machine speed hits both
//! alike.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context as _;
use aobake_core::{
    Limits,
    method::cubemap::{
        CubemapOptions,
        face::{FaceField, FaceSampling, compute_face},
        geometry::Spheroid,
    },
    rig::pose::Pose,
    trace::{Falloff, SceneOptions, SurfaceParams, no_progress, trace_poses},
};

use crate::cli::common::median;
use crate::cli::common::{character_and_clips, find_clip};

/// Arguments of `aobake bench cubemap`.
#[derive(Debug, clap::Args)]
pub(super) struct Args {
    /// The character (.glb or .gltf).
    file: PathBuf,
    /// A second glTF file with clips.
    #[arg(long)]
    clips: Option<PathBuf>,
    /// The clip (default: the first).
    #[arg(long)]
    clip: Option<String>,
    /// Texels per face edge (the default bake has 128).
    #[arg(long, default_value_t = 32)]
    resolution: usize,
    /// Shells (the default bake has 8).
    #[arg(long, default_value_t = 8)]
    shells: usize,
    /// Time samples of the timed face (the default bake has 255).
    #[arg(long, default_value_t = 16)]
    times: usize,
    /// Rays per sample point.
    #[arg(long, default_value_t = 64)]
    rays: u32,
    #[command(flatten)]
    runs: super::TracerRuns,
}

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let tracers = super::bench_tracers(&args.runs.tracer)?;
    let (character, clips) =
        character_and_clips(&args.file, args.clips.as_deref(), &Limits::default())?;
    let clip = match &args.clip {
        Some(name) => find_clip(&clips, name)?,
        None => clips.first().context("the character has no clips")?,
    };
    let options = CubemapOptions {
        resolution: args.resolution,
        shells: args.shells,
        times: args.times,
        rays: args.rays,
        ..CubemapOptions::default()
    };
    options.validate().map_err(anyhow::Error::msg)?;
    let poses: Vec<Pose> = (0..args.times)
        .map(|m| {
            let t = m as f32 * clip.duration / args.times as f32;
            Pose::sample(&character.skeleton, clip, t)
        })
        .collect();
    let frames: Vec<Vec<glam::Vec3>> = poses.iter().map(|p| character.skin(p).positions).collect();
    let spheroid = Spheroid::around(
        frames.iter().map(Vec::as_slice),
        options.outer,
        options.inner,
        options.shells,
    );
    let sampling = FaceSampling {
        spheroid,
        resolution: options.resolution,
        kroon: options.kroon(&spheroid, 0),
    };
    let points = (options.resolution * options.resolution * options.shells * options.times) as f64;
    let vertex_rays = (character.vertex_count() * poses.len()) as f64 * f64::from(args.rays);
    let surface = SurfaceParams {
        samples: args.rays,
        max_distance: sampling.kroon.max_distance,
        seed: 0,
        falloff: Falloff::None,
    };
    let mut face_rates = vec![Vec::new(); tracers.len()];
    let mut vertex_rates = vec![Vec::new(); tracers.len()];
    for run in 0..args.runs.repeat.max(1) {
        for (t, (name, engine)) in tracers.iter().enumerate() {
            aobake_core::trace::engine::set_engine(engine.clone());
            let started = Instant::now();
            let mut field = FaceField::new(options.resolution, options.shells, options.times);
            let mut parts = 0usize;
            compute_face::<()>(
                &sampling,
                0,
                &character.triangles,
                &mut |m| frames[m].clone(),
                &mut field,
                0,
                &mut |_, _| {
                    parts += 1;
                    Ok(())
                },
            )
            .map_err(|e| anyhow::anyhow!("{e}"))?;
            let face_s = started.elapsed().as_secs_f64();
            let started = Instant::now();
            trace_poses(
                &character,
                &poses,
                &SceneOptions::default(),
                &surface,
                &no_progress,
            )?;
            let vertex_s = started.elapsed().as_secs_f64();
            let face_rate = points * f64::from(args.rays) / face_s / 1e9;
            let vertex_rate = vertex_rays / vertex_s / 1e9;
            if super::casts_rays(name) {
                println!(
                    "run {} ({name}): face {face_s:.2} s ({:.1} Mrays/s, {parts} checkpoints), vertices {vertex_s:.2} s ({:.1} Mrays/s)",
                    run + 1,
                    face_rate * 1e3,
                    vertex_rate * 1e3
                );
            } else {
                println!(
                    "run {} ({name}): no rays cast: face {face_s:.2} s ({parts} checkpoints), vertices {vertex_s:.2} s",
                    run + 1,
                );
            }
            face_rates[t].push(face_rate);
            vertex_rates[t].push(vertex_rate);
        }
    }
    aobake_core::trace::engine::set_engine(None);
    println!(
        "{}: {} vertices, clip {} ({:.2} s); face {}² × {} shells × {} times, {} rays per point",
        args.file.display(),
        character.vertex_count(),
        clip.name,
        clip.duration,
        options.resolution,
        options.shells,
        options.times,
        args.rays
    );
    super::compare_tracers("face job", &tracers, &face_rates);
    super::compare_tracers("vertex tracer, same poses", &tracers, &vertex_rates);
    super::tracer_summaries(&tracers);
    for ((name, _), rates) in tracers
        .iter()
        .zip(&face_rates)
        .filter(|((name, _), _)| super::casts_rays(name))
    {
        let full = CubemapOptions::default().points() as f64 * f64::from(args.rays)
            / (median(rates) * 1e9);
        println!(
            "a default bake's faces (6 × 128² × 8 × 255 points, {} rays each) at the {name} face rate: {full:.0} s",
            args.rays
        );
    }
    Ok(())
}
