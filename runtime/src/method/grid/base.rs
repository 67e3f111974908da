//! The static base the grids' change rides on: aobake's product form of
//! the grid method (issue 29), beside the paper's grids alone.
//!
//! Malmer et al.'s grids shade a part's own vertices by a rule of thumb
//! (§4.2's `(ao_grid − 1)/2`, or its cone) and keep only the near field on
//! the ground, so a static bake beats them where the character is. The
//! base keeps what a static bake gets right and lets the grids say only
//! what a pose changes. For a receiver `r` whose grids give `g(r)` at a
//! frame:
//!
//! ```text
//! ao(r) = clamp(k · g(r) + offset(r), 0, 1)
//! offset(r) = static(r) − k · mean(g(r))
//! ```
//!
//! where `static(r)` is the mean ray-traced occlusion over the training
//! frames, `mean(g(r))` the grids' mean over the same frames, and `k` the
//! least-squares gain of the truth's change on the grids' change over
//! those frames (one per part for its vertices, one for the ground):
//! where the grids' change tracks the truth `k` is near 1, where it is
//! noise `k` falls towards 0 and the base stays static.
//!
//! The offsets are per vertex of the character and, for the ground, a
//! square texture on the ground plane of the clips' space
//! ([`crate::method::ground`]).

use glam::Vec3;

pub use crate::method::ground::{GroundBase, GroundSquare};

/// The static base of a grid asset.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticBase {
    /// Per vertex of the character, the offset (f16 values).
    pub vertex_offsets: Vec<f32>,
    /// Per part, the gain of the grids' change at its vertices (vertices
    /// of no part take the ground's).
    pub part_gains: Vec<f32>,
    /// The ground.
    pub ground: GroundBase,
}

/// Where a receiver is, for [`super::model::GridModel::ao`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Receiver {
    /// The character's vertex `index`, carried by `part` (`None`: by no
    /// part).
    Vertex {
        /// Its index in the character.
        index: usize,
        /// Its part.
        part: Option<usize>,
    },
    /// A point of the ground plane (normal up).
    Ground,
    /// Any other surface point, one the base knows nothing of (another
    /// object, a level of detail the bake never saw): the grids alone,
    /// the paper's form (gain 1, no offset). The ground's gain was fitted
    /// to the ground's change with its offsets; without them it says
    /// little (measured with the bake's vertices and ground points taken
    /// as unknown surfaces: RMSE 0.33 against 0.53 on the milk truck,
    /// whose ground gain is 0.002; 0.216 against 0.213 and 0.131 against
    /// 0.124 on the robot and Fox, gains 1.0 and 1.5).
    Other {
        /// The part it is on, if any (its own part by the self-occlusion
        /// rule).
        part: Option<usize>,
    },
}

impl Receiver {
    /// Vertex `index` whose part is `owner` in the word form the GPU
    /// lookups use (`u32::MAX`: no part).
    pub fn vertex(index: usize, owner: u32) -> Self {
        Self::Vertex {
            index,
            part: (owner != u32::MAX).then_some(owner as usize),
        }
    }
}

impl StaticBase {
    /// The gain and offset of a receiver at `p`.
    ///
    /// The GPU lookups (`grid_ao` in `shaders/wgsl/common/grid_lookup.wgsl`)
    /// take the offset from the caller, [`Self::offset`].
    pub fn terms(&self, receiver: Receiver, p: Vec3) -> (f32, f32) {
        match receiver {
            Receiver::Vertex { index, part } => (
                part.and_then(|k| self.part_gains.get(k).copied())
                    .unwrap_or(self.ground.gain),
                self.vertex_offsets.get(index).copied().unwrap_or(0.0),
            ),
            Receiver::Ground => (self.ground.gain, self.ground.offset(p)),
            Receiver::Other { .. } => (1.0, 0.0),
        }
    }
}

impl StaticBase {
    /// The offset a GPU lookup is given for `receiver` at `p`.
    pub fn offset(&self, receiver: Receiver, p: Vec3) -> f32 {
        self.terms(receiver, p).1
    }
}
