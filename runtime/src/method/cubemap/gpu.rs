//! A cubemap as the GPU lookups read it (`shaders/wgsl/cubemap_ao.wgsl`
//! from a storage buffer, `cubemap_ao_vs.wgsl` from an R32Uint texture):
//! the `Params` uniform's constant fields and the texels as words, what an
//! engine uploads once per asset.

use super::{CubemapModel, Encoding};
use crate::method::{TooLarge, ground::GroundBase, to_u32};

/// A cubemap's GPU form.
#[derive(Debug, Clone, PartialEq)]
pub struct CubemapGpu {
    /// xyz: the spheroid's centre; w: the outer scaling.
    pub centre: [f32; 4],
    /// xyz: the spheroid's radii; w: the inner scaling.
    pub radii: [f32; 4],
    /// Texels per face edge.
    pub resolution: u32,
    /// Shells, `S_d`.
    pub shells: u32,
    /// Time samples, `S_t`.
    pub times: u32,
    /// 0 discrete, 1 continuous (cosine layout), 2 continuous (Kroon's
    /// thirds layout).
    pub encoding: u32,
    /// The texels' bytes as little-endian words, four a texel (at least
    /// four words).
    pub texels: Vec<u32>,
    /// The static ground: its texels per side (0 without one), then the
    /// bits of its square's min x, min z and side and of its gain, then
    /// its offsets' f32 bits (x fastest): what `ground_offset`
    /// reads (at least one word).
    pub ground: Vec<u32>,
}

impl CubemapGpu {
    /// The GPU form of `model`.
    pub fn new(model: &CubemapModel) -> Result<Self, TooLarge> {
        let l = &model.layout;
        let s = &l.spheroid;
        let mut texels: Vec<u32> = model
            .texels
            .chunks_exact(4)
            .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
            .collect();
        texels.resize(texels.len().max(4), 0);
        to_u32(texels.len(), "texel words")?;
        Ok(Self {
            centre: [s.centre.x, s.centre.y, s.centre.z, s.outer],
            radii: [s.radii.x, s.radii.y, s.radii.z, s.inner],
            resolution: to_u32(l.resolution, "resolution")?,
            shells: to_u32(s.shells, "shells")?,
            times: to_u32(l.times, "times")?,
            encoding: match l.encoding {
                Encoding::Discrete => 0,
                Encoding::Continuous => 1,
                Encoding::Thirds => 2,
            },
            texels,
            ground: model
                .ground
                .as_ref()
                .map_or_else(|| vec![0], GroundBase::gpu_words),
        })
    }
}
