//! Vertex-method assets (static average, vertex-linear,
//! vertex-clustered): open, pose by node name, weights or per-vertex AO,
//! and the coefficients' GPU form.

use std::{
    ffi::{CStr, CString, c_char},
    sync::{Mutex, MutexGuard, OnceLock, PoisonError},
};

use aobake_runtime::{
    Asset,
    method::vertex::{
        PoseScratch, VertexAo,
        form::{FormRef, GpuArrays},
    },
    rig::{Node, Transform},
};
use glam::{Quat, Vec3};

use crate::{
    AobakePrimitive, c_string, copy_array, fail, free, live, open, out_floats, packed, put,
    put_primitive,
};

/// A vertex-method asset (static average, vertex-linear or
/// vertex-clustered), its rig and the pose being set, the GPU form once
/// asked for, the per-pose step's buffers (behind a lock: the weights and
/// the evaluation take a `const` handle, which several threads may share
/// while none sets a node), and the rig's node names as C strings.
/// Opaque to C.
#[derive(Debug)]
pub struct AobakeVertexAo(
    VertexAo,
    OnceLock<Result<GpuArrays, String>>,
    Mutex<PoseScratch>,
    Vec<CString>,
);

impl AobakeVertexAo {
    /// The handle of a posable model, its node names ready for C.
    pub(crate) fn new(ao: VertexAo) -> Self {
        let names = ao
            .skeleton()
            .nodes
            .iter()
            .map(|n| c_string(n.name.as_deref().unwrap_or_default()))
            .collect();
        Self(ao, OnceLock::new(), Mutex::default(), names)
    }

    /// The posable model.
    pub(crate) fn ao(&self) -> &VertexAo {
        &self.0
    }

    /// The per-pose step's buffers (a lock no call can poison: a panic
    /// does not cross the C ABI).
    pub(crate) fn scratch(&self) -> MutexGuard<'_, PoseScratch> {
        self.2.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

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
            Asset::Vertex(ao) => Some(AobakeVertexAo::new(*ao)),
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
    // SAFETY: forwarded from the caller.
    unsafe { live(ao) }.map(|h| &h.0)
}

/// Node `node` of the handle's rig; `None` for NULL, or past the rig
/// (with the reason left for `aobake_last_error`).
///
/// # Safety
/// `ao` must be NULL or a live handle.
unsafe fn rig_node<'a>(ao: *const AobakeVertexAo, node: usize) -> Option<&'a Node> {
    // SAFETY: forwarded from the caller.
    let nodes = &unsafe { handle(ao) }?.skeleton().nodes;
    let found = nodes.get(node);
    if found.is_none() {
        fail(format!("node {node} of {}", nodes.len()));
    }
    found
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

/// The glTF primitives whose vertices the asset's are, in order (0 for
/// NULL, and for an asset written before format 1.6).
///
/// # Safety
/// `ao` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_primitive_count(ao: *const AobakeVertexAo) -> usize {
    // SAFETY: forwarded from the caller.
    unsafe { handle(ao) }.map_or(0, |a| a.header().primitives.len())
}

/// Writes primitive `i` (below `aobake_vertex_ao_primitive_count`) to
/// `out`; `false` for NULL or past the count.
///
/// # Safety
/// `ao` must be NULL or a live handle; `out` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_primitive(
    ao: *const AobakeVertexAo,
    i: usize,
    out: *mut AobakePrimitive,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(a) = (unsafe { handle(ao) }) else {
        return false;
    };
    // SAFETY: forwarded from the caller.
    unsafe { put_primitive(&a.header().primitives, i, out) }
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
/// (`AOBAKE_GPU_BLOCK_WORDS` words each, `vertex_ao.wgsl`'s `BlockInfo`:
/// rows, columns, the first coefficient's offset in f16 elements, the
/// map's offset in `AOBAKE_GPU_MAPS` (0xffffffff: the columns are the
/// vertices), the first weight's index, three words of padding; a sparse
/// model's is one word of 0).
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
/// their translations; `docs/engines.md`; its `Params` are the vertices,
/// the blocks, and the dispatch's row stride: `aobake_vertex_ao_gpu_params`).
/// Every array has one word at least, as a GPU binding must: an array the
/// model does not use (a sparse model's blocks, a dense model's sparse
/// rows) is one word of 0, bound all the same. Sets `*words` to the length in
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
    // SAFETY: forwarded from the caller.
    let Some(arrays) = (unsafe { vertex_gpu(ao) }) else {
        return false;
    };
    // Every array has a word at least, as GPU bindings must: a sparse
    // model's blocks are one word of 0, as a dense model's unused sparse
    // rows are.
    let blocks: &[u32] = match arrays.blocks.as_flattened() {
        [] => &[0],
        words => words,
    };
    let named: [(u32, &str, &[u32]); 4] = [
        (AOBAKE_GPU_BLOCKS, "AOBAKE_GPU_BLOCKS", blocks),
        (
            AOBAKE_GPU_COEFFICIENTS,
            "AOBAKE_GPU_COEFFICIENTS",
            &arrays.coefficients,
        ),
        (AOBAKE_GPU_MAPS, "AOBAKE_GPU_MAPS", &arrays.maps),
        (
            AOBAKE_GPU_SPARSE_ROWS,
            "AOBAKE_GPU_SPARSE_ROWS",
            &arrays.sparse_rows,
        ),
    ];
    // SAFETY: forwarded from the caller.
    unsafe { copy_array(which, &named, out, len, words) }
}

/// The compute evaluator's `Params` uniform (`shaders/wgsl/vertex_ao.wgsl`),
/// field for field and byte for byte: `aobake_vertex_ao_gpu_params` fills
/// the asset's fields and leaves the dispatch's (`row_stride`) at 0 for
/// the engine; it is then copied whole into the uniform buffer (binding 0).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AobakeVertexGpuParams {
    /// Vertices to evaluate.
    pub vertices: u32,
    /// Dense blocks (`AOBAKE_GPU_BLOCKS`' words ÷ `AOBAKE_GPU_BLOCK_WORDS`;
    /// 0 for a sparse model).
    pub blocks: u32,
    /// The engine's: vertices per row of the dispatch grid (workgroups in
    /// x × 64).
    pub row_stride: u32,
    /// Padding (0).
    pub pad: u32,
}

/// The vertex-stage evaluator's `VsParams` uniform
/// (`shaders/wgsl/vertex_ao_vs.wgsl`, binding 0), field for field and
/// byte for byte: `aobake_vertex_ao_vs_params` fills the asset's fields
/// and leaves the engine's (`width`, and the harness's target size) at 0.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AobakeVertexVsParams {
    /// Vertices to evaluate.
    pub vertices: u32,
    /// Dense blocks (0 for a sparse model).
    pub blocks: u32,
    /// 1 for a sparse model (CSR rows), 0 for dense blocks.
    pub sparse: u32,
    /// The engine's: texels per row of every data texture (the arrays as
    /// R32Uint textures, word i at (i mod width, i div width); aobake uses
    /// 2048, WebGL2's smallest MAX_TEXTURE_SIZE).
    pub width: u32,
    /// The harness's (`vs_main` of the shader's test): its target's width
    /// in pixels; an engine calling `vertex_ao` from its own vertex shader
    /// leaves it 0.
    pub target_width: u32,
    /// The harness's target height in pixels (0 likewise).
    pub target_height: u32,
    /// Padding (0).
    pub pad: [u32; 2],
}

/// Writes the compute evaluator's `Params` to `out`, `row_stride` at 0
/// for the engine to fill (`docs/engines.md`). `false` for NULL or a
/// model too large for 32-bit GPU indices.
///
/// # Safety
/// `ao` must be NULL or a live handle; `out` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_gpu_params(
    ao: *const AobakeVertexAo,
    out: *mut AobakeVertexGpuParams,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(arrays) = (unsafe { vertex_gpu(ao) }) else {
        return false;
    };
    let params = AobakeVertexGpuParams {
        vertices: arrays.vertices,
        blocks: arrays.blocks.len() as u32,
        row_stride: 0,
        pad: 0,
    };
    // SAFETY: the caller passes NULL or a writable struct.
    unsafe { put(out, params) }
}

/// Writes the vertex-stage evaluator's `VsParams` to `out`, `width` and
/// the harness's target size at 0 for the engine to fill. `false` for
/// NULL or a model too large for 32-bit GPU indices.
///
/// # Safety
/// `ao` must be NULL or a live handle; `out` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_vs_params(
    ao: *const AobakeVertexAo,
    out: *mut AobakeVertexVsParams,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(arrays) = (unsafe { vertex_gpu(ao) }) else {
        return false;
    };
    let params = AobakeVertexVsParams {
        vertices: arrays.vertices,
        blocks: arrays.blocks.len() as u32,
        sparse: u32::from(arrays.sparse),
        width: 0,
        target_width: 0,
        target_height: 0,
        pad: [0; 2],
    };
    // SAFETY: the caller passes NULL or a writable struct.
    unsafe { put(out, params) }
}

/// The GPU form of the model at `ao`, packed once per handle, or why
/// there is none (NULL, or too large for 32-bit GPU indices).
///
/// # Safety
/// `ao` must be NULL or a live handle.
unsafe fn vertex_gpu<'a>(ao: *const AobakeVertexAo) -> Option<&'a GpuArrays> {
    // SAFETY: forwarded from the caller.
    let h = unsafe { live(ao) }?;
    packed(&h.1, || {
        GpuArrays::new(h.0.model().form()).map_err(|e| format!("the model has no GPU form: {e}"))
    })
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

/// The name of node `node` (NUL-terminated UTF-8, valid until the handle
/// is freed; empty where the file names none; a NUL inside a name is given
/// as a space), or NULL past the rig (or for NULL): with [`aobake_vertex_ao_node_count`] and
/// [`aobake_vertex_ao_node_parent`], how an engine lists the rig to map
/// its own bones onto.
///
/// # Safety
/// `ao` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_node_name(
    ao: *const AobakeVertexAo,
    node: usize,
) -> *const c_char {
    // SAFETY: forwarded from the caller.
    let Some(h) = (unsafe { live(ao) }) else {
        return std::ptr::null();
    };
    match h.3.get(node) {
        Some(name) => name.as_ptr(),
        None => {
            fail(format!("node {node} of {}", h.3.len()));
            std::ptr::null()
        }
    }
}

/// Writes the parent of node `node` to `out`: its index, or -1 for a root.
/// `false` past the rig (or for NULL).
///
/// # Safety
/// `ao` must be NULL or a live handle; `out` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_node_parent(
    ao: *const AobakeVertexAo,
    node: usize,
    out: *mut i64,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(n) = (unsafe { rig_node(ao, node) }) else {
        return false;
    };
    let parent = n.parent.map_or(-1, |p| p as i64);
    // SAFETY: forwarded from the caller.
    unsafe { put(out, parent) }
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
    let Some(n) = (unsafe { rig_node(ao, node) }) else {
        return false;
    };
    // SAFETY: the caller passes NULL or a writable transform.
    unsafe { put(out, n.rest.into()) }
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

/// Writes the current pose's weights (`aobake_vertex_ao_weight_count` of
/// them) to `out`; `false` if `len` is not that count. Allocates nothing
/// once the handle has computed a pose.
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
    let Some(h) = (unsafe { live(ao) }) else {
        return false;
    };
    // SAFETY: forwarded from the caller.
    let Some(out) = (unsafe { out_floats(out, len, h.0.weight_count(), "weights") }) else {
        return false;
    };
    h.0.weights_into(&mut h.scratch(), out);
    true
}

/// Writes every vertex's AO in the current pose (0 open … 1 blocked;
/// `aobake_vertex_ao_vertices` of them) to `out`; `false` if `len` is not
/// that count. It writes straight into `out`, and once the handle has
/// computed a pose it allocates nothing, so a player's frame does not
/// touch the heap.
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
    let Some(h) = (unsafe { live(ao) }) else {
        return false;
    };
    // SAFETY: forwarded from the caller.
    let Some(out) = (unsafe { out_floats(out, len, h.0.vertices(), "AO values") }) else {
        return false;
    };
    h.0.evaluate_into(&mut h.scratch(), out);
    true
}
