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
    #[error("extensionsRequired lists {0:?}, which aobake does not support")]
    UnsupportedExtension(String),
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
    /// character (by name).
    #[error("no animation channel targets a node name of the character")]
    NoAnimations,
}

impl ImportError {
    pub(crate) fn invalid(path: impl Into<String>, problem: impl Into<String>) -> Self {
        Self::Invalid {
            path: path.into(),
            problem: problem.into(),
        }
    }

    pub(crate) fn limit(what: impl Into<String>, count: u64, limit: u64) -> Self {
        Self::Limit {
            what: what.into(),
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
            Self::UnsupportedExtension(_) => "unsupported_extension",
            Self::Invalid { .. } => "gltf_invalid",
            Self::NoGeometry => "no_geometry",
            Self::NoAnimations => "no_animations",
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
            | Self::MissingFile { path, .. } => json_pointer(path),
            _ => None,
        }
    }
}

/// The JSON Pointer of a JSON path made of member names and array indices
/// (`a[3].b`: `/a/3/b`); `None` for any other text (a chunk's number, a
/// description).
fn json_pointer(path: &str) -> Option<String> {
    let mut out = String::new();
    for member in path.split('.') {
        let (name, mut rest) = member.split_at(member.find('[').unwrap_or(member.len()));
        let mut chars = name.chars();
        if !chars
            .next()
            .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
            || !chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
        {
            return None;
        }
        out.push('/');
        out.push_str(name);
        while !rest.is_empty() {
            let (index, after) = rest.strip_prefix('[')?.split_once(']')?;
            if index.is_empty() || !index.bytes().all(|b| b.is_ascii_digit()) {
                return None;
            }
            out.push('/');
            out.push_str(index);
            rest = after;
        }
    }
    Some(out)
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
        ] {
            let e = ImportError::invalid(path, "is wrong");
            assert_eq!(e.pointer().as_deref(), pointer, "{path}");
        }
        assert_eq!(ImportError::NoGeometry.pointer(), None);
    }
}
