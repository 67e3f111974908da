//! `aobake inspect`: what a glTF character holds, or a baked asset
//! (`inspect/asset.rs`), told apart by the asset's magic bytes.

mod asset;

use std::path::PathBuf;

use aobake_core::{Limits, summary::Summary};
use serde::Serialize;

/// Arguments of `aobake inspect`.
#[derive(Debug, clap::Args)]
pub(super) struct Args {
    /// glTF files (.glb, or .gltf with its buffers beside it) or baked
    /// assets (.aob, checked whole: every checksum and the model).
    #[arg(required = true)]
    files: Vec<PathBuf>,
    /// Print one JSON object per file (a JSON array) instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct Report {
    file: String,
    kind: &'static str,
    #[serde(flatten)]
    summary: Summary,
    warnings: Vec<String>,
}

/// One file's report.
#[derive(Serialize)]
#[serde(untagged)]
enum Described {
    Character(Box<Report>),
    Asset(Box<asset::Report>),
    /// A file that could not be read, and why.
    Failed {
        file: String,
        kind: &'static str,
        error: String,
    },
}

/// Describes every file; one that cannot be read is reported (as an error
/// line, or an entry with `"kind": "error"` in `--json`, even when it is
/// the only one) and the others still are, and the command then exits 1.
pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let limits = Limits::default();
    let mut reports = Vec::new();
    let mut failed = Vec::new();
    for file in &args.files {
        match describe(file, &limits) {
            Ok(report) => {
                if !args.json {
                    match &report {
                        Described::Character(r) => print_text(r),
                        Described::Asset(r) => asset::print_text(r),
                        Described::Failed { .. } => {}
                    }
                }
                reports.push(report);
            }
            // One file as text: its error is the command's.
            Err(e) if args.files.len() == 1 && !args.json => return Err(e),
            Err(e) => {
                eprintln!("error: {e:#}");
                reports.push(Described::Failed {
                    file: file.display().to_string(),
                    kind: "error",
                    error: format!("{e:#}"),
                });
                failed.push(file.display().to_string());
            }
        }
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&reports)?);
    }
    if !failed.is_empty() {
        anyhow::bail!(
            "{} of {} files could not be read: {}",
            failed.len(),
            args.files.len(),
            failed.join(", ")
        );
    }
    Ok(())
}

fn describe(file: &std::path::Path, limits: &Limits) -> anyhow::Result<Described> {
    if asset::is_asset(file)? {
        return Ok(Described::Asset(Box::new(asset::describe(file)?)));
    }
    let imported = super::load::character(file, limits)?;
    Ok(Described::Character(Box::new(Report {
        file: file.display().to_string(),
        kind: "character",
        summary: Summary::of(&imported.character, &imported.clips),
        warnings: imported.warnings,
    })))
}

fn print_text(r: &Report) {
    let s = &r.summary;
    println!("{}", r.file);
    println!(
        "  meshes       {} ({} primitives), {} instanced in the scene",
        s.meshes, s.primitives, s.mesh_instances
    );
    println!(
        "  vertices     {} in the scene ({} in the file's meshes)",
        s.vertices, s.vertices_unique
    );
    println!(
        "  triangles    {} in the scene ({} in the file's meshes)",
        s.triangles, s.triangles_unique
    );
    let per_skin: Vec<String> = s.skin_joints.iter().map(usize::to_string).collect();
    println!(
        "  skins        {}{}, palette joints {} (a rigid mesh node is a one-joint skin), morph targets {}",
        s.skins,
        if per_skin.is_empty() {
            String::new()
        } else {
            format!(" ({} joints)", per_skin.join(" + "))
        },
        s.joints,
        s.morph_targets
    );
    println!(
        "  pose params  {} joint angles, {} handle coordinates",
        s.pose_parameters, s.handle_parameters
    );
    println!("  clips        {}", s.clips.len());
    for c in &s.clips {
        println!(
            "    {:<24} {:>8.3} s  {} channels, {} keys",
            c.name, c.duration, c.channels, c.keys
        );
    }
    let [lo, hi] = s.bounds;
    println!(
        "  bounds       [{:.4}, {:.4}, {:.4}] .. [{:.4}, {:.4}, {:.4}] {} (diagonal {:.4})",
        lo[0],
        lo[1],
        lo[2],
        hi[0],
        hi[1],
        hi[2],
        if s.clips.is_empty() {
            "in the bind pose (no clips)"
        } else {
            "over every clip frame"
        },
        s.diagonal
    );
    for w in &r.warnings {
        println!("  warning      {w}");
    }
}
