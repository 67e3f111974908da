//! The GPU tracer (`shaders/wgsl/trace.wgsl`) against core's CPU tracer,
//! on both adapters a machine without a GPU has: lavapipe (Vulkan) and
//! llvmpipe (GL). The same rays: per-vertex values identical but at float
//! ties, and those within one ray; the analytic sphere over a floor within
//! the CPU tracer's own tolerances; the same bits run to run.

use aobake_core::{
    Pose,
    trace::{
        Axis, Falloff, Ground, KroonParams, Scene, SceneOptions, SurfaceMesh, SurfaceParams,
        VolumeParams, engine::NodeLayout, engine::set_engine, kroon_occlusion, no_progress, shapes,
        surface_occlusion, trace_poses, vertex_occlusion, volume_occlusion,
    },
};
use aobake_worker::gpu::{Gpu, GpuTracer};
use glam::Vec3;
use std::sync::Arc;

/// The tracers on the best adapter of `backends`, for the whole process:
/// one per node layout.
fn tracers(backends: aobake_worker::gpu::Backends) -> Vec<Arc<GpuTracer<'static>>> {
    let gpu = Gpu::with_backends(backends)
        .unwrap_or_else(|e| panic!("a {backends:?} adapter (lavapipe or llvmpipe): {e}"));
    let gpu: &'static Gpu = Box::leak(Box::new(gpu));
    [NodeLayout::Exact, NodeLayout::Quantised]
        .into_iter()
        .map(|layout| Arc::new(GpuTracer::with_layout(gpu, layout).expect("the trace pipeline")))
        .collect()
}

/// Every tracer of both adapters, each layout.
fn both_adapters() -> Vec<Arc<GpuTracer<'static>>> {
    let mut all = tracers(aobake_worker::gpu::Backends::VULKAN);
    all.extend(tracers(aobake_worker::gpu::Backends::GL));
    all
}

/// Says which tracer the asserts that follow are about.
fn announce(gpu: &GpuTracer<'_>) {
    eprintln!("adapter: {}, {:?} nodes", gpu.adapter(), gpu.layout());
}

/// `f` traced by the CPU, then by `gpu` twice; the GPU must have traced
/// (not declined every batch to the CPU).
fn cpu_and_gpu<T>(gpu: &Arc<GpuTracer<'static>>, f: impl Fn() -> T) -> (T, T, T) {
    set_engine(None);
    let cpu = f();
    let (first, second) = gpu_twice(gpu, f);
    (cpu, first, second)
}

/// `f` traced by the CPU, then by `gpu` once (for the checks that do not
/// compare two GPU runs).
fn cpu_and_gpu_once<T>(gpu: &Arc<GpuTracer<'static>>, f: impl Fn() -> T) -> (T, T) {
    set_engine(None);
    let cpu = f();
    let first = on_gpu(gpu, 1, f).remove(0);
    (cpu, first)
}

/// `f` traced by `gpu` twice.
fn gpu_twice<T>(gpu: &Arc<GpuTracer<'static>>, f: impl Fn() -> T) -> (T, T) {
    let mut runs = on_gpu(gpu, 2, f);
    let second = runs.pop().expect("two runs");
    (runs.pop().expect("two runs"), second)
}

/// `f` traced by `gpu` `runs` times; the GPU must have traced (not
/// declined every batch to the CPU).
fn on_gpu<T>(gpu: &Arc<GpuTracer<'static>>, runs: usize, f: impl Fn() -> T) -> Vec<T> {
    set_engine(Some(gpu.clone()));
    let before = gpu.stats().batches;
    let out = (0..runs).map(|_| f()).collect();
    set_engine(None);
    assert!(gpu.stats().batches > before, "the GPU traced nothing");
    out
}

/// How many of `gpu`'s values are within 1e-5 of `cpu`'s (of as many),
/// and the worst difference.
fn near(cpu: &[f32], gpu: &[f32]) -> (usize, f32) {
    assert_eq!(cpu.len(), gpu.len());
    let close = cpu
        .iter()
        .zip(gpu)
        .filter(|(a, b)| (*a - *b).abs() < 1e-5)
        .count();
    let worst = cpu
        .iter()
        .zip(gpu)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    (close, worst)
}

/// Asserts that at least 99.99 % of `gpu` equals `cpu` exactly and the rest
/// is within `one_ray`; returns the count of differing values.
fn agree(what: &str, cpu: &[f32], gpu: &[f32], one_ray: f32) -> usize {
    assert_eq!(cpu.len(), gpu.len(), "{what}");
    let differ: Vec<(usize, f32)> = cpu
        .iter()
        .zip(gpu)
        .enumerate()
        .filter(|(_, (a, b))| a != b)
        .map(|(i, (a, b))| (i, (a - b).abs()))
        .collect();
    eprintln!("{what}: {} of {} values differ", differ.len(), cpu.len());
    assert!(
        differ.len() as f64 <= 1e-4 * cpu.len() as f64,
        "{what}: {} of {} values differ: {:?}",
        differ.len(),
        cpu.len(),
        &differ[..differ.len().min(10)]
    );
    for &(i, d) in &differ {
        assert!(d <= one_ray * 1.0001, "{what}: value {i} differs by {d}");
    }
    differ.len()
}

fn ground(height: f32) -> Option<Ground> {
    Some(Ground {
        up: Axis::Z,
        height,
        half_size: None,
    })
}

#[test]
fn per_vertex_ao_is_the_cpus_but_at_float_ties_on_lavapipe_and_llvmpipe() {
    // The benchmark mesh (101,120 triangles) on a solid ground: 50,570
    // values of 32 rays each (1.6 M rays per tracer and estimator; 99.99 %
    // of as many values is at most 5 that may differ).
    let mesh = shapes::timing_mesh();
    let normals = mesh.normals();
    let options = SceneOptions {
        ground: ground(0.0),
        ..SceneOptions::default()
    };
    let scene = Scene::new(&mesh.positions, &mesh.triangles, &options).unwrap();
    let surface = SurfaceMesh {
        positions: &mesh.positions,
        normals: &normals,
        triangles: &mesh.triangles,
    };
    let params = SurfaceParams {
        samples: 32,
        max_distance: 3.0,
        seed: 7,
        falloff: Falloff::None,
    };
    // A skinned character in three poses: one batch of three scenes.
    let imported = super::bundled("RiggedFigure");
    let c = &imported.character;
    let poses: Vec<Pose> = [0.0, 0.5, 1.0]
        .iter()
        .map(|&t| Pose::sample(&c.skeleton, &imported.clips[0], t))
        .collect();
    let character = SurfaceParams {
        samples: 128,
        max_distance: 0.5,
        seed: 3,
        falloff: Falloff::None,
    };
    // Obscurance: the closest-hit query and the exponential falloff.
    let obscurance = SurfaceParams {
        falloff: Falloff::Exponential { tau: 2.0 },
        ..params
    };
    let mesh_ao = || vertex_occlusion(&scene, &surface, &params, &no_progress).unwrap();
    let character_ao = || {
        trace_poses(
            c,
            &poses,
            &SceneOptions::default(),
            &character,
            &no_progress,
        )
        .unwrap()
    };
    let obscurance_ao = || vertex_occlusion(&scene, &surface, &obscurance, &no_progress).unwrap();
    // The same poses standing on a solid ground, in obscurance: the
    // ground and the closest-hit query in one batch.
    let feet = c
        .positions
        .iter()
        .map(|p| p[1])
        .fold(f32::INFINITY, f32::min);
    let grounded = SceneOptions {
        ground: Some(Ground {
            up: Axis::Y,
            height: feet,
            half_size: None,
        }),
        ..SceneOptions::default()
    };
    let grounded_obscurance = SurfaceParams {
        falloff: Falloff::Exponential { tau: 4.0 },
        ..character
    };
    let grounded_ao = || {
        trace_poses(c, &poses, &grounded, &grounded_obscurance, &no_progress)
            .unwrap()
            .values
    };
    // The CPU's answers once: they are the same for every tracer.
    set_engine(None);
    let (cpu_mesh, cpu_character, cpu_obscurance) = (mesh_ao(), character_ao(), obscurance_ao());
    let cpu_grounded = grounded_ao();
    assert_eq!(cpu_character.poses(), 3);
    // Run to run, each tracer is compared with itself on the batches of
    // three posed scenes, with and without the ground, in AO and in
    // obscurance (one dispatch over several scenes, where an order that
    // depended on scheduling would show); the benchmark mesh is cast once
    // per tracer and estimator: on the software adapters a second pass
    // doubled this test, the suite's longest.
    for gpu in both_adapters() {
        announce(&gpu);
        let first = on_gpu(&gpu, 1, mesh_ao).remove(0);
        agree("benchmark mesh", &cpu_mesh, &first, 1.0 / 32.0);

        let (first, second) = gpu_twice(&gpu, character_ao);
        assert_eq!(first, second, "the same bits run to run");
        agree(
            "character poses",
            &cpu_character.values,
            &first.values,
            1.0 / 128.0,
        );

        let (first, second) = gpu_twice(&gpu, grounded_ao);
        assert_eq!(first, second, "the same bits run to run, grounded");
        let (close, worst) = near(&cpu_grounded, &first);
        assert!(
            close as f64 >= 0.999 * cpu_grounded.len() as f64 && worst <= 1.0 / 128.0,
            "grounded obscurance: {close} of {} within 1e-5, worst {worst}",
            cpu_grounded.len()
        );
        assert!(
            first.iter().any(|&v| v > 0.05),
            "the ground and the figure occlude"
        );

        let first = on_gpu(&gpu, 1, obscurance_ao).remove(0);
        // f32 sums of e^(−τt) per group of rays against the CPU's f64 sum.
        let (close, worst) = near(&cpu_obscurance, &first);
        assert!(
            close as f64 >= 0.9999 * cpu_obscurance.len() as f64 && worst <= 1.0 / 32.0,
            "obscurance: {close} of {} within 1e-5, worst {worst}",
            cpu_obscurance.len()
        );
    }
}

#[test]
fn the_sphere_over_a_floor_and_the_sphere_estimators_hold_on_the_gpu() {
    // The analytic case of core's tracing tests: a sphere of radius ½
    // centred 1 above an 8 × 8 floor; occlusion r²d/L³ on the floor.
    let (mesh, floor) = shapes::sphere_over_floor();
    let (r, d) = (
        f64::from(shapes::SPHERE_OVER_FLOOR.0),
        f64::from(shapes::SPHERE_OVER_FLOOR.1),
    );
    let scene = Scene::new(&mesh.positions, &mesh.triangles, &SceneOptions::default()).unwrap();
    let points = &mesh.positions[..floor];
    let up = vec![Vec3::Z; floor];
    let centre = Vec3::new(0.0, 0.0, d as f32);
    let exact: Vec<f64> = points
        .iter()
        .map(|p| r * r * d / f64::from(p.distance(centre)).powi(3))
        .collect();
    let under_centre = points.iter().position(|p| *p == Vec3::ZERO).unwrap();

    // A ball over solid ground for the sphere estimators.
    let ball = shapes::icosphere(3, 1.0, Vec3::new(0.0, 0.0, 2.0));
    let ball_scene = Scene::new(
        &ball.positions,
        &ball.triangles,
        &SceneOptions {
            ground: ground(0.0),
            ..SceneOptions::default()
        },
    )
    .unwrap();
    let probes: Vec<Vec3> = (0..400)
        .map(|i| {
            let a = i as f32 * 0.37;
            Vec3::new(
                3.0 * a.cos() * (i as f32 / 400.0),
                3.0 * a.sin(),
                0.05 + 0.01 * i as f32,
            )
        })
        .chain([Vec3::new(0.0, 0.0, 2.0), Vec3::new(1.0, 1.0, -0.5)])
        .collect();
    let volume = VolumeParams {
        samples: 256,
        max_distance: 1.5,
        seed: 5,
    };
    let kroon = KroonParams {
        samples: 256,
        max_distance: 2.0,
        alpha: 1.0,
        weight: 1.0,
        seed: 9,
    };

    for gpu in both_adapters() {
        announce(&gpu);
        for (samples, blender_rmse) in [(64, 0.0096), (256, 0.0034)] {
            let params = SurfaceParams {
                samples,
                max_distance: 100.0,
                seed: 0,
                falloff: Falloff::None,
            };
            let (cpu, first) = cpu_and_gpu_once(&gpu, || {
                surface_occlusion(&scene, points, &up, &params, &no_progress).unwrap()
            });
            agree("floor", &cpu, &first, 1.0 / samples as f32);
            let n = exact.len() as f64;
            let diffs = first.iter().zip(&exact).map(|(&v, &e)| f64::from(v) - e);
            let bias = diffs.clone().sum::<f64>() / n;
            let rmse = (diffs.map(|x| x * x).sum::<f64>() / n).sqrt();
            // The CPU tracer's tolerances (core's tracing tests).
            assert!(rmse < blender_rmse * 1.2, "{samples}: RMSE {rmse}");
            assert!(bias.abs() < 5e-4, "{samples}: bias {bias}");
            let centre_value = f64::from(first[under_centre]);
            assert!(
                (centre_value - (r / d).powi(2)).abs() < 1e-6,
                "{centre_value}"
            );
        }

        let (cpu, first, second) = cpu_and_gpu(&gpu, || {
            volume_occlusion(&ball_scene, &probes, &volume, &no_progress).unwrap()
        });
        assert_eq!(first, second);
        let occlusion = |v: &[aobake_core::trace::VolumeSample]| {
            v.iter().map(|s| s.occlusion).collect::<Vec<_>>()
        };
        agree("volume", &occlusion(&cpu), &occlusion(&first), 2.0 / 256.0);
        for (a, b) in cpu.iter().zip(&first) {
            assert_eq!(a.inside, b.inside);
            if a.occlusion == b.occlusion {
                assert!(a.direction.distance(b.direction) < 1e-4);
            }
        }
        assert!(first[probes.len() - 1].inside, "under the ground");

        let (cpu, first, second) = cpu_and_gpu(&gpu, || {
            kroon_occlusion(&ball_scene, &probes, None, &kroon, &no_progress).unwrap()
        });
        assert_eq!(first, second);
        let (close, _) = near(&cpu, &first);
        assert!(
            close as f64 >= 0.99 * cpu.len() as f64,
            "Kroon: {close} of {}",
            cpu.len()
        );
        assert_eq!(first[probes.len() - 2], 1.0, "inside the ball");
    }
}

#[test]
fn a_batch_beyond_the_adapters_binding_limit_is_split_not_refused() {
    // Storage bindings of 256 KiB: the benchmark mesh's 50,570 points
    // (3.2 MB) and a shared batch of three scenes must be cut in parts.
    let gpu = Gpu::with_binding_limit(aobake_worker::gpu::Backends::VULKAN, 256 << 10)
        .expect("a Vulkan adapter (lavapipe)");
    let gpu: &'static Gpu = Box::leak(Box::new(gpu));
    let small = Arc::new(GpuTracer::new(gpu).unwrap());
    // 40,000 floor points (2.6 MB) under a small ball: split by point.
    let ball = shapes::icosphere(3, 0.5, Vec3::new(0.0, 0.0, 0.8));
    let scene = Scene::new(&ball.positions, &ball.triangles, &SceneOptions::default()).unwrap();
    let floor: Vec<Vec3> = (0..40_000)
        .map(|i| {
            Vec3::new(
                (i % 200) as f32 * 0.02 - 2.0,
                (i / 200) as f32 * 0.02 - 2.0,
                0.0,
            )
        })
        .collect();
    let up = vec![Vec3::Z; floor.len()];
    let params = SurfaceParams {
        samples: 16,
        max_distance: 3.0,
        seed: 2,
        falloff: Falloff::None,
    };
    let (cpu, split) = cpu_and_gpu_once(&small, || {
        surface_occlusion(&scene, &floor, &up, &params, &no_progress).unwrap()
    });
    agree("split floor", &cpu, &split, 1.0 / 16.0);
    assert!(small.stats().batches >= 16, "{}", small.stats());

    // A scene that cannot be bound at all (the benchmark mesh's 4.9 MB of
    // triangles) is left to the CPU, not refused.
    let mesh = shapes::timing_mesh();
    let big = Scene::new(&mesh.positions, &mesh.triangles, &SceneOptions::default()).unwrap();
    let some = &mesh.positions[..500];
    let before = small.stats().batches;
    let trace = || surface_occlusion(&big, some, &vec![Vec3::Z; 500], &params, &no_progress);
    set_engine(None);
    let cpu = trace().unwrap();
    set_engine(Some(small.clone()));
    let fallback = trace().unwrap();
    set_engine(None);
    assert_eq!(cpu, fallback);
    assert_eq!(small.stats().batches, before, "nothing was submitted");

    // A cubemap face's checkpoint: the same points around three poses of
    // a moving ball, one shared batch, split by scene and then by point.
    let moved = |x: f32| shapes::icosphere(3, 0.5, Vec3::new(x, 0.0, 1.0));
    let balls: Vec<_> = [-0.5, 0.0, 0.5].map(moved).into();
    let scenes: Vec<Scene> = balls
        .iter()
        .map(|b| Scene::new(&b.positions, &b.triangles, &SceneOptions::default()).unwrap())
        .collect();
    let scenes: Vec<&Scene> = scenes.iter().collect();
    let points: Vec<Vec3> = (0..6000)
        .map(|i| {
            let a = i as f32 * 0.011;
            Vec3::new(2.0 * a.cos(), 2.0 * a.sin(), 0.2 + 0.0003 * i as f32)
        })
        .collect();
    let kroon = KroonParams {
        samples: 32,
        max_distance: 3.0,
        alpha: 1.0,
        weight: 1.0,
        seed: 4,
    };
    let before = small.stats().batches;
    let (cpu, split) = cpu_and_gpu_once(&small, || {
        aobake_core::trace::kroon_occlusion_many(&scenes, &points, &kroon, &no_progress).unwrap()
    });
    assert!(small.stats().batches - before > 3, "{}", small.stats());
    assert_eq!(cpu.len(), split.len());
    for (c, g) in cpu.iter().zip(&split) {
        let (close, _) = near(c, g);
        assert!(
            close as f64 >= 0.999 * c.len() as f64,
            "{close} of {}",
            c.len()
        );
    }
}

/// A bake's reference poses with every joint moved at random (Fox's
/// `perturbed` poses pass parts through each other): the values agree
/// but at float ties, and a tie is enough to change a bake's bytes (a
/// 96-pose bake had one of 165,888 values one ray apart), which is why an
/// asset does not promise the same bytes from both tracers.
#[test]
fn extreme_poses_of_a_bake_agree_with_the_cpu_but_at_ties() {
    use aobake_core::bake::{BakeParams, Plan, ReferenceSource};
    use aobake_core::method::Method;
    let imported = super::bundled("Fox");
    let c = &imported.character;
    let mut p = BakeParams::new(Method::VertexLinear);
    p.poses = 96;
    p.samples = 32;
    p.reference = ReferenceSource::Perturbed;
    // The bake's own rays.
    let params = p.surface();
    let poses = Plan::new(c, &imported.clips, p).unwrap().reference_poses();
    let gpu = &tracers(aobake_worker::gpu::Backends::VULKAN)[0];
    announce(gpu);
    let (cpu, first, second) = cpu_and_gpu(gpu, || {
        trace_poses(c, &poses, &SceneOptions::default(), &params, &no_progress).unwrap()
    });
    assert_eq!(first, second);
    agree(
        "perturbed Fox poses",
        &cpu.values,
        &first.values,
        1.0 / 32.0,
    );
}
