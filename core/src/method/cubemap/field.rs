//! The raw field a `face` job computes: Kroon's occlusion (Eq. 3.1, through
//! [`kroon_occlusion`]) at the sample point of every texel of one face on
//! every shell, one time sample (posed mesh) at a time.
//!
//! A point in space has no receiver normal, so the N·D term is 1 (the
//! full-sphere use of the thesis; see [`kroon_occlusion`]); a point inside
//! the mesh has occlusion 1. Every time sample of a face traces the same
//! directions at a texel (the scramble depends on the seed, the face and
//! the point, never on the time), so ray noise does not flicker along the
//! time curves that the encodings fit.

use glam::Vec3;

use rayon::prelude::*;

use crate::trace::{
    KroonParams, Scene, SceneOptions, TraceError, kroon_occlusion_many, no_progress,
};

use super::geometry::{Spheroid, texel_direction};

/// The sample points of one face: shell-major, then texel rows `j`, then
/// columns `i` (`(k · res + j) · res + i`).
pub fn face_points(spheroid: &Spheroid, face: usize, res: usize) -> Vec<Vec3> {
    let mut points = Vec::with_capacity(spheroid.shells * res * res);
    for k in 0..spheroid.shells {
        for j in 0..res {
            for i in 0..res {
                points.push(spheroid.point(texel_direction(face, i, j, res), k));
            }
        }
    }
    points
}

/// Occlusion at `points` (from [`face_points`]) around one posed mesh.
#[cfg(test)]
fn face_slice(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    points: &[Vec3],
    face: usize,
    params: &KroonParams,
) -> Result<Vec<f32>, TraceError> {
    let mut slices = face_slices(&[positions.to_vec()], triangles, points, face, params)?;
    Ok(slices.pop().unwrap_or_default())
}

/// Occlusion at `points` (from [`face_points`]) around several posed
/// meshes (time samples), traced as one batch: one dispatch on a GPU
/// tracer.
#[cfg(test)]
fn face_slices(
    frames: &[Vec<Vec3>],
    triangles: &[[u32; 3]],
    points: &[Vec3],
    face: usize,
    params: &KroonParams,
) -> Result<Vec<Vec<f32>>, TraceError> {
    trace_face(&face_scenes(frames, triangles)?, points, face, params)
}

/// The posed meshes (time samples) of a batch as scenes, built in
/// parallel.
pub fn face_scenes(frames: &[Vec<Vec3>], triangles: &[[u32; 3]]) -> Result<Vec<Scene>, TraceError> {
    frames
        .par_iter()
        .map(|positions| Scene::new(positions, triangles, &SceneOptions::default()))
        .collect()
}

/// Occlusion at `points` (from [`face_points`]) of face `face` around
/// `scenes`, traced as one batch: a slice per scene.
pub fn trace_face(
    scenes: &[Scene],
    points: &[Vec3],
    face: usize,
    params: &KroonParams,
) -> Result<Vec<Vec<f32>>, TraceError> {
    let params = KroonParams {
        // Faces must not share scrambles: texel i of every face would
        // otherwise trace the same directions.
        seed: params.seed ^ (0x9e37_79b9_7f4a_7c15u64.wrapping_mul(face as u64 + 1)),
        ..*params
    };
    let scenes: Vec<&Scene> = scenes.iter().collect();
    kroon_occlusion_many(&scenes, points, &params, &no_progress)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::shapes::icosphere;

    /// A sphere of radius R seen from distance d covers the solid angle
    /// 2π(1 − √(1 − (R/d)²)): with α = 0, w = 1 and D_max beyond every
    /// hit, Eq. 3.1 is the fraction of the full sphere it covers.
    fn covered(radius: f32, distance: f32) -> f32 {
        0.5 * (1.0 - (1.0 - (radius / distance).powi(2)).sqrt())
    }

    #[test]
    fn a_slice_around_a_sphere_matches_its_solid_angle_and_is_one_inside() {
        let sphere = icosphere(4, 1.0, Vec3::ZERO);
        let spheroid = Spheroid {
            centre: Vec3::ZERO,
            radii: Vec3::splat(1.0),
            outer: 4.0,
            inner: 0.0,
            shells: 4,
        };
        let res = 6;
        let params = KroonParams {
            samples: 1024,
            max_distance: 100.0,
            alpha: 0.0,
            weight: 1.0,
            seed: 7,
        };
        for face in [0, 3, 5] {
            let points = face_points(&spheroid, face, res);
            assert_eq!(points.len(), 4 * res * res);
            let ao =
                face_slice(&sphere.positions, &sphere.triangles, &points, face, &params).unwrap();
            for (p, a) in points.iter().zip(&ao) {
                let d = p.length();
                if d < 0.98 {
                    assert_eq!(*a, 1.0, "inside at {p}");
                } else if d > 1.05 {
                    let want = covered(1.0, d);
                    assert!((a - want).abs() < 0.03, "at {d}: {a} against {want}");
                }
            }
        }
    }

    #[test]
    fn slices_are_deterministic_follow_the_mesh_and_scramble_faces_apart() {
        let here = icosphere(3, 0.8, Vec3::ZERO);
        let moved = icosphere(3, 0.8, Vec3::new(0.3, 0.0, 0.3));
        let spheroid = Spheroid {
            centre: Vec3::ZERO,
            radii: Vec3::splat(1.0),
            outer: 2.0,
            inner: 0.5,
            shells: 2,
        };
        let params = KroonParams {
            samples: 256,
            max_distance: 3.0,
            alpha: 1.0,
            weight: 1.0,
            seed: 1,
        };
        let points = face_points(&spheroid, 4, 4);
        let slice = |mesh: &crate::trace::shapes::TriMesh, face| {
            face_slice(&mesh.positions, &mesh.triangles, &points, face, &params).unwrap()
        };
        let once = slice(&here, 4);
        assert!(once.iter().all(|&a| a > 0.0 && a < 0.5), "{once:?}");
        assert_eq!(once, slice(&here, 4), "the same pose, the same bytes");
        assert_ne!(once, slice(&here, 2), "faces scramble differently");
        // The +z face's points see more of a sphere moved towards them.
        let closer = slice(&moved, 4);
        let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
        assert!(mean(&closer) > mean(&once) + 0.01);
    }
}
