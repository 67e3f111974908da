//! The bytes of an upload: GLB container parsing, JSON nesting check and URI
//! resolution among the files uploaded together.
//!
//! Nothing here touches the file system or the network: a URI is either a
//! `data:` URI, decoded in memory, or the name of one of the uploaded side
//! files.

use std::collections::HashMap;

use base64::Engine as _;
use percent_encoding::percent_decode_str;

use super::{ImportError, Limits};

/// One uploaded file: its name (as the client sent it, a relative path such
/// as `Fox.bin` or `textures/skin.png`) and its bytes.
#[derive(Debug, Clone)]
pub struct SideFile {
    /// Relative name, `/`-separated.
    pub name: String,
    /// Contents.
    pub bytes: Vec<u8>,
}

/// A glTF upload: the main file (`.glb` or `.gltf`) and the files uploaded
/// with it, which are the only places external URIs may point to.
#[derive(Debug, Clone, Copy)]
pub struct Upload<'a> {
    /// The `.glb` or `.gltf` bytes.
    pub main: &'a [u8],
    /// Buffers and images uploaded with a `.gltf`.
    pub side_files: &'a [SideFile],
}

impl<'a> Upload<'a> {
    /// An upload of one self-contained file (a `.glb`, or a `.gltf` whose
    /// buffers are all `data:` URIs).
    pub fn single(main: &'a [u8]) -> Self {
        Self {
            main,
            side_files: &[],
        }
    }

    /// The upload's content digest (lower-case hex sha256): of the file
    /// itself when it comes alone, else of the main file and the side files
    /// sorted by name, each framed by its length (and name), so that no
    /// two different uploads share a digest.
    pub fn digest(&self) -> String {
        use sha2::{Digest as _, Sha256};
        if self.side_files.is_empty() {
            return crate::digest::sha256_hex(self.main);
        }
        let mut h = Sha256::new();
        h.update((self.main.len() as u64).to_le_bytes());
        h.update(self.main);
        let mut files: Vec<&SideFile> = self.side_files.iter().collect();
        files.sort_by(|a, b| a.name.cmp(&b.name));
        for f in files {
            h.update((f.name.len() as u64).to_le_bytes());
            h.update(f.name.as_bytes());
            h.update((f.bytes.len() as u64).to_le_bytes());
            h.update(&f.bytes);
        }
        crate::digest::hex(&h.finalize())
    }

    pub(crate) fn total_bytes(&self) -> u64 {
        self.main.len() as u64
            + self
                .side_files
                .iter()
                .map(|f| f.bytes.len() as u64)
                .sum::<u64>()
    }

    pub(crate) fn side_file_names(&self) -> String {
        if self.side_files.is_empty() {
            return "none".into();
        }
        let names: Vec<&str> = self.side_files.iter().map(|f| f.name.as_str()).collect();
        names.join(", ")
    }
}

/// The side files of an upload, found by the normalised relative path a
/// URI resolves to; else by its last path segment when one file alone has
/// it, since clients often upload `scene.bin` for a URI `data/scene.bin`.
/// Built once per import: a lookup is a hash, not a scan of the parts.
pub(crate) struct SideFiles<'a> {
    files: &'a [SideFile],
    by_path: HashMap<String, usize>,
    /// The files of each last path segment, in upload order.
    by_base: HashMap<String, Vec<usize>>,
}

impl<'a> SideFiles<'a> {
    pub(crate) fn new(files: &'a [SideFile]) -> Self {
        let mut by_path = HashMap::with_capacity(files.len());
        let mut by_base: HashMap<String, Vec<usize>> = HashMap::with_capacity(files.len());
        for (i, f) in files.iter().enumerate() {
            let path = normalize_name(&f.name);
            by_base
                .entry(last_segment(&path).to_owned())
                .or_default()
                .push(i);
            // The first of two files with one name, as a scan would find.
            by_path.entry(path).or_insert(i);
        }
        Self {
            files,
            by_path,
            by_base,
        }
    }

    /// The index of the file `path` names.
    pub(crate) fn position(&self, path: &str) -> Option<usize> {
        let wanted = normalize_name(path);
        self.by_path.get(&wanted).copied().or_else(|| {
            match self.by_base.get(last_segment(&wanted)) {
                Some(files) if files.len() == 1 => Some(files[0]),
                _ => None,
            }
        })
    }

    /// Every file whose last path segment is `path`'s, in upload order.
    pub(crate) fn sharing_last_segment(&self, path: &str) -> &[usize] {
        let wanted = normalize_name(path);
        self.by_base
            .get(last_segment(&wanted))
            .map_or(&[], Vec::as_slice)
    }

    /// The file `path` names.
    pub(crate) fn get(&self, path: &str) -> Option<&'a SideFile> {
        self.position(path).map(|i| &self.files[i])
    }
}

fn last_segment(path: &str) -> &str {
    path.rsplit('/').next().unwrap_or(path)
}

fn normalize_name(name: &str) -> String {
    name.split('/')
        .filter(|s| !s.is_empty() && *s != ".")
        .collect::<Vec<_>>()
        .join("/")
}

/// The two chunks of a GLB. glTF's own `Glb::from_slice` subtracts before it
/// checks and so panics on a header length below 12; this parser checks
/// every length against the bytes actually present first.
pub(crate) struct Container<'a> {
    pub(crate) json: &'a [u8],
    pub(crate) bin: Option<&'a [u8]>,
}

const GLB_MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;

fn read_u32(bytes: &[u8], at: usize) -> Option<u32> {
    let b = bytes.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

impl<'a> Container<'a> {
    pub(crate) fn parse(bytes: &'a [u8]) -> Result<Self, ImportError> {
        if !bytes.starts_with(GLB_MAGIC) {
            // Not a GLB: it must be JSON, an object. Say what the file is
            // not, rather than where a JSON parser gave up on it.
            match bytes.iter().find(|b| !b.is_ascii_whitespace()) {
                None => return Err(ImportError::Json("the file is empty".into())),
                Some(b'{') => {}
                Some(_) => {
                    return Err(ImportError::Json(
                        "the file is neither a GLB (it does not start with `glTF`) nor glTF JSON (it does not start with `{`)".into(),
                    ));
                }
            }
            return Ok(Self {
                json: bytes,
                bin: None,
            });
        }
        let err = |m: String| ImportError::Container(m);
        let version = read_u32(bytes, 4).ok_or_else(|| err("truncated header".into()))?;
        if version != 2 {
            return Err(err(format!(
                "version {version}, only version 2 is supported"
            )));
        }
        let declared = read_u32(bytes, 8).ok_or_else(|| err("truncated header".into()))? as usize;
        if declared > bytes.len() {
            return Err(err(format!(
                "header declares {declared} bytes but the file has {}",
                bytes.len()
            )));
        }
        if declared < 12 {
            return Err(err(format!(
                "header declares {declared} bytes, less than the header itself"
            )));
        }
        let body = &bytes[..declared];
        let mut at = 12usize;
        let mut json = None;
        let mut bin = None;
        let mut index = 0;
        while at < body.len() {
            let len = read_u32(body, at).ok_or_else(|| {
                err(format!(
                    "chunk {index}: truncated chunk header at byte {at}"
                ))
            })? as usize;
            let ty = read_u32(body, at + 4).ok_or_else(|| {
                err(format!(
                    "chunk {index}: truncated chunk header at byte {at}"
                ))
            })?;
            let start = at + 8;
            let end = start
                .checked_add(len)
                .filter(|&end| end <= body.len())
                .ok_or_else(|| {
                    err(format!(
                        "chunk {index}: declares {len} bytes but only {} remain",
                        body.len().saturating_sub(start)
                    ))
                })?;
            let data = &body[start..end];
            match (index, ty) {
                (0, CHUNK_JSON) => json = Some(data),
                (0, _) => return Err(err(format!("first chunk has type {ty:#010x}, not JSON"))),
                (1, CHUNK_BIN) => bin = Some(data),
                // Only the second chunk may be BIN (GLB_DUPLICATE_CHUNK,
                // GLB_UNEXPECTED_BIN_CHUNK): a reader could take either.
                (_, CHUNK_BIN) => {
                    return Err(err(format!(
                        "chunk {index} is a BIN chunk; only the chunk after JSON may be"
                    )));
                }
                (_, CHUNK_JSON) => {
                    return Err(err(format!("chunk {index} is a second JSON chunk")));
                }
                // The spec says readers ignore chunks of unknown type.
                _ => {}
            }
            // Chunks are 4-byte aligned; a writer that forgot padding still
            // gets its next chunk read at the exact end of the last one.
            at = end;
            index += 1;
        }
        let json = json.ok_or_else(|| err("no JSON chunk".into()))?;
        Ok(Self { json, bin })
    }
}

/// Refuses JSON that nests arrays or objects deeper than
/// `limits.max_json_depth` or holds more than `limits.max_json_values`
/// values, with one pass over the bytes before any parser allocates for
/// them (a parsed value costs tens of bytes, so `[0,0,0,…]` would cost
/// sixteen times its text).
pub(crate) fn check_json_shape(json: &[u8], limits: &Limits) -> Result<(), ImportError> {
    let mut depth = 0usize;
    // Each container and each comma outside strings starts a value (at
    // least one value is counted per value; a key counts with its value).
    let mut values = 1u64;
    let mut in_string = false;
    let mut escaped = false;
    for &b in json {
        if in_string {
            match (escaped, b) {
                (true, _) => escaped = false,
                (false, b'\\') => escaped = true,
                (false, b'"') => in_string = false,
                _ => {}
            }
            continue;
        }
        match b {
            b'"' => in_string = true,
            b'{' | b'[' => {
                depth += 1;
                values += 1;
                if depth > limits.max_json_depth {
                    return Err(ImportError::limit(
                        "JSON nesting depth",
                        depth as u64,
                        limits.max_json_depth as u64,
                    ));
                }
            }
            b',' => values += 1,
            b'}' | b']' => depth = depth.saturating_sub(1),
            _ => {}
        }
        if values > limits.max_json_values {
            return Err(ImportError::limit(
                "values in the JSON (numbers, strings, arrays, objects)",
                values,
                limits.max_json_values,
            ));
        }
    }
    Ok(())
}

/// Where a URI points after validation.
#[derive(Debug, PartialEq)]
pub(crate) enum UriTarget {
    /// A `data:` URI, decoded.
    Data(Vec<u8>),
    /// A normalised relative path, to be looked up among the side files.
    File(String),
}

/// Validates and resolves a glTF URI. `path` names the JSON field for the
/// error message.
pub(crate) fn resolve_uri(uri: &str, path: &str) -> Result<UriTarget, ImportError> {
    let forbid = |reason| ImportError::ForbiddenUri {
        path: path.to_owned(),
        uri: uri.chars().take(120).collect(),
        reason,
    };
    if let Some(rest) = uri.strip_prefix("data:") {
        let (meta, payload) = rest
            .split_once(',')
            .ok_or_else(|| forbid("data URI without a comma"))?;
        let bytes = if meta.ends_with(";base64") {
            base64::engine::general_purpose::STANDARD
                .decode(payload.trim())
                .map_err(|_| forbid("data URI with invalid base64"))?
        } else {
            percent_decode_str(payload).collect()
        };
        return Ok(UriTarget::Data(bytes));
    }
    // A scheme is letters, digits, `+-.` before the first `:` that comes
    // before any `/`, `?` or `#` (RFC 3986 §3.1). `C:\x` counts as one too.
    if let Some(colon) = uri.find(':')
        && !uri[..colon].contains(['/', '?', '#'])
    {
        return Err(forbid(
            "only data: URIs and relative names of uploaded files are allowed",
        ));
    }
    let decoded = percent_decode_str(uri)
        .decode_utf8()
        .map_err(|_| forbid("percent-encoding does not decode to UTF-8"))?;
    if decoded.contains('\0') {
        return Err(forbid("contains a NUL character"));
    }
    if decoded.contains('\\') {
        return Err(forbid("contains a backslash"));
    }
    if decoded.starts_with('/') {
        return Err(forbid("absolute paths are not allowed"));
    }
    // Query and fragment are not part of a file name.
    let name = decoded.split(['?', '#']).next().unwrap_or_default();
    let mut segments = Vec::new();
    for segment in name.split('/') {
        match segment {
            "" | "." => {}
            ".." => return Err(forbid("`..` segments are not allowed")),
            s => segments.push(s),
        }
    }
    if segments.is_empty() {
        return Err(forbid("empty file name"));
    }
    Ok(UriTarget::File(segments.join("/")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_that_is_neither_glb_nor_json_is_named_as_such() {
        let said = |bytes: &[u8]| match Container::parse(bytes) {
            Err(ImportError::Json(m)) => m,
            other => panic!("{:?}", other.map(|c| c.json.len())),
        };
        assert_eq!(said(b""), "the file is empty");
        assert_eq!(said(b" \n\t"), "the file is empty");
        for junk in [&b"hello world"[..], b"\x89PNG\r\n", b"[1, 2]"] {
            assert!(said(junk).contains("neither a GLB"), "{junk:?}");
        }
        // JSON objects (after whitespace) go on to the JSON parser.
        assert!(Container::parse(b"  {\"asset\": {}}").is_ok());
    }

    #[test]
    fn uris_resolve_only_to_data_or_relative_names() {
        assert_eq!(
            resolve_uri("Fox.bin", "b").unwrap(),
            UriTarget::File("Fox.bin".into())
        );
        assert_eq!(
            resolve_uri("./data/My%20Mesh.bin", "b").unwrap(),
            UriTarget::File("data/My Mesh.bin".into())
        );
        assert_eq!(
            resolve_uri("data:application/octet-stream;base64,AAEC", "b").unwrap(),
            UriTarget::Data(vec![0, 1, 2])
        );
        for bad in [
            "../secret.bin",
            "a/../../etc/passwd",
            "%2e%2e/x.bin",
            "/etc/passwd",
            "file:///etc/passwd",
            "http://example.com/a.bin",
            "C:\\Windows\\a.bin",
            "a\\..\\b.bin",
            "x%00.bin",
            "",
        ] {
            let err = resolve_uri(bad, "buffers[0].uri").unwrap_err();
            assert!(
                matches!(err, ImportError::ForbiddenUri { .. }),
                "{bad}: {err}"
            );
        }
    }

    #[test]
    fn glb_lengths_are_checked_before_use() {
        let mut glb = b"glTF".to_vec();
        glb.extend_from_slice(&2u32.to_le_bytes());
        glb.extend_from_slice(&4u32.to_le_bytes());
        assert!(matches!(
            Container::parse(&glb),
            Err(ImportError::Container(_))
        ));
        let mut glb = b"glTF".to_vec();
        glb.extend_from_slice(&2u32.to_le_bytes());
        glb.extend_from_slice(&24u32.to_le_bytes());
        glb.extend_from_slice(&1000u32.to_le_bytes());
        glb.extend_from_slice(&CHUNK_JSON.to_le_bytes());
        glb.extend_from_slice(b"{}  ");
        let err = Container::parse(&glb).err().unwrap();
        assert!(err.to_string().contains("declares 1000 bytes"), "{err}");
    }

    #[test]
    fn json_depth_ignores_brackets_in_strings() {
        let depth = |max_json_depth| Limits {
            max_json_depth,
            ..Limits::default()
        };
        assert!(check_json_shape(br#"{"a":"[[[[[[[[[["}"#, &depth(2)).is_ok());
        assert!(check_json_shape(br#"{"a":"\"[[[["}"#, &depth(2)).is_ok());
        assert!(check_json_shape(b"[[[]]]", &depth(2)).is_err());
    }

    #[test]
    fn json_values_are_counted_outside_strings() {
        let values = |max_json_values| Limits {
            max_json_values,
            ..Limits::default()
        };
        // The object, its array and the array's three numbers.
        let json = br#"{"extras":[0,0,0],"name":"a,b,c,d,e,f"}"#;
        assert!(check_json_shape(json, &values(6)).is_ok());
        let err = check_json_shape(json, &values(4)).unwrap_err();
        assert_eq!(err.code(), "limit_exceeded");
        assert!(err.to_string().contains("values in the JSON"), "{err}");
    }
}
