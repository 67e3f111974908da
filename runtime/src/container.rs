//! The asset container (DESIGN §7; the byte layout is specified in
//! `docs/asset-format.md`): one little-endian file per bake with a magic,
//! a format version, the method, a JSON header and typed sections, each
//! with a CRC-32.
//!
//! Compatibility: a reader of version `major.minor` reads every file of the
//! same major (it ignores header fields and section tags it does not know,
//! which is all a minor version may add) and rejects a newer major with
//! [`AssetError::NewerMajor`]. Nothing in a file depends on the time, so
//! the same bake by the same build on the same machine gives the same
//! bytes (faer chooses SIMD kernels at run time, so fits on CPUs with other
//! vector units may differ in the last bits).

use half::f16;

use crate::method::Method;
use serde::{Deserialize, Serialize, de::DeserializeOwned};

/// First eight bytes of every asset. Like PNG's: a high-bit byte catches
/// 7-bit transfers, CR LF and LF catch newline conversion.
pub const MAGIC: [u8; 8] = *b"\x89AOB\r\n\x1a\n";
/// Format major version this build writes and reads.
pub const MAJOR: u16 = 1;
/// Format minor version this build writes.
pub const MINOR: u16 = 6;

/// Fixed part before the header: magic, major, minor, method, flags,
/// header length, section count, reserved, CRC.
const PREAMBLE: usize = 32;
/// Per-section record before its data.
const SECTION_HEAD: usize = 24;
/// Headers and sections start on multiples of this.
const ALIGN: usize = 8;
/// A header longer than this is refused before it is read.
const MAX_HEADER_BYTES: usize = 16 << 20;

/// The element type of a section.
#[derive(Debug, Clone, PartialEq)]
pub enum Data {
    /// Half floats.
    F16(Vec<f16>),
    /// Floats.
    F32(Vec<f32>),
    /// Bytes.
    U8(Vec<u8>),
    /// 16-bit unsigned integers.
    U16(Vec<u16>),
    /// 32-bit unsigned integers.
    U32(Vec<u32>),
}

impl Data {
    fn code(&self) -> u8 {
        match self {
            Self::F16(_) => 1,
            Self::F32(_) => 2,
            Self::U8(_) => 3,
            Self::U16(_) => 4,
            Self::U32(_) => 5,
        }
    }

    fn element_size(code: u8) -> Option<usize> {
        Some(match code {
            1 | 4 => 2,
            2 | 5 => 4,
            3 => 1,
            _ => return None,
        })
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        match self {
            Self::F16(v) => v.len(),
            Self::F32(v) => v.len(),
            Self::U8(v) => v.len(),
            Self::U16(v) => v.len(),
            Self::U32(v) => v.len(),
        }
    }

    /// Whether the section holds no elements.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The element type as `docs/asset-format.md` names it.
    pub fn type_name(&self) -> &'static str {
        match self {
            Self::F16(_) => "f16",
            Self::F32(_) => "f32",
            Self::U8(_) => "u8",
            Self::U16(_) => "u16",
            Self::U32(_) => "u32",
        }
    }

    /// Bytes of the elements (the section's data, without its record and
    /// padding).
    pub fn byte_len(&self) -> usize {
        self.len() * Self::element_size(self.code()).unwrap_or_default()
    }

    fn write_le(&self, out: &mut Vec<u8>) {
        match self {
            Self::F16(v) => v.iter().for_each(|x| out.extend(x.to_le_bytes())),
            Self::F32(v) => v.iter().for_each(|x| out.extend(x.to_le_bytes())),
            Self::U8(v) => out.extend(v),
            Self::U16(v) => v.iter().for_each(|x| out.extend(x.to_le_bytes())),
            Self::U32(v) => v.iter().for_each(|x| out.extend(x.to_le_bytes())),
        }
    }

    fn read_le(code: u8, bytes: &[u8]) -> Self {
        fn chunks<const N: usize, T>(bytes: &[u8], f: fn([u8; N]) -> T) -> Vec<T> {
            bytes
                .chunks_exact(N)
                .map(|c| f(c.try_into().expect("exact chunk")))
                .collect()
        }
        match code {
            1 => Self::F16(chunks(bytes, f16::from_le_bytes)),
            2 => Self::F32(chunks(bytes, f32::from_le_bytes)),
            4 => Self::U16(chunks(bytes, u16::from_le_bytes)),
            5 => Self::U32(chunks(bytes, u32::from_le_bytes)),
            _ => Self::U8(bytes.to_vec()),
        }
    }
}

/// A tagged array.
#[derive(Debug, Clone, PartialEq)]
pub struct Section {
    /// Four ASCII bytes naming the content, such as `COEF`.
    pub tag: [u8; 4],
    /// The elements.
    pub data: Data,
}

/// A decoded container: the method, the JSON header and the sections, in
/// file order.
#[derive(Debug, Clone, PartialEq)]
pub struct Container {
    /// The method.
    pub method: Method,
    /// Format version the file was written with.
    pub version: (u16, u16),
    /// The header, as JSON text.
    pub header: String,
    /// The sections.
    pub sections: Vec<Section>,
}

/// Why bytes are not a readable asset.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AssetError {
    /// Not an aobake asset at all.
    #[error("not an aobake asset (bad magic bytes)")]
    Magic,
    /// Written by a newer, incompatible format.
    #[error(
        "asset format {major}.{minor} is newer than this reader (format {MAJOR}.x); upgrade aobake to read it"
    )]
    NewerMajor {
        /// The file's major version.
        major: u16,
        /// The file's minor version.
        minor: u16,
    },
    /// The file ends early or has bytes after its last section.
    #[error("asset is truncated or malformed: {0}")]
    Truncated(String),
    /// A checksum does not match: the bytes were damaged.
    #[error("asset is corrupt: checksum mismatch in {0}")]
    Checksum(String),
    /// A field has an impossible value.
    #[error("asset is malformed: {0}")]
    Malformed(String),
    /// Sound, but without what the reader was asked for.
    #[error("the asset cannot do this: {0}")]
    Unsupported(String),
    /// Sound, but what the caller gave it does not fit it (a palette
    /// shorter than its parts need).
    #[error("the input does not fit the asset: {0}")]
    Mismatch(String),
}

fn tag_name(tag: [u8; 4]) -> String {
    String::from_utf8_lossy(&tag).into_owned()
}

/// CRC-32 of the preamble after the magic (version, method, flags, lengths)
/// and the header text.
fn header_crc(preamble: &[u8], header: &[u8]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(preamble);
    h.update(header);
    h.finalize()
}

/// CRC-32 of a section's record (tag, type, count) and its data.
fn section_crc(record: &[u8], data: &[u8]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(record);
    h.update(data);
    h.finalize()
}

fn pad(out: &mut Vec<u8>) {
    out.resize(out.len().next_multiple_of(ALIGN), 0);
}

impl Container {
    /// A container of the current format version.
    pub fn new(method: Method, header: &impl Serialize, sections: Vec<Section>) -> Self {
        Self {
            method,
            version: (MAJOR, MINOR),
            header: serde_json::to_string(header).expect("headers serialise"),
            sections,
        }
    }

    /// The header parsed as `T`.
    pub fn header<T: DeserializeOwned>(&self) -> Result<T, AssetError> {
        serde_json::from_str(&self.header)
            .map_err(|e| AssetError::Malformed(format!("header: {e}")))
    }

    /// The first section tagged `tag`.
    pub fn section(&self, tag: &[u8; 4]) -> Result<&Data, AssetError> {
        self.sections
            .iter()
            .find(|s| &s.tag == tag)
            .map(|s| &s.data)
            .ok_or_else(|| AssetError::Malformed(format!("missing section {}", tag_name(*tag))))
    }

    /// The bytes of the file.
    pub fn to_bytes(&self) -> Vec<u8> {
        let header = self.header.as_bytes();
        let mut out = Vec::with_capacity(
            PREAMBLE
                + header.len()
                + self
                    .sections
                    .iter()
                    .map(|s| SECTION_HEAD + 4 * s.data.len() + ALIGN)
                    .sum::<usize>(),
        );
        out.extend(MAGIC);
        out.extend(self.version.0.to_le_bytes());
        out.extend(self.version.1.to_le_bytes());
        out.extend((self.method as u16).to_le_bytes());
        out.extend(0u16.to_le_bytes());
        out.extend(
            u32::try_from(header.len())
                .expect("header fits")
                .to_le_bytes(),
        );
        out.extend(
            u32::try_from(self.sections.len())
                .expect("sections fit")
                .to_le_bytes(),
        );
        out.extend(0u32.to_le_bytes());
        let crc = header_crc(&out[MAGIC.len()..], header);
        out.extend(crc.to_le_bytes());
        out.extend(header);
        pad(&mut out);
        let mut data = Vec::new();
        for section in &self.sections {
            data.clear();
            section.data.write_le(&mut data);
            let record = out.len();
            out.extend(section.tag);
            out.push(section.data.code());
            out.extend([0; 3]);
            out.extend((section.data.len() as u64).to_le_bytes());
            out.extend(0u32.to_le_bytes());
            let crc = section_crc(&out[record..], &data);
            out.extend(crc.to_le_bytes());
            out.extend(&data);
            pad(&mut out);
        }
        out
    }

    /// Reads a file, checking the magic, the version, every length and
    /// every checksum.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, AssetError> {
        let mut r = Reader { bytes, at: 0 };
        if bytes.len() < MAGIC.len() || bytes[..MAGIC.len()] != MAGIC {
            return Err(AssetError::Magic);
        }
        r.at = MAGIC.len();
        let major = r.u16("version")?;
        let minor = r.u16("version")?;
        if major > MAJOR {
            return Err(AssetError::NewerMajor { major, minor });
        }
        if major == 0 {
            return Err(AssetError::Malformed("format major version 0".into()));
        }
        let method_code = r.u16("method")?;
        let method = Method::from_code(method_code)
            .ok_or_else(|| AssetError::Malformed(format!("unknown method code {method_code}")))?;
        let _flags = r.u16("flags")?;
        let header_len = r.u32("header length")? as usize;
        let count = r.u32("section count")? as usize;
        let _reserved = r.u32("preamble")?;
        let preamble = &bytes[MAGIC.len()..r.at];
        let crc = r.u32("header checksum")?;
        if header_len > MAX_HEADER_BYTES {
            return Err(AssetError::Malformed(format!(
                "header of {header_len} bytes (the limit is {MAX_HEADER_BYTES})"
            )));
        }
        let header = r.take(header_len, "header")?;
        if header_crc(preamble, header) != crc {
            return Err(AssetError::Checksum("the header".into()));
        }
        let header = std::str::from_utf8(header)
            .map_err(|_| AssetError::Malformed("header is not UTF-8".into()))?
            .to_owned();
        r.align("header")?;
        // Each section needs at least its record, so `count` is bounded by
        // the bytes left before anything is allocated for it.
        if count > (bytes.len() - r.at) / SECTION_HEAD {
            return Err(AssetError::Truncated(format!(
                "{count} sections declared in {} bytes",
                bytes.len()
            )));
        }
        let mut sections = Vec::with_capacity(count);
        for _ in 0..count {
            let record = r.at;
            let tag: [u8; 4] = r.take(4, "section tag")?.try_into().expect("4 bytes");
            let name = tag_name(tag);
            let code = r.take(4, &name)?[0];
            let len = r.u64(&name)?;
            let _reserved = r.u32(&name)?;
            let record = &bytes[record..r.at];
            let crc = r.u32(&name)?;
            let size = Data::element_size(code).ok_or_else(|| {
                AssetError::Malformed(format!("section {name} has unknown element type {code}"))
            })?;
            let byte_len = usize::try_from(len)
                .ok()
                .and_then(|n| n.checked_mul(size))
                .ok_or_else(|| AssetError::Truncated(format!("section {name} is too long")))?;
            let data = r.take(byte_len, &name)?;
            if section_crc(record, data) != crc {
                return Err(AssetError::Checksum(format!("section {name}")));
            }
            sections.push(Section {
                tag,
                data: Data::read_le(code, data),
            });
            r.align(&name)?;
        }
        if r.at != bytes.len() {
            return Err(AssetError::Truncated(format!(
                "{} bytes after the last section",
                bytes.len() - r.at
            )));
        }
        Ok(Self {
            method,
            version: (major, minor),
            header,
            sections,
        })
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], AssetError> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.bytes.len())
            .ok_or_else(|| AssetError::Truncated(format!("file ends inside {what}")))?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn u16(&mut self, what: &str) -> Result<u16, AssetError> {
        Ok(u16::from_le_bytes(
            self.take(2, what)?.try_into().expect("2"),
        ))
    }

    fn u32(&mut self, what: &str) -> Result<u32, AssetError> {
        Ok(u32::from_le_bytes(
            self.take(4, what)?.try_into().expect("4"),
        ))
    }

    fn u64(&mut self, what: &str) -> Result<u64, AssetError> {
        Ok(u64::from_le_bytes(
            self.take(8, what)?.try_into().expect("8"),
        ))
    }

    fn align(&mut self, what: &str) -> Result<(), AssetError> {
        let n = self.at.next_multiple_of(ALIGN) - self.at;
        if self.take(n, what)?.iter().any(|&b| b != 0) {
            return Err(AssetError::Malformed(format!(
                "non-zero padding after {what}"
            )));
        }
        Ok(())
    }
}

/// The parts of the header that come from the bake rather than the model.
#[derive(Debug, Clone, PartialEq)]
pub struct AssetHeaderFields {
    /// The program that wrote it, such as `aobake 0.1.0`.
    pub generator: String,
    /// The bake key.
    pub bake_key: String,
    /// sha256 of the character upload.
    pub character: String,
    /// sha256 of the clip uploads.
    pub clips: Vec<String>,
    /// The bake's fully defaulted parameters.
    pub params: serde_json::Value,
    /// The character's primitives in aobake's vertex order (written by the
    /// methods whose arrays are per vertex).
    pub primitives: Vec<PrimitiveSpan>,
}

/// Where one glTF primitive's vertices are among an asset's: vertex
/// `first + i` of the asset is vertex `i` (in accessor order) of primitive
/// `primitive` of mesh `mesh`, as node `node` instances it (a mesh that
/// two nodes instance has a span for each). Headers list them in vertex
/// order, back to back from vertex 0 (format 1.6): what an engine that
/// imports the glTF its own way maps its vertices by.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct PrimitiveSpan {
    /// The glTF node that instances the mesh.
    pub node: usize,
    /// The glTF mesh.
    pub mesh: usize,
    /// The primitive's index in the mesh.
    pub primitive: usize,
    /// Its first vertex among the asset's.
    pub first: usize,
    /// Its vertices.
    pub count: usize,
}

/// Checks that a header's `spans` (when it has any: files before format
/// 1.6 have none) cover vertices `0..vertices` in order, back to back.
pub fn check_primitives(spans: &[PrimitiveSpan], vertices: usize) -> Result<(), AssetError> {
    if spans.is_empty() {
        return Ok(());
    }
    let mut next = 0usize;
    for (i, span) in spans.iter().enumerate() {
        if span.first != next {
            return Err(AssetError::Malformed(format!(
                "primitives[{i}] starts at vertex {}, not {next}",
                span.first
            )));
        }
        next = next
            .checked_add(span.count)
            .filter(|&n| n <= vertices)
            .ok_or_else(|| {
                AssetError::Malformed(format!(
                    "primitives[{i}] ends past the asset's {vertices} vertices"
                ))
            })?;
    }
    if next != vertices {
        return Err(AssetError::Malformed(format!(
            "the primitives cover {next} of the asset's {vertices} vertices"
        )));
    }
    Ok(())
}

#[cfg(test)]
impl AssetHeaderFields {
    /// Placeholder fields for the codecs' tests.
    pub(crate) fn for_tests() -> Self {
        Self {
            generator: "test".into(),
            bake_key: "k".into(),
            character: "c".into(),
            clips: vec![],
            params: serde_json::json!({}),
            primitives: vec![],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primitive_spans_must_tile_the_vertices_in_order() {
        let span = |first, count| PrimitiveSpan {
            node: 0,
            mesh: 0,
            primitive: 0,
            first,
            count,
        };
        assert!(check_primitives(&[], 10).is_ok(), "none: a file before 1.6");
        assert!(check_primitives(&[span(0, 4), span(4, 6)], 10).is_ok());
        for (spans, why) in [
            (vec![span(1, 9)], "starts at vertex 1, not 0"),
            (vec![span(0, 4), span(5, 5)], "starts at vertex 5, not 4"),
            (vec![span(0, 4), span(4, 7)], "ends past"),
            (vec![span(0, 4), span(4, usize::MAX)], "ends past"),
            (vec![span(0, 4)], "cover 4 of the asset's 10"),
        ] {
            let e = check_primitives(&spans, 10).unwrap_err().to_string();
            assert!(e.contains(why), "{spans:?}: {e}");
        }
    }

    fn sample() -> Container {
        Container::new(
            Method::VertexLinear,
            &serde_json::json!({"vertices": 3, "note": "ü"}),
            vec![
                Section {
                    tag: *b"COEF",
                    data: Data::F16(vec![f16::from_f32(0.5), f16::from_f32(-1.25), f16::ONE]),
                },
                Section {
                    tag: *b"MAPS",
                    data: Data::U32(vec![7, 8]),
                },
                Section {
                    tag: *b"BYTE",
                    data: Data::U8(vec![1, 2, 3, 4, 5]),
                },
            ],
        )
    }

    #[test]
    fn round_trips_and_aligns() {
        let c = sample();
        let bytes = c.to_bytes();
        assert_eq!(bytes.len() % ALIGN, 0);
        assert_eq!(Container::from_bytes(&bytes).unwrap(), c);
        assert_eq!(c.to_bytes(), bytes, "deterministic");
    }

    #[test]
    fn every_flipped_byte_is_caught() {
        let bytes = sample().to_bytes();
        for i in 0..bytes.len() {
            let mut bad = bytes.clone();
            bad[i] ^= 0x10;
            assert!(
                Container::from_bytes(&bad).is_err(),
                "byte {i} went unnoticed"
            );
        }
        for cut in [0, 7, 20, 40, bytes.len() - 1] {
            assert!(
                Container::from_bytes(&bytes[..cut]).is_err(),
                "cut at {cut}"
            );
        }
        let mut longer = bytes.clone();
        longer.extend([0; 8]);
        assert!(matches!(
            Container::from_bytes(&longer),
            Err(AssetError::Truncated(_))
        ));
    }

    #[test]
    fn newer_major_is_refused_and_newer_minor_read() {
        let mut future = sample();
        future.version = (MAJOR + 1, 3);
        // A newer major may change everything after the version, so it is
        // refused before any checksum is looked at.
        let mut bytes = future.to_bytes();
        bytes[40] ^= 0xff;
        let err = Container::from_bytes(&bytes).unwrap_err();
        assert_eq!(err, AssetError::NewerMajor { major: 2, minor: 3 });
        assert!(err.to_string().contains("2.3 is newer"), "{err}");
        future.version = (MAJOR, MINOR + 7);
        future.sections.push(Section {
            tag: *b"NEW!",
            data: Data::F32(vec![1.0]),
        });
        let read = Container::from_bytes(&future.to_bytes()).unwrap();
        assert_eq!(read.version, (MAJOR, MINOR + 7));
        assert_eq!(read.section(b"MAPS").unwrap(), &Data::U32(vec![7, 8]));
    }

    #[test]
    fn corrupt_section_names_the_section() {
        let mut bytes = sample().to_bytes();
        let at = bytes.windows(4).position(|w| w == b"MAPS").unwrap() + SECTION_HEAD;
        bytes[at] ^= 1;
        assert_eq!(
            Container::from_bytes(&bytes).unwrap_err(),
            AssetError::Checksum("section MAPS".into())
        );
        assert_eq!(
            Container::from_bytes(b"PK\x03\x04 not an asset").unwrap_err(),
            AssetError::Magic
        );
    }
}
