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
    bake::{AssetUseError, BakedAsset},
    image::FloatImage,
};
use exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, SmallVec, Text,
    WritableImage as _,
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
    if let Some(t) = args.times.iter().find(|t| !t.is_finite()) {
        bail!("--times must be finite numbers of seconds, not {t}");
    }
    let images = match BakedAsset::read(&container, None).and_then(|b| b.images(&args.times)) {
        Ok(images) => images,
        Err(AssetUseError::Unsupported(e)) => bail!(
            "{} holds a {} asset: --exr exports cubemap and grid assets ({e})",
            args.asset.display(),
            container.method
        ),
        Err(e) => bail!("cannot read {}: {e}", args.asset.display()),
    };
    std::fs::create_dir_all(&args.exr)
        .with_context(|| format!("cannot create {}", args.exr.display()))?;
    for image in &images {
        write_exr(image, &args.exr.join(&image.file))?;
    }
    eprintln!(
        "wrote {} OpenEXR files of the {} asset into {}",
        images.len(),
        container.method,
        args.exr.display()
    );
    Ok(())
}

/// One image as an OpenEXR file of 32-bit float channels.
fn write_exr(image: &FloatImage, path: &Path) -> anyhow::Result<()> {
    let channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = image
        .channels
        .iter()
        .map(|(name, values)| AnyChannel::new(name.as_str(), FlatSamples::F32(values.clone())))
        .collect();
    let mut attributes = LayerAttributes::named(image.layer.as_str());
    attributes.comments = Some(Text::from(image.comment.as_str()));
    let layer = Layer::new(
        (image.width, image.height),
        attributes,
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(channels),
    );
    Image::from_layer(layer)
        .write()
        .to_file(path)
        .with_context(|| format!("cannot write {}", path.display()))
}
