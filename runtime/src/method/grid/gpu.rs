//! Grids as the GPU lookups read them (`shaders/wgsl/grid_ao.wgsl` from
//! storage buffers, `grid_ao_vs.wgsl` from R32Uint textures): the `Params`
//! uniform's constant fields, the parts' infos and the cells (one word a
//! cell, RGBA8 with R in the low byte) followed by T_clip's f32 pairs,
//! what an engine uploads once per asset.

use super::model::GridModel;
use crate::method::{TooLarge, to_u32};

/// Grids' GPU form.
#[derive(Debug, Clone, PartialEq)]
pub struct GridGpu {
    /// 1 when the cones are baked.
    pub cones: u32,
    /// T_clip's samples per axis (0 without cones).
    pub tclip_resolution: u32,
    /// Index in `cells` of T_clip's first f32.
    pub tclip_offset: u32,
    /// 1 when the asset has a static base ([`super::base`]).
    pub base: u32,
    /// The bits of the base's ground gain (0 without a base).
    pub ground_gain: u32,
    /// Per part: cells per grid edge, the index of its first cell, the
    /// bits of its base gain (0 without a base), and a word of padding.
    pub infos: Vec<[u32; 4]>,
    /// The cells, part after part, then T_clip (at least one word).
    pub cells: Vec<u32>,
}

impl GridGpu {
    /// The GPU form of `model`.
    pub fn new(model: &GridModel) -> Result<Self, TooLarge> {
        let mut cells: Vec<u32> = Vec::new();
        let mut infos = Vec::with_capacity(model.parts.len());
        let gains = model.base.as_ref().map(|b| &b.part_gains);
        for (k, part) in model.parts.iter().enumerate() {
            infos.push([
                to_u32(part.grid.resolution, "resolution")?,
                to_u32(cells.len(), "cells")?,
                gains.and_then(|g| g.get(k)).map_or(0, |g| g.to_bits()),
                0,
            ]);
            for (i, &a) in part.occlusion.iter().enumerate() {
                let d = part.directions.as_ref().map_or([0; 3], |d| d[i]);
                cells.push(u32::from_le_bytes([d[0], d[1], d[2], a]));
            }
        }
        let tclip_offset = to_u32(cells.len(), "cells")?;
        if let Some(t) = &model.tclip {
            cells.extend(t.values.iter().flatten().map(|v| v.to_bits()));
        }
        to_u32(cells.len(), "cells")?;
        if cells.is_empty() {
            cells.push(0);
        }
        Ok(Self {
            cones: u32::from(model.cones()),
            tclip_resolution: model
                .tclip
                .as_ref()
                .map_or(Ok(0), |t| to_u32(t.resolution, "T_clip resolution"))?,
            tclip_offset,
            base: u32::from(model.base.is_some()),
            ground_gain: model.base.as_ref().map_or(0, |b| b.ground.gain.to_bits()),
            infos,
            cells,
        })
    }

    /// Parts.
    pub fn parts(&self) -> u32 {
        self.infos.len() as u32
    }
}
