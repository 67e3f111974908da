//! [`VertexAo`] runs `shaders/wgsl/vertex_ao.wgsl`, the run-time evaluation
//! of the vertex methods, so that what engines will run is tested against
//! core's CPU evaluation, and the previews shade with the model's AO as
//! the GPU computes it.

use aobake_core::method::vertex::{
    Model,
    form::{BLOCK_WORDS, GpuArrays},
};
use aobake_shaders::VertexAoParams;
use wgpu::util::DeviceExt as _;

use super::{ErrorScopes, Gpu, GpuError, dispatch_grid};

/// A model's coefficients uploaded once; [`VertexAo::evaluate`] then costs
/// one weight upload, one dispatch and one readback per pose.
#[derive(Debug)]
pub struct VertexAo<'g> {
    gpu: &'g Gpu,
    pipeline: wgpu::ComputePipeline,
    params: wgpu::Buffer,
    blocks: wgpu::Buffer,
    coefficients: wgpu::Buffer,
    maps: wgpu::Buffer,
    sparse_rows: wgpu::Buffer,
    sparse: bool,
    vertices: u32,
    weights: usize,
    groups: (u32, u32),
}

/// A model's arrays as the evaluators read them (the runtime's packing).
pub(super) fn upload(model: &Model) -> Result<GpuArrays, GpuError> {
    GpuArrays::new(model.form()).map_err(|e| GpuError::TooLarge(e.to_string()))
}

/// The compute entry point for `arrays`.
pub(super) fn entry(arrays: &GpuArrays) -> &'static str {
    if arrays.sparse {
        "cs_sparse"
    } else {
        "cs_main"
    }
}

pub(super) fn to_u32(n: usize, what: &str) -> Result<u32, GpuError> {
    u32::try_from(n).map_err(|_| GpuError::TooLarge(format!("{what}: {n}")))
}

impl<'g> VertexAo<'g> {
    /// Uploads the model's coefficients and builds the pipeline.
    pub fn new(gpu: &'g Gpu, model: &Model) -> Result<Self, GpuError> {
        let arrays = upload(model)?;
        let entry = entry(&arrays);
        let GpuArrays {
            vertices,
            weights,
            blocks,
            coefficients,
            maps,
            sparse_rows,
            ..
        } = arrays;
        let device = &gpu.device;
        let Some(groups) = dispatch_grid(vertices.div_ceil(aobake_shaders::WORKGROUP_SIZE).max(1))
        else {
            return Err(GpuError::TooLarge(format!("{vertices} vertices")));
        };
        let params = VertexAoParams {
            vertices,
            blocks: to_u32(blocks.len(), "blocks")?,
            row_stride: groups.0 * aobake_shaders::WORKGROUP_SIZE,
            _pad: 0,
        };
        // Every buffer must fit one storage binding; the shader indexes
        // coefficients as u32 f16 elements.
        let limit = device.limits().max_storage_buffer_binding_size;
        for (what, words) in [
            ("coefficients", coefficients.len()),
            ("maps", maps.len()),
            ("sparse rows", sparse_rows.len()),
            ("vertices", vertices as usize),
            ("weights", weights),
        ] {
            let bytes = 4 * words as u64;
            if bytes > limit {
                return Err(GpuError::TooLarge(format!(
                    "{what} take {bytes} bytes, over the adapter's storage binding limit of {limit}"
                )));
            }
        }
        let scope = ErrorScopes::push(device);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("vertex_ao.wgsl"),
            source: wgpu::ShaderSource::Wgsl(aobake_shaders::VERTEX_AO.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry),
            layout: None,
            module: &module,
            entry_point: Some(entry),
            compilation_options: wgpu::PipelineCompilationOptions::default(),
            cache: None,
        });
        let storage = |label, data: &[u32]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::cast_slice(data),
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let blocks = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("blocks"),
            contents: bytemuck::cast_slice(&if blocks.is_empty() {
                vec![[0; BLOCK_WORDS]]
            } else {
                blocks
            }),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let out = Self {
            gpu,
            pipeline,
            params,
            blocks,
            coefficients: storage("coefficients", &coefficients),
            maps: storage("maps", &maps),
            sparse_rows: storage("sparse rows", &sparse_rows),
            sparse: entry == "cs_sparse",
            vertices,
            weights,
            groups,
        };
        if let Some(e) = scope.pop() {
            return Err(GpuError::Pipeline(e.to_string()));
        }
        Ok(out)
    }

    /// Vertices the model evaluates.
    pub fn vertices(&self) -> u32 {
        self.vertices
    }

    /// Records the evaluation of one pose's weights ([`Model::weights`])
    /// into `encoder`, writing one f32 per vertex to `ao` (a buffer with
    /// `STORAGE` usage of at least `4 × vertices` bytes), where a render
    /// pass can read it as a vertex buffer without a round trip.
    pub fn record(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        weights: &[f32],
        ao: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        if weights.len() != self.weights {
            return Err(GpuError::TooLarge(format!(
                "{} weights given, the model takes {}",
                weights.len(),
                self.weights
            )));
        }
        let device = &self.gpu.device;
        let weights = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("weights"),
            contents: bytemuck::cast_slice(if weights.is_empty() {
                &[0.0f32][..]
            } else {
                weights
            }),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let layout = self.pipeline.get_bind_group_layout(0);
        fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
            wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            }
        }
        // Auto layouts hold only the bindings the entry point uses.
        let entries: Vec<wgpu::BindGroupEntry<'_>> = if self.sparse {
            vec![
                entry(0, &self.params),
                entry(2, &self.coefficients),
                entry(3, &self.maps),
                entry(4, &weights),
                entry(5, ao),
                entry(6, &self.sparse_rows),
            ]
        } else {
            vec![
                entry(0, &self.params),
                entry(1, &self.blocks),
                entry(2, &self.coefficients),
                entry(3, &self.maps),
                entry(4, &weights),
                entry(5, ao),
            ]
        };
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("vertex ao"),
            layout: &layout,
            entries: &entries,
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("vertex ao"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(self.groups.0, self.groups.1, 1);
        Ok(())
    }

    /// AO of every vertex for one pose's weights ([`Model::weights`]),
    /// read back.
    pub fn evaluate(&self, weights: &[f32]) -> Result<Vec<f32>, GpuError> {
        assert_eq!(weights.len(), self.weights, "one weight per row");
        let device = &self.gpu.device;
        let scope = ErrorScopes::push(device);
        let size = 4 * u64::from(self.vertices.max(1));
        let ao = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ao"),
            size,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ao readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        self.record(&mut encoder, weights, &ao)?;
        encoder.copy_buffer_to_buffer(&ao, 0, &staging, 0, size);
        let submission = self.gpu.queue.submit(Some(encoder.finish()));
        if let Some(e) = scope.pop() {
            return Err(GpuError::Pipeline(e.to_string()));
        }
        let bytes = self.gpu.read(&staging, submission)?;
        Ok(bytemuck::cast_slice::<u8, f32>(&bytes)[..self.vertices as usize].to_vec())
    }
}
