//! The WGSL evaluation of the vertex methods, run through wgpu on this
//! machine's adapter (llvmpipe or lavapipe without a GPU), against core's
//! CPU evaluation of the same fitted models.

use aobake_core::{
    Limits, Pose,
    bake::{BakeParams, Plan},
    import_character,
    method::Method,
    method::vertex::{Block, FormRef, LinearForm, Model, StaticAverage},
    trace::SceneOptions,
    trace::trace_poses,
};
use aobake_worker::gpu::{
    Gpu, VertexAo, cubemap_vertex_stage, evaluate_vertex_stage, grid_vertex_stage,
};
use half::f16;

/// f16's machine epsilon.
const F16_EPSILON: f32 = 1.0 / 1024.0;

fn gpu() -> Gpu {
    let gpu = Gpu::new().expect("a wgpu adapter (llvmpipe or lavapipe without a GPU)");
    eprintln!("adapter: {} ({:?})", gpu.info.name, gpu.info.backend);
    gpu
}

fn worst(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn every_vertex_method_matches_the_cpu() {
    let imported = super::bundled("RiggedFigure");
    let c = &imported.character;
    let gpu = gpu();

    let mut variants = Vec::new();
    let mut linear = BakeParams::new(Method::VertexLinear);
    linear.poses = 96;
    linear.samples = 32;
    variants.push(linear.clone());
    // An eigen-AO basis with its small entries dropped (sparse rows).
    let mut sparse_basis = linear.clone();
    (sparse_basis.linear.basis, sparse_basis.linear.basis_cv) = (8, false);
    sparse_basis.linear.basis_threshold = 1.0 / 512.0;
    variants.push(sparse_basis);
    linear.linear.threshold = 0.01;
    variants.push(linear);
    let mut clustered = BakeParams::new(Method::VertexClustered);
    clustered.poses = 96;
    clustered.samples = 32;
    clustered.clustered.pose_clusters = 4;
    clustered.clustered.dimensions = 5;
    variants.push(clustered.clone());
    let mut sparse_basis = clustered.clone();
    (
        sparse_basis.clustered.basis,
        sparse_basis.clustered.basis_cv,
    ) = (8, false);
    sparse_basis.clustered.basis_threshold = 1.0 / 512.0;
    variants.push(sparse_basis);
    clustered.clustered.vertex_clusters = 40;
    clustered.clustered.basis = 0;
    variants.push(clustered);

    for params in variants {
        let plan = Plan::new(c, &imported.clips, params.clone()).unwrap();
        let poses = plan.reference_poses();
        let ao = trace_poses(
            c,
            &poses,
            &SceneOptions::default(),
            &params.surface(),
            &aobake_core::trace::no_progress,
        )
        .unwrap();
        let (model, _) = plan.fit(&poses, &ao, &plan.reference_sources()).unwrap();
        let sparse_basis = params.linear.basis_threshold > 0.0
            && params.method == Method::VertexLinear
            || params.clustered.basis_threshold > 0.0 && params.method == Method::VertexClustered;
        if sparse_basis {
            assert!(
                matches!(model.form(), FormRef::Sparse(_)),
                "{:?}",
                params.method
            );
        }
        let models = [
            model,
            Model::StaticAverage(aobake_core::method::vertex::fit_static_average(&ao)),
        ];
        for model in &models {
            let on_gpu = VertexAo::new(&gpu, model).unwrap();
            let mut tests: Vec<Pose> = plan.test_poses().into_iter().map(|t| t.pose).collect();
            tests.truncate(40);
            let mut max = 0.0f32;
            let mut outputs = Vec::new();
            for (i, pose) in tests.iter().enumerate() {
                let w = model.weights(&c.skeleton, &pose.locals);
                let cpu = model.evaluate_weights(&w);
                let gpu_ao = on_gpu.evaluate(&w).unwrap();
                max = max.max(worst(&cpu, &gpu_ao));
                // The vertex-stage evaluator (WebGL2's: textures, no
                // compute) sums the same terms in the same order as the
                // compute shader on the same adapter: the same bits.
                if i % 8 == 0 {
                    let vs = evaluate_vertex_stage(&gpu, model, &w).unwrap();
                    let same = vs
                        .iter()
                        .zip(&gpu_ao)
                        .all(|(a, b)| a.to_bits() == b.to_bits());
                    assert!(
                        same && vs.len() == gpu_ao.len(),
                        "{:?}: the vertex stage differs",
                        model.method()
                    );
                }
                outputs.push(gpu_ao);
            }
            // Not a trivial agreement: real AO, varying with the pose for
            // the pose-dependent methods.
            assert!(outputs[0].iter().any(|&x| x > 0.05 && x < 0.95));
            if model.method() != Method::StaticAverage {
                assert!(worst(&outputs[0], &outputs[outputs.len() - 1]) > 0.01);
            }
            eprintln!("{:?}: worst |GPU − CPU| = {max:e}", model.method());
            // Both sides decode the same f16 coefficients and sum the same
            // products in the same order in f32: on a software adapter
            // (llvmpipe, lavapipe: no fused multiply-adds) the results are
            // the same bits. A hardware GPU may fuse multiply-adds, which
            // moves the last bit of the f32 sum: bounded there far below
            // an f16 step.
            if gpu.info.device_type == aobake_worker::gpu::DeviceType::Cpu {
                assert_eq!(max, 0.0, "{:?}: not bit for bit", model.method());
            } else {
                assert!(max < F16_EPSILON / 64.0, "{:?}: {max}", model.method());
            }
        }
    }
}

/// Every finite f16 bit pattern through the shader's decoder, exactly. Vertex
/// i reads value i; one block per exponent (binade) holds the values of
/// that binade and a zero column that every other vertex maps to, and its
/// weight scales the binade to [0.25, 0.5) (subnormals below 0.5), so
/// `0.5 + v·w` keeps all 11 significant bits of every value, signs and
/// subnormals included, inside the [0, 1] clamp and exactly in f32.
#[test]
fn the_shader_decodes_every_finite_half_exactly() {
    let values: Vec<f16> = (0..=u16::MAX)
        .map(f16::from_bits)
        .filter(|h| h.is_finite())
        .collect();
    let n = values.len();
    let exponent = |h: f16| u32::from((h.to_bits() >> 10) & 0x1f);
    let mut blocks = vec![Block {
        rows: 1,
        columns: 1,
        coefficients: vec![f16::from_f32(0.5)],
        map: Some(vec![0; n]),
    }];
    let mut weights = vec![1.0f32];
    for e in 0..31u32 {
        let mut coefficients = vec![f16::ZERO];
        let mut map = vec![0u32; n];
        for (i, &h) in values.iter().enumerate() {
            if exponent(h) == e {
                map[i] = coefficients.len() as u32;
                coefficients.push(h);
            }
        }
        blocks.push(Block {
            rows: 1,
            columns: coefficients.len(),
            coefficients,
            map: Some(map),
        });
        // |v| < 2^(e−14) for e ≥ 1 (2^−14 for subnormals): w = 2^(13−e).
        weights.push(2f32.powi(13 - e.max(1) as i32));
    }
    let model = Model::StaticAverage(StaticAverage {
        form: LinearForm {
            vertices: n,
            blocks,
        },
    });
    let gpu = gpu();
    let got = VertexAo::new(&gpu, &model)
        .unwrap()
        .evaluate(&weights)
        .unwrap();
    for (i, (g, h)) in got.iter().zip(&values).enumerate() {
        let w = weights[1 + exponent(*h) as usize];
        let want = 0.5 + h.to_f32() * w;
        assert_eq!(
            *g,
            want,
            "vertex {i}: f16 {:#06x} ({h}) decoded to {}",
            h.to_bits(),
            (g - 0.5) / w
        );
        assert!((0.0..=1.0).contains(&want));
    }
}

/// Parameters of a small cubemap bake: `resolution`² texels, `shells`,
/// `times` time samples, `rays` per point, a token evaluation.
pub(crate) fn small_cubemap(
    method: Method,
    resolution: usize,
    shells: usize,
    times: usize,
    rays: u32,
) -> BakeParams {
    let mut p = BakeParams::new(method);
    p.cubemap = aobake_core::method::cubemap::CubemapOptions {
        resolution,
        shells,
        times,
        rays,
        eval_times: 1,
        eval_points: 16,
        eval_ground: 16,
        eval_rays: 16,
        ground_resolution: 24,
        ..Default::default()
    };
    p
}

/// A small cubemap bake of CesiumMan's walk in `method`'s encoding with
/// the continuous `layout`.
fn cubemap(
    method: Method,
    layout: aobake_core::method::cubemap::ContinuousLayout,
) -> aobake_core::method::cubemap::model::CubemapModel {
    use aobake_core::{
        asset::Container,
        bake::{Bake, BakeInputs, UploadBytes, bake_in_process},
        method::cubemap::model::CubemapModel,
    };
    let bytes = super::bundled_bytes("CesiumMan");
    let inputs = BakeInputs::load(&UploadBytes::single(bytes), &[], &Limits::default()).unwrap();
    let mut p = small_cubemap(method, 8, 3, 24, 16);
    p.cubemap.continuous_layout = layout;
    let baked = bake_in_process(&Bake::new(&inputs, p).unwrap(), None).unwrap();
    CubemapModel::from_container(&Container::from_bytes(&baked.asset).unwrap())
        .unwrap()
        .0
}

#[test]
fn the_wgsl_cubemap_lookup_matches_the_cpu_for_every_encoding_and_on_the_static_ground() {
    use aobake_worker::gpu::CubemapAo;
    use glam::Vec3;
    let gpu = gpu();
    use aobake_core::method::cubemap::ContinuousLayout;
    for (method, layout) in [
        (Method::CubemapDiscrete, ContinuousLayout::Cosine),
        (Method::CubemapContinuous, ContinuousLayout::Cosine),
        (Method::CubemapContinuous, ContinuousLayout::Thirds),
    ] {
        let model = cubemap(method, layout);
        let method = format!("{:?}", model.layout.encoding);
        let s = model.layout.spheroid;
        // Points over the whole spheroid and a little beyond (where the
        // fade-out applies), on a deterministic spiral.
        let points: Vec<Vec3> = (0..4000)
            .map(|n| {
                let f = n as f32;
                let u = Vec3::new(
                    (f * 0.731).sin(),
                    ((f * 0.377).cos() * 1.7).sin(),
                    (f * 1.913).cos(),
                );
                s.centre + s.radii * s.outer * 1.25 * u * ((n % 97) as f32 / 96.0)
            })
            .collect();
        // Points of the ground plane over its static texture's square and
        // a little beyond, where the offset stops.
        let g = model.ground.as_ref().expect("a static ground by default");
        let q = g.square;
        let ground: Vec<Vec3> = (0..2000)
            .map(|n| {
                let f = n as f32;
                let (u, v) = ((f * 0.618).fract(), (f * 0.377).fract());
                Vec3::new(
                    q.min[0] + q.size * (1.2 * u - 0.1),
                    q.height,
                    q.min[1] + q.size * (1.2 * v - 0.1),
                )
            })
            .collect();
        let evaluator = CubemapAo::new(&gpu, &model).unwrap();
        let mut nonzero = 0;
        for phase in [0.0, 0.137, 0.5, 0.9999] {
            let on_gpu = evaluator.evaluate(&ground, phase, true).unwrap();
            let on_cpu: Vec<f32> = ground.iter().map(|&p| model.ground_ao(p, phase)).collect();
            let w = worst(&on_gpu, &on_cpu);
            eprintln!("{method} at phase {phase}, static ground: worst difference {w:e}");
            assert!(w < 1e-5, "{method} at phase {phase}, static ground: {w}");
            let vs = cubemap_vertex_stage(&gpu, &model, &ground, phase, true).unwrap();
            let w = worst(&vs, &on_cpu);
            assert!(
                w < 1e-5,
                "{method} at phase {phase}, static ground, vertex stage: {w}"
            );
            let bare: Vec<f32> = ground.iter().map(|&p| model.occlusion(p, phase)).collect();
            assert!(
                worst(&bare, &on_cpu) > 1e-3,
                "the static ground changes the ground's AO"
            );
            let on_gpu = evaluator.evaluate(&points, phase, false).unwrap();
            let on_cpu: Vec<f32> = points.iter().map(|&p| model.occlusion(p, phase)).collect();
            nonzero += on_cpu.iter().filter(|&&v| v > 0.01).count();
            // Both decode the same bytes; they differ by f32 rounding and
            // the GPU's cos and fused multiply-adds (the CPU's discrete
            // decode runs in f64): measured 5e-7 on llvmpipe, bounded here
            // at 1e-5, far below the field's byte step of 1/255.
            let w = worst(&on_gpu, &on_cpu);
            eprintln!("{method} at phase {phase}: worst difference {w:e}");
            assert!(w < 1e-5, "{method} at phase {phase}: {w}");
            // The vertex stage (textures, WebGL2) runs the same lookup
            // (common/cubemap_lookup.wgsl) on the same adapter.
            let vs = cubemap_vertex_stage(&gpu, &model, &points, phase, false).unwrap();
            let w = worst(&vs, &on_cpu);
            eprintln!("{method} at phase {phase}, vertex stage: worst difference {w:e}");
            assert!(w < 1e-5, "{method} at phase {phase}, vertex stage: {w}");
        }
        assert!(nonzero > 1000, "the test points see occlusion: {nonzero}");
    }
}

/// A small grid bake of the rigid robot, with or without cones.
fn grid(
    cones: bool,
    static_base: bool,
) -> (
    aobake_core::Imported,
    aobake_core::method::grid::model::GridModel,
) {
    use aobake_core::{
        Upload,
        asset::Container,
        bake::{Bake, bake_in_process},
        method::grid::{GridOptions, model::GridModel},
    };
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/data/scenes/RigidRobot/RigidRobot.gltf"
    );
    let bytes = std::fs::read(path).unwrap();
    let imported = import_character(Upload::single(&bytes), &Limits::default()).unwrap();
    let inputs = aobake_core::bake::BakeInputs {
        character: imported.character.clone(),
        clips: imported.clips.clone(),
        character_digest: "robot".into(),
        clip_digests: Vec::new(),
        warnings: Vec::new(),
    };
    let mut p = BakeParams::new(Method::Grid);
    p.grid = GridOptions {
        resolution: 8,
        rays: 32,
        cones,
        tclip_resolution: 16,
        static_base,
        ground_resolution: 8,
        eval_frames: 1,
        eval_ground: 16,
        eval_rays: 16,
        average_frames: 2,
        ..GridOptions::default()
    };
    let baked = bake_in_process(&Bake::new(&inputs, p).unwrap(), None).unwrap();
    let model = GridModel::from_container(&Container::from_bytes(&baked.asset).unwrap())
        .unwrap()
        .0;
    (imported, model)
}

#[test]
fn the_wgsl_grid_lookup_matches_the_cpu_with_and_without_cones_and_base() {
    use aobake_core::{
        bake::preview::grid_weights,
        method::grid::{
            base::Receiver,
            parts::{owners, parts},
        },
    };
    use aobake_shaders::GridReceiver;
    use aobake_worker::gpu::GridAo;
    use glam::Vec3;
    let gpu = gpu();
    for (cones, base) in [(false, false), (true, false), (true, true)] {
        let (imported, model) = grid(cones, base);
        assert_eq!(model.base.is_some(), base);
        if let Some(b) = &model.base {
            assert!(b.vertex_offsets.iter().any(|&o| o != 0.0));
            assert!(b.ground.offsets.iter().any(|&o| o != 0.0));
        }
        let c = &imported.character;
        let owner = owners(
            &parts(c, aobake_core::method::grid::PartsMode::Rigid).unwrap(),
            c.vertex_count(),
        );
        let evaluator = GridAo::new(&gpu, &model).unwrap();
        let mut nonzero = 0;
        for (clip, time) in [(0, 0.3), (1, 1.1)] {
            let pose = Pose::sample(&c.skeleton, &imported.clips[clip], time);
            let posed = c.skin(&pose);
            let palette = c.joint_matrices(&pose);
            let poses = model.poses(&palette);
            // The vertices on their parts, then points around the robot
            // (ground receivers, on no part) with normals on a spiral.
            let mut receivers: Vec<(Vec3, Vec3, Receiver)> = posed
                .positions
                .iter()
                .zip(&posed.normals)
                .zip(&owner)
                .enumerate()
                .map(|(index, ((&p, &n), &part))| (p, n, Receiver::Vertex { index, part }))
                .collect();
            for k in 0..2000 {
                let f = k as f32;
                let p = Vec3::new(
                    (f * 0.731).sin() * 0.6,
                    1.0 + (f * 0.377).cos(),
                    (f * 1.913).cos() * 0.6,
                );
                let n = Vec3::new((f * 0.51).cos(), (f * 0.23).sin(), (f * 0.87).sin()).normalize();
                receivers.push((p, n, Receiver::Ground));
            }
            let on_cpu: Vec<f32> = receivers
                .iter()
                .map(|&(p, n, r)| model.ao(&poses, p, n, r))
                .collect();
            let packed: Vec<GridReceiver> = receivers
                .iter()
                .map(|&(p, n, r)| {
                    let part = match r {
                        Receiver::Vertex { part, .. } => part,
                        _ => None,
                    };
                    GridReceiver::new(
                        p.to_array(),
                        n.to_array(),
                        part.map_or(GridReceiver::NO_PART, |o| o as u32),
                        model.offset(r, p),
                    )
                })
                .collect();
            let on_gpu = evaluator
                .evaluate(&packed, &grid_weights(&model, &palette))
                .unwrap();
            nonzero += on_cpu.iter().filter(|&&v| v > 0.01).count();
            // The same bytes, trilinear weights and table on both sides;
            // they differ by f32 rounding and fused multiply-adds.
            let w = worst(&on_gpu, &on_cpu);
            eprintln!("cones {cones}, base {base}, clip {clip}: worst difference {w:e}");
            assert!(w < 1e-5, "cones {cones}, base {base}, clip {clip}: {w}");
            // The vertex stage (textures, WebGL2) runs the same lookup
            // (common/grid_lookup.wgsl) on the same adapter.
            let vs =
                grid_vertex_stage(&gpu, &model, &grid_weights(&model, &palette), &packed).unwrap();
            let w = worst(&vs, &on_cpu);
            eprintln!(
                "cones {cones}, base {base}, clip {clip}, vertex stage: worst difference {w:e}"
            );
            assert!(
                w < 1e-5,
                "cones {cones}, base {base}, clip {clip}, vertex stage: {w}"
            );
        }
        assert!(nonzero > 500, "the receivers see occlusion: {nonzero}");
    }
}
