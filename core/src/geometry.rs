//! Geometry helpers shared by import and posing.

use glam::Vec3;

/// Angle-weighted vertex normals (Thürmer & Wüthrich 1998, what Blender
/// uses): each triangle adds its unit face normal times the corner angle at
/// the vertex. Only the vertices in `vertices` are written; degenerate
/// triangles add nothing, and a vertex without a valid triangle gets zero.
///
/// glTF asks renderers to use flat normals when a primitive has none; AO is
/// baked per vertex and needs one normal per vertex, so aobake uses these,
/// which is also what the Blender reference baker does.
pub fn angle_weighted_normals(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    vertices: std::ops::Range<usize>,
    normals: &mut [Vec3],
) {
    normals[vertices.clone()].fill(Vec3::ZERO);
    for tri in triangles {
        let p = tri.map(|i| positions[i as usize]);
        let face = (p[1] - p[0]).cross(p[2] - p[0]);
        let Some(face) = face.try_normalize() else {
            continue;
        };
        for corner in 0..3 {
            let v = tri[corner] as usize;
            if !vertices.contains(&v) {
                continue;
            }
            let a = (p[(corner + 1) % 3] - p[corner]).normalize_or_zero();
            let b = (p[(corner + 2) % 3] - p[corner]).normalize_or_zero();
            let angle = a.dot(b).clamp(-1.0, 1.0).acos();
            normals[v] += face * angle;
        }
    }
    for n in &mut normals[vertices] {
        *n = n.normalize_or_zero();
    }
}

/// Axis-aligned bounds of points; `None` for no points.
pub fn bounds(points: impl IntoIterator<Item = Vec3>) -> Option<(Vec3, Vec3)> {
    points.into_iter().fold(None, |acc, p| match acc {
        None => Some((p, p)),
        Some((lo, hi)) => Some((lo.min(p), hi.max(p))),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cube_corner_normal_is_the_diagonal() {
        // Three faces of a unit cube meeting at the origin, each split in two
        // triangles the same way: angle weighting makes the result symmetric
        // whatever the split.
        let p = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::Z,
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 1.0),
            Vec3::new(1.0, 0.0, 1.0),
        ];
        // Outward normals point to negative axes (the corner of a box seen
        // from outside at the origin).
        let tris = [
            [0, 2, 4],
            [0, 4, 1],
            [0, 3, 5],
            [0, 5, 2],
            [0, 1, 6],
            [0, 6, 3],
        ];
        let mut n = vec![Vec3::ZERO; p.len()];
        angle_weighted_normals(&p, &tris, 0..1, &mut n);
        let expect = -Vec3::ONE.normalize();
        assert!(n[0].distance(expect) < 1e-5, "{:?}", n[0]);
        assert_eq!(n[1], Vec3::ZERO, "outside the range: untouched");
    }

    #[test]
    fn degenerate_triangles_add_nothing() {
        let p = vec![Vec3::ZERO, Vec3::ZERO, Vec3::X];
        let mut n = vec![Vec3::ONE; 3];
        angle_weighted_normals(&p, &[[0, 1, 2]], 0..3, &mut n);
        assert!(n.iter().all(|n| *n == Vec3::ZERO));
    }
}
