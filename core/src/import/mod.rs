//! glTF import from bytes.
//!
//! [`import_character`] turns an upload (a `.glb`, or a `.gltf` with the
//! files uploaded beside it) into a [`Character`] and the clips of the same
//! file; [`import_clips`] reads the animations of a second file and binds
//! them to a character's nodes by name. Input is untrusted: every count is
//! checked against [`Limits`] before allocation, every byte range against
//! the data present, every URI against the uploaded names, and every number
//! for finiteness. Errors name the JSON path and element that is wrong.

mod accessor;
mod animation;
mod document;
mod error;
pub mod limits;
mod mesh;
pub mod ply;
mod rules;
mod source;

pub use document::referenced_files;
pub use error::ImportError;
pub(crate) use source::SideFiles;
pub use source::{SideFile, Upload};

use crate::{Character, Clip, Limits};

/// A character with the clips of its own file.
#[derive(Debug, Clone)]
pub struct Imported {
    /// The merged, skinned occluder and its skeleton.
    pub character: Character,
    /// The animations of the file, bound to its nodes.
    pub clips: Vec<Clip>,
    /// Things that were accepted but deserve a look (normalised weights,
    /// missing images, ignored primitives).
    pub warnings: Vec<String>,
    /// What the file calls the character: its scene's name, if any.
    pub name: Option<String>,
}

/// Imports a character and the animations of its file.
pub fn import_character(upload: Upload<'_>, limits: &Limits) -> Result<Imported, ImportError> {
    let doc = document::Document::parse(upload, limits)?;
    imported(&doc, limits)
}

/// The character and clips of a parsed file.
fn imported(doc: &document::Document, limits: &Limits) -> Result<Imported, ImportError> {
    let (character, mut warnings) = mesh::build_character(doc, limits)?;
    warnings.splice(0..0, doc.warnings.iter().cloned());
    let clips = animation::read_clips(doc, &character.skeleton, &Some, limits, &mut warnings)?;
    Ok(Imported {
        character,
        clips,
        warnings,
        name: doc.name(),
    })
}

/// A character as [`import_character`] reads it, with the file's own JSON,
/// its buffers resolved (GLB chunk, data URIs, side files) and the bytes of
/// each image a URI names (`None` where the upload lacks it): what the glTF
/// export rewrites.
pub(crate) struct Source {
    pub(crate) imported: Imported,
    pub(crate) json: serde_json::Value,
    pub(crate) buffers: Vec<Vec<u8>>,
    pub(crate) images: Vec<Option<Vec<u8>>>,
}

/// [`import_character`] with the [`Source`] kept.
pub(crate) fn import_with_source(
    upload: Upload<'_>,
    limits: &Limits,
) -> Result<Source, ImportError> {
    let doc = document::Document::parse(upload, limits)?;
    let imported = imported(&doc, limits)?;
    let container = source::Container::parse(upload.main)?;
    let json: serde_json::Value =
        serde_json::from_slice(container.json).map_err(|e| ImportError::Json(e.to_string()))?;
    let side_files = source::SideFiles::new(upload.side_files);
    let images = doc
        .root
        .images
        .iter()
        .enumerate()
        .map(|(i, image)| match &image.uri {
            None => Ok(None),
            Some(uri) => Ok(
                match source::resolve_uri(uri, &format!("images[{i}].uri"))? {
                    source::UriTarget::Data(bytes) => Some(bytes),
                    source::UriTarget::File(name) => side_files.get(&name).map(|f| f.bytes.clone()),
                },
            ),
        })
        .collect::<Result<_, ImportError>>()?;
    Ok(Source {
        imported,
        json,
        buffers: doc.buffers,
        images,
    })
}

/// Imports the animations of a separate glTF file (clips shipped apart from
/// the character), binding each channel to the character's node of the same
/// name. Returns the clips and warnings.
pub fn import_clips(
    upload: Upload<'_>,
    character: &Character,
    limits: &Limits,
) -> Result<(Vec<Clip>, Vec<String>), ImportError> {
    let doc = document::Document::parse(upload, limits)?;
    let mut warnings = doc.warnings.clone();
    let mut by_name = std::collections::HashMap::new();
    for (i, node) in character.skeleton.nodes.iter().enumerate().rev() {
        if let Some(name) = &node.name {
            by_name.insert(name.as_str(), i); // the first node of a name wins
        }
    }
    let names: Vec<Option<usize>> = doc
        .root
        .nodes
        .iter()
        .map(|n| {
            n.name
                .as_deref()
                .and_then(|name| by_name.get(name).copied())
        })
        .collect();
    let clips = animation::read_clips(
        &doc,
        &character.skeleton,
        &|node| names.get(node).copied().flatten(),
        limits,
        &mut warnings,
    )?;
    if clips.iter().all(|c| c.channels.is_empty()) {
        return Err(ImportError::NoAnimations {
            in_file: !doc.root.animations.is_empty(),
        });
    }
    Ok((clips, warnings))
}
