//! The run-time evaluators for engines that do not speak WGSL: each of
//! [`VERTEX_AO`], [`CUBEMAP_AO`] and [`GRID_AO`] (compute) and their
//! vertex-stage twins [`VERTEX_AO_VS`], [`CUBEMAP_AO_VS`] and
//! [`GRID_AO_VS`] (textures) translated by naga into GLSL (4.50 core, ES
//! 3.00 for the vertex stage, and ES 3.10, one file per entry point), HLSL (shader
//! models 5.1 and 6.0), MSL (2.1) and SPIR-V (1.3). `aobake export
//! --shaders DIR` writes them.
//!
//! Resources keep their WGSL numbering: in GLSL, `binding = 8·group +
//! binding`; in HLSL, `register(…binding, space group)`; in MSL, buffers
//! take `[[buffer(i)]]` in the order the WGSL declares them (after it, the
//! buffer of runtime array sizes that MSL needs, see [`MSL_SIZES_NOTE`]);
//! in SPIR-V, the WGSL's set and binding.
//!
//! GLSL ES 3.00 (WebGL2) has neither compute shaders nor storage buffers:
//! it gets the vertex-stage evaluators only.

use naga::{
    AddressSpace, ResourceBinding, ShaderStage, StorageAccess, TypeInner,
    back::{glsl, hlsl, msl, spv},
    valid::{Capabilities, ModuleInfo, ValidationFlags, Validator},
};

use crate::{CUBEMAP_AO, CUBEMAP_AO_VS, GRID_AO, GRID_AO_VS, TEXEL_AO, VERTEX_AO, VERTEX_AO_VS};

/// What the MSL files say about the extra buffer that holds the byte sizes
/// of the runtime-sized arrays.
pub const MSL_SIZES_NOTE: &str = "buffer slot after the last buffer: a uint per runtime-sized storage buffer, its size in bytes, in the order the slots below name (naga's, not the bindings')";

/// A target language and version.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    /// GLSL 4.50 core: one shader per entry point.
    Glsl450,
    /// GLSL ES 3.00 (WebGL2): the vertex-stage evaluator only (no compute
    /// shaders, no storage buffers), one shader per entry point.
    GlslEs300,
    /// GLSL ES 3.10 (compute shaders and storage buffers): one per entry
    /// point.
    GlslEs310,
    /// HLSL for shader model 5.1 (Direct3D 11.3 / 12, `fxc`).
    HlslSm51,
    /// HLSL for shader model 6.0 (Direct3D 12, `dxc`).
    HlslSm60,
    /// Metal Shading Language 2.1.
    Msl21,
    /// SPIR-V 1.3 (Vulkan 1.1), binary.
    SpirV13,
}

impl Target {
    /// Every target.
    pub const ALL: [Self; 7] = [
        Self::Glsl450,
        Self::GlslEs300,
        Self::GlslEs310,
        Self::HlslSm51,
        Self::HlslSm60,
        Self::Msl21,
        Self::SpirV13,
    ];

    /// Its folder under the export directory.
    pub fn dir(self) -> &'static str {
        match self {
            Self::Glsl450 => "glsl450",
            Self::GlslEs300 => "glsl-es300",
            Self::GlslEs310 => "glsl-es310",
            Self::HlslSm51 => "hlsl-sm5_1",
            Self::HlslSm60 => "hlsl-sm6_0",
            Self::Msl21 => "msl2_1",
            Self::SpirV13 => "spirv1_3",
        }
    }
}

/// One written file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ShaderFile {
    /// Its target.
    pub target: Target,
    /// Its path under the export directory, such as
    /// `glsl450/vertex_ao.cs_main.comp`.
    pub path: String,
    /// Its contents (text, or SPIR-V words little-endian).
    pub bytes: Vec<u8>,
}

/// Why a shader could not be translated.
#[derive(Debug, thiserror::Error)]
#[error("{shader} ({}): {message}", target.map_or("WGSL", Target::dir))]
pub struct ExportError {
    /// The WGSL pipeline.
    pub shader: &'static str,
    /// The target (none: the WGSL itself did not parse or validate).
    pub target: Option<Target>,
    /// What naga said.
    pub message: String,
}

/// The run-time evaluators an engine needs, by name.
pub fn runtime_sources() -> [(&'static str, &'static str); 7] {
    [
        ("texel_ao", TEXEL_AO),
        ("vertex_ao", VERTEX_AO),
        ("vertex_ao_vs", VERTEX_AO_VS),
        ("cubemap_ao", CUBEMAP_AO),
        ("cubemap_ao_vs", CUBEMAP_AO_VS),
        ("grid_ao", GRID_AO),
        ("grid_ao_vs", GRID_AO_VS),
    ]
}

/// Every run-time evaluator in every target.
pub fn export_all() -> Result<Vec<ShaderFile>, ExportError> {
    let mut files = Vec::new();
    for (name, module, info) in parsed_sources()? {
        for target in Target::ALL {
            files.extend(translate(name, &module, &info, target)?);
        }
    }
    Ok(files)
}

/// Every run-time evaluator parsed and validated ([`parse`]).
fn parsed_sources() -> Result<Vec<(&'static str, naga::Module, ModuleInfo)>, ExportError> {
    runtime_sources()
        .into_iter()
        .map(|(name, source)| {
            let (module, info) = parse(name, source).map_err(|message| ExportError {
                shader: name,
                target: None,
                message,
            })?;
            Ok((name, module, info))
        })
        .collect()
}

/// The binding table of every run-time evaluator in every target
/// (`crate::bindings`): `glsl450/vertex_ao.bindings.md` beside
/// `glsl450/vertex_ao.cs_main.comp`, and so on.
pub fn binding_tables() -> Result<Vec<ShaderFile>, ExportError> {
    let mut files = Vec::new();
    for (name, module, info) in parsed_sources()? {
        let compute = module
            .entry_points
            .iter()
            .any(|e| e.stage == ShaderStage::Compute);
        for target in Target::ALL {
            if target == Target::GlslEs300 && compute {
                continue;
            }
            let bound = bindings(&module);
            let heres = binding_places(name, &module, &info, target, &bound)?;
            let resources: Vec<crate::bindings::Resource> = bound
                .iter()
                .zip(heres)
                .map(|(b, here)| crate::bindings::Resource {
                    group: b.binding.group,
                    binding: b.binding.binding,
                    name: b.name.clone(),
                    declaration: crate::bindings::declaration(
                        &module,
                        &module.global_variables[b.handle],
                    ),
                    here,
                })
                .collect();
            let notes = match target {
                Target::Glsl450 | Target::GlslEs310 => {
                    "GLSL binds `layout(binding = 8·group + binding)`; naga names each resource per entry point, as listed."
                }
                Target::GlslEs300 => {
                    "GLSL ES 3.00 has no `layout(binding)`: bind uniform blocks with `uniformBlockBinding` and textures with `uniform1i`, by the names listed (naga's, per entry point)."
                }
                Target::HlslSm51 | Target::HlslSm60 => {
                    "HLSL binds `register(…binding, space group)`; a sampler comes from naga's sampler heap (`nagaSamplerHeap`) at the index `nagaGroup0SamplerIndexArray[binding]` holds."
                }
                Target::Msl21 => MSL_SIZES_NOTE,
                Target::SpirV13 => {
                    "SPIR-V keeps the WGSL's set and binding (`DescriptorSet`, `Binding`)."
                }
            };
            files.push(ShaderFile {
                target,
                path: format!("{}/{name}.bindings.md", target.dir()),
                bytes: crate::bindings::table(name, target.dir(), notes, &resources).into_bytes(),
            });
        }
    }
    Ok(files)
}

/// Where `target` binds each of `bound` (in order), and its name there.
fn binding_places(
    name: &'static str,
    module: &naga::Module,
    info: &ModuleInfo,
    target: Target,
    bound: &[Binding],
) -> Result<Vec<String>, ExportError> {
    let fail = |message: String| ExportError {
        shader: name,
        target: Some(target),
        message,
    };
    Ok(match target {
        Target::Glsl450 | Target::GlslEs300 | Target::GlslEs310 => {
            let options = glsl_options(target, bound);
            // naga's names, per entry point.
            let mut names: Vec<(
                String,
                std::collections::HashMap<naga::Handle<naga::GlobalVariable>, String>,
            )> = Vec::new();
            for entry in &module.entry_points {
                let (_, reflection) =
                    glsl_entry(module, info, &options, entry).map_err(|e| fail(e.to_string()))?;
                let mut of: std::collections::HashMap<_, String> = reflection
                    .uniforms
                    .iter()
                    .map(|(h, n)| (*h, n.clone()))
                    .collect();
                for (n, mapping) in &reflection.texture_mapping {
                    of.insert(mapping.texture, n.clone());
                    if let Some(sampler) = mapping.sampler {
                        of.insert(sampler, format!("{n} (combined with its texture)"));
                    }
                }
                names.push((entry.name.clone(), of));
            }
            bound
                .iter()
                .map(|b| {
                    let used: Vec<String> = names
                        .iter()
                        .filter_map(|(entry, of)| {
                            of.get(&b.handle).map(|n| format!("{entry}: `{n}`"))
                        })
                        .collect();
                    let place = match target {
                        Target::GlslEs300 => String::new(),
                        _ => format!(
                            "`layout(binding = {})` ",
                            8 * b.binding.group + b.binding.binding
                        ),
                    };
                    format!(
                        "{place}{}",
                        if used.is_empty() {
                            "(unused by the entry points)".to_owned()
                        } else {
                            used.join("; ")
                        }
                    )
                })
                .collect()
        }
        Target::HlslSm51 | Target::HlslSm60 => bound
            .iter()
            .map(|b| {
                let global = &module.global_variables[b.handle];
                let class = if b.sampler {
                    return format!(
                        "sampler heap index at `nagaGroup{}SamplerIndexArray[{}]`",
                        b.binding.group, b.binding.binding
                    );
                } else if b.texture {
                    't'
                } else {
                    match global.space {
                        AddressSpace::Uniform => 'b',
                        _ if b.writable => 'u',
                        _ => 't',
                    }
                };
                format!(
                    "`register({class}{}, space{})`",
                    b.binding.binding, b.binding.group
                )
            })
            .collect(),
        Target::Msl21 => msl_slots(bound)
            .iter()
            .map(|slot| match (slot.buffer, slot.texture, &slot.sampler) {
                (Some(i), ..) => format!("`[[buffer({i})]]`"),
                (_, Some(i), _) => format!("`[[texture({i})]]`"),
                (.., Some(msl::BindSamplerTarget::Resource(i))) => format!("`[[sampler({i})]]`"),
                _ => String::new(),
            })
            .collect(),
        Target::SpirV13 => bound
            .iter()
            .map(|b| {
                format!(
                    "`set = {}, binding = {}`",
                    b.binding.group, b.binding.binding
                )
            })
            .collect(),
    })
}

/// One entry point in GLSL, and what naga named its resources.
fn glsl_entry(
    module: &naga::Module,
    info: &ModuleInfo,
    options: &glsl::Options,
    entry: &naga::EntryPoint,
) -> Result<(String, glsl::ReflectionInfo), glsl::Error> {
    let pipeline = glsl::PipelineOptions {
        shader_stage: entry.stage,
        entry_point: entry.name.clone(),
        multiview: None,
    };
    let mut text = String::new();
    let reflection = glsl::Writer::new(
        &mut text,
        module,
        info,
        options,
        &pipeline,
        naga::proc::BoundsCheckPolicies::default(),
    )?
    .write()?;
    Ok((text, reflection))
}

/// GLSL's options for `target`: `binding = 8·group + binding`.
fn glsl_options(target: Target, bound: &[Binding]) -> glsl::Options {
    let version = match target {
        Target::Glsl450 => glsl::Version::Desktop(450),
        Target::GlslEs300 => glsl::Version::Embedded {
            version: 300,
            is_webgl: true,
        },
        _ => glsl::Version::Embedded {
            version: 310,
            is_webgl: false,
        },
    };
    glsl::Options {
        version,
        writer_flags: glsl::WriterFlags::empty(),
        binding_map: bound
            .iter()
            .map(|b| (b.binding, (8 * b.binding.group + b.binding.binding) as u8))
            .collect(),
        zero_initialize_workgroup_memory: true,
    }
}

/// Parses and validates a WGSL source with the capabilities of a
/// WebGPU-level adapter (nothing optional).
pub fn parse(name: &'static str, source: &str) -> Result<(naga::Module, ModuleInfo), String> {
    let module = naga::front::wgsl::parse_str(source)
        .map_err(|e| format!("{name}: {}", e.emit_to_string(source)))?;
    let info = Validator::new(ValidationFlags::all(), Capabilities::empty())
        .validate(&module)
        .map_err(|e| format!("{name}: {}", e.emit_to_string(source)))?;
    Ok((module, info))
}

/// One parsed WGSL pipeline ([`parse`]) in one target.
pub fn translate(
    name: &'static str,
    module: &naga::Module,
    info: &ModuleInfo,
    target: Target,
) -> Result<Vec<ShaderFile>, ExportError> {
    let fail = |message: String| ExportError {
        shader: name,
        target: Some(target),
        message,
    };
    let file = |path: String, bytes: Vec<u8>| ShaderFile {
        target,
        path: format!("{}/{path}", target.dir()),
        bytes,
    };
    let bindings = bindings(module);
    Ok(match target {
        Target::GlslEs300
            if module
                .entry_points
                .iter()
                .any(|e| e.stage == ShaderStage::Compute) =>
        {
            Vec::new()
        }
        Target::Glsl450 | Target::GlslEs300 | Target::GlslEs310 => {
            let options = glsl_options(target, &bindings);
            let mut files = Vec::new();
            for entry in &module.entry_points {
                let (text, _) =
                    glsl_entry(module, info, &options, entry).map_err(|e| fail(e.to_string()))?;
                let ext = match entry.stage {
                    ShaderStage::Vertex => "vert",
                    ShaderStage::Fragment => "frag",
                    _ => "comp",
                };
                files.push(file(
                    format!("{name}.{}.{ext}", entry.name),
                    text.into_bytes(),
                ));
            }
            files
        }
        Target::HlslSm51 | Target::HlslSm60 => {
            let options = hlsl::Options {
                shader_model: match target {
                    Target::HlslSm51 => hlsl::ShaderModel::V5_1,
                    _ => hlsl::ShaderModel::V6_0,
                },
                binding_map: bindings
                    .iter()
                    .map(|b| {
                        (
                            b.binding,
                            hlsl::BindTarget {
                                space: b.binding.group as u8,
                                register: b.binding.binding,
                                binding_array_size: None,
                                dynamic_storage_buffer_offsets_index: None,
                                restrict_indexing: false,
                            },
                        )
                    })
                    .collect(),
                zero_initialize_workgroup_memory: true,
                ..hlsl::Options::default()
            };
            let pipeline = hlsl::PipelineOptions { entry_point: None };
            let mut text = String::new();
            hlsl::Writer::new(&mut text, &options, &pipeline)
                .write(module, info, None)
                .map_err(|e| fail(e.to_string()))?;
            vec![file(format!("{name}.hlsl"), text.into_bytes())]
        }
        Target::Msl21 => {
            // Buffers in binding order, then the sizes buffer.
            let slots = msl_slots(&bindings);
            let buffers = slots.iter().filter(|s| s.buffer.is_some()).count() as u8;
            let per_entry = msl::EntryPointResources {
                resources: bindings
                    .iter()
                    .zip(&slots)
                    .map(|(b, s)| (b.binding, s.clone()))
                    .collect(),
                immediates_buffer: None,
                sizes_buffer: Some(buffers),
            };
            let options = msl::Options {
                lang_version: (2, 1),
                per_entry_point_map: module
                    .entry_points
                    .iter()
                    .map(|e| (e.name.clone(), per_entry.clone()))
                    .collect(),
                zero_initialize_workgroup_memory: true,
                ..msl::Options::default()
            };
            let (text, _) =
                msl::write_string(module, info, &options, &msl::PipelineOptions::default())
                    .map_err(|e| fail(e.to_string()))?;
            let text = format!(
                "// Sizes: {MSL_SIZES_NOTE}.\n{}{text}",
                msl_manifest(&bindings, &slots, buffers)
            );
            vec![file(format!("{name}.metal"), text.into_bytes())]
        }
        Target::SpirV13 => {
            let options = spv::Options {
                lang_version: (1, 3),
                flags: spv::WriterFlags::empty(),
                ..spv::Options::default()
            };
            let words =
                spv::write_vec(module, info, &options, None).map_err(|e| fail(e.to_string()))?;
            let bytes = words.iter().flat_map(|w| w.to_le_bytes()).collect();
            vec![file(format!("{name}.spv"), bytes)]
        }
    })
}

/// A WebGL2 program: a vertex and a fragment shader in GLSL ES 3.00 and
/// the names naga gave their resources, so that a page binds them by the
/// WGSL's binding numbers (GLSL ES 3.00 has no `layout(binding)`).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct WebGlProgram {
    /// The vertex shader.
    pub vertex: String,
    /// The fragment shader.
    pub fragment: String,
    /// Uniform blocks (`uniformBlockBinding`) and samplers
    /// (`uniform1i`) by their WGSL binding in group 0, per stage.
    pub resources: Vec<WebGlResource>,
}

/// One resource of a [`WebGlProgram`].
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct WebGlResource {
    /// Its WGSL binding (group 0).
    pub binding: u32,
    /// `block` (a uniform block) or `sampler`.
    pub kind: &'static str,
    /// Its name in the GLSL.
    pub name: String,
}

/// The dashboard viewer's program for WebGL2, for a method `family`
/// (`vertex`, `grid` or `cubemap`: [`crate::VIEWER_VERTEX`],
/// [`crate::VIEWER_GRID`], [`crate::VIEWER_CUBEMAP`]).
pub fn webgl_viewer(family: &str) -> Result<WebGlProgram, ExportError> {
    let (name, source) = match family {
        "vertex" => ("viewer_vertex", crate::VIEWER_VERTEX),
        "grid" => ("viewer_grid", crate::VIEWER_GRID),
        "cubemap" => ("viewer_cubemap", crate::VIEWER_CUBEMAP),
        _ => {
            return Err(ExportError {
                shader: "viewer",
                target: None,
                message: format!("no viewer for the {family:?} family"),
            });
        }
    };
    let fail = |target, message| ExportError {
        shader: name,
        target,
        message,
    };
    let (module, info) = parse(name, source).map_err(|m| fail(None, m))?;
    let options = glsl::Options {
        version: glsl::Version::Embedded {
            version: 300,
            is_webgl: true,
        },
        writer_flags: glsl::WriterFlags::empty(),
        binding_map: Default::default(),
        zero_initialize_workgroup_memory: true,
    };
    let mut resources = Vec::new();
    let mut stage = |shader_stage, entry_point: &str| -> Result<String, ExportError> {
        let pipeline = glsl::PipelineOptions {
            shader_stage,
            entry_point: entry_point.to_owned(),
            multiview: None,
        };
        let mut text = String::new();
        let reflection = glsl::Writer::new(
            &mut text,
            &module,
            &info,
            &options,
            &pipeline,
            naga::proc::BoundsCheckPolicies::default(),
        )
        .and_then(|mut w| w.write())
        .map_err(|e| fail(Some(Target::GlslEs300), e.to_string()))?;
        let binding = |handle: naga::Handle<naga::GlobalVariable>| {
            module.global_variables[handle]
                .binding
                .map_or(u32::MAX, |b| b.binding)
        };
        for (handle, block) in &reflection.uniforms {
            resources.push(WebGlResource {
                binding: binding(*handle),
                kind: "block",
                name: block.clone(),
            });
        }
        for (sampler, mapping) in &reflection.texture_mapping {
            resources.push(WebGlResource {
                binding: binding(mapping.texture),
                kind: "sampler",
                name: sampler.clone(),
            });
        }
        Ok(text)
    };
    let vertex = stage(ShaderStage::Vertex, "vs_main")?;
    let fragment = stage(ShaderStage::Fragment, "fs_main")?;
    resources.sort_by(|a, b| (a.binding, &a.name).cmp(&(b.binding, &b.name)));
    resources.dedup();
    Ok(WebGlProgram {
        vertex,
        fragment,
        resources,
    })
}

/// A resource the shader binds.
struct Binding {
    binding: ResourceBinding,
    /// The global variable.
    handle: naga::Handle<naga::GlobalVariable>,
    writable: bool,
    texture: bool,
    /// A sampler (the texel methods' basis textures are filtered).
    sampler: bool,
    /// The WGSL variable's name.
    name: String,
    /// naga's handle index (the `size{i}` of MSL's `_mslBufferSizes`),
    /// for a runtime-sized storage buffer.
    sized: Option<usize>,
}

/// The module's bound resources (buffers, and the vertex-stage
/// evaluator's textures, read with `textureLoad`: no samplers) in the
/// WGSL's binding order: the order the files declare them in. (naga's own
/// order is the order it met them in, which a function of a prepended
/// common file that reads a global changes.)
fn bindings(module: &naga::Module) -> Vec<Binding> {
    let mut all: Vec<Binding> = module
        .global_variables
        .iter()
        .filter_map(|(handle, g)| {
            let binding = g.binding?;
            let inner = &module.types[g.ty].inner;
            let texture = matches!(inner, TypeInner::Image { .. });
            let sampler = matches!(inner, TypeInner::Sampler { .. });
            let writable = matches!(g.space, AddressSpace::Storage { access } if access.contains(StorageAccess::STORE));
            let runtime_sized = |inner: &TypeInner| {
                matches!(inner, TypeInner::Array { size: naga::ArraySize::Dynamic, .. })
            };
            let sized = matches!(g.space, AddressSpace::Storage { .. })
                && match inner {
                    TypeInner::Struct { members, .. } => members
                        .last()
                        .is_some_and(|m| runtime_sized(&module.types[m.ty].inner)),
                    other => runtime_sized(other),
                };
            Some(Binding {
                binding,
                handle,
                writable,
                texture,
                sampler,
                name: g.name.clone().unwrap_or_default(),
                sized: sized.then(|| handle.index()),
            })
        })
        .collect();
    all.sort_by_key(|b| (b.binding.group, b.binding.binding));
    all
}

/// Each binding's Metal slot: buffers, textures and samplers numbered
/// apart, each in binding order.
fn msl_slots(bindings: &[Binding]) -> Vec<msl::BindTarget> {
    let (mut buffers, mut textures, mut samplers) = (0u8, 0u8, 0u8);
    bindings
        .iter()
        .map(|b| {
            let mut slot = msl::BindTarget::default();
            if b.texture {
                slot.texture = Some(textures);
                textures += 1;
            } else if b.sampler {
                slot.sampler = Some(msl::BindSamplerTarget::Resource(samplers));
                samplers += 1;
            } else {
                slot.buffer = Some(buffers);
                slot.mutable = b.writable;
                buffers += 1;
            }
            slot
        })
        .collect()
}

/// The Metal file's slots as a comment at its top: each WGSL resource's
/// `[[buffer(i)]]` or `[[texture(i)]]`, and which buffer each field of
/// `_mslBufferSizes` sizes (naga numbers them by its own order).
fn msl_manifest(bindings: &[Binding], slots: &[msl::BindTarget], sizes_slot: u8) -> String {
    let mut lines =
        vec!["// Slots (the WGSL's @group(0) @binding(b) in binding order):".to_owned()];
    for (b, target) in bindings.iter().zip(slots) {
        let slot = match (target.buffer, target.texture, &target.sampler) {
            (Some(i), ..) => format!("[[buffer({i})]]"),
            (_, Some(i), _) => format!("[[texture({i})]]"),
            (.., Some(msl::BindSamplerTarget::Resource(i))) => format!("[[sampler({i})]]"),
            _ => String::new(),
        };
        lines.push(format!(
            "//   @binding({}) {}: {slot}",
            b.binding.binding, b.name
        ));
    }
    let mut sized: Vec<&Binding> = bindings.iter().filter(|b| b.sized.is_some()).collect();
    sized.sort_by_key(|b| b.sized);
    if !sized.is_empty() {
        let fields: Vec<String> = sized
            .iter()
            .map(|b| format!("size{} = {} in bytes", b.sized.unwrap_or_default(), b.name))
            .collect();
        lines.push(format!(
            "//   [[buffer({sizes_slot})]]: _mslBufferSizes {{ {} }} (the fields the functions use)",
            fields.join("; ")
        ));
    }
    lines.join("\n") + "\n"
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::process::Command;

    /// Every file, written under a temporary directory.
    fn written() -> (tempfile::TempDir, Vec<ShaderFile>) {
        let dir = tempfile::tempdir().unwrap();
        let files = export_all().unwrap();
        for f in &files {
            let path = dir.path().join(&f.path);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(path, &f.bytes).unwrap();
        }
        (dir, files)
    }

    /// Runs a Khronos tool (Debian's glslang-tools and spirv-tools, which
    /// `.ci/run` installs): a missing tool fails the test.
    fn run(tool: &str, args: &[&std::ffi::OsStr]) -> (bool, String) {
        let out = Command::new(tool).args(args).output().unwrap_or_else(|e| {
            panic!("{tool} is needed (apt-get install glslang-tools spirv-tools): {e}")
        });
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        (out.status.success(), text)
    }

    /// Every resource of every evaluator has its binding table line, in
    /// every target, with the place the translation binds it.
    #[test]
    fn every_binding_table_says_what_to_put_everywhere() {
        let tables = binding_tables().unwrap();
        assert!(tables.len() >= 7 * 6);
        for t in &tables {
            let text = String::from_utf8(t.bytes.clone()).unwrap();
            assert!(!text.contains("(not documented)"), "{}:\n{text}", t.path);
            assert!(
                !text.contains("| |"),
                "{}: a resource without its place:\n{text}",
                t.path
            );
        }
        let glsl = |path: &str| {
            String::from_utf8(
                tables
                    .iter()
                    .find(|t| t.path == path)
                    .unwrap()
                    .bytes
                    .clone(),
            )
            .unwrap()
        };
        // naga's GLSL names, which an engine cannot guess.
        let vertex = glsl("glsl450/vertex_ao.bindings.md");
        assert!(
            vertex.contains("| `layout(binding = 2)` cs_main: `"),
            "{vertex}"
        );
        // WebGL2 binds by name: every resource has one.
        let webgl = glsl("glsl-es300/vertex_ao_vs.bindings.md");
        eprintln!("{webgl}");
        assert!(!webgl.contains("unused by the entry points"), "{webgl}");
        let hlsl = glsl("hlsl-sm6_0/vertex_ao.bindings.md");
        assert!(hlsl.contains("`register(u5, space0)`"), "{hlsl}");
    }

    #[test]
    fn every_evaluator_has_a_file_per_target_and_entry_point() {
        let files = export_all().unwrap();
        for (name, source) in runtime_sources() {
            let (module, _) = parse(name, source).unwrap();
            let entries = module.entry_points.len();
            assert!(entries >= 1, "{name}");
            for target in Target::ALL {
                let mine: Vec<&ShaderFile> = files
                    .iter()
                    .filter(|f| {
                        let file = f.path.rsplit('/').next().unwrap();
                        f.target == target && file.split('.').next() == Some(name)
                    })
                    .collect();
                let compute = module
                    .entry_points
                    .iter()
                    .any(|e| e.stage == ShaderStage::Compute);
                let want = match target {
                    // WebGL2 has no compute shaders.
                    Target::GlslEs300 if compute => 0,
                    Target::Glsl450 | Target::GlslEs300 | Target::GlslEs310 => entries,
                    _ => 1,
                };
                assert_eq!(mine.len(), want, "{name} {target:?}");
                assert!(mine.iter().all(|f| !f.bytes.is_empty()));
            }
        }
    }

    #[test]
    fn every_viewer_is_valid_glsl_es_300_with_every_resource_named() {
        // The family's lookup bindings (a cubemap's static ground at 4),
        // then the viewer's own: the shading uniforms (6, in both stages),
        // the viewer's uniforms (7), the skin (8) and the palette (9).
        let cubemap: Vec<u32> = vec![0, 1, 2, 4];
        for (family, lookup) in [
            ("vertex", (0..6).collect::<Vec<u32>>()),
            ("grid", (0..6).collect()),
            ("cubemap", cubemap),
        ] {
            let program = webgl_viewer(family).unwrap();
            let dir = tempfile::tempdir().unwrap();
            for (file, text) in [
                ("viewer.vert", &program.vertex),
                ("viewer.frag", &program.fragment),
            ] {
                assert!(text.starts_with("#version 300 es"), "{family} {file}");
                let path = dir.path().join(file);
                std::fs::write(&path, text).unwrap();
                let (ok, said) = run("glslangValidator", &[path.as_os_str()]);
                assert!(ok, "{family} {file}: {said}");
            }
            let mut bindings: Vec<u32> = program.resources.iter().map(|r| r.binding).collect();
            bindings.dedup();
            let want: Vec<u32> = lookup.into_iter().chain(6..10).collect();
            assert_eq!(bindings, want, "{family}: {:?}", program.resources);
            let text = format!("{}{}", program.vertex, program.fragment);
            for r in &program.resources {
                assert!(text.contains(&r.name), "{family}: {r:?}");
            }
            let shading = program.resources.iter().filter(|r| r.binding == 6).count();
            assert_eq!(shading, 2, "{family}: {:?}", program.resources);
        }
        assert!(webgl_viewer("nothing").is_err());
    }

    #[test]
    fn glslang_accepts_every_glsl_file() {
        let (dir, files) = written();
        let glsl: Vec<&ShaderFile> = files
            .iter()
            .filter(|f| {
                matches!(
                    f.target,
                    Target::Glsl450 | Target::GlslEs300 | Target::GlslEs310
                )
            })
            .collect();
        // In 4.50 and ES 3.10: vertex 2, cubemap 1, grid 1, 2 for each
        // vertex-stage twin, and texel 2 (vertex and fragment); in ES 3.00
        // the vertex-stage twins' and texel's only.
        assert_eq!(glsl.len(), 2 * 12 + 3 * 2 + 2);
        for f in glsl {
            let path = dir.path().join(&f.path);
            let (ok, said) = run("glslangValidator", &[path.as_os_str()]);
            assert!(ok, "{}: {said}", f.path);
            let text = std::str::from_utf8(&f.bytes).unwrap();
            let version = match f.target {
                Target::Glsl450 => "#version 450 core",
                Target::GlslEs300 => "#version 300 es",
                _ => "#version 310 es",
            };
            assert!(text.starts_with(version), "{}", f.path);
        }
    }

    #[test]
    fn spirv_val_accepts_the_spirv_and_naga_reads_it_back() {
        let (dir, files) = written();
        let spirv: Vec<&ShaderFile> = files
            .iter()
            .filter(|f| f.target == Target::SpirV13)
            .collect();
        assert_eq!(spirv.len(), runtime_sources().len());
        for f in spirv {
            let path = dir.path().join(&f.path);
            let (ok, said) = run(
                "spirv-val",
                &[
                    "--target-env".as_ref(),
                    "vulkan1.1".as_ref(),
                    path.as_os_str(),
                ],
            );
            assert!(ok, "{}: {said}", f.path);
            // The round trip: naga's SPIR-V front end reads it back into a
            // module that validates, with the same entry points.
            let module =
                naga::front::spv::parse_u8_slice(&f.bytes, &naga::front::spv::Options::default())
                    .unwrap();
            Validator::new(ValidationFlags::all(), Capabilities::empty())
                .validate(&module)
                .unwrap();
            let name = f
                .path
                .trim_start_matches("spirv1_3/")
                .trim_end_matches(".spv");
            let (wgsl, _) = parse(
                "wgsl",
                runtime_sources()
                    .iter()
                    .find(|(n, _)| *n == name)
                    .unwrap()
                    .1,
            )
            .unwrap();
            let names = |m: &naga::Module| -> Vec<String> {
                m.entry_points.iter().map(|e| e.name.clone()).collect()
            };
            assert_eq!(names(&module), names(&wgsl), "{name}");
        }
    }

    #[test]
    fn hlsl_and_msl_keep_the_wgsl_numbering() {
        let files = export_all().unwrap();
        let text = |path: &str| {
            let f = files.iter().find(|f| f.path == path).unwrap();
            String::from_utf8(f.bytes.clone()).unwrap()
        };
        // vertex_ao: @group(0) @binding(5) is the AO it writes, @binding(0)
        // its uniforms, @binding(6) the sparse rows it reads (naga leaves
        // out `space0`).
        for sm in ["hlsl-sm5_1", "hlsl-sm6_0"] {
            let hlsl = text(&format!("{sm}/vertex_ao.hlsl"));
            for register in ["register(u5)", "register(b0)", "register(t6)"] {
                assert!(hlsl.contains(register), "{register}: {hlsl}");
            }
            assert!(hlsl.contains("void cs_main(") && hlsl.contains("void cs_sparse("));
        }
        let msl = text("msl2_1/vertex_ao.metal");
        assert!(
            msl.contains("[[buffer(5)]]") && msl.contains("[[buffer(7)]]"),
            "{msl}"
        );
        assert!(msl.contains("kernel void cs_main(") && msl.contains("kernel void cs_sparse("));
    }

    /// Every Metal file's slots follow the WGSL's bindings, as
    /// docs/engines.md says: buffers numbered in binding order, textures
    /// too; read from the WGSL source, not from naga. (naga's own order
    /// put cubemap_ao's binding 4 at slot 0.)
    #[test]
    fn every_metal_file_numbers_its_slots_in_binding_order() {
        let files = export_all().unwrap();
        let mut checked = 0;
        for f in files.iter().filter(|f| f.path.starts_with("msl2_1/")) {
            let msl = String::from_utf8(f.bytes.clone()).unwrap();
            let name = f
                .path
                .trim_start_matches("msl2_1/")
                .trim_end_matches(".metal");
            // The composed source, common files included.
            let (_, wgsl) = runtime_sources()
                .into_iter()
                .find(|(n, _)| *n == name)
                .unwrap();
            // `@group(0) @binding(N) var<…> NAME: TYPE` or `var NAME: texture_…`.
            // The kind: 0 a buffer, 1 a texture, 2 a sampler.
            let mut resources: Vec<(u32, String, u8)> = wgsl
                .lines()
                .filter_map(|line| {
                    let rest = line.trim().strip_prefix("@group(0) @binding(")?;
                    let (n, rest) = rest.split_once(')')?;
                    let decl = rest.trim().strip_prefix("var")?;
                    let decl = decl.split_once('>').map_or(decl, |(_, after)| after);
                    let (var, ty) = decl.split_once(':')?;
                    let ty = ty.trim();
                    let kind = if ty.starts_with("texture") {
                        1
                    } else if ty.starts_with("sampler") {
                        2
                    } else {
                        0
                    };
                    Some((n.parse().ok()?, var.trim().to_owned(), kind))
                })
                .collect();
            resources.sort();
            assert!(!resources.is_empty(), "{name}");
            let mut next = [0; 3];
            for (_, var, kind) in &resources {
                let k = usize::from(*kind);
                let slot = format!(
                    "{var} [[{}({})]]",
                    ["buffer", "texture", "sampler"][k],
                    next[k]
                );
                next[k] += 1;
                assert!(msl.contains(&slot), "{name}: no `{slot}`");
                checked += 1;
            }
            // The sizes' fields are the ones the comment names.
            let fields: Vec<&str> = msl
                .lines()
                .filter_map(|l| l.trim().strip_prefix("uint size")?.strip_suffix(';'))
                .collect();
            for field in fields {
                assert!(
                    msl.contains(&format!("size{field} = ")),
                    "{name}: size{field} unnamed"
                );
            }
        }
        assert!(checked > 20, "{checked}");
    }
}
