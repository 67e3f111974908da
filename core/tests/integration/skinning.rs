//! Skinning against three.js (an independent implementation): positions
//! written by `tools/threejs-reference/generate.mjs` for every shared
//! character, three times per clip.

use aobake_core::{Pose, summary::Summary};
use serde::Deserialize;

use crate::util;

#[derive(Deserialize)]
struct Reference {
    file: String,
    samples: Vec<Sample>,
}

#[derive(Deserialize)]
struct Sample {
    clip: usize,
    time: f32,
    primitives: Vec<Primitive>,
}

#[derive(Deserialize)]
struct Primitive {
    node: usize,
    mesh: usize,
    primitive: usize,
    indices: Vec<usize>,
    positions: Vec<f32>,
}

#[test]
fn posed_positions_agree_with_threejs_within_1e4_of_the_diagonal() {
    let dir = util::repo().join("tests/data/threejs");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    files.sort();
    let mut checked = Vec::new();
    for reference in files {
        let reference: Reference =
            serde_json::from_slice(&std::fs::read(&reference).unwrap()).unwrap();
        let Some(path) = util::character_path(&reference.file) else {
            eprintln!(
                "skipped {}: not bundled and ../shared/data is absent",
                reference.file
            );
            continue;
        };
        let imported = util::load(&path);
        let character = &imported.character;
        let diagonal = Summary::of(character, &imported.clips).diagonal;
        let tolerance = 1e-4 * diagonal;
        let mut worst = 0.0f32;
        let mut compared = 0;
        for sample in &reference.samples {
            let pose = Pose::sample(
                &character.skeleton,
                &imported.clips[sample.clip],
                sample.time,
            );
            let posed = character.skin(&pose);
            for prim in &sample.primitives {
                let range = character
                    .primitives
                    .iter()
                    .find(|p| {
                        p.node == prim.node && p.mesh == prim.mesh && p.primitive == prim.primitive
                    })
                    .unwrap_or_else(|| {
                        panic!(
                            "{}: no primitive {}/{}/{}",
                            reference.file, prim.node, prim.mesh, prim.primitive
                        )
                    })
                    .vertices
                    .clone();
                for (k, &i) in prim.indices.iter().enumerate() {
                    let expect = glam::Vec3::from_slice(&prim.positions[3 * k..3 * k + 3]);
                    let got = posed.positions[range.start + i];
                    let error = got.distance(expect);
                    worst = worst.max(error);
                    compared += 1;
                    assert!(
                        error <= tolerance,
                        "{} clip {} t={}: node {} vertex {i}: aobake {got} three.js {expect} (error {error}, tolerance {tolerance})",
                        reference.file,
                        sample.clip,
                        sample.time,
                        prim.node
                    );
                }
            }
        }
        assert!(compared > 0, "{}: nothing compared", reference.file);
        eprintln!(
            "{}: {compared} positions, worst error {:.2e} of diagonal",
            reference.file,
            worst / diagonal
        );
        checked.push(reference.file);
    }
    for bundled in ["SimpleSkin.gltf", "RiggedSimple.glb", "RiggedFigure.glb"] {
        assert!(
            checked.iter().any(|c| c == bundled),
            "{bundled} was not checked"
        );
    }
}
