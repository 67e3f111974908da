//! Reading characters and clips from files for the command line.
//!
//! A `.gltf` may name side files (buffers, images); they are looked up in
//! the `.gltf`'s own folder by the relative names that core validated (no
//! absolute paths, no `..`), and handed to core as an upload. Core itself
//! never touches the file system.

use std::path::Path;

use anyhow::{Context as _, bail};
use aobake_core::{Clip, Imported, Limits, SideFile, Upload, import::referenced_files};

fn read_limited(path: &Path, limits: &Limits) -> anyhow::Result<Vec<u8>> {
    let size = std::fs::metadata(path)
        .with_context(|| format!("cannot read {}", path.display()))?
        .len();
    if size > limits.max_file_bytes {
        bail!(
            "{} is {size} bytes, over the limit of {} bytes",
            path.display(),
            limits.max_file_bytes
        );
    }
    std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))
}

/// The main file's bytes and the side files it refers to that exist beside
/// it.
fn gather(path: &Path, limits: &Limits) -> anyhow::Result<(Vec<u8>, Vec<SideFile>)> {
    let main = read_limited(path, limits)?;
    let mut side_files = Vec::new();
    if !main.starts_with(b"glTF") {
        let dir = path.parent().unwrap_or(Path::new("."));
        let names = referenced_files(&main, limits)
            .with_context(|| format!("cannot import {}", path.display()))?;
        for name in names {
            let file = dir.join(&name);
            if file.is_file() {
                side_files.push(SideFile {
                    bytes: read_limited(&file, limits)?,
                    name,
                });
            }
        }
    }
    Ok((main, side_files))
}

/// Imports a character file.
pub(super) fn character(path: &Path, limits: &Limits) -> anyhow::Result<Imported> {
    Ok(character_with_digest(path, limits)?.0)
}

/// Imports a character file and returns its upload digest too.
pub(super) fn character_with_digest(
    path: &Path,
    limits: &Limits,
) -> anyhow::Result<(Imported, String)> {
    let (main, side_files) = gather(path, limits)?;
    let upload = Upload {
        main: &main,
        side_files: &side_files,
    };
    let imported = aobake_core::import_character(upload, limits)
        .with_context(|| format!("cannot import {}", path.display()))?;
    Ok((imported, upload.digest()))
}

/// Imports the clips of a separate file, bound to `imported`'s nodes by
/// name.
pub(super) fn clips(
    path: &Path,
    imported: &Imported,
    limits: &Limits,
) -> anyhow::Result<(Vec<Clip>, Vec<String>)> {
    let (clips, warnings, _) = clips_with_digest(path, imported, limits)?;
    Ok((clips, warnings))
}

/// Imports the clips of a separate file and returns its upload digest too.
pub(super) fn clips_with_digest(
    path: &Path,
    imported: &Imported,
    limits: &Limits,
) -> anyhow::Result<(Vec<Clip>, Vec<String>, String)> {
    let (main, side_files) = gather(path, limits)?;
    let upload = Upload {
        main: &main,
        side_files: &side_files,
    };
    let (clips, warnings) = aobake_core::import_clips(upload, &imported.character, limits)
        .with_context(|| format!("cannot import clips from {}", path.display()))?;
    Ok((clips, warnings, upload.digest()))
}
