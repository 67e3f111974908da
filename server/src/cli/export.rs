//! `aobake export`: a baked asset's data in formats other tools read, and
//! the run-time shaders in the languages engines use (`--shaders DIR`,
//! `aobake_shaders::export`).
//!
//! `--gltf OUT.glb` writes the character a vertex asset was baked for
//! (`FILE`) with the AO as vertex attributes and the per-pose step in the
//! root's `extras.aobake` (`aobake_core::asset::gltf`, `docs/engines.md`);
//! a texel asset's character re-indexed over its atlas, the static AO as
//! each material's `occlusionTexture` and the basis textures as images.
//!
//! `--exr DIR` writes a cubemap asset's decoded faces as OpenEXR (the
//! `exr` crate): one file per clip time and shell, `t{time}-shell{k}.exr`,
//! a strip of the six faces side by side (+x, −x, +y, −y, +z, −z, each
//! `resolution` texels square, rows top to bottom as the cube-map
//! convention has them) in one 32-bit float channel `Y`: the occlusion,
//! 0 open and 1 blocked, decoded at each texel's centre exactly as the
//! run time decodes it; with a static ground, its texture as
//! `ground-offsets.exr` (as for grids, below).
//!
//! A grid asset's parts are written as one file per part,
//! `part{k}-{name}.exr`, its z-slices stacked top to bottom (slice z in
//! rows z·n .. (z + 1)·n, +y up within a slice, +x left to right), in the
//! channel `ao_grid` (the stored 2·ao′, 0..2) and, with cones, `axis.x`,
//! `axis.y`, `axis.z` (the average occluded direction in the part's bind
//! space), each exactly the value the run time reads at the cell; with a
//! static base, its ground texture as `ground-offsets.exr` (channel
//! `offset`, texel (x, z) at pixel (x, z)).

use super::common::refused;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use aobake_core::{
    Limits,
    bake::{AssetUseError, BakedAsset},
    image::FloatImage,
};
use exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, SmallVec, Text,
    WritableImage as _,
};

/// Arguments of `aobake export`.
#[derive(Debug, clap::Args)]
#[command(group = clap::ArgGroup::new("what").required(true).multiple(true).args(["exr", "shaders", "gltf"]))]
pub(super) struct Args {
    /// The asset (from `aobake bake` or `aobake fetch`); `--exr` and
    /// `--gltf` need one.
    asset: Option<PathBuf>,
    /// The character the asset was baked for (.glb, or .gltf with its side
    /// files beside it); `--gltf` needs it.
    file: Option<PathBuf>,
    /// Write the character with the asset's AO as a GLB. A vertex asset:
    /// `_AO` (the AO averaged over the file's clips) and `COLOR_0` per
    /// vertex, the model's coefficient rows as `_AO_BASIS_k` (VEC4). A
    /// texel asset: the atlas as a new TEXCOORD set, the averaged AO as
    /// every material's standard occlusionTexture (shown by any glTF
    /// viewer), the basis textures as 16-bit PNGs. Both: the per-pose
    /// weights' numbers in the root's `extras.aobake` (see
    /// docs/engines.md).
    #[arg(long, requires_all = ["asset", "file"])]
    gltf: Option<PathBuf>,
    /// With --gltf: a second glTF file whose animations drive the
    /// character, bound to its nodes by name (as `aobake bake --clips`
    /// took them): `_AO` averages its clips' frames too, and they are
    /// written into the GLB as animations.
    #[arg(long, requires = "gltf")]
    clips: Option<PathBuf>,
    /// Write a cubemap asset's decoded faces, a grid asset's parts as
    /// z-slices, or a texel asset's coefficient textures (`texel-ao.exr`,
    /// a channel per row), as OpenEXR files into this folder (created if
    /// missing), and the static ground's texture, when the asset has one.
    #[arg(long, requires = "asset")]
    exr: Option<PathBuf>,
    /// Clip times (seconds) to decode at; default: the start of the
    /// cycle.
    #[arg(long, num_args = 1.., default_values_t = [0.0f32])]
    times: Vec<f32>,
    /// Write the run-time evaluators (vertex AO, cubemap and grid
    /// lookups) for engines into this folder: GLSL 4.50 and ES 3.10, HLSL
    /// for shader models 5.1 and 6.0, MSL 2.1 and SPIR-V 1.3; all three
    /// also as vertex shaders reading textures (`*_vs`), in every language
    /// and in GLSL ES 3.00 for WebGL2. Translated by naga from the WGSL the
    /// previews run (no asset needed; see docs/engines.md).
    #[arg(long)]
    shaders: Option<PathBuf>,
}

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    if let Some(dir) = &args.shaders {
        write_shaders(dir)?;
    }
    if let (Some(asset), Some(exr)) = (&args.asset, &args.exr) {
        export_exr(asset, exr, &args.times)?;
    }
    match (&args.asset, &args.file, &args.gltf) {
        (Some(asset), Some(file), Some(out)) => {
            export_gltf(asset, file, args.clips.as_deref(), out)
        }
        _ => Ok(()),
    }
}

/// `--gltf OUT.glb`: the character with the asset's AO.
fn export_gltf(asset: &Path, file: &Path, clips: Option<&Path>, out: &Path) -> anyhow::Result<()> {
    let (_, container) = super::common::read_asset(asset, Some(file))?;
    let limits = Limits::default();
    let upload = super::load::upload(file, &limits)?;
    let clips = clips.map(|c| super::load::upload(c, &limits)).transpose()?;
    let export = aobake_core::asset::gltf::export_gltf(
        upload.upload(),
        clips.as_ref().map(|c| c.upload()),
        &limits,
        &container,
    )
    .with_context(|| format!("cannot export {} with {}", file.display(), asset.display()))?;
    for w in &export.warnings {
        eprintln!("warning: {w}");
    }
    // The vertex counts agree (or the export would have failed), but a
    // different upload may still be another mesh with as many vertices.
    let header: serde_json::Value = serde_json::from_str(&container.header).unwrap_or_default();
    if let Some(baked_for) = header["character"].as_str() {
        let digest = upload.digest();
        if digest != baked_for {
            eprintln!(
                "warning: {} was baked for another character upload ({}…; {} is {}…): the vertex counts agree, so its AO is written, but check that this is the same mesh",
                asset.display(),
                baked_for.get(..12).unwrap_or(baked_for),
                file.display(),
                &digest[..12]
            );
        }
    }
    std::fs::write(out, &export.glb).with_context(|| format!("cannot write {}", out.display()))?;
    eprintln!(
        "wrote {} ({} bytes): {}",
        out.display(),
        export.glb.len(),
        export.summary
    );
    Ok(())
}

/// `--shaders DIR`: every run-time evaluator in every target, one folder
/// per target, with each evaluator's binding table beside it.
fn write_shaders(dir: &Path) -> anyhow::Result<()> {
    let files = aobake_shaders::export::export_all()?;
    let tables = aobake_shaders::export::binding_tables()?;
    for f in files.iter().chain(&tables) {
        let path = dir.join(&f.path);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("cannot create {}", parent.display()))?;
        }
        std::fs::write(&path, &f.bytes)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    let targets: Vec<&str> = aobake_shaders::export::Target::ALL
        .iter()
        .map(|t| t.dir())
        .collect();
    eprintln!(
        "wrote {} shader files into {} ({}), each shader's bindings beside it (NAME.bindings.md: set, binding, its name there, type, what to put there)",
        files.len(),
        dir.display(),
        targets.join(", ")
    );
    Ok(())
}

/// `--exr DIR`: a cubemap's faces or a grid's parts as OpenEXR.
fn export_exr(asset: &Path, exr: &Path, times: &[f32]) -> anyhow::Result<()> {
    let (_, container) = super::common::read_asset(asset, None)?;
    if let Some(t) = times.iter().find(|t| !t.is_finite()) {
        bail!("--times must be finite numbers of seconds, not {t}");
    }
    let images = match BakedAsset::read(&container, None).and_then(|b| b.images(times)) {
        Ok(images) => images,
        Err(AssetUseError::Unsupported(e)) => {
            return Err(refused(format!(
                "{} holds a {} asset: --exr exports cubemap, grid and texel assets ({e})",
                asset.display(),
                container.method
            )));
        }
        Err(e) => return Err(refused(format!("cannot read {}: {e}", asset.display()))),
    };
    std::fs::create_dir_all(exr).with_context(|| format!("cannot create {}", exr.display()))?;
    for image in &images {
        write_exr(image, &exr.join(&image.file))?;
    }
    eprintln!(
        "wrote {} OpenEXR files of the {} asset into {}",
        images.len(),
        container.method,
        exr.display()
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
