//! [`GpuTracer`]: core's ray estimators in a compute shader
//! (`shaders/wgsl/trace.wgsl`), a [`RayEngine`] that a worker or
//! `aobake bake --tracer gpu` installs for the process
//! ([`aobake_core::trace::engine::set_engine`]).
//!
//! A batch (many poses' scenes and their points) is uploaded once: the
//! scenes' wide BVH nodes and triangles concatenated, the points with their
//! ray frames and seeds. Sixteen invocations share a point's rays and
//! their workgroup adds the sixteen tallies in a fixed order, so results
//! do not depend on scheduling. Dispatches are cut to the
//! adapter's limits; a batch whose buffers do not fit is split by points,
//! and one that runs out of memory is retried in halves.

use aobake_core::trace::{
    RayBatch, RayEngine, Tally, TraceError,
    engine::{Estimator, GPU_NODE_WORDS, GPU_TRIANGLE_FLOATS, GpuSceneInfo, sobol_directions},
};
use aobake_shaders::{TraceParams, TracePoint, TraceScene, TraceTally, WORKGROUP_SIZE};
use glam::Vec3A;
use wgpu::util::DeviceExt as _;

use super::{Gpu, GpuError};

/// Invocations per point (`LANES` in trace.wgsl): a 50k-vertex mesh is
/// 800k invocations, enough to fill a large GPU.
const LANES: u32 = 16;
/// Points per workgroup.
const POINTS_PER_GROUP: u32 = WORKGROUP_SIZE / LANES;
/// Most workgroups per dispatch dimension (WebGPU's minimum limit).
const MAX_GROUPS: u32 = 65_535;
/// Most invocations per dispatch: short dispatches keep a desktop GPU's
/// watchdog away and let progress be reported.
const MAX_INVOCATIONS: u64 = 1 << 22;
/// The shader's traversal stack (`STACK` in trace.wgsl).
const STACK: usize = 96;

/// core's estimators on a wgpu adapter with compute shaders.
#[derive(Debug)]
pub struct GpuTracer<'g> {
    gpu: &'g Gpu,
    pipeline: wgpu::ComputePipeline,
    sobol: [[u32; 4]; 8],
}

/// The points of a batch traced in one submission, and the scenes they use.
struct Part {
    points: std::ops::Range<usize>,
    scenes: std::ops::Range<usize>,
}

impl<'g> GpuTracer<'g> {
    /// Builds the pipeline on `gpu`.
    pub fn new(gpu: &'g Gpu) -> Result<Self, GpuError> {
        let device = &gpu.device;
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("trace.wgsl"),
            source: wgpu::ShaderSource::Wgsl(aobake_shaders::TRACE.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("trace"),
            layout: None,
            module: &module,
            entry_point: Some("cs_trace"),
            compilation_options: wgpu::PipelineCompilationOptions::default(),
            cache: None,
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Pipeline(e.to_string()));
        }
        let numbers = sobol_directions();
        let sobol = std::array::from_fn(|k| {
            let (a, b) = (numbers[2 * k], numbers[2 * k + 1]);
            [a[0], a[1], b[0], b[1]]
        });
        Ok(Self {
            gpu,
            pipeline,
            sobol,
        })
    }

    /// The adapter as a person reads it.
    pub fn adapter(&self) -> String {
        self.gpu.label()
    }

    /// Traces `batch` on the GPU: one tally per point, or `None` when a
    /// scene's tree is too deep for the shader's stack or not a wide BVH.
    pub fn trace_batch(
        &self,
        batch: &RayBatch<'_>,
        progress: &(dyn Fn(usize) + Sync),
    ) -> Result<Option<Vec<Tally>>, GpuError> {
        let mut infos = Vec::with_capacity(batch.scenes.len());
        for scene in &batch.scenes {
            match scene.gpu_info() {
                Some(info) if 7 * info.depth < STACK => infos.push(info),
                _ => return Ok(None),
            }
        }
        if batch.points.windows(2).any(|w| w[1].scene < w[0].scene)
            || batch
                .points
                .iter()
                .any(|p| p.scene as usize >= batch.scenes.len())
        {
            return Err(GpuError::TooLarge(
                "the batch's points are not grouped by scene".into(),
            ));
        }
        let mut out = Vec::with_capacity(batch.points.len());
        let mut pending = vec![self.whole(batch)];
        while let Some(part) = pending.pop() {
            match self.trace_part(batch, &infos, &part) {
                Ok(tallies) => {
                    progress(part.points.len());
                    out.extend(tallies);
                }
                Err(PartError::TooLarge) | Err(PartError::OutOfMemory) if part.points.len() > 1 => {
                    let (a, b) = self.halves(batch, &part);
                    // Pop order: the first half next.
                    pending.push(b);
                    pending.push(a);
                }
                Err(PartError::TooLarge) => {
                    return Err(GpuError::TooLarge(format!(
                        "one point's scene ({} nodes) exceeds the adapter's buffer limits",
                        batch.scenes[batch.points[part.points.start].scene as usize].node_count()
                    )));
                }
                Err(PartError::OutOfMemory) => {
                    return Err(GpuError::TooLarge(
                        "the GPU ran out of memory on a single point's scene".into(),
                    ));
                }
                Err(PartError::Gpu(e)) => return Err(e),
            }
        }
        Ok(Some(out))
    }

    fn whole(&self, batch: &RayBatch<'_>) -> Part {
        Part {
            points: 0..batch.points.len(),
            scenes: scene_range(batch, 0..batch.points.len()),
        }
    }

    fn halves(&self, batch: &RayBatch<'_>, part: &Part) -> (Part, Part) {
        let mid = part.points.start + part.points.len() / 2;
        let a = part.points.start..mid;
        let b = mid..part.points.end;
        (
            Part {
                scenes: scene_range(batch, a.clone()),
                points: a,
            },
            Part {
                scenes: scene_range(batch, b.clone()),
                points: b,
            },
        )
    }

    fn trace_part(
        &self,
        batch: &RayBatch<'_>,
        infos: &[GpuSceneInfo],
        part: &Part,
    ) -> Result<Vec<Tally>, PartError> {
        let device = &self.gpu.device;
        let limits = device.limits();
        let binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let rays_per_lane = batch.samples.div_ceil(LANES);
        // Geometry and points of the part's scenes.
        let mut nodes: Vec<u32> = Vec::new();
        let mut triangles: Vec<f32> = Vec::new();
        let mut scenes = Vec::with_capacity(part.scenes.len());
        for (scene, info) in batch.scenes[part.scenes.clone()]
            .iter()
            .zip(&infos[part.scenes.clone()])
        {
            let first_node = (nodes.len() / GPU_NODE_WORDS) as u32;
            let first_triangle = (triangles.len() / GPU_TRIANGLE_FLOATS) as u32;
            let scene_nodes = scene.gpu_nodes();
            nodes.extend(&scene_nodes);
            triangles.extend(scene.gpu_triangles());
            scenes.push(scene_constants(
                batch,
                info,
                first_node,
                first_triangle,
                (scene_nodes.len() / GPU_NODE_WORDS) as u32,
            ));
        }
        let points: Vec<TracePoint> = batch.points[part.points.clone()]
            .iter()
            .map(|p| TracePoint {
                origin: p.origin.to_array(),
                scene: p.scene - part.scenes.start as u32,
                tangent: p.tangent.to_array(),
                seed: p.seed,
                bitangent: p.bitangent.to_array(),
                _pad0: 0,
                normal: p.normal.to_array(),
                _pad1: 0,
            })
            .collect();
        let tally_bytes = part.points.len() as u64 * 32;
        let largest = [
            4 * nodes.len() as u64,
            4 * triangles.len() as u64,
            64 * points.len() as u64,
            tally_bytes,
        ]
        .into_iter()
        .max()
        .unwrap_or(0);
        if largest > binding {
            return Err(PartError::TooLarge);
        }
        if points.is_empty() {
            return Ok(Vec::new());
        }

        let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let storage = |label: &str, bytes: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                // Bindings cannot be empty.
                contents: if bytes.is_empty() { &[0u8; 64] } else { bytes },
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let nodes_buffer = storage("trace nodes", bytemuck::cast_slice(&nodes));
        let triangles_buffer = storage("trace triangles", bytemuck::cast_slice(&triangles));
        let scenes_buffer = storage("trace scenes", bytemuck::cast_slice(&scenes));
        let points_buffer = storage("trace points", bytemuck::cast_slice(&points));
        use wgpu::BufferUsages as U;
        let tallies_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("trace tallies"),
            size: tally_bytes,
            usage: U::STORAGE | U::COPY_SRC,
            mapped_at_creation: false,
        });
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("trace tallies readback"),
            size: tally_bytes,
            usage: U::MAP_READ | U::COPY_DST,
            mapped_at_creation: false,
        });
        let layout = self.pipeline.get_bind_group_layout(0);
        let alignment = u64::from(limits.min_storage_buffer_offset_alignment);
        // Points per dispatch: within the invocation cap, and a multiple of
        // the offset alignment in tallies.
        let step = alignment.div_ceil(32).max(1);
        let per_dispatch = (MAX_INVOCATIONS / u64::from(LANES))
            .min(u64::from(MAX_GROUPS) * u64::from(MAX_GROUPS) * u64::from(POINTS_PER_GROUP));
        let per_dispatch = (per_dispatch / step * step).max(step);

        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("trace") });
        let mut bind_groups = Vec::new();
        let mut dispatches = Vec::new();
        let total = points.len() as u64;
        let mut first = 0u64;
        while first < total {
            let count = per_dispatch.min(total - first);
            let workgroups = count.div_ceil(u64::from(POINTS_PER_GROUP)) as u32;
            let grid = (workgroups.min(MAX_GROUPS), workgroups.div_ceil(MAX_GROUPS));
            let params = TraceParams {
                estimator: estimator_code(batch.estimator),
                samples: batch.samples,
                group_size: rays_per_lane,
                groups: LANES,
                points: count as u32,
                first_point: first as u32,
                row_stride: grid.0,
                facing: u32::from(matches!(
                    batch.estimator,
                    Estimator::Kroon { facing: true, .. }
                )),
                alpha: match batch.estimator {
                    Estimator::Kroon { alpha, .. } => alpha,
                    _ => 0.0,
                },
                _pad: [0; 3],
                sobol: self.sobol,
            };
            let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("trace params"),
                contents: bytemuck::bytes_of(&params),
                usage: wgpu::BufferUsages::UNIFORM,
            });
            let offset = first * 32;
            let size = count * 32;
            bind_groups.push(device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("trace"),
                layout: &layout,
                entries: &[
                    entry(0, uniform.as_entire_binding()),
                    entry(1, nodes_buffer.as_entire_binding()),
                    entry(2, triangles_buffer.as_entire_binding()),
                    entry(3, scenes_buffer.as_entire_binding()),
                    entry(4, points_buffer.as_entire_binding()),
                    entry(
                        5,
                        wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: &tallies_buffer,
                            offset,
                            size: wgpu::BufferSize::new(size),
                        }),
                    ),
                ],
            }));
            dispatches.push(grid);
            first += count;
        }
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("trace"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            for (bind_group, grid) in bind_groups.iter().zip(&dispatches) {
                pass.set_bind_group(0, bind_group, &[]);
                pass.dispatch_workgroups(grid.0, grid.1, 1);
            }
        }
        encoder.copy_buffer_to_buffer(&tallies_buffer, 0, &staging, 0, tally_bytes);
        let submission = self.gpu.queue.submit(Some(encoder.finish()));
        if let Some(e) = pollster::block_on(validation.pop()) {
            return Err(PartError::Gpu(GpuError::Pipeline(e.to_string())));
        }
        if pollster::block_on(oom.pop()).is_some() {
            return Err(PartError::OutOfMemory);
        }
        let bytes = self
            .gpu
            .read(&staging, submission)
            .map_err(PartError::Gpu)?;
        let raw: &[TraceTally] = bytemuck::cast_slice(&bytes);
        Ok(raw
            .iter()
            .map(|t| Tally {
                hits: t.hits,
                back: t.back,
                sum: f64::from(t.sum),
                direction: Vec3A::from_array(t.direction),
            })
            .collect())
    }
}

enum PartError {
    TooLarge,
    OutOfMemory,
    Gpu(GpuError),
}

fn entry(binding: u32, resource: wgpu::BindingResource<'_>) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding, resource }
}

/// The scenes that the points in `points` use (they are grouped by scene).
fn scene_range(batch: &RayBatch<'_>, points: std::ops::Range<usize>) -> std::ops::Range<usize> {
    if points.is_empty() {
        return 0..0;
    }
    let first = batch.points[points.start].scene as usize;
    let last = batch.points[points.end - 1].scene as usize;
    first..last + 1
}

fn estimator_code(e: Estimator) -> u32 {
    match e {
        Estimator::Cosine => 0,
        Estimator::CosineExponential { .. } => 1,
        Estimator::Volume => 2,
        Estimator::Kroon { .. } => 3,
    }
}

/// A scene's `SceneInfo`: the batch's distances in its local frame.
fn scene_constants(
    batch: &RayBatch<'_>,
    info: &GpuSceneInfo,
    first_node: u32,
    first_triangle: u32,
    nodes: u32,
) -> TraceScene {
    let (ground_axis, ground_height, ground_half) = match info.ground {
        Some((axis, height, half)) => (axis, height, half.unwrap_or(-1.0)),
        None => (3, 0.0, -1.0),
    };
    let tau = match batch.estimator {
        Estimator::CosineExponential { tau } => tau / info.scale,
        _ => 0.0,
    };
    TraceScene {
        first_node,
        first_triangle,
        nodes,
        ground_axis,
        ground_height,
        ground_half,
        tmin: info.tmin,
        tmax: (batch.max_distance * info.scale).min(f32::MAX),
        tau,
        _pad: [0; 3],
    }
}

impl RayEngine for GpuTracer<'static> {
    fn label(&self) -> String {
        format!("gpu: {}", self.adapter())
    }

    fn trace(
        &self,
        batch: &RayBatch<'_>,
        progress: &(dyn Fn(usize) + Sync),
    ) -> Result<Option<Vec<Tally>>, TraceError> {
        self.trace_batch(batch, progress)
            .map_err(|e| TraceError::Invalid(format!("GPU tracer: {e}")))
    }
}

/// How a process picks its tracer (`aobake worker --gpu`, `aobake bake
/// --tracer`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GpuMode {
    /// The CPU tracer.
    Off,
    /// A hardware GPU with compute shaders when there is one, else the
    /// CPU (a software rasteriser such as llvmpipe does not count: it is
    /// slower than the CPU tracer).
    Auto,
    /// Any adapter with compute shaders, software ones too; an error
    /// without one.
    Require,
}

/// Installs the process's tracer as `mode` asks and returns its label
/// (`cpu`, or `gpu: ADAPTER`); with [`GpuMode::Auto`] a missing GPU is
/// not an error, and the reason is in the returned note.
pub fn install(mode: GpuMode) -> Result<(String, Option<String>), GpuError> {
    use aobake_core::trace::engine::set_engine;
    if mode == GpuMode::Off {
        set_engine(None);
        return Ok(("cpu".into(), None));
    }
    let opened = Gpu::shared().and_then(|gpu| {
        if mode == GpuMode::Auto && gpu.info.device_type == wgpu::DeviceType::Cpu {
            return Err(GpuError::NoAdapter(format!(
                "only the software adapter {}",
                gpu.label()
            )));
        }
        GpuTracer::new(gpu)
    });
    match opened {
        Ok(tracer) => {
            let tracer = std::sync::Arc::new(tracer);
            let label = tracer.label();
            set_engine(Some(tracer));
            Ok((label, None))
        }
        Err(e) if mode == GpuMode::Auto => {
            set_engine(None);
            Ok(("cpu".into(), Some(format!("no GPU tracer ({e}); tracing on the CPU"))))
        }
        Err(e) => Err(e),
    }
}
