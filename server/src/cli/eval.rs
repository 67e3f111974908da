//! `aobake eval`: a baked asset evaluated at a pose, as an engine would at
//! run time, written as CSV.

use aobake_core::method::Family;
use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context as _, bail};
use aobake_core::{Limits, asset::Container, method::vertex::Model};

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
    let bytes = std::fs::read(&args.asset)
        .with_context(|| format!("cannot read {}", args.asset.display()))?;
    let container = Container::from_bytes(&bytes)
        .with_context(|| format!("cannot read {}", args.asset.display()))?;
    match container.method.family() {
        Family::Cubemap => bail!(
            "{} is a {} asset: it holds the occlusion cast into space, not per-vertex AO; `aobake preview` renders it on the ground and `aobake export --exr` writes its faces",
            args.asset.display(),
            container.method
        ),
        Family::Grid => return grid(args, &container),
        Family::Vertex => {}
    }
    let (model, header) = Model::from_container(&container)
        .with_context(|| format!("cannot read {}", args.asset.display()))?;
    let limits = Limits::default();
    let posed = pose(&args.file, &args.pose, &limits)?;
    let character = &posed.character;
    if let Err(e) = model.check_character(character) {
        bail!(
            "{} does not fit {}: {e} (character {})",
            args.asset.display(),
            args.file.display(),
            header.character
        );
    }
    let values = model.evaluate(&character.skeleton, &posed.pose);
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
        header.method.name(),
        container.version.0,
        container.version.1
    );
    Ok(())
}

/// A grid asset at the vertices of the posed character: each vertex a
/// receiver on its own part, shaded by every part's grid (the run-time
/// lookup engines run).
fn grid(args: &Args, container: &Container) -> anyhow::Result<()> {
    use aobake_core::method::grid::{
        model::{GridModel, Terms},
        parts::{owners, parts},
    };
    let (model, header) = GridModel::from_container(container)
        .with_context(|| format!("cannot read {}", args.asset.display()))?;
    let posed = pose(&args.file, &args.pose, &Limits::default())?;
    let character = &posed.character;
    model
        .check_palette(character.joints.len())
        .with_context(|| {
            format!(
                "{} does not fit {}",
                args.asset.display(),
                args.file.display()
            )
        })?;
    let params = aobake_core::bake::BakeParams::from_canonical(&header.params)
        .context("the asset's parameters are unreadable")?;
    let found = parts(character, params.grid.parts)?;
    if found.len() != model.parts.len()
        || found
            .iter()
            .zip(&model.parts)
            .any(|(a, b)| a.joint != b.joint)
    {
        bail!(
            "{} does not fit {}: its parts are not the character's (character {})",
            args.asset.display(),
            args.file.display(),
            header.character
        );
    }
    let owner = owners(&found, character.vertex_count());
    let poses = model.poses(&character.joint_matrices(&posed.pose));
    let mut csv = String::with_capacity(character.vertex_count() * 16 + 16);
    csv.push_str("index,occlusion\n");
    for (i, (p, n)) in posed
        .mesh
        .positions
        .iter()
        .zip(&posed.mesh.normals)
        .enumerate()
    {
        let v = model.occlusion(&poses, *p, *n, owner[i], Terms::All);
        let _ = writeln!(csv, "{i},{v}");
    }
    std::fs::write(&args.out, csv)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    eprintln!(
        "wrote {}: {} vertices, grid asset of {} parts (format {}.{})",
        args.out.display(),
        character.vertex_count(),
        model.parts.len(),
        container.version.0,
        container.version.1
    );
    Ok(())
}
