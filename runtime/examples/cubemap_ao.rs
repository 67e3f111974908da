//! What an engine does with a cubemap asset, through aobake-runtime alone:
//! read it and look up the occlusion the character casts at points in
//! space at a time of its clip (here: a row of points on the ground below
//! the character, from its centre outwards).
//!
//! ```text
//! cargo run -p aobake-runtime --example cubemap_ao -- ASSET [SECONDS]
//! ```
//!
//! Points are in the character's space as baked (an engine moves them
//! into it with the inverse of the character's root transform).

use aobake_runtime::{Asset, method::cubemap::geometry::FACE_NAMES};
use glam::Vec3;

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
    let path = args.next().ok_or("usage: cubemap_ao ASSET [SECONDS]")?;
    let seconds: f32 = args.next().map_or(Ok(0.0), |s| s.parse())?;
    let Asset::Cubemap { model, header } = Asset::from_bytes(&std::fs::read(&path)?)? else {
        return Err("not a cubemap asset".into());
    };
    let l = &model.layout;
    let s = &l.spheroid;
    println!(
        "{path}: {} of clip {:?} ({} s), {} faces ({}) of {}² texels, {} shells, {} time samples, {} KiB",
        header.method.name(),
        header.clip,
        l.duration,
        FACE_NAMES.len(),
        FACE_NAMES.join(" "),
        l.resolution,
        s.shells,
        l.times,
        model.bytes() / 1024
    );
    let phase = l.phase(seconds);
    // About the feet: the ground plane the bake traced its static ground
    // on (else the bottom of the character's bounds), outwards along +x;
    // on the ground an engine uses ground_ao, elsewhere occlusion.
    let floor = model
        .ground
        .as_ref()
        .map_or(s.centre.y - s.radii.y, |g| g.square.height);
    let ground = Vec3::new(s.centre.x, floor, s.centre.z);
    let reach = s.radii.x * s.outer;
    for step in 0..=8 {
        let p = ground + Vec3::X * reach * step as f32 / 8.0;
        println!(
            "  at ({:.3}, {:.3}, {:.3}), t = {seconds} s: cubemap {:.3}, on the ground {:.3}",
            p.x,
            p.y,
            p.z,
            model.occlusion(p, phase),
            model.ground_ao(p, phase)
        );
    }
    Ok(())
}
