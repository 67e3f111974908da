//! Choosing a pose on the command line: `FILE [--clips FILE] [--clip NAME
//! --time T]`, shared by the commands that pose a character.

use std::path::{Path, PathBuf};

use anyhow::bail;
use aobake_core::{Character, Clip, Limits, Pose, PosedMesh};

/// Which pose of a character: a clip time, or the bind pose.
#[derive(Debug, clap::Args)]
pub(super) struct PoseArgs {
    /// A second glTF file whose animations drive the character, bound to its
    /// nodes by name. Its clips are searched before the character's own.
    #[arg(long)]
    pub clips: Option<PathBuf>,
    /// Clip name (see `aobake inspect`). Without it (and without
    /// `--rest`) the bind pose is used: the mesh as modelled, as the
    /// skin's inverse bind matrices place it.
    #[arg(long, requires = "time")]
    pub clip: Option<String>,
    /// The nodes' rest transforms instead of the bind pose: what an engine
    /// that never sets a node shows (it can differ from the bind pose
    /// slightly: 2e-5 in AO on Fox).
    #[arg(long, conflicts_with = "clip")]
    pub rest: bool,
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

/// Imports `file` and the clips of `clips` (searched first) and its own.
pub(super) fn character_and_clips(
    file: &Path,
    clips_file: Option<&Path>,
    limits: &Limits,
) -> anyhow::Result<(Character, Vec<Clip>)> {
    let imported = super::load::character(file, limits)?;
    let mut clips = Vec::new();
    if let Some(path) = clips_file {
        let (extra, warnings) = super::load::clips(path, &imported, limits)?;
        for w in warnings {
            eprintln!("warning: {}: {w}", path.display());
        }
        clips.extend(extra);
    }
    clips.extend(imported.clips.iter().cloned());
    Ok((imported.character, clips))
}

/// Input the command refuses (exit 5, [`super::exit::BAD_INPUT`]): a
/// file that cannot be read, an asset that does not fit its character or
/// does not serve the command, a clip the character does not have.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub(super) struct Refused(pub String);

/// A [`Refused`] error with this message.
pub(super) fn refused(message: impl std::fmt::Display) -> anyhow::Error {
    Refused(message.to_string()).into()
}

/// The asset file `path` read and its container parsed; refused when it
/// cannot be read or is not an asset. `other` is the command's character
/// file: when `path` is not an asset and `other` is, the arguments were
/// given the wrong way round, and the error says so.
pub(super) fn read_asset(
    path: &Path,
    other: Option<&Path>,
) -> anyhow::Result<(Vec<u8>, aobake_core::asset::Container)> {
    let bytes =
        std::fs::read(path).map_err(|e| refused(format!("cannot read {}: {e}", path.display())))?;
    match aobake_core::asset::Container::from_bytes(&bytes) {
        Ok(container) => Ok((bytes, container)),
        Err(e) => {
            let swapped = other
                .filter(|o| {
                    std::fs::read(o)
                        .is_ok_and(|b| aobake_core::asset::Container::from_bytes(&b).is_ok())
                })
                .map(|o| {
                    format!(
                        " ({} is one: the asset comes first, then the character)",
                        o.display()
                    )
                })
                .unwrap_or_default();
            Err(refused(format!(
                "cannot read {}: {e}{swapped}",
                path.display()
            )))
        }
    }
}

/// The clip named `name`, or an error that lists the clips.
pub(super) fn find_clip<'c>(clips: &'c [Clip], name: &str) -> anyhow::Result<&'c Clip> {
    clips.iter().find(|c| c.name == name).ok_or_else(|| {
        let names: Vec<&str> = clips.iter().map(|c| c.name.as_str()).collect();
        refused(format!(
            "no clip named {name:?}; the clips are: {}",
            if names.is_empty() {
                "none".to_owned()
            } else {
                names.join(", ")
            }
        ))
    })
}

/// Imports `file` and skins it in the pose `args` selects.
pub(super) fn pose(file: &Path, args: &PoseArgs, limits: &Limits) -> anyhow::Result<Posed> {
    let (character, clips) = character_and_clips(file, args.clips.as_deref(), limits)?;
    let pose = match (&args.clip, args.time) {
        (Some(name), Some(time)) => {
            if !time.is_finite() {
                bail!("--time must be a finite number of seconds");
            }
            Pose::sample(&character.skeleton, find_clip(&clips, name)?, time)
        }
        _ if args.rest => Pose::rest(&character.skeleton),
        _ => Pose::bind(&character),
    };
    let mesh = character.skin(&pose);
    Ok(Posed {
        character,
        mesh,
        pose,
    })
}

/// A serde enum's name, as headers and reports write it (`discrete`,
/// `rotation-vector`).
pub(super) fn serde_name(value: &impl serde::Serialize) -> String {
    match serde_json::to_value(value) {
        Ok(serde_json::Value::String(s)) => s,
        _ => "?".into(),
    }
}

/// A server address as `--server` takes it: a URL with its scheme, such
/// as `http://127.0.0.1:8080` (without one the HTTP client answers only
/// "invalid format").
pub(super) fn server_url(s: &str) -> anyhow::Result<&str> {
    let s = s.trim();
    match s.split_once("://") {
        Some((scheme, _)) if ["http", "https"].contains(&scheme.to_ascii_lowercase().as_str()) => {
            Ok(s.trim_end_matches('/'))
        }
        Some((scheme, _)) => {
            bail!("the server address {s:?} is not http:// or https:// but {scheme}://")
        }
        None => bail!(
            "the server address {s:?} is not a URL: write it with its scheme, such as http://{s}"
        ),
    }
}

/// A `--server` list: one server's URL, or several comma-separated (a
/// fleet's servers), each as [`server_url`] takes it: the first, and the
/// others to go on with when it cannot be reached.
pub(super) fn servers(s: &str) -> anyhow::Result<(String, Vec<String>)> {
    let mut urls = s
        .split(',')
        .map(|u| server_url(u).map(str::to_owned))
        .collect::<anyhow::Result<Vec<String>>>()?;
    let first = urls.remove(0);
    Ok((first, urls))
}

/// `--server` as clap reads it ([`servers`]), so a malformed address is a
/// wrong command line (exit 2).
pub(super) fn server_list(s: &str) -> Result<String, String> {
    servers(s).map(|_| s.to_owned()).map_err(|e| e.to_string())
}

/// The median of `v` (the mean of the middle two when their number is
/// even): what the benchmarks quote on noisy shared machines.
/// A clap value parser for a positive, finite number (seconds, rates):
/// what `Duration::from_secs_f64` and a rate may take.
pub(super) fn positive(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if v.is_finite() && v > 0.0 && v <= 1e9 {
        Ok(v)
    } else {
        Err(format!("{s} is not a positive number (at most 1e9)"))
    }
}

pub(super) fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// Which tracer casts this process's rays (`--tracer`, `--gpu`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(super) enum TracerChoice {
    /// The CPU tracer (every core).
    Cpu,
    /// The wgpu compute tracer on any adapter with compute shaders
    /// (software ones too); an error without one.
    Gpu,
    /// A hardware GPU when there is one, else the CPU.
    Auto,
}

impl TracerChoice {
    /// Installs the choice for the process and prints which tracer runs,
    /// stamped as log lines when `log` (a worker's); returns its label.
    pub(super) fn install(self, log: bool) -> anyhow::Result<String> {
        use aobake_worker::gpu::{GpuMode, trace::install};
        let mode = match self {
            TracerChoice::Cpu => GpuMode::Off,
            TracerChoice::Gpu => GpuMode::Require,
            TracerChoice::Auto => GpuMode::Auto,
        };
        let (label, note) = install(mode).map_err(|e| anyhow::anyhow!("--tracer gpu: {e}"))?;
        // One write a line: local workers share serve's stderr.
        for line in note.iter().chain([&format!("tracer: {label}")]) {
            if log {
                aobake_worker::say!("{line}");
            } else {
                let _ = std::io::Write::write_all(
                    &mut std::io::stderr().lock(),
                    format!("{line}\n").as_bytes(),
                );
            }
        }
        Ok(label)
    }
}
