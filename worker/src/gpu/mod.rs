//! wgpu on whatever adapter the machine has: a real GPU, or without one
//! Mesa's llvmpipe through EGL/GL or lavapipe through Vulkan (DESIGN §10).
//!
//! * [`Gpu`]: the adapter, device and queue (one per process, shared).
//! * [`VertexAo`] ([`vertex_ao`]): the vertex methods' run-time evaluation.
//! * [`CubemapAo`] ([`cubemap_ao`]): the cubemap methods' run-time lookup.
//! * [`GridAo`] ([`grid_ao`]): the grid method's run-time lookup.
//! * [`TexelAo`] ([`texel_ao`]): the texel methods' basis textures,
//!   sampled per pixel.
//! * [`GpuTracer`] ([`trace`]): core's ray estimators in compute, the
//!   same rays as the CPU tracer.
//! * [`PreviewRenderer`] ([`preview`]): core's preview [`Renderer`]
//!   (aobake_core::bake::Renderer) on wgpu.
//!
//! `WGPU_BACKEND` (`vulkan`, `gl`) picks the backend when set, as in
//! every wgpu program; by default Vulkan and GL are both tried and the
//! best adapter wins (a real GPU before a software one).

use std::{
    collections::HashMap,
    sync::{Mutex, OnceLock},
};

pub mod cubemap_ao;
pub mod grid_ao;
pub mod preview;
pub mod texel_ao;
pub mod trace;
pub mod vertex_ao;
pub mod vertex_ao_vs;

pub use cubemap_ao::CubemapAo;
pub use grid_ao::GridAo;
pub use preview::PreviewRenderer;
pub use texel_ao::TexelAo;
pub use trace::{GpuMode, GpuTracer};
pub use vertex_ao::VertexAo;
pub use vertex_ao_vs::{cubemap_vertex_stage, evaluate_vertex_stage, grid_vertex_stage};
pub use wgpu::{Backends, DeviceType};

/// Why the GPU could not be used.
#[derive(Debug, Clone, thiserror::Error)]
pub enum GpuError {
    /// No adapter (no GPU and no software driver).
    #[error("no GPU adapter: {0}")]
    NoAdapter(String),
    /// The adapter cannot run compute shaders.
    #[error("the adapter {0} has no compute shaders")]
    NoCompute(String),
    /// Device creation failed.
    #[error("cannot open the GPU device: {0}")]
    Device(String),
    /// A shader or pipeline was rejected.
    #[error("the GPU rejected a pipeline: {0}")]
    Pipeline(String),
    /// The model does not fit this adapter's limits.
    #[error("the model does not fit the GPU: {0}")]
    TooLarge(String),
    /// Reading results back failed.
    #[error("cannot read results back from the GPU: {0}")]
    Readback(String),
}

/// An adapter, its device and queue.
#[derive(Debug)]
pub struct Gpu {
    /// The adapter's description (name, backend, driver).
    pub info: wgpu::AdapterInfo,
    adapter: wgpu::Adapter,
    device: wgpu::Device,
    queue: wgpu::Queue,
    /// The vertex-stage evaluators' render pipelines by their shader's
    /// source, built on first use: a software adapter takes seconds to
    /// compile one, and the tests that compare these evaluators draw many
    /// times.
    point_pipelines: Mutex<HashMap<&'static str, wgpu::RenderPipeline>>,
}

impl Gpu {
    /// Opens the best adapter over Vulkan and GL (a real GPU before a
    /// software one), or over the backends `WGPU_BACKEND` names.
    pub fn new() -> Result<Self, GpuError> {
        pollster::block_on(Self::open(default_backends(), false, None))
    }

    /// The best adapter of these backends only (benches compare them).
    pub fn with_backends(backends: wgpu::Backends) -> Result<Self, GpuError> {
        pollster::block_on(Self::open(backends, false, None))
    }

    /// The software rasteriser only (lavapipe or llvmpipe), even on a
    /// machine with a GPU: the deterministic mode of the render tests,
    /// whose golden images were made on it, so that they compare the same
    /// rasterisation rules and arithmetic wherever they run.
    pub fn software() -> Result<Self, GpuError> {
        pollster::block_on(Self::open(default_backends(), true, None))
    }

    /// The process's adapter, opened on first use: a worker renders many
    /// previews and opening a device costs tens of milliseconds (seconds
    /// on some drivers).
    pub fn shared() -> Result<&'static Self, GpuError> {
        static GPU: OnceLock<Result<Gpu, GpuError>> = OnceLock::new();
        GPU.get_or_init(Self::new).as_ref().map_err(Clone::clone)
    }

    /// The adapter as a person reads it: name, backend and driver.
    pub fn label(&self) -> String {
        let i = &self.info;
        let driver = if i.driver_info.is_empty() {
            String::new()
        } else {
            format!(", {}", i.driver_info)
        };
        format!("{} ({:?}{driver})", i.name, i.backend)
    }

    /// The best adapter of these backends, with storage bindings limited
    /// to `bytes`: how the tests make a batch too large for its adapter.
    pub fn with_binding_limit(backends: wgpu::Backends, bytes: u64) -> Result<Self, GpuError> {
        pollster::block_on(Self::open(backends, false, Some(bytes)))
    }

    async fn open(
        backends: wgpu::Backends,
        software: bool,
        binding_limit: Option<u64>,
    ) -> Result<Self, GpuError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends,
            flags: wgpu::InstanceFlags::empty(),
            ..wgpu::InstanceDescriptor::new_without_display_handle()
        });
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                force_fallback_adapter: software,
                compatible_surface: None,
                ..Default::default()
            })
            .await
            .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let label = format!("{} ({:?})", info.name, info.backend);
        if !adapter
            .get_downlevel_capabilities()
            .flags
            .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
        {
            return Err(GpuError::NoCompute(label));
        }
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("aobake"),
                // Timestamps time the tracer's compute passes where the
                // adapter has them.
                required_features: adapter.features() & wgpu::Features::TIMESTAMP_QUERY,
                required_limits: {
                    let mut limits = adapter.limits();
                    if let Some(bytes) = binding_limit {
                        limits.max_storage_buffer_binding_size =
                            limits.max_storage_buffer_binding_size.min(bytes);
                    }
                    limits
                },
                ..Default::default()
            })
            .await
            .map_err(|e| GpuError::Device(format!("{label}: {e}")))?;
        // Every call that can fail runs in error scopes; an error outside
        // them is reported, never a panic in the middle of a worker's job.
        device.on_uncaptured_error(std::sync::Arc::new(|e| {
            eprintln!("wgpu error outside an error scope: {e}");
        }));
        Ok(Self {
            info,
            adapter,
            device,
            queue,
            point_pipelines: Mutex::default(),
        })
    }
}

/// The validation and internal error scopes around GPU work (an internal
/// error is a shader the backend cannot translate): what every pipeline
/// and dispatch runs in, so that a failure is an error, not wgpu's panic.
///
/// The fields drop in declaration order and wgpu panics unless scopes are
/// popped in reverse order of their pushing, so `internal` (pushed last)
/// comes first: a guard dropped on an early return pops cleanly.
pub(crate) struct ErrorScopes {
    internal: wgpu::ErrorScopeGuard,
    validation: wgpu::ErrorScopeGuard,
}

impl ErrorScopes {
    pub(crate) fn push(device: &wgpu::Device) -> Self {
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let internal = device.push_error_scope(wgpu::ErrorFilter::Internal);
        Self {
            internal,
            validation,
        }
    }

    /// The first error caught, if any.
    pub(crate) fn pop(self) -> Option<wgpu::Error> {
        let internal = pollster::block_on(self.internal.pop());
        let validation = pollster::block_on(self.validation.pop());
        internal.or(validation)
    }
}

/// Most workgroups per dispatch dimension (WebGPU's minimum limit).
pub(crate) const MAX_GROUPS: u32 = 65_535;

/// The (x, y) grid of a dispatch of `groups` workgroups: rows of at most
/// [`MAX_GROUPS`]; `None` when that many rows do not suffice either.
pub(crate) fn dispatch_grid(groups: u32) -> Option<(u32, u32)> {
    let grid = (groups.min(MAX_GROUPS), groups.div_ceil(MAX_GROUPS));
    (grid.1 <= MAX_GROUPS).then_some(grid)
}

/// Vulkan and GL, or what `WGPU_BACKEND` names.
fn default_backends() -> wgpu::Backends {
    wgpu::Backends::from_env().unwrap_or(wgpu::Backends::VULKAN | wgpu::Backends::GL)
}

impl Gpu {
    /// A batch lookup: uploads `input` as a storage buffer, lets `record`
    /// write `count` f32 into an output storage buffer, and reads them
    /// back (what the lookups' `evaluate` does for tests and tools).
    pub(crate) fn evaluate_batch(
        &self,
        input: &[u8],
        count: usize,
        record: impl FnOnce(
            &mut wgpu::CommandEncoder,
            &wgpu::Buffer,
            &wgpu::Buffer,
        ) -> Result<(), GpuError>,
    ) -> Result<Vec<f32>, GpuError> {
        use wgpu::util::DeviceExt as _;
        let device = &self.device;
        let scope = ErrorScopes::push(device);
        let input = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("lookup input"),
            contents: if input.is_empty() { &[0u8; 32] } else { input },
            usage: wgpu::BufferUsages::STORAGE,
        });
        let size = 4 * count.max(1) as u64;
        let buffer = |label, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        use wgpu::BufferUsages as U;
        let out = buffer("occlusion", U::STORAGE | U::COPY_SRC);
        let staging = buffer("occlusion readback", U::MAP_READ | U::COPY_DST);
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        record(&mut encoder, &input, &out)?;
        encoder.copy_buffer_to_buffer(&out, 0, &staging, 0, size);
        let submission = self.queue.submit(Some(encoder.finish()));
        if let Some(e) = scope.pop() {
            return Err(GpuError::Pipeline(e.to_string()));
        }
        let bytes = self.read(&staging, submission)?;
        Ok(bytemuck::cast_slice::<u8, f32>(&bytes)[..count].to_vec())
    }

    /// Draws `vertices` with `pipeline` and `group` (group 0) into a new
    /// `width × height` target of `format` (4 bytes a texel), cleared to
    /// `clear` first, and reads it back: 4 bytes a texel, row-major. What
    /// the tests' harness draws (points, a full-screen triangle) go
    /// through.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn draw_and_read(
        &self,
        label: &str,
        pipeline: &wgpu::RenderPipeline,
        group: &wgpu::BindGroup,
        format: wgpu::TextureFormat,
        (width, height): (u32, u32),
        clear: wgpu::Color,
        vertices: std::ops::Range<u32>,
    ) -> Result<Vec<u8>, GpuError> {
        let device = &self.device;
        let scope = ErrorScopes::push(device);
        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let target = device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = target.create_view(&wgpu::TextureViewDescriptor::default());
        let row = (4 * width).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: u64::from(row) * u64::from(height),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some(label),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(clear),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, group, &[]);
            pass.draw(vertices, 0..1);
        }
        encoder.copy_texture_to_buffer(
            target.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &staging,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(height),
                },
            },
            size,
        );
        let submission = self.queue.submit(Some(encoder.finish()));
        if let Some(e) = scope.pop() {
            return Err(GpuError::Pipeline(e.to_string()));
        }
        self.read_with(&staging, staging.size(), submission, |bytes| {
            (0..height as usize)
                .flat_map(|y| {
                    let at = y * row as usize;
                    bytes[at..at + 4 * width as usize].iter().copied()
                })
                .collect()
        })
    }

    /// Waits for `submission` and copies a `MAP_READ` buffer out.
    pub(crate) fn read(
        &self,
        staging: &wgpu::Buffer,
        submission: wgpu::SubmissionIndex,
    ) -> Result<Vec<u8>, GpuError> {
        self.read_range(staging, staging.size(), submission)
    }

    /// Waits for `submission` and copies the first `size` bytes of a
    /// `MAP_READ` buffer out.
    pub(crate) fn read_range(
        &self,
        staging: &wgpu::Buffer,
        size: u64,
        submission: wgpu::SubmissionIndex,
    ) -> Result<Vec<u8>, GpuError> {
        self.read_with(staging, size, submission, <[u8]>::to_vec)
    }

    /// Waits for `submission` and hands the first `size` bytes of a
    /// `MAP_READ` buffer to `f` where they are mapped (no copy first).
    pub(crate) fn read_with<T>(
        &self,
        staging: &wgpu::Buffer,
        size: u64,
        submission: wgpu::SubmissionIndex,
        f: impl FnOnce(&[u8]) -> T,
    ) -> Result<T, GpuError> {
        let slice = staging.slice(..size);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(submission),
                timeout: None,
            })
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        rx.recv()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let out = f(&slice
            .get_mapped_range()
            .map_err(|e| GpuError::Readback(e.to_string()))?);
        staging.unmap();
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::{ErrorScopes, Gpu};

    #[test]
    fn error_scopes_dropped_without_a_pop_unwind_in_order() {
        let gpu = Gpu::new().expect("a wgpu adapter (llvmpipe or lavapipe without a GPU)");
        // What a `?` between push and pop does: the guard is dropped, and
        // wgpu panics if its two scopes leave in the wrong order.
        drop(ErrorScopes::push(&gpu.device));
        // The device's scopes are balanced after it.
        assert!(ErrorScopes::push(&gpu.device).pop().is_none());
    }
}
