//! The one error type of glTF import.

/// Why a glTF upload was refused. Every variant names the part of the file
/// that is wrong (a JSON path such as `accessors[3]`, an element index), so
/// the message can go back to the user as is.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ImportError {
    /// The GLB container (header or chunks) is malformed.
    #[error("malformed GLB container: {0}")]
    Container(String),
    /// The JSON does not parse, or does not have glTF's shape.
    #[error("invalid glTF JSON: {0}")]
    Json(String),
    /// A declared size or count is over a configured limit.
    #[error("{what} is {count}, over the limit of {limit}")]
    Limit {
        /// What was counted.
        what: String,
        /// Where in the glTF the count is, when it is at one place (the
        /// JSON path `accessors[3].count`); `None` for a file-wide count.
        at: Option<String>,
        /// The count the file declares.
        count: u64,
        /// The configured limit.
        limit: u64,
    },
    /// A URI is not allowed: only `data:` URIs and names of files uploaded
    /// with the glTF are.
    #[error("{path}: URI {uri:?} is not allowed: {reason}")]
    ForbiddenUri {
        /// Where the URI is, e.g. `buffers[1].uri`.
        path: String,
        /// The URI as written in the file (truncated).
        uri: String,
        /// Why it is refused.
        reason: &'static str,
    },
    /// A buffer's file is not among the files given with the glTF (the
    /// upload's parts, or the files beside a `.gltf` on the command line).
    #[error(
        "{path}: file {name:?} is not among the files given with the glTF (given: {available})"
    )]
    MissingFile {
        /// Where the reference is, e.g. `buffers[0].uri`.
        path: String,
        /// The file name the glTF asks for.
        name: String,
        /// The names that were uploaded.
        available: String,
    },
    /// The file requires an extension that changes geometry and that aobake
    /// does not decode.
    #[error("extensionsRequired[{index}] is {name:?}, which aobake does not support")]
    UnsupportedExtension {
        /// Its place in `extensionsRequired`.
        index: usize,
        /// The extension's name.
        name: String,
    },
    /// Anything else that is wrong at a given place in the file.
    #[error("{path}: {problem}")]
    Invalid {
        /// Where in the glTF, e.g. `meshes[0].primitives[1].attributes.JOINTS_0`.
        path: String,
        /// What is wrong there.
        problem: String,
    },
    /// The file has no triangles to bake.
    #[error("the scene has no triangle meshes")]
    NoGeometry,
    /// A clips file none of whose animations drives a node of the
    /// character (by name); `in_file`: whether it has animations at all.
    #[error("{}", if *in_file {
        "no animation in the file drives the character: no channel targets a node name it has"
    } else {
        "the file has no animations"
    })]
    NoAnimations {
        /// The file has animations (that drive none of the character's
        /// nodes).
        in_file: bool,
    },
}

impl ImportError {
    pub(crate) fn invalid(path: impl Into<String>, problem: impl Into<String>) -> Self {
        Self::Invalid {
            path: path.into(),
            problem: problem.into(),
        }
    }

    /// A file-wide count over its limit.
    pub(crate) fn limit(what: impl Into<String>, count: u64, limit: u64) -> Self {
        Self::Limit {
            what: what.into(),
            at: None,
            count,
            limit,
        }
    }

    /// A count at the JSON path `at` over its limit.
    pub(crate) fn limit_at(
        at: impl Into<String>,
        what: impl Into<String>,
        count: u64,
        limit: u64,
    ) -> Self {
        Self::Limit {
            what: what.into(),
            at: Some(at.into()),
            count,
            limit,
        }
    }

    /// A stable machine-readable code for the error's kind, for API
    /// responses (`problem+json` `code`).
    pub fn code(&self) -> &'static str {
        match self {
            Self::Container(_) => "gltf_container",
            Self::Json(_) => "gltf_json",
            Self::Limit { .. } => "limit_exceeded",
            Self::ForbiddenUri { .. } => "forbidden_uri",
            Self::MissingFile { .. } => "missing_file",
            Self::UnsupportedExtension { .. } => "unsupported_extension",
            Self::Invalid { .. } => "gltf_invalid",
            Self::NoGeometry => "no_geometry",
            Self::NoAnimations { .. } => "no_animations",
        }
    }

    /// Where in the glTF JSON the error is, as an RFC 6901 JSON Pointer
    /// (`/meshes/0/primitives/1/attributes/JOINTS_0` for the path
    /// `meshes[0].primitives[1].attributes.JOINTS_0`), when the error names
    /// one: for API responses (`problem+json` `pointer`).
    pub fn pointer(&self) -> Option<String> {
        match self {
            Self::Invalid { path, .. }
            | Self::ForbiddenUri { path, .. }
            | Self::MissingFile { path, .. }
            | Self::Limit { at: Some(path), .. } => json_pointer(path),
            Self::UnsupportedExtension { index, .. } => {
                Some(format!("/extensionsRequired/{index}"))
            }
            _ => None,
        }
    }
}

/// Appends member `key` of a JSON object to the JSON path `path`: `.key`
/// for a name like glTF's own, `["key"]` for one from the file that is
/// not (`_UV.x`), as gltf-json writes map keys, so that the path reads
/// back as one member.
pub(crate) fn push_member(path: &mut String, key: &str) {
    if is_name(key) {
        if !path.is_empty() {
            path.push('.');
        }
        path.push_str(key);
    } else {
        path.push_str(&format!("[\"{key}\"]"));
    }
}

/// Whether `key` is written as `.key` in a JSON path.
fn is_name(key: &str) -> bool {
    let mut chars = key.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// The JSON Pointer of a JSON path made of member names, array indices
/// and quoted keys (`a[3].b["c/d"]`: `/a/3/b/c~1d`); `None` for any other
/// text (a chunk's number, a description).
fn json_pointer(path: &str) -> Option<String> {
    let mut out = String::new();
    let mut rest = path;
    let mut first = true;
    while !rest.is_empty() {
        if let Some(after) = rest.strip_prefix("[\"") {
            // A quoted key, as gltf-json and `push_member` write it: as
            // it is, up to the closing `"]` (a key holding `"]` itself
            // reads short, and the path then does not parse).
            let end = after.find("\"]")?;
            let key = &after[..end];
            out.push('/');
            out.push_str(&key.replace('~', "~0").replace('/', "~1"));
            rest = &after[end + 2..];
        } else if let Some(after) = rest.strip_prefix('[') {
            let (index, after) = after.split_once(']')?;
            if index.is_empty() || !index.bytes().all(|b| b.is_ascii_digit()) {
                return None;
            }
            out.push('/');
            out.push_str(index);
            rest = after;
        } else {
            let name = if first { rest } else { rest.strip_prefix('.')? };
            let end = name.find(['.', '[']).unwrap_or(name.len());
            if !is_name(&name[..end]) {
                return None;
            }
            out.push('/');
            out.push_str(&name[..end]);
            rest = &name[end..];
        }
        first = false;
    }
    (!out.is_empty()).then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_paths_become_pointers_and_other_text_does_not() {
        for (path, pointer) in [
            ("accessors[3]", Some("/accessors/3")),
            (
                "meshes[0].primitives[1].attributes.JOINTS_0",
                Some("/meshes/0/primitives/1/attributes/JOINTS_0"),
            ),
            ("buffers[0].uri", Some("/buffers/0/uri")),
            ("skins[2].joints[10]", Some("/skins/2/joints/10")),
            ("asset", Some("/asset")),
            ("chunk 2", None),
            ("accessors[x]", None),
            ("accessors[]", None),
            ("accessors[1", None),
            ("a..b", None),
            ("", None),
            (
                "meshes[0].primitives[0].attributes[\"POSITION\"]",
                Some("/meshes/0/primitives/0/attributes/POSITION"),
            ),
            (
                "meshes[0].primitives[1].attributes[\"_UV.x/y~z\"]",
                Some("/meshes/0/primitives/1/attributes/_UV.x~1y~0z"),
            ),
            ("nodes[2][\"unterminated", None),
            (".asset", None),
        ] {
            let e = ImportError::invalid(path, "is wrong");
            assert_eq!(e.pointer().as_deref(), pointer, "{path}");
        }
        assert_eq!(ImportError::NoGeometry.pointer(), None);
        for (at, pointer) in [
            ("accessors[3].count", "/accessors/3/count"),
            (
                "meshes[0].primitives[1].targets",
                "/meshes/0/primitives/1/targets",
            ),
            ("meshes[2].primitives[0]", "/meshes/2/primitives/0"),
        ] {
            let e = ImportError::limit_at(at, "a count", 10, 5);
            assert_eq!(e.pointer().as_deref(), Some(pointer), "{at}");
        }
        for what in ["vertex count", "animation count"] {
            assert_eq!(ImportError::limit(what, 10, 5).pointer(), None, "{what}");
        }
    }

    #[test]
    fn members_from_the_file_read_back_as_one_member() {
        let mut path = "meshes[0].primitives[1]".to_owned();
        push_member(&mut path, "attributes");
        push_member(&mut path, "_UV.x");
        assert_eq!(path, "meshes[0].primitives[1].attributes[\"_UV.x\"]");
        assert_eq!(
            json_pointer(&path).as_deref(),
            Some("/meshes/0/primitives/1/attributes/_UV.x")
        );
        let mut top = String::new();
        push_member(&mut top, "asset");
        assert_eq!(top, "asset");
    }
}
