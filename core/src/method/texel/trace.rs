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
/// there ([`Character::drawn_triangles`]: a part scaled to zero
/// covers no pixel, and its AO is undefined).
pub fn drawn_texels(character: &Character, texels: &Texels, pose: &Pose) -> Vec<bool> {
    let drawn = character.drawn_triangles(&character.skin(pose).positions);
    texels
        .texels
        .iter()
        .map(|t| drawn[t.triangle as usize])
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{
        Limits, Upload, import_character,
        method::texel::atlas::{AtlasOptions, TexelAtlas},
        trace::{Falloff, no_progress},
    };

    #[test]
    fn texel_batches_stack_into_the_whole_and_follow_the_pose() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../tests/data/characters/RiggedFigure/RiggedFigure.glb"
        );
        let bytes = std::fs::read(path).unwrap();
        let imported = import_character(Upload::single(&bytes), &Limits::default()).unwrap();
        let c = &imported.character;
        let atlas = TexelAtlas::generate(
            &c.positions,
            &c.triangles,
            &AtlasOptions {
                size: 64,
                padding: 2,
            },
        )
        .unwrap();
        let clip = &imported.clips[0];
        let poses: Vec<Pose> = [0.0, 0.6, 1.2]
            .iter()
            .map(|&t| Pose::sample(&c.skeleton, clip, t))
            .collect();
        let params = SurfaceParams {
            samples: 16,
            max_distance: 1.0,
            seed: 4,
            falloff: Falloff::None,
        };
        let options = SceneOptions::default();
        let t = &atlas.texels;
        let whole = trace_texels(c, t, &poses, &options, &params, &no_progress).unwrap();
        assert_eq!((whole.poses(), whole.vertices), (3, t.len()));
        assert!(whole.values.iter().all(|v| (0.0..=1.0).contains(v)));
        let first = trace_texels(c, t, &poses[..1], &options, &params, &no_progress).unwrap();
        let rest = trace_texels(c, t, &poses[1..], &options, &params, &no_progress).unwrap();
        assert_eq!([first.values, rest.values].concat(), whole.values);
        // The pose changes the occlusion, and some texels are occluded.
        assert_ne!(whole.row(0), whole.row(2));
        assert!(whole.row(0).iter().any(|&v| v > 0.3));
        // Every texel of a figure whose triangles all have area draws.
        assert!(drawn_texels(c, t, &poses[1]).iter().all(|&d| d));
    }
}
