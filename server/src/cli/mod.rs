//! Command-line interface: `aobake <command>`.

mod inspect;
mod load;
mod pose;

use clap::{Parser, Subcommand};

/// aobake: pose-dependent ambient occlusion for animated glTF characters.
#[derive(Debug, Parser)]
#[command(name = "aobake", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Describe glTF characters: meshes, vertices, triangles, skins, joints,
    /// morph targets, clips, pose parameters, bounds over all clips.
    Inspect(inspect::Args),
    /// Pose a character at a clip time (or in its bind pose) and write the
    /// skinned mesh as PLY, in aobake's vertex order.
    Pose(pose::Args),
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Inspect(args) => inspect::run(&args),
        Command::Pose(args) => pose::run(&args),
    }
}
