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
pub mod fit;
pub mod grid;
pub mod texel;
pub mod vertex;

/// A method's identity lives in the runtime crate, which engines read
/// assets with.
pub use aobake_runtime::method::{Family, Method};

/// The static ground texture the grids' base and the cubemaps ride on
/// (the runtime's, as engines read it).
pub use aobake_runtime::method::ground;

/// The version of `method`'s algorithm, part of the bake key: a change
/// that alters a method's bytes bumps its family's version. The one place
/// that reaches into each family's code for it.
pub fn algorithm_version(method: Method) -> u32 {
    match method.family() {
        Family::Vertex => vertex::ALGORITHM_VERSION,
        Family::Cubemap => cubemap::ALGORITHM_VERSION,
        Family::Grid => grid::ALGORITHM_VERSION,
        // Its fit is vertex-linear's: a change there changes its bytes too.
        Family::Texel => (texel::ALGORITHM_VERSION << 16) | vertex::ALGORITHM_VERSION,
    }
}

/// The cubemap encoding of a cubemap `method` with the continuous
/// encoding's `layout`; `None` for other methods.
pub fn cubemap_encoding(
    method: Method,
    layout: cubemap::ContinuousLayout,
) -> Option<cubemap::model::Encoding> {
    use cubemap::{ContinuousLayout, model::Encoding};
    match (method, layout) {
        (Method::CubemapDiscrete, _) => Some(Encoding::Discrete),
        (Method::CubemapContinuous, ContinuousLayout::Cosine) => Some(Encoding::Continuous),
        (Method::CubemapContinuous, ContinuousLayout::Thirds) => Some(Encoding::Thirds),
        _ => None,
    }
}
