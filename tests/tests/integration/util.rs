//! Shared steps: uploads, submissions and local reference bakes.

use std::path::Path;

use aobake_e2e::{ADMIN, TestEnv, binary};
use serde_json::{Value, json};

/// Small but real bake parameters (flags of `aobake bake` and `submit`).
pub(crate) const QUICK: &[&str] = &[
    "--method",
    "vertex-linear",
    "--samples",
    "32",
    "--eval-poses",
    "2",
    "--eval-fps",
    "10",
];

/// The same parameters as the API's `params` object, with `poses`.
pub(crate) fn quick_params(poses: usize) -> Value {
    json!({"samples": 32, "eval_poses": 2, "eval_fps": 10.0, "poses": poses})
}

/// Uploads a character; returns its digest.
pub(crate) fn upload(env: &TestEnv, path: &Path) -> String {
    let bytes = std::fs::read(path).unwrap();
    let (status, body, _) = env.post_bytes("/v1/characters", ADMIN, "model/gltf-binary", &bytes);
    assert!(status == 201 || status == 200, "{status} {body}");
    body["digest"].as_str().unwrap().to_owned()
}

/// Submits a vertex-linear bake; returns the answer.
pub(crate) fn submit(env: &TestEnv, character: &str, poses: usize) -> (u16, Value) {
    env.request(
        "POST",
        "/v1/bakes",
        ADMIN,
        Some(json!({"character": character, "method": "vertex-linear", "params": quick_params(poses)})),
    )
    .unwrap()
}

/// `aobake bake` of the same request in this process's temp dir; returns
/// the asset bytes.
pub(crate) fn local_bake(dir: &Path, character: &Path, poses: usize) -> Vec<u8> {
    let out = dir.join(format!("local-{poses}.aob"));
    let poses = poses.to_string();
    let mut args: Vec<&str> = vec!["bake"];
    let c = character.to_str().unwrap();
    args.push(c);
    args.extend(QUICK);
    args.extend(["--poses", &poses]);
    let status = std::process::Command::new(binary())
        .args(&args)
        .arg("--out")
        .arg(&out)
        .arg("--report")
        .arg(dir.join("local.json"))
        .env("RAYON_NUM_THREADS", "2")
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    std::fs::read(out).unwrap()
}

/// The asset bytes of a finished bake.
pub(crate) fn asset(env: &TestEnv, bake: &Value) -> Vec<u8> {
    let digest = bake["asset"]
        .as_str()
        .expect("a finished bake has an asset");
    let agent: ureq::Agent = ureq::Agent::config_builder().build().into();
    agent
        .get(format!("{}/v1/assets/{digest}", env.url))
        .header("authorization", format!("Bearer {ADMIN}"))
        .call()
        .unwrap()
        .body_mut()
        .with_config()
        .limit(1 << 30)
        .read_to_vec()
        .unwrap()
}
