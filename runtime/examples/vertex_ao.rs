//! What an engine does with a vertex-method asset (static average,
//! vertex-linear, vertex-clustered), through aobake-runtime alone: read
//! it, set the local transforms of the nodes it animates by name, compute
//! the pose's weights and every vertex's AO.
//!
//! ```text
//! cargo run -p aobake-runtime --example vertex_ao -- ASSET [POSE.json]
//! ```
//!
//! `POSE.json` is the frame's local transforms by node name, as the
//! engine's animation gives them:
//!
//! ```json
//! { "Hips": { "translation": [0, 1, 0], "rotation": [0, 0, 0, 1], "scale": [1, 1, 1] } }
//! ```
//!
//! Nodes it does not name keep their rest transforms; without it the
//! whole rig is at rest. Prints the rig, the weights and the AO's range.

use std::collections::BTreeMap;

use aobake_runtime::{method::vertex::VertexAo, rig::Transform};

/// Prints the error as a person reads it (`main` returning it would print
/// its `Debug` form).
fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let asset = args.next().ok_or("usage: vertex_ao ASSET [POSE.json]")?;
    let mut ao = VertexAo::from_bytes(&std::fs::read(&asset)?)?;
    println!(
        "{asset}: {}, {} vertices, {} weights per pose, rig of {} nodes",
        ao.header().method.name(),
        ao.vertices(),
        ao.weight_count(),
        ao.skeleton().nodes.len()
    );
    if let Some(path) = args.next() {
        let pose: BTreeMap<String, Transform> = serde_json::from_slice(&std::fs::read(path)?)?;
        for (name, local) in &pose {
            let node = ao
                .node(name)
                .ok_or_else(|| format!("the rig has no node named {name:?}"))?;
            ao.set_local(node, *local);
        }
        println!("set {} nodes", pose.len());
    }
    let weights = ao.weights();
    let shown: Vec<String> = weights.iter().take(8).map(|w| format!("{w:.3}")).collect();
    println!(
        "weights: [{}{}]",
        shown.join(", "),
        if weights.len() > 8 { ", …" } else { "" }
    );
    let values = ao.evaluate();
    let mean = values.iter().map(|&a| f64::from(a)).sum::<f64>() / values.len().max(1) as f64;
    let (lo, hi) = values
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &a| {
            (lo.min(a), hi.max(a))
        });
    println!(
        "AO over {} vertices: min {lo:.3}, mean {mean:.3}, max {hi:.3}",
        values.len()
    );
    Ok(())
}
