//! # aobake-runtime-capi
//!
//! aobake-runtime behind a C ABI, for engine plugins written in C, C++ or
//! C# (P/Invoke): a shared library (`libaobake_rt.so`, `aobake_rt.dll`,
//! `libaobake_rt.dylib`) and its header `include/aobake_rt.h`, which
//! cbindgen generates from this file (the crate's tests check that the
//! header is current and drive the library from a C program).
//!
//! What it offers is what an engine does with a vertex-method asset each
//! frame (`docs/engines.md`):
//!
//! 1. `aobake_vertex_ao_open`: read an asset from memory, checked whole.
//! 2. `aobake_vertex_ao_node`: find, once, the node of each bone the
//!    engine animates, by name.
//! 3. Per frame, `aobake_vertex_ao_set_local` for each animated node (its
//!    local translation, rotation and scale), then either
//!    `aobake_vertex_ao_weights` (the pose's weights, for the GPU
//!    evaluators in `shaders/`) or `aobake_vertex_ao_evaluate` (every
//!    vertex's AO, on the CPU).
//! 4. `aobake_vertex_ao_free`.
//!
//! And the lookups in space: `aobake_cubemap_*` (Kroon's cubemaps: the
//! occlusion a character casts at points, at a time of its clip) and
//! `aobake_grid_*` (Malmer et al.'s grids: the occlusion rigid parts cast
//! at receivers, given the frame's skinning palette).
//!
//! Errors: a function that can fail returns `false` or `NULL`, and
//! `aobake_last_error` gives the reason, on the calling thread. A handle
//! may be used from one thread at a time; separate handles are
//! independent.

use std::{
    cell::RefCell,
    ffi::{CStr, CString, c_char},
    sync::OnceLock,
};

use aobake_runtime::{
    Asset,
    method::{
        cubemap::CubemapModel,
        grid::{
            base::Receiver,
            model::{GridModel, PartPose, Terms},
        },
        vertex::{
            VertexAo,
            form::{FormRef, GpuArrays},
        },
    },
    rig::Transform,
};
use glam::{Mat4, Quat, Vec3};

/// A vertex-method asset (static average, vertex-linear or
/// vertex-clustered), its rig and the pose being set. Opaque to C.
#[derive(Debug)]
pub struct AobakeVertexAo(VertexAo, OnceLock<Result<GpuArrays, String>>);

/// A node's local transform, as glTF and engines animate it: translation,
/// rotation (unit quaternion x, y, z, w) and scale, in the parent's frame.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AobakeTransform {
    /// Translation.
    pub translation: [f32; 3],
    /// Rotation, x y z w.
    pub rotation: [f32; 4],
    /// Scale per axis.
    pub scale: [f32; 3],
}

impl From<Transform> for AobakeTransform {
    fn from(t: Transform) -> Self {
        Self {
            translation: t.translation.to_array(),
            rotation: t.rotation.to_array(),
            scale: t.scale.to_array(),
        }
    }
}

thread_local! {
    static LAST_ERROR: RefCell<Option<CString>> = const { RefCell::new(None) };
}

fn fail(message: impl Into<String>) {
    let text = message.into().replace('\0', " ");
    let c = CString::new(text).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = Some(c));
}

/// The reason the last failing call on this thread failed, as UTF-8, or
/// NULL if none has. Valid until the next failing call on this thread.
#[unsafe(no_mangle)]
pub extern "C" fn aobake_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ref().map_or(std::ptr::null(), |c| c.as_ptr()))
}

/// Reads the asset in `len` bytes at `bytes` (copied) with
/// [`Asset::from_bytes`], keeps it as a new handle if `pick` takes its
/// family, or returns NULL with the reason.
///
/// # Safety
/// `bytes` must be NULL or point to `len` readable bytes.
unsafe fn open<T>(
    bytes: *const u8,
    len: usize,
    wanted: &str,
    pick: impl FnOnce(Asset) -> Option<T>,
) -> *mut T {
    if bytes.is_null() {
        fail("bytes is NULL");
        return std::ptr::null_mut();
    }
    // SAFETY: the caller promises `len` readable bytes at `bytes`, which
    // is not NULL.
    let data = unsafe { std::slice::from_raw_parts(bytes, len) };
    let asset = match Asset::from_bytes(data) {
        Ok(asset) => asset,
        Err(e) => {
            fail(e.to_string());
            return std::ptr::null_mut();
        }
    };
    let method = asset.method();
    match pick(asset) {
        Some(handle) => Box::into_raw(Box::new(handle)),
        None => {
            fail(format!("a {} asset is not a {wanted} asset", method.name()));
            std::ptr::null_mut()
        }
    }
}

/// Frees a handle made by [`open`] (NULL is ignored).
///
/// # Safety
/// `handle` must be NULL or a live handle from [`open`] not yet freed.
unsafe fn free<T>(handle: *mut T) {
    if !handle.is_null() {
        // SAFETY: the caller passes a live handle made by Box::into_raw.
        drop(unsafe { Box::from_raw(handle) });
    }
}

/// Reads a vertex-method asset from `len` bytes at `bytes` (copied; the
/// caller may free them after). NULL on failure: not an asset, damaged,
/// not a vertex method, or written before asset format 1.4 (no rig).
///
/// # Safety
/// `bytes` must point to `len` readable bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_open(
    bytes: *const u8,
    len: usize,
) -> *mut AobakeVertexAo {
    // SAFETY: forwarded from the caller.
    unsafe {
        open(bytes, len, "vertex", |a| match a {
            Asset::Vertex(ao) => Some(AobakeVertexAo(*ao, OnceLock::new())),
            _ => None,
        })
    }
}

/// Frees a handle from `aobake_vertex_ao_open` (NULL is ignored).
///
/// # Safety
/// `ao` must be NULL or a handle from `aobake_vertex_ao_open` not yet
/// freed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_free(ao: *mut AobakeVertexAo) {
    // SAFETY: forwarded from the caller.
    unsafe { free(ao) }
}

/// The handle behind a pointer, or an error for NULL.
///
/// # Safety
/// `ao` must be NULL or a live handle.
unsafe fn handle<'a>(ao: *const AobakeVertexAo) -> Option<&'a VertexAo> {
    // SAFETY: the caller passes NULL or a live handle.
    let h = unsafe { ao.as_ref() }.map(|h| &h.0);
    if h.is_none() {
        fail("the handle is NULL");
    }
    h
}

/// Vertices the asset covers, in aobake's vertex order (0 for NULL).
///
/// # Safety
/// `ao` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_vertices(ao: *const AobakeVertexAo) -> usize {
    // SAFETY: forwarded from the caller.
    unsafe { handle(ao) }.map_or(0, VertexAo::vertices)
}

/// Weights per pose: the length `aobake_vertex_ao_weights` fills (0 for
/// NULL).
///
/// # Safety
/// `ao` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_weight_count(ao: *const AobakeVertexAo) -> usize {
    // SAFETY: forwarded from the caller.
    unsafe { handle(ao) }.map_or(0, VertexAo::weight_count)
}

/// `aobake_vertex_ao_gpu_words`' arrays: the dense blocks
/// (`AOBAKE_GPU_BLOCK_WORDS` words each; none for a sparse model).
pub const AOBAKE_GPU_BLOCKS: u32 = 0;
/// The f16 coefficients, two per word (element 2i in the low half).
pub const AOBAKE_GPU_COEFFICIENTS: u32 = 1;
/// Dense: the blocks' vertex-cluster maps one after another; sparse: the
/// `vertices + 1` row offsets.
pub const AOBAKE_GPU_MAPS: u32 = 2;
/// Sparse: each coefficient's row, u16 two per word.
pub const AOBAKE_GPU_SPARSE_ROWS: u32 = 3;
/// Words per dense block in `AOBAKE_GPU_BLOCKS`.
pub const AOBAKE_GPU_BLOCK_WORDS: usize = 8;
const _: () = assert!(AOBAKE_GPU_BLOCK_WORDS == aobake_runtime::method::vertex::form::BLOCK_WORDS);

/// The GPU form of the asset's coefficients, as the evaluators in
/// `shaders/` read them (`vertex_ao.wgsl`'s bindings 1 to 3 and 6, and
/// their translations; `docs/engines.md`): sets `*words` to the length in
/// words of array `which` (`AOBAKE_GPU_BLOCKS`, `_COEFFICIENTS`, `_MAPS`
/// or `_SPARSE_ROWS`) and copies it to `out` when `out` is not NULL (then
/// `len` must be at least `*words`). Call it with `out` NULL to size the
/// buffer. `false` for a NULL handle, an unknown array, a short buffer, or
/// a model too large for 32-bit GPU indices.
///
/// # Safety
/// `ao` must be NULL or a live handle; `out` NULL or `len` writable
/// words; `words` a writable `size_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_gpu_words(
    ao: *const AobakeVertexAo,
    which: u32,
    out: *mut u32,
    len: usize,
    words: *mut usize,
) -> bool {
    // SAFETY: the caller passes NULL or a live handle.
    let Some(h) = (unsafe { ao.as_ref() }) else {
        fail("the handle is NULL");
        return false;
    };
    // Packed once per handle: an engine asks for each array twice (its
    // size, then its words).
    let packed = h.1.get_or_init(|| {
        GpuArrays::new(h.0.model().form()).map_err(|e| format!("the model has no GPU form: {e}"))
    });
    let arrays = match packed {
        Ok(a) => a,
        Err(e) => {
            fail(e.clone());
            return false;
        }
    };
    let array: &[u32] = match which {
        AOBAKE_GPU_BLOCKS => arrays.blocks.as_flattened(),
        AOBAKE_GPU_COEFFICIENTS => &arrays.coefficients,
        AOBAKE_GPU_MAPS => &arrays.maps,
        AOBAKE_GPU_SPARSE_ROWS => &arrays.sparse_rows,
        other => {
            fail(format!(
                "array {other}: AOBAKE_GPU_BLOCKS (0) to AOBAKE_GPU_SPARSE_ROWS (3)"
            ));
            return false;
        }
    };
    // SAFETY: the caller passes a writable `size_t`, or NULL.
    let Some(words) = (unsafe { words.as_mut() }) else {
        fail("words is NULL");
        return false;
    };
    *words = array.len();
    if out.is_null() {
        return true;
    }
    if len < array.len() {
        fail(format!(
            "out holds {len} words, the array has {}",
            array.len()
        ));
        return false;
    }
    // SAFETY: the caller promises `len` writable words at `out`, which is
    // not NULL, and `len` is at least the array's length.
    unsafe { std::ptr::copy_nonoverlapping(array.as_ptr(), out, array.len()) };
    true
}

/// Whether the GPU form is sparse (evaluate with `cs_sparse`, reading the
/// row offsets and `AOBAKE_GPU_SPARSE_ROWS`) or dense (`cs_main`, reading
/// the blocks and maps); `false` for NULL.
///
/// # Safety
/// `ao` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_gpu_sparse(ao: *const AobakeVertexAo) -> bool {
    // SAFETY: forwarded from the caller.
    unsafe { handle(ao) }.is_some_and(|h| matches!(h.model().form(), FormRef::Sparse(_)))
}

/// Nodes of the rig (0 for NULL).
///
/// # Safety
/// `ao` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_node_count(ao: *const AobakeVertexAo) -> usize {
    // SAFETY: forwarded from the caller.
    unsafe { handle(ao) }.map_or(0, |h| h.skeleton().nodes.len())
}

/// The node named `name` (NUL-terminated UTF-8), or -1 if the rig has
/// none (or on NULL).
///
/// # Safety
/// `ao` must be NULL or a live handle; `name` NULL or a NUL-terminated
/// string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_node(
    ao: *const AobakeVertexAo,
    name: *const c_char,
) -> i64 {
    // SAFETY: forwarded from the caller.
    let Some(h) = (unsafe { handle(ao) }) else {
        return -1;
    };
    if name.is_null() {
        fail("name is NULL");
        return -1;
    }
    // SAFETY: the caller passes a NUL-terminated string.
    let Ok(name) = unsafe { CStr::from_ptr(name) }.to_str() else {
        fail("the name is not UTF-8");
        return -1;
    };
    match h.node(name) {
        Some(n) => n as i64,
        None => {
            fail(format!("the rig has no node named {name:?}"));
            -1
        }
    }
}

/// Writes node `node`'s rest transform to `out`; `false` for a node the
/// rig does not have.
///
/// # Safety
/// `ao` must be NULL or a live handle; `out` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_rest(
    ao: *const AobakeVertexAo,
    node: usize,
    out: *mut AobakeTransform,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(h) = (unsafe { handle(ao) }) else {
        return false;
    };
    let Some(n) = h.skeleton().nodes.get(node) else {
        fail(format!("node {node} of {}", h.skeleton().nodes.len()));
        return false;
    };
    // SAFETY: the caller passes NULL or a writable transform.
    match unsafe { out.as_mut() } {
        Some(out) => {
            *out = n.rest.into();
            true
        }
        None => {
            fail("out is NULL");
            false
        }
    }
}

/// Sets node `node`'s local transform for the next weights or
/// evaluation. `false`, and nothing changed, for a node the rig does not
/// have or a transform that is not finite.
///
/// # Safety
/// `ao` must be NULL or a live handle; `local` NULL or readable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_set_local(
    ao: *mut AobakeVertexAo,
    node: usize,
    local: *const AobakeTransform,
) -> bool {
    // SAFETY: the caller passes NULL or a live handle, used by one thread.
    let Some(h) = (unsafe { ao.as_mut() }).map(|h| &mut h.0) else {
        fail("the handle is NULL");
        return false;
    };
    // SAFETY: the caller passes NULL or a readable transform.
    let Some(t) = (unsafe { local.as_ref() }) else {
        fail("local is NULL");
        return false;
    };
    let local = Transform {
        translation: Vec3::from_array(t.translation),
        rotation: Quat::from_array(t.rotation),
        scale: Vec3::from_array(t.scale),
    };
    if !(local.translation.is_finite() && local.rotation.is_finite() && local.scale.is_finite()) {
        fail(format!("node {node}'s transform is not finite"));
        return false;
    }
    if local.rotation.length_squared() == 0.0 {
        fail(format!("node {node}'s rotation is the zero quaternion"));
        return false;
    }
    if !h.set_local(node, local) {
        fail(format!("node {node} of {}", h.skeleton().nodes.len()));
        return false;
    }
    true
}

/// Puts every node back at its rest transform.
///
/// # Safety
/// `ao` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_reset(ao: *mut AobakeVertexAo) {
    // SAFETY: the caller passes NULL or a live handle, used by one thread.
    if let Some(h) = unsafe { ao.as_mut() } {
        h.0.reset();
    }
}

/// Copies `values` to `len` floats at `out` if the lengths agree.
///
/// # Safety
/// `out` must be NULL or point to `len` writable floats.
unsafe fn fill(values: &[f32], out: *mut f32, len: usize, what: &str) -> bool {
    if out.is_null() && !values.is_empty() {
        fail(format!(
            "{what} is NULL: it must hold {} floats",
            values.len()
        ));
        return false;
    }
    if len != values.len() {
        fail(format!(
            "{what}: {} values to write, the buffer holds {len}",
            values.len()
        ));
        return false;
    }
    if values.is_empty() {
        return true;
    }
    // SAFETY: the caller promises `len` writable floats at `out`, which is
    // not NULL, and `len` is the source's length.
    unsafe { std::ptr::copy_nonoverlapping(values.as_ptr(), out, len) };
    true
}

/// Writes the current pose's weights (`aobake_vertex_ao_weight_count` of
/// them) to `out`; `false` if `len` is not that count.
///
/// # Safety
/// `ao` must be NULL or a live handle; `out` NULL or `len` writable
/// floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_weights(
    ao: *const AobakeVertexAo,
    out: *mut f32,
    len: usize,
) -> bool {
    // SAFETY: forwarded from the caller.
    match unsafe { handle(ao) } {
        // SAFETY: forwarded from the caller.
        Some(h) => unsafe { fill(&h.weights(), out, len, "weights") },
        None => false,
    }
}

/// Writes every vertex's AO in the current pose (0 open … 1 blocked;
/// `aobake_vertex_ao_vertices` of them) to `out`; `false` if `len` is not
/// that count.
///
/// # Safety
/// `ao` must be NULL or a live handle; `out` NULL or `len` writable
/// floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_evaluate(
    ao: *const AobakeVertexAo,
    out: *mut f32,
    len: usize,
) -> bool {
    // SAFETY: forwarded from the caller.
    match unsafe { handle(ao) } {
        // SAFETY: forwarded from the caller.
        Some(h) => unsafe { fill(&h.evaluate(), out, len, "evaluate") },
        None => false,
    }
}

/// A cubemap asset. Opaque to C.
#[derive(Debug)]
pub struct AobakeCubemap(CubemapModel);

/// A grid asset. Opaque to C.
#[derive(Debug)]
pub struct AobakeGrid(GridModel);

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
            Asset::Cubemap { model, .. } => Some(AobakeCubemap(model)),
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

/// The baked clip's duration in seconds (the cycle), 0 for NULL.
///
/// # Safety
/// `cubemap` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_cubemap_duration(cubemap: *const AobakeCubemap) -> f32 {
    // SAFETY: the caller passes NULL or a live handle.
    unsafe { cubemap.as_ref() }.map_or(0.0, |c| c.0.layout.duration)
}

/// Writes the occlusion the character casts at `count` points (`3 ·
/// count` floats, x y z, in the character's space as baked) at `seconds`
/// of its clip to `out` (`count` floats). `false` on NULL.
///
/// # Safety
/// `cubemap` must be NULL or a live handle; `points` NULL or `3 · count`
/// readable floats; `out` NULL or `count` writable floats.
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
    // SAFETY: the caller passes NULL or a live handle.
    let Some(c) = (unsafe { cubemap.as_ref() }) else {
        fail("the handle is NULL");
        return false;
    };
    // SAFETY: forwarded from the caller.
    let Some(points) = (unsafe { floats(points, count, 3, "points") }) else {
        return false;
    };
    let phase = c.0.layout.phase(seconds);
    let values: Vec<f32> = points
        .chunks_exact(3)
        .map(|p| look(&c.0, Vec3::from_slice(p), phase))
        .collect();
    // SAFETY: forwarded from the caller.
    unsafe { fill(&values, out, count, "occlusion") }
}

/// `count · width` floats at `data`, or NULL's error.
///
/// # Safety
/// `data` must be NULL or point to `count · width` readable floats.
unsafe fn floats<'a>(
    data: *const f32,
    count: usize,
    width: usize,
    what: &str,
) -> Option<&'a [f32]> {
    if data.is_null() {
        fail(format!("{what} is NULL"));
        return None;
    }
    let Some(len) = count.checked_mul(width) else {
        fail(format!("{what}: {count} items overflow"));
        return None;
    };
    // SAFETY: the caller promises `count · width` readable floats.
    Some(unsafe { std::slice::from_raw_parts(data, len) })
}

/// Reads a grid asset from `len` bytes at `bytes`; NULL on failure.
///
/// # Safety
/// `bytes` must point to `len` readable bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_open(bytes: *const u8, len: usize) -> *mut AobakeGrid {
    // SAFETY: forwarded from the caller.
    unsafe {
        open(bytes, len, "grid", |a| match a {
            Asset::Grid { model, .. } => Some(AobakeGrid(model)),
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

/// Parts (rigid bodies with a grid each), 0 for NULL.
///
/// # Safety
/// `grid` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_part_count(grid: *const AobakeGrid) -> usize {
    // SAFETY: the caller passes NULL or a live handle.
    unsafe { grid.as_ref() }.map_or(0, |g| g.0.parts.len())
}

/// Matrices the palette must hold: the highest joint a part follows, plus
/// one (0 for NULL).
///
/// # Safety
/// `grid` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_grid_palette_len(grid: *const AobakeGrid) -> usize {
    // SAFETY: the caller passes NULL or a live handle.
    unsafe { grid.as_ref() }.map_or(0, |g| {
        g.0.parts.iter().map(|p| p.joint + 1).max().unwrap_or(0)
    })
}

/// A grid lookup's checked inputs: the parts posed and each receiver's
/// point, normal and part.
struct GridReceivers {
    poses: Vec<PartPose>,
    receivers: Vec<(Vec3, Vec3, Option<usize>)>,
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
) -> Option<(&'a AobakeGrid, GridReceivers)> {
    // SAFETY: the caller passes NULL or a live handle.
    let Some(g) = (unsafe { grid.as_ref() }) else {
        fail("the handle is NULL");
        return None;
    };
    if let Err(e) = g.0.check_palette(palette_len) {
        fail(e.to_string());
        return None;
    }
    // SAFETY: forwarded from the caller.
    let (Some(palette), Some(points), Some(normals)) = (unsafe {
        (
            floats(palette, palette_len, 16, "palette"),
            floats(points, count, 3, "points"),
            floats(normals, count, 3, "normals"),
        )
    }) else {
        return None;
    };
    let own: Vec<Option<usize>> = if parts.is_null() {
        vec![None; count]
    } else {
        // SAFETY: the caller promises `count` readable part indices.
        let parts = unsafe { std::slice::from_raw_parts(parts, count) };
        let n = g.0.parts.len();
        if let Some(bad) = parts.iter().find(|&&k| k >= n as i64 || k < -1) {
            fail(format!("part {bad} of {n}"));
            return None;
        }
        parts.iter().map(|&k| usize::try_from(k).ok()).collect()
    };
    let palette: Vec<Mat4> = palette
        .chunks_exact(16)
        .map(|m| Mat4::from_cols_slice(m))
        .collect();
    let receivers = points
        .chunks_exact(3)
        .zip(normals.chunks_exact(3))
        .zip(own)
        .map(|((p, n), k)| (Vec3::from_slice(p), Vec3::from_slice(n), k))
        .collect();
    Some((
        g,
        GridReceivers {
            poses: g.0.poses(&palette),
            receivers,
        },
    ))
}

/// Writes the occlusion every part casts at `count` receivers to `out`
/// (`count` floats), the parts posed by the frame's skinning `palette`
/// (`palette_len` column-major 4 × 4 matrices, world from bind, as the
/// renderer skins with). `points` and `normals` are `3 · count` floats
/// (world space, unit normals); `parts` is NULL (no receiver is on a
/// part, as the ground) or `count` part indices, -1 for none: a receiver
/// on a part takes its own part by the self-occlusion rule. These are
/// the paper's grids alone; [`aobake_grid_ao`] adds the asset's static
/// base.
///
/// # Safety
/// `grid` must be NULL or a live handle; each pointer NULL or holding the
/// counts above.
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
    let values: Vec<f32> = r
        .receivers
        .iter()
        .map(|&(p, n, k)| g.0.occlusion(&r.poses, p, n, k, Terms::All))
        .collect();
    // SAFETY: forwarded from the caller.
    unsafe { fill(&values, out, count, "occlusion") }
}

/// Writes the AO an engine shows at `count` receivers to `out`: as
/// [`aobake_grid_occlusion`], plus the asset's static base when it has
/// one (`gain · grids + offset`, clamped; see `docs/engines.md`).
/// `receivers` is NULL (no receiver takes an offset) or `count` values:
/// the receiver's vertex index in the character (its offset; with a
/// static base, an index past the character's vertices is refused), -1
/// for a point of the ground (the base's ground texture), -2 for any
/// other surface.
///
/// # Safety
/// As [`aobake_grid_occlusion`]; `receivers` NULL or holding `count`
/// values.
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
    let kinds: Vec<i64> = if receivers.is_null() {
        vec![-2; count]
    } else {
        // SAFETY: the caller promises `count` readable values.
        unsafe { std::slice::from_raw_parts(receivers, count) }.to_vec()
    };
    // With a static base, a vertex's offset is its own: an index past the
    // character's vertices is a caller's mistake, not offset 0.
    let vertices = g.0.base.as_ref().map(|b| b.vertex_offsets.len());
    let mut values = Vec::with_capacity(count);
    for (i, (&(p, n, part), &kind)) in r.receivers.iter().zip(&kinds).enumerate() {
        let receiver = match kind {
            -1 => Receiver::Ground,
            -2 => Receiver::Other,
            index => match usize::try_from(index) {
                Ok(index) if vertices.is_some_and(|v| index >= v) => {
                    fail(format!(
                        "receiver {i}: vertex {index} of {} (the character the asset was baked for)",
                        vertices.unwrap_or_default()
                    ));
                    return false;
                }
                Ok(index) => Receiver::Vertex { index, part },
                Err(_) => {
                    fail(format!("receiver kind {index}: a vertex index, -1 or -2"));
                    return false;
                }
            },
        };
        values.push(g.0.ao(&r.poses, p, n, receiver));
    }
    // SAFETY: forwarded from the caller.
    unsafe { fill(&values, out, count, "occlusion") }
}
