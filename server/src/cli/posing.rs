//! Choosing a pose on the command line: `FILE [--clips FILE] [--clip NAME
//! --time T]`, shared by the commands that pose a character.

use std::path::{Path, PathBuf};

use anyhow::bail;
use aobake_core::{Character, Limits, Pose, PosedMesh};

/// Which pose of a character: a clip time, or the bind pose.
#[derive(Debug, clap::Args)]
pub(super) struct PoseArgs {
    /// A second glTF file whose animations drive the character, bound to its
    /// nodes by name. Its clips are searched before the character's own.
    #[arg(long)]
    pub clips: Option<PathBuf>,
    /// Clip name (see `aobake inspect`). Without it the bind pose is used:
    /// the mesh as modelled.
    #[arg(long, requires = "time")]
    pub clip: Option<String>,
    /// Time in the clip, in seconds. Before the first key the first key
    /// holds, after the last key the last one.
    #[arg(long, requires = "clip", allow_negative_numbers = true)]
    pub time: Option<f32>,
}

/// A character skinned in the chosen pose.
#[derive(Debug)]
pub(super) struct Posed {
    pub character: Character,
    pub mesh: PosedMesh,
    pub pose: Pose,
}

/// Imports `file` and skins it in the pose `args` selects.
pub(super) fn pose(file: &Path, args: &PoseArgs, limits: &Limits) -> anyhow::Result<Posed> {
    let imported = super::load::character(file, limits)?;
    let mut clips = Vec::new();
    if let Some(path) = &args.clips {
        let (extra, warnings) = super::load::clips(path, &imported, limits)?;
        for w in warnings {
            eprintln!("warning: {}: {w}", path.display());
        }
        clips.extend(extra);
    }
    clips.extend(imported.clips.iter().cloned());
    let character = imported.character;
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
        _ => Pose::bind(&character),
    };
    let mesh = character.skin(&pose);
    Ok(Posed {
        character,
        mesh,
        pose,
    })
}
