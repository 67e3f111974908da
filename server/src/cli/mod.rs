//! Command-line interface: `aobake <command>`.
//!
//! One file per command (`bench/` holds `aobake bench`'s measurements);
//! `common` (choosing a pose), `load` (reading files) and `params` (the
//! bake flags) are shared by several.

mod bake;
mod bench;
mod blobs;
pub mod client;
mod common;
mod eval;
mod export;
mod inspect;
mod key;
mod load;
mod params;
mod pose;
mod preview;
mod trace;
mod worker;

use clap::{Parser, Subcommand};

/// aobake: pose-dependent ambient occlusion for animated glTF characters.
#[derive(Debug, Parser)]
#[command(name = "aobake", version, about, long_about = None, after_help = EXIT_CODES)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Describe glTF characters (meshes, vertices, triangles, skins, joints,
    /// morph targets, clips, pose parameters, bounds over all clips) or
    /// baked assets (method, format, keys, the model's shape, sections;
    /// every checksum checked).
    Inspect(inspect::Args),
    /// Pose a character at a clip time (or in its bind pose) and write the
    /// skinned mesh as PLY, in aobake's vertex order.
    Pose(pose::Args),
    /// Ray-trace ground-truth ambient occlusion at every vertex of a posed
    /// character or a PLY mesh and write it as CSV.
    Trace(trace::Args),
    /// Bake pose-dependent AO: per vertex (trace reference poses, fit the
    /// method, judge it on held-out poses against the static average),
    /// Kroon's cubemaps around a clip (six faces traced, encoded, judged
    /// against fresh ground truth) or Malmer's grids around every rigid
    /// part (traced slab by slab, judged on clip frames), and write the
    /// asset, a JSON report and its plot.
    Bake(Box<bake::Args>),
    /// Print a method's bake parameters with their defaults (and any
    /// flags applied) as JSON: the names `--param` and the API take.
    Params(params::Args),
    /// Print the bake key of a character, its clips and the parameters,
    /// without baking: what `fetch --key` looks up, so CI can fetch a
    /// cached asset before deciding to submit.
    Key(key::Args),
    /// Evaluate a baked asset (per-vertex, grid, or texel: its textures
    /// sampled at the vertices) at a pose and write per-vertex AO as CSV.
    Eval(eval::Args),
    /// Write a baked asset's data for other tools: a cubemap's decoded
    /// faces, a grid asset's parts as z-slices, or a texel asset's
    /// coefficient textures, as OpenEXR (--exr DIR);
    /// the character with a vertex asset's AO as glTF (--gltf OUT.glb); or
    /// the run-time shaders for engines (--shaders DIR).
    Export(export::Args),
    /// Render a baked asset with wgpu: a still at a clip time (ground
    /// truth, model, screen-space AO, error; the model and GTAO judged
    /// per pixel) or an animated PNG of a whole clip.
    Preview(preview::Args),
    /// Run the bake service: the HTTP API on SQLite and local disk under
    /// --data, with local worker processes.
    ///
    /// The admin token is AOBAKE_ADMIN_TOKEN when set, else a new one each
    /// start, written to DATA/admin.token (each start revokes the tokens
    /// the previous one generated). Several servers share one PostgreSQL
    /// (--database) and one S3-compatible bucket (--blobs): give them the
    /// same AOBAKE_ADMIN_TOKEN, and --workers 0 where the workers run
    /// elsewhere (`aobake worker`, with a token from `aobake token create
    /// --scope worker`). docs/service.md has the whole story.
    Serve(Box<crate::serve::ServeArgs>),
    /// Run jobs for a server (a separate process; many may run on many
    /// machines).
    Worker(worker::WorkerArgs),
    /// Upload a character (and clips) to a server and bake it.
    Submit(Box<client::SubmitArgs>),
    /// Show a bake's state and progress.
    Status(client::StatusArgs),
    /// Cancel a queued, running or paused bake: its running jobs stop at
    /// their next heartbeat and no job is leased again (`retry` takes it
    /// up again).
    Cancel(client::ControlArgs),
    /// Pause a queued or running bake: no new job of it is leased (running
    /// ones finish).
    Pause(client::ControlArgs),
    /// Resume a paused bake.
    Resume(client::ControlArgs),
    /// Queue a failed or cancelled bake again: its unfinished jobs with
    /// fresh attempts (what finished is kept, unless the blob store lost
    /// its outputs: those jobs run again). A done bake that lost its
    /// asset, report or previews is queued again the same way.
    Retry(client::ControlArgs),
    /// Download a finished bake's asset by bake id or bake key (exit 4 when
    /// there is none).
    Fetch(client::FetchArgs),
    /// Manage API tokens.
    Token(client::TokenArgs),
    /// List a server's bakes, newest first: each one's id, state,
    /// progress, method, character and age.
    Bakes(client::BakesArgs),
    /// List the workers a server knows: each one's state (idle, busy,
    /// stopped), the job it runs, its tracer and when it was last seen.
    Workers(client::WorkersArgs),
    /// Operators' checks of the blob store: `aobake blobs verify
    /// [--repair]` finds blobs the database names that are missing or
    /// corrupt, on local disk or S3, and repairs what can be.
    Blobs(blobs::Args),
    /// Print the HTTP API's OpenAPI 3.1 description (YAML).
    Openapi,
    /// Measure speed: print figures for the benchmarks that issues and
    /// notes quote.
    Bench(bench::Args),
}

impl Cli {
    /// Whether the command is the service or a worker: long-running
    /// processes that must outlive a closed output pipe.
    pub fn is_service(&self) -> bool {
        matches!(self.command, Command::Serve(_) | Command::Worker(_))
    }

    /// Whether the command opens a GPU adapter (Vulkan or GL through
    /// wgpu): a bake or a worker looking for the GPU tracer, previews,
    /// benchmarks.
    pub fn opens_gpu(&self) -> bool {
        matches!(
            self.command,
            Command::Bake(_) | Command::Preview(_) | Command::Worker(_) | Command::Bench(_)
        )
    }
}

/// The exit codes, as `aobake --help` lists them.
const EXIT_CODES: &str = "Exit codes (for scripts to branch on):
  0  success
  1  failed (a cause not below)
  2  the command line is wrong
  3  worker: the server refuses its leases for good (token, scope, address)
  4  fetch: no finished bake for that id or key
  5  the input was refused: a file that cannot be read or does not import (a
     character or an asset), an asset for another character or command, a clip
     the character lacks, a parameter out of range, or a request the server
     answered 4xx (a bake that does not exist, an action its state forbids)
  6  no token was given, or the server refused the token (401) or its scope (403)
  7  the server could not be reached, failed (5xx) or stayed too busy (429), after
     waiting out an outage: try again later
  8  submit --wait: the bake failed or was cancelled
130  submit --wait: Ctrl-C stopped the following (the bake goes on on the server)
141  stdout was closed (a pipe into head)";

/// What a script can branch on ([`EXIT_CODES`]).
pub mod exit {
    /// Failed for a cause not below.
    pub const FAILED: u8 = 1;
    /// `fetch`: no finished bake.
    pub const NOT_BAKED: u8 = 4;
    /// The input was refused, here or by the server (a 4xx).
    pub const BAD_INPUT: u8 = 5;
    /// No token, or the server refused the token or its scope.
    pub const TOKEN: u8 = 6;
    /// The server could not be reached or failed.
    pub const UNAVAILABLE: u8 = 7;
    /// `submit --wait`: the bake failed or was cancelled.
    pub const BAKE_FAILED: u8 = 8;
    /// `submit --wait`: Ctrl-C stopped the following (128 + SIGINT, as a
    /// shell reports it); the bake goes on.
    pub const INTERRUPTED: i32 = 130;
}

/// The exit code for `err` ([`EXIT_CODES`]): by the first cause that
/// says; an [`client::Exit`] carries its own.
pub fn exit_code(err: &anyhow::Error) -> u8 {
    use aobake_api::ApiError;
    for cause in err.chain() {
        if let Some(e) = cause.downcast_ref::<client::Exit>() {
            return e.code;
        }
        if let Some(e) = cause.downcast_ref::<ApiError>() {
            return match e {
                ApiError::Status {
                    status: 401 | 403, ..
                } => exit::TOKEN,
                // A 429 or 408 arrives after the client waited it out:
                // the server is busy, not the input wrong.
                ApiError::Status {
                    status: 408 | 429, ..
                } => exit::UNAVAILABLE,
                ApiError::Status { status, .. } if *status >= 500 => exit::UNAVAILABLE,
                ApiError::Status { .. } => exit::BAD_INPUT,
                ApiError::Transport { .. } => exit::UNAVAILABLE,
                ApiError::Tls { .. } | ApiError::Decode { .. } => exit::FAILED,
            };
        }
        if cause.is::<common::Refused>()
            || cause.is::<aobake_core::ImportError>()
            || cause.is::<aobake_core::bake::BakeError>()
            || cause.is::<aobake_core::asset::AssetError>()
        {
            return exit::BAD_INPUT;
        }
    }
    exit::FAILED
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Inspect(args) => inspect::run(&args),
        Command::Pose(args) => pose::run(&args),
        Command::Trace(args) => trace::run(&args),
        Command::Bake(args) => bake::run(&args),
        Command::Params(args) => params::run(&args),
        Command::Key(args) => key::run(&args),
        Command::Eval(args) => eval::run(&args),
        Command::Export(args) => export::run(&args),
        Command::Preview(args) => preview::run(&args),
        Command::Bench(args) => bench::run(&args),
        Command::Blobs(args) => blobs::run(&args),
        Command::Serve(args) => {
            tokio::runtime::Runtime::new()?.block_on(crate::serve::serve(*args))
        }
        Command::Worker(args) => worker::run(&args),
        Command::Openapi => {
            print!("{}", crate::openapi::yaml());
            Ok(())
        }
        Command::Submit(args) => client::submit(&args).map_err(client::explain_refusal),
        Command::Status(args) => client::status(&args).map_err(client::explain_refusal),
        Command::Cancel(args) => client::control(&args, "cancel").map_err(client::explain_refusal),
        Command::Pause(args) => client::control(&args, "pause").map_err(client::explain_refusal),
        Command::Resume(args) => client::control(&args, "resume").map_err(client::explain_refusal),
        Command::Retry(args) => client::control(&args, "retry").map_err(client::explain_refusal),
        Command::Fetch(args) => client::fetch(&args).map_err(client::explain_refusal),
        Command::Token(args) => client::token(&args).map_err(client::explain_refusal),
        Command::Workers(args) => client::workers(&args).map_err(client::explain_refusal),
        Command::Bakes(args) => client::bakes(&args).map_err(client::explain_refusal),
    }
}

/// Every command, its arguments and their help, as Markdown: the
/// reference `docs/cli.md` holds, generated from the definitions above
/// (a test keeps the file equal to it; `AOBAKE_BLESS=1` rewrites it).
pub fn reference_markdown() -> String {
    use clap::CommandFactory as _;
    let mut cli = Cli::command();
    cli.build();
    let mut out = String::from(
        "# Command reference\n\nGenerated from `aobake --help` and each command's `--help` (a test keeps\nthis file equal to them; `AOBAKE_BLESS=1 cargo nextest run -p aobake-server\ncli_reference` rewrites it). [usage.md](usage.md) says what the commands\nare for and how they fit together.\n",
    );
    for sub in cli.get_subcommands() {
        command_markdown(&mut out, sub, "aobake");
    }
    out
}

fn command_markdown(out: &mut String, cmd: &clap::Command, parent: &str) {
    if cmd.is_hide_set() || cmd.get_name() == "help" {
        return;
    }
    let path = format!("{parent} {}", cmd.get_name());
    out.push_str(&format!("\n## `{path}`\n\n"));
    if let Some(about) = cmd.get_long_about().or(cmd.get_about()) {
        out.push_str(&format!("{}\n\n", about.to_string().trim()));
    }
    let usage = cmd
        .clone()
        .bin_name(&path)
        .render_usage()
        .to_string()
        .replace("Usage: ", "");
    out.push_str(&format!("Usage: `{}`\n", usage.trim()));
    let args: Vec<&clap::Arg> = cmd
        .get_arguments()
        .filter(|a| !a.is_hide_set() && !matches!(a.get_id().as_str(), "help" | "version"))
        .collect();
    if !args.is_empty() {
        out.push_str("\n| argument | what |\n|---|---|\n");
        for a in args {
            let takes = a.get_action().takes_values();
            let names = a
                .get_value_names()
                .filter(|_| takes)
                .map(|v| {
                    v.iter()
                        .map(|n| format!("<{n}>"))
                        .collect::<Vec<_>>()
                        .join(" ")
                })
                .unwrap_or_default();
            let name = match (a.is_positional(), a.get_long()) {
                (true, _) => names.clone(),
                (false, Some(long)) => format!("--{long} {names}").trim().to_owned(),
                (false, None) => a.get_id().to_string(),
            };
            let mut what = a
                .get_long_help()
                .or(a.get_help())
                .map(|h| {
                    h.to_string()
                        .split_whitespace()
                        .collect::<Vec<_>>()
                        .join(" ")
                })
                .unwrap_or_default();
            if !what.is_empty() && !what.ends_with(['.', ')', ':']) {
                what.push('.');
            }
            let possible: Vec<String> = a
                .get_possible_values()
                .iter()
                .filter(|p| !p.is_hide_set())
                .map(|p| format!("`{}`", p.get_name()))
                .collect();
            if !possible.is_empty() && takes {
                what.push_str(&format!(" One of {}.", possible.join(", ")));
            }
            let defaults: Vec<String> = a
                .get_default_values()
                .iter()
                .map(|d| d.to_string_lossy().into_owned())
                .collect();
            if !defaults.is_empty() && takes {
                what.push_str(&format!(" Default: `{}`.", defaults.join(" ")));
            }
            if let Some(env) = a.get_env() {
                what.push_str(&format!(" Environment: `{}`.", env.to_string_lossy()));
            }
            if a.is_required_set() {
                what.push_str(" Required.");
            }
            out.push_str(&format!(
                "| `{}` | {} |\n",
                name.replace('|', "\\|"),
                what.trim().replace('|', "\\|")
            ));
        }
    }
    for sub in cmd.get_subcommands() {
        command_markdown(out, sub, &path);
    }
}

#[cfg(test)]
mod reference_tests {
    /// `docs/cli.md` is what the command definitions say, word for word:
    /// a flag added, renamed or reworded without it fails here.
    #[test]
    fn cli_reference_is_the_commands_own() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/cli.md");
        let want = super::reference_markdown();
        if std::env::var_os("AOBAKE_BLESS").is_some() {
            std::fs::write(&path, &want).unwrap();
        }
        let have = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            have == want,
            "docs/cli.md differs from the commands' help: AOBAKE_BLESS=1 cargo nextest run -p aobake-server cli_reference"
        );
    }
}
