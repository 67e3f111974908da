//! `aobake preview`: a baked asset rendered locally with wgpu, as the
//! service's `preview` job renders it: a still of one clip time (the
//! ray-traced ground truth, the model, and the error) or an animated PNG
//! of a whole clip (the model beside the ground truth).

use super::common::refused;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use aobake_core::{
    Character, Clip, Limits,
    bake::{AssetUseError, BakedAsset, preview::Subject},
    method::texel::atlas::{AtlasOptions, PADDING, TexelAtlas},
};
use aobake_worker::gpu::{Gpu, PreviewRenderer};

use super::common::{character_and_clips, find_clip};

/// Arguments of `aobake preview`.
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("when").required(true).args(["time", "animate"])))]
pub(super) struct Args {
    /// The asset (from `aobake bake` or `aobake fetch`).
    asset: PathBuf,
    /// The character it was baked for.
    file: PathBuf,
    /// A second glTF file whose animations drive the character, bound to
    /// its nodes by name. Its clips are searched before the character's
    /// own.
    #[arg(long)]
    clips: Option<PathBuf>,
    /// The clip to show (see `aobake inspect`).
    #[arg(long)]
    clip: String,
    /// A still at this time in the clip, in seconds: ground truth, model,
    /// screen-space AO (GTAO, what an engine computes without a bake) and
    /// the model's error side by side; the model and GTAO are measured
    /// against per-pixel ray-traced AO and printed.
    #[arg(long, allow_negative_numbers = true)]
    time: Option<f32>,
    /// An animated PNG of the whole clip instead, model beside ground
    /// truth.
    #[arg(long)]
    animate: bool,
    /// With --time: also measure the texel floor of a generated atlas of
    /// this side (texels): the ray-traced AO at its texel centres,
    /// filtered as a GPU filters the texture, against per-pixel
    /// ray-traced AO (the best any texture of that atlas can show).
    #[arg(long, value_name = "SIDE", requires = "time")]
    texel_floor: Option<u32>,
    /// Where to write the PNG.
    #[arg(long)]
    out: PathBuf,
}

/// An asset and the character it was baked for, loaded and checked.
struct Loaded {
    asset: BakedAsset,
    character: Character,
    clips: Vec<Clip>,
}

impl Loaded {
    fn new(asset: &Path, file: &Path, clips: Option<&Path>) -> anyhow::Result<Self> {
        let (_, container) = super::common::read_asset(asset, Some(file))?;
        let (character, clips) = character_and_clips(file, clips, &Limits::default())?;
        let baked = BakedAsset::read(&container, Some(&character)).map_err(|e| match e {
            AssetUseError::Mismatch(e) => refused(format!(
                "{} does not fit {}: {e}",
                asset.display(),
                file.display()
            )),
            e => refused(format!("cannot read {}: {e}", asset.display())),
        })?;
        Ok(Self {
            asset: baked,
            character,
            clips,
        })
    }

    /// A generated atlas of `side` texels of the character's bind pose.
    fn atlas(&self, side: u32) -> anyhow::Result<TexelAtlas> {
        TexelAtlas::of_character(
            &self.character,
            &AtlasOptions {
                size: side,
                padding: PADDING,
            },
        )
        .context("cannot measure the texel floor")
    }

    fn subject(&self) -> anyhow::Result<Subject<'_>> {
        let (model, surface) = self.asset.preview_model()?;
        Ok(Subject::new(&self.character, model, surface))
    }
}

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let loaded = Loaded::new(&args.asset, &args.file, args.clips.as_deref())?;
    let clip = find_clip(&loaded.clips, &args.clip)?;
    if let Some(baked) = loaded.asset.clip().filter(|&c| c != args.clip) {
        bail!(
            "{} holds cubemaps of clip {baked:?}: they darken the world as that clip plays, not {:?}; preview it with --clip {baked:?}",
            args.asset.display(),
            args.clip
        );
    }
    if args.texel_floor.is_some() && loaded.asset.is_texel() {
        bail!(
            "{} is a texel asset: its stills measure the floor of its own atlas already (\"texel truth\"); --texel-floor measures another atlas beside a vertex, grid or cubemap asset",
            args.asset.display()
        );
    }
    let gpu = Gpu::shared().context("no GPU adapter for the preview")?;
    let mut renderer = PreviewRenderer::new(gpu)?;
    let atlas = args
        .texel_floor
        .map(|side| loaded.atlas(side))
        .transpose()?;
    let subject = Subject {
        texel_floor: atlas.as_ref(),
        ..loaded.subject()?
    };
    let preview = match args.time {
        Some(t) if !t.is_finite() => bail!("--time must be a finite number of seconds"),
        Some(t) => subject
            .stills(Some(clip), &[t], None, &mut renderer)?
            .remove(0),
        None => subject.animation(clip, None, &mut renderer)?,
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
    if let Some(screen) = &i.screen_space {
        eprint!(
            "the screen-space baseline (GTAO, panel 3) beside the model:\n{}",
            screen.summary()
        );
    }
    Ok(())
}

/// Arguments of `aobake bench preview`.
#[derive(Debug, clap::Args)]
pub(super) struct BenchArgs {
    /// The asset.
    asset: PathBuf,
    /// The character it was baked for.
    file: PathBuf,
    /// A second glTF file with clips.
    #[arg(long)]
    clips: Option<PathBuf>,
    /// The clip (default: the first).
    #[arg(long)]
    clip: Option<String>,
    /// Timed runs per adapter (medians are quoted).
    #[arg(long, default_value_t = 5)]
    runs: usize,
    /// Also the texel floor of generated atlases of these sides (texels,
    /// comma-separated) at the still, against the per-vertex floor and
    /// GTAO.
    #[arg(long, value_name = "SIDES", value_delimiter = ',')]
    texel_floor: Vec<u32>,
}

/// Milliseconds per rendered panel of a still (4 panels) and of an
/// animation, on every adapter the machine has among Vulkan and GL, runs
/// interleaved so that drift in machine speed hits all alike.
pub(super) fn bench(args: &BenchArgs) -> anyhow::Result<()> {
    let loaded = Loaded::new(&args.asset, &args.file, args.clips.as_deref())?;
    let clip = match &args.clip {
        Some(name) => find_clip(&loaded.clips, name)?,
        None => loaded.clips.first().context("the character has no clips")?,
    };
    let subject = loaded.subject()?;
    let mut adapters = Vec::new();
    for backends in [wgpu_backends::VULKAN, wgpu_backends::GL] {
        match Gpu::with_backends(backends) {
            Ok(gpu) => adapters.push(gpu),
            Err(e) => eprintln!("{backends:?}: {e}"),
        }
    }
    // An adapter whose backend cannot build the preview's pipelines (a GL
    // context without storage buffers in fragment shaders, say) is
    // skipped with the reason.
    let mut renderers: Vec<PreviewRenderer<'_>> = adapters
        .iter()
        .filter_map(|gpu| match PreviewRenderer::new(gpu) {
            Ok(r) => Some(r),
            Err(e) => {
                eprintln!("skipping {}: {e}", gpu.label());
                None
            }
        })
        .collect();
    if renderers.is_empty() {
        bail!("no adapter to render with");
    }
    let mut stills = vec![Vec::new(); renderers.len()];
    let mut frames = vec![Vec::new(); renderers.len()];
    let mut gtao = vec![Vec::new(); renderers.len()];
    let mut model = vec![Vec::new(); renderers.len()];
    let mut comparison = None;
    let still_time = 0.5 * clip.duration;
    for run in 0..args.runs.max(1) {
        for (i, r) in renderers.iter_mut().enumerate() {
            let s = subject
                .stills(Some(clip), &[still_time], None, r)?
                .remove(0);
            let a = subject.animation(clip, None, r)?;
            // The first run includes shader compilation and warm-up.
            if run > 0 || args.runs <= 1 {
                stills[i].push(s.info.frame_ms);
                frames[i].push(a.info.frame_ms);
                if let Some(screen) = &s.info.screen_space {
                    gtao[i].push(screen.gtao_ms);
                    model[i].push(screen.model_ms);
                }
            }
            if comparison.is_none() {
                comparison = s.info.screen_space;
            }
        }
    }
    println!(
        "{}: {} vertices, {} triangles; clip {} ({} animation frames); medians of {} runs after one warm-up",
        args.file.display(),
        loaded.character.vertex_count(),
        loaded.character.triangles.len(),
        clip.name,
        aobake_core::bake::preview::animation_times(clip).len(),
        args.runs.saturating_sub(1).max(1)
    );
    println!(
        "| adapter | MSAA | still panel 360² (ms) | animation panel 240² (ms) | GTAO pass 360² (ms) | model evaluation (ms) |"
    );
    println!("|---|---|---|---|---|---|");
    for (i, r) in renderers.iter().enumerate() {
        println!(
            "| {} | {}× | {:.1} | {:.1} | {:.2} | {:.2} |",
            r.gpu().label(),
            r.samples(),
            super::common::median(&stills[i]),
            super::common::median(&frames[i]),
            super::common::median(&gtao[i]),
            super::common::median(&model[i])
        );
    }
    if let Some(screen) = comparison {
        println!(
            "the still at {still_time:.2} s, against per-pixel ray-traced AO:\n{}",
            screen.summary()
        );
    }
    if !args.texel_floor.is_empty() {
        if loaded.asset.is_texel() {
            bail!(
                "{} is a texel asset: its stills above measure the floor of its own atlas (\"texel truth\"); --texel-floor measures other atlases beside a vertex, grid or cubemap asset",
                args.asset.display()
            );
        }
        texel_floors(
            &loaded,
            &subject,
            clip,
            still_time,
            &args.texel_floor,
            &mut renderers[0],
        )?;
    }
    Ok(())
}

/// The texel floor of an atlas of each side in `sides` at the still, as a
/// table beside the per-vertex floor and GTAO on the same pixels.
fn texel_floors(
    loaded: &Loaded,
    subject: &Subject<'_>,
    clip: &Clip,
    time: f32,
    sides: &[u32],
    renderer: &mut PreviewRenderer<'_>,
) -> anyhow::Result<()> {
    println!(
        "texel floors at {time:.2} s on the character, RMSE against per-pixel ray-traced AO ({} rays):",
        subject.surface.samples
    );
    println!(
        "| atlas | charts | texels | utilisation | atlas (s) | truth trace (s) | texel floor | per-vertex floor | GTAO |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for &side in sides {
        let started = std::time::Instant::now();
        let atlas = match loaded.atlas(side) {
            Ok(a) => a,
            Err(e) => {
                println!("| {side} | {e:#} | | | | | | | |");
                continue;
            }
        };
        let atlas_s = started.elapsed().as_secs_f64();
        let with_atlas = Subject {
            texel_floor: Some(&atlas),
            ..*subject
        };
        let still = with_atlas
            .stills(Some(clip), &[time], None, renderer)?
            .remove(0);
        let screen = still
            .info
            .screen_space
            .context("the still measured nothing")?;
        let (Some(e), Some(a)) = (&screen.character, &screen.atlas) else {
            bail!("the still shows no character");
        };
        let floor = e.texel_truth.context("no texel floor was measured")?;
        println!(
            "| {}×{} | {} | {} | {:.0} % | {atlas_s:.2} | {:.2} | {:.4} | {:.4} | {:.4} |",
            a.width,
            a.height,
            a.charts,
            a.texels,
            100.0 * a.utilisation,
            // The still's truth: its vertices, ground and the atlas's texels.
            still.info.trace_s,
            floor.rmse,
            e.per_vertex_truth.rmse,
            e.gtao.rmse
        );
    }
    Ok(())
}

/// wgpu's backend flags, without a direct dependency on wgpu here.
mod wgpu_backends {
    pub(super) use aobake_worker::gpu::Backends;
    pub(super) const VULKAN: Backends = Backends::VULKAN;
    pub(super) const GL: Backends = Backends::GL;
}
