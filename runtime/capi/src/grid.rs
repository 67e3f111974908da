//! Malmer et al.'s grids: the occlusion rigid parts cast at receivers,
//! posed by the frame's skinning palette, on the CPU or in the form the
//! GPU lookups read.

use std::{
    ffi::{CString, c_char},
    sync::OnceLock,
};

use aobake_runtime::{
    Asset, PrimitiveSpan,
    method::grid::{
        base::Receiver,
        gpu::GridGpu,
        model::{GridModel, PartPose, Terms},
    },
};
use glam::{Mat4, Vec3};

use crate::{
    AobakePrimitive, c_string, copy_array, fail, finite_floats, floats, free, live, open,
    out_floats, packed, put, put_primitive,
};

/// A grid asset. Opaque to C.
#[derive(Debug)]
pub struct AobakeGrid(
    GridModel,
    OnceLock<Result<GridForm, String>>,
    /// The parts' names as C strings.
    Vec<CString>,
    /// The glTF primitives of the receivers' vertices, in order.
    Vec<PrimitiveSpan>,
);

/// Reads a grid asset from `len` bytes at `bytes`; NULL on failure.
///
/// # Safety
/// `bytes` must point to `len` readable bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_open(bytes: *const u8, len: usize) -> *mut AobakeGrid {
    // SAFETY: forwarded from the caller.
    unsafe {
        open(bytes, len, "grid", |a| match a {
            Asset::Grid { model, header } => {
                let names = model.parts.iter().map(|p| c_string(&p.name)).collect();
                Some(AobakeGrid(model, OnceLock::new(), names, header.primitives))
            }
            _ => None,
        })
    }
}

/// Frees a grid handle (NULL is ignored).
///
/// # Safety
/// `grid` must be NULL or a live handle from `aobake_grid_open`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_free(grid: *mut AobakeGrid) {
    // SAFETY: forwarded from the caller.
    unsafe { free(grid) }
}

/// Parts (rigid bodies with a grid each), 0 for NULL (with the reason
/// set).
///
/// # Safety
/// `grid` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_part_count(grid: *const AobakeGrid) -> usize {
    // SAFETY: forwarded from the caller.
    unsafe { live(grid) }.map_or(0, |g| g.0.parts.len())
}

/// The glTF primitives of the character's vertices, in aobake's vertex
/// order (the order of the static base's vertex offsets): 0 for NULL, and
/// for an asset written before format 1.6.
///
/// # Safety
/// `grid` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_primitive_count(grid: *const AobakeGrid) -> usize {
    // SAFETY: forwarded from the caller.
    unsafe { live(grid) }.map_or(0, |g| g.3.len())
}

/// Writes primitive `i` (below `aobake_grid_primitive_count`) to `out`;
/// `false` for NULL or past the count.
///
/// # Safety
/// `grid` must be NULL or a live handle; `out` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_primitive(
    grid: *const AobakeGrid,
    i: usize,
    out: *mut AobakePrimitive,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(g) = (unsafe { live(grid) }) else {
        return false;
    };
    // SAFETY: forwarded from the caller.
    unsafe { put_primitive(&g.3, i, out) }
}

/// Matrices the palette must hold: the highest joint a part follows, plus
/// one (0 for NULL, with the reason set).
///
/// # Safety
/// `grid` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_palette_len(grid: *const AobakeGrid) -> usize {
    // SAFETY: forwarded from the caller.
    unsafe { live(grid) }.map_or(0, |g| {
        g.0.parts.iter().map(|p| p.joint + 1).max().unwrap_or(0)
    })
}

/// A grid lookup's checked inputs: the parts posed, and the receivers'
/// points, normals (3 floats each) and parts.
struct GridReceivers<'a> {
    poses: Vec<PartPose>,
    points: &'a [f32],
    normals: &'a [f32],
    parts: Option<&'a [i64]>,
}

impl GridReceivers<'_> {
    /// Receiver `i`'s point, unit normal and part (a normal that is not
    /// of unit length is normalised; one that is, to within f32's
    /// rounding, is taken as it is).
    fn get(&self, i: usize) -> (Vec3, Vec3, Option<usize>) {
        let n = Vec3::from_slice(&self.normals[3 * i..]);
        let n = if (n.length_squared() - 1.0).abs() > 1e-6 {
            // Scaled first: a tiny normal is still a direction, and a huge
            // one does not overflow its length.
            (n / n.abs().max_element()).normalize()
        } else {
            n
        };
        (
            Vec3::from_slice(&self.points[3 * i..]),
            n,
            self.parts.and_then(|k| usize::try_from(k[i]).ok()),
        )
    }
}

/// The grids posed by `palette_len` matrices at `palette`, or the reason
/// they cannot be: a short palette, or a part's matrix that is not finite
/// or cannot be inverted (matrices no part follows are not checked).
///
/// # Safety
/// `palette` must be NULL or point to `16 · palette_len` readable floats.
unsafe fn posed(g: &AobakeGrid, palette: *const f32, palette_len: usize) -> Option<Vec<PartPose>> {
    if let Err(e) = g.0.check_palette(palette_len) {
        fail(e.to_string());
        return None;
    }
    // SAFETY: forwarded from the caller.
    let palette = unsafe { floats(palette, palette_len, 16, "palette") }?;
    let palette: Vec<Mat4> = palette
        .chunks_exact(16)
        .map(Mat4::from_cols_slice)
        .collect();
    let poses = g.0.poses(&palette);
    let singular = poses
        .iter()
        .position(|p| !(p.grid_from_world.is_finite() && p.world_from_bind.is_finite()));
    if let Some(k) = singular {
        fail(format!(
            "palette: matrix {} (part {k}'s joint) is not finite or cannot be inverted",
            g.0.parts[k].joint
        ));
        return None;
    }
    Some(poses)
}

/// Reads a grid lookup's arguments; `None` (with the reason set) when any
/// is wrong.
///
/// # Safety
/// As [`aobake_grid_occlusion`].
unsafe fn grid_receivers<'a>(
    grid: *const AobakeGrid,
    palette: *const f32,
    palette_len: usize,
    points: *const f32,
    normals: *const f32,
    parts: *const i64,
    count: usize,
) -> Option<(&'a AobakeGrid, GridReceivers<'a>)> {
    // SAFETY: forwarded from the caller.
    let g = unsafe { live(grid) }?;
    // SAFETY: forwarded from the caller.
    let poses = unsafe { posed(g, palette, palette_len) }?;
    // SAFETY: forwarded from the caller.
    let points = unsafe { finite_floats(points, count, 3, "points") }?;
    // SAFETY: forwarded from the caller.
    let normals = unsafe { finite_floats(normals, count, 3, "normals") }?;
    if let Some(i) = normals
        .chunks_exact(3)
        .position(|n| Vec3::from_slice(n).abs().max_element() == 0.0)
    {
        fail(format!("normals: item {i} has no direction (zero length)"));
        return None;
    }
    let parts = if parts.is_null() || count == 0 {
        None
    } else {
        // SAFETY: the caller promises `count` readable part indices.
        let parts = unsafe { std::slice::from_raw_parts(parts, count) };
        let n = g.0.parts.len();
        if let Some(bad) = parts.iter().find(|&&k| k >= n as i64 || k < -1) {
            fail(format!("part {bad} of {n}"));
            return None;
        }
        Some(parts)
    };
    Some((
        g,
        GridReceivers {
            poses,
            points,
            normals,
            parts,
        },
    ))
}

/// Writes the occlusion every part casts at `count` receivers to `out`
/// (`count` floats), the parts posed by the frame's skinning `palette`
/// (`palette_len` column-major 4 × 4 matrices, world from bind, as the
/// renderer skins with; see [`aobake_grid_part_name`]). `points` and
/// `normals` are `3 · count` finite floats in the palette's world
/// (normals are normalised; a zero one is refused); `parts` is NULL (no
/// receiver is on a part, as the ground) or `count` part indices, -1 for
/// none: a receiver on a part takes its own part by the self-occlusion
/// rule. These are the paper's grids alone; [`aobake_grid_ao`] adds the
/// asset's static base.
///
/// # Safety
/// `grid` must be NULL or a live handle; each pointer NULL or holding the
/// counts above; `out` overlapping none of the inputs.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_occlusion(
    grid: *const AobakeGrid,
    palette: *const f32,
    palette_len: usize,
    points: *const f32,
    normals: *const f32,
    parts: *const i64,
    count: usize,
    out: *mut f32,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some((g, r)) =
        (unsafe { grid_receivers(grid, palette, palette_len, points, normals, parts, count) })
    else {
        return false;
    };
    // SAFETY: forwarded from the caller.
    let Some(out) = (unsafe { out_floats(out, count, count, "occlusion values") }) else {
        return false;
    };
    for (i, o) in out.iter_mut().enumerate() {
        let (p, n, k) = r.get(i);
        *o = g.0.occlusion(&r.poses, p, n, k, Terms::All);
    }
    true
}

/// Writes the AO an engine shows at `count` receivers to `out`: as
/// [`aobake_grid_occlusion`], plus the asset's static base when it has
/// one (`gain · grids + offset`, clamped; see `docs/engines.md`).
/// `receivers` is NULL or `count` values:
/// the receiver's vertex index in the character (its offset; with a
/// static base, an index past the character's vertices is refused), -1
/// for a point of the ground (the base's ground texture), -2 for any
/// other surface (the grids alone, as [`aobake_grid_occlusion`] gives
/// them with the receiver's part: the base knows nothing of a surface the
/// bake did not see, such as another object or level of detail); NULL
/// takes every receiver as -2. The base's
/// ground texture lies in the space the palette was baked in: an engine
/// that places the character elsewhere looks up in the character's
/// space (its points, normals and palette taken through the inverse of
/// the placement).
///
/// # Safety
/// As [`aobake_grid_occlusion`]; `receivers` NULL or holding `count`
/// values (not overlapping `out` either).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_ao(
    grid: *const AobakeGrid,
    palette: *const f32,
    palette_len: usize,
    points: *const f32,
    normals: *const f32,
    parts: *const i64,
    receivers: *const i64,
    count: usize,
    out: *mut f32,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some((g, r)) =
        (unsafe { grid_receivers(grid, palette, palette_len, points, normals, parts, count) })
    else {
        return false;
    };
    let kinds: &[i64] = if receivers.is_null() || count == 0 {
        &[]
    } else {
        // SAFETY: the caller promises `count` readable values.
        unsafe { std::slice::from_raw_parts(receivers, count) }
    };
    // With a static base, a vertex's offset is its own: an index past the
    // character's vertices is a caller's mistake, not offset 0. Checked
    // before anything is written.
    let vertices = g.0.base.as_ref().map(|b| b.vertex_offsets.len());
    for (i, &kind) in kinds.iter().enumerate() {
        match (kind, vertices) {
            (-2 | -1, _) => {}
            (index, _) if index < 0 => {
                fail(format!("receiver kind {index}: a vertex index, -1 or -2"));
                return false;
            }
            (index, Some(v)) if index as u64 >= v as u64 => {
                fail(format!(
                    "receiver {i}: vertex {index} of {v} (the character the asset was baked for)"
                ));
                return false;
            }
            _ => {}
        }
    }
    // SAFETY: forwarded from the caller.
    let Some(out) = (unsafe { out_floats(out, count, count, "occlusion values") }) else {
        return false;
    };
    for (i, o) in out.iter_mut().enumerate() {
        let (p, n, part) = r.get(i);
        let receiver = match kinds.get(i).copied().unwrap_or(-2) {
            -1 => Receiver::Ground,
            index => match usize::try_from(index) {
                Ok(index) => Receiver::Vertex { index, part },
                Err(_) => Receiver::Other { part },
            },
        };
        *o = g.0.ao(&r.poses, p, n, receiver);
    }
    true
}

/// The palette entry (joint) part `part` follows, or -1 for a part the
/// asset does not have (or NULL). The bake puts a vertex of the
/// character on the part of its heaviest skin influence (the first of
/// equal weights, in its `JOINTS_0`/`WEIGHTS_0` order), or on none when
/// that joint has no part (it carries no triangle): the `parts` the
/// lookups take, and the `own` of the GPU lookups.
///
/// # Safety
/// `grid` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_part_joint(grid: *const AobakeGrid, part: usize) -> i64 {
    // SAFETY: forwarded from the caller.
    let Some(g) = (unsafe { live(grid) }) else {
        return -1;
    };
    match g.0.parts.get(part) {
        Some(p) => p.joint as i64,
        None => {
            fail(format!("part {part} of {}", g.0.parts.len()));
            -1
        }
    }
}

/// The GPU lookups' `Params` uniform (`shaders/wgsl/common/
/// grid_lookup.wgsl`), field for field and byte for byte: an engine
/// copies it whole into the uniform buffer after filling the fields of a
/// dispatch (`points`, `row_stride`), which `aobake_grid_gpu_params` sets
/// to 0.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AobakeGridGpuParams {
    /// Parts.
    pub parts: u32,
    /// The engine's: receivers to evaluate (compute shader).
    pub points: u32,
    /// The engine's: receivers per row of the dispatch grid (workgroups
    /// in x × 64; compute shader).
    pub row_stride: u32,
    /// 1 when the cones are baked.
    pub cones: u32,
    /// T_clip's samples per axis (0 without cones).
    pub tclip_resolution: u32,
    /// Index in the cells of T_clip's first f32.
    pub tclip_offset: u32,
    /// 1 when the asset has a static base.
    pub base: u32,
    /// The base's ground gain (0 without a base); the shader reads its
    /// bits as a u32.
    pub ground_gain: f32,
}

/// `aobake_grid_gpu_words`' arrays: the parts' infos, four words each
/// (cells per edge, index of the first cell, the f32 bits of the base's
/// gain at the part's vertices, padding; `grid_ao.wgsl`'s binding 1).
pub const AOBAKE_GRID_GPU_INFOS: u32 = 0;
/// The cells, one word each (RGBA8, R in the low byte), part after part,
/// then T_clip's f32 pairs (binding 2).
pub const AOBAKE_GRID_GPU_CELLS: u32 = 1;
/// The static base's offset per vertex of the character (f32 bits; no
/// words without a base, when `grid_ao`'s offset is 0): the `offset` a
/// vertex shader passes to `grid_ao`, a vertex attribute.
pub const AOBAKE_GRID_GPU_VERTEX_OFFSETS: u32 = 2;
/// The static base's ground texture as `common/ground_texture.wgsl`'s
/// `ground_offset` reads it: texels per side (0 without a base), the f32
/// bits of its square's min x, min z and side and of its gain, then its
/// offsets (x fastest). The grid lookups have no binding for it: an
/// engine's ground shader computes the offset it passes to `grid_ao`
/// (with that function, or from the offsets as a filtered texture,
/// `docs/engines.md`).
pub const AOBAKE_GRID_GPU_GROUND: u32 = 3;

/// Everything `aobake_grid_gpu_words` hands out: the grids' GPU form and
/// the static base's words.
#[derive(Debug)]
struct GridForm {
    grids: GridGpu,
    /// The base's offset per vertex (f32 bits; none without a base).
    vertex_offsets: Vec<u32>,
    /// The base's ground texture's words (one word, 0, without a base).
    ground: Vec<u32>,
}

/// The GPU form of the grid at `grid`, packed once per handle (an engine
/// asks for each array twice), or why there is none (NULL, or too large
/// for 32-bit GPU indices).
///
/// # Safety
/// `grid` must be NULL or a live handle.
unsafe fn grid_gpu<'a>(grid: *const AobakeGrid) -> Option<&'a GridForm> {
    // SAFETY: forwarded from the caller.
    let g = unsafe { live(grid) }?;
    packed(&g.1, || {
        let grids = GridGpu::new(&g.0).map_err(|e| format!("the grid has no GPU form: {e}"))?;
        let base = g.0.base.as_ref();
        Ok(GridForm {
            grids,
            vertex_offsets: base.map_or_else(Vec::new, |b| {
                b.vertex_offsets.iter().map(|x| x.to_bits()).collect()
            }),
            ground: base.map_or_else(|| vec![0], |b| b.ground.gpu_words()),
        })
    })
}

/// Writes the GPU lookups' `Params` to `out`, the fields of a dispatch
/// at 0 (`docs/engines.md`). `false` for NULL or a grid too large for
/// 32-bit GPU indices.
///
/// # Safety
/// `grid` must be NULL or a live handle; `out` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_gpu_params(
    grid: *const AobakeGrid,
    out: *mut AobakeGridGpuParams,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(GridForm { grids: gpu, .. }) = (unsafe { grid_gpu(grid) }) else {
        return false;
    };
    let params = AobakeGridGpuParams {
        parts: gpu.parts(),
        points: 0,
        row_stride: 0,
        cones: gpu.cones,
        tclip_resolution: gpu.tclip_resolution,
        tclip_offset: gpu.tclip_offset,
        base: gpu.base,
        ground_gain: f32::from_bits(gpu.ground_gain),
    };
    // SAFETY: the caller passes NULL or a writable struct.
    unsafe { put(out, params) }
}

/// The GPU lookups' arrays as they read them, uploaded once per asset:
/// sets `*words` to the length in words of array `which`
/// (`AOBAKE_GRID_GPU_INFOS`, `_CELLS`, `_VERTEX_OFFSETS` or `_GROUND`)
/// and copies it to `out` when `out` is not NULL (then `len` must be at
/// least `*words`). Call it with `out` NULL to size the buffer. `false`
/// for a NULL handle, a grid too large for 32-bit GPU indices, an unknown
/// array or a short buffer (`*words` is still set).
///
/// # Safety
/// `grid` must be NULL or a live handle; `out` NULL or `len` writable
/// words; `words` a writable `size_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_gpu_words(
    grid: *const AobakeGrid,
    which: u32,
    out: *mut u32,
    len: usize,
    words: *mut usize,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(gpu) = (unsafe { grid_gpu(grid) }) else {
        return false;
    };
    let named: [(u32, &str, &[u32]); 4] = [
        (
            AOBAKE_GRID_GPU_INFOS,
            "AOBAKE_GRID_GPU_INFOS",
            gpu.grids.infos.as_flattened(),
        ),
        (
            AOBAKE_GRID_GPU_CELLS,
            "AOBAKE_GRID_GPU_CELLS",
            &gpu.grids.cells,
        ),
        (
            AOBAKE_GRID_GPU_VERTEX_OFFSETS,
            "AOBAKE_GRID_GPU_VERTEX_OFFSETS",
            &gpu.vertex_offsets,
        ),
        (
            AOBAKE_GRID_GPU_GROUND,
            "AOBAKE_GRID_GPU_GROUND",
            &gpu.ground,
        ),
    ];
    // SAFETY: forwarded from the caller.
    unsafe { copy_array(which, &named, out, len, words) }
}

/// Writes the parts' poses for a frame, as the GPU lookups read them
/// (`grid_ao.wgsl`'s binding 3), to `out`: per part 32 floats,
/// `grid_from_world` then `world_from_bind`, column-major, from the
/// frame's skinning `palette` as [`aobake_grid_occlusion`] takes it.
/// `len` must be `32 · aobake_grid_part_count`. `false` for NULL, a
/// short palette, a matrix that is not finite or cannot be inverted, or a
/// buffer of another length.
///
/// # Safety
/// `grid` must be NULL or a live handle; `palette` NULL or `16 ·
/// palette_len` readable floats; `out` NULL or `len` writable floats, not
/// overlapping `palette`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_gpu_poses(
    grid: *const AobakeGrid,
    palette: *const f32,
    palette_len: usize,
    out: *mut f32,
    len: usize,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(g) = (unsafe { live(grid) }) else {
        return false;
    };
    // SAFETY: forwarded from the caller.
    let Some(poses) = (unsafe { posed(g, palette, palette_len) }) else {
        return false;
    };
    // SAFETY: forwarded from the caller.
    let Some(out) = (unsafe { out_floats(out, len, 32 * poses.len(), "poses' floats") }) else {
        return false;
    };
    for (o, pose) in out.chunks_exact_mut(32).zip(&poses) {
        pose.grid_from_world.write_cols_to_slice(&mut o[..16]);
        pose.world_from_bind.write_cols_to_slice(&mut o[16..]);
    }
    true
}

/// The name of part `part` (its node's, NUL-terminated UTF-8; valid until
/// the handle is freed), or NULL for a part the asset does not have (or
/// NULL). The palette entry `aobake_grid_part_joint(grid, part)` is that
/// node's `world_from_bind`: its world matrix times its inverse bind
/// matrix when it is a skin's joint, its world matrix when it is a rigid
/// mesh's node; entries no part follows are not read.
///
/// # Safety
/// `grid` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_part_name(
    grid: *const AobakeGrid,
    part: usize,
) -> *const c_char {
    // SAFETY: forwarded from the caller.
    let Some(g) = (unsafe { live(grid) }) else {
        return std::ptr::null();
    };
    match g.2.get(part) {
        Some(name) => name.as_ptr(),
        None => {
            fail(format!("part {part} of {}", g.2.len()));
            std::ptr::null()
        }
    }
}

/// Writes the height (y, in the space the palette was baked in) of the
/// ground plane the asset's static base lies on to `out`: where the
/// ground receivers of `aobake_grid_ao` are. `false` for NULL or an asset
/// without a static base.
///
/// # Safety
/// `grid` must be NULL or a live handle; `out` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_ground_height(grid: *const AobakeGrid, out: *mut f32) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(g) = (unsafe { live(grid) }) else {
        return false;
    };
    let Some(base) = &g.0.base else {
        fail("the asset has no static base (baked with grid.static_base = false)");
        return false;
    };
    // SAFETY: the caller passes NULL or a writable float.
    unsafe { put(out, base.ground.square.height) }
}
