//! [`GpuTracer`]: core's ray estimators in a compute shader
//! (`shaders/wgsl/trace.wgsl`), a [`RayEngine`] that a worker or
//! `aobake bake --tracer gpu` installs for the process
//! ([`aobake_core::trace::engine::set_engine`]).
//!
//! A batch (many poses' scenes and their points) is uploaded once: the
//! scenes' wide BVH nodes and triangles concatenated, the points with their
//! ray frames and seeds. Sixteen invocations share a point's rays and
//! their workgroup adds the sixteen tallies in a fixed order, so results
//! do not depend on scheduling. Dispatches are cut to the adapter's
//! limits; a batch whose buffers do not fit is split (by scene, then by
//! point), one that runs out of memory is retried in halves, and one whose
//! single scene does not fit is left to the CPU.

use aobake_core::trace::{
    RayBatch, RayEngine, Tally, TraceError,
    engine::{Estimator, GPU_TRIANGLE_FLOATS, GpuSceneInfo, NodeLayout, sobol_directions},
};
use aobake_shaders::{
    TRACE_LANES, TRACE_STACK, TraceParams, TracePoint, TraceScene, TraceTally, WORKGROUP_SIZE,
};
use glam::Vec3A;
use rayon::prelude::*;
use wgpu::util::DeviceExt as _;

use super::{ErrorScopes, Gpu, GpuError};

// trace.wgsl's node_size(): 16 vec4 a node exact, 6 quantised.
const _: () =
    assert!(NodeLayout::Exact.words() == 16 * 4 && NodeLayout::Quantised.words() == 6 * 4);
/// Bytes of the two resolved timestamps.
const TIMER_BYTES: u64 = 16;
/// Points per workgroup (`TRACE_LANES` invocations per point: a
/// 50k-vertex mesh is 800k invocations, enough to fill a large GPU).
const POINTS_PER_GROUP: u32 = WORKGROUP_SIZE / TRACE_LANES;
/// Most invocations per dispatch: short dispatches keep a desktop GPU's
/// watchdog away and let progress be reported.
const MAX_INVOCATIONS: u64 = 1 << 22;
/// Points per dispatch: within the invocation cap.
const PER_DISPATCH: u64 = MAX_INVOCATIONS / TRACE_LANES as u64;
// A dispatch's workgroups fit the dispatch grid.
const _: () = assert!(
    PER_DISPATCH / POINTS_PER_GROUP as u64 <= super::MAX_GROUPS as u64 * super::MAX_GROUPS as u64
);

/// core's estimators on a wgpu adapter with compute shaders.
#[derive(Debug)]
pub struct GpuTracer<'g> {
    gpu: &'g Gpu,
    layout: NodeLayout,
    pipeline: wgpu::ComputePipeline,
    sobol: [[u32; 4]; 8],
    /// Buffers kept between batches (allocating them is a large part of
    /// a small batch's cost); one batch at a time uses them.
    buffers: std::sync::Mutex<Buffers>,
    stats: Counters,
}

/// Device buffers that grow to the largest batch seen.
#[derive(Debug, Default)]
struct Buffers {
    nodes: Option<wgpu::Buffer>,
    triangles: Option<wgpu::Buffer>,
    scenes: Option<wgpu::Buffer>,
    points: Option<wgpu::Buffer>,
    tallies: Option<wgpu::Buffer>,
    staging: Option<wgpu::Buffer>,
    /// Two timestamps around the compute pass, where the adapter has
    /// timestamp queries, and the buffer they resolve to (copied behind
    /// the tallies in `staging`, so one mapping reads both).
    timer: Option<(wgpu::QuerySet, wgpu::Buffer)>,
}

/// Running totals of the tracer's work in this process.
#[derive(Debug, Default)]
struct Counters {
    batches: std::sync::atomic::AtomicU64,
    rays: std::sync::atomic::AtomicU64,
    /// Nanoseconds: the whole call, the GPU's compute passes (timestamps),
    /// and waiting for the results.
    wall_ns: std::sync::atomic::AtomicU64,
    kernel_ns: std::sync::atomic::AtomicU64,
    wait_ns: std::sync::atomic::AtomicU64,
}

/// What a [`GpuTracer`] has done so far.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceStats {
    /// Submissions (a batch is one unless it was split).
    pub batches: u64,
    /// Rays cast.
    pub rays: u64,
    /// Seconds in the tracer's calls, preparation and readback included.
    pub wall_s: f64,
    /// Seconds of the compute passes on the GPU (timestamp queries; zero
    /// where the adapter has none).
    pub kernel_s: f64,
    /// Seconds waiting for the GPU and reading the results back.
    pub wait_s: f64,
}

impl std::fmt::Display for TraceStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Rays and rates in G when there are billions, else in M (a small
        // run on a software adapter would read 0.00 G).
        let (scale, unit) = if self.rays >= 1_000_000_000 {
            (1e9, "G")
        } else {
            (1e6, "M")
        };
        let rate = |s: f64| {
            if s > 0.0 {
                self.rays as f64 / s / scale
            } else {
                0.0
            }
        };
        write!(
            f,
            "{} submissions, {:.2} {unit} rays: {:.2} s in the tracer ({:.2} {unit}rays/s), {:.2} s waiting for the GPU",
            self.batches,
            self.rays as f64 / scale,
            self.wall_s,
            rate(self.wall_s),
            self.wait_s
        )?;
        if self.kernel_s > 0.0 {
            write!(
                f,
                ", {:.2} s in its compute passes ({:.2} {unit}rays/s)",
                self.kernel_s,
                rate(self.kernel_s)
            )?;
        }
        Ok(())
    }
}

/// A buffer of at least `size` bytes in `slot`, reallocated (with room to
/// grow) when too small.
fn ensure<'b>(
    device: &wgpu::Device,
    slot: &'b mut Option<wgpu::Buffer>,
    size: u64,
    usage: wgpu::BufferUsages,
    label: &str,
) -> &'b wgpu::Buffer {
    let size = size.max(256);
    if slot.as_ref().is_none_or(|b| b.size() < size) {
        // Room to grow, within what one binding may see.
        let limits = device.limits();
        let cap = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        *slot = Some(device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: size.next_power_of_two().min(cap.max(size)),
            usage,
            mapped_at_creation: false,
        }));
    }
    slot.as_ref().expect("just made")
}

/// The points of a batch traced in one submission, and the scenes they use.
struct Part {
    points: std::ops::Range<usize>,
    scenes: std::ops::Range<usize>,
}

impl<'g> GpuTracer<'g> {
    /// Builds the pipeline on `gpu`, with the default node layout.
    pub fn new(gpu: &'g Gpu) -> Result<Self, GpuError> {
        Self::with_layout(gpu, NodeLayout::default())
    }

    /// Builds the pipeline on `gpu` for nodes in `layout`.
    pub fn with_layout(gpu: &'g Gpu, layout: NodeLayout) -> Result<Self, GpuError> {
        let device = &gpu.device;
        let scope = ErrorScopes::push(device);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("trace.wgsl"),
            source: wgpu::ShaderSource::Wgsl(aobake_shaders::TRACE.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("trace"),
            layout: None,
            module: &module,
            entry_point: Some("cs_trace"),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants: &[(
                    "QUANTISED",
                    f64::from(u8::from(layout == NodeLayout::Quantised)),
                )],
                // Every invocation writes its slot of `partial` before the
                // barrier that precedes any read.
                zero_initialize_workgroup_memory: false,
            },
            cache: None,
        });
        if let Some(e) = scope.pop() {
            return Err(GpuError::Pipeline(e.to_string()));
        }
        let numbers = sobol_directions();
        let sobol = std::array::from_fn(|k| {
            let (a, b) = (numbers[2 * k], numbers[2 * k + 1]);
            [a[0], a[1], b[0], b[1]]
        });
        Ok(Self {
            gpu,
            layout,
            pipeline,
            sobol,
            buffers: std::sync::Mutex::default(),
            stats: Counters::default(),
        })
    }

    /// The work done so far.
    pub fn stats(&self) -> TraceStats {
        use std::sync::atomic::Ordering::Relaxed;
        let s = &self.stats;
        TraceStats {
            batches: s.batches.load(Relaxed),
            rays: s.rays.load(Relaxed),
            wall_s: s.wall_ns.load(Relaxed) as f64 * 1e-9,
            kernel_s: s.kernel_ns.load(Relaxed) as f64 * 1e-9,
            wait_s: s.wait_ns.load(Relaxed) as f64 * 1e-9,
        }
    }

    /// The adapter as a person reads it.
    pub fn adapter(&self) -> String {
        self.gpu.label()
    }

    /// How the nodes of the trees it traces are laid out.
    pub fn layout(&self) -> NodeLayout {
        self.layout
    }

    /// Traces `batch` on the GPU: one tally per point (per point and scene
    /// when the points are shared), or `None` when a scene's tree is too
    /// deep for the shader's stack, not a wide BVH, or too large for the
    /// adapter's bindings, for the CPU to trace.
    pub fn trace_batch(
        &self,
        batch: &RayBatch<'_>,
        progress: &(dyn Fn(usize) + Sync),
    ) -> Result<Option<Vec<Tally>>, GpuError> {
        let mut infos = Vec::with_capacity(batch.scenes.len());
        for scene in &batch.scenes {
            match scene.gpu_info() {
                Some(info) if 7 * info.depth < TRACE_STACK as usize => infos.push(info),
                _ => return Ok(None),
            }
        }
        // Core checked the batch (RayBatch::check): points grouped by scene.
        let mut out = Vec::with_capacity(batch.tallies());
        let mut pending = vec![self.whole(batch)];
        while let Some(part) = pending.pop() {
            match self.trace_part(batch, &infos, &part) {
                Ok(tallies) => {
                    progress(tallies.len());
                    out.extend(tallies);
                }
                Err(PartError::TooLarge) | Err(PartError::OutOfMemory)
                    if part.points.len() > 1 || part.scenes.len() > 1 =>
                {
                    let (a, b) = self.halves(batch, &part);
                    // Pop order: the first half next.
                    pending.push(b);
                    pending.push(a);
                }
                // One scene beyond what the adapter can bind: the CPU
                // traces the batch.
                Err(PartError::TooLarge) => return Ok(None),
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
            scenes: if batch.shared {
                0..batch.scenes.len()
            } else {
                scene_range(batch, 0..batch.points.len())
            },
        }
    }

    /// A part in two. Shared points keep their tallies scene by scene: the
    /// scenes are halved first, with every point, and one scene's points
    /// after.
    fn halves(&self, batch: &RayBatch<'_>, part: &Part) -> (Part, Part) {
        if batch.shared {
            let (s, p) = (part.scenes.clone(), part.points.clone());
            if s.len() > 1 {
                let mid = s.start + s.len() / 2;
                return (
                    Part {
                        points: p.clone(),
                        scenes: s.start..mid,
                    },
                    Part {
                        points: p,
                        scenes: mid..s.end,
                    },
                );
            }
            let mid = p.start + p.len() / 2;
            return (
                Part {
                    points: p.start..mid,
                    scenes: s.clone(),
                },
                Part {
                    points: mid..p.end,
                    scenes: s,
                },
            );
        }
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
        let started = std::time::Instant::now();
        let device = &self.gpu.device;
        let limits = device.limits();
        let binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let rays_per_lane = batch.samples.div_ceil(TRACE_LANES);
        // Geometry and points of the part's scenes, converted in parallel
        // (before the buffers are locked).
        let words = self.layout.words();
        let geometry: Vec<(Vec<u32>, Vec<f32>)> = batch.scenes[part.scenes.clone()]
            .par_iter()
            .map(|scene| (scene.gpu_nodes(self.layout), scene.gpu_triangles()))
            .collect();
        let mut nodes: Vec<u32> = Vec::with_capacity(geometry.iter().map(|g| g.0.len()).sum());
        let mut triangles: Vec<f32> = Vec::with_capacity(geometry.iter().map(|g| g.1.len()).sum());
        let mut scenes = Vec::with_capacity(part.scenes.len());
        for ((scene_nodes, scene_triangles), info) in
            geometry.iter().zip(&infos[part.scenes.clone()])
        {
            let first_node = (nodes.len() / words) as u32;
            let first_triangle = (triangles.len() / GPU_TRIANGLE_FLOATS) as u32;
            nodes.extend(scene_nodes);
            triangles.extend(scene_triangles);
            scenes.push(scene_constants(
                batch,
                info,
                first_node,
                first_triangle,
                (scene_nodes.len() / words) as u32,
            ));
        }
        let tally_count = if batch.shared {
            part.points.len() * part.scenes.len()
        } else {
            part.points.len()
        } as u64;
        let tally_bytes = tally_count * size_of::<TraceTally>() as u64;
        let timed = device.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        // The readback buffer holds the tallies and, behind them, the
        // timestamps.
        let read_bytes = tally_bytes + if timed { TIMER_BYTES } else { 0 };
        let largest = [
            4 * nodes.len() as u64,
            4 * triangles.len() as u64,
            (size_of::<TracePoint>() * part.points.len()) as u64,
            tally_bytes,
        ]
        .into_iter()
        .max()
        .unwrap_or(0);
        if largest > binding || read_bytes > limits.max_buffer_size {
            return Err(PartError::TooLarge);
        }
        if part.points.is_empty() {
            return Ok(Vec::new());
        }
        let points: Vec<TracePoint> = batch.points[part.points.clone()]
            .par_iter()
            .map(|p| TracePoint {
                origin: p.origin.to_array(),
                // Shared points are traced in the dispatch's scene.
                scene: if batch.shared {
                    0
                } else {
                    p.scene - part.scenes.start as u32
                },
                tangent: p.tangent.to_array(),
                seed: p.seed,
                bitangent: p.bitangent.to_array(),
                _pad0: 0,
                normal: p.normal.to_array(),
                _pad1: 0,
            })
            .collect();

        let mut guard = self.buffers.lock().unwrap_or_else(|e| e.into_inner());
        let buffers = &mut *guard;
        let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let scopes = ErrorScopes::push(device);
        use wgpu::BufferUsages as U;
        let queue = &self.gpu.queue;
        let upload = |slot: &mut Option<wgpu::Buffer>, bytes: &[u8], label: &str| {
            let buffer = ensure(
                device,
                slot,
                bytes.len() as u64,
                U::STORAGE | U::COPY_DST,
                label,
            );
            if !bytes.is_empty() {
                queue.write_buffer(buffer, 0, bytes);
            }
        };
        upload(
            &mut buffers.nodes,
            bytemuck::cast_slice(&nodes),
            "trace nodes",
        );
        upload(
            &mut buffers.triangles,
            bytemuck::cast_slice(&triangles),
            "trace triangles",
        );
        upload(
            &mut buffers.scenes,
            bytemuck::cast_slice(&scenes),
            "trace scenes",
        );
        upload(
            &mut buffers.points,
            bytemuck::cast_slice(&points),
            "trace points",
        );
        ensure(
            device,
            &mut buffers.tallies,
            tally_bytes,
            U::STORAGE | U::COPY_SRC,
            "trace tallies",
        );
        ensure(
            device,
            &mut buffers.staging,
            read_bytes,
            U::MAP_READ | U::COPY_DST,
            "trace readback",
        );
        if buffers.timer.is_none() && timed {
            let set = device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("trace timer"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            });
            let resolve = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("trace timer resolve"),
                size: TIMER_BYTES,
                usage: U::QUERY_RESOLVE | U::COPY_SRC,
                mapped_at_creation: false,
            });
            buffers.timer = Some((set, resolve));
        }
        let (Some(nodes_buffer), Some(triangles_buffer), Some(scenes_buffer), Some(points_buffer)) = (
            &buffers.nodes,
            &buffers.triangles,
            &buffers.scenes,
            &buffers.points,
        ) else {
            unreachable!("uploaded above");
        };
        let (Some(tallies_buffer), Some(staging)) = (&buffers.tallies, &buffers.staging) else {
            unreachable!("made above");
        };
        let layout = self.pipeline.get_bind_group_layout(0);
        // (scene, first point, points, first tally) of each dispatch: shared
        // points once per scene, scene by scene; else the points in order.
        let total = points.len() as u64;
        let chunks = || {
            (0..total)
                .step_by(PER_DISPATCH as usize)
                .map(move |f| (f, PER_DISPATCH.min(total - f)))
        };
        let jobs: Vec<(u32, u64, u64, u64)> = if batch.shared {
            (0..part.scenes.len() as u64)
                .flat_map(|s| chunks().map(move |(f, c)| (s as u32, f, c, s * total + f)))
                .collect()
        } else {
            chunks().map(|(f, c)| (0, f, c, f)).collect()
        };

        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("trace"),
        });
        let mut bind_groups = Vec::new();
        let mut dispatches = Vec::new();
        for &(scene, first, count, tally_base) in &jobs {
            let workgroups = count.div_ceil(u64::from(POINTS_PER_GROUP)) as u32;
            let grid = super::dispatch_grid(workgroups).expect("PER_DISPATCH fits the grid");
            let params = TraceParams {
                estimator: estimator_code(batch.estimator),
                samples: batch.samples,
                group_size: rays_per_lane,
                _pad: 0,
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
                scene,
                shared_points: u32::from(batch.shared),
                tally_base: tally_base as u32,
                sobol: self.sobol,
            };
            let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("trace params"),
                contents: bytemuck::bytes_of(&params),
                usage: wgpu::BufferUsages::UNIFORM,
            });
            bind_groups.push(device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("trace"),
                layout: &layout,
                entries: &[
                    entry(0, uniform.as_entire_binding()),
                    entry(1, nodes_buffer.as_entire_binding()),
                    entry(2, triangles_buffer.as_entire_binding()),
                    entry(3, scenes_buffer.as_entire_binding()),
                    entry(4, points_buffer.as_entire_binding()),
                    entry(5, tallies_buffer.as_entire_binding()),
                ],
            }));
            dispatches.push(grid);
        }
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("trace"),
                timestamp_writes: buffers.timer.as_ref().map(|(set, _)| {
                    wgpu::ComputePassTimestampWrites {
                        query_set: set,
                        beginning_of_pass_write_index: Some(0),
                        end_of_pass_write_index: Some(1),
                    }
                }),
            });
            pass.set_pipeline(&self.pipeline);
            for (bind_group, grid) in bind_groups.iter().zip(&dispatches) {
                pass.set_bind_group(0, bind_group, &[]);
                pass.dispatch_workgroups(grid.0, grid.1, 1);
            }
        }
        encoder.copy_buffer_to_buffer(tallies_buffer, 0, staging, 0, tally_bytes);
        if let Some((set, resolve)) = &buffers.timer {
            encoder.resolve_query_set(set, 0..2, resolve, 0);
            encoder.copy_buffer_to_buffer(resolve, 0, staging, tally_bytes, TIMER_BYTES);
        }
        let waiting = std::time::Instant::now();
        let submission = self.gpu.queue.submit(Some(encoder.finish()));
        if let Some(e) = scopes.pop() {
            return Err(PartError::Gpu(GpuError::Pipeline(e.to_string())));
        }
        if pollster::block_on(oom.pop()).is_some() {
            // The buffers may be the cause: the retry allocates afresh.
            *buffers = Buffers::default();
            return Err(PartError::OutOfMemory);
        }
        let period = f64::from(queue.get_timestamp_period());
        // Copied out as they are: nothing parallel runs while the buffers
        // are locked (a rayon thread waiting in a parallel loop may take up
        // another job's trace, which would then wait on this lock).
        let (raw, kernel_ns) = self
            .gpu
            .read_with(staging, read_bytes, submission, |bytes| {
                let (tallies, ticks) = bytes.split_at(tally_bytes as usize);
                let tick = |k: usize| {
                    ticks
                        .get(8 * k..8 * k + 8)
                        .map_or(0, |b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
                };
                let kernel_ns = (tick(1).saturating_sub(tick(0)) as f64 * period) as u64;
                (
                    bytemuck::pod_collect_to_vec::<u8, TraceTally>(tallies),
                    kernel_ns,
                )
            })
            .map_err(PartError::Gpu)?;
        drop(guard);
        let tallies: Vec<Tally> = raw
            .par_iter()
            .map(|t| Tally {
                hits: t.hits,
                back: t.back,
                sum: f64::from(t.sum),
                direction: Vec3A::from_array(t.direction),
            })
            .collect();
        {
            use std::sync::atomic::Ordering::Relaxed;
            let s = &self.stats;
            s.batches.fetch_add(1, Relaxed);
            // A tally per point, or per point and scene when shared.
            s.rays
                .fetch_add(tally_count * u64::from(batch.samples), Relaxed);
            s.wall_ns
                .fetch_add(started.elapsed().as_nanos() as u64, Relaxed);
            s.wait_ns
                .fetch_add(waiting.elapsed().as_nanos() as u64, Relaxed);
            s.kernel_ns.fetch_add(kernel_ns, Relaxed);
        }
        Ok(tallies)
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
        scale: info.scale,
        _pad: [0; 2],
        centre: info.centre.to_array(),
        _pad1: 0,
    }
}

impl RayEngine for GpuTracer<'static> {
    fn label(&self) -> String {
        format!("gpu: {}", self.adapter())
    }

    fn summary(&self) -> Option<String> {
        Some(self.stats().to_string())
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
            Ok((
                "cpu".into(),
                Some(format!("no GPU tracer ({e}); tracing on the CPU")),
            ))
        }
        Err(e) => Err(e),
    }
}

#[cfg(test)]
mod tests {
    use super::TraceStats;

    #[test]
    fn stats_read_in_the_unit_of_their_size() {
        let stats = |rays| TraceStats {
            batches: 3,
            rays,
            wall_s: 2.0,
            kernel_s: 1.0,
            wait_s: 1.5,
        };
        let small = stats(5_000_000).to_string();
        assert!(
            small.contains("5.00 M rays") && small.contains("(2.50 Mrays/s)"),
            "{small}"
        );
        assert!(small.contains("compute passes (5.00 Mrays/s)"), "{small}");
        let large = stats(3_000_000_000).to_string();
        assert!(large.starts_with("3 submissions, 3.00 G rays"), "{large}");
        assert!(large.contains("(1.50 Grays/s)"), "{large}");
        let untimed = TraceStats {
            kernel_s: 0.0,
            ..stats(1)
        };
        assert!(!untimed.to_string().contains("compute passes"));
    }
}
