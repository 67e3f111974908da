//! The posed mesh as a PLY file (positions, normals, triangles), in the
//! product's vertex order, so other tools (Blender's AO bake in
//! `shared/tools/blender-ao`) can bake the very same mesh.

use std::fmt::Write as _;

use glam::Vec3;

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

#[cfg(test)]
mod tests {
    use super::*;

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
