//! Malmer et al.'s grids as an engine reads them: each rigid part's
//! occlusion grid ([`model`]), the static base their change rides on in
//! aobake's product form ([`base`]), how an asset stores them
//! ([`codec`]) and the cone table `T_clip` ([`tclip`]).

pub mod base;
pub mod codec;
pub mod gpu;
pub mod model;
pub mod tclip;

use glam::{Mat4, Vec3};
use serde::{Deserialize, Serialize};

/// The version of the grid bake's algorithm, part of the bake key: bump
/// it when a change alters what a bake's asset holds (3: the primitive
/// table in the header).
pub const ALGORITHM_VERSION: u32 = 3;

/// Most parts a grid asset may hold.
pub const MAX_PARTS: usize = 256;

/// Where a part's grid sits in the part's (bind) space: an axis-aligned
/// box of `2·half` around `centre`, cut into `resolution³` cells whose
/// centres are the sample points.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GridBox {
    /// Centre of the part's bounding box.
    pub centre: Vec3,
    /// The grid's half extent per axis, e_i of Eq. 4.
    pub half: Vec3,
    /// Cells per edge.
    pub resolution: usize,
}

impl GridBox {
    /// The sample point of cell (x, y, z), bind space.
    pub fn cell_centre(&self, x: usize, y: usize, z: usize) -> Vec3 {
        let n = self.resolution as f32;
        let u = (Vec3::new(x as f32, y as f32, z as f32) + 0.5) / n;
        self.centre - self.half + 2.0 * self.half * u
    }

    /// The matrix from bind space to grid space, where the box is [0, 1]³.
    pub fn grid_from_bind(&self) -> Mat4 {
        Mat4::from_scale(0.5 / self.half) * Mat4::from_translation(self.half - self.centre)
    }

    /// Cells in one z-layer.
    pub fn layer_cells(&self) -> usize {
        self.resolution * self.resolution
    }

    /// Cells of the grid.
    pub fn cells(&self) -> usize {
        self.resolution.pow(3)
    }
}
