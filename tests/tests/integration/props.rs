//! Static props (issue 51): a mesh with no skin and no animation bakes
//! through the service as on the command line, in the one pose it has;
//! and (issue 52, on that cheap bake) a finished bake whose asset is lost
//! is baked again, never answered as done.

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

/// A finished bake whose asset is gone from the blob store (an emptied
/// bucket, an expired object) is never a cache hit: the cache says it is
/// lost, and submitting the request again bakes it again, whose asset
/// `fetch` then serves (issue 52).
#[test]
fn a_lost_asset_is_not_a_cache_hit_and_is_baked_again() {
    let mut env = TestEnv::start(Options::default());
    env.start_worker(&[]);
    let digest = upload(&env, &crates());
    let request = json!({"character": digest, "method": "static-average",
        "params": {"poses": 4, "samples": 16, "eval_poses": 2}});
    let submit = || {
        env.request("POST", "/v1/bakes", ADMIN, Some(request.clone()))
            .unwrap()
    };
    let (status, first) = submit();
    assert_eq!(status, 202, "{first}");
    let id = first["id"].as_i64().unwrap();
    let done = env.wait_bake(id, Duration::from_secs(120));
    let key = done["key"].as_str().unwrap().to_owned();
    let lost = done["asset"].as_str().unwrap().to_owned();
    let (status, _) = env
        .request("GET", &format!("/v1/cache/{key}"), ADMIN, None)
        .unwrap();
    assert_eq!(status, 200);
    // The asset's blob disappears from the store.
    let file = env.data().join("blobs").join(&lost[..2]).join(&lost);
    std::fs::remove_file(&file).unwrap();
    let (status, problem) = env
        .request("GET", &format!("/v1/cache/{key}"), ADMIN, None)
        .unwrap();
    assert_eq!(status, 404, "{problem}");
    let detail = problem["detail"].as_str().unwrap_or_default();
    assert!(
        detail.contains(&format!(
            "bake {id} with key {key} finished, but its asset is gone"
        )),
        "{detail}"
    );
    // Submitted again: a new bake, not the lost one's "done".
    let (status, again) = submit();
    assert_eq!(status, 202, "{again}");
    let second = again["id"].as_i64().unwrap();
    assert_ne!(second, id);
    // Asked again while it runs: the same new bake, not a third.
    let (_, same) = submit();
    assert_eq!(same["id"].as_i64(), Some(second), "{same}");
    let redone = env.wait_bake(second, Duration::from_secs(120));
    assert_eq!(redone["state"], "done", "{redone}");
    let (status, hit) = env
        .request("GET", &format!("/v1/cache/{key}"), ADMIN, None)
        .unwrap();
    assert_eq!((status, hit["id"].as_i64()), (200, Some(second)), "{hit}");
    let bytes = asset(&env, &redone);
    assert_eq!(
        aobake_core::digest::sha256_hex(&bytes),
        lost,
        "the same request bakes the same bytes"
    );
}
