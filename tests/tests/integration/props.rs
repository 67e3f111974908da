//! Static props (issue 51): a mesh with no skin and no animation bakes
//! through the service as on the command line, in the one pose it has;
//! and (issue 52, on that cheap bake) a finished bake whose asset is lost
//! is baked again, never answered as done.

use std::time::Duration;

use aobake_e2e::{ADMIN, Options, TestEnv, TestS3};
use serde_json::{Value, json};

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
    assert_eq!(again["rebakes"].as_i64(), Some(id), "the answer says so");
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
    // Lost again: `aobake retry` queues the done bake again, running only
    // the jobs that make what it lost.
    let finished = |id: i64| -> Vec<(String, Value)> {
        let (_, view) = env
            .request("GET", &format!("/v1/bakes/{id}"), ADMIN, None)
            .unwrap();
        view["jobs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|j| {
                (
                    j["kind"].as_str().unwrap().to_owned(),
                    j["finished_at"].clone(),
                )
            })
            .collect()
    };
    let before = finished(second);
    std::fs::remove_file(&file).unwrap();
    let out = env.aobake(&["retry", &second.to_string()]);
    assert!(out.status.success(), "{out:?}");
    let retried = env.wait_bake(second, Duration::from_secs(120));
    assert_eq!(retried["state"], "done", "{retried}");
    assert_eq!(retried["asset"].as_str(), Some(lost.as_str()));
    assert!(file.exists(), "the asset stored again");
    let after = finished(second);
    let ran: Vec<&str> = before
        .iter()
        .zip(&after)
        .filter(|(b, a)| b.1 != a.1)
        .map(|(b, _)| b.0.as_str())
        .collect();
    assert!(ran.contains(&"assemble"), "{ran:?}");
    assert!(
        !ran.contains(&"sample"),
        "the samples it held were kept: {ran:?}"
    );
}

/// `aobake blobs verify` on the blob store a server runs on (`blobs`:
/// none for the data folder's): a done bake, then its asset deleted, its
/// report's bytes changed and a sample job's output deleted behind the
/// server's back (`lose`, `corrupt`). Verify lists all three and exits 1;
/// `--repair` queues the bake again, which bakes the same bytes; verify
/// then finds nothing.
fn blobs_verify_finds_and_repairs(
    env: &mut TestEnv,
    blobs: Option<&str>,
    lose: &dyn Fn(&TestEnv, &str),
    corrupt: &dyn Fn(&TestEnv, &str),
) {
    env.start_worker(&[]);
    let digest = upload(env, &crates());
    let request = json!({"character": digest, "method": "static-average",
        "params": {"poses": 4, "samples": 16, "eval_poses": 2}});
    let (status, first) = env
        .request("POST", "/v1/bakes", ADMIN, Some(request))
        .unwrap();
    assert_eq!(status, 202, "{first}");
    let id = first["id"].as_i64().unwrap();
    let done = env.wait_bake(id, Duration::from_secs(120));
    let (asset_digest, report) = (
        done["asset"].as_str().unwrap().to_owned(),
        done["report"].as_str().unwrap().to_owned(),
    );
    let (_, view) = env
        .request("GET", &format!("/v1/bakes/{id}"), ADMIN, None)
        .unwrap();
    let sample = view["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .find(|j| j["kind"] == "sample")
        .expect("a sample job")
        .clone();
    let sampled = sample["outputs"][0]["digest"].as_str().unwrap().to_owned();
    let data = env.data();
    let data = data.to_str().unwrap();
    let verify = |repair: bool| {
        let mut args = vec!["blobs", "verify", "--data", data];
        if let Some(url) = blobs {
            args.extend(["--blobs", url]);
        }
        if repair {
            args.push("--repair");
        }
        let out = env.aobake(&args);
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (code, text, err) = verify(false);
    assert_eq!(code, Some(0), "{text}{err}");
    assert!(text.contains(", 0 damaged"), "{text}");
    lose(env, &asset_digest);
    lose(env, &sampled);
    corrupt(env, &report);
    let (code, text, err) = verify(false);
    assert_eq!(code, Some(1), "{text}{err}");
    for line in [
        format!("missing  {asset_digest}  bake {id} asset: `--repair` queues the bake again"),
        format!("corrupt  {report}  bake {id} report: `--repair` queues the bake again"),
        format!("missing  {sampled}  job {} (sample) output ", sample["id"]),
    ] {
        assert!(text.contains(&line), "{line:?} in\n{text}");
    }
    assert!(err.contains("--repair deletes what is corrupt"), "{err}");
    let (code, text, err) = verify(true);
    assert_eq!(code, Some(0), "{text}{err}");
    assert!(
        text.contains(&format!(
            "corrupt  {report}  bake {id} report: deleted; the bake is queued again"
        )),
        "{text}"
    );
    assert!(
        text.contains(&format!("bakes queued again: {id}")),
        "{text}"
    );
    let redone = env.wait_bake(id, Duration::from_secs(120));
    assert_eq!(redone["state"], "done", "{redone}");
    assert_eq!(redone["report"].as_str(), Some(report.as_str()));
    let bytes = asset(env, &redone);
    assert_eq!(aobake_core::digest::sha256_hex(&bytes), asset_digest);
    let (code, text, err) = verify(false);
    assert_eq!(code, Some(0), "{text}{err}");
    assert!(text.contains(", 0 damaged"), "{text}");
}

#[test]
fn blobs_verify_finds_and_repairs_lost_and_corrupt_blobs_on_disk() {
    let mut env = TestEnv::start(Options::default());
    let file = |env: &TestEnv, d: &str| env.data().join("blobs").join(&d[..2]).join(d);
    blobs_verify_finds_and_repairs(
        &mut env,
        None,
        &|env, d| std::fs::remove_file(file(env, d)).unwrap(),
        &|env, d| std::fs::write(file(env, d), b"not the report").unwrap(),
    );
}

#[test]
fn blobs_verify_finds_and_repairs_lost_and_corrupt_blobs_on_s3() {
    let s3 = TestS3::start();
    let mut env = TestEnv::start(Options {
        blobs: Some(s3.url.clone()),
        ..Options::default()
    });
    blobs_verify_finds_and_repairs(
        &mut env,
        Some(&s3.url),
        &|_, d| s3.delete_blob(d),
        &|_, d| s3.overwrite_blob(d, b"not the report"),
    );
}
