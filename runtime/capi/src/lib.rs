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
//! A texel asset (texel-linear) opens with `aobake_texel_open`: its pose
//! is set and its weights read through the vertex functions on the
//! handle `aobake_texel_pose` gives, and `aobake_texel_basis` and
//! `aobake_texel_atlas_*` give the textures and the atlas's mesh the
//! shader `texel_ao` samples (`aobake_texel_sample` does it on the CPU).
//!
//! And the lookups in space: `aobake_cubemap_*` (Kroon's cubemaps: the
//! occlusion a character casts at points, at a time of its clip) and
//! `aobake_grid_*` (Malmer et al.'s grids: the occlusion rigid parts cast
//! at receivers, given the frame's skinning palette).
//!
//! Every family also gives its GPU form, the arrays the shaders in
//! `shaders/` read (`*_gpu_words`, sized by a first call) and their
//! constant parameters, for engines that evaluate on the GPU.
//! `aobake_rt_abi_version` lets a plugin check the library against the
//! header it was compiled with.
//!
//! Errors: a function that can fail returns `false` or `NULL`, and
//! `aobake_last_error` gives the reason, on the calling thread. A call
//! that changes a handle (`set_local`, `reset`, `free`) has it to itself;
//! calls that take it `const` may come from several threads at once;
//! separate handles are independent.

use std::{
    cell::RefCell,
    ffi::{CString, c_char},
    sync::OnceLock,
};

use aobake_runtime::{Asset, PrimitiveSpan};

mod cubemap;
mod grid;
mod texel;
mod vertex;

pub use cubemap::*;
pub use grid::*;
pub use texel::*;
pub use vertex::*;

thread_local! {
    static LAST_ERROR: RefCell<Option<CString>> = const { RefCell::new(None) };
}

fn fail(message: impl Into<String>) {
    let c = c_string(&message.into());
    LAST_ERROR.with(|e| *e.borrow_mut() = Some(c));
}

/// `text` as a C string, each NUL in it a space (a name with a NUL is
/// given back with a space there, which finds no node by that name).
fn c_string(text: &str) -> CString {
    CString::new(text.replace('\0', " ")).unwrap_or_default()
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

/// The handle `handle` points to, or NULL's error.
///
/// # Safety
/// `handle` must be NULL or a live handle.
unsafe fn live<'a, T>(handle: *const T) -> Option<&'a T> {
    // SAFETY: the caller passes NULL or a live handle.
    let h = unsafe { handle.as_ref() };
    if h.is_none() {
        fail("the handle is NULL");
    }
    h
}

/// Writes `value` to `out`, or NULL's error.
///
/// # Safety
/// `out` must be NULL or writable.
unsafe fn put<T>(out: *mut T, value: T) -> bool {
    // SAFETY: the caller passes NULL or a writable `T`.
    match unsafe { out.as_mut() } {
        Some(out) => {
            *out = value;
            true
        }
        None => {
            fail("out is NULL");
            false
        }
    }
}

/// Where one glTF primitive's vertices are among an asset's: vertex
/// `first + i` of the asset is vertex `i` (in accessor order) of primitive
/// `primitive` of mesh `mesh`, as node `node` instances it (indices of the
/// glTF file the asset was baked from, as the asset says: check them
/// against the file before indexing with them). For an engine that
/// imports the glTF its own way and so orders its vertices its own way.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AobakePrimitive {
    /// The glTF node that instances the mesh.
    pub node: usize,
    /// The glTF mesh.
    pub mesh: usize,
    /// The primitive's index in the mesh.
    pub primitive: usize,
    /// Its first vertex among the asset's.
    pub first: usize,
    /// Its vertices.
    pub count: usize,
}

/// Writes span `i` of `spans` to `out`, or the reason it cannot: past
/// the spans (an asset before format 1.6 has none), or `out` NULL.
///
/// # Safety
/// `out` must be NULL or writable.
unsafe fn put_primitive(spans: &[PrimitiveSpan], i: usize, out: *mut AobakePrimitive) -> bool {
    let Some(s) = spans.get(i) else {
        fail(if spans.is_empty() {
            "the asset lists no primitives (written before asset format 1.6: bake it again)"
                .to_owned()
        } else {
            format!("primitive {i} of {}", spans.len())
        });
        return false;
    };
    // SAFETY: forwarded from the caller.
    unsafe { put(out, AobakePrimitive::from(*s)) }
}

impl From<PrimitiveSpan> for AobakePrimitive {
    fn from(s: PrimitiveSpan) -> Self {
        Self {
            node: s.node,
            mesh: s.mesh,
            primitive: s.primitive,
            first: s.first,
            count: s.count,
        }
    }
}

/// A handle's GPU form, packed by `pack` on first use and kept (an
/// engine asks for each array twice: its size, then its words), or why
/// it has none.
fn packed<G>(
    cell: &OnceLock<Result<G, String>>,
    pack: impl FnOnce() -> Result<G, String>,
) -> Option<&G> {
    match cell.get_or_init(pack) {
        Ok(gpu) => Some(gpu),
        Err(e) => {
            fail(e.clone());
            None
        }
    }
}

/// `want` writable floats at `out`, or the reason they are not: `out`
/// NULL (with `want` above 0) or `len` not `want`.
///
/// # Safety
/// `out` must be NULL or point to `len` writable floats.
unsafe fn out_floats<'a>(
    out: *mut f32,
    len: usize,
    want: usize,
    what: &str,
) -> Option<&'a mut [f32]> {
    if len != want {
        fail(format!(
            "out: the {what} are {want} floats, the buffer holds {len}"
        ));
        return None;
    }
    if want == 0 {
        return Some(&mut []);
    }
    if out.is_null() {
        fail(format!("out is NULL: the {what} are {want} floats"));
        return None;
    }
    // SAFETY: the caller promises `len` writable floats at `out`, which is
    // not NULL, and `len` is `want`.
    Some(unsafe { std::slice::from_raw_parts_mut(out, want) })
}

/// `count · width` floats at `data`, or the reason they are not: NULL,
/// or a count that overflows.
///
/// # Safety
/// `data` must be NULL or point to `count · width` readable floats.
unsafe fn floats<'a>(
    data: *const f32,
    count: usize,
    width: usize,
    what: &str,
) -> Option<&'a [f32]> {
    let Some(len) = count.checked_mul(width) else {
        fail(format!("{what}: {count} items overflow"));
        return None;
    };
    if len == 0 {
        return Some(&[]);
    }
    if data.is_null() {
        fail(format!("{what} is NULL"));
        return None;
    }
    // SAFETY: the caller promises `count · width` readable floats at
    // `data`, which is not NULL.
    Some(unsafe { std::slice::from_raw_parts(data, len) })
}

/// [`floats`], each a finite number: an item with a NaN or an infinity
/// is refused, named by its index.
///
/// # Safety
/// As [`floats`].
unsafe fn finite_floats<'a>(
    data: *const f32,
    count: usize,
    width: usize,
    what: &str,
) -> Option<&'a [f32]> {
    // SAFETY: forwarded from the caller.
    let values = unsafe { floats(data, count, width, what) }?;
    if let Some(bad) = values.iter().position(|x| !x.is_finite()) {
        fail(format!("{what}: item {} is not finite", bad / width));
        return None;
    }
    Some(values)
}

/// Sets `*words` to `array`'s length and copies it to `out` unless `out`
/// is NULL (then `len` must be at least the length; `*words` is set
/// even when it is not): the two calls of every `*_gpu_words` function,
/// sizing then filling.
///
/// # Safety
/// `out` must be NULL or point to `len` writable words; `words` NULL or a
/// writable `size_t`.
unsafe fn copy_words(array: &[u32], out: *mut u32, len: usize, words: *mut usize) -> bool {
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

/// [`copy_words`] for array `which` of a GPU form: `arrays` holds each
/// array's constant, its name and its words. An unknown `which` is
/// refused, naming the arrays there are.
///
/// # Safety
/// As [`copy_words`].
unsafe fn copy_array(
    which: u32,
    arrays: &[(u32, &str, &[u32])],
    out: *mut u32,
    len: usize,
    words: *mut usize,
) -> bool {
    match arrays.iter().find(|(k, _, _)| *k == which) {
        // SAFETY: forwarded from the caller.
        Some((_, _, array)) => unsafe { copy_words(array, out, len, words) },
        None => {
            let known: Vec<String> = arrays
                .iter()
                .map(|(k, name, _)| format!("{name} ({k})"))
                .collect();
            fail(format!("array {which}: {}", known.join(", ")));
            false
        }
    }
}

/// The version of the C ABI this header describes. It changes when a
/// function, constant or struct of the header changes incompatibly (new
/// functions alone do not change it), so a plugin checks at load that
/// `aobake_rt_abi_version() == AOBAKE_RT_ABI_VERSION`: a library that
/// passes means what the header says by every function both have (one
/// older than the header may lack functions added since: the loader
/// names them).
pub const AOBAKE_RT_ABI_VERSION: u32 = 1;

/// The C ABI version of the loaded library (`AOBAKE_RT_ABI_VERSION` of
/// the header it was built with).
#[unsafe(no_mangle)]
pub extern "C" fn aobake_rt_abi_version() -> u32 {
    AOBAKE_RT_ABI_VERSION
}

/// The loaded library's version (aobake's release, as "0.1.0"), a static
/// NUL-terminated string.
#[unsafe(no_mangle)]
pub extern "C" fn aobake_rt_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}
