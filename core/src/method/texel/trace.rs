//! Texels traced like vertices: each pose skinned, its BVH built, and the
//! occlusion traced at every texel's point and normal on the posed mesh
//! (the barycentric blend of its triangle's skinned corners: the point
//! the rasteriser shows there), with the same estimator, rays and seed
//! rule as the vertices' (`trace::trace_poses`).

use crate::{
    Character, Pose,
    trace::{AoBlock, Progress, Scene, SceneOptions, SurfaceParams, TraceError, surface_occlusion},
};

use super::atlas::Texels;

/// Occlusion of every texel in every pose of a batch: an [`AoBlock`] whose
/// columns are the texels (in [`Texels::texels`]'s order). Every pose uses
/// the same seed, so a texel's rays take the same directions relative to
/// its normal in every pose, as a vertex's do. `progress` counts texels.
pub fn trace_texels(
    character: &Character,
    texels: &Texels,
    poses: &[Pose],
    options: &SceneOptions,
    params: &SurfaceParams,
    progress: Progress<'_>,
) -> Result<AoBlock, TraceError> {
    let mut values = Vec::with_capacity(texels.len() * poses.len());
    for pose in poses {
        let posed = character.skin(pose);
        let scene = Scene::new(&posed.positions, &character.triangles, options)?;
        let (points, normals) =
            texels.points(&posed.positions, &posed.normals, &character.triangles);
        values.extend(surface_occlusion(
            &scene, &points, &normals, params, progress,
        )?);
    }
    Ok(AoBlock {
        vertices: texels.len(),
        values,
    })
}

/// Which texels draw something in a pose: those whose triangle has area
/// there ([`Character::drawn_vertices`]'s rule: a part scaled to zero
/// covers no pixel, and its AO is undefined).
pub fn drawn_texels(character: &Character, texels: &Texels, pose: &Pose) -> Vec<bool> {
    let posed = character.skin(pose);
    let (lo, hi) = crate::geometry::bounds(character.positions.iter().copied())
        .unwrap_or((glam::Vec3::ZERO, glam::Vec3::ZERO));
    let least = (1e-6 * (hi - lo).length()).powi(2);
    let drawn: Vec<bool> = character
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| posed.positions[i as usize]);
            (b - a).cross(c - a).length() > least
        })
        .collect();
    texels
        .texels
        .iter()
        .map(|t| drawn[t.triangle as usize])
        .collect()
}
