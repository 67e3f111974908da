//! Triangle meshes as PLY files.
//!
//! [`write`]: the posed mesh (positions, normals, triangles) in the
//! product's vertex order, so other tools (Blender's AO bake in
//! `shared/tools/blender-ao`) can bake the very same mesh. [`read`]: a
//! mesh from any PLY (ASCII or binary, through `ply-rs-bw`), for tracing
//! meshes made elsewhere, such as the analytic AO test cases.

use std::fmt::Write as _;

use glam::Vec3;
use ply_rs_bw::{
    parser::{Parser, Reader},
    ply::{Property, PropertyAccess, PropertyAccessResult},
};

use crate::Limits;

/// PLY encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// `binary_little_endian 1.0`: exact floats, compact.
    Binary,
    /// `ascii 1.0`: readable; floats printed so they read back exactly.
    Ascii,
}

/// Encodes a triangle mesh with per-vertex normals.
pub fn write(
    positions: &[Vec3],
    normals: &[Vec3],
    triangles: &[[u32; 3]],
    encoding: Encoding,
) -> Vec<u8> {
    let format = match encoding {
        Encoding::Binary => "binary_little_endian",
        Encoding::Ascii => "ascii",
    };
    let mut out = format!(
        "ply\nformat {format} 1.0\ncomment written by aobake\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        positions.len(),
        triangles.len()
    )
    .into_bytes();
    match encoding {
        Encoding::Binary => {
            out.reserve(positions.len() * 24 + triangles.len() * 13);
            for (p, n) in positions.iter().zip(normals) {
                for v in p.to_array().into_iter().chain(n.to_array()) {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
            for t in triangles {
                out.push(3);
                for i in t {
                    out.extend_from_slice(&i.to_le_bytes());
                }
            }
        }
        Encoding::Ascii => {
            let mut text = String::new();
            for (p, n) in positions.iter().zip(normals) {
                let _ = writeln!(text, "{} {} {} {} {} {}", p.x, p.y, p.z, n.x, n.y, n.z);
            }
            for t in triangles {
                let _ = writeln!(text, "3 {} {} {}", t[0], t[1], t[2]);
            }
            out.extend_from_slice(text.as_bytes());
        }
    }
    out
}

/// A mesh read from PLY.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    /// Vertex positions, in file order.
    pub positions: Vec<Vec3>,
    /// Per-vertex normals when the file has `nx ny nz`.
    pub normals: Option<Vec<Vec3>>,
    /// Triangles; polygons are split into fans.
    pub triangles: Vec<[u32; 3]>,
}

/// Why a PLY file was refused.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// Not parseable as PLY.
    #[error("not a valid PLY file: {0}")]
    Parse(String),
    /// Parseable, but not a mesh aobake can use; the message says why.
    #[error("{0}")]
    Invalid(String),
}

#[derive(Debug, Default)]
struct Vertex {
    p: [f32; 3],
    n: [f32; 3],
}

#[derive(Debug, Default)]
struct Face {
    indices: Vec<i64>,
}

fn scalar(p: &Property) -> Option<f32> {
    Some(match *p {
        Property::Float(v) => v,
        Property::Double(v) => v as f32,
        Property::Char(v) => v.into(),
        Property::UChar(v) => v.into(),
        Property::Short(v) => v.into(),
        Property::UShort(v) => v.into(),
        Property::Int(v) => v as f32,
        Property::UInt(v) => v as f32,
        _ => return None,
    })
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Vertex::default()
    }
    fn set_property(&mut self, key: &str, property: Property) -> PropertyAccessResult {
        let slot = match key {
            "x" => &mut self.p[0],
            "y" => &mut self.p[1],
            "z" => &mut self.p[2],
            "nx" => &mut self.n[0],
            "ny" => &mut self.n[1],
            "nz" => &mut self.n[2],
            _ => return PropertyAccessResult::Ignored,
        };
        match scalar(&property) {
            Some(v) => {
                *slot = v;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::UnsupportedType,
        }
    }
}

impl PropertyAccess for Face {
    fn new() -> Self {
        Face::default()
    }
    fn set_property(&mut self, key: &str, property: Property) -> PropertyAccessResult {
        if key != "vertex_indices" && key != "vertex_index" {
            return PropertyAccessResult::Ignored;
        }
        self.indices = match property {
            Property::ListChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListInt(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUInt(v) => v.into_iter().map(i64::from).collect(),
            _ => return PropertyAccessResult::UnsupportedType,
        };
        PropertyAccessResult::Set
    }
}

/// Reads a triangle or polygon mesh: the `vertex` element's `x y z` (and
/// `nx ny nz` if all three are declared) and the `face` element's
/// `vertex_indices` (or `vertex_index`). Counts are checked against
/// `limits` before the body is read; indices and coordinates are checked
/// after.
pub fn read(bytes: &[u8], limits: &Limits) -> Result<Mesh, ReadError> {
    let parse = |e: ply_rs_bw::parser::ParseError| ReadError::Parse(e.to_string());
    let mut reader = Reader::new(std::io::BufReader::new(bytes));
    let vertex_parser = Parser::<Vertex>::new();
    let face_parser = Parser::<Face>::new();
    let header = vertex_parser.read_header(&mut reader).map_err(parse)?;

    let mut vertices = None;
    let mut faces = Vec::new();
    let mut has_normals = false;
    for element in header.elements.values() {
        match element.name.as_str() {
            "vertex" => {
                for axis in ["x", "y", "z"] {
                    if !element.properties.contains_key(axis) {
                        return Err(ReadError::Invalid(format!(
                            "the vertex element has no `{axis}` property"
                        )));
                    }
                }
                if element.count as u64 > limits.max_vertices {
                    return Err(ReadError::Invalid(format!(
                        "{} vertices, more than the limit of {}",
                        element.count, limits.max_vertices
                    )));
                }
                has_normals = ["nx", "ny", "nz"]
                    .iter()
                    .all(|k| element.properties.contains_key(*k));
                vertices = Some(
                    vertex_parser
                        .read_payload_for_element(&mut reader, element, &header)
                        .map_err(parse)?,
                );
            }
            "face" => {
                if element.count as u64 > limits.max_triangles {
                    return Err(ReadError::Invalid(format!(
                        "{} faces, more than the limit of {} triangles",
                        element.count, limits.max_triangles
                    )));
                }
                faces = face_parser
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(parse)?;
            }
            // Other elements (edges, materials) are skipped by reading
            // them as faces without the properties we use.
            _ => {
                face_parser
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(parse)?;
            }
        }
    }
    let vertices = vertices.ok_or_else(|| ReadError::Invalid("no vertex element".into()))?;
    if let Some(i) = vertices
        .iter()
        .position(|v| !v.p.iter().chain(&v.n).all(|c| c.is_finite()))
    {
        return Err(ReadError::Invalid(format!(
            "vertex {i} has a non-finite coordinate"
        )));
    }
    let count = vertices.len() as i64;
    let mut triangles = Vec::new();
    for (f, face) in faces.iter().enumerate() {
        if let Some(&bad) = face.indices.iter().find(|&&i| i < 0 || i >= count) {
            return Err(ReadError::Invalid(format!(
                "face {f} refers to vertex {bad}; there are {count}"
            )));
        }
        for k in 2..face.indices.len() {
            triangles
                .push([face.indices[0], face.indices[k - 1], face.indices[k]].map(|i| i as u32));
            if triangles.len() as u64 > limits.max_triangles {
                return Err(ReadError::Invalid(format!(
                    "more than the limit of {} triangles",
                    limits.max_triangles
                )));
            }
        }
    }
    Ok(Mesh {
        positions: vertices.iter().map(|v| Vec3::from(v.p)).collect(),
        normals: has_normals.then(|| vertices.iter().map(|v| Vec3::from(v.n)).collect()),
        triangles,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_back_what_it_writes() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::new(0.25, 1.5, -2.0)];
        let n = [Vec3::Z, Vec3::Y, Vec3::X];
        for encoding in [Encoding::Binary, Encoding::Ascii] {
            let mesh = read(&write(&p, &n, &[[0, 1, 2]], encoding), &Limits::default()).unwrap();
            assert_eq!(mesh.positions, p);
            assert_eq!(mesh.normals.as_deref(), Some(&n[..]));
            assert_eq!(mesh.triangles, [[0, 1, 2]]);
        }
    }

    #[test]
    fn polygons_become_fans_and_bad_indices_are_refused() {
        let quad = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
                    property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
                    0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
        let mesh = read(quad.as_bytes(), &Limits::default()).unwrap();
        assert_eq!(mesh.triangles, [[0, 1, 2], [0, 2, 3]]);
        assert!(mesh.normals.is_none());
        let bad = quad.replace("4 0 1 2 3", "3 0 1 4");
        let err = read(bad.as_bytes(), &Limits::default()).unwrap_err();
        assert!(
            err.to_string().contains("face 0 refers to vertex 4"),
            "{err}"
        );
        let nan = quad.replace("1 1 0", "nan 1 0");
        assert!(read(nan.as_bytes(), &Limits::default()).is_err());
        let limits = Limits {
            max_vertices: 3,
            ..Limits::default()
        };
        let err = read(quad.as_bytes(), &limits).unwrap_err();
        assert!(err.to_string().contains("limit"), "{err}");
        assert!(read(b"not a ply", &Limits::default()).is_err());
    }

    #[test]
    fn header_counts_and_binary_size_match() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let n = [Vec3::Z; 3];
        let bytes = write(&p, &n, &[[0, 1, 2]], Encoding::Binary);
        let text = String::from_utf8_lossy(&bytes);
        let header_end = text.find("end_header\n").unwrap() + "end_header\n".len();
        assert!(text.contains("element vertex 3\n") && text.contains("element face 1\n"));
        assert_eq!(bytes.len() - header_end, 3 * 24 + 13);
        let ascii = String::from_utf8(write(&p, &n, &[[0, 1, 2]], Encoding::Ascii)).unwrap();
        assert!(
            ascii.ends_with("1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n"),
            "{ascii}"
        );
    }
}
