//! Simple triangle meshes: the analytic AO test scenes and the tracing
//! benchmark mesh, built the way `shared/tools/blender-ao/make_test_meshes.py`
//! builds them (same vertex order and winding), so the Blender reference
//! can bake the very same triangles.

use glam::Vec3;

/// An indexed triangle mesh.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Counter-clockwise triangles.
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// Appends `other`, offsetting its indices.
    pub fn append(&mut self, other: &TriMesh) {
        let offset = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|i| i + offset)));
    }

    /// Angle-weighted vertex normals (see [`crate::geometry`]).
    pub fn normals(&self) -> Vec<Vec3> {
        let mut n = vec![Vec3::ZERO; self.positions.len()];
        crate::geometry::angle_weighted_normals(
            &self.positions,
            &self.triangles,
            0..n.len(),
            &mut n,
        );
        n
    }
}

/// A `nu` × `nv` grid of vertices `origin + i/(nu−1)·u + j/(nv−1)·v`, two
/// triangles per cell, facing `u × v`.
pub fn grid(origin: Vec3, u: Vec3, v: Vec3, nu: u32, nv: u32) -> TriMesh {
    let mut mesh = TriMesh::default();
    for j in 0..nv {
        for i in 0..nu {
            mesh.positions
                .push(origin + u * (i as f32 / (nu - 1) as f32) + v * (j as f32 / (nv - 1) as f32));
        }
    }
    for j in 0..nv - 1 {
        for i in 0..nu - 1 {
            let a = j * nu + i;
            let (b, c, d) = (a + 1, a + nu + 1, a + nu);
            mesh.triangles.push([a, b, c]);
            mesh.triangles.push([a, c, d]);
        }
    }
    mesh
}

/// An icosphere: the icosahedron subdivided `level` times, radius `r`,
/// centre `c`, outward-facing.
pub fn icosphere(level: u32, r: f32, c: Vec3) -> TriMesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut vs: Vec<[f64; 3]> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .map(unit)
    .to_vec();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut cache = std::collections::HashMap::new();
        let mut mid = |a: u32, b: u32, vs: &mut Vec<[f64; 3]>| {
            *cache.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let (p, q) = (vs[a as usize], vs[b as usize]);
                vs.push(unit([
                    0.5 * (p[0] + q[0]),
                    0.5 * (p[1] + q[1]),
                    0.5 * (p[2] + q[2]),
                ]));
                (vs.len() - 1) as u32
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let ab = mid(a, b, &mut vs);
            let bc = mid(b, c, &mut vs);
            let ca = mid(c, a, &mut vs);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    TriMesh {
        positions: vs
            .iter()
            .map(|v| {
                Vec3::new(
                    (f64::from(c.x) + v[0] * f64::from(r)) as f32,
                    (f64::from(c.y) + v[1] * f64::from(r)) as f32,
                    (f64::from(c.z) + v[2] * f64::from(r)) as f32,
                )
            })
            .collect(),
        triangles: faces,
    }
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    [v[0] / n, v[1] / n, v[2] / n]
}

/// A closed box of the given centre and size, each face an `n` × `n` grid,
/// vertices welded along edges, outward-facing.
pub fn subdivided_box(centre: Vec3, size: Vec3, n: u32) -> TriMesh {
    let h = size / 2.0;
    let c = centre;
    // origin, u, v with u × v outward
    let faces = [
        (
            Vec3::new(c.x - h.x, c.y - h.y, c.z + h.z),
            Vec3::new(size.x, 0.0, 0.0),
            Vec3::new(0.0, size.y, 0.0),
        ),
        (
            Vec3::new(c.x - h.x, c.y + h.y, c.z - h.z),
            Vec3::new(size.x, 0.0, 0.0),
            Vec3::new(0.0, -size.y, 0.0),
        ),
        (
            Vec3::new(c.x + h.x, c.y - h.y, c.z - h.z),
            Vec3::new(0.0, size.y, 0.0),
            Vec3::new(0.0, 0.0, size.z),
        ),
        (
            Vec3::new(c.x - h.x, c.y + h.y, c.z - h.z),
            Vec3::new(0.0, -size.y, 0.0),
            Vec3::new(0.0, 0.0, size.z),
        ),
        (
            Vec3::new(c.x + h.x, c.y + h.y, c.z - h.z),
            Vec3::new(-size.x, 0.0, 0.0),
            Vec3::new(0.0, 0.0, size.z),
        ),
        (
            Vec3::new(c.x - h.x, c.y - h.y, c.z - h.z),
            Vec3::new(size.x, 0.0, 0.0),
            Vec3::new(0.0, 0.0, size.z),
        ),
    ];
    let mut mesh = TriMesh::default();
    let mut index = std::collections::HashMap::new();
    for (o, u, v) in faces {
        let g = grid(o, u, v, n + 1, n + 1);
        let ids: Vec<u32> = g
            .positions
            .iter()
            .map(|p| {
                // Weld by position rounded to 1e-6, as the Python script does to 1e-9.
                let key = (p * 1e6).round().as_ivec3().to_array();
                *index.entry(key).or_insert_with(|| {
                    mesh.positions.push(*p);
                    (mesh.positions.len() - 1) as u32
                })
            })
            .collect();
        mesh.triangles
            .extend(g.triangles.iter().map(|t| t.map(|i| ids[i as usize])));
    }
    mesh
}

/// The sphere-over-floor case of `shared/tools/blender-ao`: an 8 × 8
/// floor at z = 0 (41 × 41 vertices, listed first) and a sphere of radius
/// ½ centred 1 above the floor's middle (`icosphere(5, …)`). Returns the
/// mesh and the number of floor vertices. A floor point at distance L
/// from the centre has occlusion r²d/L³ (the sphere is wholly above its
/// tangent plane), exactly (r/d)² under the centre.
pub fn sphere_over_floor() -> (TriMesh, usize) {
    let mut mesh = grid(
        Vec3::new(-4.0, -4.0, 0.0),
        Vec3::new(8.0, 0.0, 0.0),
        Vec3::new(0.0, 8.0, 0.0),
        41,
        41,
    );
    let floor = mesh.positions.len();
    mesh.append(&icosphere(
        5,
        SPHERE_OVER_FLOOR.0,
        Vec3::new(0.0, 0.0, SPHERE_OVER_FLOOR.1),
    ));
    (mesh, floor)
}

/// The radius and the centre's height of [`sphere_over_floor`]'s sphere.
pub const SPHERE_OVER_FLOOR: (f32, f32) = (0.5, 1.0);

/// The tracing benchmark mesh of `shared/tools/blender-ao` (`timing`): an
/// icosphere (level 6, radius 1, on the ground) and four boxes subdivided
/// 20 × 20 per face standing around it, z up, ground at z = 0: 101,120
/// triangles, 50,570 vertices.
pub fn timing_mesh() -> TriMesh {
    let mut mesh = icosphere(6, 1.0, Vec3::new(0.0, 0.0, 1.0));
    for (x, y, s) in [
        (2.2, 0.0, 1.0),
        (-2.2, 0.0, 1.2),
        (0.0, 2.4, 0.8),
        (0.0, -2.4, 1.4),
    ] {
        mesh.append(&subdivided_box(
            Vec3::new(x, y, s / 2.0),
            Vec3::splat(s),
            20,
        ));
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timing_mesh_has_the_reference_counts() {
        let m = timing_mesh();
        assert_eq!(m.triangles.len(), 101_120);
        assert_eq!(m.positions.len(), 50_570);
    }

    #[test]
    fn shapes_face_outwards() {
        let sphere = icosphere(2, 0.5, Vec3::new(1.0, 2.0, 3.0));
        let bx = subdivided_box(Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0), 3);
        for (mesh, centre) in [(&sphere, Vec3::new(1.0, 2.0, 3.0)), (&bx, Vec3::ZERO)] {
            for t in &mesh.triangles {
                let p = t.map(|i| mesh.positions[i as usize]);
                let n = (p[1] - p[0]).cross(p[2] - p[0]);
                assert!(n.dot((p[0] + p[1] + p[2]) / 3.0 - centre) > 0.0);
            }
        }
        // Closed: every edge is shared by exactly two triangles.
        let mut edges = std::collections::HashMap::new();
        for t in &bx.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        assert!(edges.values().all(|&c| c == 2));
    }
}
