//! [`evaluate_vertex_stage`] runs `shaders/wgsl/vertex_ao_vs.wgsl`, the
//! vertex-method evaluation in a vertex shader with its arrays in
//! textures: what a WebGL2 engine (GLSL ES 3.00, no compute shaders) runs.
//! It draws vertex v as a point at pixel (v % width, v / width) of an
//! R32Uint target (the AO's bits) and reads the target back, so that tests compare it
//! with the compute shader and the CPU.

use aobake_core::method::vertex::{Model, form::GpuArrays};
use aobake_shaders::{VS_TEXTURE_WIDTH, VertexAoVsParams};
use wgpu::util::DeviceExt as _;

use super::{
    Gpu, GpuError,
    vertex_ao::{to_u32, upload},
};

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

/// AO of every vertex of `model` for one pose's `weights`
/// ([`Model::weights`]), computed by the vertex-stage evaluator.
pub fn evaluate_vertex_stage(
    gpu: &Gpu,
    model: &Model,
    weights: &[f32],
) -> Result<Vec<f32>, GpuError> {
    let arrays = upload(model)?;
    let sparse = arrays.sparse;
    let GpuArrays {
        vertices,
        weights: want,
        blocks,
        coefficients,
        maps,
        sparse_rows,
        ..
    } = arrays;
    if weights.len() != want {
        return Err(GpuError::TooLarge(format!(
            "{} weights given, the model takes {want}",
            weights.len()
        )));
    }
    let device = &gpu.device;
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let target_width = vertices.clamp(1, VS_TEXTURE_WIDTH);
    let target_height = vertices.div_ceil(target_width).max(1);
    let params = VertexAoVsParams {
        vertices,
        blocks: to_u32(blocks.len(), "blocks")?,
        sparse: u32::from(sparse),
        width: VS_TEXTURE_WIDTH,
        target_width,
        target_height,
        _pad: [0; 2],
    };
    let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("vertex ao vs params"),
        contents: bytemuck::bytes_of(&params),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let weight_bits: Vec<u32> = weights.iter().map(|w| w.to_bits()).collect();
    let views = [
        data_texture(gpu, "blocks", bytemuck::cast_slice(&blocks))?,
        data_texture(gpu, "coefficients", &coefficients)?,
        data_texture(gpu, "maps", &maps)?,
        data_texture(gpu, "weights", &weight_bits)?,
        data_texture(gpu, "sparse rows", &sparse_rows)?,
    ];
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("vertex_ao_vs.wgsl"),
        source: wgpu::ShaderSource::Wgsl(aobake_shaders::VERTEX_AO_VS.into()),
    });
    let format = wgpu::TextureFormat::R32Uint;
    let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("vertex ao vs"),
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
                format,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    });
    let mut entries = vec![wgpu::BindGroupEntry {
        binding: 0,
        resource: params.as_entire_binding(),
    }];
    for (i, view) in views.iter().enumerate() {
        entries.push(wgpu::BindGroupEntry {
            binding: i as u32 + 1,
            resource: wgpu::BindingResource::TextureView(view),
        });
    }
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("vertex ao vs"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &entries,
    });
    let size = wgpu::Extent3d {
        width: target_width,
        height: target_height,
        depth_or_array_layers: 1,
    };
    let target = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("vertex ao vs target"),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let view = target.create_view(&wgpu::TextureViewDescriptor::default());
    let row = (4 * target_width).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("vertex ao vs readback"),
        size: u64::from(row * target_height),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder =
        device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
    {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("vertex ao vs"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    // A pixel no vertex reached reads as a NaN.
                    load: wgpu::LoadOp::Clear(wgpu::Color {
                        r: f64::from(u32::MAX),
                        g: 0.0,
                        b: 0.0,
                        a: 0.0,
                    }),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.draw(0..vertices, 0..1);
    }
    encoder.copy_texture_to_buffer(
        target.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &staging,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(target_height),
            },
        },
        size,
    );
    let submission = gpu.queue.submit(Some(encoder.finish()));
    if let Some(e) = pollster::block_on(scope.pop()) {
        return Err(GpuError::Pipeline(e.to_string()));
    }
    let bytes = gpu.read(&staging, submission)?;
    let mut ao = Vec::with_capacity(vertices as usize);
    for v in 0..vertices {
        let (x, y) = (v % target_width, v / target_width);
        let at = (y * row + 4 * x) as usize;
        ao.push(f32::from_le_bytes(
            bytes[at..at + 4].try_into().expect("4 bytes"),
        ));
    }
    Ok(ao)
}
