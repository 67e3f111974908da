//! Core's preview [`Renderer`] on wgpu: `shaders/wgsl/preview.wgsl` draws
//! the posed character and a ground plane into a multisampled sRGB target,
//! the model's AO computed per frame into a buffer that the raster reads
//! as a vertex attribute (the AO never leaves the GPU), and the resolved
//! image read back. A vertex model is evaluated on the character by
//! [`VertexAo`]; a cubemap is looked up on the ground's vertices by
//! [`CubemapAo`] at the frame's phase.

use aobake_core::bake::{Camera, Panel, PreviewModel, RenderFrame, RenderScene, Renderer};
use aobake_core::image::{HeatMap, Image};
use aobake_core::method::grid::{base::Receiver, model::GridModel};
use aobake_shaders::{GridReceiver, PreviewUniforms};
use glam::Vec3;
use wgpu::util::DeviceExt as _;

use super::{CubemapAo, Gpu, GpuError, GridAo, VertexAo};

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

/// The preview pipeline on one [`Gpu`].
#[derive(Debug)]
pub struct PreviewRenderer<'g> {
    gpu: &'g Gpu,
    pipeline: wgpu::RenderPipeline,
    samples: u32,
}

impl<'g> PreviewRenderer<'g> {
    /// Builds the pipeline: 4× multisampling where the adapter has it for
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
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("preview.wgsl"),
            source: wgpu::ShaderSource::Wgsl(aobake_shaders::PREVIEW.into()),
        });
        let attribute = |location, format| {
            [wgpu::VertexAttribute {
                format,
                offset: 0,
                shader_location: location,
            }]
        };
        let attributes = [
            attribute(0, wgpu::VertexFormat::Float32x3),
            attribute(1, wgpu::VertexFormat::Float32x3),
            attribute(2, wgpu::VertexFormat::Float32),
            attribute(3, wgpu::VertexFormat::Float32),
        ];
        let buffers: Vec<Option<wgpu::VertexBufferLayout<'_>>> = attributes
            .iter()
            .enumerate()
            .map(|(i, a)| {
                Some(wgpu::VertexBufferLayout {
                    array_stride: if i < 2 { 12 } else { 4 },
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: a,
                })
            })
            .collect();
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("preview"),
            layout: None,
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &buffers,
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
                count: samples,
                ..Default::default()
            },
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(COLOR.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Pipeline(e.to_string()));
        }
        Ok(Self {
            gpu,
            pipeline,
            samples,
        })
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
            Panel::Model => 1,
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
}

/// Vertex buffers of one surface.
struct Mesh {
    positions: wgpu::Buffer,
    normals: wgpu::Buffer,
    truth: wgpu::Buffer,
    model: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
}

impl Mesh {
    fn draw(&self, pass: &mut wgpu::RenderPass<'_>) {
        pass.set_vertex_buffer(0, self.positions.slice(..));
        pass.set_vertex_buffer(1, self.normals.slice(..));
        pass.set_vertex_buffer(2, self.truth.slice(..));
        pass.set_vertex_buffer(3, self.model.slice(..));
        pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..self.index_count, 0, 0..1);
    }
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

impl PreviewRenderer<'_> {
    fn render_frames(
        &self,
        scene: &RenderScene<'_>,
        frames: &[RenderFrame],
        panels: &[Panel],
    ) -> Result<Vec<Image>, GpuError> {
        let gpu = self.gpu;
        let device = &gpu.device;
        let (width, height) = scene.size;
        let vertices = match scene.model {
            PreviewModel::Vertex(m) => m.vertices(),
            PreviewModel::Cubemap(..) | PreviewModel::Grid(..) => {
                frames.first().map_or(0, |f| f.positions.len())
            }
        };
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
        }
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
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
        };
        let cubemap = matches!(evaluator, Evaluator::Cubemap(_));
        let grid = matches!(evaluator, Evaluator::Grid(..));
        use wgpu::BufferUsages as U;
        let dynamic = U::VERTEX | U::COPY_DST;
        let n = vertices.max(1) as u64;
        let buffer = |label, size, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        let indices: Vec<u32> = scene.triangles.iter().flatten().copied().collect();
        let truth = buffer("truth", 4 * n, dynamic);
        let character = Mesh {
            positions: buffer("positions", 12 * n, dynamic),
            normals: buffer("normals", 12 * n, dynamic),
            // A cubemap does not shade the character: ray-traced in both.
            model: if cubemap {
                truth.clone()
            } else {
                buffer("model ao", 4 * n, U::VERTEX | U::STORAGE)
            },
            truth,
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
        let g = scene.ground;
        let ground_n = g.positions.len().max(1) as u64;
        let ground_ao = buffer("ground ao", 4 * ground_n, dynamic);
        let ground_model = if cubemap || grid {
            buffer("ground model ao", 4 * ground_n, U::VERTEX | U::STORAGE)
        } else {
            ground_ao.clone()
        };
        // The grids' receivers: the character's (rewritten every frame)
        // and the ground's (fixed).
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
            truth: ground_ao.clone(),
            model: ground_model.clone(),
            indices: init(
                device,
                "ground indices",
                bytemuck::cast_slice(&ground_indices),
                U::INDEX,
            ),
            index_count: ground_indices.len() as u32,
        };
        let layout = self.pipeline.get_bind_group_layout(0);
        let bind = |panel: Panel, on_ground: bool| {
            let u = init(
                device,
                "uniforms",
                bytemuck::bytes_of(&Self::uniforms(scene, panel, on_ground)),
                U::UNIFORM,
            );
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("preview"),
                layout: &layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: u.as_entire_binding(),
                }],
            })
        };
        let groups: Vec<(wgpu::BindGroup, wgpu::BindGroup)> = panels
            .iter()
            .map(|&p| (bind(p, false), bind(p, true)))
            .collect();
        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let texture = |label, format, samples, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size,
                mip_level_count: 1,
                sample_count: samples,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
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
        let staging = buffer(
            "preview readback",
            panel_bytes * panels.len().max(1) as u64,
            U::MAP_READ | U::COPY_DST,
        );
        let bg = look::BACKGROUND.map(f64::from);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Pipeline(e.to_string()));
        }
        let mut images = Vec::with_capacity(frames.len() * panels.len());
        for frame in frames {
            let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
            gpu.queue.write_buffer(
                &character.positions,
                0,
                bytemuck::cast_slice(&frame.positions),
            );
            gpu.queue
                .write_buffer(&character.normals, 0, bytemuck::cast_slice(&frame.normals));
            gpu.queue
                .write_buffer(&character.truth, 0, bytemuck::cast_slice(&frame.truth));
            if frame.ground_ao.len() != g.positions.len() {
                return Err(GpuError::TooLarge(format!(
                    "{} ground values for {} ground vertices",
                    frame.ground_ao.len(),
                    g.positions.len()
                )));
            }
            gpu.queue
                .write_buffer(&ground_ao, 0, bytemuck::cast_slice(&frame.ground_ao));
            let mut encoder =
                device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
            match &evaluator {
                Evaluator::Vertex(e) => e.record(&mut encoder, &frame.weights, &character.model)?,
                Evaluator::Cubemap(e) => e.record(
                    &mut encoder,
                    &ground_positions,
                    g.positions.len() as u32,
                    frame.phase,
                    true,
                    &ground_model,
                )?,
                Evaluator::Grid(e, model, owners) => {
                    let (on_character, on_ground) = receivers
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
                    gpu.queue
                        .write_buffer(on_character, 0, bytemuck::cast_slice(&mine));
                    e.record(
                        &mut encoder,
                        &frame.weights,
                        on_character,
                        vertices as u32,
                        &character.model,
                    )?;
                    e.record(
                        &mut encoder,
                        &frame.weights,
                        on_ground,
                        g.positions.len() as u32,
                        &ground_model,
                    )?;
                }
            }
            for (k, (on_character, on_ground)) in groups.iter().enumerate() {
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
                        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                            view: &depth,
                            depth_ops: Some(wgpu::Operations {
                                load: wgpu::LoadOp::Clear(1.0),
                                store: wgpu::StoreOp::Discard,
                            }),
                            stencil_ops: None,
                        }),
                        timestamp_writes: None,
                        occlusion_query_set: None,
                        multiview_mask: None,
                    });
                    pass.set_pipeline(&self.pipeline);
                    pass.set_bind_group(0, on_ground, &[]);
                    ground.draw(&mut pass);
                    pass.set_bind_group(0, on_character, &[]);
                    character.draw(&mut pass);
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
            if let Some(e) = pollster::block_on(scope.pop()) {
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
}
