//! Parsing and validating the glTF JSON, resolving its buffers, and checking
//! the node graph.

use std::borrow::Cow;

use gltf::json::{self, validation::Validate as _};

use super::{
    ImportError, rules,
    source::{Container, SideFiles, Upload, UriTarget, check_json_shape, resolve_uri},
};
use crate::import::limits::Limits;

/// Extensions that change how geometry is stored; a file that requires one
/// cannot be read correctly without decoding it.
const GEOMETRY_EXTENSIONS: &[&str] = &[
    "KHR_draco_mesh_compression",
    "EXT_meshopt_compression",
    "KHR_meshopt_compression",
    "EXT_mesh_gpu_instancing",
];

/// Top-level parts of a glTF that AO does not read.
const UNUSED_PARTS: &[&str] = &["materials", "textures", "images", "samplers", "cameras"];

/// Extensions whose data the accessor reader handles natively.
const DECODED_EXTENSIONS: &[&str] = &["KHR_mesh_quantization"];

/// Families of extensions that change only how a surface looks (materials,
/// textures, lights, metadata), never where it is or how it moves: a file
/// that requires one is accepted with a warning (docs/import-policy.md).
/// Any other required extension is refused, as the glTF spec asks of a
/// reader that does not know it.
const APPEARANCE_EXTENSION_PREFIXES: &[&str] = &[
    "KHR_materials_",
    "KHR_texture_",
    "EXT_texture_",
    "KHR_lights_",
    "EXT_lights_",
    "KHR_xmp",
];

/// A parsed, validated glTF file with its buffers in memory.
pub(crate) struct Document {
    pub(crate) root: json::Root,
    pub(crate) buffers: Vec<Vec<u8>>,
    /// Parent of each node.
    pub(crate) parents: Vec<Option<usize>>,
    pub(crate) warnings: Vec<String>,
    /// Numbers decoded so far from accessors without a bufferView
    /// ([`Limits::max_zero_filled`]).
    pub(crate) zero_filled: std::cell::Cell<u64>,
}

impl Document {
    pub(crate) fn parse(upload: Upload<'_>, limits: &Limits) -> Result<Self, ImportError> {
        let total = upload.total_bytes();
        if total > limits.max_file_bytes {
            return Err(ImportError::limit(
                "upload size in bytes",
                total,
                limits.max_file_bytes,
            ));
        }
        let container = Container::parse(upload.main)?;
        check_json_shape(container.json, limits)?;
        let raw: serde_json::Value =
            serde_json::from_slice(container.json).map_err(|e| ImportError::Json(e.to_string()))?;
        rules::check_integer_widths(&raw)?;
        // The text is parsed once: the tree just checked becomes the Root.
        let root: json::Root =
            serde_json::from_value(raw).map_err(|e| ImportError::Json(e.to_string()))?;
        let mut warnings = Vec::new();
        validate(&root, &mut warnings)?;
        let nodes = root.nodes.len() as u64;
        if nodes > limits.max_nodes {
            return Err(ImportError::limit("node count", nodes, limits.max_nodes));
        }
        let parents = node_parents(&root)?;
        let image_problems = rules::check(&root, &parents)?;
        if image_problems > 0 {
            warnings.push(format!(
                "{image_problems} images stored in buffer views are malformed (no mimeType, a uri \
                 as well, or a missing or strided view); ignored, since images are never decoded"
            ));
        }
        let side_files = SideFiles::new(upload.side_files);
        let buffers = load_buffers(&root, upload, &side_files, container.bin, limits)?;
        check_views(&root, &buffers)?;
        check_images(&root, &side_files, &mut warnings)?;
        Ok(Self {
            root,
            buffers,
            parents,
            warnings,
            zero_filled: std::cell::Cell::new(0),
        })
    }

    /// Node indices of the scene to bake, depth-first in child order: the
    /// default scene, else the first scene, else every root node.
    pub(crate) fn scene_nodes(&self) -> Vec<usize> {
        let roots: Vec<usize> = match self.root.scene.or(if self.root.scenes.is_empty() {
            None
        } else {
            Some(json::Index::new(0))
        }) {
            Some(scene) => self.root.scenes[scene.value()]
                .nodes
                .iter()
                .map(|n| n.value())
                .collect(),
            None => (0..self.root.nodes.len())
                .filter(|&n| self.parents[n].is_none())
                .collect(),
        };
        let mut seen = vec![false; self.root.nodes.len()];
        let mut out = Vec::new();
        let mut stack: Vec<usize> = roots.into_iter().rev().collect();
        while let Some(n) = stack.pop() {
            if std::mem::replace(&mut seen[n], true) {
                continue;
            }
            out.push(n);
            if let Some(children) = &self.root.nodes[n].children {
                stack.extend(children.iter().rev().map(|c| c.value()));
            }
        }
        out
    }

    /// The default (else first) scene's name, when it has one.
    pub(crate) fn name(&self) -> Option<String> {
        let scene = self
            .root
            .scene
            .map(|s| s.value())
            .or((!self.root.scenes.is_empty()).then_some(0))
            .and_then(|s| self.root.scenes.get(s))?;
        scene
            .name
            .as_ref()
            .map(|s| s.trim().to_owned())
            .filter(|s| !s.is_empty())
    }

    /// All nodes with each parent before its children.
    pub(crate) fn parents_first(&self) -> Vec<usize> {
        let mut order: Vec<usize> = (0..self.parents.len())
            .filter(|&n| self.parents[n].is_none())
            .collect();
        let mut i = 0;
        while i < order.len() {
            if let Some(children) = &self.root.nodes[order[i]].children {
                order.extend(children.iter().map(|c| c.value()));
            }
            i += 1;
        }
        order
    }
}

fn validate(root: &json::Root, warnings: &mut Vec<String>) -> Result<(), ImportError> {
    for (index, ext) in root.extensions_required.iter().enumerate() {
        let unsupported = || ImportError::UnsupportedExtension {
            index,
            name: ext.clone(),
        };
        if GEOMETRY_EXTENSIONS.contains(&ext.as_str()) {
            return Err(unsupported());
        }
        if DECODED_EXTENSIONS.contains(&ext.as_str()) {
            continue;
        }
        if !APPEARANCE_EXTENSION_PREFIXES
            .iter()
            .any(|p| ext.starts_with(p))
        {
            return Err(unsupported());
        }
        warnings.push(format!(
            "required extension {ext} is ignored: it does not change geometry or animation"
        ));
    }
    // The major version must be 2 (spec §3.2: a reader refuses a major it
    // does not know); `minVersion`, when present, must not ask for more.
    let major = |v: &str| v.split('.').next().and_then(|m| m.parse::<u32>().ok());
    if major(&root.asset.version) != Some(2) {
        return Err(ImportError::invalid(
            "asset.version",
            format!("{:?} is not a glTF 2.x version", root.asset.version),
        ));
    }
    if let Some(min) = &root.asset.min_version
        && (major(min) != Some(2) || min.as_str() > "2.0")
    {
        return Err(ImportError::invalid(
            "asset.minVersion",
            format!("{min:?} asks for a newer glTF than 2.0"),
        ));
    }
    // gltf-json's validation indexes `accessors` with the POSITION index
    // unchecked (mesh.rs, primitive_validate_hook) and panics on a bad one,
    // so attribute indices are checked first.
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            for (semantic, index) in &prim.attributes {
                if index.value() >= root.accessors.len() {
                    // An attribute whose name did not parse is named by
                    // the primitive's attributes as a whole.
                    let mut path = format!("meshes[{m}].primitives[{p}].attributes");
                    if let json::validation::Checked::Valid(s) = semantic {
                        path.push_str(&format!("[\"{}\"]", s.to_string()));
                    }
                    return Err(ImportError::invalid(
                        path,
                        format!("accessor {} does not exist", index.value()),
                    ));
                }
            }
        }
    }
    let mut first = None;
    let mut missing_bounds = 0usize;
    let mut ignored = 0usize;
    root.validate(root, json::Path::new, &mut |path, error| {
        let path = path().to_string();
        if path.starts_with("extensionsRequired") {
            return;
        }
        // POSITION accessors must declare min and max, but many exporters
        // leave them out and nothing here needs them.
        let missing = error == json::validation::Error::Missing;
        if missing && (path.ends_with(".min") || path.ends_with(".max")) {
            missing_bounds += 1;
            return;
        }
        // The spec allows accessors without bufferView (all zeros, or
        // sparse); the reader fills zeros.
        if missing && path.starts_with("accessors[") && path.ends_with(".bufferView") {
            return;
        }
        // Materials, textures, images, samplers and cameras are never used
        // for AO: a problem there (e.g. a webp texture without `source`)
        // is not worth refusing the character for.
        if UNUSED_PARTS.iter().any(|p| path.starts_with(p)) {
            ignored += 1;
            return;
        }
        if first.is_none() {
            first = Some((path, error));
        }
    });
    if ignored > 0 {
        warnings.push(format!(
            "{ignored} problems in materials, textures, images or cameras ignored (AO does not use them)"
        ));
    }
    if missing_bounds > 0 {
        warnings.push(format!(
            "{missing_bounds} POSITION accessor bounds (min/max) are missing; the spec requires them"
        ));
    }
    match first {
        None => Ok(()),
        Some((path, error)) => Err(ImportError::invalid(
            path,
            match error {
                json::validation::Error::IndexOutOfBounds => "index out of bounds",
                json::validation::Error::Invalid => "invalid value",
                json::validation::Error::Missing => "required value missing",
                json::validation::Error::Oversize => "size exceeds the system's limits",
                json::validation::Error::Unsupported => "unsupported",
            },
        )),
    }
}

/// Parent of every node; refuses nodes with two parents and cycles.
fn node_parents(root: &json::Root) -> Result<Vec<Option<usize>>, ImportError> {
    let n = root.nodes.len();
    let mut parents = vec![None; n];
    for (i, node) in root.nodes.iter().enumerate() {
        let children = || node.children.iter().flatten().map(|c| c.value());
        rules::unique(children(), &format!("nodes[{i}].children"))?;
        for (k, c) in children().enumerate() {
            if c == i {
                return Err(ImportError::invalid(
                    format!("nodes[{i}].children[{k}]"),
                    "a node is its own child",
                ));
            }
            if let Some(p) = parents[c].replace(i) {
                return Err(ImportError::invalid(
                    format!("nodes[{i}].children[{k}]"),
                    format!(
                        "node {c} is already a child of node {p}: the node graph must be a forest"
                    ),
                ));
            }
        }
    }
    // With one parent each, a cycle is a chain that never reaches a root.
    let mut state = vec![0u8; n]; // 0 unknown, 1 on the current walk, 2 reaches a root
    for start in 0..n {
        let mut walk = Vec::new();
        let mut node = start;
        loop {
            match state[node] {
                2 => break,
                1 => {
                    return Err(ImportError::invalid(
                        format!("nodes[{node}]"),
                        "the node graph has a cycle through this node",
                    ));
                }
                _ => {}
            }
            state[node] = 1;
            walk.push(node);
            match parents[node] {
                Some(p) => node = p,
                None => break,
            }
        }
        for w in walk {
            state[w] = 2;
        }
    }
    Ok(parents)
}

/// Each buffer's bytes: its declared `byteLength` of the data its URI or
/// the GLB's binary chunk holds. Buffers may share a side file, so the
/// bytes they declare in all are held to the upload's limit too.
fn load_buffers(
    root: &json::Root,
    upload: Upload<'_>,
    side_files: &SideFiles<'_>,
    bin: Option<&[u8]>,
    limits: &Limits,
) -> Result<Vec<Vec<u8>>, ImportError> {
    let declared: u64 = root
        .buffers
        .iter()
        .map(|b| b.byte_length.0)
        .fold(0, u64::saturating_add);
    if declared > limits.max_file_bytes {
        return Err(ImportError::limit(
            "bytes the buffers declare in all",
            declared,
            limits.max_file_bytes,
        ));
    }
    let mut buffers = Vec::with_capacity(root.buffers.len());
    for (i, buffer) in root.buffers.iter().enumerate() {
        let path = format!("buffers[{i}]");
        // A data URI's bytes are this buffer's own; a side file's or the
        // binary chunk's are borrowed, and only the declared ones copied
        // (a buffer may name a large file for a few of its bytes).
        let data: Cow<'_, [u8]> = match &buffer.uri {
            Some(uri) => match resolve_uri(uri, &format!("{path}.uri"))? {
                UriTarget::Data(bytes) => Cow::Owned(bytes),
                UriTarget::File(name) => Cow::Borrowed(
                    &side_files
                        .get(&name)
                        .ok_or_else(|| ImportError::MissingFile {
                            path: format!("{path}.uri"),
                            name: name.clone(),
                            available: upload.side_file_names(),
                        })?
                        .bytes,
                ),
            },
            None if i == 0 => Cow::Borrowed(bin.ok_or_else(|| {
                ImportError::invalid(&path, "has no uri and the file has no GLB binary chunk")
            })?),
            None => return Err(ImportError::invalid(&path, "has no uri")),
        };
        let declared = buffer.byte_length.0;
        if (data.len() as u64) < declared {
            return Err(ImportError::invalid(
                &path,
                format!(
                    "declares byteLength {declared} but its data has {} bytes",
                    data.len()
                ),
            ));
        }
        buffers.push(match data {
            Cow::Owned(mut bytes) => {
                bytes.truncate(declared as usize);
                bytes
            }
            Cow::Borrowed(bytes) => bytes[..declared as usize].to_vec(),
        });
    }
    Ok(buffers)
}

/// Every buffer view lies inside its buffer, whether or not an accessor
/// reads it (one holding an image, say): a view past the end is a broken
/// file, not a texture problem.
fn check_views(root: &json::Root, buffers: &[Vec<u8>]) -> Result<(), ImportError> {
    for (i, view) in root.buffer_views.iter().enumerate() {
        let path = format!("bufferViews[{i}]");
        let b = view.buffer.value();
        let buffer = buffers
            .get(b)
            .ok_or_else(|| ImportError::invalid(&path, format!("buffer {b} does not exist")))?;
        let offset = view.byte_offset.map_or(0, |o| o.0);
        let len = view.byte_length.0;
        if offset
            .checked_add(len)
            .is_none_or(|end| end > buffer.len() as u64)
        {
            return Err(ImportError::invalid(
                &path,
                format!(
                    "bytes {offset}..{} lie past the end of buffer {b} ({} bytes)",
                    offset.saturating_add(len),
                    buffer.len()
                ),
            ));
        }
    }
    Ok(())
}

/// Image URIs must be safe; a missing image is only a warning, since AO
/// does not use textures.
fn check_images(
    root: &json::Root,
    side_files: &SideFiles<'_>,
    warnings: &mut Vec<String>,
) -> Result<(), ImportError> {
    for (i, image) in root.images.iter().enumerate() {
        if let Some(uri) = &image.uri
            && let UriTarget::File(name) = resolve_uri(uri, &format!("images[{i}].uri"))?
            && side_files.get(&name).is_none()
        {
            warnings.push(format!(
                "images[{i}]: {name:?} is not among the files given with the glTF (AO does not need images)"
            ));
        }
    }
    Ok(())
}

/// The relative file names a `.gltf` refers to (buffers first, then
/// images), for callers that gather side files. Forbidden URIs are errors.
pub fn referenced_files(main: &[u8], limits: &Limits) -> Result<Vec<String>, ImportError> {
    let container = Container::parse(main)?;
    check_json_shape(container.json, limits)?;
    let root =
        json::Root::from_slice(container.json).map_err(|e| ImportError::Json(e.to_string()))?;
    let buffers = root
        .buffers
        .iter()
        .enumerate()
        .map(|(i, b)| (format!("buffers[{i}].uri"), &b.uri));
    let images = root
        .images
        .iter()
        .enumerate()
        .map(|(i, b)| (format!("images[{i}].uri"), &b.uri));
    let mut names = Vec::new();
    for (path, uri) in buffers.chain(images) {
        if let Some(uri) = uri
            && let UriTarget::File(name) = resolve_uri(uri, &path)?
        {
            names.push(name);
        }
    }
    Ok(names)
}
