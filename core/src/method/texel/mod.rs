//! The texture-space family (DESIGN §5, "texel"; beyond the four papers):
//! the vertex methods' models fitted per texel of a UV atlas instead of
//! per vertex, so that AO can change between vertices, where per-vertex
//! storage cannot.
//!
//! So far this room holds what every texel method stands on:
//! * [`atlas`]: a lightmap atlas of the character, generated
//!   deterministically (uvunwrap, a pure-Rust xatlas-style unwrapper),
//!   and its texels as surface points: each texel that shows the surface
//!   names a triangle and barycentric coordinates, so it is posed with the
//!   mesh and traced like a vertex; the texture an engine samples is then
//!   dilated past the charts' borders.
//! * [`trace`]: a batch of poses traced at the texels (an `AoBlock` whose
//!   columns are texels), and which texels a pose draws.
//!
//! It must not know about jobs, files or GPUs (core's rule).

pub mod atlas;
pub mod trace;

use serde::{Deserialize, Serialize};

/// The texel methods' algorithm version and their run-time form live in
/// the runtime crate, which engines read assets with.
pub use aobake_runtime::method::texel::{ALGORITHM_VERSION, AtlasLayout, MAX_TEXTURES, TexelModel};

pub use atlas::DEFAULT_ATLAS;

/// A texel bake's options; its fit reads vertex-linear's (`linear`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TexelOptions {
    /// The atlas's side in texels: the densest packing of the generated
    /// atlas's charts that fits one page this wide (or the page a UV set
    /// of the character's own is drawn at).
    pub atlas: u32,
    /// A UV set of the character's own (`TEXCOORD_k`) to use as the
    /// atlas instead of a generated one: refused, naming the place, when
    /// a UV leaves [0, 1]² or two places of the surface share a texel.
    #[serde(default)]
    pub uv_set: Option<u32>,
}

impl Default for TexelOptions {
    fn default() -> Self {
        Self {
            atlas: DEFAULT_ATLAS,
            uv_set: None,
        }
    }
}

impl TexelOptions {
    /// Checks the ranges; the error names the parameter.
    pub fn validate(&self) -> Result<(), String> {
        if atlas::SIZES.contains(&self.atlas) {
            Ok(())
        } else {
            Err(format!(
                "texel.atlas must be between {} and {} texels, not {}",
                atlas::SIZES.start(),
                atlas::SIZES.end(),
                self.atlas
            ))
        }
    }
}
