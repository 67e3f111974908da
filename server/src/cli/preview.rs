//! `aobake preview`: a baked asset rendered locally with wgpu, as the
//! service's `preview` job renders it: a still of one clip time (the
//! ray-traced ground truth, the model, and the error) or an animated PNG
//! of a whole clip (the model beside the ground truth).

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use aobake_core::{
    Limits,
    asset::Container,
    bake::{BakeParams, preview::Subject},
    method::vertex::Model,
};
use aobake_worker::gpu::{Gpu, PreviewRenderer};

use super::posing::{character_and_clips, find_clip};

/// Arguments of `aobake preview`.
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("when").required(true).args(["time", "animate"])))]
pub(super) struct Args {
    /// The asset (from `aobake bake` or `aobake fetch`).
    asset: PathBuf,
    /// The character it was baked for.
    file: PathBuf,
    /// A second glTF file whose animations drive the character, bound to
    /// its nodes by name. Its clips are searched before the character's.
    #[arg(long)]
    clips: Option<PathBuf>,
    /// The clip to show (see `aobake inspect`).
    #[arg(long)]
    clip: String,
    /// A still at this time in the clip, in seconds: ground truth, model
    /// and error side by side.
    #[arg(long, allow_negative_numbers = true)]
    time: Option<f32>,
    /// An animated PNG of the whole clip instead, model beside ground
    /// truth.
    #[arg(long)]
    animate: bool,
    /// Where to write the PNG.
    #[arg(long)]
    out: PathBuf,
}

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let bytes = std::fs::read(&args.asset)
        .with_context(|| format!("cannot read {}", args.asset.display()))?;
    let container = Container::from_bytes(&bytes)
        .with_context(|| format!("cannot read {}", args.asset.display()))?;
    let (model, header) = Model::from_container(&container)
        .with_context(|| format!("cannot read {}", args.asset.display()))?;
    // The ground truth is traced as the bake traced its held-out poses.
    let params: BakeParams = serde_json::from_value(header.params.clone())
        .unwrap_or_else(|_| BakeParams::new(header.method));
    let (character, clips) =
        character_and_clips(&args.file, args.clips.as_deref(), &Limits::default())?;
    if let Err(e) = model.check_character(&character) {
        bail!(
            "{} does not fit {}: {e} (character {})",
            args.asset.display(),
            args.file.display(),
            header.character
        );
    }
    let clip = find_clip(&clips, &args.clip)?;
    let gpu = Gpu::shared().context("no GPU adapter for the preview")?;
    let mut renderer = PreviewRenderer::new(gpu)?;
    let subject = Subject {
        character: &character,
        model: &model,
        surface: params.held_out_surface(),
    };
    let preview = match args.time {
        Some(t) if !t.is_finite() => bail!("--time must be a finite number of seconds"),
        Some(t) => subject.stills(Some(clip), &[t], &mut renderer)?.remove(0),
        None => subject.animation(clip, &mut renderer)?,
    };
    std::fs::write(&args.out, &preview.png)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    let i = &preview.info;
    eprintln!(
        "wrote {}: {}×{} {}{}; {:.1} ms per panel on {} ({}× MSAA), ground truth traced in {:.2} s",
        args.out.display(),
        i.width,
        i.height,
        i.kind,
        if i.kind == "animation" {
            format!(" of {} frames", i.times.len())
        } else {
            String::new()
        },
        i.frame_ms,
        i.adapter,
        renderer.samples(),
        i.trace_s
    );
    Ok(())
}
