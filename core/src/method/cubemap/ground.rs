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

/// The truth on the ground plane the static ground is fitted to: Eq. 3.1
/// at every texel centre of `square` (as the field is traced, with the
/// bake's Kroon rays and seed) at `GROUND_TIMES` of the clip's time
/// samples. It does not depend on the encoding, so `assemble` traces it
/// once and `evaluate` fits every other encoding's ground to it too.
#[derive(Debug, Clone, PartialEq)]
pub struct TexelTruth {
    /// The texture's square.
    pub square: GroundSquare,
    /// The clip's time samples (indices into the setup's times).
    pub samples: Vec<usize>,
    /// Per sample, the truth at every texel centre (x fastest).
    pub truth: Vec<Vec<f32>>,
}

impl TexelTruth {
    /// Traces the truth at the texel centres of a `resolution`² square
    /// under the spheroid.
    pub fn trace(
        setup: &Setup<'_>,
        kroon: &KroonParams,
        resolution: usize,
    ) -> Result<Self, TraceError> {
        let square = square(setup, resolution);
        let texels = square.texel_centres();
        let samples = Self::samples(setup);
        let truth = samples
            .par_iter()
            .map(|&m| {
                let scene = Scene::new(
                    &setup.positions(m),
                    &setup.character.triangles,
                    &SceneOptions::default(),
                )?;
                kroon_occlusion(&scene, &texels, None, kroon, &no_progress)
            })
            .collect::<Result<_, TraceError>>()?;
        Ok(Self {
            square,
            samples,
            truth,
        })
    }

    /// The clip's time samples the ground is fitted over.
    fn samples(setup: &Setup<'_>) -> Vec<usize> {
        let step = setup.times.len().div_ceil(GROUND_TIMES).max(1);
        (0..setup.times.len()).step_by(step).collect()
    }

    /// The ground base of `model` fitted to this truth and the model's
    /// lookups at the same texels and times; and, for comparison, the
    /// static ground bake the truth gives alone (its mean per texel, gain
    /// 0).
    pub fn fit(&self, setup: &Setup<'_>, model: &CubemapModel) -> (GroundBase, GroundBase) {
        let texels = self.square.texel_centres();
        let cube: Vec<Vec<f32>> = self
            .samples
            .iter()
            .map(|&m| {
                let phase = model.layout.phase(setup.times[m]);
                texels.iter().map(|&p| model.occlusion(p, phase)).collect()
            })
            .collect();
        let still = GroundBase {
            square: self.square,
            gain: 0.0,
            offsets: least_squares::offsets(&self.truth, &cube, |_| 0.0),
        };
        (
            least_squares::ground(self.square, &self.truth, &cube),
            still,
        )
    }

    /// The truth as bytes (f32 little-endian, sample after sample), for
    /// the hand-over from `assemble` to `evaluate`.
    pub fn to_bytes(&self) -> Vec<u8> {
        self.truth
            .iter()
            .flatten()
            .flat_map(|x| x.to_le_bytes())
            .collect()
    }

    /// The truth [`Self::to_bytes`] wrote for `setup` and `resolution`,
    /// or why the bytes are not it.
    pub fn from_bytes(setup: &Setup<'_>, resolution: usize, bytes: &[u8]) -> Result<Self, String> {
        let square = square(setup, resolution);
        let samples = Self::samples(setup);
        let texels = square.texels();
        if bytes.len() != 4 * texels * samples.len() {
            return Err(format!(
                "the ground's truth holds {} bytes, not {} texels × {} times",
                bytes.len(),
                texels,
                samples.len()
            ));
        }
        let values: Vec<f32> = bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        Ok(Self {
            square,
            samples,
            truth: values
                .chunks_exact(texels.max(1))
                .map(<[f32]>::to_vec)
                .collect(),
        })
    }
}
