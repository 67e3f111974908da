//! [`CubemapAo`] runs `shaders/wgsl/cubemap_ao.wgsl`, the run-time lookup
//! of Kroon's cubemaps, so that what engines run is tested against core's
//! CPU lookup, and the previews shade the ground with the cubemap as the
//! GPU evaluates it.

use aobake_core::method::cubemap::{gpu::CubemapGpu, model::CubemapModel};
use aobake_shaders::CubemapAoParams;
use wgpu::util::DeviceExt as _;

use super::{ErrorScopes, Gpu, GpuError, dispatch_grid};

/// A cubemap's texels uploaded once; each [`CubemapAo::record`] then costs
/// one small uniform and one dispatch.
#[derive(Debug)]
pub struct CubemapAo<'g> {
    gpu: &'g Gpu,
    pipeline: wgpu::ComputePipeline,
    texels: wgpu::Buffer,
    ground: wgpu::Buffer,
    base: CubemapAoParams,
}

/// The `Params` uniform of a cubemap's GPU form, with no points yet
/// (`points`, `phase` and `row_stride` are set per dispatch).
pub(super) fn params(form: &CubemapGpu) -> CubemapAoParams {
    CubemapAoParams {
        centre: form.centre,
        radii: form.radii,
        resolution: form.resolution,
        shells: form.shells,
        times: form.times,
        encoding: form.encoding,
        points: 0,
        phase: 0.0,
        row_stride: 0,
        on_ground: 0,
    }
}

impl<'g> CubemapAo<'g> {
    /// Uploads the model's texels and builds the pipeline.
    pub fn new(gpu: &'g Gpu, model: &CubemapModel) -> Result<Self, GpuError> {
        let device = &gpu.device;
        let limit = device.limits().max_storage_buffer_binding_size;
        if model.texels.len() as u64 > limit {
            return Err(GpuError::TooLarge(format!(
                "{} bytes of texels, over the adapter's storage binding limit of {limit}",
                model.texels.len()
            )));
        }
        let gpu_form = CubemapGpu::new(model).map_err(|e| GpuError::TooLarge(e.to_string()))?;
        let base = params(&gpu_form);
        let scope = ErrorScopes::push(device);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("cubemap_ao.wgsl"),
            source: wgpu::ShaderSource::Wgsl(aobake_shaders::CUBEMAP_AO.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("cubemap ao"),
            layout: None,
            module: &module,
            entry_point: Some("cs_main"),
            compilation_options: wgpu::PipelineCompilationOptions::default(),
            cache: None,
        });
        let texels = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("cubemap texels"),
            contents: bytemuck::cast_slice(&gpu_form.texels),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let ground = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("cubemap static ground"),
            contents: bytemuck::cast_slice(&gpu_form.ground),
            usage: wgpu::BufferUsages::STORAGE,
        });
        if let Some(e) = scope.pop() {
            return Err(GpuError::Pipeline(e.to_string()));
        }
        Ok(Self {
            gpu,
            pipeline,
            texels,
            ground,
            base,
        })
    }

    /// Records the lookup of `count` points (`points`: packed xyz f32, a
    /// `STORAGE` buffer) at `phase` into `encoder`, one f32 each into `out`
    /// (a `STORAGE` buffer a render pass can then read as a vertex
    /// buffer); `on_ground`: the points are on the ground plane, where the
    /// static ground applies (`CubemapModel::ground_ao`).
    pub fn record(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        points: &wgpu::Buffer,
        count: u32,
        phase: f32,
        on_ground: bool,
        out: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        let device = &self.gpu.device;
        let needed = count.div_ceil(aobake_shaders::WORKGROUP_SIZE).max(1);
        let Some(groups) = dispatch_grid(needed) else {
            return Err(GpuError::TooLarge(format!("{count} points")));
        };
        let params = CubemapAoParams {
            points: count,
            phase,
            row_stride: groups.0 * aobake_shaders::WORKGROUP_SIZE,
            on_ground: u32::from(on_ground),
            ..self.base
        };
        let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("cubemap params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let layout = self.pipeline.get_bind_group_layout(0);
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("cubemap ao"),
            layout: &layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: self.texels.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: points.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: out.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: self.ground.as_entire_binding(),
                },
            ],
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("cubemap ao"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(groups.0, groups.1, 1);
        Ok(())
    }

    /// Occlusion at every point at `phase`, read back.
    pub fn evaluate(
        &self,
        points: &[glam::Vec3],
        phase: f32,
        on_ground: bool,
    ) -> Result<Vec<f32>, GpuError> {
        let count = u32::try_from(points.len())
            .map_err(|_| GpuError::TooLarge(format!("{} points", points.len())))?;
        self.gpu.evaluate_batch(
            bytemuck::cast_slice(points),
            points.len(),
            |encoder, input, out| self.record(encoder, input, count, phase, on_ground, out),
        )
    }
}
