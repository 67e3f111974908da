//! What an engine does with a grid asset, through aobake-runtime alone:
//! read it, pose its parts with a skinning palette, and look up the
//! occlusion the parts cast at receivers (here: each part's grid centre,
//! facing up, shaded by the other parts).
//!
//! ```text
//! cargo run -p aobake-runtime --example grid_ao -- ASSET [PALETTE.json]
//! ```
//!
//! `PALETTE.json` is the frame's palette as the renderer skins with it: an
//! array with one column-major 4 × 4 matrix (16 numbers) per joint.
//! Without it every palette entry is the identity: each part sits in its
//! own bind space (for a rigid part, its node's frame at the origin), so
//! parts may overlap; pass the frame's palette to see a real pose.

use aobake_runtime::{
    Container,
    method::grid::model::{GridModel, Terms},
};
use glam::{Mat4, Vec3};

/// Prints the error as a person reads it (`main` returning it would print
/// its `Debug` form).
fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let asset = args.next().ok_or("usage: grid_ao ASSET [PALETTE.json]")?;
    let container = Container::from_bytes(&std::fs::read(&asset)?)?;
    let (model, header) = GridModel::from_container(&container)?;
    let joints = model.parts.iter().map(|p| p.joint + 1).max().unwrap_or(0);
    let palette: Vec<Mat4> = match args.next() {
        Some(path) => {
            let columns: Vec<[f32; 16]> = serde_json::from_slice(&std::fs::read(path)?)?;
            columns.iter().map(Mat4::from_cols_array).collect()
        }
        None => vec![Mat4::IDENTITY; joints],
    };
    model.check_palette(palette.len())?;
    let poses = model.poses(&palette);
    println!(
        "{asset}: {} parts of character {}, cones {}",
        model.parts.len(),
        header.character,
        model.cones()
    );
    // A receiver at each part's grid centre, facing up, shaded by the
    // other parts (an engine passes its own vertices or ground points).
    for (k, (part, pose)) in model.parts.iter().zip(&poses).enumerate() {
        let centre = pose
            .grid_from_world
            .inverse()
            .transform_point3(Vec3::splat(0.5));
        let ao = model.occlusion(&poses, centre, Vec3::Y, Some(k), Terms::Others);
        println!(
            "  {:<16} at ({:.3}, {:.3}, {:.3}), from the other parts: occlusion {ao:.3}",
            part.name, centre.x, centre.y, centre.z
        );
    }
    Ok(())
}
