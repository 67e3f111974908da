//! `aobake trace`: ground-truth ambient occlusion per vertex of one posed
//! mesh, as CSV.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, bail};
use aobake_core::{
    Limits, geometry,
    import::ply,
    trace::{
        Axis, Falloff, Ground, Scene, SceneOptions, SurfaceMesh, SurfaceParams, vertex_occlusion,
    },
};
use glam::Vec3;

use super::common::{PoseArgs, pose};

/// Arguments of `aobake trace`.
#[derive(Debug, clap::Args)]
pub(super) struct Args {
    /// The mesh: a glTF character (.glb, .gltf), posed with --clip/--time
    /// (bind pose without), or a PLY triangle mesh (its `nx ny nz` normals
    /// are used when present, angle-weighted normals otherwise).
    #[arg(long)]
    mesh: PathBuf,
    #[command(flatten)]
    pose: PoseArgs,
    /// Rays per vertex (cosine-weighted about the vertex normal); powers of
    /// two stratify best. At most 65536.
    #[arg(long, default_value_t = 256)]
    samples: u32,
    /// Hits farther than this (model units) do not occlude. Default: no
    /// limit.
    #[arg(long, allow_negative_numbers = true)]
    max_distance: Option<f32>,
    /// Obscurance instead of AO: a hit at distance d counts e^(−τd), with
    /// τ given here per model unit (Kontkanen & Aila Eq. 2).
    #[arg(long, value_name = "TAU", allow_negative_numbers = true)]
    obscurance: Option<f32>,
    /// Add a ground plane below the mesh: a solid half-space, or a square
    /// with --ground-half-size.
    #[arg(long)]
    ground: bool,
    /// The up axis, for --ground. glTF is y-up; meshes from Blender are
    /// z-up.
    #[arg(long, value_enum, default_value = "y")]
    up: UpAxis,
    /// Height of the ground along the up axis. Default: the mesh's lowest
    /// point.
    #[arg(long, requires = "ground", allow_negative_numbers = true)]
    ground_height: Option<f32>,
    /// Make the ground a square of this half edge, centred under the mesh
    /// (as the Blender reference baker does), instead of infinite.
    #[arg(long, requires = "ground", allow_negative_numbers = true)]
    ground_half_size: Option<f32>,
    /// Seed of the ray directions: the same seed gives the same output,
    /// whatever the thread count.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Worker threads. Default: one per core.
    #[arg(long)]
    threads: Option<usize>,
    /// Output CSV: `index,occlusion` per vertex (0 = open, 1 = blocked), in
    /// aobake's vertex order (the order `aobake pose` writes).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum UpAxis {
    X,
    Y,
    Z,
}

impl From<UpAxis> for Axis {
    fn from(a: UpAxis) -> Axis {
        match a {
            UpAxis::X => Axis::X,
            UpAxis::Y => Axis::Y,
            UpAxis::Z => Axis::Z,
        }
    }
}

/// A triangle mesh with one normal per vertex.
#[derive(Debug)]
pub(super) struct Mesh {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
}

fn is_ply(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"))
}

/// Reads a PLY mesh (normals from the file, or angle-weighted).
pub(super) fn read_ply(path: &Path, limits: &Limits) -> anyhow::Result<Mesh> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mesh =
        ply::read(&bytes, limits).with_context(|| format!("cannot read {}", path.display()))?;
    let normals = mesh.normals.unwrap_or_else(|| {
        let mut n = vec![Vec3::ZERO; mesh.positions.len()];
        geometry::angle_weighted_normals(&mesh.positions, &mesh.triangles, 0..n.len(), &mut n);
        n
    });
    Ok(Mesh {
        positions: mesh.positions,
        normals,
        triangles: mesh.triangles,
    })
}

fn load(args: &Args, limits: &Limits) -> anyhow::Result<Mesh> {
    if is_ply(&args.mesh) {
        if args.pose.clip.is_some() || args.pose.clips.is_some() {
            bail!("--clip and --clips apply to glTF characters, not to a PLY mesh");
        }
        return read_ply(&args.mesh, limits);
    }
    let posed = pose(&args.mesh, &args.pose, limits)?;
    Ok(Mesh {
        positions: posed.mesh.positions,
        normals: posed.mesh.normals,
        triangles: posed.character.triangles,
    })
}

/// A progress bar on stderr (drawn only when stderr is a terminal).
pub(super) fn progress_bar(len: u64, what: &str) -> indicatif::ProgressBar {
    styled_bar(len, what, "{rate} eta {eta} {msg}")
}

/// A bar whose message says the time left (a bake followed on a server:
/// its stages' own paces, `aobake_api::progress`), not indicatif's one
/// rate over all units.
pub(super) fn follow_bar(len: u64, what: &str) -> indicatif::ProgressBar {
    styled_bar(len, what, "{msg}")
}

fn styled_bar(len: u64, what: &str, tail: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{what} {{bar:40}} {{pos}}/{{len}} {{percent}}% {tail}"
        ))
        .expect("valid template")
        // indicatif's own per_sec prints four decimals.
        .with_key(
            "rate",
            |state: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                let r = state.per_sec();
                let _ = if r >= 10.0 {
                    write!(w, "{r:.0}/s")
                } else {
                    write!(w, "{r:.1}/s")
                };
            },
        ),
    );
    bar
}

/// Runs `f` on a rayon pool of `threads` threads (all cores for `None`).
pub(super) fn with_threads<T: Send>(
    threads: Option<usize>,
    f: impl FnOnce() -> T + Send,
) -> anyhow::Result<T> {
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if n == 0 {
            bail!("--threads must be at least 1");
        }
        builder = builder.num_threads(n);
    }
    Ok(builder
        .build()
        .context("cannot start worker threads")?
        .install(f))
}

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let limits = Limits::default();
    let mesh = load(args, &limits)?;
    let axis = Axis::from(args.up);
    let ground = args.ground.then(|| {
        let lowest = mesh
            .positions
            .iter()
            .map(|p| p[axis as usize])
            .fold(f32::INFINITY, f32::min);
        Ground {
            up: axis,
            height: args
                .ground_height
                .unwrap_or(if lowest.is_finite() { lowest } else { 0.0 }),
            half_size: args.ground_half_size,
        }
    });
    let params = SurfaceParams {
        samples: args.samples,
        max_distance: args.max_distance.unwrap_or(f32::INFINITY),
        seed: args.seed,
        falloff: args
            .obscurance
            .map_or(Falloff::None, |tau| Falloff::Exponential { tau }),
    };
    let started = Instant::now();
    let (scene, values) = with_threads(args.threads, || -> anyhow::Result<_> {
        let scene = Scene::new(
            &mesh.positions,
            &mesh.triangles,
            &SceneOptions {
                ground,
                ..SceneOptions::default()
            },
        )?;
        let bar = progress_bar(mesh.positions.len() as u64, "tracing");
        let surface = SurfaceMesh {
            positions: &mesh.positions,
            normals: &mesh.normals,
            triangles: &mesh.triangles,
        };
        let values = vertex_occlusion(&scene, &surface, &params, &|n| bar.inc(n as u64))?;
        bar.finish_and_clear();
        Ok((scene, values))
    })??;
    let seconds = started.elapsed().as_secs_f64();

    let mut csv = String::with_capacity(values.len() * 16 + 16);
    csv.push_str("index,occlusion\n");
    for (i, v) in values.iter().enumerate() {
        use std::fmt::Write as _;
        let _ = writeln!(csv, "{i},{v}");
    }
    std::fs::File::create(&args.out)
        .and_then(|mut f| f.write_all(csv.as_bytes()))
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    let rays = values.len() as f64 * f64::from(args.samples);
    eprintln!(
        "wrote {}: {} vertices, {} triangles, {} rays per vertex in {:.2} s ({:.2} Mrays/s)",
        args.out.display(),
        values.len(),
        scene.triangle_count(),
        args.samples,
        seconds,
        rays / seconds / 1e6
    );
    Ok(())
}
