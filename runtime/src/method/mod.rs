//! What names a method: its name (CLI, API, headers), its code (the
//! asset preamble) and its family (the shape of its bake); and, one folder
//! per family below, what an engine needs to read and evaluate the
//! family's assets (`cubemap`, `grid`, `vertex`).

pub mod cubemap;
pub mod grid;
pub mod ground;
pub mod texel;
pub mod vertex;

use serde::{Deserialize, Serialize};

/// Why a model's arrays do not fit the GPU evaluators' 32-bit offsets.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what} ({count}) do not fit in 32 bits")]
pub struct TooLarge {
    /// What overflowed.
    pub what: &'static str,
    /// How many there are.
    pub count: usize,
}

pub(crate) fn to_u32(count: usize, what: &'static str) -> Result<u32, TooLarge> {
    u32::try_from(count).map_err(|_| TooLarge { what, count })
}

/// The method an asset holds, as a number in the asset preamble (so tools
/// can tell without parsing JSON) and as a name in headers, the CLI and
/// the API.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Mean AO over the reference poses (the baseline).
    StaticAverage = 1,
    /// Kontkanen & Aila 2006: linear in the joint angles.
    VertexLinear = 2,
    /// Kirk & Arikan 2007: pose clusters, PCA, moving least squares.
    VertexClustered = 3,
    /// Kroon 2023: nested cubemaps around the character, one per shell,
    /// each texel's time curve in four quadratic segments.
    CubemapDiscrete = 4,
    /// Kroon 2023: four cubemaps, each texel's (time × distance) field in
    /// a cosine basis with residual curves.
    CubemapContinuous = 5,
    /// Malmer et al. 2005: a 3D grid of the occlusion each rigid part
    /// casts into space, moved with the part.
    Grid = 6,
    /// Beyond the papers: vertex-linear's model fitted per texel of a UV
    /// atlas (its coefficients as textures).
    TexelLinear = 7,
}

/// How a method's bake is split into jobs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    /// Per-vertex AO fitted to traced reference poses.
    Vertex,
    /// Occlusion cast into space over a cyclic clip, one job per face.
    Cubemap,
    /// Occlusion cast into space by each rigid part, `slab` jobs per part.
    Grid,
    /// Per-texel AO of an atlas fitted to traced reference poses: the
    /// per-vertex family's jobs with texels for vertices.
    Texel,
}

impl Family {
    /// Whether its bakes need joint angles (a pose space to fit over). A
    /// cubemap bakes the world around the clip as it plays, root motion
    /// included (Kroon's spinning cube has nothing else), and a grid is
    /// baked per part, so neither needs them.
    pub fn needs_joint_angles(self) -> bool {
        match self {
            Self::Vertex | Self::Texel => true,
            Self::Cubemap | Self::Grid => false,
        }
    }
}

impl Method {
    /// Every method, in code order.
    pub const ALL: [Self; 7] = [
        Self::StaticAverage,
        Self::VertexLinear,
        Self::VertexClustered,
        Self::CubemapDiscrete,
        Self::CubemapContinuous,
        Self::Grid,
        Self::TexelLinear,
    ];

    /// The method's name, as the CLI and the API spell it.
    pub fn name(self) -> &'static str {
        match self {
            Self::StaticAverage => "static-average",
            Self::VertexLinear => "vertex-linear",
            Self::VertexClustered => "vertex-clustered",
            Self::CubemapDiscrete => "cubemap-discrete",
            Self::CubemapContinuous => "cubemap-continuous",
            Self::Grid => "grid",
            Self::TexelLinear => "texel-linear",
        }
    }

    /// The method named `name` (as [`Method::name`] spells it).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }

    /// The number in the asset preamble.
    pub fn code(self) -> u16 {
        self as u16
    }

    /// The method with preamble number `code`.
    pub fn from_code(code: u16) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.code() == code)
    }

    /// The shape of the method's job graph.
    pub fn family(self) -> Family {
        match self {
            Self::StaticAverage | Self::VertexLinear | Self::VertexClustered => Family::Vertex,
            Self::CubemapDiscrete | Self::CubemapContinuous => Family::Cubemap,
            Self::Grid => Family::Grid,
            Self::TexelLinear => Family::Texel,
        }
    }

    /// Whether the method fits per-vertex AO to pose parameters (what
    /// more reference poses, cross-validated reference sources and scale
    /// parameters serve).
    pub fn fits_poses(self) -> bool {
        match self {
            Self::VertexLinear | Self::VertexClustered | Self::TexelLinear => true,
            Self::StaticAverage | Self::CubemapDiscrete | Self::CubemapContinuous | Self::Grid => {
                false
            }
        }
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Method {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::from_name(s).ok_or_else(|| {
            let names: Vec<&str> = Self::ALL.iter().map(|m| m.name()).collect();
            format!(
                "unknown method {s:?}; the methods are: {}",
                names.join(", ")
            )
        })
    }
}
