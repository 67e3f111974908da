//! Core's preview [`Renderer`] on wgpu: `shaders/wgsl/preview.wgsl` draws
//! the posed character and a ground plane into a multisampled sRGB target,
//! the model's AO computed per frame into a buffer that the raster reads
//! as a vertex attribute (the AO never leaves the GPU), and the resolved
//! image read back. A vertex model is evaluated on the character by
//! [`VertexAo`]; a cubemap is looked up on the ground's vertices by
//! [`CubemapAo`] at the frame's phase; a texel model's basis textures
//! ([`TexelAo`]) are sampled per pixel of the character, drawn over its
//! atlas's vertices, and its truth panel samples the ray-traced AO at the
//! atlas's texels the same way.

use aobake_core::bake::screen_space::{ScreenFrame, Surface};
use aobake_core::bake::{Camera, Panel, PreviewModel, RenderFrame, RenderScene, Renderer};
use aobake_core::image::{HeatMap, Image};
use aobake_core::method::grid::{base::Receiver, model::GridModel};
use aobake_shaders::{GridReceiver, GtaoParams, PreviewUniforms};
use glam::Vec3;
use wgpu::util::DeviceExt as _;

use super::{
    CubemapAo, ErrorScopes, Gpu, GpuError, GridAo, TexelAo, VertexAo,
    texel_ao::{f16_bits, float_texture},
};

const COLOR: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
const DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Lighting, in linear units: the look of every preview. Ambient light
/// dominates so that the AO, which only darkens the ambient term, reads
/// clearly; the key light is weak and wrapped, enough to show the form.
mod look {
    /// Towards the key light: from the front left, above.
    pub(super) const LIGHT: [f32; 3] = [-0.45, 0.8, 0.4];
    pub(super) const KEY: f32 = 0.12;
    /// The key light wraps half way round (a soft light).
    pub(super) const WRAP: f32 = 0.5;
    pub(super) const AMBIENT: f32 = 1.0;
    pub(super) const CHARACTER: [f32; 3] = [0.6, 0.6, 0.6];
    pub(super) const GROUND: [f32; 3] = [0.4, 0.4, 0.4];
    pub(super) const BACKGROUND: [f32; 3] = [0.32, 0.36, 0.42];
}

/// The preview pipelines on one [`Gpu`].
#[derive(Debug)]
pub struct PreviewRenderer<'g> {
    gpu: &'g Gpu,
    /// The panels (`fs_main`), multisampled.
    pipeline: wgpu::RenderPipeline,
    /// The screen-space baseline's G-buffer (`fs_gbuffer`), one sample.
    gbuffer: wgpu::RenderPipeline,
    /// A panel shaded with the baseline's occlusion (`fs_screen_space`),
    /// multisampled.
    screen: wgpu::RenderPipeline,
    /// GTAO over the G-buffer (gtao.wgsl).
    gtao: wgpu::ComputePipeline,
    /// Binding 0 (the uniforms) of `pipeline` and `gbuffer`.
    surface_layout: wgpu::BindGroupLayout,
    /// Bindings 0–2 of `screen`.
    screen_layout: wgpu::BindGroupLayout,
    samples: u32,
    /// preview.wgsl, for the texel pipelines.
    module: wgpu::ShaderModule,
    /// A texel model's pipelines, built on first use (a software adapter
    /// takes seconds per pipeline, and most previews draw no texel model).
    texel: std::sync::OnceLock<Result<TexelPipelines, GpuError>>,
}

/// The pipelines that draw a texel model's character (`vs_texel`).
#[derive(Debug)]
struct TexelPipelines {
    /// Bindings 0 (uniforms), 3–5 (the model's textures and weights) and
    /// 6 (the truth's texture).
    layout: wgpu::BindGroupLayout,
    /// The panels (`fs_texel`), multisampled.
    colour: wgpu::RenderPipeline,
    /// The G-buffer (`fs_gbuffer_texel`).
    gbuffer: wgpu::RenderPipeline,
}

/// The vertex attributes, one buffer each: position, normal, truth,
/// model, and (a texel model's) the atlas's UV.
const ATTRIBUTES: [[wgpu::VertexAttribute; 1]; 5] = {
    const fn at(shader_location: u32, format: wgpu::VertexFormat) -> [wgpu::VertexAttribute; 1] {
        [wgpu::VertexAttribute {
            format,
            offset: 0,
            shader_location,
        }]
    }
    [
        at(0, wgpu::VertexFormat::Float32x3),
        at(1, wgpu::VertexFormat::Float32x3),
        at(2, wgpu::VertexFormat::Float32),
        at(3, wgpu::VertexFormat::Float32),
        at(4, wgpu::VertexFormat::Float32x2),
    ]
};

/// The vertex buffers of the first `count` [`ATTRIBUTES`].
fn vertex_buffers(count: usize) -> Vec<Option<wgpu::VertexBufferLayout<'static>>> {
    ATTRIBUTES[..count]
        .iter()
        .map(|a| {
            Some(wgpu::VertexBufferLayout {
                array_stride: a[0].format.size(),
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: a,
            })
        })
        .collect()
}

/// One raster pipeline of preview.wgsl.
struct Raster<'a> {
    label: &'a str,
    layout: &'a wgpu::PipelineLayout,
    vertex: &'a str,
    buffers: &'a [Option<wgpu::VertexBufferLayout<'static>>],
    fragment: &'a str,
    samples: u32,
    targets: &'a [Option<wgpu::ColorTargetState>],
}

fn raster(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    r: Raster<'_>,
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(r.label),
        layout: Some(r.layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some(r.vertex),
            compilation_options: Default::default(),
            buffers: r.buffers,
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            front_face: wgpu::FrontFace::Ccw,
            cull_mode: None,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: wgpu::MultisampleState {
            count: r.samples,
            ..Default::default()
        },
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some(r.fragment),
            compilation_options: Default::default(),
            targets: r.targets,
        }),
        multiview_mask: None,
        cache: None,
    })
}

fn pipeline_layout(device: &wgpu::Device, group: &wgpu::BindGroupLayout) -> wgpu::PipelineLayout {
    device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("preview"),
        bind_group_layouts: &[Some(group)],
        immediate_size: 0,
    })
}

fn layout_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
    ty: wgpu::BindingType,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty,
        count: None,
    }
}

const UNIFORM: wgpu::BindingType = wgpu::BindingType::Buffer {
    ty: wgpu::BufferBindingType::Uniform,
    has_dynamic_offset: false,
    min_binding_size: None,
};

/// The G-buffer's targets, integer texels (renderable on every adapter,
/// unlike float formats on GL): world position (f32 bits), surface and the
/// model's AO (fixed point); normal and the interpolated truth (f32 bits).
/// 32 bytes a pixel, WebGPU's limit.
const GBUFFER: [wgpu::TextureFormat; 2] = [
    wgpu::TextureFormat::Rgba32Uint,
    wgpu::TextureFormat::Rgba32Uint,
];

impl<'g> PreviewRenderer<'g> {
    /// The adapter it renders on.
    pub fn gpu(&self) -> &'g Gpu {
        self.gpu
    }

    /// Builds the pipelines: 4× multisampling where the adapter has it for
    /// both the colour and the depth format, else none.
    pub fn new(gpu: &'g Gpu) -> Result<Self, GpuError> {
        let supports = |f: wgpu::TextureFormat| {
            gpu.adapter
                .get_texture_format_features(f)
                .flags
                .sample_count_supported(4)
        };
        let samples = if supports(COLOR) && supports(DEPTH) {
            4
        } else {
            1
        };
        let device = &gpu.device;
        let scope = ErrorScopes::push(device);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("preview.wgsl"),
            source: wgpu::ShaderSource::Wgsl(aobake_shaders::PREVIEW.into()),
        });
        let buffers = vertex_buffers(4);
        use wgpu::ShaderStages as S;
        let entry = layout_entry;
        let uniform = UNIFORM;
        let surface_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("preview surface"),
            entries: &[entry(0, S::VERTEX_FRAGMENT, uniform)],
        });
        let screen_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("preview screen-space"),
            entries: &[
                entry(0, S::VERTEX_FRAGMENT, uniform),
                entry(
                    1,
                    S::FRAGMENT,
                    wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                ),
                entry(2, S::FRAGMENT, uniform),
            ],
        });
        let (surface_pipeline_layout, screen_pipeline_layout) = (
            pipeline_layout(device, &surface_layout),
            pipeline_layout(device, &screen_layout),
        );
        let gbuffer_targets: Vec<Option<wgpu::ColorTargetState>> =
            GBUFFER.iter().map(|&f| Some(f.into())).collect();
        let color_targets = [Some(COLOR.into())];
        let raster = |label, layout, fragment, samples, targets| {
            raster(
                device,
                &module,
                Raster {
                    label,
                    layout,
                    vertex: "vs_main",
                    buffers: &buffers,
                    fragment,
                    samples,
                    targets,
                },
            )
        };
        let pipeline = raster(
            "preview",
            &surface_pipeline_layout,
            "fs_main",
            samples,
            &color_targets,
        );
        let gbuffer = raster(
            "preview g-buffer",
            &surface_pipeline_layout,
            "fs_gbuffer",
            1,
            &gbuffer_targets,
        );
        let screen = raster(
            "preview screen-space",
            &screen_pipeline_layout,
            "fs_screen_space",
            samples,
            &color_targets,
        );
        let gtao_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("gtao.wgsl"),
            source: wgpu::ShaderSource::Wgsl(aobake_shaders::GTAO.into()),
        });
        let gtao = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("gtao"),
            layout: None,
            module: &gtao_module,
            entry_point: Some("cs_main"),
            compilation_options: Default::default(),
            cache: None,
        });
        if let Some(e) = scope.pop() {
            return Err(GpuError::Pipeline(e.to_string()));
        }
        Ok(Self {
            gpu,
            pipeline,
            gbuffer,
            screen,
            gtao,
            surface_layout,
            screen_layout,
            samples,
            module,
            texel: std::sync::OnceLock::new(),
        })
    }

    /// The texel pipelines, built on first use.
    fn texel_pipelines(&self) -> Result<&TexelPipelines, GpuError> {
        self.texel
            .get_or_init(|| {
                let device = &self.gpu.device;
                let scope = ErrorScopes::push(device);
                use wgpu::ShaderStages as S;
                let texture = |view_dimension| wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: true },
                    view_dimension,
                    multisampled: false,
                };
                let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some("preview texel"),
                    entries: &[
                        layout_entry(0, S::VERTEX_FRAGMENT, UNIFORM),
                        layout_entry(3, S::FRAGMENT, texture(wgpu::TextureViewDimension::D2Array)),
                        layout_entry(
                            4,
                            S::FRAGMENT,
                            wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                        ),
                        layout_entry(5, S::FRAGMENT, UNIFORM),
                        layout_entry(6, S::FRAGMENT, texture(wgpu::TextureViewDimension::D2)),
                    ],
                });
                let pipeline_layout = pipeline_layout(device, &layout);
                let buffers = vertex_buffers(5);
                let gbuffer_targets: Vec<Option<wgpu::ColorTargetState>> =
                    GBUFFER.iter().map(|&f| Some(f.into())).collect();
                let raster = |label, fragment, samples, targets| {
                    raster(
                        device,
                        &self.module,
                        Raster {
                            label,
                            layout: &pipeline_layout,
                            vertex: "vs_texel",
                            buffers: &buffers,
                            fragment,
                            samples,
                            targets,
                        },
                    )
                };
                let pipelines = TexelPipelines {
                    colour: raster(
                        "preview texel",
                        "fs_texel",
                        self.samples,
                        &[Some(COLOR.into())],
                    ),
                    gbuffer: raster(
                        "preview texel g-buffer",
                        "fs_gbuffer_texel",
                        1,
                        &gbuffer_targets,
                    ),
                    layout,
                };
                match scope.pop() {
                    Some(e) => Err(GpuError::Pipeline(e.to_string())),
                    None => Ok(pipelines),
                }
            })
            .as_ref()
            .map_err(Clone::clone)
    }

    /// Samples per pixel of the target (4, or 1 where the adapter cannot).
    pub fn samples(&self) -> u32 {
        self.samples
    }

    fn uniforms(scene: &RenderScene<'_>, panel: Panel, ground: bool) -> PreviewUniforms {
        let aspect = scene.size.0 as f32 / scene.size.1.max(1) as f32;
        uniforms(&scene.camera, aspect, &scene.heat_map, panel, ground)
    }
}

/// The preview shader's uniforms for one surface (`ground`, else the
/// character) of one panel seen by `camera` at `aspect`: the looks every
/// preview shares. The dashboard's viewer shades with the same ones
/// (`shaders/wgsl/common/shade.wgsl`).
pub fn uniforms(
    camera: &Camera,
    aspect: f32,
    heat_map: &HeatMap,
    panel: Panel,
    ground: bool,
) -> PreviewUniforms {
    let (c, h) = (camera, heat_map);
    let v4 = |v: [f32; 3], w: f32| [v[0], v[1], v[2], w];
    let light = Vec3::from(look::LIGHT).normalize().to_array();
    PreviewUniforms {
        clip_from_world: c.clip_from_world(aspect).to_cols_array_2d(),
        eye: c.eye.extend(1.0).to_array(),
        light: v4(light, look::KEY),
        ambient: v4([look::AMBIENT; 3], look::WRAP),
        albedo: v4(
            if ground {
                look::GROUND
            } else {
                look::CHARACTER
            },
            1.0,
        ),
        neutral: v4(h.neutral, h.range),
        too_dark: v4(h.too_dark, 0.0),
        too_bright: v4(h.too_bright, 0.0),
        ground: [c.target.x, c.ground_y, c.target.z, c.ground_half_extent],
        background: v4(look::BACKGROUND, 1.0),
        panel: match panel {
            Panel::Truth => 0,
            // The screen-space panel shades the model's slot with GTAO.
            Panel::Model | Panel::ScreenSpace => 1,
            Panel::Error => 2,
        },
        surface: u32::from(ground),
        _pad: [0; 2],
    }
}

/// What computes a panel's model AO on the GPU.
enum Evaluator<'g> {
    Vertex(VertexAo<'g>),
    Cubemap(CubemapAo<'g>),
    /// The grids, their model (for the static base's offsets) and each
    /// character vertex's part.
    Grid(GridAo<'g>, &'g GridModel, &'g [u32]),
    /// A texel model's textures, and what its character is drawn with.
    Texel(TexelAo<'g>, TexelStage<'g>),
}

/// A texel model's character: drawn over its atlas's vertices (each a
/// character vertex, `xref`), with the truth at the atlas's texels in a
/// texture rewritten per frame.
struct TexelStage<'s> {
    atlas: &'s aobake_core::method::texel::AtlasLayout,
    truth: wgpu::Texture,
    truth_view: wgpu::TextureView,
}

/// Vertex buffers of one surface.
struct Mesh {
    positions: wgpu::Buffer,
    normals: wgpu::Buffer,
    truth: wgpu::Buffer,
    model: wgpu::Buffer,
    /// A texel model's character: the atlas's UVs (attribute 4).
    uvs: Option<wgpu::Buffer>,
    indices: wgpu::Buffer,
    index_count: u32,
}

impl Mesh {
    fn draw(&self, pass: &mut wgpu::RenderPass<'_>) {
        if let Some(uvs) = &self.uvs {
            pass.set_vertex_buffer(4, uvs.slice(..));
        }
        pass.set_vertex_buffer(0, self.positions.slice(..));
        pass.set_vertex_buffer(1, self.normals.slice(..));
        pass.set_vertex_buffer(2, self.truth.slice(..));
        pass.set_vertex_buffer(3, self.model.slice(..));
        pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..self.index_count, 0, 0..1);
    }
}

/// A 2D texture of `size` pixels, one mip level.
fn create_texture(
    device: &wgpu::Device,
    label: &str,
    (width, height): (u32, u32),
    format: wgpu::TextureFormat,
    samples: u32,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: samples,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

/// A depth attachment cleared to the far plane, not kept after the pass.
fn cleared_depth(view: &wgpu::TextureView) -> Option<wgpu::RenderPassDepthStencilAttachment<'_>> {
    Some(wgpu::RenderPassDepthStencilAttachment {
        view,
        depth_ops: Some(wgpu::Operations {
            load: wgpu::LoadOp::Clear(1.0),
            store: wgpu::StoreOp::Discard,
        }),
        stencil_ops: None,
    })
}

fn init(
    device: &wgpu::Device,
    label: &str,
    bytes: &[u8],
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: bytes,
        usage,
    })
}

/// Everything one render call draws with: the model's evaluator, both
/// surfaces' buffers and the grids' receivers, made once and rewritten per
/// frame.
struct Stage<'s> {
    evaluator: Evaluator<'s>,
    vertices: usize,
    character: Mesh,
    ground: Mesh,
    ground_positions: wgpu::Buffer,
    ground_count: usize,
    /// The grids' receivers: the character's (rewritten every frame) and
    /// the ground's (fixed).
    receivers: Option<(wgpu::Buffer, wgpu::Buffer)>,
}

/// A single-sampled texture and a view of it.
struct Target {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
}

/// The screen-space baseline's resources for one target size: the
/// G-buffer, its depth, GTAO's output and the bind group that reads them.
struct ScreenPass {
    targets: Vec<Target>,
    depth: wgpu::TextureView,
    occlusion: wgpu::Buffer,
    gtao_group: wgpu::BindGroup,
    groups: [u32; 2],
    /// The `fs_screen_space` bind groups, character then ground.
    shade_groups: (wgpu::BindGroup, wgpu::BindGroup),
}

impl<'g> PreviewRenderer<'g> {
    /// Checks the frames against the model and builds the [`Stage`].
    fn stage<'s>(
        &self,
        scene: &RenderScene<'s>,
        frames: &[RenderFrame],
    ) -> Result<Stage<'s>, GpuError>
    where
        'g: 's,
    {
        let gpu = self.gpu;
        let device = &gpu.device;
        let vertices = match scene.model {
            PreviewModel::Vertex(m) => m.vertices(),
            PreviewModel::Cubemap(..) | PreviewModel::Grid(..) | PreviewModel::Texel(..) => {
                frames.first().map_or(0, |f| f.positions.len())
            }
        };
        let g = scene.ground;
        for f in frames {
            if f.positions.len() != vertices
                || f.normals.len() != vertices
                || f.truth.len() != vertices
            {
                return Err(GpuError::TooLarge(format!(
                    "a frame has {} positions for a model of {vertices} vertices",
                    f.positions.len()
                )));
            }
            if let PreviewModel::Texel(m, _) = scene.model
                && f.texel_truth.len() != m.atlas.texels.len()
            {
                return Err(GpuError::TooLarge(format!(
                    "a frame's truth holds {} texels for an atlas of {}",
                    f.texel_truth.len(),
                    m.atlas.texels.len()
                )));
            }
            if f.ground_ao.len() != g.positions.len() {
                return Err(GpuError::TooLarge(format!(
                    "{} ground values for {} ground vertices",
                    f.ground_ao.len(),
                    g.positions.len()
                )));
            }
        }
        let evaluator = match scene.model {
            PreviewModel::Vertex(m) => Evaluator::Vertex(VertexAo::new(gpu, m)?),
            PreviewModel::Cubemap(m, _) => Evaluator::Cubemap(CubemapAo::new(gpu, m)?),
            PreviewModel::Grid(m, owners) => {
                if owners.len() != vertices {
                    return Err(GpuError::TooLarge(format!(
                        "{} vertex parts for {vertices} vertices",
                        owners.len()
                    )));
                }
                Evaluator::Grid(GridAo::new(gpu, m)?, m, owners)
            }
            PreviewModel::Texel(m, _) => {
                let atlas = &m.atlas;
                if atlas.xref.iter().any(|&x| x as usize >= vertices)
                    || atlas.triangles.len() != scene.triangles.len()
                {
                    return Err(GpuError::TooLarge(format!(
                        "an atlas over {} triangles for a character of {} triangles and {vertices} vertices",
                        atlas.triangles.len(),
                        scene.triangles.len()
                    )));
                }
                let size = (atlas.width, atlas.height);
                let truth = float_texture(
                    gpu,
                    "texel truth",
                    size,
                    1,
                    &vec![0; (size.0 * size.1) as usize],
                    wgpu::TextureUsages::COPY_DST,
                );
                let truth_view = truth.create_view(&Default::default());
                Evaluator::Texel(
                    TexelAo::new(gpu, m)?,
                    TexelStage {
                        atlas,
                        truth,
                        truth_view,
                    },
                )
            }
        };
        let texel = match &evaluator {
            Evaluator::Texel(_, t) => Some(t.atlas),
            _ => None,
        };
        // The character's vertices as drawn: a texel model's atlas
        // vertices, else the character's.
        let drawn = texel.map_or(vertices, |a| a.xref.len());
        let cubemap = matches!(evaluator, Evaluator::Cubemap(_));
        let grid = matches!(evaluator, Evaluator::Grid(..));
        use wgpu::BufferUsages as U;
        let dynamic = U::VERTEX | U::COPY_DST;
        let n = drawn.max(1) as u64;
        let buffer = |label, size, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        let triangles = texel.map_or(scene.triangles, |a| &a.triangles);
        let indices: Vec<u32> = triangles.iter().flatten().copied().collect();
        let truth = buffer("truth", 4 * n, dynamic);
        let character = Mesh {
            positions: buffer("positions", 12 * n, dynamic),
            normals: buffer("normals", 12 * n, dynamic),
            // A cubemap does not shade the character: ray-traced in both;
            // a texel model shades it from its textures.
            model: if cubemap || texel.is_some() {
                truth.clone()
            } else {
                buffer("model ao", 4 * n, U::VERTEX | U::STORAGE)
            },
            truth,
            uvs: texel.map(|a| {
                init(
                    device,
                    "atlas uvs",
                    bytemuck::cast_slice(if a.uvs.is_empty() {
                        &[[0.0f32; 2]]
                    } else {
                        &a.uvs
                    }),
                    U::VERTEX,
                )
            }),
            indices: init(
                device,
                "indices",
                bytemuck::cast_slice(if indices.is_empty() {
                    &[0u32; 3]
                } else {
                    &indices
                }),
                U::INDEX,
            ),
            index_count: indices.len() as u32,
        };
        // A vertex method's ground shows the ray-traced occlusion in both
        // AO slots (no vertex method bakes it); a cubemap's and the grids'
        // are looked up into their own buffer.
        let ground_n = g.positions.len().max(1) as u64;
        let ground_ao = buffer("ground ao", 4 * ground_n, dynamic);
        let ground_model = if cubemap || grid {
            buffer("ground model ao", 4 * ground_n, U::VERTEX | U::STORAGE)
        } else {
            ground_ao.clone()
        };
        let receivers = match &evaluator {
            Evaluator::Grid(_, model, _) => Some(model),
            _ => None,
        }
        .map(|model| {
            let up = [0.0, 1.0, 0.0];
            let ground: Vec<GridReceiver> = g
                .positions
                .iter()
                .map(|&p| {
                    let offset = model.offset(Receiver::Ground, p);
                    GridReceiver::new(p.to_array(), up, GridReceiver::NO_PART, offset)
                })
                .collect();
            (
                buffer("character receivers", 32 * n, U::STORAGE | U::COPY_DST),
                init(
                    device,
                    "ground receivers",
                    bytemuck::cast_slice(&ground),
                    U::STORAGE,
                ),
            )
        });
        let ground_indices: Vec<u32> = g.triangles.iter().flatten().copied().collect();
        let ground_positions = init(
            device,
            "ground",
            bytemuck::cast_slice(&g.positions),
            U::VERTEX | U::STORAGE,
        );
        let ground = Mesh {
            positions: ground_positions.clone(),
            normals: init(
                device,
                "ground normals",
                bytemuck::cast_slice(&vec![Vec3::Y; g.positions.len()]),
                U::VERTEX,
            ),
            truth: ground_ao,
            model: ground_model,
            uvs: None,
            indices: init(
                device,
                "ground indices",
                bytemuck::cast_slice(&ground_indices),
                U::INDEX,
            ),
            index_count: ground_indices.len() as u32,
        };
        Ok(Stage {
            evaluator,
            vertices,
            character,
            ground,
            ground_positions,
            ground_count: g.positions.len(),
            receivers,
        })
    }

    /// Uploads a frame and records the model's evaluation.
    fn evaluate(
        &self,
        stage: &Stage<'_>,
        frame: &RenderFrame,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<(), GpuError> {
        let queue = &self.gpu.queue;
        let c = &stage.character;
        match &stage.evaluator {
            // Per atlas vertex, its character vertex's.
            Evaluator::Texel(_, t) => {
                fn expand<T: Copy>(xref: &[u32], values: &[T]) -> Vec<T> {
                    xref.iter().map(|&x| values[x as usize]).collect()
                }
                let xref = &t.atlas.xref;
                let positions = expand(xref, &frame.positions);
                queue.write_buffer(&c.positions, 0, bytemuck::cast_slice(&positions));
                let normals = expand(xref, &frame.normals);
                queue.write_buffer(&c.normals, 0, bytemuck::cast_slice(&normals));
                let truth = expand(xref, &frame.truth);
                queue.write_buffer(&c.truth, 0, bytemuck::cast_slice(&truth));
            }
            _ => {
                queue.write_buffer(&c.positions, 0, bytemuck::cast_slice(&frame.positions));
                queue.write_buffer(&c.normals, 0, bytemuck::cast_slice(&frame.normals));
                queue.write_buffer(&c.truth, 0, bytemuck::cast_slice(&frame.truth));
            }
        }
        queue.write_buffer(
            &stage.ground.truth,
            0,
            bytemuck::cast_slice(&frame.ground_ao),
        );
        match &stage.evaluator {
            Evaluator::Vertex(e) => e.record(encoder, &frame.weights, &c.model),
            Evaluator::Texel(e, t) => {
                e.write_weights(&frame.weights)?;
                let a = t.atlas;
                let image = a.image(&frame.texel_truth);
                queue.write_texture(
                    t.truth.as_image_copy(),
                    bytemuck::cast_slice(&f16_bits(&image)),
                    wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(2 * a.width),
                        rows_per_image: Some(a.height),
                    },
                    wgpu::Extent3d {
                        width: a.width,
                        height: a.height,
                        depth_or_array_layers: 1,
                    },
                );
                Ok(())
            }
            Evaluator::Cubemap(e) => e.record(
                encoder,
                &stage.ground_positions,
                stage.ground_count as u32,
                frame.phase,
                true,
                &stage.ground.model,
            ),
            Evaluator::Grid(e, model, owners) => {
                let (on_character, on_ground) = stage
                    .receivers
                    .as_ref()
                    .expect("grid receivers are made for grids");
                let mine: Vec<GridReceiver> = frame
                    .positions
                    .iter()
                    .zip(&frame.normals)
                    .zip(owners.iter())
                    .enumerate()
                    .map(|(i, ((&p, n), &o))| {
                        let offset = model.offset(Receiver::vertex(i, o), p);
                        GridReceiver::new(p.to_array(), n.to_array(), o, offset)
                    })
                    .collect();
                queue.write_buffer(on_character, 0, bytemuck::cast_slice(&mine));
                e.record(
                    encoder,
                    &frame.weights,
                    on_character,
                    stage.vertices as u32,
                    &c.model,
                )?;
                e.record(
                    encoder,
                    &frame.weights,
                    on_ground,
                    stage.ground_count as u32,
                    &stage.ground.model,
                )
            }
        }
    }

    /// The bind group of one surface of one panel: a texel model's
    /// character's also binds its textures.
    fn surface_group(
        &self,
        scene: &RenderScene<'_>,
        stage: &Stage<'_>,
        panel: Panel,
        ground: bool,
    ) -> Result<wgpu::BindGroup, GpuError> {
        let device = &self.gpu.device;
        let u = init(
            device,
            "uniforms",
            bytemuck::bytes_of(&Self::uniforms(scene, panel, ground)),
            wgpu::BufferUsages::UNIFORM,
        );
        let mut entries = vec![wgpu::BindGroupEntry {
            binding: 0,
            resource: u.as_entire_binding(),
        }];
        let layout = match &stage.evaluator {
            Evaluator::Texel(e, t) if !ground => {
                entries.extend(e.entries());
                entries.push(wgpu::BindGroupEntry {
                    binding: 6,
                    resource: wgpu::BindingResource::TextureView(&t.truth_view),
                });
                &self.texel_pipelines()?.layout
            }
            _ => &self.surface_layout,
        };
        Ok(device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("preview"),
            layout,
            entries: &entries,
        }))
    }

    /// The pipelines the character is drawn with: a texel model's
    /// (colour, G-buffer), or the others'.
    fn character_pipelines(
        &self,
        stage: &Stage<'_>,
    ) -> Result<(&wgpu::RenderPipeline, &wgpu::RenderPipeline), GpuError> {
        Ok(match stage.evaluator {
            Evaluator::Texel(..) => {
                let t = self.texel_pipelines()?;
                (&t.colour, &t.gbuffer)
            }
            _ => (&self.pipeline, &self.gbuffer),
        })
    }

    /// The screen-space pass's resources for `scene`'s size and camera.
    fn screen_pass(&self, scene: &RenderScene<'_>) -> ScreenPass {
        let device = &self.gpu.device;
        let (width, height) = scene.size;
        use wgpu::TextureUsages as T;
        let texture = |label, format, usage| {
            let texture = create_texture(device, label, scene.size, format, 1, usage);
            let view = texture.create_view(&Default::default());
            Target { texture, view }
        };
        let targets: Vec<Target> = GBUFFER
            .iter()
            .zip(["g-buffer position", "g-buffer normal"])
            .map(|(&f, label)| {
                texture(
                    label,
                    f,
                    T::RENDER_ATTACHMENT | T::TEXTURE_BINDING | T::COPY_SRC,
                )
            })
            .collect();
        let depth = texture("g-buffer depth", DEPTH, T::RENDER_ATTACHMENT).view;
        let pixels = u64::from(width) * u64::from(height);
        use wgpu::BufferUsages as U;
        let occlusion = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("gtao occlusion"),
            size: 4 * pixels.max(1),
            usage: U::STORAGE | U::COPY_SRC,
            mapped_at_creation: false,
        });
        let c = &scene.camera;
        let g = &scene.gtao;
        let view = c.view_from_world();
        let params = GtaoParams {
            view_from_world: view.to_cols_array_2d(),
            eye: c.eye.extend(1.0).to_array(),
            width,
            height,
            slices: g.slices,
            steps: g.steps,
            radius: g.radius,
            focal: 0.5 * height as f32 / (0.5 * c.fov_y).tan(),
            falloff: g.falloff,
            _pad: 0,
        };
        let params = init(
            device,
            "gtao params",
            bytemuck::bytes_of(&params),
            U::UNIFORM,
        );
        let gtao_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("gtao"),
            layout: &self.gtao.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&targets[0].view),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::TextureView(&targets[1].view),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: occlusion.as_entire_binding(),
                },
            ],
        });
        let width_uniform = init(
            device,
            "screen width",
            bytemuck::bytes_of(&[width, height, 0, 0]),
            U::UNIFORM,
        );
        let shade = |ground: bool| {
            let u = init(
                device,
                "uniforms",
                bytemuck::bytes_of(&Self::uniforms(scene, Panel::ScreenSpace, ground)),
                U::UNIFORM,
            );
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("preview screen-space"),
                layout: &self.screen_layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: u.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: occlusion.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: width_uniform.as_entire_binding(),
                    },
                ],
            })
        };
        ScreenPass {
            targets,
            depth,
            occlusion: occlusion.clone(),
            gtao_group,
            groups: [width.div_ceil(8), height.div_ceil(8)],
            shade_groups: (shade(false), shade(true)),
        }
    }

    /// Records the G-buffer pass of the frame `stage` holds.
    fn record_gbuffer(
        &self,
        stage: &Stage<'_>,
        screen: &ScreenPass,
        groups: &(wgpu::BindGroup, wgpu::BindGroup),
        character: &wgpu::RenderPipeline,
        encoder: &mut wgpu::CommandEncoder,
    ) {
        let attachments: Vec<Option<wgpu::RenderPassColorAttachment<'_>>> = screen
            .targets
            .iter()
            .map(|t| {
                Some(wgpu::RenderPassColorAttachment {
                    view: &t.view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                })
            })
            .collect();
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("preview g-buffer"),
            color_attachments: &attachments,
            depth_stencil_attachment: cleared_depth(&screen.depth),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.gbuffer);
        pass.set_bind_group(0, &groups.1, &[]);
        stage.ground.draw(&mut pass);
        pass.set_pipeline(character);
        pass.set_bind_group(0, &groups.0, &[]);
        stage.character.draw(&mut pass);
    }

    /// Records GTAO over the G-buffer.
    fn record_gtao(&self, screen: &ScreenPass, encoder: &mut wgpu::CommandEncoder) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("gtao"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.gtao);
        pass.set_bind_group(0, &screen.gtao_group, &[]);
        pass.dispatch_workgroups(screen.groups[0], screen.groups[1], 1);
    }

    fn render_frames(
        &self,
        scene: &RenderScene<'_>,
        frames: &[RenderFrame],
        panels: &[Panel],
    ) -> Result<Vec<Image>, GpuError> {
        let gpu = self.gpu;
        let device = &gpu.device;
        let (width, height) = scene.size;
        let scope = ErrorScopes::push(device);
        let stage = self.stage(scene, frames)?;
        let groups: Vec<(wgpu::BindGroup, wgpu::BindGroup)> = panels
            .iter()
            .map(|&p| {
                Ok((
                    self.surface_group(scene, &stage, p, false)?,
                    self.surface_group(scene, &stage, p, true)?,
                ))
            })
            .collect::<Result<_, GpuError>>()?;
        let (colour, gbuffer) = self.character_pipelines(&stage)?;
        let screen = panels
            .contains(&Panel::ScreenSpace)
            .then(|| self.screen_pass(scene));
        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let texture = |label, format, samples, usage| {
            create_texture(device, label, scene.size, format, samples, usage)
        };
        use wgpu::TextureUsages as T;
        let resolved = texture("resolved", COLOR, 1, T::RENDER_ATTACHMENT | T::COPY_SRC);
        let resolved_view = resolved.create_view(&Default::default());
        let msaa = (self.samples > 1)
            .then(|| texture("msaa", COLOR, self.samples, T::RENDER_ATTACHMENT))
            .map(|t| t.create_view(&Default::default()));
        let depth = texture("depth", DEPTH, self.samples, T::RENDER_ATTACHMENT)
            .create_view(&Default::default());
        let row = (4 * width).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let panel_bytes = u64::from(row) * u64::from(height);
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("preview readback"),
            size: panel_bytes * panels.len().max(1) as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bg = look::BACKGROUND.map(f64::from);
        if let Some(e) = scope.pop() {
            return Err(GpuError::Pipeline(e.to_string()));
        }
        let mut images = Vec::with_capacity(frames.len() * panels.len());
        for frame in frames {
            let scope = ErrorScopes::push(device);
            let mut encoder =
                device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
            self.evaluate(&stage, frame, &mut encoder)?;
            if let Some(screen) = &screen {
                self.record_gbuffer(&stage, screen, &groups[0], gbuffer, &mut encoder);
                self.record_gtao(screen, &mut encoder);
            }
            for (k, (&panel, (on_character, on_ground))) in panels.iter().zip(&groups).enumerate() {
                {
                    let (view, resolve_target) = match &msaa {
                        Some(m) => (m, Some(&resolved_view)),
                        None => (&resolved_view, None),
                    };
                    let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                        label: Some("preview"),
                        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                            view,
                            depth_slice: None,
                            resolve_target,
                            ops: wgpu::Operations {
                                load: wgpu::LoadOp::Clear(wgpu::Color {
                                    r: bg[0],
                                    g: bg[1],
                                    b: bg[2],
                                    a: 1.0,
                                }),
                                store: wgpu::StoreOp::Store,
                            },
                        })],
                        depth_stencil_attachment: cleared_depth(&depth),
                        timestamp_writes: None,
                        occlusion_query_set: None,
                        multiview_mask: None,
                    });
                    match (&screen, panel) {
                        (Some(s), Panel::ScreenSpace) => {
                            pass.set_pipeline(&self.screen);
                            pass.set_bind_group(0, &s.shade_groups.1, &[]);
                            stage.ground.draw(&mut pass);
                            pass.set_bind_group(0, &s.shade_groups.0, &[]);
                        }
                        _ => {
                            pass.set_pipeline(&self.pipeline);
                            pass.set_bind_group(0, on_ground, &[]);
                            stage.ground.draw(&mut pass);
                            pass.set_pipeline(colour);
                            pass.set_bind_group(0, on_character, &[]);
                        }
                    }
                    stage.character.draw(&mut pass);
                }
                encoder.copy_texture_to_buffer(
                    resolved.as_image_copy(),
                    wgpu::TexelCopyBufferInfo {
                        buffer: &staging,
                        layout: wgpu::TexelCopyBufferLayout {
                            offset: k as u64 * panel_bytes,
                            bytes_per_row: Some(row),
                            rows_per_image: Some(height),
                        },
                    },
                    size,
                );
            }
            let submission = gpu.queue.submit(Some(encoder.finish()));
            if let Some(e) = scope.pop() {
                return Err(GpuError::Pipeline(e.to_string()));
            }
            let bytes = gpu.read(&staging, submission)?;
            for k in 0..panels.len() {
                let mut rgba = Vec::with_capacity((4 * width * height) as usize);
                for y in 0..height as usize {
                    let at = k * panel_bytes as usize + y * row as usize;
                    rgba.extend_from_slice(&bytes[at..at + 4 * width as usize]);
                }
                images.push(Image {
                    width,
                    height,
                    rgba,
                });
            }
        }
        Ok(images)
    }

    /// Submits `encoder` and waits for it: the milliseconds from
    /// submission to completion.
    fn timed(&self, encoder: wgpu::CommandEncoder) -> Result<f64, GpuError> {
        let started = std::time::Instant::now();
        let submission = self.gpu.queue.submit(Some(encoder.finish()));
        self.gpu
            .device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(submission),
                timeout: None,
            })
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        Ok(1e3 * started.elapsed().as_secs_f64())
    }

    fn screen_frames(
        &self,
        scene: &RenderScene<'_>,
        frames: &[RenderFrame],
    ) -> Result<Vec<ScreenFrame>, GpuError> {
        let gpu = self.gpu;
        let device = &gpu.device;
        let (width, height) = scene.size;
        let scope = ErrorScopes::push(device);
        let stage = self.stage(scene, frames)?;
        let groups = (
            self.surface_group(scene, &stage, Panel::Model, false)?,
            self.surface_group(scene, &stage, Panel::Model, true)?,
        );
        let (_, gbuffer) = self.character_pipelines(&stage)?;
        let screen = self.screen_pass(scene);
        let pixels = (width * height) as usize;
        // Rows of the G-buffer's copies, then GTAO's output.
        let row = (16 * width).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let target_bytes = u64::from(row) * u64::from(height);
        let offsets = [0, target_bytes];
        let gtao_at = 2 * target_bytes;
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("screen-space readback"),
            size: gtao_at + 4 * pixels as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        if let Some(e) = scope.pop() {
            return Err(GpuError::Pipeline(e.to_string()));
        }
        let new_encoder =
            || device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        let mut out = Vec::with_capacity(frames.len());
        for frame in frames {
            let scope = ErrorScopes::push(device);
            // Each pass alone, timed from submission to completion.
            let mut encoder = new_encoder();
            self.evaluate(&stage, frame, &mut encoder)?;
            let model_ms = self.timed(encoder)?;
            let mut encoder = new_encoder();
            self.record_gbuffer(&stage, &screen, &groups, gbuffer, &mut encoder);
            self.timed(encoder)?;
            let mut encoder = new_encoder();
            self.record_gtao(&screen, &mut encoder);
            let gtao_ms = self.timed(encoder)?;
            let mut encoder = new_encoder();
            for (target, &offset) in screen.targets.iter().zip(&offsets) {
                encoder.copy_texture_to_buffer(
                    target.texture.as_image_copy(),
                    wgpu::TexelCopyBufferInfo {
                        buffer: &staging,
                        layout: wgpu::TexelCopyBufferLayout {
                            offset,
                            bytes_per_row: Some(row),
                            rows_per_image: Some(height),
                        },
                    },
                    wgpu::Extent3d {
                        width,
                        height,
                        depth_or_array_layers: 1,
                    },
                );
            }
            encoder.copy_buffer_to_buffer(
                &screen.occlusion,
                0,
                &staging,
                gtao_at,
                4 * pixels as u64,
            );
            let submission = gpu.queue.submit(Some(encoder.finish()));
            if let Some(e) = scope.pop() {
                return Err(GpuError::Pipeline(e.to_string()));
            }
            let bytes = gpu.read(&staging, submission)?;
            let texels = |k: usize| -> Vec<[f32; 4]> {
                (0..height as usize)
                    .flat_map(|y| {
                        let at = offsets[k] as usize + y * row as usize;
                        bytes[at..at + 16 * width as usize].chunks_exact(16)
                    })
                    .map(bytemuck::pod_read_unaligned::<[f32; 4]>)
                    .collect()
            };
            let position = texels(0);
            let normal = texels(1);
            // The position's last word: the surface in its low 2 bits,
            // the model's AO in 20-bit fixed point above; the normal's
            // last word: the truth's f32 bits.
            let word = |p: &[f32; 4]| p[3].to_bits();
            out.push(ScreenFrame {
                width,
                height,
                positions: position
                    .iter()
                    .map(|p| Vec3::new(p[0], p[1], p[2]))
                    .collect(),
                surfaces: position
                    .iter()
                    .map(|p| Surface::from_code(word(p) & 3))
                    .collect(),
                normals: normal.iter().map(|n| Vec3::new(n[0], n[1], n[2])).collect(),
                truth: normal.iter().map(|n| n[3]).collect(),
                model: position
                    .iter()
                    .map(|p| (word(p) >> 2) as f32 / 1_048_575.0)
                    .collect(),
                gtao: bytemuck::pod_collect_to_vec::<u8, f32>(&bytes[gtao_at as usize..]),
                gtao_ms,
                model_ms,
            });
        }
        Ok(out)
    }
}

impl Renderer for PreviewRenderer<'_> {
    fn adapter(&self) -> String {
        self.gpu.label()
    }

    fn render(
        &mut self,
        scene: &RenderScene<'_>,
        frames: &[RenderFrame],
        panels: &[Panel],
    ) -> Result<Vec<Image>, String> {
        self.render_frames(scene, frames, panels)
            .map_err(|e| e.to_string())
    }

    fn screen_space(
        &mut self,
        scene: &RenderScene<'_>,
        frames: &[RenderFrame],
    ) -> Result<Vec<ScreenFrame>, String> {
        self.screen_frames(scene, frames).map_err(|e| e.to_string())
    }
}
