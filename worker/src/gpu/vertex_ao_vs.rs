//! The vertex-stage evaluators: what a WebGL2 engine (GLSL ES 3.00, no
//! compute shaders) runs, with every array in an R32Uint texture.
//! [`evaluate_vertex_stage`] runs `shaders/wgsl/vertex_ao_vs.wgsl`,
//! [`cubemap_vertex_stage`] `cubemap_ao_vs.wgsl` and [`grid_vertex_stage`]
//! `grid_ao_vs.wgsl`. Each draws element n as a point at pixel
//! (n % width, n / width) of an R32Uint target (its value's bits) and
//! reads the target back ([`draw_points`]), so that tests compare it with
//! the compute shaders and the CPU.

use aobake_core::method::{
    cubemap::{gpu::CubemapGpu, model::CubemapModel},
    grid::{gpu::GridGpu, model::GridModel},
    vertex::{Model, form::GpuArrays},
};
use aobake_shaders::{CubemapAoParams, GridAoParams, VS_TEXTURE_WIDTH, VertexAoVsParams};
use glam::Vec3;
use wgpu::util::DeviceExt as _;

use super::{
    ErrorScopes, Gpu, GpuError,
    vertex_ao::{to_u32, upload},
};

/// One resource of a point draw, at its WGSL binding in group 0.
enum Resource<'a> {
    /// A uniform buffer's bytes.
    Uniform(&'a [u8]),
    /// An R32Uint data texture's words.
    Words(&'a [u32]),
}

/// A data texture of `words`, [`VS_TEXTURE_WIDTH`] texels wide (element i
/// at (i % width, i / width)), R32Uint.
fn data_texture(gpu: &Gpu, label: &str, words: &[u32]) -> Result<wgpu::TextureView, GpuError> {
    let width = VS_TEXTURE_WIDTH;
    let height = to_u32(words.len().div_ceil(width as usize).max(1), label)?;
    if height > gpu.device.limits().max_texture_dimension_2d {
        return Err(GpuError::TooLarge(format!(
            "{label}: {} words need a texture {height} texels high",
            words.len()
        )));
    }
    let mut padded = words.to_vec();
    padded.resize((width * height) as usize, 0);
    let texture = gpu.device.create_texture_with_data(
        &gpu.queue,
        &wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::R32Uint,
            usage: wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        },
        wgpu::util::TextureDataOrder::LayerMajor,
        bytemuck::cast_slice(&padded),
    );
    Ok(texture.create_view(&wgpu::TextureViewDescriptor::default()))
}

/// The target's size for `count` points: [`VS_TEXTURE_WIDTH`] wide at
/// most.
fn target_size(count: u32) -> (u32, u32) {
    let width = count.clamp(1, VS_TEXTURE_WIDTH);
    (width, count.div_ceil(width).max(1))
}

/// The format of the target the points are drawn into.
const TARGET_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;

/// `source`'s point-drawing pipeline, built once per [`Gpu`]: compiled
/// outside the cache's lock (seconds on a software adapter), and kept
/// only when it compiled, so that a rejected shader says why every time.
fn point_pipeline(
    gpu: &Gpu,
    label: &str,
    source: &'static str,
) -> Result<wgpu::RenderPipeline, GpuError> {
    let built = || {
        gpu.point_pipelines
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    };
    if let Some(pipeline) = built().get(source) {
        return Ok(pipeline.clone());
    }
    let device = &gpu.device;
    let scope = ErrorScopes::push(device);
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: None,
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs_main"),
            compilation_options: wgpu::PipelineCompilationOptions::default(),
            buffers: &[],
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::PointList,
            ..wgpu::PrimitiveState::default()
        },
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some("fs_main"),
            compilation_options: wgpu::PipelineCompilationOptions::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format: TARGET_FORMAT,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    });
    if let Some(e) = scope.pop() {
        return Err(GpuError::Pipeline(e.to_string()));
    }
    Ok(built().entry(source).or_insert(pipeline).clone())
}

/// Draws points `0..count` with `source`'s `vs_main` and `fs_main` (the
/// entry points of common/point_target.wgsl) and `resources` bound, and
/// reads each point's value back.
fn draw_points(
    gpu: &Gpu,
    label: &str,
    source: &'static str,
    resources: &[(u32, Resource<'_>)],
    count: u32,
) -> Result<Vec<f32>, GpuError> {
    let device = &gpu.device;
    let scope = ErrorScopes::push(device);
    let (target_width, target_height) = target_size(count);
    enum Bound {
        Buffer(wgpu::Buffer),
        View(wgpu::TextureView),
    }
    let mut bound = Vec::with_capacity(resources.len());
    for (binding, resource) in resources {
        bound.push((
            *binding,
            match resource {
                Resource::Uniform(bytes) => Bound::Buffer(device.create_buffer_init(
                    &wgpu::util::BufferInitDescriptor {
                        label: Some(label),
                        contents: bytes,
                        usage: wgpu::BufferUsages::UNIFORM,
                    },
                )),
                Resource::Words(words) => Bound::View(data_texture(gpu, label, words)?),
            },
        ));
    }
    let pipeline = point_pipeline(gpu, label, source)?;
    let entries: Vec<wgpu::BindGroupEntry<'_>> = bound
        .iter()
        .map(|(binding, b)| wgpu::BindGroupEntry {
            binding: *binding,
            resource: match b {
                Bound::Buffer(buffer) => buffer.as_entire_binding(),
                Bound::View(view) => wgpu::BindingResource::TextureView(view),
            },
        })
        .collect();
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &entries,
    });
    // A pixel no point reached reads as a NaN.
    let clear = wgpu::Color {
        r: f64::from(u32::MAX),
        g: 0.0,
        b: 0.0,
        a: 0.0,
    };
    let bytes = gpu.draw_and_read(
        label,
        &pipeline,
        &bind_group,
        TARGET_FORMAT,
        (target_width, target_height),
        clear,
        0..count,
    );
    if let Some(e) = scope.pop() {
        return Err(GpuError::Pipeline(e.to_string()));
    }
    Ok(bytemuck::pod_collect_to_vec::<u8, f32>(&bytes?)[..count as usize].to_vec())
}

/// The data layout uniform of the cubemap and grid vertex stages
/// (`DataLayout` of common/data_textures.wgsl) for `count` points.
fn data_layout(count: u32) -> [u32; 4] {
    let (width, height) = target_size(count);
    [VS_TEXTURE_WIDTH, width, height, 0]
}

/// AO of every vertex of `model` for one pose's `weights`
/// ([`Model::weights`]), computed by the vertex-stage evaluator.
pub fn evaluate_vertex_stage(
    gpu: &Gpu,
    model: &Model,
    weights: &[f32],
) -> Result<Vec<f32>, GpuError> {
    let arrays = upload(model)?;
    let GpuArrays {
        vertices,
        weights: want,
        ..
    } = arrays;
    if weights.len() != want {
        return Err(GpuError::TooLarge(format!(
            "{} weights given, the model takes {want}",
            weights.len()
        )));
    }
    let (target_width, target_height) = target_size(vertices);
    let params = VertexAoVsParams {
        vertices,
        blocks: to_u32(arrays.blocks.len(), "blocks")?,
        sparse: u32::from(arrays.sparse),
        width: VS_TEXTURE_WIDTH,
        target_width,
        target_height,
        _pad: [0; 2],
    };
    let weight_bits: Vec<u32> = weights.iter().map(|w| w.to_bits()).collect();
    let blocks: &[u32] = bytemuck::cast_slice(&arrays.blocks);
    draw_points(
        gpu,
        "vertex_ao_vs.wgsl",
        aobake_shaders::VERTEX_AO_VS,
        &[
            (0, Resource::Uniform(bytemuck::bytes_of(&params))),
            (1, Resource::Words(blocks)),
            (2, Resource::Words(&arrays.coefficients)),
            (3, Resource::Words(&arrays.maps)),
            (4, Resource::Words(&weight_bits)),
            (5, Resource::Words(&arrays.sparse_rows)),
        ],
        vertices,
    )
}

/// The occlusion `model` casts at `points` at `phase` (with `on_ground`,
/// on the ground plane: its static ground applies), computed by the
/// cubemap's vertex-stage lookup.
pub fn cubemap_vertex_stage(
    gpu: &Gpu,
    model: &CubemapModel,
    points: &[Vec3],
    phase: f32,
    on_ground: bool,
) -> Result<Vec<f32>, GpuError> {
    let form = CubemapGpu::new(model).map_err(|e| GpuError::TooLarge(e.to_string()))?;
    let count = to_u32(points.len(), "points")?;
    let params = CubemapAoParams {
        points: count,
        phase,
        on_ground: u32::from(on_ground),
        ..super::cubemap_ao::params(&form)
    };
    let xyz: Vec<u32> = points
        .iter()
        .flat_map(|p| p.to_array().map(f32::to_bits))
        .collect();
    draw_points(
        gpu,
        "cubemap_ao_vs.wgsl",
        aobake_shaders::CUBEMAP_AO_VS,
        &[
            (0, Resource::Uniform(bytemuck::bytes_of(&params))),
            (1, Resource::Words(&form.texels)),
            (
                2,
                Resource::Uniform(bytemuck::bytes_of(&data_layout(count))),
            ),
            (3, Resource::Words(&xyz)),
            (4, Resource::Words(&form.ground)),
        ],
        count,
    )
}

/// The occlusion `model`'s parts at `poses` ([`super::grid_ao::POSE_FLOATS`]
/// per part) cast on `receivers` (grid_ao.wgsl's `Receiver`s), computed by
/// the grid's vertex-stage lookup.
pub fn grid_vertex_stage(
    gpu: &Gpu,
    model: &GridModel,
    poses: &[f32],
    receivers: &[aobake_shaders::GridReceiver],
) -> Result<Vec<f32>, GpuError> {
    let form = GridGpu::new(model).map_err(|e| GpuError::TooLarge(e.to_string()))?;
    let count = to_u32(receivers.len(), "receivers")?;
    let params = GridAoParams {
        points: count,
        ..super::grid_ao::params(&form)
    };
    let infos: &[u32] = bytemuck::cast_slice(&form.infos);
    let pose_bits: Vec<u32> = poses.iter().map(|p| p.to_bits()).collect();
    draw_points(
        gpu,
        "grid_ao_vs.wgsl",
        aobake_shaders::GRID_AO_VS,
        &[
            (0, Resource::Uniform(bytemuck::bytes_of(&params))),
            (1, Resource::Words(infos)),
            (2, Resource::Words(&form.cells)),
            (3, Resource::Words(&pose_bits)),
            (
                4,
                Resource::Uniform(bytemuck::bytes_of(&data_layout(count))),
            ),
            (5, Resource::Words(bytemuck::cast_slice(receivers))),
        ],
        count,
    )
}
