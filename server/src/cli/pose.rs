//! `aobake pose`.

use std::path::PathBuf;

use anyhow::Context as _;
use aobake_core::{Limits, import::ply};

use super::common::{PoseArgs, pose};

/// Arguments of `aobake pose`.
#[derive(Debug, clap::Args)]
pub(super) struct Args {
    /// The character (.glb, or .gltf with its buffers beside it).
    file: PathBuf,
    #[command(flatten)]
    pose: PoseArgs,
    /// Output PLY file.
    #[arg(long)]
    out: PathBuf,
    /// Write ASCII PLY instead of binary little-endian.
    #[arg(long)]
    ascii: bool,
}

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let posed = pose(&args.file, &args.pose, &Limits::default())?;
    let encoding = if args.ascii {
        ply::Encoding::Ascii
    } else {
        ply::Encoding::Binary
    };
    let triangles = &posed.character.triangles;
    let bytes = ply::write(
        &posed.mesh.positions,
        &posed.mesh.normals,
        triangles,
        encoding,
    );
    std::fs::write(&args.out, bytes)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    eprintln!(
        "wrote {} ({} vertices, {} triangles)",
        args.out.display(),
        posed.mesh.positions.len(),
        triangles.len()
    );
    Ok(())
}
