//! The methods (DESIGN §5) and the one place that dispatches on them.
//!
//! A [`Method`] names what a bake fits and what an asset holds. Each
//! method belongs to a [`Family`] that decides the shape of its job graph
//! (`bake::family`): the per-vertex family (`sample` jobs → `fit` →
//! `evaluate` → `assemble`) lives in [`vertex`]; Kroon's cubemaps (`face`
//! jobs → `assemble` → `evaluate`) in [`cubemap`]; Malmer et al.'s grids
//! (`slab` jobs → `assemble` → `evaluate`) in [`grid`]. The queue and the
//! runner never change when a method arrives.

pub mod cubemap;
pub mod grid;
mod id;
pub mod vertex;

pub use id::{Family, Method};

/// What differs by method in its algorithms: the one place that reaches
/// into each family's code.
impl Method {
    /// The version of the method's algorithm, part of the bake key: a
    /// change that alters a method's bytes bumps its family's version.
    pub fn algorithm_version(self) -> u32 {
        match self.family() {
            Family::Vertex => vertex::ALGORITHM_VERSION,
            Family::Cubemap => cubemap::ALGORITHM_VERSION,
            Family::Grid => grid::ALGORITHM_VERSION,
        }
    }

    /// The cubemap encoding of a cubemap method with the continuous
    /// encoding's `layout`.
    pub fn cubemap_encoding(
        self,
        layout: cubemap::ContinuousLayout,
    ) -> Option<cubemap::model::Encoding> {
        use cubemap::{ContinuousLayout, model::Encoding};
        match (self, layout) {
            (Self::CubemapDiscrete, _) => Some(Encoding::Discrete),
            (Self::CubemapContinuous, ContinuousLayout::Cosine) => Some(Encoding::Continuous),
            (Self::CubemapContinuous, ContinuousLayout::Thirds) => Some(Encoding::Thirds),
            _ => None,
        }
    }
}
