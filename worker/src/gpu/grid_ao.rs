//! [`GridAo`] runs `shaders/wgsl/grid_ao.wgsl`, the run-time lookup of
//! Malmer et al.'s grids, so that what engines run is tested against
//! core's CPU lookup, and the previews shade the parts and the ground with
//! the grids as the GPU evaluates them.

use aobake_core::method::grid::{gpu::GridGpu, model::GridModel};
use aobake_shaders::{GridAoParams, GridPartInfo, GridReceiver};
use wgpu::util::DeviceExt as _;

use super::{ErrorScopes, Gpu, GpuError, dispatch_grid};

/// Floats per part in a frame's poses (two column-major 4 × 4 matrices).
pub const POSE_FLOATS: usize = aobake_core::bake::preview::GRID_POSE_FLOATS;

/// A grid set's cells uploaded once; each [`GridAo::record`] then uploads
/// the parts' poses and costs one dispatch.
#[derive(Debug)]
pub struct GridAo<'g> {
    gpu: &'g Gpu,
    pipeline: wgpu::ComputePipeline,
    infos: wgpu::Buffer,
    cells: wgpu::Buffer,
    base: GridAoParams,
}

/// The `Params` uniform of grids' GPU form, with no receivers yet
/// (`points` and `row_stride` are set per dispatch).
pub(super) fn params(form: &GridGpu) -> GridAoParams {
    GridAoParams {
        parts: form.parts(),
        points: 0,
        row_stride: 0,
        cones: form.cones,
        tclip_resolution: form.tclip_resolution,
        tclip_offset: form.tclip_offset,
        base: form.base,
        ground_gain: form.ground_gain,
    }
}

impl<'g> GridAo<'g> {
    /// Uploads the model's cells (one u32 a cell, RGBA8) and `T_clip`, and
    /// builds the pipeline.
    pub fn new(gpu: &'g Gpu, model: &GridModel) -> Result<Self, GpuError> {
        let device = &gpu.device;
        let arrays = GridGpu::new(model).map_err(|e| GpuError::TooLarge(e.to_string()))?;
        let cells = &arrays.cells;
        let infos: Vec<GridPartInfo> = arrays
            .infos
            .iter()
            .map(|i| GridPartInfo {
                resolution: i[0],
                offset: i[1],
                gain: i[2],
                _pad: 0,
            })
            .collect();
        let limit = device.limits().max_storage_buffer_binding_size;
        if 4 * cells.len() as u64 > limit {
            return Err(GpuError::TooLarge(format!(
                "{} bytes of cells, over the adapter's storage binding limit of {limit}",
                4 * cells.len()
            )));
        }
        let base = params(&arrays);
        let scope = ErrorScopes::push(device);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("grid_ao.wgsl"),
            source: wgpu::ShaderSource::Wgsl(aobake_shaders::GRID_AO.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("grid ao"),
            layout: None,
            module: &module,
            entry_point: Some("cs_main"),
            compilation_options: wgpu::PipelineCompilationOptions::default(),
            cache: None,
        });
        let storage = |label, bytes: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: if bytes.is_empty() { &[0u8; 16] } else { bytes },
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let infos = storage("grid parts", bytemuck::cast_slice(&infos));
        let cells = storage("grid cells", bytemuck::cast_slice(cells));
        if let Some(e) = scope.pop() {
            return Err(GpuError::Pipeline(e.to_string()));
        }
        Ok(Self {
            gpu,
            pipeline,
            infos,
            cells,
            base,
        })
    }

    /// Records the lookup of `count` receivers (`receivers`: a `STORAGE`
    /// buffer of [`GridReceiver`]) with the parts at `poses`
    /// ([`POSE_FLOATS`] per part, `aobake_core::bake::preview::grid_weights`)
    /// into `encoder`, one f32 each into `out` (a `STORAGE` buffer a render
    /// pass can then read as a vertex buffer).
    pub fn record(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        poses: &[f32],
        receivers: &wgpu::Buffer,
        count: u32,
        out: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        let device = &self.gpu.device;
        if poses.len() != POSE_FLOATS * self.base.parts as usize {
            return Err(GpuError::TooLarge(format!(
                "{} pose floats for {} parts",
                poses.len(),
                self.base.parts
            )));
        }
        let needed = count.div_ceil(aobake_shaders::WORKGROUP_SIZE).max(1);
        let Some(groups) = dispatch_grid(needed) else {
            return Err(GpuError::TooLarge(format!("{count} receivers")));
        };
        let params = GridAoParams {
            points: count,
            row_stride: groups.0 * aobake_shaders::WORKGROUP_SIZE,
            ..self.base
        };
        let init = |label, bytes: &[u8], usage| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: if bytes.is_empty() { &[0u8; 128] } else { bytes },
                usage,
            })
        };
        let params = init(
            "grid params",
            bytemuck::bytes_of(&params),
            wgpu::BufferUsages::UNIFORM,
        );
        let poses = init(
            "grid poses",
            bytemuck::cast_slice(poses),
            wgpu::BufferUsages::STORAGE,
        );
        let layout = self.pipeline.get_bind_group_layout(0);
        let entries = [&params, &self.infos, &self.cells, &poses, receivers, out];
        let entries: Vec<wgpu::BindGroupEntry<'_>> = entries
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("grid ao"),
            layout: &layout,
            entries: &entries,
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("grid ao"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(groups.0, groups.1, 1);
        Ok(())
    }

    /// Occlusion at every receiver with the parts at `poses`, read back.
    pub fn evaluate(
        &self,
        receivers: &[GridReceiver],
        poses: &[f32],
    ) -> Result<Vec<f32>, GpuError> {
        let count = u32::try_from(receivers.len())
            .map_err(|_| GpuError::TooLarge(format!("{} receivers", receivers.len())))?;
        self.gpu.evaluate_batch(
            bytemuck::cast_slice(receivers),
            receivers.len(),
            |encoder, input, out| self.record(encoder, poses, input, count, out),
        )
    }
}
