//! The happy path as a studio and its CI live it.

use std::time::Duration;

use serde_json::json;

use aobake_e2e::{ADMIN, Options, TestEnv, TestPostgres, TestS3, character};

use crate::util::{
    Follower, QUICK, asset, follow_events, local_bake, quick_params, submit, upload,
};

#[test]
fn a_service_bake_is_byte_identical_to_aobake_bake_and_cached_by_key() {
    let mut env = TestEnv::start(Options::default());
    // One worker traces on the GPU tracer (lavapipe or llvmpipe here), the
    // other on the CPU: the same rays, so the same bytes as `aobake bake`.
    env.start_worker(&[("AOBAKE_GPU", "require")]);
    env.start_worker(&[("AOBAKE_GPU", "off")]);
    let cm = character("CesiumMan");
    let cm_arg = cm.to_str().unwrap();
    let mut args = vec!["submit", cm_arg, "--poses", "24", "--wait"];
    args.extend(QUICK);
    let out = env.aobake(&args);
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "{stdout}\n{}\n{}",
        String::from_utf8_lossy(&out.stderr),
        env.worker_logs()
    );
    // "bake 1: key K, queued", then the summary.
    let key = stdout
        .split("key ")
        .nth(1)
        .and_then(|s| s.split(',').next())
        .unwrap()
        .to_owned();
    assert_eq!(key.len(), 64, "{stdout}");
    assert!(stdout.contains("frames of the training clips"), "{stdout}");
    // CI computes the same key without baking: `aobake key` on the same
    // file and flags.
    let mut args = vec!["key", cm_arg, "--poses", "24"];
    args.extend(QUICK);
    let out = env.aobake(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), key);
    // For scripts: `submit --json [--wait]` prints the bake alone, here
    // the finished one (the same key: the cache answers).
    for wait in [false, true] {
        let mut args = vec!["submit", cm_arg, "--poses", "24", "--json"];
        args.extend(QUICK);
        if wait {
            args.push("--wait");
        }
        let out = env.aobake(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let printed: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(
            (&printed["key"], &printed["state"]),
            (&json!(key), &json!("done"))
        );
        assert_eq!(
            printed["asset"].as_str().map(str::len),
            Some(64),
            "{printed}"
        );
    }
    // And a client without the command line, from the file's sha256 and
    // the request it would send: POST /v1/keys.
    let digest = aobake_core::digest::sha256_hex(&std::fs::read(&cm).unwrap());
    let request =
        json!({"character": digest, "method": "vertex-linear", "params": quick_params(24)});
    let (status, computed) = env
        .request("POST", "/v1/keys", ADMIN, Some(request))
        .unwrap();
    assert_eq!((status, &computed["key"]), (200, &json!(key)), "{computed}");
    assert_eq!(computed["algorithm_version"], 10, "{computed}");
    assert_eq!(computed["params"]["poses"], 24, "{computed}");
    // Digests need not be uploads; a malformed one, an unknown method or
    // parameter is refused by name.
    let unseen = json!({"character": "ab".repeat(32), "method": "grid"});
    let (status, _) = env
        .request("POST", "/v1/keys", ADMIN, Some(unseen))
        .unwrap();
    assert_eq!(status, 200);
    for (bad, code) in [
        (
            json!({"character": "nothex", "method": "grid"}),
            "bad_digest",
        ),
        (json!({"character": digest, "method": "nope"}), "bad_method"),
        (
            json!({"character": digest, "method": "grid", "params": {"rays": -1}}),
            "bad_params",
        ),
    ] {
        let (status, problem) = env.request("POST", "/v1/keys", ADMIN, Some(bad)).unwrap();
        assert_eq!(
            (status, problem["code"].as_str()),
            (400, Some(code)),
            "{problem}"
        );
    }
    let out = env.aobake(&["status", "1"]);
    let status = String::from_utf8_lossy(&out.stdout);
    // Jobs counted in the dashboard's groups: every job of a done bake is
    // done.
    let (_, view) = env.request("GET", "/v1/bakes/1", ADMIN, None).unwrap();
    let jobs = view["jobs"].as_array().unwrap().len();
    assert!(
        status.starts_with("bake 1: done")
            && status.contains(&format!("; jobs: {jobs} done; key ")),
        "{status}"
    );

    let fetched = env.dir.path().join("svc.aob");
    let out = env.aobake(&["fetch", "--key", &key, "--out", fetched.to_str().unwrap()]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let service = std::fs::read(&fetched).unwrap();
    // The file has the mode any new file gets here (as one std::fs::write
    // makes), not a temporary file's 0600; a file fetched over keeps its
    // own.
    use std::os::unix::fs::PermissionsExt as _;
    let mode = |p: &std::path::Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    let reference = env.dir.path().join("reference");
    std::fs::write(&reference, b"").unwrap();
    assert_eq!(mode(&fetched), mode(&reference));
    std::fs::set_permissions(&fetched, std::fs::Permissions::from_mode(0o640)).unwrap();
    let again = env.aobake(&["fetch", "--key", &key, "--out", fetched.to_str().unwrap()]);
    assert!(again.status.success());
    assert_eq!(mode(&fetched), 0o640);
    // Into a pipe, as a script does: straight through, the same bytes
    // (and no temporary file is left beside the one it wrote).
    let piped = env.aobake(&["fetch", "--key", &key, "--out", "/dev/stdout"]);
    assert!(
        piped.status.success(),
        "{}",
        String::from_utf8_lossy(&piped.stderr)
    );
    assert!(piped.stdout == service, "{} bytes", piped.stdout.len());
    let beside: Vec<_> = std::fs::read_dir(env.dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".tmp"))
        .collect();
    assert!(beside.is_empty(), "{beside:?}");
    let local = local_bake(env.dir.path(), &cm, 24);
    assert!(
        service == local,
        "the service's asset differs from aobake bake's"
    );

    // The same request again: 200 at once, the same asset.
    let digest = upload(&env, &cm);
    let (status, again) = submit(&env, &digest, 24);
    assert_eq!(status, 200, "{again}");
    assert_eq!(again["state"], "done");
    assert_eq!(asset(&env, &again), local);
    let (status, cached) = env
        .request("GET", &format!("/v1/cache/{key}"), ADMIN, None)
        .unwrap();
    assert_eq!((status, &cached["id"]), (200, &again["id"]));

    // No bake for a key: exit 4, so CI can branch.
    let out = env.aobake(&["fetch", "--key", &"0".repeat(64), "--out", "x.aob"]);
    assert_eq!(out.status.code(), Some(4));
    assert!(!env.dir.path().join("x.aob").exists());
    // Nor for an id the server has never had.
    let out = env.aobake(&["fetch", "999", "--out", "x.aob"]);
    assert_eq!(out.status.code(), Some(4));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("no bake 999"),
        "{out:?}"
    );

    // Versions of the character, newest first.
    let (_, versions) = env
        .request(
            "GET",
            &format!("/v1/characters/{digest}/bakes?method=vertex-linear"),
            ADMIN,
            None,
        )
        .unwrap();
    assert_eq!(versions[0]["id"], again["id"]);

    // The report and the metrics.
    let id = again["id"].as_i64().unwrap();
    let (status, report) = env
        .request("GET", &format!("/v1/bakes/{id}/report"), ADMIN, None)
        .unwrap();
    assert_eq!(status, 200);
    assert_eq!(report["bake_key"], key.as_str());
    let (_, metrics) = env.request("GET", "/metrics", ADMIN, None).unwrap();
    let metrics = metrics.as_str().unwrap();
    assert!(
        metrics.contains("aobake_jobs{state=\"completed\"}"),
        "{metrics}"
    );
    assert!(metrics.contains("aobake_request_seconds"), "{metrics}");

    // The bake's jobs: every one completed once, by a worker, with its
    // checkpointed sample jobs' cursors.
    let (_, bake) = env
        .request("GET", &format!("/v1/bakes/{id}"), ADMIN, None)
        .unwrap();
    let jobs = bake["jobs"].as_array().unwrap();
    assert!(
        jobs.iter()
            .all(|j| j["state"] == "completed" && j["attempts"] == 1)
    );
    assert_eq!(bake["progress"]["done"], bake["progress"]["total"]);
    let (_, workers) = env.request("GET", "/v1/workers", ADMIN, None).unwrap();
    assert_eq!(workers.as_array().unwrap().len(), 2, "{workers}");
    // Each worker said what traces its rays.
    let mut tracers: Vec<&str> = workers
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w["tracer"].as_str().unwrap())
        .collect();
    tracers.sort_unstable();
    assert_eq!(tracers[0], "cpu", "{workers}");
    assert!(tracers[1].starts_with("gpu: "), "{workers}");
    assert_eq!(jobs.last().unwrap()["kind"], "preview");
    // `aobake workers` lists the same two, with their tracers.
    let listed = env.aobake(&["workers"]);
    let table = String::from_utf8_lossy(&listed.stdout);
    assert!(listed.status.success(), "{listed:?}");
    assert!(table.starts_with("worker  "), "{table}");
    for w in workers.as_array().unwrap() {
        let row = table
            .lines()
            .find(|l| l.starts_with(w["id"].as_str().unwrap()))
            .unwrap_or_else(|| panic!("{table}"));
        assert!(
            row.contains(w["tracer"].as_str().unwrap()) && row.contains(" ago (started "),
            "{row}"
        );
    }

    // The previews: three stills and an animation of the held-out clip,
    // each a PNG served as an image under its digest, and each naming the
    // adapter that drew it.
    let (status, previews) = env
        .request("GET", &format!("/v1/bakes/{id}/previews"), ADMIN, None)
        .unwrap();
    assert_eq!(status, 200, "{previews}");
    assert_eq!(previews["state"], "completed");
    let items = previews["previews"].as_array().unwrap();
    let kinds: Vec<&str> = items.iter().map(|p| p["kind"].as_str().unwrap()).collect();
    assert_eq!(
        kinds,
        ["still", "still", "still", "animation"],
        "{previews}"
    );
    for p in items {
        assert!(p["adapter"].as_str().unwrap().len() > 3, "{p}");
        assert!(p["frame_ms"].as_f64().unwrap() > 0.0, "{p}");
        let digest = p["digest"].as_str().unwrap();
        let (content_type, bytes) = get_bytes(&env, &format!("/v1/previews/{digest}"));
        assert_eq!(content_type, "image/png");
        assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"));
        assert_eq!(aobake_core::bake::sha256_hex(&bytes), digest);
    }
    let animation = &items[3];
    assert!(animation["times"].as_array().unwrap().len() > 10);
    // Only PNGs are images: the asset's digest is no preview.
    let asset_digest = again["asset"].as_str().unwrap();
    let (status, problem) = env
        .request("GET", &format!("/v1/previews/{asset_digest}"), ADMIN, None)
        .unwrap();
    assert_eq!(status, 404, "{problem}");

    viewer_bundles_hold_what_an_engine_computes(&env, id, &cm, &service);
}

/// An `AOVW` bundle's description and its arrays' bytes by name.
fn read_bundle(
    bytes: &[u8],
) -> (
    serde_json::Value,
    std::collections::HashMap<String, Vec<u8>>,
) {
    assert_eq!(&bytes[..4], b"AOVW");
    let len = u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize;
    let meta: serde_json::Value = serde_json::from_slice(&bytes[12..12 + len]).unwrap();
    let arrays = meta["arrays"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(name, a)| {
            let offset = 12 + len + a["offset"].as_u64().unwrap() as usize;
            let count = a["count"].as_u64().unwrap() as usize;
            assert_eq!(offset % 4, 0, "{name}");
            (name.clone(), bytes[offset..offset + 4 * count].to_vec())
        })
        .collect();
    (meta, arrays)
}

fn floats(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

/// The dashboard viewer's bundles: the scene has the character and the
/// asset's arrays; a clip's frames hold, at every frame, the weights the
/// asset's model computes for that pose (bit for bit), and the previews'
/// truth with the model's error at their frames. Only a token that may
/// see the character's mesh (submit) gets them.
fn viewer_bundles_hold_what_an_engine_computes(
    env: &TestEnv,
    id: i64,
    character: &std::path::Path,
    asset: &[u8],
) {
    use aobake_core::{
        Limits, Upload, asset::Container, import_character, method::vertex::Model, rig::pose::Pose,
    };
    let (content_type, bytes) = get_bytes(env, &format!("/v1/bakes/{id}/viewer"));
    assert_eq!(content_type, "application/vnd.aobake.viewer");
    let (scene, arrays) = read_bundle(&bytes);
    let v = scene["vertices"].as_u64().unwrap() as usize;
    assert_eq!(v, 3273);
    assert_eq!(scene["model"]["family"], "vertex");
    assert_eq!(arrays["positions"].len(), 4 * 3 * v);
    assert_eq!(arrays["static_ao"].len(), 4 * v);
    assert!(
        scene["program"]["vertex"]
            .as_str()
            .unwrap()
            .starts_with("#version 300 es")
    );
    let clip = scene["preview_clip"].as_str().unwrap();

    let (_, bytes) = get_bytes(env, &format!("/v1/bakes/{id}/viewer/frames?clip={clip}"));
    let (frames, arrays) = read_bundle(&bytes);
    let times: Vec<f32> = frames["times"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_f64().unwrap() as f32)
        .collect();
    let per_frame = frames["inputs"].as_u64().unwrap() as usize;
    let inputs = floats(&arrays["inputs"]);
    assert_eq!(inputs.len(), per_frame * times.len());
    let bytes = std::fs::read(character).unwrap();
    let imported = import_character(Upload::single(&bytes), &Limits::default()).unwrap();
    let skeleton = &imported.character.skeleton;
    let (model, _) = Model::from_container(&Container::from_bytes(asset).unwrap()).unwrap();
    let clip = imported.clips.iter().find(|c| c.name == clip).unwrap();
    for (i, &t) in times.iter().enumerate() {
        let want = model.weights(skeleton, &Pose::sample(skeleton, clip, t).locals);
        assert_eq!(
            &inputs[i * per_frame..(i + 1) * per_frame],
            want.as_slice(),
            "frame {i} at {t} s"
        );
    }
    // The previews' clip plays at their frames (3 stills and their
    // animation's), every one with truth, so nothing comes and goes as it
    // plays; it opens on the first still.
    let truth = frames["truth"].as_array().unwrap();
    assert!(truth.iter().all(|t| t.is_u64()), "{truth:?}");
    let start = frames["start"].as_u64().unwrap() as usize;
    assert_eq!(times[start], 0.15 * 2.0);
    let errors = frames["errors"].as_array().unwrap();
    assert!(errors.len() > 10, "{errors:?}");
    assert_eq!(floats(&arrays["truth"]).len(), errors.len() * v);
    for e in errors {
        let rmse = e["character"]["rmse"].as_f64().unwrap();
        assert!(rmse > 0.0 && rmse < 0.2, "{e}");
    }
    // The mesh is the studio's: `read` alone is refused, and why.
    let reader = env.token(&["read"]);
    let (status, problem) = env
        .request("GET", &format!("/v1/bakes/{id}/viewer"), &reader, None)
        .unwrap();
    assert_eq!(status, 403, "{problem}");
    assert!(
        problem["detail"].as_str().unwrap().contains("submit"),
        "{problem}"
    );
    let (status, problem) = env
        .request(
            "GET",
            &format!("/v1/bakes/{id}/viewer/frames?clip=nope"),
            ADMIN,
            None,
        )
        .unwrap();
    assert_eq!(status, 404, "{problem}");
    assert!(
        problem["detail"].as_str().unwrap().contains("animation_0"),
        "{problem}"
    );
    let (status, _) = env
        .request("GET", "/v1/bakes/999/viewer", ADMIN, None)
        .unwrap();
    assert_eq!(status, 404);
}

/// A GET's content type and body bytes.
fn get_bytes(env: &TestEnv, path: &str) -> (String, Vec<u8>) {
    let agent: ureq::Agent = ureq::Agent::config_builder().build().into();
    let mut response = agent
        .get(format!("{}{path}", env.url))
        .header("authorization", format!("Bearer {ADMIN}"))
        .call()
        .unwrap();
    let content_type = response
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or_default()
        .to_owned();
    let bytes = response
        .body_mut()
        .with_config()
        .limit(64 << 20)
        .read_to_vec()
        .unwrap();
    (content_type, bytes)
}

#[test]
fn assets_are_served_with_etag_and_ranges() {
    let mut env = TestEnv::start(Options::default());
    env.start_worker(&[]);
    let digest = upload(&env, &character("RiggedSimple"));
    // A submit's Location is the bake, there to follow.
    let request =
        json!({"character": digest, "method": "vertex-linear", "params": quick_params(8)});
    let (status, b, headers) = env.post_bytes(
        "/v1/bakes",
        ADMIN,
        "application/json",
        request.to_string().as_bytes(),
    );
    assert_eq!(status, 202, "{b}");
    let location = &headers.iter().find(|(k, _)| k == "location").unwrap().1;
    assert_eq!(*location, format!("/v1/bakes/{}", b["id"]));
    let (_, followed) = env.request("GET", location, ADMIN, None).unwrap();
    assert_eq!(followed["id"], b["id"]);
    let b = env.wait_bake(b["id"].as_i64().unwrap(), Duration::from_secs(120));
    assert_eq!(b["state"], "done", "{b}");
    assert_served_with_etag_and_ranges(&env, &b);
}

#[test]
fn a_service_on_s3_blobs_bakes_the_same_bytes_and_serves_ranges() {
    // A real S3-compatible server (moto); the server keeps no blob on disk.
    let s3 = TestS3::start();
    let mut env = TestEnv::start(Options {
        blobs: Some(s3.url.clone()),
        ..Options::default()
    });
    env.start_worker(&[]);
    let rigged = character("RiggedSimple");
    let digest = upload(&env, &rigged);
    let (_, b) = submit(&env, &digest, 8);
    let b = env.wait_bake(b["id"].as_i64().unwrap(), Duration::from_secs(120));
    assert_eq!(b["state"], "done", "{b}");
    assert!(asset(&env, &b) == local_bake(env.dir.path(), &rigged, 8));
    assert_served_with_etag_and_ranges(&env, &b);
    assert!(
        !env.data().join("blobs").exists(),
        "blobs were written to the data directory"
    );
}

/// The asset of bake `b`: a 304 for its ETag, a 206 for a byte range, a
/// 416 with its length for a range it does not have, and the whole of it
/// when If-Range names something else.
fn assert_served_with_etag_and_ranges(env: &TestEnv, b: &serde_json::Value) {
    let asset_digest = b["asset"].as_str().unwrap();
    let agent: ureq::Agent = ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build()
        .into();
    let url = format!("{}/v1/assets/{asset_digest}", env.url);
    let auth = format!("Bearer {ADMIN}");
    let whole = asset(env, b);
    let mut r = agent
        .get(&url)
        .header("authorization", &auth)
        .header("if-none-match", format!("\"{asset_digest}\""))
        .call()
        .unwrap();
    assert_eq!(r.status().as_u16(), 304);
    assert!(r.body_mut().read_to_vec().unwrap().is_empty());
    // HEAD: GET's status and headers (the length of the whole, or of the
    // range); 404 for a digest that is not there.
    let head = |range: Option<&str>, digest: &str| {
        let mut req = agent
            .head(format!("{}/v1/assets/{digest}", env.url))
            .header("authorization", &auth);
        if let Some(range) = range {
            req = req.header("range", range);
        }
        let r = req.call().unwrap();
        let header = |name: &str| {
            r.headers()
                .get(name)
                .map(|v| v.to_str().unwrap().to_owned())
        };
        (
            r.status().as_u16(),
            header("content-length"),
            header("content-range"),
            header("etag"),
        )
    };
    let etag = Some(format!("\"{asset_digest}\""));
    assert_eq!(
        head(None, asset_digest),
        (200, Some(whole.len().to_string()), None, etag.clone())
    );
    assert_eq!(
        head(Some("bytes=8-15"), asset_digest),
        (
            206,
            Some("8".into()),
            Some(format!("bytes 8-15/{}", whole.len())),
            etag
        )
    );
    assert_eq!(head(None, &"0".repeat(64)).0, 404);
    let mut r = agent
        .get(&url)
        .header("authorization", &auth)
        .header("range", "bytes=8-15")
        .call()
        .unwrap();
    assert_eq!(r.status().as_u16(), 206);
    assert_eq!(
        r.headers()["content-range"].to_str().unwrap(),
        format!("bytes 8-15/{}", whole.len())
    );
    assert_eq!(r.body_mut().read_to_vec().unwrap(), &whole[8..16]);
    let len = whole.len();
    // A resume of a file already whole (curl -C -, wget -c), a range past
    // the end and a malformed one: 416 with the length, which tells the
    // client it has it all.
    for range in [
        format!("bytes={len}-"),
        "bytes=999999999-".into(),
        "bytes=9-2".into(),
    ] {
        let r = agent
            .get(&url)
            .header("authorization", &auth)
            .header("range", &range)
            .call()
            .unwrap();
        assert_eq!(r.status().as_u16(), 416, "{range}");
        assert_eq!(
            r.headers()["content-range"].to_str().unwrap(),
            format!("bytes */{len}"),
            "{range}"
        );
        assert_eq!(
            r.headers()["content-type"].to_str().unwrap(),
            "application/problem+json"
        );
    }
    // If-Range naming another representation, or a unit other than
    // bytes: the whole blob (RFC 9110 §13.1.5, §14.2); its own ETag: the
    // range.
    for (if_range, range, status) in [
        ("\"other\"".to_owned(), "bytes=0-9", 200),
        ("Sat, 28 Nov 2026 00:00:00 GMT".to_owned(), "bytes=0-9", 200),
        (format!("\"{asset_digest}\""), "bytes=0-9", 206),
        (format!("\"{asset_digest}\""), "Bytes=0-9", 206),
        (format!("\"{asset_digest}\""), "lines=0-9", 200),
    ] {
        let mut r = agent
            .get(&url)
            .header("authorization", &auth)
            .header("range", range)
            .header("if-range", &if_range)
            .call()
            .unwrap();
        assert_eq!(r.status().as_u16(), status, "{if_range} {range}");
        let body = r.body_mut().read_to_vec().unwrap();
        assert_eq!(
            body,
            if status == 206 {
                &whole[..10]
            } else {
                &whole[..]
            }
        );
    }
}

/// The client commands' exit codes tell a pipeline what went wrong
/// (`aobake --help` lists them): input refused 5, token refused 6, server
/// unreachable 7, the followed bake cancelled 8.
#[test]
fn client_exit_codes_tell_failures_apart() {
    let env = TestEnv::start(Options::default());
    let exits = |mut command: std::process::Command, code: i32| {
        let out = command.output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(code), "{stderr}");
    };
    // A bake that does not exist; a file that does not import.
    exits(env.aobake_command(&["status", "424242"]), 5);
    let truncated = env.dir.path().join("truncated.glb");
    let glb = std::fs::read(character("RiggedSimple")).unwrap();
    std::fs::write(&truncated, &glb[..glb.len() / 2]).unwrap();
    let truncated = truncated.to_str().unwrap();
    exits(
        env.aobake_command(&["submit", truncated, "--method", "vertex-linear"]),
        5,
    );
    // A token the server does not know; a server that is not there.
    let mut command = env.aobake_command(&["status", "1"]);
    command.env("AOBAKE_TOKEN", "not-a-token");
    exits(command, 6);
    // No token at all (none given, no admin.token in the data folder):
    // the same exit, with what to do, before anything is sent.
    let out = env
        .aobake_command(&["status", "1", "--data", "no-such-folder"])
        .env_remove("AOBAKE_TOKEN")
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(6), "{said}");
    assert!(
        said.starts_with("error: no token: pass --token or set AOBAKE_TOKEN"),
        "{said}"
    );
    let mut command = env.aobake_command(&["status", "1"]);
    command.env("AOBAKE_SERVER", "http://127.0.0.1:1");
    exits(command, 7);
    // A fleet's servers, comma-separated: one that cannot be reached is
    // passed over (the live one answers: no such bake); a malformed
    // entry is a wrong command line.
    let fleet = format!("http://127.0.0.1:1,{}", env.url);
    exits(
        env.aobake_command(&["status", "424242", "--server", &fleet]),
        5,
    );
    exits(
        env.aobake_command(&["status", "1", "--server", "http://127.0.0.1:1,"]),
        2,
    );
    // The bake submit --wait follows is cancelled (no worker runs it).
    let rig = character("RiggedSimple");
    let mut args = vec!["submit", rig.to_str().unwrap(), "--poses", "8", "--wait"];
    args.extend(QUICK);
    let mut follower = Follower::spawn(env.aobake_command(&args), env.dir.path(), "cancelled");
    let id = follower.submitted().to_string();
    assert!(env.aobake(&["cancel", &id]).status.success());
    let done = follower.child.wait().unwrap();
    let stderr = follower.stderr();
    assert_eq!(done.code(), Some(8), "{stderr}");
    assert!(stderr.contains(&format!("bake {id} cancelled")), "{stderr}");
    // Its report is not "yet" to come.
    let (status, problem) = env
        .request("GET", &format!("/v1/bakes/{id}/report"), ADMIN, None)
        .unwrap();
    assert_eq!(status, 404);
    assert_eq!(
        problem["detail"],
        format!("bake {id} was cancelled: it has no report")
    );
}

/// `aobake pause`, `resume`, `cancel` and `retry` drive a bake as the
/// API's actions do, and a refused one says why.
#[test]
fn the_cli_pauses_resumes_cancels_and_retries_a_bake() {
    let env = TestEnv::start(Options::default());
    let digest = upload(&env, &character("RiggedSimple"));
    let (_, b) = submit(&env, &digest, 8);
    let id = b["id"].as_i64().unwrap().to_string();
    // Fetched by its key before it is done: exit 4, saying which bake
    // has the key and how far it is, so a pipeline waits for it.
    let out = env.aobake(&[
        "fetch",
        "--key",
        b["key"].as_str().unwrap(),
        "--out",
        "x.aob",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(4), "{stderr}");
    assert!(
        stderr.contains(&format!("yet: bake {id} with this key is queued (0 of ")),
        "{stderr}"
    );
    let run = |action: &str| {
        let out = env.aobake(&[action, &id]);
        (
            out.status.success(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    // No worker runs: the bake stays queued between the actions.
    for (action, state) in [
        ("pause", "paused"),
        ("resume", "queued"),
        ("cancel", "cancelled"),
        ("retry", "queued"),
    ] {
        let (ok, stdout, stderr) = run(action);
        assert!(
            ok && stdout.starts_with(&format!("bake {id}: {state} (")),
            "{action}: {stdout}{stderr}"
        );
    }
    let (ok, _, stderr) = run("resume");
    assert!(
        !ok && stderr.contains("409") && stderr.contains("only a paused bake can be resumed"),
        "{stderr}"
    );

    // `aobake bakes` lists them newest first, the character by its file
    // name; --method and --limit are the list's.
    let (_, second) = submit(&env, &digest, 4);
    let second = second["id"].as_i64().unwrap().to_string();
    let list = |args: &[&str]| {
        let out = env.aobake(&[&["bakes"], args].concat());
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        stdout
            .lines()
            .map(|l| l.split_whitespace().map(str::to_owned).collect())
            .collect::<Vec<Vec<String>>>()
    };
    let rows = list(&[]);
    assert_eq!(rows[0][..3], ["bake", "state", "progress"], "{rows:?}");
    let ids: Vec<&str> = rows[1..].iter().map(|r| r[0].as_str()).collect();
    assert_eq!(ids, [second.as_str(), id.as_str()], "{rows:?}");
    for row in &rows[1..] {
        assert_eq!(row[1..5], ["queued", "0", "%", "vertex-linear"], "{rows:?}");
        assert_eq!(row[5], "RiggedSimple.glb", "{rows:?}");
        assert_eq!(row[6], "submitted", "{rows:?}");
    }
    assert_eq!(list(&["--limit", "1"]).len(), 2);
    assert_eq!(list(&["--method", "grid"]).len(), 1, "the head alone");
    let out = env.aobake(&["bakes", "--json", "--limit", "1"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json[0]["id"].to_string(), second, "{json}");
}

#[test]
fn progress_arrives_as_server_sent_events() {
    let mut env = TestEnv::start(Options::default());
    let digest = upload(&env, &character("RiggedSimple"));
    let (_, b) = submit(&env, &digest, 16);
    let id = b["id"].as_i64().unwrap();
    let url = env.url.clone();
    let events = follow_events(&url, id, || {
        env.start_worker(&[]);
    });
    assert_eq!(events[0]["state"], "queued");
    assert!(events.len() >= 3, "{events:?}");
    // Each event says something new: none repeats the one before.
    assert!(events.windows(2).all(|w| w[0] != w[1]), "{events:?}");
    let progress: Vec<i64> = events.iter().map(|e| e["done"].as_i64().unwrap()).collect();
    assert!(progress.windows(2).all(|w| w[0] <= w[1]), "{progress:?}");
    assert_eq!(
        progress.last(),
        events.last().unwrap()["total"].as_i64().as_ref()
    );
}

#[test]
fn two_servers_on_one_postgres_and_bucket_serve_one_bake() {
    // Servers A and B share PostgreSQL and an S3 bucket. The character is
    // uploaded and the bake submitted through B, a worker works through A,
    // and a client follows the bake's progress on B.
    let (pg, s3) = (TestPostgres::start(), TestS3::start());
    let shared = || Options {
        database: Some(pg.url.clone()),
        blobs: Some(s3.url.clone()),
        ..Options::default()
    };
    let mut a = TestEnv::start(shared());
    let b = TestEnv::start(shared());
    let rigged = character("RiggedSimple");
    let digest = upload(&b, &rigged);
    let (status, bake) = submit(&b, &digest, 16);
    assert_eq!(status, 202, "{bake}");
    let id = bake["id"].as_i64().unwrap();
    let events = follow_events(&b.url, id, || {
        a.start_worker(&[]);
    });
    // B's client heard the progress A's worker made, in order, to the end.
    assert_eq!(events[0]["state"], "queued");
    assert!(events.len() >= 3, "{events:?}");
    let progress: Vec<i64> = events.iter().map(|e| e["done"].as_i64().unwrap()).collect();
    assert!(progress.windows(2).all(|w| w[0] <= w[1]), "{progress:?}");
    // Either server serves the asset, the same bytes as `aobake bake`.
    let done = a.wait_bake(id, Duration::from_secs(60));
    assert!(asset(&a, &done) == local_bake(a.dir.path(), &rigged, 16));
    assert!(asset(&b, &done) == asset(&a, &done));
}

/// The batch protocol on the wire: a lease request names a process's idle
/// slots and gets a job for each, in order; a completions request is
/// answered item by item, each refused as `complete` would refuse it,
/// the rest recorded.
#[test]
fn the_worker_protocol_leases_and_completes_in_batches() {
    let env = TestEnv::start(Options {
        job_rays: Some(0),
        ..Options::default()
    });
    let digest = upload(&env, &character("RiggedSimple"));
    let (status, b) = submit(&env, &digest, 12);
    assert_eq!(status, 202, "{b}");
    let id = b["id"].as_i64().unwrap();
    let worker = env.token(&["worker"]);
    let post = |path: &str, body: serde_json::Value| {
        env.request("POST", path, &worker, Some(body)).unwrap()
    };
    let many: Vec<String> = (0..65).map(|i| format!("p/{i}")).collect();
    for (body, code) in [
        (json!({"workers": []}), "bad_workers"),
        (json!({ "workers": many }), "bad_workers"),
        (json!({"workers": ["p/0", "p/0"]}), "bad_workers"),
        (json!({"workers": ["p/0", ""]}), "bad_worker"),
    ] {
        let (status, answer) = post("/v1/jobs/leases", body.clone());
        assert_eq!(
            (status, answer["code"].as_str()),
            (400, Some(code)),
            "{body}: {answer}"
        );
    }
    let (status, answer) = post("/v1/jobs/completions", json!({"completions": []}));
    assert_eq!(
        (status, answer["code"].as_str()),
        (400, Some("bad_completions")),
        "{answer}"
    );

    // Twelve poses in jobs of four: three reference samples are ready.
    let slots = ["p/0", "p/1", "p/2"];
    let (status, got) = post(
        "/v1/jobs/leases",
        json!({"workers": slots, "wait_secs": 10}),
    );
    assert_eq!(status, 200, "{got}");
    let leases = got["leases"].as_array().unwrap();
    let workers: Vec<&str> = leases
        .iter()
        .map(|l| l["job"]["worker"].as_str().unwrap())
        .collect();
    assert_eq!(workers, slots, "{got}");
    let mut ids: Vec<i64> = leases
        .iter()
        .map(|l| l["job"]["id"].as_i64().unwrap())
        .collect();
    ids.dedup();
    assert_eq!(ids.len(), 3, "{got}");
    assert!(leases.iter().all(|l| l["bake"]["id"] == id), "{got}");

    let item = |l: &serde_json::Value, token: &serde_json::Value, outputs: serde_json::Value| json!({"job": l["job"]["id"], "token": token, "completion": {"outputs": outputs, "timings": {}}});
    let missing = json!([{"name": "ao-reference", "digest": "0".repeat(64)}]);
    let (status, answer) = post(
        "/v1/jobs/completions",
        json!({"completions": [
            item(&leases[0], &leases[0]["token"], missing),
            item(&leases[1], &json!("stale"), json!([])),
            item(&leases[2], &leases[2]["token"], json!([])),
        ]}),
    );
    assert_eq!(status, 200, "{answer}");
    let results = answer["results"].as_array().unwrap();
    let refusal = |i: usize| {
        (
            results[i]["job"].clone(),
            results[i]["problem"]["status"].as_u64(),
            results[i]["problem"]["code"].as_str(),
        )
    };
    assert_eq!(
        refusal(0),
        (
            leases[0]["job"]["id"].clone(),
            Some(400),
            Some("missing_blob")
        ),
        "{answer}"
    );
    assert_eq!(
        refusal(1),
        (leases[1]["job"]["id"].clone(), Some(409), Some("conflict")),
        "{answer}"
    );
    assert!(results[2].get("problem").is_none(), "{answer}");
    let (_, bake) = env
        .request("GET", &format!("/v1/bakes/{id}"), ADMIN, None)
        .unwrap();
    assert_eq!(bake["jobs_done"], 1, "only the third was recorded: {bake}");
    // The refused two are still leased: completed properly, they count.
    let (status, answer) = post(
        "/v1/jobs/completions",
        json!({"completions": [
            item(&leases[0], &leases[0]["token"], json!([])),
            item(&leases[1], &leases[1]["token"], json!([])),
        ]}),
    );
    assert_eq!(status, 200, "{answer}");
    assert!(
        answer["results"]
            .as_array()
            .unwrap()
            .iter()
            .all(|r| r.get("problem").is_none()),
        "{answer}"
    );
    let (_, bake) = env
        .request("GET", &format!("/v1/bakes/{id}"), ADMIN, None)
        .unwrap();
    assert_eq!(bake["jobs_done"], 3, "{bake}");
}

#[test]
fn requests_over_the_rate_get_429_with_retry_after() {
    let env = TestEnv::start(Options {
        rate: 5,
        ..Options::default()
    });
    let mut limited = None;
    for _ in 0..40 {
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .build()
            .into();
        let r = agent
            .get(format!("{}/v1/bakes", env.url))
            .header("authorization", format!("Bearer {ADMIN}"))
            .call()
            .unwrap();
        if r.status().as_u16() == 429 {
            limited = Some(r);
            break;
        }
    }
    let r = limited.expect("40 requests at once were never limited");
    let wait: u64 = r.headers()["retry-after"]
        .to_str()
        .unwrap()
        .parse()
        .unwrap();
    assert!(wait >= 1);
    assert_eq!(
        r.headers()["content-type"].to_str().unwrap(),
        "application/problem+json"
    );
}

#[test]
fn a_worker_over_the_rate_waits_and_fails_no_job() {
    // 10 requests a second: the evaluate job alone fetches more blobs
    // than the burst allows. Rate-limited calls wait (Retry-After) and
    // are sent again; no attempt is used up.
    let mut env = TestEnv::start(Options {
        rate: 10,
        job_rays: Some(0),
        ..Options::default()
    });
    let digest = upload(&env, &character("Fox"));
    let (status, b) = submit(&env, &digest, 24);
    assert_eq!(status, 202, "{b}");
    let id = b["id"].as_i64().unwrap();
    env.start_worker(&[]);
    let started = std::time::Instant::now();
    let bake = loop {
        // Slow polls, 429s allowed: the test's token has its own rate.
        std::thread::sleep(Duration::from_secs(1));
        let (status, b) = env
            .request("GET", &format!("/v1/bakes/{id}"), ADMIN, None)
            .unwrap();
        if status == 200 && matches!(b["state"].as_str(), Some("done" | "failed")) {
            break b;
        }
        assert!(
            started.elapsed() < Duration::from_secs(240),
            "{b}\n{}",
            env.worker_logs()
        );
    };
    assert_eq!(bake["state"], "done", "{bake}\n{}", env.worker_logs());
    let jobs = bake["jobs"].as_array().unwrap();
    assert!(jobs.len() > 20, "{bake}");
    assert!(
        jobs.iter().all(|j| j["attempts"] == 1),
        "{bake}\n{}",
        env.worker_logs()
    );
    assert!(
        !env.worker_logs().contains("failed"),
        "{}",
        env.worker_logs()
    );
}

#[test]
fn a_worker_stopped_with_sigterm_finishes_its_job_and_leases_no_more() {
    let mut env = TestEnv::start(Options::default());
    let digest = upload(&env, &character("CesiumMan"));
    let (_, b) = submit(&env, &digest, 64);
    let id = b["id"].as_i64().unwrap();
    let w = env.start_worker(&[]);
    env.wait_jobs_done(id, 2, Duration::from_secs(60));
    env.signal_worker(w, nix::sys::signal::Signal::SIGTERM);
    let started = std::time::Instant::now();
    while !env.worker_exited(w) {
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "the worker did not stop"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let (_, bake) = env
        .request("GET", &format!("/v1/bakes/{id}"), ADMIN, None)
        .unwrap();
    let jobs = bake["jobs"].as_array().unwrap();
    // Nothing left running: the job it held finished (or was given back).
    assert!(jobs.iter().all(|j| j["state"] != "running"), "{bake}");
    assert!(jobs.iter().all(|j| j["attempts"].as_i64().unwrap() <= 1));
    assert!(bake["state"] != "done", "it stopped leasing");
    let log = env.worker_logs();
    assert!(log.contains("stopped"), "{log}");
    // Another worker finishes the bake.
    env.start_worker(&[]);
    let end = env.wait_bake(id, Duration::from_secs(120));
    assert_eq!(end["state"], "done");
}

/// Waits until worker `id` has polled (`GET /v1/workers` lists it), then
/// half a second more: well inside its first long poll.
fn wait_polling(env: &TestEnv, id: &str) {
    let started = std::time::Instant::now();
    loop {
        let (_, workers) = env.request("GET", "/v1/workers", ADMIN, None).unwrap();
        if workers
            .as_array()
            .is_some_and(|a| a.iter().any(|w| w["id"] == id))
        {
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "{id} never polled: {workers}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(500));
}

/// An idle worker is inside a long poll (20 s by default) most of the
/// time: SIGTERM stops it without waiting for the poll to end, it tells
/// the server so (listed as stopped at once, not a lease later), and the
/// abandoned poll leases nothing to it after it has gone; nor does the
/// poll of a worker killed outright.
#[test]
fn an_idle_worker_stops_at_once_on_sigterm_and_a_gone_workers_poll_takes_no_job() {
    // A lease far longer than the stop: without the worker's word the
    // server would list it as idle for 30 s.
    let mut env = TestEnv::start(Options {
        lease_secs: 30.0,
        ..Options::default()
    });
    let w = env.start_worker(&[]);
    wait_polling(&env, "w0");
    env.signal_worker(w, nix::sys::signal::Signal::SIGTERM);
    let signalled = std::time::Instant::now();
    while !env.worker_exited(w) {
        assert!(
            signalled.elapsed() < Duration::from_secs(5),
            "an idle worker took over 5 s to stop (its poll has 19 s to run)\n{}",
            env.worker_logs()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let logs = env.worker_logs();
    assert!(
        logs.contains("stopped") && !logs.contains("could not tell the server"),
        "{logs}"
    );
    let (_, workers) = env.request("GET", "/v1/workers", ADMIN, None).unwrap();
    let w0 = workers
        .as_array()
        .unwrap()
        .iter()
        .find(|w| w["id"] == "w0")
        .unwrap();
    assert_eq!(
        (&w0["state"], &w0["job_id"]),
        (&json!("stopped"), &serde_json::Value::Null),
        "{workers}"
    );
    // A worker killed mid-poll (SIGKILL: no chance to say anything).
    let killed = env.start_worker(&[]);
    wait_polling(&env, "w1");
    env.kill_worker(killed);
    // A bake submitted now waits for a worker: the gone workers' polls
    // were dropped with their connections, not left to lease jobs to
    // them.
    let digest = upload(&env, &character("RiggedSimple"));
    let (_, b) = submit(&env, &digest, 8);
    let id = b["id"].as_i64().unwrap();
    std::thread::sleep(Duration::from_secs(2));
    let (_, bake) = env
        .request("GET", &format!("/v1/bakes/{id}"), ADMIN, None)
        .unwrap();
    let jobs = bake["jobs"].as_array().unwrap();
    assert!(!jobs.is_empty(), "{bake}");
    assert!(
        jobs.iter()
            .all(|j| j["attempts"] == 0 && j["worker"].is_null()),
        "{bake}"
    );
    env.start_worker(&[]);
    let end = env.wait_bake(id, Duration::from_secs(120));
    assert_eq!(end["state"], "done", "{end}");
    let jobs = end["jobs"].as_array().unwrap();
    assert!(jobs.iter().all(|j| j["attempts"] == 1), "{end}");
}

#[test]
fn clips_and_multi_file_characters_upload_and_bake() {
    let mut env = TestEnv::start(Options::default());
    env.start_worker(&[]);
    // A .gltf with its buffer as a side file, as multipart/form-data.
    let glb = std::fs::read(character("RiggedSimple")).unwrap();
    let (mut json, bin) = aobake_e2e::hostile::glb_parts(&glb);
    json["buffers"][0]["uri"] = serde_json::json!("rig.bin");
    let gltf = json.to_string().into_bytes();
    let (content_type, body) =
        aobake_e2e::multipart(&[("main", "rig.gltf", &gltf), ("rig.bin", "rig.bin", &bin)]);
    let post = |path: &str, body: &[u8]| env.post_bytes(path, ADMIN, &content_type, body);
    let (status, uploaded, _) = post("/v1/characters", &body);
    assert_eq!(status, 201, "{uploaded}");
    let (_, glb_upload, _) = env.post_bytes("/v1/characters", ADMIN, "model/gltf-binary", &glb);
    assert_ne!(
        uploaded["digest"], glb_upload["digest"],
        "another upload, another digest"
    );
    // The same character, each under the name it was uploaded with (the
    // multipart part's file name; the raw GLB sent none).
    assert_eq!(uploaded["summary"]["name"], "rig.gltf");
    assert_eq!(glb_upload["summary"]["name"], serde_json::Value::Null);
    let without_name = |s: &serde_json::Value| {
        let mut s = s.clone();
        s.as_object_mut().unwrap().remove("name");
        s
    };
    assert_eq!(
        without_name(&uploaded["summary"]),
        without_name(&glb_upload["summary"]),
        "the same character"
    );
    // Uploaded again under another name: the stored summary, the first
    // name, as every page shows it.
    let (status, again, _) = post("/v1/characters?name=again.gltf", &body);
    assert_eq!((status, &again["summary"]), (200, &uploaded["summary"]));
    // With a file the glTF does not use (a folder sent whole): that part
    // is left out and said so, and the digest, hence the cache key, is the
    // same.
    let (_, extra) = aobake_e2e::multipart(&[
        ("main", "rig.gltf", &gltf),
        ("rig.bin", "rig.bin", &bin),
        ("files", "notes.txt", b"not a buffer"),
    ]);
    let (status, with_extra, _) = post("/v1/characters", &extra);
    assert_eq!(status, 200, "{with_extra}");
    assert_eq!(with_extra["digest"], uploaded["digest"], "{with_extra}");
    let warnings = with_extra["summary"]["warnings"].to_string();
    assert!(
        warnings.contains("notes.txt") && warnings.contains("left out"),
        "{with_extra}"
    );
    assert!(
        !uploaded["summary"]["warnings"]
            .to_string()
            .contains("notes.txt")
    );
    // Without its side file the .gltf is refused by name.
    let (status, refused, _) = env.post_bytes(
        "/v1/characters",
        ADMIN,
        "model/gltf-binary",
        json.to_string().as_bytes(),
    );
    assert_eq!(status, 422, "{refused}");
    assert!(
        refused["detail"].as_str().unwrap().contains("rig.bin"),
        "{refused}"
    );

    // Clips for a character, from a second file: the Fox's own clips.
    let fox = upload(&env, &character("Fox"));
    let fox_bytes = std::fs::read(character("Fox")).unwrap();
    let (status, clips, _) = env.post_bytes(
        &format!("/v1/clips?character={fox}"),
        ADMIN,
        "model/gltf-binary",
        &fox_bytes,
    );
    assert_eq!(status, 201, "{clips}");
    let names: Vec<&str> = clips["summary"]["clips"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["Survey", "Walk", "Run"]);
    // Clips for a skeleton they do not drive are refused.
    let rigged = upload(&env, &character("RiggedSimple"));
    let (status, _, _) = env.post_bytes(
        &format!("/v1/clips?character={rigged}"),
        ADMIN,
        "model/gltf-binary",
        &fox_bytes,
    );
    assert_eq!(status, 422);
    // A bake with the clip file: another key than without it, and done.
    let with = |clips: serde_json::Value| {
        env.request(
            "POST",
            "/v1/bakes",
            ADMIN,
            Some(serde_json::json!({"character": fox, "clips": clips, "method": "static-average",
                "params": {"poses": 8, "samples": 16, "eval_poses": 1, "eval_fps": 2.0, "test_clips": ["Run"]}})),
        )
        .unwrap()
        .1
    };
    let a = with(serde_json::json!([clips["digest"]]));
    let b = with(serde_json::json!([]));
    assert_ne!(a["key"], b["key"]);
    let a = env.wait_bake(a["id"].as_i64().unwrap(), Duration::from_secs(120));
    assert_eq!(a["state"], "done", "{a}");
}

#[test]
fn a_worker_without_any_gpu_adapter_finishes_the_bake_and_says_why_there_are_no_previews() {
    let mut env = TestEnv::start(Options::default());
    // A backend this platform does not have: no adapter at all.
    env.start_worker(&[("WGPU_BACKEND", "metal")]);
    let digest = upload(&env, &character("CesiumMan"));
    let (status, b) = submit(&env, &digest, 8);
    assert_eq!(status, 202, "{b}");
    let id = b["id"].as_i64().unwrap();
    let done = env.wait_bake(id, Duration::from_secs(120));
    assert_eq!(done["state"], "done", "{done}\n{}", env.worker_logs());
    assert!(done["asset"].is_string());
    let (status, previews) = env
        .request("GET", &format!("/v1/bakes/{id}/previews"), ADMIN, None)
        .unwrap();
    assert_eq!(status, 200);
    assert_eq!(previews["state"], "completed");
    assert_eq!(previews["previews"], serde_json::json!([]));
    let why = previews["unavailable"].as_str().unwrap();
    assert!(why.contains("no GPU adapter"), "{why}");
}

#[test]
fn workers_share_a_bakes_fit_work_and_the_asset_is_byte_identical() {
    // Fox has three clips: three unseen-clips folds, each a job of its
    // own that needs only traced poses, so two workers run folds beside
    // the fit. The asset and the folds' figures equal aobake bake's.
    let mut env = TestEnv::start(Options::default());
    // Checkpoints at most every 60 s of work: none of this bake's jobs
    // runs that long, so none saves one (fast poses cost the server no
    // saves).
    // One worker runs two jobs at once (its idle slots leased in one
    // request, completions sent together), the other one.
    env.start_worker(&[
        ("AOBAKE_CHECKPOINT_SECS", "60"),
        ("AOBAKE_CONCURRENCY", "2"),
    ]);
    env.start_worker(&[("AOBAKE_CHECKPOINT_SECS", "60")]);
    let fox = character("Fox");
    let digest = upload(&env, &fox);
    let (status, b) = submit(&env, &digest, 24);
    assert_eq!(status, 202, "{b}");
    let id = b["id"].as_i64().unwrap();
    let bake = env.wait_bake(id, Duration::from_secs(240));
    assert_eq!(bake["state"], "done", "{bake}\n{}", env.worker_logs());
    let jobs = bake["jobs"].as_array().unwrap();
    let samples = jobs.iter().filter(|j| j["kind"] == "sample");
    assert!(
        samples.clone().count() >= 1 && samples.clone().all(|j| j["checkpoint"].is_null()),
        "{bake}"
    );
    let unseen: Vec<&serde_json::Value> = jobs.iter().filter(|j| j["kind"] == "unseen").collect();
    assert_eq!(unseen.len(), 3, "{bake}");
    // A fit job is worth its four steps, and completes with all of them.
    for j in unseen.iter().chain(
        jobs.iter()
            .filter(|j| j["kind"] == "fit")
            .collect::<Vec<_>>()
            .iter(),
    ) {
        assert_eq!(
            (j["state"].as_str(), j["work"].as_i64()),
            (Some("completed"), Some(4)),
            "{j}"
        );
    }
    // Every job ran on one of the three slots, some on the two-slot
    // worker's.
    let ran: Vec<&str> = jobs.iter().filter_map(|j| j["worker"].as_str()).collect();
    assert_eq!(ran.len(), jobs.len(), "{bake}");
    assert!(
        ran.iter().all(|w| ["w0/0", "w0/1", "w1"].contains(w)),
        "{ran:?}"
    );
    assert!(ran.iter().any(|w| w.starts_with("w0/")), "{ran:?}");
    let local = local_bake(env.dir.path(), &fox, 24);
    assert!(
        asset(&env, &bake) == local,
        "the service's asset differs from aobake bake's"
    );
    let (status, report) = env
        .request("GET", &format!("/v1/bakes/{id}/report"), ADMIN, None)
        .unwrap();
    assert_eq!(status, 200, "{report}");
    let local_report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(env.dir.path().join("local-24.json")).unwrap())
            .unwrap();
    let folds = &report["evaluation"]["unseen_clips"];
    assert_eq!(folds["folds"].as_array().map(Vec::len), Some(3), "{report}");
    assert_eq!(folds, &local_report["evaluation"]["unseen_clips"]);
}
