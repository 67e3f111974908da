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
//! Errors: a function that can fail returns `false` or `NULL`, and
//! `aobake_last_error` gives the reason, on the calling thread. A handle
//! may be used from one thread at a time; separate handles are
//! independent.

use std::{
    cell::RefCell,
    ffi::{CStr, CString, c_char},
};

use aobake_runtime::{method::vertex::VertexAo, rig::Transform};
use glam::{Quat, Vec3};

/// A vertex-method asset (static average, vertex-linear or
/// vertex-clustered), its rig and the pose being set. Opaque to C.
#[derive(Debug)]
pub struct AobakeVertexAo(VertexAo);

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
    if bytes.is_null() {
        fail("bytes is NULL");
        return std::ptr::null_mut();
    }
    // SAFETY: the caller promises `len` readable bytes at `bytes`, which
    // is not NULL.
    let data = unsafe { std::slice::from_raw_parts(bytes, len) };
    match VertexAo::from_bytes(data) {
        Ok(ao) => Box::into_raw(Box::new(AobakeVertexAo(ao))),
        Err(e) => {
            fail(e.to_string());
            std::ptr::null_mut()
        }
    }
}

/// Frees a handle from `aobake_vertex_ao_open` (NULL is ignored).
///
/// # Safety
/// `ao` must be NULL or a handle from `aobake_vertex_ao_open` not yet
/// freed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_vertex_ao_free(ao: *mut AobakeVertexAo) {
    if !ao.is_null() {
        // SAFETY: the caller passes a live handle made by Box::into_raw.
        drop(unsafe { Box::from_raw(ao) });
    }
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
    if out.is_null() || len != values.len() {
        fail(format!(
            "{what}: {} values to write, the buffer holds {len}{}",
            values.len(),
            if out.is_null() { " (NULL)" } else { "" }
        ));
        return false;
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
