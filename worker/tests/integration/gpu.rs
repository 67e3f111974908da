//! The WGSL evaluation of the vertex methods, run through wgpu on this
//! machine's adapter (llvmpipe or lavapipe without a GPU), against core's
//! CPU evaluation of the same fitted models.

use aobake_core::{
    Limits, Pose, Upload,
    asset::Method,
    bake::{BakeParams, Plan},
    import_character,
    model::{Block, LinearForm, Model, StaticAverage},
    reference::trace_poses,
    trace::SceneOptions,
};
use aobake_worker::gpu::{Gpu, VertexAo};
use half::f16;

/// f16's machine epsilon: both sides decode the same f16 coefficients and
/// sum in f32, so they may differ only by f32 rounding (and fused
/// multiply-adds on the GPU), far below this.
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
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/data/characters/RiggedFigure/RiggedFigure.glb"
    );
    let bytes = std::fs::read(path).unwrap();
    let imported = import_character(Upload::single(&bytes), &Limits::default()).unwrap();
    let c = &imported.character;
    let gpu = gpu();

    let mut variants = Vec::new();
    let mut linear = BakeParams::new(Method::VertexLinear);
    linear.poses = 96;
    linear.samples = 32;
    variants.push(linear.clone());
    linear.linear.threshold = 0.01;
    variants.push(linear);
    let mut clustered = BakeParams::new(Method::VertexClustered);
    clustered.poses = 96;
    clustered.samples = 32;
    clustered.clustered.pose_clusters = 4;
    clustered.clustered.dimensions = 5;
    variants.push(clustered.clone());
    clustered.clustered.vertex_clusters = 40;
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
        let (model, _) = plan.fit(&poses, &ao).unwrap();
        let models = [model, Model::StaticAverage(StaticAverage::fit(&ao))];
        for model in &models {
            let on_gpu = VertexAo::new(&gpu, model).unwrap();
            let mut tests: Vec<Pose> = plan.test_poses().into_iter().map(|t| t.pose).collect();
            tests.truncate(40);
            let mut max = 0.0f32;
            let mut outputs = Vec::new();
            for pose in &tests {
                let w = model.weights(&c.skeleton, pose);
                let cpu = model.evaluate_weights(&w);
                let gpu = on_gpu.evaluate(&w).unwrap();
                max = max.max(worst(&cpu, &gpu));
                outputs.push(gpu);
            }
            // Not a trivial agreement: real AO, varying with the pose for
            // the pose-dependent methods.
            assert!(outputs[0].iter().any(|&x| x > 0.05 && x < 0.95));
            if model.method() != Method::StaticAverage {
                assert!(worst(&outputs[0], &outputs[outputs.len() - 1]) > 0.01);
            }
            eprintln!("{:?}: worst |GPU − CPU| = {max:e}", model.method());
            assert!(max < F16_EPSILON, "{:?}: {max}", model.method());
        }
    }
}

/// Every finite f16 bit pattern through the shader's decoder: one block
/// holding all of them, read as 0.5 + v·2⁻¹⁷ so that the result stays
/// inside the [0, 1] clamp.
#[test]
fn the_shader_decodes_every_finite_half() {
    let values: Vec<f16> = (0..=u16::MAX)
        .map(f16::from_bits)
        .filter(|h| h.is_finite())
        .collect();
    let n = values.len();
    let form = LinearForm {
        vertices: n,
        blocks: vec![
            Block {
                rows: 1,
                columns: 1,
                coefficients: vec![f16::from_f32(0.5)],
                map: Some(vec![0; n]),
            },
            Block {
                rows: 1,
                columns: n,
                coefficients: values.clone(),
                map: None,
            },
        ],
    };
    let model = Model::StaticAverage(StaticAverage { form });
    let gpu = gpu();
    let weights = [1.0, 2f32.powi(-17)];
    let got = VertexAo::new(&gpu, &model)
        .unwrap()
        .evaluate(&weights)
        .unwrap();
    let cpu = model.evaluate_weights(&weights);
    for (i, (g, want)) in got.iter().zip(&cpu).enumerate() {
        assert!(
            (g - want).abs() <= 1e-7,
            "f16 {:#06x} ({}): GPU {g}, CPU {want}",
            values[i].to_bits(),
            values[i]
        );
    }
}
