//! Texel assets (texel-linear): the vertex methods' model over the texels
//! of a UV atlas. The pose and its weights go through the vertex
//! functions on [`aobake_texel_pose`]'s handle (their "vertices" are the
//! texels); the basis textures, the atlas's mesh and a CPU sampler are
//! here (`docs/engines.md`, "Texel assets").

use std::sync::OnceLock;

use aobake_runtime::{
    Asset,
    method::{
        texel::{TexelModel, bilinear},
        vertex::VertexAo,
    },
};

use crate::{
    AobakeVertexAo, copy_array, fail, finite_floats, free, live, open, out_floats, packed, put,
};

/// A texel asset: its model posed through a vertex handle, its atlas, and
/// its basis textures once asked for. Opaque to C.
#[derive(Debug)]
pub struct AobakeTexel {
    pose: AobakeVertexAo,
    model: TexelModel,
    basis: OnceLock<Result<Vec<Vec<f32>>, String>>,
}

/// Reads a texel asset from `len` bytes at `bytes` (copied). NULL on
/// failure: not an asset, damaged, or not a texel method.
///
/// # Safety
/// `bytes` must point to `len` readable bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_texel_open(bytes: *const u8, len: usize) -> *mut AobakeTexel {
    // SAFETY: forwarded from the caller.
    unsafe {
        open(bytes, len, "texel", |a| match a {
            Asset::Texel { model, header } => {
                let ao = VertexAo::new(model.model.clone(), *header).ok()?;
                Some(AobakeTexel {
                    pose: AobakeVertexAo::new(ao),
                    model: *model,
                    basis: OnceLock::new(),
                })
            }
            _ => None,
        })
    }
}

/// Frees a handle from `aobake_texel_open` (NULL is ignored); the handle
/// `aobake_texel_pose` gave goes with it.
///
/// # Safety
/// `texel` must be NULL or a live handle not yet freed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_texel_free(texel: *mut AobakeTexel) {
    // SAFETY: forwarded from the caller.
    unsafe { free(texel) }
}

/// The handle that poses the texel asset: `aobake_vertex_ao_node`,
/// `aobake_vertex_ao_set_local`, `aobake_vertex_ao_reset`,
/// `aobake_vertex_ao_weight_count` and `aobake_vertex_ao_weights` on it
/// set the pose and give its weights, one per basis texture; its
/// "vertices" are the atlas's texels. Valid until `aobake_texel_free`;
/// never freed on its own. NULL for a NULL handle.
///
/// # Safety
/// `texel` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_texel_pose(texel: *mut AobakeTexel) -> *mut AobakeVertexAo {
    if texel.is_null() {
        fail("the handle is NULL");
        return std::ptr::null_mut();
    }
    // SAFETY: the caller passes a live handle, which is not NULL; the
    // field's place is taken without making a reference, so the pointer
    // and the handle's `const` calls may be used in any order.
    unsafe { &raw mut (*texel).pose }
}

/// Writes the atlas's size in texels to `width` and `height`: each basis
/// texture's. `false` for NULL.
///
/// # Safety
/// `texel` must be NULL or a live handle; `width` and `height` NULL or
/// writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_texel_atlas_size(
    texel: *const AobakeTexel,
    width: *mut u32,
    height: *mut u32,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(t) = (unsafe { live(texel) }) else {
        return false;
    };
    let a = &t.model.atlas;
    // SAFETY: forwarded from the caller.
    unsafe { put(width, a.width) && put(height, a.height) }
}

/// Writes basis texture `layer` (one per weight, in weight order; width ×
/// height floats, row 0 at v = 0, dilated past the charts) to `out`;
/// `false` for a layer past the weights, a `len` other than width ×
/// height, or a model without textures (sparse rows).
///
/// # Safety
/// `texel` must be NULL or a live handle; `out` NULL or `len` writable
/// floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_texel_basis(
    texel: *const AobakeTexel,
    layer: usize,
    out: *mut f32,
    len: usize,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(t) = (unsafe { live(texel) }) else {
        return false;
    };
    let Some(basis) = packed(&t.basis, || t.model.basis().map_err(|e| e.to_string())) else {
        return false;
    };
    let Some(image) = basis.get(layer) else {
        fail(format!(
            "layer {layer}: the model has {} basis textures",
            basis.len()
        ));
        return false;
    };
    // SAFETY: forwarded from the caller.
    let Some(out) = (unsafe { out_floats(out, len, image.len(), "basis texels") }) else {
        return false;
    };
    out.copy_from_slice(image);
    true
}

/// `aobake_texel_atlas_words`' arrays: per atlas vertex, the vertex of
/// aobake's order it was made from (its position, normal and skin).
pub const AOBAKE_TEXEL_ATLAS_VERTEX_OF: u32 = 0;
/// The character's triangles in its order, three atlas vertices each.
pub const AOBAKE_TEXEL_ATLAS_TRIANGLES: u32 = 1;
/// Per model column (texel), its place in the textures: row × width +
/// column.
pub const AOBAKE_TEXEL_ATLAS_TEXELS: u32 = 2;

/// Sets `*words` to the length of the atlas's array `which`
/// (`AOBAKE_TEXEL_ATLAS_*`) and copies it to `out` unless `out` is NULL
/// (then `len` must be at least `*words`): the mesh an engine draws the
/// character with to sample the textures, its UVs from
/// `aobake_texel_atlas_uvs`.
///
/// # Safety
/// `texel` must be NULL or a live handle; `out` NULL or `len` writable
/// words; `words` a writable `size_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_texel_atlas_words(
    texel: *const AobakeTexel,
    which: u32,
    out: *mut u32,
    len: usize,
    words: *mut usize,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(t) = (unsafe { live(texel) }) else {
        return false;
    };
    let a = &t.model.atlas;
    let triangles = a.triangles.as_flattened();
    let named: [(u32, &str, &[u32]); 3] = [
        (
            AOBAKE_TEXEL_ATLAS_VERTEX_OF,
            "AOBAKE_TEXEL_ATLAS_VERTEX_OF",
            &a.xref,
        ),
        (
            AOBAKE_TEXEL_ATLAS_TRIANGLES,
            "AOBAKE_TEXEL_ATLAS_TRIANGLES",
            triangles,
        ),
        (
            AOBAKE_TEXEL_ATLAS_TEXELS,
            "AOBAKE_TEXEL_ATLAS_TEXELS",
            &a.texels,
        ),
    ];
    // SAFETY: forwarded from the caller.
    unsafe { copy_array(which, &named, out, len, words) }
}

/// Atlas vertices (`AOBAKE_TEXEL_ATLAS_VERTEX_OF`'s length); 0 for NULL.
///
/// # Safety
/// `texel` must be NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_texel_atlas_vertex_count(texel: *const AobakeTexel) -> usize {
    // SAFETY: forwarded from the caller.
    unsafe { live(texel) }.map_or(0, |t| t.model.atlas.xref.len())
}

/// Writes each atlas vertex's texture coordinate (u, v in [0, 1]; two
/// floats a vertex) to `out`; `false` if `len` is not twice
/// `aobake_texel_atlas_vertex_count`.
///
/// # Safety
/// `texel` must be NULL or a live handle; `out` NULL or `len` writable
/// floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_texel_atlas_uvs(
    texel: *const AobakeTexel,
    out: *mut f32,
    len: usize,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(t) = (unsafe { live(texel) }) else {
        return false;
    };
    let uvs = t.model.atlas.uvs.as_flattened();
    // SAFETY: forwarded from the caller.
    let Some(out) = (unsafe { out_floats(out, len, uvs.len(), "UVs") }) else {
        return false;
    };
    out.copy_from_slice(uvs);
    true
}

/// The AO at `count` texture coordinates (`uvs`, two floats each) in the
/// pose set on `aobake_texel_pose`'s handle, written to `out` (`count`
/// floats): the basis textures weighted by the pose's weights, filtered
/// bilinearly (clamp to edge) and clamped to [0, 1], what the shader
/// `texel_ao` computes. A reference for an engine's GPU path, not a
/// frame's work: it builds the pose's whole texture.
///
/// # Safety
/// `texel` must be NULL or a live handle; `uvs` NULL or `2 · count`
/// readable floats; `out` NULL or `len` writable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn aobake_texel_sample(
    texel: *const AobakeTexel,
    uvs: *const f32,
    count: usize,
    out: *mut f32,
    len: usize,
) -> bool {
    // SAFETY: forwarded from the caller.
    let Some(t) = (unsafe { live(texel) }) else {
        return false;
    };
    // SAFETY: forwarded from the caller.
    let Some(uvs) = (unsafe { finite_floats(uvs, count, 2, "uvs") }) else {
        return false;
    };
    // SAFETY: forwarded from the caller.
    let Some(out) = (unsafe { out_floats(out, len, count, "AO values") }) else {
        return false;
    };
    let mut weights = vec![0.0; t.pose.ao().weight_count()];
    t.pose
        .ao()
        .weights_into(&mut t.pose.scratch(), &mut weights);
    let image = match t.model.texture(&weights) {
        Ok(image) => image,
        Err(e) => {
            fail(e.to_string());
            return false;
        }
    };
    let a = &t.model.atlas;
    for (o, uv) in out.iter_mut().zip(uvs.chunks_exact(2)) {
        *o = bilinear(&image, a.width, a.height, [uv[0], uv[1]]).clamp(0.0, 1.0);
    }
    true
}
