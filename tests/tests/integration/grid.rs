//! A grid bake of the milk truck through the service (issue 13): slab jobs
//! per part on local workers, the worker holding a slab killed mid-slab,
//! another aborting right after a checkpoint; the successors resume from
//! the slabs' per-layer checkpoints and the asset equals `aobake bake`'s
//! byte for byte. `aobake export --exr` writes every part's grid, read
//! back here with the exr crate's reader.

use std::time::Duration;

use aobake_e2e::{ADMIN, Options, TestEnv, character};
use serde_json::{Value, json};

use crate::util::{
    aobake_bake, asset, bake_view, deep_running_job, export_exr, exr_channel, job_info, upload,
};

/// 32³ cells with 512 rays: a slab of 8 layers is a few seconds of
/// tracing with a checkpoint after each layer; a token evaluation.
const FLAGS: &[&str] = &[
    "--param",
    "grid.rays=512",
    "--param",
    "grid.eval_frames=2",
    "--param",
    "grid.eval_ground=64",
    "--param",
    "grid.eval_rays=32",
    "--param",
    "grid.average_frames=2",
];

fn params() -> Value {
    json!({"grid": {"rays": 512, "eval_frames": 2, "eval_ground": 64, "eval_rays": 32,
        "average_frames": 2}})
}

#[test]
fn a_grid_bake_survives_killed_slab_workers_with_the_same_bytes() {
    let mut env = TestEnv::start(Options {
        lease_secs: 1.5,
        max_attempts: 30,
        ..Options::default()
    });
    let truck = character("CesiumMilkTruck");
    let digest = upload(&env, &truck);
    let (status, b) = env
        .request(
            "POST",
            "/v1/bakes",
            ADMIN,
            Some(json!({"character": digest, "method": "grid", "params": params()})),
        )
        .unwrap();
    assert_eq!(status, 202, "{b}");
    let id = b["id"].as_i64().unwrap();
    let kinds: Vec<String> = bake_view(&env, id)["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j["kind"].as_str().unwrap().to_owned())
        .collect();
    // Three parts (the body and two axles), four slabs of 8 layers each,
    // the static base's training frames in one batch, then the previews'
    // truth in batches of 4 frames (3 stills and the animation's frames)
    // beside them.
    let truth = kinds.iter().filter(|k| *k == "preview-truth").count();
    assert!(truth >= 1, "{kinds:?}");
    let mut want = vec!["slab"; 12];
    want.push("sample");
    want.extend(vec!["preview-truth"; truth]);
    want.extend(["assemble", "evaluate", "preview"]);
    assert_eq!(kinds, want);
    env.start_worker(&[("AOBAKE_FAULT", "after_checkpoint")]);
    let victim = env.start_worker(&[]);
    let (killed_job, cursor_at_kill) = deep_running_job(&env, id, "slab", 2);
    env.kill_worker(victim);
    env.start_worker(&[]);
    env.start_worker(&[]);
    let done = env.wait_bake(id, Duration::from_secs(400));
    assert_eq!(done["state"], "done", "{done}");
    let logs = env.worker_logs();
    assert!(logs.contains("fault injected after checkpoint"), "{logs}");
    // The killed slab resumed at or after the checkpoint seen before the
    // kill: the kill lost at most the layer in progress.
    let jobs = done["jobs"].as_array().unwrap();
    let killed = jobs
        .iter()
        .find(|j| j["id"].as_i64() == Some(killed_job))
        .unwrap();
    assert!(killed["attempts"].as_i64().unwrap() > 1, "{killed}");
    let info = job_info(&env, killed);
    let resumed_at = info["resumed_at"].as_i64().unwrap();
    assert!(
        resumed_at >= cursor_at_kill,
        "the killed slab resumed at {resumed_at}, before its checkpoint at {cursor_at_kill}"
    );
    assert_eq!(info["computed"].as_i64().unwrap(), 8 - resumed_at);
    // The same request through `aobake bake`, undisturbed.
    let mut args = vec!["--method", "grid"];
    args.extend(FLAGS);
    let local = aobake_bake(env.dir.path(), &truck, &args, "local");
    let served = asset(&env, &done);
    assert!(
        served == local,
        "the disturbed bake's asset differs from an undisturbed one"
    );
    // `aobake export --exr`: one file per part, read back cell for cell.
    let exr_dir = export_exr(&env, &served);
    let (model, _) = aobake_core::method::grid::model::GridModel::from_container(
        &aobake_core::asset::Container::from_bytes(&served).unwrap(),
    )
    .unwrap();
    let mut files: Vec<_> = std::fs::read_dir(&exr_dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    files.sort();
    assert_eq!(files.len(), 4, "three parts and the ground: {files:?}");
    let base = model.base.as_ref().expect("a static base by default");
    let ground =
        exr::prelude::read_all_flat_layers_from_file(exr_dir.join("ground-offsets.exr")).unwrap();
    let offsets: Vec<f32> = ground.layer_data[0].channel_data.list[0]
        .sample_data
        .values_as_f32()
        .collect();
    assert_eq!(
        offsets, base.ground.offsets,
        "the ground's offsets bit for bit"
    );
    let part = &model.parts[1];
    let file = files.iter().find(|f| f.starts_with("part1-")).unwrap();
    let image = exr::prelude::read_all_flat_layers_from_file(exr_dir.join(file)).unwrap();
    let layer = &image.layer_data[0];
    assert_eq!((layer.size.width(), layer.size.height()), (32, 32 * 32));
    let channel = |name: &str| exr_channel(layer, name);
    let (ao, axis_y) = (channel("ao_grid"), channel("axis.y"));
    let dirs = part.directions.as_ref().expect("cones by default");
    for (z, y, x) in [(0, 0, 0), (16, 5, 30), (31, 31, 7), (9, 20, 11)] {
        let cell = (z * 32 + y) * 32 + x;
        let pixel = (z * 32 + (31 - y)) * 32 + x;
        assert_eq!(ao[pixel], 2.0 * f32::from(part.occlusion[cell]) / 255.0);
        assert_eq!(axis_y[pixel], f32::from(dirs[cell][1]) / 255.0 * 2.0 - 1.0);
    }
    // The report is a grid report with every variant.
    let (_, report) = env
        .request("GET", &format!("/v1/bakes/{id}/report"), ADMIN, None)
        .unwrap();
    let names: Vec<&str> = report["evaluation"]["variants"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["name"].as_str().unwrap())
        .collect();
    assert_eq!(names[0], "grids on a static base (cones)");
    assert!(names.contains(&"grids (cones)"), "{names:?}");
    assert!(names.contains(&"static average"), "{names:?}");
    assert_eq!(report["parts"].as_array().unwrap().len(), 3);
}
