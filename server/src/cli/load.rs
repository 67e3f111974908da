//! Reading characters and clips from files for the command line.
//!
//! A `.gltf` may name side files (buffers, images); they are looked up in
//! the `.gltf`'s own folder by the relative names that core validated (no
//! absolute paths, no `..`), and handed to core as an upload. Core itself
//! never touches the file system.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use aobake_core::{Clip, Imported, Limits, SideFile, bake::UploadBytes, import::referenced_files};

use super::common::refused;

fn read_limited(path: &Path, limits: &Limits) -> anyhow::Result<Vec<u8>> {
    let unreadable = |e: std::io::Error| refused(format!("cannot read {}: {e}", path.display()));
    let size = std::fs::metadata(path).map_err(unreadable)?.len();
    if size > limits.max_file_bytes {
        return Err(refused(format!(
            "{} is {size} bytes, over the limit of {} bytes",
            path.display(),
            limits.max_file_bytes
        )));
    }
    std::fs::read(path).map_err(unreadable)
}

/// The main file's bytes and the side files it refers to that exist beside
/// it: what a client uploads for this file.
pub(super) fn upload(path: &Path, limits: &Limits) -> anyhow::Result<UploadBytes> {
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
    Ok(UploadBytes { main, side_files })
}

/// Imports a character file.
pub(super) fn character(path: &Path, limits: &Limits) -> anyhow::Result<Imported> {
    let upload = upload(path, limits)?;
    aobake_core::import_character(upload.upload(), limits)
        .with_context(|| format!("cannot import {}", path.display()))
}

/// Imports the clips of a separate file, bound to `imported`'s nodes by
/// name.
pub(super) fn clips(
    path: &Path,
    imported: &Imported,
    limits: &Limits,
) -> anyhow::Result<(Vec<Clip>, Vec<String>)> {
    let upload = upload(path, limits)?;
    aobake_core::import_clips(upload.upload(), &imported.character, limits)
        .with_context(|| format!("cannot import clips from {}", path.display()))
}

/// Reads the clip files of a new bake (with their side files) and checks
/// them as the server does ([`aobake_core::bake::check_clip_list`]): at
/// most 256, counted before any is read, none given twice (the same bytes
/// under two paths count as one file given twice). Exits 5 (bad input)
/// naming the files.
pub(super) fn clip_uploads(paths: &[PathBuf], limits: &Limits) -> anyhow::Result<Vec<UploadBytes>> {
    use aobake_core::bake::{ClipListError, MAX_CLIP_FILES, check_clip_list};
    let bad_input = |message| {
        anyhow::Error::from(super::client::Exit {
            code: super::exit::BAD_INPUT,
            message,
        })
    };
    if paths.len() > MAX_CLIP_FILES {
        let e = ClipListError::TooMany(paths.len());
        return Err(bad_input(format!("error: {e}")));
    }
    let uploads = paths
        .iter()
        .map(|p| upload(p, limits))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let digests: Vec<String> = uploads.iter().map(UploadBytes::digest).collect();
    let message = match check_clip_list(&digests) {
        Ok(()) => return Ok(uploads),
        Err(e @ ClipListError::TooMany(_)) => format!("error: {e}"),
        Err(ClipListError::Twice(first, again)) if paths[first] == paths[again] => {
            format!("error: clip file {} is given twice", paths[first].display())
        }
        Err(ClipListError::Twice(first, again)) => format!(
            "error: clip files {} and {} are the same file (the same bytes): give it once",
            paths[first].display(),
            paths[again].display()
        ),
    };
    Err(bad_input(message))
}
