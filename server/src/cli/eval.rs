//! `aobake eval`: a baked asset evaluated at a pose, as an engine would at
//! run time, written as CSV.

use super::common::refused;
use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context as _;
use aobake_core::{
    Limits,
    asset::Container,
    bake::{AssetUseError, BakedAsset},
};

use super::common::{PoseArgs, pose};

/// Arguments of `aobake eval`.
#[derive(Debug, clap::Args)]
pub(super) struct Args {
    /// The asset (from `aobake bake`).
    asset: PathBuf,
    /// The character it was baked for.
    file: PathBuf,
    #[command(flatten)]
    pose: PoseArgs,
    /// Output CSV: `index,occlusion` per vertex (0 = open, 1 = blocked).
    #[arg(long)]
    out: PathBuf,
}

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let (_, container) = super::common::read_asset(&args.asset, Some(&args.file))?;
    let posed = pose(&args.file, &args.pose, &Limits::default())?;
    let character = &posed.character;
    let values = BakedAsset::read(&container, Some(character))
        .and_then(|baked| baked.vertex_ao(character, &posed.pose, &posed.mesh))
        .or_else(|e| refuse(args, &container, e))?;
    let mut csv = String::with_capacity(values.len() * 16 + 16);
    csv.push_str("index,occlusion\n");
    for (i, v) in values.iter().enumerate() {
        let _ = writeln!(csv, "{i},{v}");
    }
    std::fs::write(&args.out, csv)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    eprintln!(
        "wrote {}: {} vertices, {} asset (format {}.{})",
        args.out.display(),
        values.len(),
        container.method.name(),
        container.version.0,
        container.version.1
    );
    Ok(())
}

/// Why the asset gives no per-vertex AO for this character, naming both.
fn refuse<T>(args: &Args, container: &Container, e: AssetUseError) -> anyhow::Result<T> {
    let (asset, file) = (args.asset.display(), args.file.display());
    Err(refused(match e {
        AssetUseError::Unreadable(e) => format!("cannot read {asset}: {e}"),
        AssetUseError::Mismatch(e) => match other_character(args, container) {
            Some(note) => format!("{asset} does not fit {file}: {note} ({e})"),
            None => format!("{asset} does not fit {file}: {e}"),
        },
        AssetUseError::Unsupported(e) => format!("{asset} is a {} asset: {e}", container.method),
    }))
}

/// Why, when the asset names another character upload than `args.file`
/// (a GLB's digest is its bytes'): the likely cause of a mismatch, put
/// before any advice about how the asset was baked.
fn other_character(args: &Args, container: &Container) -> Option<String> {
    let header: serde_json::Value = serde_json::from_str(&container.header).ok()?;
    let baked_for = header["character"].as_str()?;
    let bytes = std::fs::read(&args.file)
        .ok()
        .filter(|b| b.starts_with(b"glTF"))?;
    let digest = aobake_core::digest::sha256_hex(&bytes);
    (digest != baked_for).then(|| {
        format!(
            "it was baked for another character upload ({}…; {} is {}…)",
            baked_for.get(..12).unwrap_or(baked_for),
            args.file.display(),
            &digest[..12]
        )
    })
}
