//! The per-pose weights of hand-made vertex-linear and vertex-clustered
//! models (features, clamping, projection, MLS blending, a linear base,
//! the basis mix), held to the bits that aobake-runtime computed before
//! its per-pose step was rewritten to reuse buffers (commit d107b01): the
//! rewrite changed no arithmetic. `GOLDEN_PRINT=1` prints the bits.

use aobake_runtime::method::vertex::{
    Basis, Centering, Coefficients, Features, LinearBase, LinearForm, PoseCluster, VertexClustered,
    VertexLinear,
};
use aobake_runtime::pose_space::{JointAngles, Range};

fn no_coefficients() -> Coefficients {
    Coefficients::Dense(LinearForm {
        vertices: 0,
        blocks: Vec::new(),
    })
}

/// Two rotated joints and one translation (9 angles), matrix features
/// (21) projected onto 4 directions, then a basis of rank 3.
fn linear(features: Features, projected: bool, basis: bool) -> VertexLinear {
    let count = features.count(9, 2);
    let rows = if projected { 4 } else { count };
    let wave = |n: usize, a: f32, b: f32| {
        (0..n)
            .map(|i| (a * i as f32 + b).sin())
            .collect::<Vec<f32>>()
    };
    VertexLinear {
        parameters: rows,
        features,
        rotations: 2,
        projection: projected.then(|| wave(4 * count, 0.37, 0.1)),
        mean: wave(count, 0.71, 0.3).iter().map(|x| 0.1 * x).collect(),
        inv_std: wave(count, 0.53, 0.9).iter().map(|x| 2.0 + x).collect(),
        ranges: (0..9)
            .map(|i| Range {
                min: -0.5 - 0.1 * i as f32,
                max: 0.4 + 0.05 * i as f32,
            })
            .collect(),
        coefficients: no_coefficients(),
        basis: basis.then(|| Basis {
            inputs: rows + 1,
            rank: 3,
            mix: wave(3 * (rows + 1), 0.29, 0.7),
            offset: vec![0.25, -0.5, 0.125],
        }),
    }
}

fn clustered(base: bool, basis: bool) -> VertexClustered {
    let handles = 6;
    let centre = |k: f32| {
        (0..handles)
            .map(|i| (k + 0.3 * i as f32).cos())
            .collect::<Vec<f32>>()
    };
    let clusters: Vec<PoseCluster> = (0..3)
        .map(|j| PoseCluster {
            center: centre(j as f32),
            axes: (0..2 * handles)
                .map(|i| ((i + 7 * j) as f32 * 0.41).sin() * 1.7)
                .collect(),
        })
        .collect();
    let base = base.then(|| {
        Box::new(LinearBase {
            joint_angles: JointAngles::default(),
            weights: linear(Features::RotationVector, false, false),
        })
    });
    let inputs = if base.is_some() { 10 } else { 1 } + 3 * 3;
    VertexClustered {
        handles,
        dimensions: 2,
        alpha: 10.0,
        centering: Centering::Cluster,
        clamp: 1.5,
        clusters,
        form: no_coefficients(),
        base,
        basis: basis.then(|| Basis {
            inputs,
            rank: 4,
            mix: (0..4 * inputs).map(|i| (i as f32 * 0.23).cos()).collect(),
            offset: vec![0.5, 0.25, -0.125, 1.0],
        }),
    }
}

/// Every weight of every case, as f32 bits.
fn bits() -> Vec<u32> {
    let angles: Vec<f64> = (0..9).map(|i| (i as f64 * 1.3 - 4.0) * 0.17).collect();
    let mut out = Vec::new();
    for features in [Features::RotationVector, Features::Matrix] {
        for projected in [false, true] {
            for basis in [false, true] {
                out.extend(linear(features, projected, basis).weights_f64(&angles));
            }
        }
    }
    let near: Vec<f64> = clustered(false, false).clusters[1]
        .center
        .iter()
        .enumerate()
        .map(|(i, &c)| f64::from(c) + 0.05 * (i as f64 - 2.5))
        .collect();
    let on: Vec<f64> = clustered(false, false).clusters[2]
        .center
        .iter()
        .map(|&c| f64::from(c))
        .collect();
    for h in [&near, &on] {
        for basis in [false, true] {
            out.extend(clustered(false, basis).weights_with_f64(h, &[]));
            out.extend(clustered(true, basis).weights_with_f64(h, &angles));
        }
        out.extend(
            clustered(true, false)
                .blend_weights_f64(h)
                .iter()
                .map(|&w| w as f32),
        );
    }
    out.into_iter().map(f32::to_bits).collect()
}

#[test]
fn weights_are_the_bits_they_were() {
    let now = bits();
    if std::env::var_os("GOLDEN_PRINT").is_some() {
        println!("GOLDEN {:?}", now);
        return;
    }
    assert_eq!(now, GOLDEN, "the per-pose weights changed");
}

const GOLDEN: &[u32] = &[
    0xbfbca94b, 0xbfd015f1, 0xbf7c47dc, 0xbe5bab9b, 0x3edd6450, 0x3f491661, 0x3f638da7, 0x3f56d76a,
    0x3f67925f, 0x3f800000, 0xc031e76d, 0xbfd210d1, 0xbfd96f7f, 0x3f800000, 0x3edeb69d, 0x3f3c2fe8,
    0xbff08916, 0x403d3b6c, 0x3f800000, 0xbfe701d8, 0xbfbb3b94, 0xc0153d17, 0x3f800000, 0xbee08510,
    0xbf1394dc, 0x3f8dbaef, 0x3f2f363f, 0xbe9fa3df, 0xbf0bc47a, 0xbea1aef5, 0x3f192801, 0xbe54e2eb,
    0xbe58d417, 0x3f1bf90c, 0xbf38cb93, 0xbfa97100, 0xbe70571e, 0x3e929ac5, 0x3f3eb53f, 0x3e901d44,
    0xbad435e1, 0x3f2fc765, 0x3f27fb73, 0x3f4b64a6, 0x3f800000, 0x3fea6197, 0x401398f0, 0x3fa0b36b,
    0x3f800000, 0x403f6080, 0x403eb759, 0xc01f61a5, 0xc0597475, 0x3f800000, 0x403070ae, 0x40ac9055,
    0x40c7d520, 0x3f800000, 0x3f800000, 0x80000000, 0x00000000, 0x00000000, 0xbec50dc4, 0x3f06bcfa,
    0x3f800000, 0x00000000, 0x00000000, 0x00000000, 0xbfbca94b, 0xbfd015f1, 0xbf7c47dc, 0xbe5bab9b,
    0x3edd6450, 0x3f491661, 0x3f638da7, 0x3f56d76a, 0x3f67925f, 0x3f800000, 0x80000000, 0x00000000,
    0x00000000, 0xbec50dc4, 0x3f06bcfa, 0x3f800000, 0x00000000, 0x00000000, 0x00000000, 0x3fbf3c6a,
    0x3ff63037, 0x40173ea1, 0x3f97b39e, 0x3f800000, 0xbf746dd9, 0xbf040ce7, 0x3d7e9b22, 0xbf5b46ef,
    0x3f800000, 0x00000000, 0x3f800000, 0x00000000, 0x3f800000, 0x80000000, 0x00000000, 0x00000000,
    0x00000000, 0x00000000, 0x00000000, 0x00000000, 0x00000000, 0x3f800000, 0xbfbca94b, 0xbfd015f1,
    0xbf7c47dc, 0xbe5bab9b, 0x3edd6450, 0x3f491661, 0x3f638da7, 0x3f56d76a, 0x3f67925f, 0x3f800000,
    0x80000000, 0x00000000, 0x00000000, 0x00000000, 0x00000000, 0x00000000, 0x00000000, 0x00000000,
    0x3f800000, 0x3db1aafc, 0x3de8db60, 0x3e7c68b0, 0xbf90453a, 0x3f800000, 0xc00838aa, 0xbf97a866,
    0xbd8922cc, 0xbee0c2bd, 0x3f800000, 0x00000000, 0x00000000, 0x3f800000,
];
