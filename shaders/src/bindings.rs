//! What an engine binds where: a table per run-time evaluator and target
//! language (`aobake export --shaders DIR` writes it beside the shaders as
//! `NAME.bindings.md`), so that a programmer reads set, binding, the name
//! the translation gave each resource, its type and what goes into it,
//! without reading naga's output.

use naga::{AddressSpace, ImageClass, ImageDimension, ScalarKind, TypeInner, VectorSize};

/// What goes into each resource of the run-time evaluators, by shader and
/// WGSL name (a test checks that every bound resource has its line).
pub fn what_to_bind(shader: &str, name: &str) -> Option<&'static str> {
    let vertex_ao_vs = shader == "vertex_ao_vs";
    Some(match (shader, name) {
        ("vertex_ao", "params") => {
            "`Params`: `AobakeVertexGpuParams` (`aobake_vertex_ao_gpu_params`), with `row_stride` set to the dispatch's workgroups in x × 64"
        }
        ("vertex_ao", "blocks") => {
            "`AOBAKE_GPU_BLOCKS`' words (`aobake_vertex_ao_gpu_words`): 8 per dense block (`BlockInfo`); one word of 0 for a sparse model"
        }
        ("vertex_ao", "coefficients") => {
            "`AOBAKE_GPU_COEFFICIENTS`' words: the f16 coefficients, two per word"
        }
        ("vertex_ao", "maps") => {
            "`AOBAKE_GPU_MAPS`' words: dense, the vertex-cluster maps; sparse, the `vertices + 1` row offsets"
        }
        ("vertex_ao", "weights") => {
            "the pose's weights as f32, per frame (`aobake_vertex_ao_weights`; `Model::weights` in Rust)"
        }
        ("vertex_ao", "ao") => {
            "the output: one f32 per vertex, its AO (0 open, 1 blocked), in aobake's vertex order"
        }
        ("vertex_ao", "sparse_rows") => {
            "`AOBAKE_GPU_SPARSE_ROWS`' words: a sparse model's coefficient rows, u16 two per word; one word of 0 for a dense model"
        }
        (_, "vs_params") if vertex_ao_vs => {
            "`VsParams`: `AobakeVertexVsParams` (`aobake_vertex_ao_vs_params`), with `width` set to the data textures' width (aobake uses 2048); the harness's target size stays 0 in an engine's own shader"
        }
        (_, "blocks_tex") if vertex_ao_vs => {
            "`AOBAKE_GPU_BLOCKS`' words as an R32Uint texture (word i at (i mod width, i div width))"
        }
        (_, "coefficients_tex") if vertex_ao_vs => {
            "`AOBAKE_GPU_COEFFICIENTS`' words as an R32Uint texture"
        }
        (_, "maps_tex") if vertex_ao_vs => "`AOBAKE_GPU_MAPS`' words as an R32Uint texture",
        (_, "weights_tex") if vertex_ao_vs => {
            "the pose's weights, their f32 bits as an R32Uint texture, per frame"
        }
        (_, "sparse_rows_tex") if vertex_ao_vs => {
            "`AOBAKE_GPU_SPARSE_ROWS`' words as an R32Uint texture"
        }
        ("cubemap_ao" | "cubemap_ao_vs", "params") => {
            "`Params`: `AobakeCubemapGpuParams` (`aobake_cubemap_gpu_params`), with `points`, `row_stride` (compute), `phase` (`aobake_cubemap_phase`, per frame) and `on_ground` set"
        }
        ("cubemap_ao", "texels") => {
            "`AOBAKE_CUBEMAP_GPU_TEXELS`' words (`aobake_cubemap_gpu_words`), four per texel"
        }
        ("cubemap_ao", "points") => {
            "the points to look up, xyz f32 each, in the character's space as baked"
        }
        ("cubemap_ao", "occlusion") => "the output: one f32 per point",
        ("cubemap_ao", "ground_words") => {
            "`AOBAKE_CUBEMAP_GPU_GROUND`' words: the static ground (one word of 0 without one)"
        }
        ("cubemap_ao_vs", "cubemap_texels") => {
            "`AOBAKE_CUBEMAP_GPU_TEXELS`' words as an R32Uint texture"
        }
        ("cubemap_ao_vs" | "grid_ao_vs", "data_layout") => {
            "`DataLayout`: `width`, the data textures' width; `target_width` and `target_height`, the harness's target (0 in an engine's own shader)"
        }
        ("cubemap_ao_vs", "cubemap_ground") => {
            "`AOBAKE_CUBEMAP_GPU_GROUND`' words as an R32Uint texture"
        }
        ("cubemap_ao_vs", "cubemap_points") => {
            "the harness's points (xyz f32 bits, three words each) as an R32Uint texture; an engine passes its own point instead"
        }
        ("grid_ao" | "grid_ao_vs", "params") => {
            "`Params`: `AobakeGridGpuParams` (`aobake_grid_gpu_params`), with `points` and `row_stride` (compute) set"
        }
        ("grid_ao", "infos") => {
            "`AOBAKE_GRID_GPU_INFOS`' words (`aobake_grid_gpu_words`): four per part"
        }
        ("grid_ao", "cells") => "`AOBAKE_GRID_GPU_CELLS`' words: the cells and T_clip",
        ("grid_ao", "poses") => {
            "per frame, 32 f32 per part: `grid_from_world` then `world_from_bind`, column-major (`aobake_grid_gpu_poses`)"
        }
        ("grid_ao", "receivers") => {
            "the receivers, 8 words each: xyz position, the part's index (u32 bits; 0xffffffff for none), xyz unit normal, the static base's offset (`AOBAKE_GRID_GPU_VERTEX_OFFSETS`; 0 without a base)"
        }
        ("grid_ao", "occlusion") => "the output: one f32 per receiver",
        ("grid_ao_vs", "grid_infos") => "`AOBAKE_GRID_GPU_INFOS`' words as an R32Uint texture",
        ("grid_ao_vs", "grid_cells") => "`AOBAKE_GRID_GPU_CELLS`' words as an R32Uint texture",
        ("grid_ao_vs", "grid_poses") => {
            "the parts' poses (32 f32 bits each, as `poses` above) as an R32Uint texture, per frame"
        }
        ("grid_ao_vs", "grid_receivers") => {
            "the harness's receivers (8 words each, as grid_ao's) as an R32Uint texture; an engine passes its own vertex instead"
        }
        ("texel_ao", "probe") => {
            "the harness's `TexelProbe` (its target's size and the sample offset in texels); an engine's own fragment shader has none"
        }
        ("texel_ao", "texel_basis") => {
            "the basis textures, one layer per weight in weight order, R16Float (`aobake_texel_basis`; `texel-ao.exr`'s channels)"
        }
        ("texel_ao", "texel_sampler") => {
            "linear min and mag filtering, clamp to edge (mipmaps are safe: the textures are dilated)"
        }
        ("texel_ao", "texel_weights") => {
            "`TexelWeights` (1,040 bytes): `count`, 3 words of padding, then weight k at `w[k / 4][k % 4]`, per frame (`aobake_vertex_ao_weights` on `aobake_texel_pose`'s handle)"
        }
        _ => return None,
    })
}

/// A bound resource of a module, as the tables list it.
#[derive(Debug, Clone)]
pub struct Resource {
    /// Its group (set).
    pub group: u32,
    /// Its binding.
    pub binding: u32,
    /// Its WGSL name.
    pub name: String,
    /// Its WGSL declaration: `var<uniform> params: Params`.
    pub declaration: String,
    /// Where the target language binds it, and the name it has there.
    pub here: String,
}

/// The WGSL spelling of a global's address space and type.
pub fn declaration(module: &naga::Module, global: &naga::GlobalVariable) -> String {
    let space = match global.space {
        AddressSpace::Uniform => "<uniform>".to_owned(),
        AddressSpace::Storage { access } => {
            if access.contains(naga::StorageAccess::STORE) {
                "<storage, read_write>".to_owned()
            } else {
                "<storage, read>".to_owned()
            }
        }
        _ => String::new(),
    };
    format!(
        "var{space} {}: {}",
        global.name.as_deref().unwrap_or("?"),
        type_name(module, global.ty)
    )
}

fn type_name(module: &naga::Module, ty: naga::Handle<naga::Type>) -> String {
    let t = &module.types[ty];
    if let Some(name) = &t.name {
        return name.clone();
    }
    let scalar = |s: naga::Scalar| {
        match s.kind {
            ScalarKind::Float => "f",
            ScalarKind::Sint => "i",
            ScalarKind::Uint => "u",
            _ => "?",
        }
        .to_owned()
            + &(8 * s.width).to_string()
    };
    match &t.inner {
        TypeInner::Scalar(s) => scalar(*s),
        TypeInner::Vector { size, scalar: s } => {
            let n = match size {
                VectorSize::Bi => 2,
                VectorSize::Tri => 3,
                VectorSize::Quad => 4,
            };
            format!("vec{n}<{}>", scalar(*s))
        }
        TypeInner::Array { base, size, .. } => match size {
            naga::ArraySize::Constant(n) => format!("array<{}, {n}>", type_name(module, *base)),
            _ => format!("array<{}>", type_name(module, *base)),
        },
        TypeInner::Image {
            dim,
            arrayed,
            class,
        } => {
            let d = match dim {
                ImageDimension::D1 => "1d",
                ImageDimension::D2 => "2d",
                ImageDimension::D3 => "3d",
                ImageDimension::Cube => "cube",
            };
            let texel = match class {
                ImageClass::Sampled { kind, .. } => match kind {
                    ScalarKind::Float => "f32",
                    ScalarKind::Sint => "i32",
                    _ => "u32",
                },
                _ => "?",
            };
            let array = if *arrayed { "_array" } else { "" };
            format!("texture_{d}{array}<{texel}>")
        }
        TypeInner::Sampler { .. } => "sampler".to_owned(),
        _ => "?".to_owned(),
    }
}

/// The table of `shader`'s resources in `language`, as Markdown.
pub fn table(shader: &str, language: &str, notes: &str, resources: &[Resource]) -> String {
    let mut out = format!(
        "# {shader}: bindings ({language})\n\nEvery resource of `{shader}` as this translation binds it (group = set, binding = the WGSL's), and what an engine puts there. Generated by `aobake export --shaders`; docs/engines.md has the walk-through. {notes}\n\n| group | binding | WGSL | here | what to put there |\n|---|---|---|---|---|\n"
    );
    for r in resources {
        out.push_str(&format!(
            "| {} | {} | `{}` | {} | {} |\n",
            r.group,
            r.binding,
            r.declaration,
            r.here,
            what_to_bind(shader, &r.name).unwrap_or("(not documented)")
        ));
    }
    out
}
