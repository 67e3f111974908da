//! Rust mirrors of the WGSL structs that cross the CPU–GPU boundary, field
//! for field, `#[repr(C)]` and `Pod`, each with its size asserted here and
//! checked against naga's layout of the WGSL in this crate's tests.

use bytemuck::{Pod, Zeroable};

/// `Params` of vertex_ao.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct VertexAoParams {
    /// Vertices to evaluate.
    pub vertices: u32,
    /// Entries in `blocks`.
    pub blocks: u32,
    /// Vertices per row of the dispatch grid (workgroups in x × 64).
    pub row_stride: u32,
    /// Padding.
    pub _pad: u32,
}

/// `VsParams` of vertex_ao_vs.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct VertexAoVsParams {
    /// Vertices to evaluate.
    pub vertices: u32,
    /// Blocks in the blocks texture (dense).
    pub blocks: u32,
    /// 1 for sparse (CSR) coefficients, 0 for dense blocks.
    pub sparse: u32,
    /// Texels per row of every data texture.
    pub width: u32,
    /// The test target's width in pixels.
    pub target_width: u32,
    /// The test target's height in pixels.
    pub target_height: u32,
    /// Padding.
    pub _pad: [u32; 2],
}

/// `BlockInfo` of vertex_ao.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct BlockInfo {
    /// Weights (rows) of the block.
    pub rows: u32,
    /// Coefficient columns (vertices or vertex clusters).
    pub columns: u32,
    /// Offset of the first coefficient, in f16 elements.
    pub coef_offset: u32,
    /// Offset of the block's map in `maps`, or [`BlockInfo::NO_MAP`].
    pub map_offset: u32,
    /// Offset of the block's first weight.
    pub weight_offset: u32,
    /// Padding.
    pub _pad: [u32; 3],
}

impl BlockInfo {
    /// `map_offset` of a block whose columns are the vertices.
    pub const NO_MAP: u32 = u32::MAX;
}

/// `Params` of cubemap_ao.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct CubemapAoParams {
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
    /// 0 discrete, 1 continuous.
    pub encoding: u32,
    /// Points to evaluate.
    pub points: u32,
    /// The phase of the cycle in [0, 1).
    pub phase: f32,
    /// Points per row of the dispatch grid (workgroups in x × 64).
    pub row_stride: u32,
    /// 1: the points are on the ground plane (`cubemap_ground_ao`, with
    /// the static ground); 0: anywhere (`cubemap_occlusion`).
    pub on_ground: u32,
}

/// `Params` of grid_ao.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GridAoParams {
    /// Parts.
    pub parts: u32,
    /// Receivers to evaluate.
    pub points: u32,
    /// Receivers per row of the dispatch grid (workgroups in x × 64).
    pub row_stride: u32,
    /// 1 when the cones are baked.
    pub cones: u32,
    /// `T_clip`'s samples per axis.
    pub tclip_resolution: u32,
    /// Index in `cells` of `T_clip`'s first f32.
    pub tclip_offset: u32,
    /// 1 when the asset has a static base.
    pub base: u32,
    /// The bits of the base's ground gain.
    pub ground_gain: u32,
}

/// `PartInfo` of grid_ao.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GridPartInfo {
    /// Cells per grid edge.
    pub resolution: u32,
    /// Index in `cells` of the part's first cell.
    pub offset: u32,
    /// The bits of the base's gain at the part's vertices.
    pub gain: u32,
    /// Padding.
    pub _pad: u32,
}

/// `Receiver` of grid_ao.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GridReceiver {
    /// xyz: the position; w: the bits of its part's index
    /// ([`GridReceiver::NO_PART`] for none).
    pub position: [f32; 4],
    /// xyz: the unit normal; w: the static base's offset (0 without).
    pub normal: [f32; 4],
}

impl GridReceiver {
    /// The part index of a receiver of no part.
    pub const NO_PART: u32 = u32::MAX;

    /// A receiver at `p` with normal `n` on part `own`, with the static
    /// base's `offset`.
    pub fn new(p: [f32; 3], n: [f32; 3], own: u32, offset: f32) -> Self {
        Self {
            position: [p[0], p[1], p[2], f32::from_bits(own)],
            normal: [n[0], n[1], n[2], offset],
        }
    }
}

/// `Uniforms` of preview.wgsl: one per (panel, surface) draw.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct PreviewUniforms {
    /// Clip space from world space, column-major.
    pub clip_from_world: [[f32; 4]; 4],
    /// xyz: the eye.
    pub eye: [f32; 4],
    /// xyz: unit direction towards the key light; w: its intensity.
    pub light: [f32; 4],
    /// rgb: ambient radiance; w: the key light's wrap.
    pub ambient: [f32; 4],
    /// rgb: albedo.
    pub albedo: [f32; 4],
    /// rgb: the heat map's neutral colour; w: its saturating error.
    pub neutral: [f32; 4],
    /// rgb: the colour of a model too dark.
    pub too_dark: [f32; 4],
    /// rgb: the colour of a model too bright.
    pub too_bright: [f32; 4],
    /// xyz: the ground's centre; w: its half extent.
    pub ground: [f32; 4],
    /// rgb: the background.
    pub background: [f32; 4],
    /// 0 truth, 1 model, 2 error.
    pub panel: u32,
    /// 0 character, 1 ground.
    pub surface: u32,
    /// Padding.
    pub _pad: [u32; 2],
}

/// `TexelWeights` of common/texel_ao.wgsl: a pose's weights, four to a
/// vector.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct TexelWeights {
    /// Weights in use.
    pub count: u32,
    /// Padding.
    pub _pad: [u32; 3],
    /// Weight k is `w[k / 4][k % 4]`.
    pub w: [[f32; 4]; 64],
}

impl TexelWeights {
    /// The uniform of a pose's `weights`; `None` past
    /// [`crate::TEXEL_MAX_LAYERS`] of them.
    pub fn new(weights: &[f32]) -> Option<Self> {
        let mut out = Self::zeroed();
        if weights.len() > 4 * out.w.len() {
            return None;
        }
        for (k, &w) in weights.iter().enumerate() {
            out.w[k / 4][k % 4] = w;
        }
        out.count = weights.len() as u32;
        Some(out)
    }
}

/// `TexelProbe` of texel_ao.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct TexelProbe {
    /// The target's size in pixels.
    pub size: [f32; 2],
    /// Added to each pixel centre, in texels.
    pub offset: [f32; 2],
}

/// `Params` of gtao.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GtaoParams {
    /// View space (x right, y up, looking down −z) from world space,
    /// column-major.
    pub view_from_world: [[f32; 4]; 4],
    /// xyz: the eye (world space).
    pub eye: [f32; 4],
    /// Target width in pixels.
    pub width: u32,
    /// Target height in pixels.
    pub height: u32,
    /// Screen directions per pixel (each a slice through both sides).
    pub slices: u32,
    /// Samples per side of a slice.
    pub steps: u32,
    /// Occluders farther than this from the pixel count not (world units).
    pub radius: f32,
    /// Pixels per world unit at view depth 1: `(height / 2) / tan(fov_y / 2)`.
    pub focal: f32,
    /// The fraction of the radius over which an occluder fades out.
    pub falloff: f32,
    /// Padding.
    pub _pad: u32,
}

/// `Params` of trace.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct TraceParams {
    /// 0 cosine (count), 1 cosine with exponential falloff, 2 volume,
    /// 3 Kroon.
    pub estimator: u32,
    /// Rays per point.
    pub samples: u32,
    /// Rays per lane.
    pub group_size: u32,
    /// Padding.
    pub _pad: u32,
    /// Points of this dispatch.
    pub points: u32,
    /// The first point's index in the batch.
    pub first_point: u32,
    /// Workgroups per row of the dispatch grid.
    pub row_stride: u32,
    /// Kroon: 1 when the normals weight the hits.
    pub facing: u32,
    /// Kroon's α.
    pub alpha: f32,
    /// With `shared_points`: the scene every point of this dispatch is traced in.
    pub scene: u32,
    /// 1: the points are in model units, shared by every scene (each
    /// dispatch traces them in `scene`); 0: each point names its scene and
    /// is in that scene's frame.
    pub shared_points: u32,
    /// The index of this dispatch's first tally.
    pub tally_base: u32,
    /// Sobol direction numbers of dimensions 0 and 1, two index bits per
    /// entry.
    pub sobol: [[u32; 4]; 8],
}

/// `SceneInfo` of trace.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct TraceScene {
    /// The scene's first node in the batch's nodes.
    pub first_node: u32,
    /// The scene's first triangle in the batch's triangles.
    pub first_triangle: u32,
    /// Nodes (0: no triangles).
    pub nodes: u32,
    /// The ground's up axis, 3 for none.
    pub ground_axis: u32,
    /// The ground's height (local frame).
    pub ground_height: f32,
    /// A finite ground's half edge; negative for a solid half-space.
    pub ground_half: f32,
    /// Hits closer than this are ignored (local units).
    pub tmin: f32,
    /// Hits farther than this do not count (local units; f32::MAX for
    /// none).
    pub tmax: f32,
    /// τ of the exponential falloff, per local unit.
    pub tau: f32,
    /// Local units per model unit.
    pub scale: f32,
    /// Padding.
    pub _pad: [u32; 2],
    /// The local frame's origin in model units.
    pub centre: [f32; 3],
    /// Padding.
    pub _pad1: u32,
}

/// `RayPoint` of trace.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct TracePoint {
    /// The ray origin (local frame).
    pub origin: [f32; 3],
    /// Index of the point's scene.
    pub scene: u32,
    /// The ray frame's tangent.
    pub tangent: [f32; 3],
    /// The point's scramble seed.
    pub seed: u32,
    /// The ray frame's bitangent.
    pub bitangent: [f32; 3],
    /// Padding.
    pub _pad0: u32,
    /// The normal (zero for none).
    pub normal: [f32; 3],
    /// Padding.
    pub _pad1: u32,
}

/// `Tally` of trace.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct TraceTally {
    /// Sum of the directions that hit (volume).
    pub direction: [f32; 3],
    /// The weighted sum.
    pub sum: f32,
    /// Rays that hit within the limit.
    pub hits: u32,
    /// Rays whose closest hit is a back face.
    pub back: u32,
    /// Padding.
    pub _pad: [u32; 2],
}

const _: () = assert!(size_of::<TraceParams>() == 176);
const _: () = assert!(size_of::<TraceScene>() == 64);
const _: () = assert!(size_of::<TracePoint>() == 64);
const _: () = assert!(size_of::<TraceTally>() == 32);
const _: () = assert!(size_of::<GtaoParams>() == 112);
const _: () = assert!(size_of::<VertexAoParams>() == 16);
const _: () = assert!(size_of::<BlockInfo>() == 32);
const _: () = assert!(size_of::<CubemapAoParams>() == 64);
const _: () = assert!(size_of::<PreviewUniforms>() == 224);
const _: () = assert!(size_of::<TexelWeights>() == 1040);
const _: () = assert!(size_of::<TexelProbe>() == 16);
const _: () = assert!(size_of::<GridAoParams>() == 32);
const _: () = assert!(size_of::<GridPartInfo>() == 16);
const _: () = assert!(size_of::<GridReceiver>() == 32);
