//! The cubemap's change on a static ground (issue 29; the run time is
//! [`CubemapModel::ground_ao`]): the grids' product form
//! ([`crate::method::grid::base`]) applied to the ground under a cubemap.
//!
//! A cubemap samples the field around the character coarsely near its
//! feet, where the ground's occlusion changes fastest with distance, and
//! its time average (the static baseline) shares that sampling error, so
//! on the ground the two are close. A ground texture traced directly on
//! the plane holds the static part at the plane's own resolution; the
//! cubemap then carries only what the clip changes:
//!
//! ```text
//! ao(p, t) = clamp(k · cubemap(p, t) + offset(p), 0, 1)   on the ground
//! offset = mean_t truth − k · mean_t cubemap,   k the least-squares gain
//! ```
//!
//! fitted at `assemble` over time samples of the baked clip (the
//! cubemap's own, not the evaluation's random times). Off the ground
//! plane the cubemap is used as it is.

use rayon::prelude::*;

use super::{model::CubemapModel, setup::Setup};
use crate::{
    method::{
        fit as least_squares,
        ground::{GroundBase, GroundSquare},
    },
    trace::{KroonParams, Scene, SceneOptions, TraceError, kroon_occlusion, no_progress},
};

/// Time samples of the clip the ground is fitted over.
pub const GROUND_TIMES: usize = 32;

/// The ground square under the spheroid: its footprint at the ground's
/// height, `resolution` texels a side.
pub fn square(setup: &Setup<'_>, resolution: usize) -> GroundSquare {
    let s = &setup.spheroid;
    let (x, z) = setup.ground_section();
    let half = x.max(z).max(1e-6);
    GroundSquare {
        min: [s.centre.x - half, s.centre.z - half],
        size: 2.0 * half,
        height: setup.ground_y(),
        resolution,
    }
}

/// The ground base of `model` over `GROUND_TIMES` of the clip's time
/// samples, from the truth (Eq. 3.1 at every texel centre, as the field is
/// traced, with `kroon`'s rays and seed) and the model's lookups there;
/// and, for comparison, the static ground bake those samples give (the
/// mean truth per texel, gain 0).
pub fn fit(
    setup: &Setup<'_>,
    model: &CubemapModel,
    kroon: &KroonParams,
    resolution: usize,
) -> Result<(GroundBase, GroundBase), TraceError> {
    let square = square(setup, resolution);
    let texels = square.texel_centres();
    let step = setup.times.len().div_ceil(GROUND_TIMES).max(1);
    let samples: Vec<usize> = (0..setup.times.len()).step_by(step).collect();
    let traced: Vec<(Vec<f32>, Vec<f32>)> = samples
        .par_iter()
        .map(|&m| {
            let scene = Scene::new(
                &setup.positions(m),
                &setup.character.triangles,
                &SceneOptions::default(),
            )?;
            let truth = kroon_occlusion(&scene, &texels, None, kroon, &no_progress)?;
            let phase = model.layout.phase(setup.times[m]);
            let cube = texels.iter().map(|&p| model.occlusion(p, phase)).collect();
            Ok((truth, cube))
        })
        .collect::<Result<_, TraceError>>()?;
    let (truth, cube): (Vec<Vec<f32>>, Vec<Vec<f32>>) = traced.into_iter().unzip();
    let still = GroundBase {
        square,
        gain: 0.0,
        offsets: least_squares::offsets(&truth, &cube, |_| 0.0),
    };
    Ok((least_squares::ground(square, &truth, &cube), still))
}
