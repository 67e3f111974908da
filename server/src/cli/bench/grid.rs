//! `aobake bench grid`: the speed of a grid slab (Malmer et al.'s Eq. 5,
//! full-sphere rays from every cell centre of a part's grid), on each
//! tracer in turn within a run, so that drift in machine speed hits all
//! alike.

use std::path::PathBuf;
use std::time::Instant;

use aobake_core::{
    Limits,
    method::grid::field::{RawCell, around, part_scene, trace_layers},
    trace::{TraceError, VolumeParams},
};

use crate::cli::common::character_and_clips;

/// Arguments of `aobake bench grid`.
#[derive(Debug, clap::Args)]
pub(super) struct Args {
    /// The character (.glb or .gltf): its whole bind-pose mesh is the part.
    file: PathBuf,
    /// Cells per grid edge (the default bake has 32).
    #[arg(long, default_value_t = 32)]
    resolution: usize,
    /// Rays per cell (the default bake has 256).
    #[arg(long, default_value_t = 256)]
    rays: u32,
    #[command(flatten)]
    runs: super::TracerRuns,
}

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let tracers = super::bench_tracers(&args.runs.tracer)?;
    let (character, _) = character_and_clips(&args.file, None, &Limits::default())?;
    let positions = &character.positions;
    // The grid method's defaults: Eq. 4's ε = 0.1 and no distance limit.
    let grid = around(positions, 0.1, args.resolution);
    let scene = part_scene(positions, &character.triangles)?;
    let params = VolumeParams {
        samples: args.rays,
        max_distance: f32::INFINITY,
        seed: 1,
    };
    let n = args.resolution;
    let rays = (n * n * n) as f64 * f64::from(args.rays);
    println!(
        "{}: {} vertices, {} triangles as one part; {n}³ cells, {} rays each ({:.1} M rays a slab of every layer)",
        args.file.display(),
        character.vertex_count(),
        character.triangles.len(),
        args.rays,
        rays / 1e6
    );
    let mut rates = vec![Vec::new(); tracers.len()];
    let mut cells: Vec<Vec<RawCell>> = vec![Vec::new(); tracers.len()];
    for run in 0..args.runs.repeat.max(1) {
        for (t, (name, engine)) in tracers.iter().enumerate() {
            aobake_core::trace::engine::set_engine(engine.clone());
            let started = Instant::now();
            let mut traced = Vec::with_capacity(n * n * n);
            trace_layers::<TraceError>(&scene, &grid, 0, 0..n, params, &mut |_, layer| {
                traced.extend(layer);
                Ok(())
            })?;
            let seconds = started.elapsed().as_secs_f64();
            if super::casts_rays(name) {
                println!(
                    "run {} ({name}): {seconds:.3} s, {:.1} Mrays/s",
                    run + 1,
                    rays / seconds / 1e6
                );
            } else {
                println!("run {} ({name}): no rays cast: {seconds:.3} s", run + 1);
            }
            rates[t].push(rays / seconds / 1e9);
            cells[t] = traced;
        }
    }
    aobake_core::trace::engine::set_engine(None);
    super::compare_tracers("grid slab", &tracers, &rates);
    super::tracer_summaries(&tracers);
    // The same rays: cells whose occluded fraction differs.
    for ((name, _), other) in tracers
        .iter()
        .zip(&cells)
        .skip(1)
        .filter(|((name, _), _)| super::casts_rays(name))
    {
        let differ = other
            .iter()
            .zip(&cells[0])
            .filter(|(a, b)| a.occlusion != b.occlusion || a.inside != b.inside)
            .count();
        println!(
            "cells {name} against {}: {differ} of {} differ",
            tracers[0].0,
            other.len()
        );
    }
    Ok(())
}
