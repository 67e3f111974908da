//! `aobake pose`.

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use aobake_core::{Limits, Pose, ply};

/// Arguments of `aobake pose`.
#[derive(Debug, clap::Args)]
pub(super) struct Args {
    /// The character (.glb, or .gltf with its buffers beside it).
    file: PathBuf,
    /// A second glTF file whose animations drive the character, bound to its
    /// nodes by name. Its clips are searched before the character's own.
    #[arg(long)]
    clips: Option<PathBuf>,
    /// Clip name (see `aobake inspect`). Without it the bind pose is
    /// written: the mesh as modelled.
    #[arg(long, requires = "time")]
    clip: Option<String>,
    /// Time in the clip, in seconds. Before the first key the first key
    /// holds, after the last key the last one.
    #[arg(long, requires = "clip", allow_negative_numbers = true)]
    time: Option<f32>,
    /// Output PLY file.
    #[arg(long)]
    out: PathBuf,
    /// Write ASCII PLY instead of binary little-endian.
    #[arg(long)]
    ascii: bool,
}

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let limits = Limits::default();
    let imported = super::load::character(&args.file, &limits)?;
    let mut clips = Vec::new();
    if let Some(path) = &args.clips {
        let (extra, warnings) = super::load::clips(path, &imported, &limits)?;
        for w in warnings {
            eprintln!("warning: {}: {w}", path.display());
        }
        clips.extend(extra);
    }
    clips.extend(imported.clips.iter().cloned());
    let character = &imported.character;
    let pose = match (&args.clip, args.time) {
        (Some(name), Some(time)) => {
            if !time.is_finite() {
                bail!("--time must be a finite number of seconds");
            }
            let Some(clip) = clips.iter().find(|c| &c.name == name) else {
                let names: Vec<&str> = clips.iter().map(|c| c.name.as_str()).collect();
                bail!(
                    "no clip named {name:?}; the clips are: {}",
                    if names.is_empty() {
                        "none".to_owned()
                    } else {
                        names.join(", ")
                    }
                );
            };
            Pose::sample(&character.skeleton, clip, time)
        }
        _ => Pose::bind(character),
    };
    let posed = character.skin(&pose);
    let encoding = if args.ascii {
        ply::Encoding::Ascii
    } else {
        ply::Encoding::Binary
    };
    let bytes = ply::write(
        &posed.positions,
        &posed.normals,
        &character.triangles,
        encoding,
    );
    std::fs::write(&args.out, bytes)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    eprintln!(
        "wrote {} ({} vertices, {} triangles)",
        args.out.display(),
        posed.positions.len(),
        character.triangles.len()
    );
    Ok(())
}
