//! `aobake export`: a baked asset's data in formats other tools read.
//! `--exr DIR` writes a cubemap asset's decoded faces as OpenEXR (the
//! `exr` crate): one file per clip time and shell, `t{time}-shell{k}.exr`,
//! a strip of the six faces side by side (+x, −x, +y, −y, +z, −z, each
//! `resolution` texels square, rows top to bottom as the cube-map
//! convention has them) in one 32-bit float channel `Y`: the occlusion,
//! 0 open and 1 blocked, decoded at each texel's centre exactly as the
//! run time decodes it.
//!
//! A grid asset's parts are written as one file per part,
//! `part{k}-{name}.exr`, its z-slices stacked top to bottom (slice z in
//! rows z·n .. (z + 1)·n, +y up within a slice, +x left to right), in the
//! channel `ao_grid` (the stored 2·ao′, 0..2) and, with cones, `axis.x`,
//! `axis.y`, `axis.z` (the average occluded direction in the part's bind
//! space), each exactly the value the run time reads at the cell.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use aobake_core::{
    asset::Container,
    method::{
        Family,
        cubemap::geometry::FACES,
        cubemap::model::CubemapModel,
        grid::model::{GridModel, PartGrid},
    },
};
use exr::prelude::{
    Encoding, Image, Layer, LayerAttributes, SpecificChannels, Text, WritableImage as _,
};

/// Arguments of `aobake export`.
#[derive(Debug, clap::Args)]
pub(super) struct Args {
    /// The asset (from `aobake bake` or `aobake fetch`).
    asset: PathBuf,
    /// Write a cubemap asset's decoded faces, or a grid asset's parts as
    /// z-slices, as OpenEXR files into this folder (created if missing).
    #[arg(long)]
    exr: PathBuf,
    /// Clip times (seconds) to decode at; default: the start of the
    /// cycle.
    #[arg(long, num_args = 1.., default_values_t = [0.0f32])]
    times: Vec<f32>,
}

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let bytes = std::fs::read(&args.asset)
        .with_context(|| format!("cannot read {}", args.asset.display()))?;
    let container = Container::from_bytes(&bytes)
        .with_context(|| format!("cannot read {}", args.asset.display()))?;
    match container.method.family() {
        Family::Grid => return grids(args, &container),
        Family::Vertex => bail!(
            "{} holds a {} asset: --exr exports cubemap and grid assets (per-vertex AO has no image to export)",
            args.asset.display(),
            container.method
        ),
        Family::Cubemap => {}
    }
    let (model, header) = CubemapModel::from_container(&container)
        .with_context(|| format!("cannot read {}", args.asset.display()))?;
    if let Some(t) = args.times.iter().find(|t| !t.is_finite()) {
        bail!("--times must be finite numbers of seconds, not {t}");
    }
    std::fs::create_dir_all(&args.exr)
        .with_context(|| format!("cannot create {}", args.exr.display()))?;
    let mut written = 0;
    for &t in &args.times {
        for shell in 0..model.layout.spheroid.shells {
            let path = args.exr.join(format!("t{t:.3}-shell{shell}.exr"));
            write_strip(&model, t, shell, &header.clip, &path)?;
            written += 1;
        }
    }
    eprintln!(
        "wrote {written} OpenEXR files ({} time(s) × {} shells) of {}² texels × 6 faces into {}",
        args.times.len(),
        model.layout.spheroid.shells,
        model.layout.resolution,
        args.exr.display()
    );
    Ok(())
}

/// The six faces of `shell` at clip time `t` side by side.
fn write_strip(
    model: &CubemapModel,
    t: f32,
    shell: usize,
    clip: &str,
    path: &Path,
) -> anyhow::Result<()> {
    let res = model.layout.resolution;
    let phase = model.layout.phase(t);
    let faces: Vec<Vec<f32>> = (0..FACES)
        .map(|face| model.decode_face(face, shell, phase))
        .collect();
    let pixels = SpecificChannels::build()
        .with_channel("Y")
        .with_pixel_fn(|p| {
            let (face, i, j) = (p.x() / res, p.x() % res, p.y());
            (faces[face][j * res + i],)
        });
    let mut attributes = LayerAttributes::named(format!("shell {shell}").as_str());
    attributes.comments = Some(Text::from(
        format!(
            "aobake {}: occlusion (0 open, 1 blocked) of clip {clip} at t = {t} s (phase {phase:.4}) on shell {shell}; faces +x -x +y -y +z -z left to right",
            model.method()
        )
        .as_str(),
    ));
    let layer = Layer::new(
        (FACES * res, res),
        attributes,
        Encoding::FAST_LOSSLESS,
        pixels,
    );
    Image::from_layer(layer)
        .write()
        .to_file(path)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Every part of a grid asset as a file of z-slices.
fn grids(args: &Args, container: &Container) -> anyhow::Result<()> {
    let (model, _) = GridModel::from_container(container)
        .with_context(|| format!("cannot read {}", args.asset.display()))?;
    std::fs::create_dir_all(&args.exr)
        .with_context(|| format!("cannot create {}", args.exr.display()))?;
    for (k, part) in model.parts.iter().enumerate() {
        let path = args.exr.join(grid_file_name(k, &part.name));
        write_slices(part, &path)?;
    }
    eprintln!(
        "wrote {} OpenEXR files (one per part, z-slices top to bottom{}) into {}",
        model.parts.len(),
        if model.cones() {
            ", with the cone axes"
        } else {
            ""
        },
        args.exr.display()
    );
    Ok(())
}

/// `part{k}-{name}.exr`, the name reduced to letters, digits, `-` and `_`.
fn grid_file_name(k: usize, name: &str) -> String {
    let safe: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .take(64)
        .collect();
    format!("part{k}-{safe}.exr")
}

/// One part's cells as stacked z-slices.
fn write_slices(part: &PartGrid, path: &Path) -> anyhow::Result<()> {
    let n = part.grid.resolution;
    let cell = |x: usize, y: usize| {
        let (z, row) = (y / n, y % n);
        (z * n + (n - 1 - row)) * n + x
    };
    let occlusion = |i: usize| 2.0 * f32::from(part.occlusion[i]) / 255.0;
    let mut attributes = LayerAttributes::named(part.name.as_str());
    attributes.comments = Some(Text::from(
        format!(
            "aobake grid: part {} ({n}^3 cells); ao_grid = 2 x occluded fraction of the sphere; z-slices top to bottom, +y up, +x right; axis in the part's bind space",
            part.name
        )
        .as_str(),
    ));
    let size = (n, n * n);
    let written = match &part.directions {
        None => Image::from_layer(Layer::new(
            size,
            attributes,
            Encoding::FAST_LOSSLESS,
            SpecificChannels::build()
                .with_channel("ao_grid")
                .with_pixel_fn(|p| (occlusion(cell(p.x(), p.y())),)),
        ))
        .write()
        .to_file(path),
        Some(d) => {
            let axis = |i: usize, c: usize| f32::from(d[i][c]) / 255.0 * 2.0 - 1.0;
            Image::from_layer(Layer::new(
                size,
                attributes,
                Encoding::FAST_LOSSLESS,
                SpecificChannels::build()
                    .with_channel("ao_grid")
                    .with_channel("axis.x")
                    .with_channel("axis.y")
                    .with_channel("axis.z")
                    .with_pixel_fn(|p| {
                        let i = cell(p.x(), p.y());
                        (occlusion(i), axis(i, 0), axis(i, 1), axis(i, 2))
                    }),
            ))
            .write()
            .to_file(path)
        }
    };
    written.with_context(|| format!("cannot write {}", path.display()))
}
