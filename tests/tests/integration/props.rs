//! Static props (issue 51): a mesh with no skin and no animation bakes
//! through the service as on the command line, in the one pose it has.

use std::time::Duration;

use aobake_e2e::{ADMIN, Options, TestEnv};
use serde_json::json;

use crate::util::{aobake_bake, asset, upload};

fn crates() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/props/Crates/Crates.glb")
}

#[test]
fn a_static_prop_bakes_through_the_service_as_aobake_bake_does() {
    let mut env = TestEnv::start(Options::default());
    env.start_worker(&[]);
    let digest = upload(&env, &crates());
    let params = json!({"poses": 8, "samples": 32, "eval_poses": 2});
    let (status, b) = env
        .request(
            "POST",
            "/v1/bakes",
            ADMIN,
            Some(json!({"character": digest, "method": "static-average", "params": params})),
        )
        .unwrap();
    assert_eq!(status, 202, "{b}");
    // A method that fits AO to poses says what a static mesh takes.
    let (refused, problem) = env
        .request(
            "POST",
            "/v1/bakes",
            ADMIN,
            Some(json!({"character": digest, "method": "vertex-linear"})),
        )
        .unwrap();
    assert!((400..500).contains(&refused), "{refused} {problem}");
    let detail = problem["detail"].as_str().unwrap_or_default();
    assert!(
        detail.contains("no clip moves the mesh") && detail.contains("bake static-average"),
        "{problem}"
    );
    let id = b["id"].as_i64().unwrap();
    let done = env.wait_bake(id, Duration::from_secs(300));
    assert_eq!(done["state"], "done", "{done}");
    let (_, report) = env
        .request("GET", &format!("/v1/bakes/{id}/report"), ADMIN, None)
        .unwrap();
    assert_eq!(report["character"]["clips"], json!(["rest"]), "{report}");
    let served = asset(&env, &done);
    let local = aobake_bake(
        env.dir.path(),
        &crates(),
        &[
            "--method",
            "static-average",
            "--poses",
            "8",
            "--samples",
            "32",
            "--eval-poses",
            "2",
        ],
        "crates",
    );
    assert!(served == local, "the service's asset is aobake bake's");
}
