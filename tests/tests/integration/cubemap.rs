//! A cubemap bake through the service (issue 12): six face jobs on local
//! workers, the worker holding a face killed mid-face, another aborting
//! right after a checkpoint; the successors resume from the faces'
//! incremental checkpoints, lose at most one checkpoint interval, and the
//! asset equals `aobake bake`'s byte for byte.

use std::time::Duration;

use aobake_e2e::{ADMIN, Options, TestEnv, character};
use serde_json::{Value, json};

use crate::util::{aobake_bake, asset, bake_view, deep_running_job, job_info, upload};

/// 48² texels, 6 shells, 64 time samples, 32 rays: a face is a few
/// seconds of tracing with 31 checkpoints (2 time samples each).
const FLAGS: &[&str] = &[
    "--param",
    "cubemap.resolution=48",
    "--param",
    "cubemap.shells=6",
    "--param",
    "cubemap.times=64",
    "--param",
    "cubemap.rays=32",
    "--param",
    "cubemap.eval_times=2",
    "--param",
    "cubemap.eval_points=256",
    "--param",
    "cubemap.eval_ground=128",
    "--param",
    "cubemap.eval_rays=64",
];

fn params() -> Value {
    json!({"cubemap": {"resolution": 48, "shells": 6, "times": 64, "rays": 32,
        "eval_times": 2, "eval_points": 256, "eval_ground": 128, "eval_rays": 64}})
}

/// Submits a cubemap-discrete bake of `params()`; its id.
fn submit(env: &TestEnv, digest: &str) -> i64 {
    let (status, b) = env
        .request(
            "POST",
            "/v1/bakes",
            ADMIN,
            Some(json!({"character": digest, "method": "cubemap-discrete", "params": params()})),
        )
        .unwrap();
    assert_eq!(status, 202, "{b}");
    b["id"].as_i64().unwrap()
}

#[test]
fn a_cubemap_bake_survives_killed_face_workers_with_the_same_bytes() {
    let mut env = TestEnv::start(Options {
        lease_secs: 1.5,
        max_attempts: 30,
        ..Options::default()
    });
    let cm = character("CesiumMan");
    let digest = upload(&env, &cm);
    let id = submit(&env, &digest);
    let kinds: Vec<String> = bake_view(&env, id)["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j["kind"].as_str().unwrap().to_owned())
        .collect();
    // The previews' truth beside the faces, in batches of 4 frames.
    let truth = kinds.iter().filter(|k| *k == "preview-truth").count();
    assert!(truth >= 1, "{kinds:?}");
    let mut want = vec!["face"; 6];
    want.extend(vec!["preview-truth"; truth]);
    want.extend(["assemble", "evaluate", "preview"]);
    assert_eq!(kinds, want);
    // One worker aborts right after its first checkpoint.
    env.start_worker(&[("AOBAKE_FAULT", "after_checkpoint")]);
    let victim = env.start_worker(&[]);
    // Kill the other as soon as a face it runs is well under way (the
    // aborting worker never gets past its first checkpoint).
    let (killed_job, cursor_at_kill) = deep_running_job(&env, id, "face", 10);
    env.kill_worker(victim);
    env.start_worker(&[]);
    env.start_worker(&[]);
    let done = env.wait_bake(id, Duration::from_secs(300));
    assert_eq!(done["state"], "done", "{done}");
    let jobs = done["jobs"].as_array().unwrap().clone();
    let logs = env.worker_logs();
    assert!(logs.contains("fault injected after checkpoint"), "{logs}");
    // Every face's last attempt computed only the time samples after the
    // checkpoint it resumed from; the killed face resumed at or after the
    // checkpoint seen just before the kill, so the kill lost at most the
    // samples since its last checkpoint: one interval (2 time samples).
    let mut resumed = 0;
    for j in jobs.iter().filter(|j| j["kind"] == "face") {
        let attempts = j["attempts"].as_i64().unwrap();
        let info = job_info(&env, j);
        let resumed_at = info["resumed_at"].as_i64().unwrap();
        assert_eq!(
            info["computed"].as_i64().unwrap(),
            64 - resumed_at,
            "{info}"
        );
        if j["id"].as_i64() == Some(killed_job) {
            assert!(attempts > 1, "{j}");
            assert!(
                resumed_at >= cursor_at_kill,
                "the killed face resumed at {resumed_at}, before its checkpoint at {cursor_at_kill}"
            );
        }
        if attempts > 1 && resumed_at > 0 {
            resumed += 1;
        }
    }
    assert!(
        resumed >= 2,
        "the killed and the aborted faces resumed: {jobs:?}"
    );
    // The same request through `aobake bake`, undisturbed.
    let mut args = vec!["--method", "cubemap-discrete"];
    args.extend(FLAGS);
    let local = aobake_bake(env.dir.path(), &cm, &args, "local");
    assert!(
        asset(&env, &done) == local,
        "the disturbed bake's asset differs from an undisturbed one"
    );
    // `aobake export --exr` writes the decoded faces; read back with the
    // exr crate's reader, each file holds exactly the run time's values.
    let served = env.dir.path().join("served.aob");
    std::fs::write(&served, asset(&env, &done)).unwrap();
    let exr_dir = env.dir.path().join("exr");
    let out = env.aobake(&[
        "export",
        served.to_str().unwrap(),
        "--exr",
        exr_dir.to_str().unwrap(),
        "--times",
        "0.25",
        "1.5",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (model, _) = aobake_core::method::cubemap::model::CubemapModel::from_container(
        &aobake_core::asset::Container::from_bytes(&std::fs::read(&served).unwrap()).unwrap(),
    )
    .unwrap();
    for (t, shell) in [(0.25f32, 0usize), (1.5, 5)] {
        let path = exr_dir.join(format!("t{t:.3}-shell{shell}.exr"));
        let image = exr::prelude::read_first_flat_layer_from_file(&path).unwrap();
        let layer = &image.layer_data;
        assert_eq!((layer.size.width(), layer.size.height()), (6 * 48, 48));
        let y = layer.channel_data.list[0]
            .sample_data
            .values_as_f32()
            .collect::<Vec<f32>>();
        let phase = model.layout.phase(t);
        for face in 0..6 {
            let want = model.decode_face(face, shell, phase);
            for j in 0..48 {
                for i in 0..48 {
                    assert_eq!(y[j * 6 * 48 + face * 48 + i], want[j * 48 + i]);
                }
            }
        }
    }
    // And the static ground's texture, value for value.
    let ground =
        exr::prelude::read_first_flat_layer_from_file(exr_dir.join("ground-offsets.exr")).unwrap();
    let offsets: Vec<f32> = ground.layer_data.channel_data.list[0]
        .sample_data
        .values_as_f32()
        .collect();
    let g = model.ground.as_ref().expect("a static ground by default");
    assert_eq!(offsets, g.offsets, "the ground's offsets bit for bit");
    // The report is a cubemap report, with both encodings.
    let (_, report) = env
        .request("GET", &format!("/v1/bakes/{id}/report"), ADMIN, None)
        .unwrap();
    let names: Vec<&str> = report["evaluation"]["variants"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["name"].as_str().unwrap())
        .collect();
    assert_eq!(names[0], "cubemap-discrete");
    assert!(names.contains(&"cubemap-continuous"), "{names:?}");
}

/// A face's progress moves with its batches, within about a second, even
/// when the worker's heartbeat period is far longer than a face (here
/// 30 s): the bar does not sit at 0 until faces complete.
#[test]
fn a_faces_progress_moves_before_it_completes() {
    let mut env = TestEnv::start(Options {
        lease_secs: 120.0,
        ..Options::default()
    });
    let digest = upload(&env, &character("CesiumMan"));
    let id = submit(&env, &digest);
    env.start_worker(&[]);
    let started = std::time::Instant::now();
    let mut partial = None;
    while partial.is_none() && started.elapsed() < Duration::from_secs(120) {
        let view = bake_view(&env, id);
        partial = view["jobs"].as_array().unwrap().iter().find_map(|j| {
            let (progress, work) = (j["progress"].as_i64().unwrap(), j["work"].as_i64().unwrap());
            (j["kind"] == "face" && j["state"] == "running" && progress > 0 && progress < work)
                .then(|| (progress, work, view["progress"]["done"].as_i64().unwrap()))
        });
        std::thread::sleep(Duration::from_millis(50));
    }
    let (progress, work, done) = partial.expect("a running face showed partial progress");
    assert!(
        done >= progress,
        "the bake's bar counts the face's progress: {done} < {progress}"
    );
    eprintln!("a running face at {progress}/{work}, the bake at {done}");
}
