//! Kroon's cubemaps: the occlusion a character casts at points of space
//! at a time of its clip, on the CPU or in the form the GPU lookups read.

use std::sync::OnceLock;

use aobake_runtime::{
    Asset,
    method::cubemap::{CubemapModel, gpu::CubemapGpu},
};
use glam::Vec3;

use crate::{copy_array, fail, finite_floats, free, live, open, out_floats, packed, put};

/// A cubemap asset. Opaque to C.
#[derive(Debug)]
pub struct AobakeCubemap(CubemapModel, OnceLock<Result<CubemapGpu, String>>);

/// Reads a cubemap asset (`cubemap-discrete` or `cubemap-continuous`) from
/// `len` bytes at `bytes`; NULL on failure.
///
/// # Safety
/// `bytes` must point to `len` readable bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_cubemap_open(bytes: *const u8, len: usize) -> *mut AobakeCubemap {
    // SAFETY: forwarded from the caller.
    unsafe {
        open(bytes, len, "cubemap", |a| match a {
            Asset::Cubemap { model, .. } => Some(AobakeCubemap(model, OnceLock::new())),
            _ => None,
        })
    }
}

/// Frees a cubemap handle (NULL is ignored).
///
/// # Safety
/// `cubemap` must be NULL or a live handle from `aobake_cubemap_open`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_cubemap_free(cubemap: *mut AobakeCubemap) {
    // SAFETY: forwarded from the caller.
    unsafe { free(cubemap) }
}

/// The baked clip's duration in seconds (the cycle), 0 for NULL (with
/// the reason set).
///
/// # Safety
/// `cubemap` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_cubemap_duration(cubemap: *const AobakeCubemap) -> f32 {
    // SAFETY: forwarded from the caller.
    unsafe { live(cubemap) }.map_or(0.0, |c| c.0.layout.duration)
}

/// Writes the occlusion the character casts at `count` points (`3 ·
/// count` finite floats, x y z, in the character's space as baked: an
/// engine that places the character elsewhere takes its points through
/// the inverse of that placement) at `seconds` of its clip (finite) to
/// `out` (`count` floats). `false` on NULL or input that is not finite,
/// with nothing written.
///
/// # Safety
/// `cubemap` must be NULL or a live handle; `points` NULL or `3 · count`
/// readable floats; `out` NULL or `count` writable floats, not
/// overlapping `points`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_cubemap_occlusion(
    cubemap: *const AobakeCubemap,
    seconds: f32,
    points: *const f32,
    count: usize,
    out: *mut f32,
) -> bool {
    // SAFETY: forwarded from the caller.
    unsafe {
        cubemap_lookup(
            cubemap,
            seconds,
            points,
            count,
            out,
            CubemapModel::occlusion,
        )
    }
}

/// As [`aobake_cubemap_occlusion`] for points of the ground plane: with
/// the asset's static ground, `gain · occlusion + offset`, clamped (see
/// `docs/engines.md`).
///
/// # Safety
/// As [`aobake_cubemap_occlusion`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_cubemap_ground_ao(
    cubemap: *const AobakeCubemap,
    seconds: f32,
    points: *const f32,
    count: usize,
    out: *mut f32,
) -> bool {
    // SAFETY: forwarded from the caller.
    unsafe {
        cubemap_lookup(
            cubemap,
            seconds,
            points,
            count,
            out,
            CubemapModel::ground_ao,
        )
    }
}

/// `look` at `count` points at `seconds`, into `out`.
///
/// # Safety
/// As [`aobake_cubemap_occlusion`].
unsafe fn cubemap_lookup(
    cubemap: *const AobakeCubemap,
    seconds: f32,
    points: *const f32,
    count: usize,
    out: *mut f32,
    look: fn(&CubemapModel, Vec3, f32) -> f32,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(c) = (unsafe { live(cubemap) }) else {
        return false;
    };
    if !seconds.is_finite() {
        fail(format!("seconds is {seconds}, not a time"));
        return false;
    }
    // SAFETY: forwarded from the caller.
    let Some(points) = (unsafe { finite_floats(points, count, 3, "points") }) else {
        return false;
    };
    // SAFETY: forwarded from the caller.
    let Some(out) = (unsafe { out_floats(out, count, count, "occlusion values") }) else {
        return false;
    };
    let phase = c.0.layout.phase(seconds);
    for (o, p) in out.iter_mut().zip(points.chunks_exact(3)) {
        *o = look(&c.0, Vec3::from_slice(p), phase);
    }
    true
}

/// The phase of the clip at `seconds` (the fraction of its cycle, 0 to
/// 1; 0 for a time that is not finite): the GPU lookups' `Params.phase`
/// at that time. 0 for NULL (with the reason set).
///
/// # Safety
/// `cubemap` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_cubemap_phase(cubemap: *const AobakeCubemap, seconds: f32) -> f32 {
    // SAFETY: forwarded from the caller.
    unsafe { live(cubemap) }.map_or(0.0, |c| c.0.layout.phase(seconds))
}

/// The GPU lookups' `Params` uniform (`shaders/wgsl/common/
/// cubemap_lookup.wgsl`), field for field and byte for byte: an engine
/// copies it whole into the uniform buffer after filling the fields of a
/// dispatch or draw (`points`, `phase`, `row_stride`, `on_ground`), which
/// `aobake_cubemap_gpu_params` sets to 0.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AobakeCubemapGpuParams {
    /// xyz: the spheroid's centre; w: the outer scaling.
    pub centre: [f32; 4],
    /// xyz: the spheroid's radii; w: the inner scaling.
    pub radii: [f32; 4],
    /// Texels per face edge.
    pub resolution: u32,
    /// Shells.
    pub shells: u32,
    /// Time samples.
    pub times: u32,
    /// 0 discrete, 1 continuous (cosine layout), 2 continuous (Kroon's
    /// thirds layout).
    pub encoding: u32,
    /// The engine's: points to evaluate (compute shader).
    pub points: u32,
    /// The engine's: the phase at the frame's time
    /// (`aobake_cubemap_phase`).
    pub phase: f32,
    /// The engine's: points per row of the dispatch grid (workgroups in
    /// x × 64; compute shader).
    pub row_stride: u32,
    /// The engine's: 1 for points on the ground plane (the static
    /// ground's `cubemap_ground_ao`), 0 for points anywhere.
    pub on_ground: u32,
}

/// `aobake_cubemap_gpu_words`' arrays: the texels, four words each
/// (`cubemap_ao.wgsl`'s binding 1).
pub const AOBAKE_CUBEMAP_GPU_TEXELS: u32 = 0;
/// The static ground's words (binding 4): texels per side (0 without a
/// static ground), the f32 bits of its square's min x, min z and side
/// and of its gain, then its offsets (x fastest).
pub const AOBAKE_CUBEMAP_GPU_GROUND: u32 = 1;

/// The GPU form of the cubemap at `cubemap`, packed once per handle, or
/// why there is none (NULL, or too large for 32-bit GPU indices).
///
/// # Safety
/// `cubemap` must be NULL or a live handle.
unsafe fn cubemap_gpu<'a>(cubemap: *const AobakeCubemap) -> Option<&'a CubemapGpu> {
    // SAFETY: forwarded from the caller.
    let c = unsafe { live(cubemap) }?;
    packed(&c.1, || {
        CubemapGpu::new(&c.0).map_err(|e| format!("the cubemap has no GPU form: {e}"))
    })
}

/// Writes the GPU lookups' `Params` to `out`, the fields of a dispatch
/// at 0 (`docs/engines.md`). `false` for NULL or a cubemap too large for
/// 32-bit GPU indices.
///
/// # Safety
/// `cubemap` must be NULL or a live handle; `out` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_cubemap_gpu_params(
    cubemap: *const AobakeCubemap,
    out: *mut AobakeCubemapGpuParams,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(gpu) = (unsafe { cubemap_gpu(cubemap) }) else {
        return false;
    };
    let params = AobakeCubemapGpuParams {
        centre: gpu.centre,
        radii: gpu.radii,
        resolution: gpu.resolution,
        shells: gpu.shells,
        times: gpu.times,
        encoding: gpu.encoding,
        points: 0,
        phase: 0.0,
        row_stride: 0,
        on_ground: 0,
    };
    // SAFETY: the caller passes NULL or a writable struct.
    unsafe { put(out, params) }
}

/// The GPU lookups' arrays as they read them, uploaded once per asset:
/// sets `*words` to the length in words of array `which`
/// (`AOBAKE_CUBEMAP_GPU_TEXELS` or `_GROUND`) and copies it to `out` when
/// `out` is not NULL (then `len` must be at least `*words`). Call it with
/// `out` NULL to size the buffer. `false` for a NULL handle, a cubemap
/// too large for 32-bit GPU indices, an unknown array or a short buffer
/// (`*words` is still set).
///
/// # Safety
/// `cubemap` must be NULL or a live handle; `out` NULL or `len` writable
/// words; `words` a writable `size_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_cubemap_gpu_words(
    cubemap: *const AobakeCubemap,
    which: u32,
    out: *mut u32,
    len: usize,
    words: *mut usize,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(gpu) = (unsafe { cubemap_gpu(cubemap) }) else {
        return false;
    };
    let named: [(u32, &str, &[u32]); 2] = [
        (
            AOBAKE_CUBEMAP_GPU_TEXELS,
            "AOBAKE_CUBEMAP_GPU_TEXELS",
            &gpu.texels,
        ),
        (
            AOBAKE_CUBEMAP_GPU_GROUND,
            "AOBAKE_CUBEMAP_GPU_GROUND",
            &gpu.ground,
        ),
    ];
    // SAFETY: forwarded from the caller.
    unsafe { copy_array(which, &named, out, len, words) }
}

/// Writes the height (y, in the character's space as baked) of the ground
/// plane the asset's static ground lies on to `out`: where
/// `aobake_cubemap_ground_ao`'s points are. `false` for NULL or an asset
/// without a static ground.
///
/// # Safety
/// `cubemap` must be NULL or a live handle; `out` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_cubemap_ground_height(
    cubemap: *const AobakeCubemap,
    out: *mut f32,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(c) = (unsafe { live(cubemap) }) else {
        return false;
    };
    let Some(ground) = &c.0.ground else {
        fail("the asset has no static ground (baked with cubemap.static_ground = false)");
        return false;
    };
    // SAFETY: the caller passes NULL or a writable float.
    unsafe { put(out, ground.square.height) }
}
