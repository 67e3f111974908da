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
    /// Padding.
    pub _pad: u32,
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

const _: () = assert!(size_of::<VertexAoParams>() == 16);
const _: () = assert!(size_of::<BlockInfo>() == 32);
const _: () = assert!(size_of::<CubemapAoParams>() == 64);
const _: () = assert!(size_of::<PreviewUniforms>() == 224);
